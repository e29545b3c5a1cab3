//! Fit time and accuracy per test kind: pendulum, slider and input-driven axis against the SciPy
//! peer (`bench/scipy_peer.py`, run as a subprocess on the same files: the shared examples and
//! the bench's own records, `bench::records`), lift per input-noise
//! level in `bench::lift` (it has no peer). The ratio is the peer's total time over ours on the
//! same files.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use pantowatch_models::identify::{FitOptions, fit_base};
use serde_json::{Value, json};

use super::table::{Row, Sizes, SuiteArgs, median};

/// Target speed-up over the SciPy peer for single joints.
const RATIO_TARGET: f64 = 200.0;

/// One timed file: our median time and estimates, the truth, the peer's (if it ran).
#[derive(Debug, Clone)]
struct Timed {
    name: String,
    rust_s: f64,
    viscous: f64,
    dry: f64,
    truth: (f64, f64),
    peer: Option<(f64, f64, f64)>,
}

fn err_pct(est: f64, truth: f64) -> f64 {
    100.0 * (est / truth - 1.0)
}

impl Timed {
    /// Largest |error| of viscous and dry against the truth, %.
    fn err(&self) -> f64 {
        err_pct(self.viscous, self.truth.0)
            .abs()
            .max(err_pct(self.dry, self.truth.1).abs())
    }
    fn peer_err(&self) -> Option<f64> {
        self.peer.map(|(_, v, d)| {
            err_pct(v, self.truth.0)
                .abs()
                .max(err_pct(d, self.truth.1).abs())
        })
    }
}

pub fn run(a: &SuiteArgs, sizes: &Sizes) -> Vec<Row> {
    let mut rows = Vec::new();
    match pantowatch::cli::examples_dir() {
        None => {
            for m in ["fit: pendulum", "fit: slider"] {
                rows.push(Row::failed(
                    m,
                    "≥ 200× the SciPy peer",
                    "../shared/data/examples not found (set PANTOWATCH_EXAMPLES)",
                ));
            }
        }
        Some(ex) => match single_joints(a, sizes, &ex) {
            Ok(r) => rows.extend(r),
            Err(e) => rows.push(Row::failed(
                "fit: pendulum, slider",
                "≥ 200× the SciPy peer",
                &format!("{e:#}"),
            )),
        },
    }
    rows.extend(super::scaling::rows(sizes, a.quick));
    rows.extend(super::lift::rows(sizes));
    rows
}

/// The pendulum files (quick: one) and the slider file of the example set.
fn example_files(ex: &Path, quick: bool) -> (Vec<PathBuf>, Vec<PathBuf>) {
    let pend: Vec<&str> = if quick {
        vec!["J3_baseline"]
    } else {
        vec![
            "J1_baseline",
            "J2_baseline",
            "J3_baseline",
            "J4_baseline",
            "J5_baseline",
            "J6_baseline",
            "J7_baseline",
            "J5_viscous_x2.5",
            "J3_dry_x1.8",
        ]
    };
    let path = |n: &str| ex.join(format!("{n}.json"));
    (
        pend.into_iter().map(path).collect(),
        vec![path("slider_baseline")],
    )
}

fn single_joints(a: &SuiteArgs, sizes: &Sizes, ex: &Path) -> anyhow::Result<Vec<Row>> {
    let truth: Value = serde_json::from_slice(&std::fs::read(ex.join("truth.json"))?)?;
    let (pend, mut slider) = example_files(ex, a.quick);
    // The bench's own records (issue 38): a 30 s slider and an input-driven axis, in a fresh
    // directory of this run.
    let dir = std::env::temp_dir().join(format!("pantowatch-bench-records-{}", std::process::id()));
    let records = super::records::write(&dir)?;
    let truth = super::records::truth_with(truth, &records);
    let (driven, slid): (Vec<_>, Vec<_>) = records.iter().map(|r| r.path.clone()).partition(|p| {
        p.file_stem()
            .is_some_and(|s| s.to_string_lossy().starts_with("driven"))
    });
    slider.extend(slid);
    let all: Vec<PathBuf> = pend.iter().chain(&slider).chain(&driven).cloned().collect();
    let peer = run_peer(a, &all, sizes.repeat);
    let mut timed = HashMap::new();
    for f in &all {
        eprintln!("   fitting {}", f.display());
        let t = time_file(f, sizes.repeat, &truth)?;
        timed.insert(f.clone(), t);
    }
    if let Ok(p) = &peer {
        for t in timed.values_mut() {
            t.peer = p.get(&t.name).copied();
        }
    }
    let peer_note = peer.as_ref().err().cloned();
    let _ = std::fs::remove_dir_all(&dir);
    let pick =
        |files: &[PathBuf]| -> Vec<Timed> { files.iter().map(|f| timed[f].clone()).collect() };
    Ok(vec![
        kind_row("fit: pendulum", &pick(&pend), peer_note.as_deref()),
        kind_row("fit: slider", &pick(&slider), peer_note.as_deref()),
        kind_row(
            "fit: input-driven axis",
            &pick(&driven),
            peer_note.as_deref(),
        ),
    ])
}

/// Our identification (`fit_base`, what the peer does too) of one file: median of `repeat`.
fn time_file(f: &Path, repeat: usize, truth: &Value) -> anyhow::Result<Timed> {
    let doc = pantowatch::cli::read_trace(f)?;
    let (test, _) = doc
        .joint_test()
        .map_err(|e| anyhow::anyhow!("{}: {e}", f.display()))?;
    let name = f
        .file_stem()
        .map_or(String::new(), |s| s.to_string_lossy().into_owned());
    let tv = truth
        .get(&name)
        .ok_or_else(|| anyhow::anyhow!("truth.json has no entry {name}"))?;
    let num = |k: &str| {
        tv.get(k)
            .and_then(Value::as_f64)
            .ok_or_else(|| anyhow::anyhow!("truth.json {name}.{k} missing"))
    };
    let opts = FitOptions::default();
    let mut times = Vec::new();
    let mut last = None;
    for _ in 0..repeat {
        let t0 = Instant::now();
        let fit = fit_base(&test, &opts).map_err(|e| anyhow::anyhow!("{name}: {e}"))?;
        times.push(t0.elapsed().as_secs_f64());
        last = Some(fit);
    }
    let fit = last.ok_or_else(|| anyhow::anyhow!("no fit"))?;
    let truth = (num("viscous")?, num("dry")?);
    Ok(Timed {
        name,
        rust_s: median(times),
        viscous: fit.law.viscous,
        dry: fit.law.dry,
        truth,
        peer: None,
    })
}

/// Runs the SciPy peer on `files` (one core: single-threaded BLAS); file stem → (median s,
/// viscous, dry). `Err` says why there is no peer column.
fn run_peer(
    a: &SuiteArgs,
    files: &[PathBuf],
    repeat: usize,
) -> Result<HashMap<String, (f64, f64, f64)>, String> {
    let script = a
        .peer
        .clone()
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("../bench/scipy_peer.py"));
    if !script.is_file() {
        return Err(format!(
            "peer: unavailable ({} not found)",
            script.display()
        ));
    }
    let has_scipy = Command::new("python3")
        .args(["-c", "import numpy, scipy"])
        .output()
        .is_ok_and(|o| o.status.success());
    if !has_scipy {
        return Err("peer: unavailable (python3 with numpy and scipy not found: pip install -r bench/requirements.txt)".into());
    }
    eprintln!("   SciPy peer on {} files (repeat {repeat})…", files.len());
    let out = Command::new("python3")
        .arg(&script)
        .args(files)
        .args(["--repeat", &repeat.to_string()])
        .env("OMP_NUM_THREADS", "1")
        .env("OPENBLAS_NUM_THREADS", "1")
        .env("MKL_NUM_THREADS", "1")
        .output()
        .map_err(|e| format!("peer: unavailable ({e})"))?;
    if !out.status.success() {
        return Err(format!(
            "peer: failed ({})",
            String::from_utf8_lossy(&out.stderr)
                .lines()
                .last()
                .unwrap_or("")
        ));
    }
    let mut m = HashMap::new();
    for line in String::from_utf8_lossy(&out.stdout).lines() {
        let Ok(v) = serde_json::from_str::<Value>(line) else {
            continue;
        };
        let f = |k: &str| v.get(k).and_then(Value::as_f64);
        let (Some(file), Some(s), Some(vi), Some(d)) = (
            v.get("file").and_then(Value::as_str),
            f("seconds"),
            f("viscous"),
            f("dry"),
        ) else {
            continue;
        };
        let stem = Path::new(file)
            .file_stem()
            .map_or(String::new(), |s| s.to_string_lossy().into_owned());
        m.insert(stem, (s, vi, d));
    }
    Ok(m)
}

fn kind_row(measure: &str, ts: &[Timed], peer_note: Option<&str>) -> Row {
    let n = ts.len();
    let rust_total: f64 = ts.iter().map(|t| t.rust_s).sum();
    let rust_per = rust_total / n as f64;
    let err = ts.iter().map(Timed::err).fold(0.0, f64::max);
    let per_file: Vec<_> = ts
        .iter()
        .map(|t| {
            json!({"file": t.name, "rust_s": t.rust_s, "viscous": t.viscous, "dry": t.dry,
                   "truth": [t.truth.0, t.truth.1], "err_pct": t.err(),
                   "peer_s": t.peer.map(|p| p.0), "peer_err_pct": t.peer_err(),
                   "ratio": t.peer.map(|p| p.0 / t.rust_s)})
        })
        .collect();
    let all_peer = ts.iter().all(|t| t.peer.is_some());
    let (measured, pass, value) = if all_peer && peer_note.is_none() {
        let peer_total: f64 = ts.iter().filter_map(|t| t.peer.map(|p| p.0)).sum();
        let ratio = peer_total / rust_total;
        let min = ts
            .iter()
            .filter_map(|t| t.peer.map(|p| p.0 / t.rust_s))
            .fold(f64::INFINITY, f64::min);
        let peer_err = ts.iter().filter_map(Timed::peer_err).fold(0.0, f64::max);
        (
            format!(
                "{:.1} ms/fit vs peer {:.2} s: **{ratio:.0}×** (per file ≥ {min:.0}×); worst error {err:.2} % (peer {peer_err:.2} %); {n} file(s)",
                rust_per * 1e3,
                peer_total / n as f64
            ),
            // Every trace, not only the total (issue 38).
            Some(min >= RATIO_TARGET),
            Some(min),
        )
    } else {
        (
            format!(
                "{:.1} ms/fit; worst error {err:.2} %; {}",
                rust_per * 1e3,
                peer_note.unwrap_or("peer: unavailable")
            ),
            None,
            None,
        )
    };
    Row {
        measure: format!("{measure} ({n} trace{})", if n == 1 { "" } else { "s" }),
        measured,
        target: "≥ 200× the SciPy peer on every trace, same accuracy".into(),
        pass,
        value,
        unit: "× peer".into(),
        detail: json!(per_file),
    }
}

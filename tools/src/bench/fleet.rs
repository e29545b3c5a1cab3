//! Fleet re-processing: lift traces synthesised like the demo fleet's (raise and lower, every
//! sixth pantograph's J3 dry friction worn, realistic sensor noise on every channel), fitted on
//! every core with a progress bar; fits per second and the time projected for a year of monthly
//! lift tests of 1,000 pantographs.

use std::num::NonZeroUsize;
use std::time::Instant;

use indicatif::{ProgressBar, ProgressStyle};
use pantowatch_models::drift::DriftThresholds;
use pantowatch_models::lift::batch;
use serde_json::json;

use super::table::{FLEET_YEAR, Row, Sizes};
use pantowatch::cli::simulate::docs::noisy_lift_doc;
use pantowatch::trace::TraceDoc;

/// Target for re-processing [`FLEET_YEAR`] traces on 2 cores, s.
const TARGET_S: f64 = 600.0;
/// Traces synthesised, then fitted, at a time (bounds memory with `--full`: ~0.2 MB each).
const CHUNK: usize = 400;

/// The `i`-th trace of the synthetic year: pantograph `i / 12`, month `i % 12`; every sixth
/// pantograph's J3 dry friction grows to 1.8× over the year, the rest stay at Table 4. Every
/// channel carries the stand's realistic sensor noise (issue 15: K = 1, inputs included).
fn fleet_doc(i: usize) -> anyhow::Result<TraceDoc> {
    let (p, m) = (i / 12, i % 12);
    let factor = if p % 6 == 1 {
        1.0 + 0.8 * m as f64 / 11.0
    } else {
        1.0
    };
    let drift = format!("J3:dry={factor}");
    let scale: &[&str] = if factor == 1.0 { &[] } else { &[&drift] };
    noisy_lift_doc(
        (i as u64) * 7 + 3,
        scale,
        1.0,
        &format!("160EC-{:04}", p + 1),
        &format!("bench-fleet-{i}"),
    )
}

/// Runs `work(i)` for every `i < n` on `threads` threads, ticking `bar` per item; the results
/// in index order. The queue is `pantowatch_models::lift::batch::map` (what `fit_many` runs
/// on): each thread keeps its lift-fit buffers from one trace to the next.
fn parallel<T: Send>(
    n: usize,
    threads: usize,
    bar: &ProgressBar,
    work: impl Fn(usize) -> T + Sync,
) -> Vec<T> {
    let idx: Vec<usize> = (0..n).collect();
    let tick = |_done: usize| bar.inc(1);
    batch::map(&idx, NonZeroUsize::new(threads), &tick, |&i| work(i))
}

/// Fits every document on `threads` cores (the same call the worker makes per job).
fn fit_all(docs: &[TraceDoc], threads: usize, bar: &ProgressBar) -> Vec<Result<(), String>> {
    let th = DriftThresholds::default();
    parallel(docs.len(), threads, bar, |i| {
        pantowatch::fitting::fit_document(&docs[i], &th)
            .map(|_| ())
            .map_err(|e| e.to_string())
    })
}

fn bar(n: usize, what: &str) -> ProgressBar {
    let b = ProgressBar::new(n as u64);
    b.set_style(
        ProgressStyle::with_template(&format!(
            "   {what} {{bar:40}} {{pos}}/{{len}} {{per_sec}} eta {{eta}}"
        ))
        .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    b
}

pub fn run(sizes: &Sizes) -> Vec<Row> {
    let measure = format!(
        "fleet re-processing ({} lift traces{})",
        sizes.fleet_traces,
        if sizes.fleet_traces < FLEET_YEAR {
            ", projected to 12,000"
        } else {
            ""
        }
    );
    let row = match measure_fleet(sizes.fleet_traces) {
        Ok(r) => {
            let threads = std::thread::available_parallelism().map_or(1, usize::from);
            let rate = r.fitted as f64 / r.fit_s;
            let projected = FLEET_YEAR as f64 / rate;
            Row {
                measure,
                measured: format!(
                    "{rate:.2} fits/s on {threads} cores → 12,000 in **{:.1} min**{}",
                    projected / 60.0,
                    if r.failed > 0 {
                        format!(" ({} of {} fits failed)", r.failed, r.fitted + r.failed)
                    } else {
                        String::new()
                    }
                ),
                target: "12,000 in ≤ 10 min on 2 cores".into(),
                pass: Some(projected <= TARGET_S && r.failed == 0),
                value: Some(projected),
                unit: "s for 12,000".into(),
                detail: json!({"traces": sizes.fleet_traces, "fitted": r.fitted, "failed": r.failed,
                               "fit_wall_s": r.fit_s, "fits_per_s": rate, "threads": threads,
                               "first_error": r.first_error}),
            }
        }
        Err(e) => Row::failed(&measure, "12,000 in ≤ 10 min on 2 cores", &format!("{e:#}")),
    };
    vec![row]
}

struct FleetRun {
    fitted: usize,
    failed: usize,
    /// Wall time of the fit phases only (synthesis is not timed).
    fit_s: f64,
    first_error: Option<String>,
}

fn measure_fleet(n: usize) -> anyhow::Result<FleetRun> {
    let threads = std::thread::available_parallelism().map_or(1, usize::from);
    let synth = bar(n, "synthesise");
    let fits = bar(n, "fit       ");
    let mut r = FleetRun {
        fitted: 0,
        failed: 0,
        fit_s: 0.0,
        first_error: None,
    };
    for start in (0..n).step_by(CHUNK) {
        let len = CHUNK.min(n - start);
        let docs = parallel(len, threads, &synth, |k| fleet_doc(start + k))
            .into_iter()
            .collect::<anyhow::Result<Vec<_>>>()?;
        let t0 = Instant::now();
        let results = fit_all(&docs, threads, &fits);
        r.fit_s += t0.elapsed().as_secs_f64();
        for res in results {
            match res {
                Ok(()) => r.fitted += 1,
                Err(e) => {
                    r.failed += 1;
                    r.first_error.get_or_insert(e);
                }
            }
        }
    }
    synth.finish_and_clear();
    fits.finish_and_clear();
    if r.fitted == 0 {
        anyhow::bail!(
            "no lift trace could be fitted: {}",
            r.first_error.unwrap_or_default()
        );
    }
    Ok(r)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parallel_keeps_order_and_runs_everything() {
        let b = ProgressBar::hidden();
        let out = parallel(50, 3, &b, |i| i * i);
        assert_eq!(out, (0..50).map(|i| i * i).collect::<Vec<_>>());
        assert_eq!(b.position(), 50);
    }
}

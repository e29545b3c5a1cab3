//! The `pantowatch-tools bench` binary as a user runs it: `bench suite` at toy sizes against
//! the real databases, and `bench FILE…` on a simulated trace.

use std::process::Command;

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_pantowatch-tools"))
}

/// Runs `cmd`, asserts it succeeded (its output in the message if not), returns its stdout.
fn run_ok(cmd: &mut Command) -> String {
    let out = cmd.output().unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout).to_string();
    assert!(
        out.status.success(),
        "{stdout}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    stdout
}

fn tmp(name: &str) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("pantowatch-tools-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

/// `bench suite` end to end at toy sizes, every section against the real databases (PostgreSQL
/// on 127.0.0.1:5432, SQLite files): one table with every measure under the machine line, the
/// same run in the `--json-out` file, no fleet fit failed, every stored trace read back
/// bit-exact, and no peer → the ratio is not judged (rather than a crash). Nothing here is
/// timed against a target: the figures are the benchmark's, not the test's.
#[test]
fn bench_suite_runs_every_section_and_writes_its_json() {
    let json = tmp("suite.json");
    let _ = std::fs::remove_file(&json);
    let stdout = run_ok(
        bin()
            .args([
                "bench",
                "suite",
                "--quick",
                "--repeat",
                "1",
                "--fleet-traces",
                "3",
                "--ingest-traces",
                "6",
                "--concurrency",
                "2",
                "--pantographs",
                "12",
                "--queries",
                "10",
                "--peer",
                "/nonexistent/scipy_peer.py",
            ])
            .arg("--json-out")
            .arg(&json),
    );
    assert!(stdout.starts_with("Machine: "), "{stdout}");
    for measure in [
        "| fit: pendulum",
        "| fit: slider",
        "| fit time vs length: pendulum J3",
        "| fit time vs length: slider J8",
        "| fit time vs length: input-driven axis",
        "| fit: input-driven axis, positioning-benchmark size (25k samples, 1 kHz)",
        "| fit: lift, clean inputs (3 raise-and-lower lifts, one core)",
        "| fit: lift, realistic sensor noise (3 raise-and-lower lifts, one core)",
        "| fit: lift, 2× sensor noise (3 raise-and-lower lifts, one core)",
        // The core count closes the label (the loop tries its candidates on every core offered).
        "| fit: lift with an undeclared effect, whole residual loop (3 lifts, realistic noise, ",
        "| fleet re-processing (3 lift traces, projected to 12,000)",
        "| ingest: API into PostgreSQL",
        "| storage",
        "| query: fleet health, PostgreSQL (12 pantographs, 144 fits)",
        "| query: fleet health, SQLite (12 pantographs, 144 fits)",
        "| fit: input-driven axis (1 trace)",
        "| fit time vs length: quadrangle swing",
        "| fit time vs length: lift (raise and lower, 8 s)",
        "| fit time vs length: static_force",
        "| plan: fleet test plan, PostgreSQL (12 pantographs, 240 fits)",
        "| plan: fleet test plan, SQLite (12 pantographs, 240 fits)",
    ] {
        assert!(stdout.contains(measure), "no row {measure:?} in\n{stdout}");
    }
    assert!(!stdout.contains("not measured"), "{stdout}");
    let v: serde_json::Value = serde_json::from_slice(&std::fs::read(&json).unwrap()).unwrap();
    let rows = v["rows"].as_array().unwrap();
    assert_eq!(rows.len(), 21, "{v}");
    let row = |prefix: &str| {
        rows.iter()
            .find(|r| r["measure"].as_str().unwrap().starts_with(prefix))
            .unwrap_or_else(|| panic!("{prefix}"))
    };
    // The residual loop's row: its time per protocol (p95, the slowest its value), the work
    // each lift took, and what it named.
    let lp = row("fit: lift with an undeclared effect");
    assert!(lp["value"].as_f64().is_some_and(|s| s > 0.0), "{lp}");
    let lifts = lp["detail"]["lifts"].as_array().unwrap();
    assert_eq!(lifts.len(), 3, "{lp}");
    let mut protocols: Vec<&str> = lifts
        .iter()
        .map(|l| l["protocol"].as_str().unwrap())
        .collect();
    protocols.sort_unstable();
    assert_eq!(protocols, ["design", "raise", "raise-and-lower"], "{lp}");
    assert!(
        lifts
            .iter()
            .all(|l| l["steps"].as_u64().is_some_and(|s| s > 0)),
        "{lp}"
    );
    assert!(
        lp["detail"]["named_right"].as_u64().is_some_and(|n| n >= 2),
        "{lp}"
    );
    // Issue 38: fit time against record length per single-joint kind, at 1k and 10k samples
    // (quick), judged on its growth exponent (its value), each length with both timings.
    for prefix in [
        "fit time vs length: pendulum",
        "fit time vs length: slider",
        "fit time vs length: input-driven",
    ] {
        let r = row(prefix);
        assert!(r["value"].as_f64().is_some_and(f64::is_finite), "{r}");
        assert!(r["pass"].is_boolean(), "{r}");
        let points = r["detail"].as_array().unwrap();
        assert_eq!(points.len(), 2, "{r}");
        for p in points {
            assert!(p["identify_s"].as_f64().is_some_and(|t| t > 0.0), "{r}");
            assert!(p["with_loop_s"].as_f64().is_some_and(|t| t > 0.0), "{r}");
        }
    }
    let emps = row("fit: input-driven axis, positioning-benchmark");
    assert!(
        emps["detail"]["samples"]
            .as_u64()
            .is_some_and(|n| n.abs_diff(25_000) <= 1),
        "{emps}"
    );
    // Without the peer the single-joint ratio is not judged, and says why.
    assert!(row("fit: pendulum")["pass"].is_null());
    assert!(
        row("fit: pendulum")["measured"]
            .as_str()
            .unwrap()
            .contains("peer")
    );
    let fleet = &row("fleet re-processing")["detail"];
    assert_eq!(
        (fleet["fitted"].as_u64(), fleet["failed"].as_u64()),
        (Some(3), Some(0))
    );
    let storage = &row("storage")["detail"];
    assert_eq!(storage["bit_exact"], storage["traces"]);
    assert_eq!(storage["traces"].as_u64(), Some(6));
    assert_eq!(v["sizes"]["fleet_traces"].as_u64(), Some(3));
    assert!(v["machine"]["cores"].as_u64().unwrap() >= 1);
    // The lift rows' noisy lifts carry input noise the fit estimated; the clean ones none.
    for (prefix, noisy) in [
        ("fit: lift, clean", false),
        ("fit: lift, realistic", true),
        ("fit: lift, 2×", true),
    ] {
        let lifts = row(prefix)["detail"]["lifts"].as_array().unwrap();
        assert_eq!(lifts.len(), 3, "{prefix}");
        for l in lifts {
            let sd = l["input_noise_sd"]["T_Nm"].as_f64().unwrap();
            assert_eq!(sd > 0.5, noisy, "{prefix}: T noise sd {sd}");
        }
    }
}

/// `bench --json FILE` (what bench/run.sh reads beside the SciPy peer): one JSON line per file
/// with the fitted law and the time per fit.
#[test]
fn bench_files_json_prints_one_line_per_file() {
    let defaults = pantowatch::cli::simulate::docs::simulate_defaults().unwrap();
    let args = pantowatch::cli::simulate::SimulateArgs {
        kind: "pendulum".into(),
        joint: "J3".into(),
        duration: 10.0,
        seed: 3,
        ..defaults
    };
    let doc = pantowatch::cli::simulate::simulate_doc(&args).unwrap();
    let trace = tmp("bench-j3.json");
    std::fs::write(&trace, serde_json::to_vec(&doc.to_value()).unwrap()).unwrap();
    let stdout = run_ok(bin().args(["bench", "--json", "--repeat", "1"]).arg(&trace));
    let lines: Vec<serde_json::Value> = stdout
        .lines()
        .map(|l| serde_json::from_str(l).unwrap_or_else(|e| panic!("{e}: {l}")))
        .collect();
    assert_eq!(lines.len(), 1, "{stdout}");
    let l = &lines[0];
    assert_eq!(l["kind"], "pendulum", "{l}");
    assert_eq!(l["fits"], 1, "{l}");
    assert!(l["viscous"].as_f64().is_some_and(f64::is_finite), "{l}");
    assert!(
        l["seconds_per_fit"].as_f64().is_some_and(|s| s > 0.0),
        "{l}"
    );
}

//! `pantowatch-tools bench FILE…`: time the identification of each trace on one core (median of
//! `--repeat` runs) — the Rust side of `bench/run.sh`, which puts it beside the SciPy peer.
//! Lift traces are timed too: the complete-pantograph MAP fit with its fit-result mapping (one
//! thread; "viscous"/"dry" show J3's, the joint a lift informs best).

use std::time::Instant;

use pantowatch_models::drift::DriftThresholds;
use pantowatch_models::identify::{FitOptions, fit_base};
use serde_json::json;

use pantowatch::trace::{Kind, TraceDoc};

use super::table::{BenchArgs, median};

/// Times every file of `a.files` and prints a table or JSON lines.
pub fn run(a: BenchArgs) -> anyhow::Result<()> {
    if !a.json {
        println!(
            "{:<28} {:>10} {:>14} {:>12} {:>12} {:>10}",
            "file", "fit ms", "fit+resid ms", "viscous", "dry", "rmse"
        );
    }
    for f in &a.files {
        let doc = pantowatch::cli::read_trace(f)?;
        if doc.kind == Kind::Lift {
            bench_lift(&a, f, &doc)?;
            continue;
        }
        let (test, baseline) = doc
            .joint_test()
            .map_err(|e| anyhow::anyhow!("{}: {e}", f.display()))?;
        let opts = FitOptions::default();
        let (mut t_fit, mut t_all) = (Vec::new(), Vec::new());
        let mut last = None;
        for _ in 0..a.repeat.max(1) {
            let t0 = Instant::now();
            let fit =
                fit_base(&test, &opts).map_err(|e| anyhow::anyhow!("{}: {e}", f.display()))?;
            t_fit.push(t0.elapsed().as_secs_f64());
            let t0 = Instant::now();
            let _ =
                pantowatch_models::fit_joint_test(&test, &baseline, &Default::default(), "", &opts)
                    .map_err(|e| anyhow::anyhow!("{e}"))?;
            t_all.push(t0.elapsed().as_secs_f64());
            last = Some(fit);
        }
        let fit = last.expect("at least one run");
        let (s_fit, s_all) = (median(t_fit), median(t_all));
        if a.json {
            println!(
                "{}",
                json!({"file": f.display().to_string(), "kind": doc.kind.as_str(), "joint": baseline.joint, "viscous": fit.law.viscous, "dry": fit.law.dry,
                       "rmse": fit.rmse, "seconds_per_fit": s_fit, "seconds_with_residual": s_all, "fits": a.repeat.max(1), "iterations": fit.iterations, "evaluations": fit.evaluations})
            );
        } else {
            let name = f
                .file_name()
                .map_or(String::new(), |n| n.to_string_lossy().into_owned());
            println!(
                "{:<28} {:>10.2} {:>14.2} {:>12.6} {:>12.6} {:>10.5}",
                name,
                s_fit * 1e3,
                s_all * 1e3,
                fit.law.viscous,
                fit.law.dry,
                fit.rmse
            );
        }
    }
    Ok(())
}

/// One lift file: median time of `--repeat` fits (MAP identification + fit result).
fn bench_lift(a: &BenchArgs, f: &std::path::Path, doc: &TraceDoc) -> anyhow::Result<()> {
    let mut times = Vec::new();
    let mut last = None;
    for _ in 0..a.repeat.max(1) {
        let t0 = Instant::now();
        let rep = pantowatch::fitting::fit_lift(doc, &DriftThresholds::default())
            .map_err(|e| anyhow::anyhow!("{}: {e}", f.display()))?;
        times.push(t0.elapsed().as_secs_f64());
        last = Some(rep);
    }
    let rep = last.expect("at least one run");
    let s_fit = median(times);
    let j3 = rep.result.joints.iter().find(|j| j.joint == "J3");
    let (viscous, dry) = j3.map_or((f64::NAN, f64::NAN), |j| (j.viscous.value, j.dry.value));
    let samples = doc.channel("t_s").map_or(0, <[f64]>::len);
    if a.json {
        println!(
            "{}",
            json!({"file": f.display().to_string(), "kind": "lift", "joint": "J3", "viscous": viscous, "dry": dry,
                   "rmse": rep.result.rmse.value, "seconds_per_fit": s_fit, "seconds_with_residual": s_fit, "fits": a.repeat.max(1),
                   "iterations": rep.fit.iterations, "evaluations": rep.fit.evaluations, "samples": samples})
        );
    } else {
        let name = f
            .file_name()
            .map_or(String::new(), |n| n.to_string_lossy().into_owned());
        println!(
            "{:<28} {:>10.2} {:>14.2} {:>12.6} {:>12.6} {:>10.5}   (lift, {samples} samples, {} evaluations; J3)",
            name,
            s_fit * 1e3,
            s_fit * 1e3,
            viscous,
            dry,
            rep.result.rmse.value,
            rep.fit.evaluations
        );
    }
    Ok(())
}

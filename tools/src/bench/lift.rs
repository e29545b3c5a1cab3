//! Lift fit time per input-noise level (issue 15): raise-and-lower lifts — Table 4 and drifted
//! joints — with clean inputs, the stand's realistic sensor noise and twice it; p50 / p95 of one fit.
//!
//! Each lift is fitted once, on this thread (one core), the way the worker fits a job
//! (`fitting::fit_lift`); the documents are synthesised first and not timed.

use std::time::Instant;

use pantowatch_models::drift::DriftThresholds;
use serde_json::json;

use super::table::{Row, Sizes, median, quantile};
use pantowatch::cli::simulate::docs::{noisy_lift_doc, simulate_defaults};
use pantowatch::cli::simulate::{SimulateArgs, simulate_doc};

/// Target time of one lift fit on one core, s (issue 15: p50, on realistic and 2× noise).
pub const LIFT_TARGET_S: f64 = 0.3;

/// Input-noise levels: K × `LiftSensorNoise::realistic()` (`simulate --sensor-noise K`).
const LEVELS: [(f64, &str); 3] = [
    (0.0, "clean inputs"),
    (1.0, "realistic sensor noise"),
    (2.0, "2× sensor noise"),
];

/// Friction of the simulated pantograph, cycled over the lifts of a level: Table 4, J3 dry
/// ×1.8, J5 viscous ×2.5, J2 dry ×1.5 (`simulate --scale-joint`).
const CASES: [&[&str]; 4] = [&[], &["J3:dry=1.8"], &["J5:viscous=2.5"], &["J2:dry=1.5"]];

/// One row per noise level: p50 and p95 of `sizes.lift_seeds` lift fits; then the residual
/// loop's row against the realistic level's p50 ([`loop_row`]).
pub fn rows(sizes: &Sizes) -> Vec<Row> {
    let mut rows = level_rows(sizes);
    let plain_p50 = rows
        .iter()
        .find(|r| r.detail["sensor_noise_k"] == json!(1.0))
        .and_then(|r| r.value);
    rows.push(
        loop_row(sizes.lift_seeds, plain_p50)
            .unwrap_or_else(|e| Row::failed(LOOP_MEASURE, LOOP_TARGET, &format!("{e:#}"))),
    );
    rows
}

/// Most the residual loop may cost on a lift with an effect, × the plain lift fit (issue 16,
/// point 6).
pub const LOOP_TARGET_RATIO: f64 = 3.0;
const LOOP_MEASURE: &str = "fit: lift with an undeclared effect, whole residual loop";
const LOOP_TARGET: &str = "≤ 3× the plain fit of the same lift (p50, realistic noise)";

/// Lifts of the residual loop's row: an effect the plain model lacks (`simulate --effect`),
/// one with a joint drifted too; cycled over the row's lifts.
const LOOP_CASES: [(&str, &[&str]); 7] = [
    ("quadratic_drag:c_a=4", &[]),
    ("quadratic_drag:c_a=8", &["J3:dry=1.8"]),
    ("sensor_delay:delay_s=0.02", &[]),
    ("sensor_delay:delay_s=0.04", &[]),
    ("sensor_offset:offset=0.02", &[]),
    ("stribeck:ratio=1.2", &[]),
    // A heavy drive side (the size at which a compliant drive shows: README, lift effects).
    ("drive_compliance:inertia=5,stiffness=15000,damping=80", &[]),
];

/// The residual loop's cost (issue 16, point 6): `n` lifts with the stand's realistic noise, each
/// carrying one effect of [`LOOP_CASES`], fitted as the worker fits them (gate, vocabulary,
/// refits, held-out test), each against the plain model's fit of the same trace
/// (`fit_plain_lift`, timed just before); also against `plain_p50_s`, the realistic level's
/// plain-fit p50 on lifts without an effect.
fn loop_row(n: usize, plain_p50_s: Option<f64>) -> anyhow::Result<Row> {
    let th = DriftThresholds::default();
    let mut times = Vec::with_capacity(n);
    let mut ratios = Vec::with_capacity(n);
    let mut per = Vec::with_capacity(n);
    eprintln!("   fitting {n} lifts with an undeclared effect (residual loop)");
    for i in 0..n {
        let (effect, drift) = LOOP_CASES[i % LOOP_CASES.len()];
        let d = simulate_defaults()?;
        let args = SimulateArgs {
            kind: "lift".into(),
            protocol: "raise-and-lower".into(),
            scale_joints: drift.iter().map(|s| s.to_string()).collect(),
            effects: vec![effect.to_string()],
            h_noise_mm: 0.0,
            sensor_noise: 1.0,
            fs: 500.0,
            seed: 5100 + i as u64,
            serial: "160EC-BENCH".into(),
            trace_id: Some(format!("bench-loop-{i}")),
            ..d
        };
        let doc = simulate_doc(&args)?;
        // The plain model's fit of the same trace: what the lift costs without the loop.
        let channels = doc.lift_channels().map_err(|e| anyhow::anyhow!("{e}"))?;
        let t0 = Instant::now();
        pantowatch_models::lift::report::fit_plain_lift(&channels, &th)
            .map_err(|e| anyhow::anyhow!("plain lift fit ({effect}): {e}"))?;
        let plain_s = t0.elapsed().as_secs_f64();
        let t0 = Instant::now();
        let rep = pantowatch::fitting::fit_lift(&doc, &th)
            .map_err(|e| anyhow::anyhow!("lift fit ({effect}): {e}"))?;
        let s = t0.elapsed().as_secs_f64();
        times.push(s);
        ratios.push(s / plain_s);
        let res = &rep.result.residual;
        let named: Vec<&str> = res.effects.iter().map(|e| e.name.as_str()).collect();
        per.push(
            json!({"effect": effect, "drift": drift, "seconds": s, "plain_seconds": plain_s,
                        "verdict": res.verdict, "named": named}),
        );
    }
    let p50 = median(times.clone());
    let ratio = median(ratios.clone());
    let ratio_max = ratios.iter().copied().fold(0.0, f64::max);
    let by_effect = |prefix: &str| {
        median(
            per.iter()
                .filter(|p| p["effect"].as_str().is_some_and(|e| e.starts_with(prefix)))
                .filter_map(|p| p["seconds"].as_f64())
                .collect(),
        )
    };
    let (drag, delay) = (by_effect("quadratic_drag"), by_effect("sensor_delay"));
    let (offset, stribeck) = (by_effect("sensor_offset"), by_effect("stribeck"));
    let compliance = by_effect("drive_compliance");
    let named = per
        .iter()
        .filter(|p| {
            let effect = p["effect"].as_str().unwrap_or("");
            p["named"].as_array().is_some_and(|a| {
                a.iter()
                    .any(|n| n.as_str().is_some_and(|n| effect.starts_with(n)))
            })
        })
        .count();
    let clean = plain_p50_s.map_or(String::new(), |p| {
        format!("; {:.1}× a clean lift's plain fit ({p:.3} s)", p50 / p)
    });
    Ok(Row {
        measure: format!("{LOOP_MEASURE} ({n} lifts, realistic noise, one core)"),
        measured: format!(
            "**{ratio:.1}×** the same trace's plain fit (p50; max {ratio_max:.1}×); loop p50 \
             {p50:.3} s (drag {drag:.3} s, delay {delay:.3} s, offset {offset:.3} s, stribeck \
             {stribeck:.3} s, drive compliance {compliance:.3} s){clean}; {named}/{n} named right"
        ),
        target: LOOP_TARGET.into(),
        pass: Some(ratio <= LOOP_TARGET_RATIO),
        value: Some(ratio),
        unit: "×".into(),
        detail: json!({"ratio_p50": ratio, "ratio_max": ratio_max, "p50_s": p50,
                       "clean_plain_p50_s": plain_p50_s, "drag_p50_s": drag,
                       "delay_p50_s": delay, "offset_p50_s": offset, "stribeck_p50_s": stribeck,
                       "named_right": named, "lifts": per}),
    })
}

fn level_rows(sizes: &Sizes) -> Vec<Row> {
    LEVELS
        .iter()
        .map(|&(k, label)| {
            let measure = format!(
                "fit: lift, {label} ({} raise-and-lower lifts, one core)",
                sizes.lift_seeds
            );
            level(k, sizes.lift_seeds).unwrap_or_else(|e| {
                Row::failed(&measure, "≤ 0.3 s per lift (p50)", &format!("{e:#}"))
            })
        })
        .collect()
}

fn level(k: f64, n: usize) -> anyhow::Result<Row> {
    let label = LEVELS
        .iter()
        .find(|l| l.0 == k)
        .map_or("?", |l| l.1)
        .to_string();
    let docs = (0..n)
        .map(|i| {
            let case = CASES[i % CASES.len()];
            let doc = noisy_lift_doc(
                1000 * (k as u64) + 31 + i as u64,
                case,
                k,
                "160EC-BENCH",
                &format!("bench-lift-k{k}-{i}"),
            )?;
            Ok((case, doc))
        })
        .collect::<anyhow::Result<Vec<_>>>()?;
    eprintln!("   fitting {n} lifts, {label}");
    let th = DriftThresholds::default();
    let mut times = Vec::with_capacity(n);
    let mut per = Vec::with_capacity(n);
    for (case, doc) in &docs {
        let t0 = Instant::now();
        let rep = pantowatch::fitting::fit_lift(doc, &th)
            .map_err(|e| anyhow::anyhow!("lift fit ({}): {e}", case.join(" ")))?;
        let s = t0.elapsed().as_secs_f64();
        times.push(s);
        let flagged: Vec<&str> = rep
            .fit
            .joints
            .iter()
            .filter(|j| j.flagged())
            .map(|j| j.joint)
            .collect();
        let inp = rep.fit.inputs.first().copied().unwrap_or_default();
        per.push(
            json!({"case": case.join(" "), "seconds": s, "flagged": flagged,
                        "evaluations": rep.fit.evaluations,
                        "input_noise_sd": {"T_Nm": inp.torque.noise_sd, "Fs_N": inp.fs.noise_sd,
                                           "Fm_N": inp.fm.noise_sd}}),
        );
    }
    let (p50, p95) = (median(times.clone()), quantile(times.clone(), 0.95));
    let max = times.iter().copied().fold(0.0, f64::max);
    Ok(Row {
        measure: format!("fit: lift, {label} ({n} raise-and-lower lifts, one core)"),
        measured: format!("p50 **{p50:.3} s**, p95 {p95:.3} s, max {max:.3} s per lift"),
        target: "≤ 0.3 s per lift (p50)".into(),
        pass: Some(p50 <= LIFT_TARGET_S),
        value: Some(p50),
        unit: "s".into(),
        detail: json!({"sensor_noise_k": k, "p50_s": p50, "p95_s": p95, "max_s": max, "lifts": per}),
    })
}

//! Interval coverage and flags of lift fits on realistic-noise lifts (issue 15, point 2): each
//! lift has one joint's dry or viscous friction drifted (0.4–3×) or none; prints, per lift, the
//! informed parameters whose 95 % interval misses the truth and any flag on an undrifted joint.
//!
//! `cargo run --release -p pantowatch-models --example lift_coverage -- [SEEDS] [K] [FIRST]`
//! (seeds FIRST..FIRST+SEEDS, FIRST 0 by default: the README's set; 100 and up are fresh); the fit's
//! settings can be varied by `PW_DRAWS` (input-noise draws), `PW_ROBUST=1` (sandwich) and
//! `PW_SIGMA_H_M` (the σ_H floor), `PW_SCATTER` (undrifted joints spread about Table 4),
//! `PW_ROUNDS` (rounds of the designed moves instead of the raise and lower): how the README's coverage table was measured. Prints the
//! RMS of z = ln(estimate/truth)/relative sd (1 when calibrated).

use pantowatch_models::drift::Status;
use pantowatch_models::lift::dynamics::LiftModel;
use pantowatch_models::lift::geometry::builtin_160ec;
use pantowatch_models::lift::identify::{LiftFitOptions, fit_map};
use pantowatch_models::lift::input_noise::fleet_scatter;
use pantowatch_models::lift::protocol::{LiftProtocol, record};
use pantowatch_models::lift::sensitivity::LiftParam;
use pantowatch_models::lift::sensors::LiftSensorNoise;
use pantowatch_models::lift::simulate::SimOptions;

fn main() {
    let mut args = std::env::args().skip(1);
    let seeds: u64 = args.next().and_then(|s| s.parse().ok()).unwrap_or(2);
    let k: f64 = args.next().and_then(|s| s.parse().ok()).unwrap_or(1.0);
    let first: u64 = args.next().and_then(|s| s.parse().ok()).unwrap_or(0);
    let g = builtin_160ec();
    let base = LiftModel::new(g);
    // `PW_ROUNDS=N`: the designed moves (1.424 ↔ 1.216 m) repeated N rounds instead of the
    // raise and lower (`design::rounds_of_moves`; docs/VALIDATION.md, "Long protocols fit").
    let protocol = match std::env::var("PW_ROUNDS").ok().and_then(|s| s.parse().ok()) {
        Some(n) => {
            pantowatch_models::lift::design::rounds_of_moves(&base, g, &[1.424, 1.216], 1.0, 2.0, n)
                .unwrap()
        }
        None => LiftProtocol::raise_and_lower(&base, g).unwrap(),
    };
    let drifts = pantowatch_models::lift::input_noise::COVERAGE_DRIFTS;
    let (mut n, mut hit, mut false_flags) = (0, 0, 0);
    // z = ln(estimate / truth) / relative sd: sd(z) ≈ 1 when the intervals are calibrated.
    let mut zs: Vec<f64> = Vec::new();
    let mut opts = LiftFitOptions::default();
    if let Some(d) = std::env::var("PW_DRAWS").ok().and_then(|s| s.parse().ok()) {
        opts.input_noise_draws = d;
    }
    if let Ok(r) = std::env::var("PW_ROBUST") {
        opts.robust_covariance = r == "1";
    }
    if let Some(s) = std::env::var("PW_SIGMA_H_M")
        .ok()
        .and_then(|s| s.parse().ok())
    {
        opts.h_noise_m = s;
    }
    for seed in first..first + seeds {
        for d in &drifts {
            // `PW_SCATTER=s`: every coefficient first at Table 4 × exp(s·z) (`fleet_scatter`, a
            // fleet's spread, seeded per lift), the drift on top: no truth at the prior's mean.
            let mut m = match std::env::var("PW_SCATTER")
                .ok()
                .and_then(|s| s.parse().ok())
            {
                Some(s) => fleet_scatter(&base, &opts.friction_params, s, 77_000 + seed),
                None => base.clone(),
            };
            let mut drifted = None;
            if let Some((j, kind, f)) = d {
                let p = LiftParam::named(j, kind).unwrap();
                let mut off = 0.0;
                let v = p.get(&m, 0.0) * f;
                p.set(&mut m, &mut off, v);
                drifted = Some(p);
            }
            let mut truth_of = |p: LiftParam| p.get(&m, 0.0);
            let clean = record(&m, &protocol, &SimOptions::default()).unwrap();
            let rec = LiftSensorNoise::realistic()
                .scaled(k)
                .apply(&clean, 1000 + seed);
            let fit = fit_map(&base, &[rec.trace()], &opts);
            let Ok(fit) = fit else {
                println!("{d:?} seed {seed}: fit failed {:?}", fit.err());
                continue;
            };
            let mut misses = Vec::new();
            for e in fit.params.iter().filter(|e| e.informed) {
                let truth = if Some(e.param) == drifted {
                    e.param.get(&m, 0.0)
                } else {
                    truth_of(e.param)
                };
                n += 1;
                zs.push((e.value / truth).ln() / (e.posterior_sd / e.value));
                if e.ci95[0] <= truth && truth <= e.ci95[1] {
                    hit += 1;
                } else {
                    misses.push(format!(
                        "{}.{} {:.4} [{:.4}, {:.4}] truth {:.4}",
                        e.param.joint(),
                        e.param.kind(),
                        e.value,
                        e.ci95[0],
                        e.ci95[1],
                        truth
                    ));
                }
            }
            let relative = |p: LiftParam| p.get(&m, 0.0) / p.get(&base, 0.0);
            // A false flag: an entry without the drifted parameter flagged while its truth lies
            // inside the watch band (undrifted, every truth is 1; with `PW_SCATTER` a joint the
            // fleet's spread put outside the band may be flagged rightly).
            let w = opts.thresholds.watch;
            let inside = |level: f64| w[0] < level && level < w[1];
            let flagged = |s: Status| matches!(s, Status::Watch | Status::Alarm);
            false_flags += fit
                .combinations
                .iter()
                .filter(|c| {
                    flagged(c.status)
                        && drifted.is_none_or(|p| !c.params.contains(&p))
                        && inside(c.level_of(relative))
                })
                .count();
            false_flags += fit
                .params
                .iter()
                .filter(|e| {
                    e.informed
                        && flagged(e.status)
                        && Some(e.param) != drifted
                        && inside(relative(e.param))
                })
                .count();
            for c in fit.combinations.iter().filter(|c| c.informed) {
                let truth = c.level_of(relative);
                n += 1;
                zs.push((c.value / truth).ln() / (c.posterior_sd / c.value));
                if c.ci95[0] <= truth && truth <= c.ci95[1] {
                    hit += 1;
                } else {
                    misses.push(format!(
                        "{} {:.4} [{:.4}, {:.4}] truth {:.4}",
                        c.label(),
                        c.value,
                        c.ci95[0],
                        c.ci95[1],
                        truth
                    ));
                }
            }
            let combos: Vec<String> = fit
                .combinations
                .iter()
                .map(|c| {
                    format!(
                        "{} w{:.2?} {:.3} [{:.3},{:.3}] {:?}",
                        c.label(),
                        c.weights,
                        c.value,
                        c.ci95[0],
                        c.ci95[1],
                        c.status
                    )
                })
                .collect();
            let flags: Vec<String> = fit
                .joints
                .iter()
                .filter(|j| matches!(j.status, Status::Watch | Status::Alarm))
                .map(|j| format!("{}:{:?}", j.joint, j.status))
                .collect();
            let _ = &mut truth_of;
            println!(
                "{:<22} seed {seed}: evals {:>3}  flags {:?}  combos {:?}  misses {:?}",
                format!("{d:?}"),
                fit.evaluations,
                flags,
                combos,
                misses
            );
        }
    }
    let rms_z = (zs.iter().map(|z| z * z).sum::<f64>() / zs.len().max(1) as f64).sqrt();
    println!("RMS z over the reported entries {rms_z:.3} (1 = calibrated; < 1 = too wide)");
    println!(
        "coverage {hit}/{n} = {:.1} %, false flags (undrifted entries, truth inside the watch band) {false_flags}",
        100.0 * hit as f64 / n.max(1) as f64
    );
}

//! Where a fleet year's lift-fit time goes (issue 15, point 1): realistic-noise raise-and-lower
//! lifts like the bench suite's fleet (every sixth pantograph's J3 dry worn toward 1.8×), each
//! fitted as the worker fits a lift (`lift::report::fit_lift_trace`: the plain fit, and the
//! effects loop where the residual exceeds `EFFECT_TRY_RATIO`) on one core; prints the time
//! share of the lifts whose loop ran, and the p50/p95.
//!
//! `cargo run --release -p pantowatch-models --example lift_fleet_profile -- [LIFTS]`
use std::time::Instant;

use pantowatch_models::drift::DriftThresholds;
use pantowatch_models::lift::dynamics::LiftModel;
use pantowatch_models::lift::geometry::builtin_160ec;
use pantowatch_models::lift::protocol::{LiftProtocol, record};
use pantowatch_models::lift::report::{LiftChannels, fit_lift_trace};
use pantowatch_models::lift::residual::EFFECT_TRY_RATIO;
use pantowatch_models::lift::sensitivity::LiftParam;
use pantowatch_models::lift::sensors::LiftSensorNoise;
use pantowatch_models::lift::simulate::SimOptions;

fn main() {
    let lifts: usize = std::env::args()
        .nth(1)
        .and_then(|s| s.parse().ok())
        .unwrap_or(120);
    let g = builtin_160ec();
    let base = LiftModel::new(g);
    let protocol = LiftProtocol::raise_and_lower(&base, g).unwrap();
    let j3 = LiftParam::named("J3", "dry").unwrap();
    let th = DriftThresholds::default();
    let (mut times, mut looped) = (Vec::new(), Vec::new());
    let (mut evals, mut iters, mut rejected, mut cliffs) = (0usize, 0usize, 0usize, 0usize);
    for i in 0..lifts {
        let (p, month) = (i / 12, i % 12);
        let factor = if p % 6 == 1 {
            1.0 + 0.8 * month as f64 / 11.0
        } else {
            1.0
        };
        let mut m = base.clone();
        let mut off = 0.0;
        j3.set(&mut m, &mut off, j3.get(&base, 0.0) * factor);
        let clean = record(&m, &protocol, &SimOptions::default()).unwrap();
        let rec = LiftSensorNoise::realistic().apply(&clean, (i as u64) * 7 + 3);
        let ch = LiftChannels::from(&rec);
        let t0 = Instant::now();
        let rep = fit_lift_trace(&ch, &th, "x").unwrap();
        let dt = t0.elapsed().as_secs_f64();
        let ratio = rep.result.residual.excess_ratio.unwrap_or(f64::NAN);
        let tried = rep.result.residual.holdout_note.is_none();
        times.push(dt);
        evals += rep.fit.evaluations;
        iters += rep.fit.iterations;
        rejected += rep.fit.rejected;
        cliffs += rep.fit.cliffs;
        looped.push(tried);
        if tried {
            println!(
                "lift {i}: {dt:.3} s, loop ran (plain ratio {ratio:.2}), effects {:?}",
                rep.result
                    .residual
                    .effects
                    .iter()
                    .map(|e| e.name.clone())
                    .collect::<Vec<_>>()
            );
        }
    }
    let total: f64 = times.iter().sum();
    let in_loop: f64 = times
        .iter()
        .zip(&looped)
        .filter(|(_, l)| **l)
        .map(|(t, _)| t)
        .sum();
    let mut s = times.clone();
    s.sort_by(f64::total_cmp);
    println!(
        "{lifts} lifts: {total:.1} s ({:.3} s mean, p50 {:.3}, p95 {:.3}); loop ran on {} lifts, {:.0} % of the time (try ratio {EFFECT_TRY_RATIO})",
        total / lifts as f64,
        s[lifts / 2],
        s[lifts * 95 / 100],
        looped.iter().filter(|l| **l).count(),
        100.0 * in_loop / total
    );
    println!(
        "LM of the plain fits: {:.1} evaluations and {:.1} iterations per lift; {:.1} evaluated trials rejected, {:.1} of them cliffs",
        evals as f64 / lifts as f64,
        iters as f64 / lifts as f64,
        rejected as f64 / lifts as f64,
        cliffs as f64 / lifts as f64
    );
}

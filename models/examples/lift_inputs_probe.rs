//! Measures what sensor noise on a lift's inputs costs a fit, with and without the input
//! reconstruction (`lift::inputs`): evaluations, iterations, right-hand sides, time, J3 dry.
//!
//! `cargo run --release -p pantowatch-models --example lift_inputs_probe -- [SEEDS] [CUTOFF_HZ]
//! [raw|-] [MAX_STEPS] [K]`: raise-and-lower lifts (Table 4, J3 dry ×1.8) with 0, 1 and 2 ×
//! the stand's sensor noise over SEEDS seeds; `raw` adds one fit per level on the inputs as
//! recorded; MAX_STEPS sets the integrator's step limit; K runs that noise level only.

use std::time::Instant;

use pantowatch_models::lift::dynamics::LiftModel;
use pantowatch_models::lift::geometry::builtin_160ec;
use pantowatch_models::lift::identify::{LiftFitOptions, fit_map};
use pantowatch_models::lift::inputs::reconstruct;
use pantowatch_models::lift::protocol::{LiftProtocol, record};
use pantowatch_models::lift::sensitivity::{LiftParam, simulate_sensitivities};
use pantowatch_models::lift::sensors::LiftSensorNoise;
use pantowatch_models::lift::simulate::SimOptions;
use pantowatch_models::lift::topology::RevJoint;

fn main() {
    let mut args = std::env::args().skip(1);
    let seeds: u64 = args.next().and_then(|s| s.parse().ok()).unwrap_or(3);
    let cutoff: f64 = args.next().and_then(|s| s.parse().ok()).unwrap_or(20.0);
    let raw_too = args.next().as_deref() == Some("raw");
    let max_steps: Option<usize> = args.next().and_then(|s| s.parse().ok());
    let only: Option<f64> = args.next().and_then(|s| s.parse().ok());
    let g = builtin_160ec();
    let base = LiftModel::new(g);
    let protocol = LiftProtocol::raise_and_lower(&base, g).unwrap();
    let j3 = LiftParam::named("J3", "dry").unwrap();
    println!("cutoff {cutoff} Hz");
    println!(
        "noise  j3x  seed recon  evals iters  rhs_one_eval  time_s  j3dry/truth  sd_T sd_Fs sd_Fm"
    );
    for k in [0.0, 1.0, 2.0] {
        if only.is_some_and(|o| o != k) {
            continue;
        }
        for factor in [1.0, 1.8] {
            let mut m = base.clone();
            m.friction.dry_mu[RevJoint::J3.index()] *= factor;
            let clean = record(&m, &protocol, &SimOptions::default()).unwrap();
            for seed in 0..seeds {
                let rec = LiftSensorNoise::realistic()
                    .scaled(k)
                    .apply(&clean, 100 + seed);
                let rec = if k == 0.0 { clean.clone() } else { rec };
                for on in [true, false] {
                    if !on && (!raw_too || k == 0.0 || seed > 0) {
                        continue;
                    }
                    let mut opts = LiftFitOptions::default();
                    opts.inputs.enabled = on;
                    opts.inputs.cutoff_hz = cutoff;
                    if let Some(n) = max_steps {
                        opts.sim.max_steps = n;
                    }
                    let r = reconstruct(&rec.inputs(), &opts.inputs).unwrap();
                    let one = simulate_sensitivities(&base, &r.inputs(), &[j3], 0.0, &opts.sim)
                        .map_or_else(
                            |e| {
                                eprintln!("baseline run: {e}");
                                (0, 0)
                            },
                            |o| (o.rhs_evaluations, o.steps),
                        );
                    let tr = rec.trace();
                    let t0 = Instant::now();
                    let fit = fit_map(&base, &[tr], &opts).unwrap();
                    let dt = t0.elapsed().as_secs_f64();
                    let est = fit.params.iter().find(|p| p.param == j3).unwrap();
                    let i = &fit.inputs[0];
                    println!(
                        "{k:>4} {factor:>4} {seed:>5} {on:>5} {:>6} {:>5} {:>13} {dt:>7.3} {:>7.3} [{:.2},{:.2}] {} {:.3} {:.3} {:.3}",
                        fit.evaluations,
                        fit.iterations,
                        format!("{}/{}", one.0, one.1),
                        est.map_value / est.baseline / factor,
                        est.ci95[0] / est.baseline,
                        est.ci95[1] / est.baseline,
                        fit.joints
                            .iter()
                            .find(|j| j.joint == "J3")
                            .unwrap()
                            .flagged(),
                        i.torque.noise_sd,
                        i.fs.noise_sd,
                        i.fm.noise_sd,
                    );
                }
            }
        }
    }
}

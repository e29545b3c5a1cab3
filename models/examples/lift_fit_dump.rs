//! Every lift-fit answer in full precision, to diff two builds: realistic- and 2×-noise
//! raise-and-lower lifts (every third at Table 4, the others one coefficient drifted 0.4, 1.8 or
//! 3×), each fitted with [`LiftFitOptions::default`]; stdout carries per lift the termination,
//! RMSE and every parameter's and combination's value, sd and status, stderr the LM's
//! evaluations. Session 16 checked the LM's unevaluated rejections with it (docs/PERFORMANCE.md,
//! "Session 16"): `diff` of two builds' stdout over 96 lifts was empty.
//!
//! `cargo run --release -p pantowatch-models --example lift_fit_dump -- [LIFTS] > fits.txt`
use std::time::Instant;

use pantowatch_models::lift::dynamics::LiftModel;
use pantowatch_models::lift::fit::LiftFitOptions;
use pantowatch_models::lift::geometry::builtin_160ec;
use pantowatch_models::lift::identify::fit_map;
use pantowatch_models::lift::protocol::{LiftProtocol, record};
use pantowatch_models::lift::sensors::LiftSensorNoise;
use pantowatch_models::lift::simulate::SimOptions;

fn main() {
    let lifts: usize = std::env::args()
        .nth(1)
        .and_then(|s| s.parse().ok())
        .unwrap_or(24);
    let g = builtin_160ec();
    let base = LiftModel::new(g);
    let protocol = LiftProtocol::raise_and_lower(&base, g).unwrap();
    let opts = LiftFitOptions::default();
    let params = &opts.friction_params;
    let (mut evaluations, mut seconds) = (0usize, 0.0f64);
    for i in 0..lifts {
        let seed = i as u64;
        let mut m = base.clone();
        if i % 3 != 0 {
            let p = params[(i * 7) % params.len()];
            let factor = [0.4, 1.8, 3.0][i % 3];
            let mut offset_nm = 0.0;
            p.set(&mut m, &mut offset_nm, p.get(&base, 0.0) * factor);
        }
        let clean = record(&m, &protocol, &SimOptions::default()).unwrap();
        let mut noise = LiftSensorNoise::realistic();
        if i % 2 == 1 {
            noise = noise.scaled(2.0);
        }
        let rec = noise.apply(&clean, seed * 13 + 5);
        let trace = rec.trace();
        let t0 = Instant::now();
        let fit = fit_map(&base, &[trace], &opts).unwrap();
        seconds += t0.elapsed().as_secs_f64();
        evaluations += fit.evaluations;
        let params: Vec<String> = fit
            .params
            .iter()
            .map(|p| format!("{:e}/{:e}/{:?}", p.value, p.posterior_sd, p.status))
            .collect();
        let combinations: Vec<String> = fit
            .combinations
            .iter()
            .map(|c| format!("{:e}/{:e}/{:?}", c.value, c.posterior_sd, c.status))
            .collect();
        println!(
            "lift {i}: {:?} rmse {:e} | {} | {}",
            fit.termination,
            fit.rmse_m[0],
            params.join(" "),
            combinations.join(" ")
        );
        eprintln!(
            "lift {i}: {} evaluations, {} iterations",
            fit.evaluations, fit.iterations
        );
    }
    eprintln!(
        "{lifts} lifts: {:.1} evaluations and {:.3} s per fit",
        evaluations as f64 / lifts as f64,
        seconds / lifts as f64
    );
}

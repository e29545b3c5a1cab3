//! The lift fit's objective along one line: the posterior's regression line through J3 dry
//! (every parameter moved by its posterior correlation with J3 dry × its sd, so k = ±1 is
//! one posterior sd), at the fit's integrator tolerance and at tight ones. Shows (1) the
//! evaluation noise of adaptive steps at the fit's tolerance (why `LmOptions::noise_sd`) and
//! (2) how the true curvature compares with the Gauss–Newton one the intervals use.
//!
//! `cargo run --release -p pantowatch-models --example lift_noise_scan -- [SEED]`: one
//! raise-and-lower lift at Table 4 with the stand's realistic noise on every channel.

use pantowatch_models::lift::dynamics::LiftModel;
use pantowatch_models::lift::geometry::builtin_160ec;
use pantowatch_models::lift::identify::{LiftFitOptions, fit_map};
use pantowatch_models::lift::inputs::reconstruct;
use pantowatch_models::lift::protocol::{LiftProtocol, record};
use pantowatch_models::lift::sensitivity::{LiftParam, simulate_sensitivities};
use pantowatch_models::lift::sensors::LiftSensorNoise;
use pantowatch_models::lift::simulate::SimOptions;

fn main() {
    let seed: u64 = std::env::args()
        .nth(1)
        .and_then(|s| s.parse().ok())
        .unwrap_or(0);
    let g = builtin_160ec();
    let base = LiftModel::new(g);
    let protocol = LiftProtocol::raise_and_lower(&base, g).unwrap();
    let clean = record(&base, &protocol, &SimOptions::default()).unwrap();
    let rec = LiftSensorNoise::realistic().apply(&clean, 500 + seed);
    let opts = LiftFitOptions::default();
    let trace = rec.trace();
    let fit = fit_map(&base, &[trace], &opts).unwrap();
    let inputs = reconstruct(&rec.inputs(), &opts.inputs).unwrap();
    let j3 = LiftParam::named("J3", "dry").unwrap();
    let i3 = fit.params.iter().position(|p| p.param == j3).unwrap();
    let corr = &fit.posterior_correlation;
    let pf = fit.params.len();
    let e = &fit.params[i3];
    println!(
        "J3 dry MAP {:.4} (× Table 4 {:.3}), posterior sd {:.4}",
        e.map_value,
        e.map_value / e.baseline,
        e.posterior_sd
    );
    // The model and torque offset k posterior sd along the regression line.
    let at = |k: f64| {
        let mut m = base.clone();
        for (i, p) in fit.params.iter().enumerate() {
            let mut unused = 0.0;
            let v = p.map_value + k * corr[(i, i3)] * p.posterior_sd;
            p.param.set(&mut m, &mut unused, v);
        }
        let o = &fit.offsets[0];
        (m, o.map_value + k * corr[(pf, i3)] * o.posterior_sd)
    };
    let sigma = opts.h_noise_m;
    let cost = |k: f64, sim: &SimOptions| {
        let (m, off) = at(k);
        simulate_sensitivities(&m, &inputs.inputs(), &[j3], off, sim)
            .map(|run| {
                0.5 * run
                    .strip_height_m
                    .iter()
                    .zip(&rec.strip_height_m)
                    .map(|(a, b)| ((a - b) / sigma).powi(2))
                    .sum::<f64>()
            })
            .unwrap_or(f64::NAN)
    };
    // The Gauss–Newton curvature along the line: ½|∂H/∂k|²/σ² from the sensitivities.
    let (m0, o0) = at(0.0);
    let mut params: Vec<LiftParam> = fit.params.iter().map(|p| p.param).collect();
    params.push(LiftParam::TorqueOffset);
    let tight = SimOptions {
        rtol: 1e-8,
        atol: 1e-10,
        h_max_s: 0.01,
        ..Default::default()
    };
    let run = simulate_sensitivities(&m0, &inputs.inputs(), &params, o0, &tight).unwrap();
    let p = params.len();
    let step: Vec<f64> = (0..p)
        .map(|i| {
            if i < pf {
                corr[(i, i3)] * fit.params[i].posterior_sd
            } else {
                corr[(pf, i3)] * fit.offsets[0].posterior_sd
            }
        })
        .collect();
    let gn: f64 = (0..run.strip_height_m.len())
        .map(|k| {
            let d: f64 = (0..p).map(|i| run.d_height[k * p + i] * step[i]).sum();
            (d / sigma).powi(2)
        })
        .sum::<f64>()
        * 0.5;
    println!("Gauss–Newton: the data cost rises by {gn:.2}·k² along the line");
    println!("   k   cost at the fit's rtol 1e-5   cost at rtol 1e-8");
    for i in -8..=8 {
        let k = i as f64 * 0.25;
        println!(
            "{k:+.2}   {:>12.2}   {:>12.2}",
            cost(k, &opts.sim),
            cost(k, &tight)
        );
    }
}

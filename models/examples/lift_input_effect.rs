//! How far the inputs' sensor noise moves a lift's simulated H (issue 15): the model run on
//! the clean record's inputs against the same inputs with the stand's noise, reconstructed.
//! `cargo run --release -p pantowatch-models --example lift_input_effect -- [SEEDS]`
use pantowatch_models::lift::dynamics::LiftModel;
use pantowatch_models::lift::geometry::builtin_160ec;
use pantowatch_models::lift::identify::LiftFitOptions;
use pantowatch_models::lift::inputs::reconstruct;
use pantowatch_models::lift::protocol::{LiftProtocol, record};
use pantowatch_models::lift::sensitivity::simulate_sensitivities;
use pantowatch_models::lift::sensors::LiftSensorNoise;
use pantowatch_models::lift::simulate::SimOptions;

fn main() {
    let seeds: u64 = std::env::args()
        .nth(1)
        .and_then(|s| s.parse().ok())
        .unwrap_or(5);
    let g = builtin_160ec();
    let m = LiftModel::new(g);
    let p = LiftProtocol::raise_and_lower(&m, g).unwrap();
    let clean = record(&m, &p, &SimOptions::default()).unwrap();
    let opts = LiftFitOptions::default();
    let run = |u: &pantowatch_models::lift::simulate::LiftInputs| {
        simulate_sensitivities(&m, u, &[], 0.0, &opts.sim)
            .unwrap()
            .strip_height_m
    };
    let h_clean_rec = run(&clean.inputs());
    let rc = reconstruct(&clean.inputs(), &opts.inputs).unwrap();
    let h_clean_recon = run(&rc.inputs());
    let rms = |a: &[f64], b: &[f64]| {
        (a.iter().zip(b).map(|(x, y)| (x - y).powi(2)).sum::<f64>() / a.len() as f64).sqrt()
    };
    println!(
        "model vs record H: {:.2} mm; clean reconstructed vs clean {:.2} mm",
        rms(&h_clean_rec, &clean.strip_height_m) * 1e3,
        rms(&h_clean_recon, &h_clean_rec) * 1e3
    );
    for seed in 0..seeds {
        let mut noise = LiftSensorNoise::realistic();
        noise.h_sd_m = 0.0;
        let rec = noise.apply(&clean, 500 + seed);
        let r = reconstruct(&rec.inputs(), &opts.inputs).unwrap();
        let h = run(&r.inputs());
        let mut noq = noise;
        noq.h_step_m = 0.0;
        noq.torque_step_nm = 0.0;
        noq.force_step_n = 0.0;
        let rec2 = noq.apply(&clean, 500 + seed);
        let r2 = reconstruct(&rec2.inputs(), &opts.inputs).unwrap();
        let h2 = run(&r2.inputs());
        let k = h.len() - 1;
        println!(
            "seed {seed}: ΔH rms {:.2} mm (end {:.2} mm), no logger steps {:.2} mm; info {:?}",
            rms(&h, &h_clean_recon) * 1e3,
            (h[k] - h_clean_recon[k]) * 1e3,
            rms(&h2, &h_clean_recon) * 1e3,
            r.info
        );
    }
}

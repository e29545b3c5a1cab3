use pantowatch_models::lift::dynamics::LiftModel;
use pantowatch_models::lift::geometry::builtin_160ec;
use pantowatch_models::lift::identify::{LiftFitOptions, LiftTrace, fit_map};
use pantowatch_models::lift::protocol::{LiftProtocol, record};
use pantowatch_models::lift::sensitivity::LiftParam;
use pantowatch_models::lift::sensors::LiftSensorNoise;
use pantowatch_models::lift::simulate::SimOptions;

fn main() {
    let g = builtin_160ec();
    let m = LiftModel::new(g);
    let p = LiftProtocol::raise_and_lower(&m, g).unwrap();
    let clean = record(&m, &p, &SimOptions::default()).unwrap();
    let j3 = LiftParam::named("J3", "dry").unwrap();
    for seed in 0..4u64 {
        let mut line = format!("seed {seed}:");
        for k in [0.0, 0.125, 0.25, 0.5, 1.0, 2.0] {
            let noise = LiftSensorNoise {
                h_sd_m: 0.0,
                h_step_m: 0.0,
                torque_step_nm: 0.0,
                force_step_n: 0.0,
                ..LiftSensorNoise::realistic().scaled(k)
            };
            let rec = noise.apply(&clean, 7000 + seed);
            let mut opts = LiftFitOptions::default();
            opts.input_noise_draws = std::env::var("D")
                .ok()
                .and_then(|s| s.parse().ok())
                .unwrap_or(0);
            let fit = fit_map(
                &m,
                &[LiftTrace {
                    inputs: rec.inputs(),
                    strip_height_m: &rec.strip_height_m,
                }],
                &opts,
            )
            .unwrap();
            let e = fit.params.iter().find(|e| e.param == j3).unwrap();
            line += &format!(
                " k{k}: {:+.4} sd {:.4} off {:+.3} rmse {:.2}mm |",
                e.map_value / e.baseline - 1.0,
                e.posterior_sd / e.baseline,
                fit.offsets[0].map_value,
                fit.rmse_m[0] * 1e3
            );
        }
        println!("{line}");
    }
}

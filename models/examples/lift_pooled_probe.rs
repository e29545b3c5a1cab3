//! Residual of pooled lift fits (issue 16): three realistic-noise raise-and-lower lifts of one
//! Table 4 pantograph fitted together, against each fitted alone — H RMSE per trace and the
//! residual's excess over the noise floor, to tell whether pooling leaves a model error.
//!
//! `cargo run --release -p pantowatch-models --example lift_pooled_probe -- [SETS]`
use pantowatch_models::lift::dynamics::LiftModel;
use pantowatch_models::lift::geometry::builtin_160ec;
use pantowatch_models::lift::identify::{LiftFitOptions, LiftTrace, fit_map};
use pantowatch_models::lift::protocol::{LiftProtocol, record};
use pantowatch_models::lift::sensors::LiftSensorNoise;
use pantowatch_models::lift::simulate::SimOptions;

fn main() {
    let sets: u64 = std::env::args()
        .nth(1)
        .and_then(|s| s.parse().ok())
        .unwrap_or(3);
    let g = builtin_160ec();
    let m = LiftModel::new(g);
    let p = LiftProtocol::raise_and_lower(&m, g).unwrap();
    let clean = record(&m, &p, &SimOptions::default()).unwrap();
    let opts = LiftFitOptions::default();
    for set in 0..sets {
        let recs: Vec<_> = (0..3)
            .map(|k| LiftSensorNoise::realistic().apply(&clean, 40 + 3 * set + k))
            .collect();
        let traces: Vec<LiftTrace> = recs.iter().map(|r| r.trace()).collect();
        let pooled = fit_map(&m, &traces, &opts).unwrap();
        let alone: Vec<f64> = traces
            .iter()
            .map(|t| fit_map(&m, std::slice::from_ref(t), &opts).unwrap().rmse_m[0])
            .collect();
        println!(
            "set {set}: pooled RMSE {:?} mm ({} evals, {:?}); alone {:?} mm; offsets {:?}",
            pooled
                .rmse_m
                .iter()
                .map(|v| (v * 1e4).round() / 10.0)
                .collect::<Vec<_>>(),
            pooled.evaluations,
            pooled.termination,
            alone
                .iter()
                .map(|v| (v * 1e4).round() / 10.0)
                .collect::<Vec<_>>(),
            pooled
                .offsets
                .iter()
                .map(|o| (o.map_value * 100.0).round() / 100.0)
                .collect::<Vec<_>>()
        );
    }
}

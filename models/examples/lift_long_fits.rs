//! Long protocols fitted as the service fits them (session 18): lifts of 2, 4 and 6 rounds of
//! the designed moves (`design::rounds_of_moves`, 1.424 ↔ 1.216 m, τ 1 s, 2 s dwells), Table 4
//! and J1 dry ×3, the stand's noise, seeds 6000–6002; each through `fit_lift_trace` (the plain
//! fit and the residual loop). Prints time, residual ratio, verdict, named effects and flags.
//!
//! `cargo run --release -p pantowatch-models --example lift_long_fits`
use pantowatch_models::drift::{DriftThresholds, Status};
use pantowatch_models::lift::design::rounds_of_moves;
use pantowatch_models::lift::dynamics::LiftModel;
use pantowatch_models::lift::geometry::builtin_160ec;
use pantowatch_models::lift::protocol::record;
use pantowatch_models::lift::report::{LiftChannels, fit_lift_trace};
use pantowatch_models::lift::sensitivity::LiftParam;
use pantowatch_models::lift::sensors::LiftSensorNoise;
fn main() {
    let g = builtin_160ec();
    let m = LiftModel::new(g);
    let th = DriftThresholds::default();
    let j1 = LiftParam::named("J1", "dry").unwrap();
    for rounds in [2usize, 4, 6] {
        let p = rounds_of_moves(&m, g, &[1.424, 1.216], 1.0, 2.0, rounds).unwrap();
        for f in [1.0, 3.0] {
            let mut w = m.clone();
            let mut off = 0.0;
            j1.set(&mut w, &mut off, f * j1.get(&m, 0.0));
            let clean = record(&w, &p, &Default::default()).unwrap();
            for seed in 6000..6003u64 {
                let rec = LiftSensorNoise::realistic().apply(&clean, seed);
                let t0 = std::time::Instant::now();
                match fit_lift_trace(&LiftChannels::from(&rec), &th, "x") {
                    Ok(r) => {
                        let flags: Vec<String> = r
                            .result
                            .joints
                            .iter()
                            .filter(|j| !matches!(j.status, Status::Ok | Status::Unknown))
                            .map(|j| format!("{} {:?}", j.joint, j.status))
                            .collect();
                        let effects: Vec<String> = r
                            .result
                            .residual
                            .effects
                            .iter()
                            .map(|e| format!("{:?}", e.name))
                            .collect();
                        println!(
                            "{rounds} rounds J1x{f} seed {seed}: {:.2} s ratio {:.2} verdict {:?} effects {:?} flags {:?} rmse {:.2} mm",
                            t0.elapsed().as_secs_f64(),
                            r.result.residual.excess_ratio.unwrap_or(f64::NAN),
                            r.result.residual.verdict,
                            effects,
                            flags,
                            r.result.rmse.value * 1e3
                        );
                    }
                    Err(e) => println!("{rounds} rounds J1x{f} seed {seed}: error {e}"),
                }
            }
        }
    }
}

//! Residual structure of lift fits (issue 16): on realistic-noise lifts of the model itself
//! (drifts or none) against lifts with an undeclared sensor fault on H (zero offset, delay).
//! Prints, per lift, the residual RMS over the noise estimated from its first differences,
//! Ljung–Box Q over 20 lags on the residual decimated to 50 Hz, and the flags.
//!
//! `cargo run --release -p pantowatch-models --example lift_residual_probe -- [SEEDS]`
use pantowatch_models::drift::Status;
use pantowatch_models::lift::dynamics::LiftModel;
use pantowatch_models::lift::geometry::builtin_160ec;
use pantowatch_models::lift::identify::{LiftFitOptions, fit_map};
use pantowatch_models::lift::protocol::{LiftProtocol, record};
use pantowatch_models::lift::sensitivity::LiftParam;
use pantowatch_models::lift::sensors::LiftSensorNoise;
use pantowatch_models::lift::simulate::SimOptions;
use pantowatch_models::residual::{ljung_box, noise_sigma};

fn main() {
    let seeds: u64 = std::env::args()
        .nth(1)
        .and_then(|s| s.parse().ok())
        .unwrap_or(2);
    let g = builtin_160ec();
    let base = LiftModel::new(g);
    let protocol = LiftProtocol::raise_and_lower(&base, g).unwrap();
    let drifts = pantowatch_models::lift::input_noise::COVERAGE_DRIFTS;
    let faults: [(&str, f64); 5] = [
        ("none", 0.0),
        ("offset_mm", 2.0),
        ("offset_mm", 5.0),
        ("delay_ms", 20.0),
        ("delay_ms", 50.0),
    ];
    for seed in 0..seeds {
        for (fi, (fault, size)) in faults.iter().enumerate() {
            let ds: Vec<_> = if fi == 0 { drifts.to_vec() } else { vec![None] };
            for d in ds {
                let mut m = base.clone();
                if let Some((j, kind, f)) = d {
                    let p = LiftParam::named(j, kind).unwrap();
                    let mut off = 0.0;
                    p.set(&mut m, &mut off, p.get(&base, 0.0) * f);
                }
                let clean = record(&m, &protocol, &SimOptions::default()).unwrap();
                let k: f64 = std::env::var("K")
                    .ok()
                    .and_then(|s| s.parse().ok())
                    .unwrap_or(1.0);
                let mut rec = LiftSensorNoise::realistic()
                    .scaled(k)
                    .apply(&clean, 1000 + seed);
                match *fault {
                    "offset_mm" => rec
                        .strip_height_m
                        .iter_mut()
                        .for_each(|h| *h += size * 1e-3),
                    "delay_ms" => {
                        let k = (size * 1e-3 * protocol.sample_hz).round() as usize;
                        let h = rec.strip_height_m.clone();
                        for i in 0..h.len() {
                            rec.strip_height_m[i] = h[i.saturating_sub(k)];
                        }
                    }
                    _ => {}
                }
                let fit = fit_map(&base, &[rec.trace()], &LiftFitOptions::default()).unwrap();
                let r: Vec<f64> = fit.fitted_height_m[0]
                    .iter()
                    .zip(&rec.strip_height_m)
                    .map(|(a, b)| b - a)
                    .collect();
                let rms = (r.iter().map(|v| v * v).sum::<f64>() / r.len() as f64).sqrt();
                let sig = noise_sigma(&r);
                let floored = rms / sig.max(LiftFitOptions::default().h_noise_m);
                let dec: Vec<f64> = r
                    .chunks(10)
                    .map(|c| c.iter().sum::<f64>() / c.len() as f64)
                    .collect();
                let q = ljung_box(&dec, 20);
                let flags: Vec<String> = fit
                    .joints
                    .iter()
                    .filter(|j| matches!(j.status, Status::Watch | Status::Alarm))
                    .map(|j| format!("{}:{:?}", j.joint, j.status))
                    .chain(
                        fit.combinations
                            .iter()
                            .filter(|c| matches!(c.status, Status::Watch | Status::Alarm))
                            .map(|c| format!("{}:{:?}", c.label(), c.status)),
                    )
                    .collect();
                println!(
                    "{fault:>9} {size:>4} {:<24} seed {seed}: rms {:.3} mm sigma {:.3} mm ratio {:.2} floored {floored:.2} Q50Hz {:>8.1} flags {:?}",
                    format!("{d:?}"),
                    rms * 1e3,
                    sig * 1e3,
                    rms / sig,
                    q,
                    flags
                );
            }
        }
    }
}

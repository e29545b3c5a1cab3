//! Issue 16's score on simulated lifts: each lift carries at most one effect the plain model
//! lacks (or a joint drift, or nothing), the stand's realistic sensor noise on every channel,
//! and goes through the whole lift pipeline (`fit_lift_trace`: gate, vocabulary, refit).
//! Prints per lift the verdict, the named effects, RMSE before/after and any flagged joint.
//!
//! `cargo run --release -p pantowatch-models --example lift_effects_probe -- [SEEDS] [CASE…]`
//! (cases: `clean`, `drag:<c_a N/(m/s)²>`, `delay:<ms>`, `offset:<mm>`, `gain:<%>`,
//! `stribeck:<μs/μk − 1>` at `$STRIBECK_JOINT` (J3) with `$STRIBECK_VS` rad/s, `band:<factor>`:
//! J3 dry friction × factor over the middle third of the lift's α range, outside the vocabulary,
//! `compliance:<k N·m/rad>`: the bellows as spring k, damper `$DRIVE_C` N·m·s/rad (default 10)
//! and drive inertia `$DRIVE_JD` kg·m² (default 0.2))
use pantowatch_models::drift::{DriftThresholds, Status};
use pantowatch_models::lift::dynamics::LiftModel;
use pantowatch_models::lift::geometry::builtin_160ec;
use pantowatch_models::lift::protocol::{LiftProtocol, record};
use pantowatch_models::lift::report::{LiftChannels, fit_lift_trace};
use pantowatch_models::lift::sensors::LiftSensorNoise;
use pantowatch_models::lift::simulate::SimOptions;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let seeds: u64 = args.first().and_then(|s| s.parse().ok()).unwrap_or(2);
    let cases: Vec<String> = if args.len() > 1 {
        args[1..].to_vec()
    } else {
        vec![
            "clean".into(),
            "drag:3".into(),
            "drag:10".into(),
            "delay:20".into(),
        ]
    };
    let k: f64 = std::env::var("K")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(1.0);
    let g = builtin_160ec();
    let base = LiftModel::new(g);
    let protocol = LiftProtocol::raise_and_lower(&base, g).unwrap();
    // The α range a clean raise and lower sweeps (for `band`).
    let protocol_alpha = {
        let rec = record(&base, &protocol, &SimOptions::default()).unwrap();
        let (hmin, hmax) = rec
            .strip_height_m
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), h| {
                (a.min(*h), b.max(*h))
            });
        let a = |h: f64| {
            pantowatch_models::lift::statics::alpha_at_height(&base, h, 0.0, base.alpha_range_rad)
                .unwrap_or(0.0)
        };
        (a(hmin), a(hmax))
    };
    for case in &cases {
        // `<effect>[:size][@J3.dry*2]`: an effect, optionally with one joint drifted.
        let (case_effect, drift) = match case.split_once('@') {
            Some((c, d)) => {
                let (jk, f) = d.split_once('*').unwrap();
                let (j, k) = jk.split_once('.').unwrap();
                (c, Some((j, k, f.parse::<f64>().unwrap())))
            }
            None => (case.as_str(), None),
        };
        let (name, size) = match case_effect.split_once(':') {
            Some((n, v)) => (n, v.parse::<f64>().unwrap()),
            None => (case_effect, 0.0),
        };
        let first: u64 = std::env::var("FIRST_SEED")
            .ok()
            .and_then(|s| s.parse().ok())
            .unwrap_or(0);
        for seed in first..first + seeds {
            let mut m = base.clone();
            if let Some((j, kind, f)) = drift {
                let p = pantowatch_models::lift::sensitivity::LiftParam::named(j, kind).unwrap();
                let mut off = 0.0;
                p.set(&mut m, &mut off, p.get(&base, 0.0) * f);
            }
            if name == "drag" {
                m.head_drag_ns2_per_m2 = size;
            }
            if name == "band" {
                // J3 dry friction × size over the middle third of the lift's α range (outside
                // the vocabulary).
                let (lo, hi) = (
                    protocol_alpha.0 + (protocol_alpha.1 - protocol_alpha.0) / 3.0,
                    protocol_alpha.0 + 2.0 * (protocol_alpha.1 - protocol_alpha.0) / 3.0,
                );
                m.friction_band = Some(pantowatch_models::lift::dynamics::FrictionBand {
                    joint_index: 3,
                    alpha_lo_rad: lo,
                    alpha_hi_rad: hi,
                    factor: size,
                });
            }
            if name == "compliance" {
                let env = |k: &str, d: f64| {
                    std::env::var(k)
                        .ok()
                        .and_then(|v| v.parse().ok())
                        .unwrap_or(d)
                };
                m.drive_compliance = Some(pantowatch_models::lift::dynamics::DriveCompliance {
                    stiffness_nm_per_rad: size,
                    damping_nms_per_rad: env("DRIVE_C", 10.0),
                    inertia_kgm2: env("DRIVE_JD", 0.2),
                });
            }
            if name == "stribeck" {
                // At joint $STRIBECK_JOINT (default J3), Stribeck speed $STRIBECK_VS rad/s.
                let j = std::env::var("STRIBECK_JOINT").unwrap_or_else(|_| "J3".into());
                let j = pantowatch_models::lift::topology::RevJoint::ALL
                    .into_iter()
                    .find(|r| r.name() == j)
                    .unwrap();
                m.stribeck_excess[j.index()] = size;
                if let Some(vs) = std::env::var("STRIBECK_VS")
                    .ok()
                    .and_then(|v| v.parse().ok())
                {
                    m.stribeck_speed_rad_s[j.index()] = vs;
                }
            }
            let clean = record(&m, &protocol, &SimOptions::default()).unwrap();
            let mut rec = LiftSensorNoise::realistic()
                .scaled(k)
                .apply(&clean, 7000 + seed);
            match name {
                "offset" => rec
                    .strip_height_m
                    .iter_mut()
                    .for_each(|h| *h += size * 1e-3),
                "gain" => {
                    let h0 = rec.strip_height_m[0];
                    rec.strip_height_m
                        .iter_mut()
                        .for_each(|h| *h = h0 + (*h - h0) * (1.0 + size / 100.0));
                }
                "delay" => {
                    let lag = (size * 1e-3 * protocol.sample_hz).round() as usize;
                    let h = rec.strip_height_m.clone();
                    for i in 0..h.len() {
                        rec.strip_height_m[i] = h[i.saturating_sub(lag)];
                    }
                }
                _ => {}
            }
            let ch = LiftChannels::from(&rec);
            let t0 = std::time::Instant::now();
            let rep = fit_lift_trace(&ch, &DriftThresholds::default(), "probe").unwrap();
            let secs = t0.elapsed().as_secs_f64();
            let r = &rep.result.residual;
            let flags: Vec<String> = rep
                .result
                .joints
                .iter()
                .filter(|j| matches!(j.status, Status::Watch | Status::Alarm))
                .map(|j| format!("{}:{:?}", j.joint, j.status))
                .collect();
            let effects: Vec<String> = r
                .effects
                .iter()
                .map(|e| format!("{} {}", e.name, serde_json::Value::Object(e.params.clone())))
                .collect();
            println!(
                "{case:>10} seed {seed}: verdict {:?} ratio {:.2} rmse {:.3}->{:.3} mm holdout {:.3}->{:.3} mm {:?} effects {effects:?} flags {flags:?} withheld {:?} {secs:.2}s",
                r.verdict,
                r.excess_ratio.unwrap_or(f64::NAN),
                r.rmse_before * 1e3,
                r.rmse_after * 1e3,
                r.holdout_rmse_before * 1e3,
                r.holdout_rmse_after * 1e3,
                r.holdout_note,
                r.joints_withheld.is_some(),
            );
        }
    }
}

use super::*;
use crate::contract::drift::Status;
use crate::lift::dynamics::LiftModel;
use crate::lift::geometry::builtin_160ec;
use crate::lift::identify::{LiftFitOptions, LiftTrace, fit_map};
use crate::lift::protocol::{LiftProtocol, record};
use crate::lift::report::fit_result;
use crate::lift::sensitivity::LiftParam;
use crate::lift::sensors::LiftSensorNoise;
use crate::lift::simulate::SimOptions;

/// The service's entry (`report::fit_lift_trace`, default drift bands) on `rec`'s inputs with
/// `h` as the H channel.
fn fit_with_h(
    rec: &crate::lift::protocol::LiftRecord,
    h: &[f64],
) -> crate::contract::report::FitResult {
    use crate::lift::report::{LiftChannels, fit_lift_trace};
    let u = rec.inputs();
    fit_lift_trace(
        &LiftChannels {
            t_s: u.t_s,
            strip_height_m: h,
            torque_nm: u.torque_nm,
            fs_n: u.fs_n,
            fm_n: u.fm_n,
        },
        &crate::contract::drift::DriftThresholds::default(),
        "t",
    )
    .unwrap()
    .result
}

/// A J3 dry drift of `j3_factor` (> 1: drifted) shows in the combination holding J3 (its own
/// entry is reported as not separately identified), and no other entry is flagged.
fn only_a_j3_drift_is_flagged(r: &crate::contract::report::FitResult, j3_factor: f64) {
    for j in &r.joints {
        let flagged = matches!(j.status, Status::Watch | Status::Alarm);
        if j3_factor > 1.0 && j.joint.contains("J3") && j.joint.contains('+') {
            assert!(flagged, "J3 ×{j3_factor} not shown: {j:?}");
        } else {
            assert!(!flagged, "J3 ×{j3_factor}: {j:?}");
        }
    }
}

#[test]
fn white_noise_is_trusted_and_a_slow_error_is_not() {
    let n = 4000;
    let t: Vec<f64> = (0..n).map(|k| k as f64 / 500.0).collect();
    let mut rng = crate::numerics::noise::Noise::new(5);
    let white: Vec<f64> = (0..n).map(|_| 0.5e-3 * rng.normal()).collect();
    let h: Vec<f64> = t.iter().map(|t| 1.0 + 0.1 * t).collect();
    let d = diagnose(&t, &white, &h, &h, 0.0);
    assert!((d.noise_m - 0.5e-3).abs() < 0.05e-3, "{d:?}");
    assert!(d.excess_ratio < 1.1 && d.trusted, "{d:?}");
    // A 3 mm slow wave on top: RMS ≈ 2.2 mm against 0.5 mm noise.
    let slow: Vec<f64> = white
        .iter()
        .zip(&t)
        .map(|(w, t)| w + 3e-3 * (t * 1.5).sin())
        .collect();
    let d = diagnose(&t, &slow, &h, &h, 0.0);
    assert!(!d.trusted && d.excess_ratio > MODEL_ERROR_RATIO, "{d:?}");
    // A noise-free record's µm residual is judged against the floor, not against itself.
    let tiny: Vec<f64> = t.iter().map(|t| 2e-6 * (t * 1.5).sin()).collect();
    assert!(diagnose(&t, &tiny, &h, &h, 0.7e-3).trusted);
    assert!(!diagnose(&t, &tiny, &h, &h, 0.0).trusted);
    // Nothing to judge: trusted, not a crash.
    let e = diagnose(&[], &[], &[], &[], 0.0);
    assert!(e.trusted && e.rms_m.is_nan());
}

/// Issue 16, point 4, on the data-level faults this module can detect without a vocabulary:
/// realistic-noise raise-and-lower lifts at Table 4 whose H channel lags the inputs by 20 or
/// 50 ms (an undeclared sensor delay). Without the gate the fit flagged joints that had not
/// drifted (J1+J3 dry watch, J5+J8 dry alarm; `examples/lift_residual_probe`). Asserted: every
/// such fit says `unexplained`, withholds every joint and combination (unknown, not
/// identified), and names the strip speed among what the residual follows. Controls: the same
/// lifts without the delay, Table 4 and J3 dry ×2.2, are trusted, with no verdict, and the J3
/// drift is still flagged.
#[test]
fn an_undeclared_h_delay_withholds_the_joints_and_controls_do_not() {
    let g = builtin_160ec();
    let base = LiftModel::new(g);
    let protocol = LiftProtocol::raise_and_lower(&base, g).unwrap();
    let opts = LiftFitOptions::default();
    let run = |m: &LiftModel, delay_ms: f64, seed: u64| {
        let clean = record(m, &protocol, &SimOptions::default()).unwrap();
        let mut rec = LiftSensorNoise::realistic().apply(&clean, 300 + seed);
        let k = (delay_ms * 1e-3 * protocol.sample_hz).round() as usize;
        let h = rec.strip_height_m.clone();
        for i in 0..h.len() {
            rec.strip_height_m[i] = h[i.saturating_sub(k)];
        }
        let trace = rec.trace();
        let fit = fit_map(&base, &[trace], &opts).unwrap();
        let trace = rec.trace();
        fit_result(&base, &fit, &trace, &fit.fitted_height_m[0], &opts, "t")
    };
    for seed in 0..2 {
        for delay_ms in [20.0, 50.0] {
            let r = run(&base, delay_ms, seed);
            assert_eq!(
                r.residual.verdict.as_deref(),
                Some("unexplained"),
                "{delay_ms} ms"
            );
            assert!(r.residual.joints_withheld.is_some());
            assert!(r.residual.excess_ratio.unwrap() > MODEL_ERROR_RATIO);
            for j in &r.joints {
                assert!(!j.identifiable && j.status == Status::Unknown, "{j:?}");
            }
            assert!(r.combinations.iter().all(|c| c.status == Status::Unknown));
            assert!(
                r.residual.correlates_with[..2]
                    .iter()
                    .any(|(s, _)| s == "strip speed"),
                "{:?}",
                r.residual.correlates_with
            );
        }
        let ok = run(&base, 0.0, seed);
        assert!(ok.residual.verdict.is_none() && ok.residual.joints_withheld.is_none());
        assert!(ok.residual.excess_ratio.unwrap() < MODEL_ERROR_RATIO);
        let mut worn = base.clone();
        let p = LiftParam::named("J3", "dry").unwrap();
        let mut off = 0.0;
        p.set(&mut worn, &mut off, p.get(&base, 0.0) * 2.2);
        let w = run(&worn, 0.0, seed);
        assert!(w.residual.joints_withheld.is_none());
        let j13 = w.joints.iter().find(|j| j.joint == "J1+J3").unwrap();
        assert!(
            matches!(j13.status, Status::Watch | Status::Alarm),
            "{j13:?}"
        );
    }
}

/// Issue 16, points 2–4, through the service's entry (`report::fit_lift_trace`): realistic-noise
/// raise-and-lower lifts of an unworn pantograph (2 seeds each) with
/// - an H delay of 20 or 50 ms → `sensor_delay` named (4 of 4), the truth in its interval, RMSE
///   at most half the base fit's (6.3 → 0.50, 10.9 → 0.51, 6.0 → 0.50, 13.1 → 0.50 mm), no
///   joint flagged, joints reported from the augmented fit;
/// - effects outside the lift vocabulary — an H gain error of 1.5 % or 5 % (a mis-scaled
///   sensor) and a 3 mm, 0.7 Hz sway (a structural mode) → never a name, never a joint flagged;
///   the 5 % gain and the sway `unexplained` with the joints withheld (the 1.5 % gain is
///   absorbed by the fit within 2× the noise: not detected, and raises no flag);
/// - none → trusted, no effect, no verdict.
#[test]
fn a_delay_is_named_and_other_errors_stay_unexplained() {
    use crate::lift::report::{LiftChannels, fit_lift_trace};
    let g = builtin_160ec();
    let base = LiftModel::new(g);
    let protocol = LiftProtocol::raise_and_lower(&base, g).unwrap();
    let clean = record(&base, &protocol, &SimOptions::default()).unwrap();
    let (mut named, mut tried) = (0, 0);
    for seed in 0..2u64 {
        let rec = LiftSensorNoise::realistic().apply(&clean, 500 + seed);
        let t = rec.inputs().t_s.to_vec();
        let fit = |h: &[f64]| {
            let u = rec.inputs();
            fit_lift_trace(
                &LiftChannels {
                    t_s: u.t_s,
                    strip_height_m: h,
                    torque_nm: u.torque_nm,
                    fs_n: u.fs_n,
                    fm_n: u.fm_n,
                },
                &crate::contract::drift::DriftThresholds::default(),
                "t",
            )
            .unwrap()
            .result
        };
        for delay_samples in [10usize, 25] {
            let truth_s = delay_samples as f64 / protocol.sample_hz;
            let h: Vec<f64> = (0..rec.strip_height_m.len())
                .map(|i| rec.strip_height_m[i.saturating_sub(delay_samples)])
                .collect();
            let r = fit(&h);
            tried += 1;
            eprintln!(
                "delay {truth_s} s seed {seed}: effects {:?} rmse {:.4} -> {:.4} mm",
                r.residual.effects,
                r.residual.rmse_before * 1e3,
                r.residual.rmse_after * 1e3
            );
            // Never a wrong name, and never a joint flagged by the delay.
            assert!(r.residual.effects.iter().all(|e| e.name == "sensor_delay"));
            for j in &r.joints {
                assert!(!matches!(j.status, Status::Watch | Status::Alarm), "{j:?}");
            }
            if let Some(e) = r.residual.effects.first() {
                named += 1;
                let ci = e.params["delay_s_ci95"].as_array().unwrap();
                let (lo, hi) = (ci[0].as_f64().unwrap(), ci[1].as_f64().unwrap());
                assert!(lo <= truth_s && truth_s <= hi, "{e:?} truth {truth_s}");
                assert!(r.residual.rmse_after <= 0.5 * r.residual.rmse_before);
                assert!(
                    r.residual.holdout_rmse_after
                        <= crate::lift::holdout::MAX_HOLDOUT_RATIO * r.residual.holdout_rmse_before
                );
                assert!(r.residual.joints_withheld.is_none() && r.residual.verdict.is_none());
                assert!(r.joints.iter().any(|j| j.identifiable));
            } else {
                assert_eq!(r.residual.verdict.as_deref(), Some("unexplained"));
            }
        }
        let outside: [(&str, Vec<f64>); 3] = [
            (
                "gain 1.5 %",
                rec.strip_height_m.iter().map(|h| h * 1.015).collect(),
            ),
            (
                "gain 5 %",
                rec.strip_height_m.iter().map(|h| h * 1.05).collect(),
            ),
            (
                "sway 3 mm 0.7 Hz",
                rec.strip_height_m
                    .iter()
                    .zip(&t)
                    .map(|(h, t)| h + 3e-3 * (std::f64::consts::TAU * 0.7 * t).sin())
                    .collect(),
            ),
        ];
        for (what, h) in outside {
            let r = fit(&h);
            eprintln!(
                "{what} seed {seed}: effects {:?} ratio {:?}",
                r.residual.effects, r.residual.excess_ratio
            );
            assert!(
                r.residual.effects.is_empty(),
                "{what}: {:?}",
                r.residual.effects
            );
            // Never a joint flagged; detected ones withheld as unexplained.
            for j in &r.joints {
                assert!(
                    !matches!(j.status, Status::Watch | Status::Alarm),
                    "{what}: {j:?}"
                );
            }
            if what.starts_with("sway") || what.starts_with("gain 5") {
                assert_eq!(r.residual.verdict.as_deref(), Some("unexplained"), "{what}");
                assert!(
                    r.joints.iter().all(|j| j.status == Status::Unknown),
                    "{what}"
                );
            }
        }
        let ok = fit(&rec.strip_height_m);
        assert!(ok.residual.effects.is_empty() && ok.residual.verdict.is_none());
    }
    // Issue 16's target is ≥ 90 % named right; measured 4 of 4 since the delay is one fitted
    // parameter (the profile search it replaced named 3 of 4). Asserted: every one.
    assert_eq!(named, tried, "sensor_delay named on {named} of {tried}");
}

/// Issue 16, points 2 and 4, `quadratic_drag` through the service's entry: realistic-noise
/// raise-and-lower lifts (2 seeds each) of a head with c_a = 4 N/(m/s)² on an unworn
/// pantograph, and c_a = 8 with J3 dry friction ×2. The drag is named, its 95 % interval holds
/// the truth, the RMSE at least halves, no joint is flagged but the drifted one's entry
/// (J1+J3, the combination a raise and lower informs), and joints come from the augmented fit.
/// Measured (`examples/lift_effects_probe`, seeds 12–19): c_a 2, 4, 8 and 4 with J3 ×2 named on
/// 25 of 32 lifts (the rest absorbed by the friction to 0.95–1.39× the noise, below the try
/// ratio, no flag), 25 of 25 intervals holding the truth.
#[test]
fn a_head_drag_is_named_with_joints_from_the_augmented_fit() {
    let g = builtin_160ec();
    let base = LiftModel::new(g);
    let protocol = LiftProtocol::raise_and_lower(&base, g).unwrap();
    let j3 = LiftParam::named("J3", "dry").unwrap();
    for (c_a, j3_factor) in [(4.0, 1.0), (8.0, 2.0)] {
        let mut m = base.clone();
        m.head_drag_ns2_per_m2 = c_a;
        let mut off = 0.0;
        j3.set(&mut m, &mut off, j3.get(&base, 0.0) * j3_factor);
        let clean = record(&m, &protocol, &SimOptions::default()).unwrap();
        for seed in 0..2u64 {
            let rec = LiftSensorNoise::realistic().apply(&clean, 7012 + seed);
            let r = fit_with_h(&rec, &rec.strip_height_m);
            eprintln!(
                "c_a {c_a} J3 ×{j3_factor} seed {seed}: effects {:?} rmse {:.3} -> {:.3} mm",
                r.residual.effects,
                r.residual.rmse_before * 1e3,
                r.residual.rmse_after * 1e3
            );
            assert_eq!(r.residual.effects.len(), 1, "{:?}", r.residual);
            let e = &r.residual.effects[0];
            assert_eq!(e.name, "quadratic_drag");
            let ci = e.params["c_a_ns2_per_m2_ci95"].as_array().unwrap();
            let (lo, hi) = (ci[0].as_f64().unwrap(), ci[1].as_f64().unwrap());
            assert!(lo <= c_a && c_a <= hi, "{e:?} truth {c_a}");
            assert!(r.residual.rmse_after <= 0.5 * r.residual.rmse_before);
            // Judged on the held-out blocks too (`lift::holdout`).
            assert!(r.residual.holdout_note.is_none(), "{:?}", r.residual);
            assert!(
                r.residual.holdout_rmse_after
                    <= crate::lift::holdout::MAX_HOLDOUT_RATIO * r.residual.holdout_rmse_before
            );
            assert!(r.residual.joints_withheld.is_none() && r.residual.verdict.is_none());
            let shown = r.joints.iter().any(|j| {
                j.joint.contains("J3") && matches!(j.status, Status::Watch | Status::Alarm)
            });
            assert_eq!(shown, j3_factor > 1.0, "{:?}", r.joints);
            only_a_j3_drift_is_flagged(&r, j3_factor);
        }
    }
}

/// Issue 16, points 2 and 4, `stribeck` through the service's entry: realistic-noise
/// raise-and-lower lifts (2 seeds each) of an unworn pantograph whose J3 static friction is
/// 1.3× its kinetic (v_s 0.05 rad/s), and one 1.2× whose J3 kinetic dry friction has also
/// doubled. `stribeck` at J3 is named — never another effect — its ratio's 95 % interval holds
/// the truth, the RMSE at least halves, and no joint is flagged but the drifted one's entry.
#[test]
fn a_stribeck_friction_is_named_at_its_joint() {
    use crate::lift::topology::RevJoint;
    let g = builtin_160ec();
    let base = LiftModel::new(g);
    let protocol = LiftProtocol::raise_and_lower(&base, g).unwrap();
    let j3 = LiftParam::named("J3", "dry").unwrap();
    for (ratio, j3_factor) in [(1.3, 1.0), (1.2, 2.0)] {
        let mut m = base.clone();
        m.stribeck_excess[RevJoint::J3.index()] = ratio - 1.0;
        let mut off = 0.0;
        j3.set(&mut m, &mut off, j3.get(&base, 0.0) * j3_factor);
        let clean = record(&m, &protocol, &SimOptions::default()).unwrap();
        for seed in 0..2u64 {
            let rec = LiftSensorNoise::realistic().apply(&clean, 7030 + seed);
            let r = fit_with_h(&rec, &rec.strip_height_m);
            eprintln!(
                "ratio {ratio} J3 ×{j3_factor} seed {seed}: effects {:?} rmse {:.3} -> {:.3} mm",
                r.residual.effects,
                r.residual.rmse_before * 1e3,
                r.residual.rmse_after * 1e3
            );
            assert_eq!(r.residual.effects.len(), 1, "{:?}", r.residual);
            let e = &r.residual.effects[0];
            assert_eq!(e.name, "stribeck");
            assert_eq!(e.params["joint"], "J1+J3");
            assert_eq!(e.params["fitted_at"], "J3");
            let ci = e.params["ratio_ci95"].as_array().unwrap();
            let (lo, hi) = (ci[0].as_f64().unwrap(), ci[1].as_f64().unwrap());
            assert!(lo <= ratio && ratio <= hi, "{e:?} truth {ratio}");
            assert!(r.residual.rmse_after <= 0.5 * r.residual.rmse_before);
            assert!(r.residual.joints_withheld.is_none() && r.residual.verdict.is_none());
            only_a_j3_drift_is_flagged(&r, j3_factor);
        }
    }
}

/// Issue 16, points 2 and 4, `sensor_offset` through the service's entry: realistic-noise
/// raise-and-lower lifts of an unworn pantograph whose H zero is off by −10 mm (the two noise
/// seeds on which, before `sensor_offset` was in the vocabulary and the candidates were judged
/// by BIC, the loop named `quadratic_drag`) and +20 mm. The offset is named — never another
/// effect — its interval holds the truth, no joint is flagged. The model's start is pinned to
/// the first sample's static equilibrium, which is what makes an offset visible at all.
#[test]
fn an_h_zero_offset_is_named_not_a_drag() {
    let g = builtin_160ec();
    let base = LiftModel::new(g);
    let protocol = LiftProtocol::raise_and_lower(&base, g).unwrap();
    let clean = record(&base, &protocol, &SimOptions::default()).unwrap();
    for (offset_m, seed) in [(-0.01, 7001u64), (-0.01, 7002), (0.02, 7000)] {
        let rec = LiftSensorNoise::realistic().apply(&clean, seed);
        let h: Vec<f64> = rec.strip_height_m.iter().map(|h| h + offset_m).collect();
        let r = fit_with_h(&rec, &h);
        eprintln!(
            "offset {offset_m} seed {seed}: effects {:?} rmse {:.3} -> {:.3} mm",
            r.residual.effects,
            r.residual.rmse_before * 1e3,
            r.residual.rmse_after * 1e3
        );
        assert_eq!(r.residual.effects.len(), 1, "{:?}", r.residual);
        let e = &r.residual.effects[0];
        assert_eq!(e.name, "sensor_offset");
        let ci = e.params["offset_m_ci95"].as_array().unwrap();
        let (lo, hi) = (ci[0].as_f64().unwrap(), ci[1].as_f64().unwrap());
        assert!(lo <= offset_m && offset_m <= hi, "{e:?} truth {offset_m}");
        assert!(r.residual.rmse_after <= 0.5 * r.residual.rmse_before);
        for j in &r.joints {
            assert!(!matches!(j.status, Status::Watch | Status::Alarm), "{j:?}");
        }
    }
}

/// Issue 16, an effect outside the lift vocabulary simulated in the dynamics: J3's dry friction
/// ×1.2 over the middle third of the lower arm's stroke (a scored stretch of the pin). No
/// vocabulary effect may take its name: the verdict is `unexplained`, the joints withheld, no
/// joint flagged. Measured (`examples/lift_effects_probe -- 4 band:1.05 band:1.1 band:1.2
/// band:1.5 band:2 band:3`, 24 lifts): never named; ×1.05 leaves 2.0–2.6× the noise (tried,
/// nothing passes, no flag), ×1.1 and more `unexplained`, withheld.
#[test]
fn a_friction_band_outside_the_vocabulary_stays_unexplained() {
    use crate::lift::dynamics::FrictionBand;
    use crate::lift::statics::alpha_at_height;
    use crate::lift::topology::RevJoint;
    let g = builtin_160ec();
    let base = LiftModel::new(g);
    let protocol = LiftProtocol::raise_and_lower(&base, g).unwrap();
    let plain = record(&base, &protocol, &SimOptions::default()).unwrap();
    let (hmin, hmax) = plain
        .strip_height_m
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), h| {
            (a.min(*h), b.max(*h))
        });
    let a = |h: f64| alpha_at_height(&base, h, 0.0, base.alpha_range_rad).unwrap();
    let (a0, a1) = (a(hmin), a(hmax));
    let mut m = base.clone();
    m.friction_band = Some(FrictionBand {
        joint_index: RevJoint::J3.index(),
        alpha_lo_rad: a0 + (a1 - a0) / 3.0,
        alpha_hi_rad: a0 + 2.0 * (a1 - a0) / 3.0,
        factor: 1.2,
    });
    let clean = record(&m, &protocol, &SimOptions::default()).unwrap();
    let rec = LiftSensorNoise::realistic().apply(&clean, 7000);
    let r = fit_with_h(&rec, &rec.strip_height_m);
    assert!(r.residual.effects.is_empty(), "{:?}", r.residual.effects);
    assert_eq!(r.residual.verdict.as_deref(), Some("unexplained"));
    assert!(r.residual.joints_withheld.is_some());
    for j in &r.joints {
        assert!(!matches!(j.status, Status::Watch | Status::Alarm), "{j:?}");
    }
}

/// Issue 16, bad input: a lift too short for the held-out test (3 s of a raise: one whole block
/// held out, 2 needed) gets no held-out figure and a reason naming the minimum; a 4.2 s record
/// gets one, near the noise on a correct model. Through the service's entry, a correct lift is
/// not held-out tested (nothing to judge) and says so.
#[test]
fn a_record_too_short_for_the_held_out_test_says_so() {
    use crate::lift::holdout::{Holdout, blocks};
    use crate::lift::report::{LiftChannels, NO_HOLDOUT_NEEDED, fit_lift_trace};
    let g = builtin_160ec();
    let base = LiftModel::new(g);
    let protocol = LiftProtocol::raise_and_lower(&base, g).unwrap();
    let clean = record(&base, &protocol, &SimOptions::default()).unwrap();
    let rec = LiftSensorNoise::realistic().apply(&clean, 900);
    let t0 = rec.t_s[0];
    let opts = LiftFitOptions::default();
    for (secs, judged) in [(3.0, false), (4.2, true)] {
        let n = rec.t_s.iter().take_while(|t| **t - t0 < secs).count();
        let u = rec.inputs();
        let trace = LiftTrace {
            inputs: crate::lift::simulate::LiftInputs {
                t_s: &u.t_s[..n],
                torque_nm: &u.torque_nm[..n],
                fs_n: &u.fs_n[..n],
                fm_n: &u.fm_n[..n],
            },
            strip_height_m: &rec.strip_height_m[..n],
        };
        let fit = fit_map(&base, &[trace], &opts).unwrap();
        let h = blocks(&base, &trace, &fit, &opts).unwrap();
        eprintln!("{secs} s: {h:?}");
        match h {
            Holdout::Judged { holdout_rmse_m, .. } => {
                assert!(judged);
                assert!(holdout_rmse_m < 2.0 * opts.h_noise_m);
            }
            Holdout::Short(why) => {
                assert!(!judged);
                assert!(
                    why.contains("held-out test not run") && why.contains("3.5 s"),
                    "{why}"
                );
            }
        }
    }
    let r = fit_lift_trace(
        &LiftChannels::from(&rec),
        &crate::contract::drift::DriftThresholds::default(),
        "t",
    )
    .unwrap()
    .result;
    assert_eq!(r.residual.holdout_note.as_deref(), Some(NO_HOLDOUT_NEEDED));
    assert_eq!(r.residual.holdout_rmse_before, r.residual.rmse_before);
}

/// Issue 16, points 2 and 4, `drive_compliance` through the service's entry, realistic-noise
/// raise-and-lower lifts. (a) A drive of the size a 160EC bellows drive has (J_d 0.3 kg·m²,
/// k 3000 N·m/rad, c 10 N·m·s/rad: a 16 Hz drive-side mode) is absorbed by the plain fit within
/// the noise: the residual stays under the try ratio, no effect is named and no joint is
/// flagged (no wear alarm from it). (b) A heavy drive side (J_d 5 kg·m², k 15000 N·m/rad, c 80
/// N·m·s/rad, 8.7 Hz) is named `drive_compliance` — never another effect — with J_d within
/// 25 % of the truth, the RMSE at least halved and no joint flagged. Measured over more seeds
/// (`examples/lift_effects_probe`): docs/VALIDATION.md, "Lift effects named".
#[test]
fn a_compliant_drive_is_absorbed_at_its_real_size_and_named_when_heavy() {
    use crate::lift::dynamics::DriveCompliance;
    let g = builtin_160ec();
    let base = LiftModel::new(g);
    let protocol = LiftProtocol::raise_and_lower(&base, g).unwrap();
    let cases = [(0.3, 3000.0, 10.0, false), (5.0, 15000.0, 80.0, true)];
    for (inertia_kgm2, stiffness_nm_per_rad, damping_nms_per_rad, named) in cases {
        let mut m = base.clone();
        m.drive_compliance = Some(DriveCompliance {
            stiffness_nm_per_rad,
            damping_nms_per_rad,
            inertia_kgm2,
        });
        let clean = record(&m, &protocol, &SimOptions::default()).unwrap();
        for seed in 0..2u64 {
            let rec = LiftSensorNoise::realistic().apply(&clean, 7012 + seed);
            let r = fit_with_h(&rec, &rec.strip_height_m);
            eprintln!(
                "J_d {inertia_kgm2} k {stiffness_nm_per_rad} seed {seed}: ratio {:?} effects {:?} rmse {:.3} -> {:.3} mm",
                r.residual.excess_ratio,
                r.residual.effects,
                r.residual.rmse_before * 1e3,
                r.residual.rmse_after * 1e3
            );
            only_a_j3_drift_is_flagged(&r, 1.0);
            if !named {
                assert!(r.residual.effects.is_empty(), "{:?}", r.residual);
                assert!(
                    r.residual.excess_ratio.unwrap() < super::EFFECT_TRY_RATIO,
                    "{:?}",
                    r.residual
                );
                continue;
            }
            assert_eq!(r.residual.effects.len(), 1, "{:?}", r.residual);
            let e = &r.residual.effects[0];
            assert_eq!(e.name, "drive_compliance");
            let jd = e.params["inertia_kgm2"].as_f64().unwrap();
            assert!((jd - inertia_kgm2).abs() <= 0.25 * inertia_kgm2, "{e:?}");
            assert!(r.residual.rmse_after <= 0.5 * r.residual.rmse_before);
            assert!(r.residual.joints_withheld.is_none());
        }
    }
}

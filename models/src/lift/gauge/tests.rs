//! Tests of the gauge fit: recovered numbers against the truth the records were made with, over
//! several seeds, at the stated gauge (σ 0.2 N, 0.1 N steps, 15 readings per branch over 0.8–1.84 m).

use super::effects::fit_with_effects;
use super::fit::FITTED_JOINTS;
use super::solve::{forces_near, warm_starts};
use super::*;
use crate::contract::drift::{DriftThresholds, Status};
use crate::lift::attribution::Combination;
use crate::lift::dynamics::LiftModel;
use crate::lift::geometry::builtin_160ec;
use crate::lift::sensitivity::LiftParam;
use crate::lift::topology::RevJoint;

/// Readings per branch of the test records.
const PER_BRANCH: usize = 15;

pub(super) fn setup() -> (LiftModel, DriveLine, (f64, f64)) {
    let g = builtin_160ec();
    (
        LiftModel::new(g),
        DriveLine::from_lift_test(g),
        (g.alpha_min_rad, g.alpha_max_rad),
    )
}

/// `base` with each `(joint, factor)` of `drift` applied to its dry μ.
pub(super) fn drifted(base: &LiftModel, drift: &[(RevJoint, f64)]) -> LiftModel {
    let mut m = base.clone();
    for (j, k) in drift {
        m.friction.dry_mu[j.index()] *= k;
    }
    m
}

pub(super) fn record(truth: &LiftModel, seed: u64, offset_n: f64, rate: f64) -> GaugeRecord {
    let (_, drive, ar) = setup();
    let opts = GaugeSimOptions {
        seed,
        offset_n,
        spring_rate_factor: rate,
        ..GaugeSimOptions::default()
    };
    simulate_gauge(truth, ar, &drive, &reading_heights(PER_BRANCH), &opts).unwrap()
}

/// The combination's level of `truth` over `base` (each member's dry μ over its baseline).
pub(super) fn true_level(c: &Combination, truth: &LiftModel, base: &LiftModel) -> f64 {
    c.level_of(|p| p.get(truth, 0.0) / p.get(base, 0.0))
}

fn describe(c: &Combination) -> String {
    let w: Vec<String> = c
        .params
        .iter()
        .zip(&c.weights)
        .map(|(p, w)| format!("{} {w:.3}", p.joint()))
        .collect();
    format!(
        "{} = {:.4} [{:.4}, {:.4}] ({:?}); weights {}",
        c.label(),
        c.value,
        c.ci95[0],
        c.ci95[1],
        c.status,
        w.join(", ")
    )
}

/// The built-in type's simulation: the same record as the general one, seeded; a bad factor is
/// an error, not a panic.
#[test]
fn the_builtin_simulation_is_the_general_one() {
    let (base, drive, ar) = setup();
    let opts = GaugeSimOptions {
        seed: 9,
        ..GaugeSimOptions::default()
    };
    let drift = [(RevJoint::J3, 2.0)];
    let a = simulate_builtin_gauge(&drift, 10, &opts).unwrap();
    let b = simulate_gauge(
        &drifted(&base, &drift),
        ar,
        &drive,
        &reading_heights(10),
        &opts,
    )
    .unwrap();
    assert_eq!(a, b);
    assert_eq!(a.len(), 20);
    assert!(simulate_builtin_gauge(&[(RevJoint::J1, f64::NAN)], 10, &opts).is_err());
    // Too few readings per branch: the record's own refusal.
    let e = simulate_builtin_gauge(&[], 2, &opts).unwrap_err();
    assert_eq!(e.field(), Some("channels.H_m"));
}

#[test]
fn the_record_splits_at_the_first_highest_reading() {
    let h = reading_heights(6);
    assert_eq!(h.len(), 12);
    let r = GaugeRecord::new(h.clone(), vec![90.0; 12], 0.1).unwrap();
    assert_eq!(r.turn, 5);
    assert_eq!(r.raising(), 0..6);
    assert_eq!(r.lowering(), 6..12);
    assert_eq!(r.direction(5), StaticFriction::Raising);
    assert_eq!(r.direction(6), StaticFriction::Lowering);
    // A record that holds at the top: the first top reading turns it.
    let mut held = h[..6].to_vec();
    held.extend([1.84, 1.84]);
    held.extend(h[7..].iter());
    let r = GaugeRecord::new(held.clone(), vec![90.0; held.len()], 0.1).unwrap();
    assert_eq!(r.turn, 5);
}

/// Each refusal names its field (and the reading, where one is at fault).
#[test]
fn bad_records_are_refused_naming_the_field() {
    let h = reading_heights(6);
    let f = vec![90.0; h.len()];
    let refuse = |h: Vec<f64>, f: Vec<f64>, q: f64| GaugeRecord::new(h, f, q).unwrap_err();
    let field = |e: &GaugeError| e.field_path().unwrap();
    let spoil = |v: &[f64], k: usize, x: f64| {
        let mut v = v.to_vec();
        v[k] = x;
        v
    };
    // Non-finite values.
    let e = refuse(spoil(&h, 3, f64::NAN), f.clone(), 0.1);
    assert_eq!(field(&e), "channels.H_m[3]", "{e}");
    let e = refuse(h.clone(), spoil(&f, 7, f64::INFINITY), 0.1);
    assert_eq!(field(&e), "channels.F_N[7]", "{e}");
    // Heights outside the working range, forces outside what a drive can hold.
    let e = refuse(spoil(&h, 4, 2.5), f.clone(), 0.1);
    assert_eq!(field(&e), "channels.H_m[4]", "{e}");
    let e = refuse(spoil(&h, 0, 0.5), f.clone(), 0.1);
    assert_eq!(field(&e), "channels.H_m[0]", "{e}");
    let e = refuse(h.clone(), spoil(&f, 2, 1e308), 0.1);
    assert_eq!(field(&e), "channels.F_N[2]", "{e}");
    // Lengths.
    let e = refuse(h.clone(), f[..5].to_vec(), 0.1);
    assert_eq!(e.field(), Some("channels.F_N"), "{e}");
    // No lowering branch, no raising branch.
    let up = h[..6].to_vec();
    let e = refuse(up, vec![90.0; 6], 0.1);
    assert!(
        matches!(
            e,
            GaugeError::NoBranch {
                branch: "lowering",
                ..
            }
        ),
        "{e}"
    );
    assert_eq!(e.field(), Some("channels.H_m"));
    let down: Vec<f64> = h[6..].to_vec();
    let e = refuse(down, vec![90.0; 6], 0.1);
    assert!(
        matches!(
            e,
            GaugeError::NoBranch {
                branch: "raising",
                ..
            }
        ),
        "{e}"
    );
    assert_eq!(e.field(), Some("channels.H_m"));
    // A branch that turns back.
    let e = refuse(spoil(&h, 2, h[1] - 0.01), f.clone(), 0.1);
    assert_eq!(field(&e), "channels.H_m[2]", "{e}");
    let e = refuse(spoil(&h, 9, h[8] + 0.01), f.clone(), 0.1);
    assert_eq!(field(&e), "channels.H_m[9]", "{e}");
    // Too few readings on a branch (the data file's minimum).
    let min = gauge_data().min_points_per_branch;
    let mut short = reading_heights(min - 1);
    short.truncate(2 * (min - 1));
    let e = refuse(short.clone(), vec![90.0; short.len()], 0.1);
    assert!(matches!(e, GaugeError::TooFewPoints { .. }), "{e}");
    assert_eq!(e.field(), Some("channels.H_m"));
    // Resolutions: non-positive, non-finite, absurd.
    for q in [0.0, -0.1, f64::NAN, f64::INFINITY, 1e-9, 50.0] {
        let e = refuse(h.clone(), f.clone(), q);
        assert_eq!(e.field(), Some("test.gauge_resolution_n"), "{q}: {e}");
    }
    // The trace function refuses alike, before any fit.
    let ch = GaugeChannels {
        strip_height_m: &h,
        force_n: &f[..3],
        resolution_n: 0.1,
    };
    let e = fit_gauge_trace(&ch, &DriftThresholds::default(), "x").unwrap_err();
    assert_eq!(e.field(), Some("channels.F_N"));
}

/// The fit's warm-started solver gives the characteristic's strip force (the exact solver's)
/// at drifted friction and another spring rate, to well under the gauge's resolution.
#[test]
fn the_fast_solver_matches_the_exact_one() {
    let (base, drive, ar) = setup();
    let rec = GaugeRecord::new(reading_heights(8), vec![90.0; 16], 0.1).unwrap();
    let warm = warm_starts(&base, ar, &drive, &rec).unwrap();
    let truth = drifted(&base, &[(RevJoint::J3, 3.0), (RevJoint::J5, 0.3)]);
    let steep = simulate::spring_rate_drive(&drive, 1.4);
    let fast = forces_near(&truth, ar, &steep, &rec, &warm).unwrap();
    let exact = predicted_forces_n(&truth, ar, &steep, &rec).unwrap();
    for (a, b) in fast.iter().zip(&exact) {
        assert!((a - b).abs() < 1e-6, "{a} vs {b}");
    }
    // Raising below lowering at the same height.
    assert!(exact[0] < exact[15] && exact[7] < exact[8], "{exact:?}");
}

/// Table 4 measured with the stated gauge, seeds 0–4: the fit names one combination whose
/// level's interval holds 1, judged `ok`; no effect is named, nothing is flagged.
#[test]
fn a_baseline_gauge_record_fits_to_level_one() {
    let (base, drive, ar) = setup();
    for seed in 0..5 {
        let rec = record(&base, seed, 0.0, 1.0);
        let lp = fit_with_effects(&base, ar, &drive, &rec, &GaugeFitOptions::default()).unwrap();
        let fit = &lp.fit;
        assert_eq!(
            lp.verdict,
            GaugeVerdict::None,
            "seed {seed}: {:?}",
            lp.residual
        );
        assert_eq!(fit.combinations.len(), 1, "seed {seed}");
        let c = &fit.combinations[0];
        eprintln!(
            "seed {seed}: {}; RMSE {:.3} N, noise {:.3} N, dof {:.1}, {} it",
            describe(c),
            fit.rmse_n,
            fit.noise_n,
            fit.dof,
            fit.iterations
        );
        assert!(
            c.informed && c.ci95[0] <= 1.0 && 1.0 <= c.ci95[1],
            "seed {seed}"
        );
        assert_eq!(c.status, Status::Ok, "seed {seed}");
        assert!(
            fit.params
                .iter()
                .all(|p| !matches!(p.status, Status::Watch | Status::Alarm))
        );
        assert!(fit.rmse_n < 0.3, "seed {seed}: {}", fit.rmse_n);
    }
}

/// Friction drifts fitted back, seeds 100–119 each (80 records): the combination's interval
/// holds the level of the truth (computed with the reported weights) on at least 18 of 20, and a
/// level whose truth lies beyond the watch band is flagged on every record, one inside it on none.
/// Measured: 19–20/20 covered for each drift, RMS z 0.93–0.99 (issue 39: the level holds
/// every joint the gap tells of, `fit::level_min_share`; J1+J3 alone had RMS z 0.25–0.73).
#[test]
fn a_friction_drift_is_fitted_back_and_flagged() {
    for (drift, flagged_truth) in [
        (vec![(RevJoint::J3, 2.0), (RevJoint::J1, 2.0)], true),
        (vec![(RevJoint::J3, 2.0), (RevJoint::J5, 2.0)], true),
        (
            vec![
                (RevJoint::J3, 2.0),
                (RevJoint::J2, 2.0),
                (RevJoint::J4, 0.5),
            ],
            true,
        ),
        (vec![(RevJoint::J1, 3.0)], false),
    ] {
        let (covered, flagged, n, rms_z) = fit_drift_back(&drift);
        eprintln!("{drift:?}: coverage {covered}/{n}, flagged {flagged}/{n}, RMS z {rms_z:.2}");
        assert!(covered >= 18, "{drift:?}: coverage {covered}/{n}");
        assert_eq!(flagged, if flagged_truth { n } else { 0 }, "{drift:?}");
    }
}

/// Fit `drift` back on seeds 100–119: (covered, flagged, records, RMS z of ln level).
fn fit_drift_back(drift: &[(RevJoint, f64)]) -> (usize, usize, usize, f64) {
    let (base, drive, ar) = setup();
    let truth = drifted(&base, drift);
    let (mut covered, mut flagged, mut n, mut z2) = (0, 0, 0, 0.0);
    for seed in 100..120 {
        let rec = record(&truth, seed, 0.0, 1.0);
        let lp = fit_with_effects(&base, ar, &drive, &rec, &GaugeFitOptions::default()).unwrap();
        assert_eq!(
            lp.verdict,
            GaugeVerdict::None,
            "seed {seed}: {:?}",
            lp.residual
        );
        let c = &lp.fit.combinations[0];
        let level = true_level(c, &truth, &base);
        let holds = c.ci95[0] <= level && level <= c.ci95[1];
        let sd_ln = (c.ci95[1] / c.ci95[0]).ln() / (2.0 * lp.fit.t_quantile);
        z2 += ((c.value / level).ln() / sd_ln).powi(2);
        n += 1;
        covered += usize::from(holds);
        flagged += usize::from(matches!(c.status, Status::Watch | Status::Alarm));
    }
    (covered, flagged, n, (z2 / n as f64).sqrt())
}

/// A gauge whose zero is +5 N, seeds 200–204: `sensor_offset` is named with b inside its
/// interval, and the friction (from the augmented fit) is not flagged.
#[test]
fn an_offset_gauge_is_named_not_a_friction_alarm() {
    let (base, drive, ar) = setup();
    for seed in 200..205 {
        let rec = record(&base, seed, 5.0, 1.0);
        let lp = fit_with_effects(&base, ar, &drive, &rec, &GaugeFitOptions::default()).unwrap();
        let e = lp.fit.offset.expect("b is fitted");
        eprintln!(
            "seed {seed}: {:?} b {:.3} [{:.3}, {:.3}] N; RMSE {:.3} → {:.3} N; tried {:?}",
            lp.verdict,
            e.value,
            e.ci95[0],
            e.ci95[1],
            lp.plain.as_ref().map_or(f64::NAN, |p| p.0.rmse_n),
            lp.fit.rmse_n,
            lp.tried
        );
        assert_eq!(
            lp.verdict,
            GaugeVerdict::Named(GaugeEffect::SensorOffset),
            "seed {seed}"
        );
        assert!(e.ci95[0] <= 5.0 && 5.0 <= e.ci95[1], "seed {seed}: {e:?}");
        let c = &lp.fit.combinations[0];
        assert_eq!(c.status, Status::Ok, "seed {seed}: {}", describe(c));
    }
    // With a real drift besides (J3 and J1 dry ×2), seeds 210–212: the offset is named and the
    // drift still shows, its level's interval holding the truth.
    let truth = drifted(&base, &[(RevJoint::J3, 2.0), (RevJoint::J1, 2.0)]);
    for seed in 210..213 {
        let rec = record(&truth, seed, 5.0, 1.0);
        let lp = fit_with_effects(&base, ar, &drive, &rec, &GaugeFitOptions::default()).unwrap();
        assert_eq!(
            lp.verdict,
            GaugeVerdict::Named(GaugeEffect::SensorOffset),
            "seed {seed}"
        );
        let c = &lp.fit.combinations[0];
        let level = true_level(c, &truth, &base);
        eprintln!("seed {seed} (drifted): {}; truth {level:.4}", describe(c));
        assert!(c.ci95[0] <= level && level <= c.ci95[1], "seed {seed}");
        assert_eq!(c.status, Status::Watch, "seed {seed}");
    }
}

/// A drive characteristic 1.3× as steep as the type's, seeds 300–304: `spring_rate` is named,
/// its interval holding 1.3, and the friction is not flagged.
#[test]
fn another_spring_rate_is_named() {
    let (base, drive, ar) = setup();
    for seed in 300..305 {
        let rec = record(&base, seed, 0.0, 1.3);
        let lp = fit_with_effects(&base, ar, &drive, &rec, &GaugeFitOptions::default()).unwrap();
        let e = lp.fit.spring_rate.expect("k was fitted");
        eprintln!(
            "seed {seed}: {:?} k {:.4} [{:.4}, {:.4}]; RMSE {:.3} → {:.3} N; tried {:?}",
            lp.verdict,
            e.value,
            e.ci95[0],
            e.ci95[1],
            lp.plain.as_ref().map_or(f64::NAN, |p| p.0.rmse_n),
            lp.fit.rmse_n,
            lp.tried
        );
        assert_eq!(
            lp.verdict,
            GaugeVerdict::Named(GaugeEffect::SpringRate),
            "seed {seed}"
        );
        assert!(e.ci95[0] <= 1.3 && 1.3 <= e.ci95[1], "seed {seed}: {e:?}");
        let c = &lp.fit.combinations[0];
        assert_eq!(c.status, Status::Ok, "seed {seed}: {}", describe(c));
    }
}

/// The contract's result: J1…J9 then the combination entry, each member reported at baseline,
/// not identified, naming the combination; RMSE in N; the JSON carries it all.
#[test]
fn the_report_has_every_joint_and_the_combination() {
    let (base, _, _) = setup();
    let rec = record(&base, 7, 5.0, 1.0);
    let ch = GaugeChannels {
        strip_height_m: &rec.heights_m,
        force_n: &rec.forces_n,
        resolution_n: rec.resolution_n,
    };
    let rep = fit_gauge_trace(&ch, &DriftThresholds::default(), "gauge-7").unwrap();
    let r = &rep.result;
    let names: Vec<&str> = r.joints.iter().map(|j| j.joint.as_str()).collect();
    assert_eq!(
        names[..10],
        ["J1", "J2", "J2'", "J3", "J4", "J5", "J6", "J7", "J8", "J9"]
    );
    assert_eq!(names.len(), 10 + r.combinations.len());
    assert_eq!(r.combinations.len(), 1);
    let c = &r.combinations[0];
    let share: f64 = c.members.iter().map(|m| m.weight).sum();
    assert!((share - 1.0).abs() < 1e-9);
    let entry = r.joints.last().unwrap();
    assert_eq!(entry.dry.combination.as_deref(), Some(c.label.as_str()));
    assert_eq!(entry.dry.unit, "× Table 4");
    for m in &c.members {
        let j = r.joints.iter().find(|j| j.joint == m.joint).unwrap();
        assert!(!j.dry.identifiable && j.dry.status == Status::Unknown);
        assert_eq!(j.dry.combination.as_deref(), Some(c.label.as_str()));
        assert_eq!(Some(j.dry.value), j.dry.baseline);
    }
    for j in &r.joints[..10] {
        assert!(!j.viscous.identifiable, "{}", j.joint);
        assert!(matches!(j.status, Status::Ok | Status::Unknown));
    }
    assert_eq!(r.rmse.unit, "N");
    assert_eq!(rep.verdict, GaugeVerdict::Named(GaugeEffect::SensorOffset));
    assert_eq!(r.residual.effects[0].name, "sensor_offset");
    assert!(r.residual.rmse_before > 2.0 * r.residual.rmse_after);
    assert!((r.fit.sensor_offset.value - 5.0).abs() < 1.0);
    let json = serde_json::to_value(r).unwrap();
    assert!(json["residual"]["effects"][0]["params"]["offset_n_ci95"].is_array());
    assert_eq!(json["joints"].as_array().unwrap().len(), 11);
    // Every fitted joint is a member or reported alone.
    assert_eq!(rep.fit.params.len(), FITTED_JOINTS.len());
    assert!(
        rep.fit
            .params
            .iter()
            .all(|p| matches!(p.param, LiftParam::Dry(_)))
    );
}

/// Pooling with lifts: a realistic-noise reference lift (seed 11) of a pantograph with J3 and J1
/// dry ×2, fitted alone and with a gauge record of the same pantograph (seed 11, its zero off by
/// 2 N; `LiftFitOptions::gauge_records`): the gauge's readings join the fit (their RMSE at the
/// gauge's noise, the zero's interval holding 2 N). Measured: the gauge informs the same direction as the lift (J1 0.13, J3 0.87), so the
/// J1+J3 level hardly narrows (sd 0.0308 → 0.0305: what is left is the prior spread of the joints
/// outside it); what pooling adds is the members apart — J1 dry sd 0.319 → 0.251, J3 0.057 →
/// 0.048 (× Table 4; with the gauge's zero fixed at 0 instead of fitted, 0.205 and 0.042, the
/// mean of the branches then counting as friction information). The pooled level lies within 3
/// posterior sd of the truth.
#[test]
fn a_gauge_record_pooled_with_a_lift_tells_its_members_apart() {
    use crate::lift::identify::{LiftFit, LiftFitOptions, PooledGauge, fit_map};
    use crate::lift::protocol::{LiftProtocol, record as lift_record};
    use crate::lift::sensors::LiftSensorNoise;
    use crate::lift::simulate::SimOptions;
    let (base, drive, ar) = setup();
    let g = builtin_160ec();
    let truth = drifted(&base, &[(RevJoint::J3, 2.0), (RevJoint::J1, 2.0)]);
    let clean = lift_record(&truth, &LiftProtocol::reference(g), &SimOptions::default()).unwrap();
    let rec = LiftSensorNoise::realistic().apply(&clean, 11);
    let trace = rec.trace();
    // The gauge's zero off by 2 N besides: each pooled record's zero is a nuisance of the fit.
    let gauge = record(&truth, 11, 2.0, 1.0);
    let own = fit_gauge(&base, ar, &drive, &gauge, &GaugeFitOptions::default()).unwrap();
    let c = &own.combinations[0];
    let lift_opts = LiftFitOptions::default();
    let alone = fit_map(&base, &[trace], &lift_opts).unwrap();
    let pooled_opts = LiftFitOptions {
        gauge_records: vec![PooledGauge {
            record: gauge.clone(),
            drive,
        }],
        ..LiftFitOptions::default()
    };
    let pooled = fit_map(&base, &[trace], &pooled_opts).unwrap();
    // The level Σ w x of a lift fit and its posterior sd (units of Table 4).
    let level = |f: &LiftFit| -> (f64, f64) {
        let idx: Vec<usize> = c
            .params
            .iter()
            .map(|p| f.params.iter().position(|e| e.param == *p).unwrap())
            .collect();
        let x = |i: usize| f.params[i].map_value / f.params[i].baseline;
        let sd = |i: usize| f.params[i].posterior_sd / f.params[i].baseline;
        let v: f64 = idx.iter().zip(&c.weights).map(|(&i, w)| w * x(i)).sum();
        let mut var = 0.0;
        for (&a, wa) in idx.iter().zip(&c.weights) {
            for (&b, wb) in idx.iter().zip(&c.weights) {
                var += wa * wb * f.posterior_correlation[(a, b)] * sd(a) * sd(b);
            }
        }
        (v, var.max(0.0).sqrt())
    };
    let truth_level = true_level(c, &truth, &base);
    let (va, sa) = level(&alone);
    let (vp, sp) = level(&pooled);
    eprintln!(
        "truth {truth_level:.4}; gauge alone {:.4} [{:.4}, {:.4}]; lift alone {va:.4} ± {sa:.4}; \
         pooled {vp:.4} ± {sp:.4}; pooled gauge RMSE {:.3} N, lift RMSE {:.3} mm (alone {:.3} mm)",
        c.value,
        c.ci95[0],
        c.ci95[1],
        pooled.gauge_rmse_n[0],
        pooled.rmse_m[0] * 1e3,
        alone.rmse_m[0] * 1e3
    );
    for (name, f) in [("lift alone", &alone), ("pooled", &pooled)] {
        let sds: Vec<String> = f
            .params
            .iter()
            .filter(|e| e.param.kind() == "dry")
            .map(|e| {
                format!(
                    "{} {:.3}±{:.3}{}",
                    e.param.joint(),
                    e.map_value / e.baseline,
                    e.posterior_sd / e.baseline,
                    if e.informed { "*" } else { "" }
                )
            })
            .collect();
        let combos: Vec<String> = f.combinations.iter().map(describe).collect();
        eprintln!("{name}: dry {}; combinations {combos:?}", sds.join(", "));
    }
    assert!(alone.gauge_rmse_n.is_empty());
    assert!(pooled.gauge_rmse_n[0] < 0.35, "{}", pooled.gauge_rmse_n[0]);
    assert_eq!(pooled.gauge_fitted_n[0].len(), gauge.len());
    assert!(sp <= sa, "pooled sd {sp} vs lift alone {sa}");
    let b = pooled.gauge_offsets[0];
    eprintln!(
        "pooled gauge zero {:.3} [{:.3}, {:.3}] N",
        b.value, b.ci95[0], b.ci95[1]
    );
    assert!(b.ci95[0] <= 2.0 && 2.0 <= b.ci95[1], "{b:?}");
    let sd_of = |f: &LiftFit, j: RevJoint| {
        let e = f
            .params
            .iter()
            .find(|e| e.param == LiftParam::Dry(j))
            .unwrap();
        e.posterior_sd / e.baseline
    };
    for (j, most) in [(RevJoint::J1, 0.9), (RevJoint::J3, 0.9)] {
        let (a, p) = (sd_of(&alone, j), sd_of(&pooled, j));
        assert!(p < most * a, "{j:?}: pooled sd {p} vs lift alone {a}");
    }
    assert!(
        (vp - truth_level).abs() < 3.0 * sp,
        "{vp} vs {truth_level} ± {sp}"
    );
}

/// A model error outside the vocabulary — a bow of 4 N at mid-height on both branches (zero at
/// the ends of the range), seeds 400–402: neither effect explains it, the verdict is
/// `unexplained`, and the report withholds every joint and the combination.
#[test]
fn a_bow_no_effect_explains_is_unexplained_and_withheld() {
    let (base, drive, ar) = setup();
    let [lo, hi] = gauge_data().working_height_m;
    for seed in 400..403 {
        let clean = record(&base, seed, 0.0, 1.0);
        let bowed: Vec<f64> = clean
            .heights_m
            .iter()
            .zip(&clean.forces_n)
            .map(|(h, f)| {
                let u = (2.0 * h - lo - hi) / (hi - lo);
                f + 4.0 * (1.0 - u * u)
            })
            .collect();
        let rec = GaugeRecord::new(clean.heights_m.clone(), bowed, clean.resolution_n).unwrap();
        let opts = GaugeFitOptions::default();
        let lp = fit_with_effects(&base, ar, &drive, &rec, &opts).unwrap();
        eprintln!(
            "seed {seed}: {:?}; plain {:?}; tried {:?}",
            lp.verdict, lp.residual, lp.tried
        );
        assert_eq!(lp.verdict, GaugeVerdict::Unexplained, "seed {seed}");
        let r = report::gauge_result(&base, &lp, &rec, &opts, "bow");
        assert_eq!(r.residual.verdict.as_deref(), Some("unexplained"));
        assert!(r.residual.joints_withheld.is_some());
        assert!(r.residual.effects.is_empty());
        assert!(
            r.joints
                .iter()
                .all(|j| !j.identifiable && j.status == Status::Unknown)
        );
        assert!(r.combinations.iter().all(|c| c.status == Status::Unknown));
    }
}

/// The report-level pool (`lift::report::fit_pooled_lift_and_gauge_traces`): one lift and one
/// gauge record of the same pantograph; the result is the lift's, its `pooled` block naming both.
#[test]
fn one_lift_and_one_gauge_record_pool_in_the_report() {
    use crate::lift::protocol::{LiftProtocol, record as lift_record};
    use crate::lift::report::{LiftChannels, fit_pooled_lift_and_gauge_traces};
    use crate::lift::sensors::LiftSensorNoise;
    use crate::lift::simulate::SimOptions;
    let (base, _, _) = setup();
    let g = builtin_160ec();
    let clean = lift_record(&base, &LiftProtocol::reference(g), &SimOptions::default()).unwrap();
    let rec = LiftSensorNoise::realistic().apply(&clean, 5);
    let lift = LiftChannels::from(&rec);
    let gauge = record(&base, 5, 0.0, 1.0);
    let gch = GaugeChannels {
        strip_height_m: &gauge.heights_m,
        force_n: &gauge.forces_n,
        resolution_n: gauge.resolution_n,
    };
    let th = DriftThresholds::default();
    let ids = ["lift-1".to_string()];
    let gids = ["gauge-1".to_string()];
    let rep = fit_pooled_lift_and_gauge_traces(&[lift], &ids, &[gch], &gids, 30.0, &th).unwrap();
    let pooled = rep.result.pooled.as_ref().unwrap();
    assert_eq!(pooled.trace_ids, ["lift-1", "gauge-1"]);
    assert_eq!(rep.result.trace_id, "lift-1");
    assert!(rep.fit.gauge_rmse_n[0] < 0.35, "{:?}", rep.fit.gauge_rmse_n);
    assert!(rep.result.joints.iter().all(|j| j.status != Status::Alarm));
    // A lift alone is no pool; a gauge record without an id is refused.
    assert!(fit_pooled_lift_and_gauge_traces(&[lift], &ids, &[], &[], 30.0, &th).is_err());
    assert!(fit_pooled_lift_and_gauge_traces(&[lift], &ids, &[gch], &[], 30.0, &th).is_err());
}

/// Measurement probe (ignored; `cargo test -p pantowatch-models --lib gauge::tests::probe --
/// --ignored --nocapture`): at twice the noise and a coarse gauge, and for small effects, what is
/// named and what is covered. Its figures are in the module doc.
#[test]
#[ignore]
fn probe_noise_and_small_effects() {
    let (base, drive, ar) = setup();
    let truth = drifted(&base, &[(RevJoint::J3, 2.0), (RevJoint::J1, 2.0)]);
    for (sd, q) in [(0.2, 0.1), (0.4, 0.1), (0.4, 0.5)] {
        for (name, m, b, k) in [
            ("baseline", &base, 0.0, 1.0),
            ("J1,J3 x2", &truth, 0.0, 1.0),
            ("b +1 N", &base, 1.0, 1.0),
            ("b +2 N", &base, 2.0, 1.0),
            ("k 1.02", &base, 0.0, 1.02),
            ("k 1.05", &base, 0.0, 1.05),
            ("k 1.1", &base, 0.0, 1.1),
        ] {
            let (mut named, mut covered, mut flagged, mut unexplained) = (0, 0, 0, 0);
            for seed in 500..510 {
                let opts = GaugeSimOptions {
                    seed,
                    noise_sd_n: sd,
                    resolution_n: q,
                    offset_n: b,
                    spring_rate_factor: k,
                };
                let rec =
                    simulate_gauge(m, ar, &drive, &reading_heights(PER_BRANCH), &opts).unwrap();
                let lp =
                    fit_with_effects(&base, ar, &drive, &rec, &GaugeFitOptions::default()).unwrap();
                named += usize::from(matches!(lp.verdict, GaugeVerdict::Named(_)));
                unexplained += usize::from(lp.verdict == GaugeVerdict::Unexplained);
                let c = &lp.fit.combinations[0];
                let level = true_level(c, m, &base);
                covered += usize::from(c.ci95[0] <= level && level <= c.ci95[1]);
                flagged += usize::from(matches!(c.status, Status::Watch | Status::Alarm));
            }
            eprintln!(
                "σ {sd} N, q {q} N, {name}: named {named}/10, unexplained {unexplained}/10, \
                 level covered {covered}/10, flagged {flagged}/10"
            );
        }
    }
}

/// Measurement probe (ignored): how far an offset the loop does not name moves the plain fit's
/// level (σ 0.2 N, seeds 600–604).
#[test]
#[ignore]
fn probe_offset_bias() {
    let (base, drive, ar) = setup();
    for b in [-1.0, 0.5, 1.0, 2.0, 0.0] {
        let mut shift = Vec::new();
        for seed in 600..605 {
            let clean = record(&base, seed, 0.0, 1.0);
            let off = record(&base, seed, b, 1.0);
            let o = GaugeFitOptions {
                fit_offset: std::env::var("GAUGE_PROBE_OFFSET").is_ok(),
                ..GaugeFitOptions::default()
            };
            let f0 = fit_gauge(&base, ar, &drive, &clean, &o).unwrap();
            let f1 = fit_gauge(&base, ar, &drive, &off, &o).unwrap();
            let r = diagnose(&off, &f1.fitted_n, f1.noise_floor_n);
            let c = &f1.combinations[0];
            shift.push(format!(
                "{:+.4} ±{:.3} (excess {:.2}, ρ1 {:.2})",
                c.value - f0.combinations[0].value,
                c.posterior_sd,
                r.excess_ratio,
                r.rho1
            ));
        }
        eprintln!("b {b:+} N: level shift {}", shift.join(", "));
    }
}

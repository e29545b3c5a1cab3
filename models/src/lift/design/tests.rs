use super::*;
use crate::lift::geometry::builtin_160ec;
use crate::lift::sensors::LiftSensorNoise;

#[test]
fn limits_name_the_field_outside_them() {
    let g = builtin_160ec();
    let m = LiftModel::new(g);
    let lim = ProtocolLimits::stand(g);
    let ok = LiftProtocol::raise_and_lower(&m, g).unwrap();
    lim.check(&ok).unwrap();
    let mut p = ok.clone();
    p.moves[0].tau_s = 0.1;
    assert_eq!(lim.check(&p).unwrap_err().field, "moves[0].tau_s");
    let mut p = ok.clone();
    p.moves[0].height_m = Some(2.2);
    assert_eq!(lim.check(&p).unwrap_err().field, "moves[0].height_m");
    let mut p = ok.clone();
    p.moves[0].torque_nm = 5000.0;
    assert_eq!(lim.check(&p).unwrap_err().field, "moves[0].torque_nm");
    let mut p = ok.clone();
    p.t_end_s = 60.0;
    assert_eq!(lim.check(&p).unwrap_err().field, "t_end_s");
    let mut p = ok.clone();
    p.moves.push(Move {
        t_s: 4.0,
        ..p.moves[0]
    });
    assert_eq!(lim.check(&p).unwrap_err().field, "moves[1].t_s");
}

#[test]
fn set_torque_is_continuous_through_every_move() {
    let g = builtin_160ec();
    let mut p = LiftProtocol::reference(g);
    p.moves = vec![
        Move {
            t_s: 3.5,
            torque_nm: 900.0,
            tau_s: 0.4,
            height_m: None,
        },
        Move {
            t_s: 6.0,
            torque_nm: 1000.0,
            tau_s: 2.0,
            height_m: None,
        },
    ];
    for t in [0.0, 3.5, 6.0] {
        let (a, b) = (p.set_torque_nm(t - 1e-9), p.set_torque_nm(t + 1e-9));
        assert!((a - b).abs() < 1e-5, "jump at {t}: {a} → {b}");
    }
    // Each move relaxes to its target: 5 τ after the last, within 1 % of the way left.
    let left = (p.set_torque_nm(6.0) - 1000.0).abs();
    assert!((p.set_torque_nm(16.0) - 1000.0).abs() < 0.01 * left);
    let json = serde_json::to_string(&p).unwrap();
    let back: LiftProtocol = serde_json::from_str(&json).unwrap();
    assert_eq!(back, p);
}

/// Issue 15, point 3: the designed protocol's predicted standard deviations against those its
/// fits realise. The prediction is the design's final one, the simulated-fit spread
/// (`simulated_spread`: `SIMULATED_FITS` lifts, seeds from `SIMULATED_SEED0` = 9000). The
/// realisation: 16 other lifts of the designed protocol at Table 4 with the stand's realistic
/// sensor noise on every channel (H 0.5 mm, T 1 N·m, Fs/Fm 0.2 N, logger steps; seeds
/// 7000–7015, disjoint from the prediction's), each fitted as the service fits a lift. For every
/// parameter the design reports informed (J3, J5, J8 dry), the realised sample sd is within a
/// factor 1.5 of the predicted, both ways. Measured (`examples/lift_design -- 16 [SEED0]`,
/// × Table 4): predicted J3 dry 0.025, J5 dry 0.254, J8 dry 0.092; realised on seeds 7000–7015
/// 0.023, 0.307, 0.091 (0.94×, 1.21×, 0.99×), on 8000–8015 0.024, 0.297, 0.074, on
/// 10000–10015 0.018, 0.346, 0.106 (0.71×, 1.36×, 1.15×: 16 lifts' sd is itself ±18 %).
/// The design beats the raise and lower on its criterion and on J3 dry's linearised sd, and
/// keeps the stand's limits.
#[test]
fn designed_protocol_realises_its_predicted_spread() {
    use crate::lift::identify::fit_map;
    let g = builtin_160ec();
    let m = LiftModel::new(g);
    let lim = ProtocolLimits::stand(g);
    let noise = LiftSensorNoise::realistic();
    let opts = LiftFitOptions::default();
    let d = design(
        &m,
        g,
        &lim,
        &DesignSpace::stand(&lim),
        &noise,
        &opts,
        None,
        &|_, _| {},
    )
    .unwrap();
    lim.check(&d.protocol).unwrap();
    assert!(!d.steps.is_empty());
    let rl = LiftProtocol::raise_and_lower(&m, g).unwrap();
    let a = predict(&m, &rl, &noise, &opts, INPUT_DRAWS).unwrap();
    let b = predict(&m, &d.protocol, &noise, &opts, INPUT_DRAWS).unwrap();
    assert!(b.log_det > a.log_det, "{} vs {}", b.log_det, a.log_det);
    let j3 = LiftParam::named("J3", "dry").unwrap();
    assert!(b.sd_of(j3).unwrap() < a.sd_of(j3).unwrap());
    let sim = simulated_spread(
        &m,
        &d.protocol,
        &b.params,
        &noise,
        &opts,
        SIMULATED_FITS,
        SIMULATED_SEED0,
        None,
        &|_| {},
    )
    .unwrap();
    assert_eq!(sim.failed, 0);
    // The realisation's seeds (7000–7015) are none of the prediction's (9000..).
    let clean = record(&m, &d.protocol, &SimOptions::default()).unwrap();
    let fits: Vec<_> = (0..16u64)
        .map(|seed| {
            let rec = noise.apply(&clean, 7000 + seed);
            fit_map(&m, &[rec.trace()], &opts).unwrap()
        })
        .collect();
    let mut checked = Vec::new();
    for (i, p) in b.params.iter().enumerate() {
        if !b.informed[i] || *p == LiftParam::TorqueOffset {
            continue;
        }
        let xs: Vec<f64> = fits
            .iter()
            .map(|f| {
                let e = f.params.iter().find(|e| e.param == *p).unwrap();
                e.map_value / e.baseline
            })
            .collect();
        let mean = xs.iter().sum::<f64>() / xs.len() as f64;
        let sd =
            (xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (xs.len() - 1) as f64).sqrt();
        let ratio = sd / sim.sd[i];
        eprintln!(
            "{}.{}: predicted {:.3} (linearised {:.3}, Fisher H alone {:.3}), realised {sd:.3} (ratio {ratio:.2})",
            p.joint(),
            p.kind(),
            sim.sd[i],
            b.sd_sampling[i],
            b.sd_h[i]
        );
        assert!(
            (1.0 / 1.5..=1.5).contains(&ratio),
            "{p:?}: predicted {} realised {sd}",
            sim.sd[i]
        );
        checked.push(*p);
    }
    // The design informs J3, J5 and J8 dry (docs/VALIDATION.md, "A designed lift test"): each is checked.
    for (j, kind) in [("J3", "dry"), ("J5", "dry"), ("J8", "dry")] {
        let p = LiftParam::named(j, kind).unwrap();
        assert!(checked.contains(&p), "{j} {kind} not informed: {checked:?}");
    }
}

/// Why no designed test separates J1's dry friction (docs/VALIDATION.md, "A designed lift test"): it is
/// not the test's length or the noise but J2's dry friction, whose friction torque enters H
/// with nearly J1's shape on every move the drive can make. With the H noise alone and the
/// fit's prior, J1's posterior sd stays above 0.1 × Table 4 on every protocol tried, up to a
/// 27.5 s test of six rounds; the same information with J2 dry known to 5 % pins J1 2–5×
/// tighter on the long tests.
#[test]
fn j1_dry_is_held_by_j2_dry_on_every_protocol_tried() {
    let g = builtin_160ec();
    let m = LiftModel::new(g);
    // The stand could run 30 s between duties; the service takes 12 s (`[stand]
    // duration_max_s`, what the fit is validated for). The longer tests are asked here of
    // the information, which needs no fit.
    let lim = ProtocolLimits {
        duration_max_s: 30.0,
        ..ProtocolLimits::stand(g)
    };
    let noise = LiftSensorNoise::realistic();
    let opts = LiftFitOptions::default();
    let j1 = LiftParam::named("J1", "dry").unwrap();
    let j2 = LiftParam::named("J2", "dry").unwrap();
    let protocols = [
        (
            "raise and lower",
            LiftProtocol::raise_and_lower(&m, g).unwrap(),
        ),
        (
            "designed moves",
            rounds_of_moves(&m, g, &[1.424, 1.216], 1.0, 2.0, 1).unwrap(),
        ),
        (
            "designed moves ×6",
            rounds_of_moves(&m, g, &[1.424, 1.216], 1.0, 2.0, 6).unwrap(),
        ),
        (
            "full range, fastest",
            rounds_of_moves(&m, g, &[0.8, 1.84], 0.4, 2.0, 1).unwrap(),
        ),
        (
            "full range ×3",
            rounds_of_moves(&m, g, &[0.8, 1.84], 1.0, 2.0, 3).unwrap(),
        ),
    ];
    for (name, p) in &protocols {
        lim.check(p).unwrap();
        let pr = predict(&m, p, &noise, &opts, 0).unwrap();
        let (i1, i2) = (
            pr.params.iter().position(|q| *q == j1).unwrap(),
            pr.params.iter().position(|q| *q == j2).unwrap(),
        );
        let n = pr.fisher.nrows();
        let post = |j2_known: bool| {
            let mut a = pr.fisher.clone();
            for i in 0..n {
                a[(i, i)] += prior_sd(i, n, &opts).powi(-2);
            }
            if j2_known {
                a[(i2, i2)] += 0.05f64.powi(-2);
            }
            inverse_spd(&a)[(i1, i1)].sqrt()
        };
        let (alone, with_j2) = (post(false), post(true));
        eprintln!(
            "{name} ({:.1} s): J1 dry sd {alone:.3}, with J2 dry known {with_j2:.3}",
            p.t_end_s
        );
        assert!((alone - pr.sd_h[i1]).abs() < 1e-9 * alone.max(1.0));
        assert!(alone > 0.1, "{name}: J1 dry sd {alone}");
        if p.t_end_s > 15.0 {
            assert!(with_j2 < alone / 2.0, "{name}: {with_j2} vs {alone}");
        }
    }
}

/// A J1 ×3 drift on the designed moves reads in the J1+J3 level, never in J1 or J3 alone:
/// fitted alone, J1 read 0.9–2.5 × Table 4 over six seeds with a linearised sd of 0.12 (truth
/// 3; `examples/lift_long_protocols`), the level 1.26–1.30 (truth 1.26). The same on two
/// rounds of them (11.5 s) on seeds whose fits failed before the time continuation
/// (`lift::identify`: the integrator's step underflow at 11.3–11.4 s).
#[test]
fn a_j1_drift_on_the_designed_moves_shows_in_the_level_not_in_j1() {
    use crate::lift::identify::fit_map;
    let g = builtin_160ec();
    let m = LiftModel::new(g);
    let noise = LiftSensorNoise::realistic();
    let opts = LiftFitOptions::default();
    let j1 = LiftParam::named("J1", "dry").unwrap();
    let j3 = LiftParam::named("J3", "dry").unwrap();
    let mut worn = m.clone();
    let mut off = 0.0;
    j1.set(&mut worn, &mut off, 3.0 * j1.get(&m, 0.0));
    for (rounds, seeds) in [(1, 5000..5004u64), (2, 6000..6002)] {
        let p = rounds_of_moves(&m, g, &[1.424, 1.216], 1.0, 2.0, rounds).unwrap();
        ProtocolLimits::stand(g).check(&p).unwrap();
        let clean = record(&worn, &p, &SimOptions::default()).unwrap();
        for seed in seeds {
            let rec = noise.apply(&clean, seed);
            let fit = fit_map(&m, &[rec.trace()], &opts).unwrap();
            let e = |q: LiftParam| fit.params.iter().find(|e| e.param == q).unwrap();
            let at = format!("{rounds} rounds, seed {seed}");
            assert!(!e(j1).informed && !e(j3).informed, "{at}");
            let c = &fit.combinations[e(j1).combination.expect("J1 in a combination")];
            assert_eq!(e(j3).combination, e(j1).combination);
            let truth: f64 = c
                .params
                .iter()
                .zip(&c.weights)
                .map(|(q, w)| if *q == j1 { 3.0 * w } else { *w })
                .sum();
            assert!(c.informed, "{at}");
            assert!(
                (c.ci95[0]..=c.ci95[1]).contains(&truth),
                "{at}: level {} {:?}, truth {truth}",
                c.value,
                c.ci95
            );
            // The drift shows: the level's interval lies above baseline.
            assert!(c.ci95[0] > 1.0, "{at}: {:?}", c.ci95);
        }
    }
}

/// Issue 36, point 6: the design says what the fit will report. On the designed moves the
/// Fisher information informs J3, J5 and J8 dry, but a lift's fit reports only the J1+J3 dry
/// level (`SimulatedSpread::reported`, printed by `design-test` as "fit rep."); J5 and J8 are
/// never judged by such a lift. A J5 dry ×2.5 drift is not detectable by it (the reported-only
/// refit stays at the noise): nothing is flagged, J5 stays unidentified, the level moves ~6 %. And a clean designed lift names no effect
/// (it named a false 8 mm `sensor_offset` before: an offset is not tried where the fit reports
/// a level, `report::fit_lift_trace`).
#[test]
fn the_design_says_what_the_fit_reports() {
    use crate::contract::drift::{DriftThresholds, Status};
    use crate::lift::report::{LiftChannels, fit_lift_trace};
    let g = builtin_160ec();
    let m = LiftModel::new(g);
    let p = rounds_of_moves(&m, g, &[1.424, 1.216], 1.0, 2.0, 1).unwrap();
    let opts = LiftFitOptions::default();
    let noise = LiftSensorNoise::realistic();
    let s = simulated_spread(
        &m,
        &p,
        &opts.friction_params,
        &noise,
        &opts,
        6,
        SIMULATED_SEED0,
        None,
        &|_| {},
    )
    .unwrap();
    let share = |j: &str| {
        let q = LiftParam::named(j, "dry").unwrap();
        let i = s.params.iter().position(|x| *x == q).unwrap();
        (s.reported[i], s.reported_in[i].clone())
    };
    for j in ["J1", "J3"] {
        let (sh, within) = share(j);
        assert!(sh >= 0.5, "{j}: {sh}");
        assert_eq!(within.as_deref(), Some("J1+J3 dry"), "{j}");
    }
    for j in ["J5", "J8"] {
        assert_eq!(share(j).0, 0.0, "{j} is not reported by the fit");
    }
    let mut j5 = m.clone();
    let q = LiftParam::named("J5", "dry").unwrap();
    q.set(&mut j5, &mut 0.0, 2.5 * q.get(&m, 0.0));
    for (model, seed, drifted) in [(&m, 7100u64, false), (&m, 7101, false), (&j5, 7102, true)] {
        let clean = record(model, &p, &SimOptions::default()).unwrap();
        let rec = noise.apply(&clean, seed);
        let r = fit_lift_trace(&LiftChannels::from(&rec), &DriftThresholds::default(), "d")
            .unwrap()
            .result;
        eprintln!(
            "seed {seed} J5 drifted {drifted}: effects {:?} verdict {:?} check {:?}",
            r.residual.effects, r.residual.verdict, r.fit.absorption
        );
        assert!(r.residual.effects.is_empty(), "{:?}", r.residual.effects);
        for j in &r.joints {
            assert!(!matches!(j.status, Status::Watch | Status::Alarm), "{j:?}");
            if j.joint == "J5" || j.joint == "J8" {
                assert!(!j.identifiable, "{j:?}");
            }
        }
        // Clean: the level holds Table 4. With J5 ×2.5 the reported-only refit left 0.89× the
        // noise (not detectable), and the level read 1.057 [1.002, 1.115]: a J5 drift leans on
        // the J1+J3 level by ~6 %, inside the watch band, unflagged (the `no flag` above) —
        // what the design's "fit rep." column tells the user: J5 is not judged by this test.
        if let Some(c) = r
            .combinations
            .iter()
            .find(|c| c.label == "J1+J3 dry" && c.identifiable)
        {
            if drifted {
                assert!(c.value < 1.1 && c.ci95[0] > 0.9, "{c:?}");
            } else {
                assert!(c.ci95[0] <= 1.0 && 1.0 <= c.ci95[1], "{c:?}");
            }
        }
    }
}

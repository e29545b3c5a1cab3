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
    // The design informs J3, J5 and J8 dry (README, "A designed lift test"): each is checked.
    for (j, kind) in [("J3", "dry"), ("J5", "dry"), ("J8", "dry")] {
        let p = LiftParam::named(j, kind).unwrap();
        assert!(checked.contains(&p), "{j} {kind} not informed: {checked:?}");
    }
}

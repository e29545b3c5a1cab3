use super::*;
use crate::data::builtin_160ec;
use crate::joint::dynamics::{Dof, Mechanism};
use crate::joint::identify::Readout;
use crate::joint::rig::PendulumRig;
use crate::joint::synth::{Sensor, Truth, grid, measure_truth};
use crate::numerics::noise::Noise;

const DEG: f64 = 180.0 / std::f64::consts::PI;

#[test]
fn release_from_rest_is_the_first_sample_and_a_carried_start_is_its_turning_point() {
    let period = 2.0 * std::f64::consts::PI / 11.0;
    let t: Vec<f64> = (0..2000).map(|i| i as f64 * 0.001).collect();
    let mut rng = Noise::new(1);
    // From rest, with noise at the start (the case that fooled a short window).
    let at_rest: Vec<f64> = t
        .iter()
        .map(|x| 40.0 * (11.0 * x).cos() + 0.05 * rng.normal())
        .collect();
    let r = find_release(&t, &at_rest, period);
    assert_eq!(
        (r.index, r.rule, r.warning),
        (0, ReleaseRule::FirstSample, None)
    );
    // Carried: starts mid-swing, turning point at 11 t + 1 = π → t = 0.1947 s.
    let carried: Vec<f64> = t
        .iter()
        .map(|x| 40.0 * (11.0 * x + 1.0).cos() + 0.05 * rng.normal())
        .collect();
    let r = find_release(&t, &carried, period);
    assert_eq!(r.rule, ReleaseRule::TurningPoint);
    assert!(
        (t[r.index] - (std::f64::consts::PI - 1.0) / 11.0).abs() < 0.005,
        "release at {}",
        t[r.index]
    );
}

/// What the hand does before it lets go.
#[derive(Debug, Clone, Copy)]
enum Hand {
    /// The trace starts at the release.
    None,
    /// Holds the rod at the release angle for this long (s), with a 6 Hz, 0.1° tremor.
    Hold(f64),
    /// Lifts it the last 25° to the release angle over this long (s), arriving at rest.
    Carry(f64),
}

/// A J3 pendulum (the paper's rig, Table 4 friction) released by hand at `release_deg`: the
/// hand's part, then the free swing, read at 500 Hz with 0.05° noise and 0.01° steps.
/// Returns t, α and the true release time.
fn by_hand(release_deg: f64, hand: Hand, seed: u64) -> (Vec<f64>, Vec<f64>, f64, f64) {
    let data = builtin_160ec();
    let rig = PendulumRig::paper_default(data, "J3").unwrap();
    let jd = data.joint("J3").unwrap();
    let dof = Dof {
        mech: Mechanism::Pendulum(rig),
        input: None,
        torsion: 0.0,
    };
    let truth = Truth {
        law: crate::joint::friction::FrictionLaw::base(jd.viscous_baseline(), jd.dry_mu),
        readout: Readout::default(),
        dry_fade: 0.0,
    };
    let sensor = Sensor {
        scale: DEG,
        noise_sigma: 0.05,
        quantum: 0.01,
        offset: 0.0,
        seed,
    };
    let free_t = grid(12.0, 500.0);
    let free = measure_truth(&dof, &truth, release_deg / DEG, 0.0, &free_t, &sensor).unwrap();
    let hand_s = match hand {
        Hand::None => 0.0,
        Hand::Hold(s) | Hand::Carry(s) => s,
    };
    let mut rng = Noise::new(seed + 1000);
    let mut t = Vec::new();
    let mut y = Vec::new();
    for k in 0..(hand_s * 500.0).round() as usize {
        let tk = k as f64 / 500.0;
        let a = match hand {
            Hand::Hold(_) | Hand::None => {
                release_deg + 0.1 * (2.0 * std::f64::consts::PI * 6.0 * tk).sin()
            }
            Hand::Carry(s) => {
                release_deg - 25.0 * (1.0 + (std::f64::consts::PI * tk / s).cos()) / 2.0
            }
        };
        t.push(tk);
        y.push(((a + 0.05 * rng.normal()) / 0.01).round() * 0.01);
    }
    let t_release = t.len() as f64 / 500.0;
    for (tk, yk) in free_t.iter().zip(&free) {
        t.push(t_release + tk);
        y.push(*yk);
    }
    (t, y, t_release, dof.period_s(12.0))
}

/// Issue 17, point 2: releases by hand at 45°, 90° and 135° — the trace starting at the
/// release, a hold of 0.15–0.6 s, a carry of 0.2–0.4 s (the 90° case that fooled the fixed
/// 0.4-period window let go at 0.23–0.24 s) — are found within 15 ms or reported with a
/// warning, never silently wrong; a trace that starts at its release reads as such, quietly.
#[test]
fn a_release_by_hand_is_found_or_warned_never_silently_wrong() {
    let mut found = 0;
    let mut warned = 0;
    let mut seed = 40;
    for release_deg in [45.0, 90.0, 135.0] {
        for hand in [
            Hand::None,
            Hand::Hold(0.15),
            Hand::Hold(0.6),
            Hand::Carry(0.2),
            Hand::Carry(0.235),
            Hand::Carry(0.4),
        ] {
            seed += 1;
            let (t, y, t_true, period) = by_hand(release_deg, hand, seed);
            let r = find_release(&t, &y, period);
            let err = t[r.index] - t_true;
            eprintln!(
                "{release_deg}° {hand:?}: release {:.3} s (true {t_true:.3}, {:+.1} ms) {:?} {:?}",
                t[r.index],
                1e3 * err,
                r.rule,
                r.warning
            );
            match &r.warning {
                None => {
                    assert!(
                        err.abs() <= 0.015,
                        "{release_deg}° {hand:?}: silently {:.1} ms off",
                        1e3 * err
                    );
                    found += 1;
                }
                Some(w) => {
                    assert!(w.contains("test.release_t_s"), "{w}");
                    warned += 1;
                }
            }
            if matches!(hand, Hand::None) {
                assert_eq!((r.index, r.warning.as_deref()), (0, None), "{release_deg}°");
            }
        }
    }
    eprintln!("found {found}, warned {warned}");
    assert!(found >= 15, "found {found} of 18 ({warned} warned)");
    // A slow hand: 25° over 1.5 s, as long as a free half-swing of J3 but a quarter of its
    // size or less. Where its motion counts as motion (above 10 % of the peak rate: at 45° and
    // 90°) it is no free swing, the release is its turning point and the result says so; at
    // 135° it is slow beside the swing and reads as a hold.
    for release_deg in [45.0, 90.0, 135.0] {
        let (t, y, t_true, period) = by_hand(release_deg, Hand::Carry(1.5), 77);
        let r = find_release(&t, &y, period);
        eprintln!(
            "{release_deg}° slow: {:.3} (true {t_true:.3}) {:?}",
            t[r.index], r.warning
        );
        assert!((t[r.index] - t_true).abs() <= 0.015, "{}", t[r.index]);
        if release_deg < 100.0 {
            assert_eq!(r.rule, ReleaseRule::TurningPoint);
            let w = r.warning.expect("a slow hand is reported");
            assert!(
                w.contains("not free") && w.contains("test.release_t_s"),
                "{w}"
            );
        }
    }
}

#[test]
fn a_stated_release_is_the_first_sample_at_or_after_it() {
    let t: Vec<f64> = (0..100).map(|i| i as f64 * 0.01).collect();
    assert_eq!(stated_release(&t, 0.0, 20), Some(0));
    assert_eq!(stated_release(&t, 0.255, 20), Some(26));
    assert_eq!(stated_release(&t, 0.99, 20), None);
    assert_eq!(stated_release(&t, -0.1, 20), None);
    assert_eq!(stated_release(&t, f64::NAN, 20), None);
}

//! The disturbed-release rule on simulated releases (free, and held back by a decaying torque)
//! read at the stand's noise, and on the real encoder pendulum at 45° and 90°.

use super::*;
use crate::contract::drift::DriftThresholds;
use crate::contract::testspec::Baseline;
use crate::data::builtin_160ec;
use crate::joint::dynamics::{Dof, Input, Mechanism};
use crate::joint::friction::FrictionLaw;
use crate::joint::identify::release::{ReleaseRule, find_release};
use crate::joint::identify::{FitOptions, JointTest, Readout, release_of};
use crate::joint::rig::PendulumRig;
use crate::joint::synth::{Sensor, Truth, grid, measure_truth};

const DEG: f64 = 180.0 / std::f64::consts::PI;

#[test]
fn elliptic_k_matches_known_values() {
    // K(0) = π/2; K(sin 45°) = 1.854075 (Abramowitz & Stegun, Table 17.1).
    assert!((ellipk(0.0) - std::f64::consts::FRAC_PI_2).abs() < 1e-14);
    assert!((ellipk(std::f64::consts::FRAC_1_SQRT_2) - 1.854_074_677).abs() < 1e-8);
    // The ideal pendulum at 90°: T/T₀ = 1.18034.
    let f = Restoring::Gravity.period_factor(std::f64::consts::FRAC_PI_2);
    assert!((f - 1.180_34).abs() < 1e-4, "{f}");
}

/// The encoder pendulum of `../shared/data/measured` as its trace states it (a 0.1 kg rod,
/// J/(m·d) = 0.0824 m, a 2 mm pin): a small, fast rig, period 0.576 s.
fn rod() -> PendulumRig {
    PendulumRig {
        mass_kg: 0.1,
        inertia_kgm2: 0.000_618_32,
        com_distance_m: 0.075,
        pin_radius_m: 0.002,
        gravity_m_s2: 9.81,
    }
}

/// The rod's friction as fitted from its 45° recording (μ 0.74, D 4·10⁻⁵ N·m·s/rad).
fn rod_law() -> FrictionLaw {
    FrictionLaw::base(4e-5, 0.74)
}

/// A pendulum released from rest at `release_deg`, held back for `hold_s` by a torque against
/// gravity of `strength` × the gravity torque at the release, decaying as (1 − t/hold)², read at
/// the stand's noise (0.05° white, 0.01° steps) at 500 Hz for 10 small-amplitude periods.
fn held_release(
    rig: PendulumRig,
    law: FrictionLaw,
    release_deg: f64,
    hold_s: f64,
    strength: f64,
    seed: u64,
) -> JointTest {
    held_release_with(rig, law, release_deg, hold_s, strength, seed, Other::None)
}

/// Physics the vocabulary of the identified model lacks, simulated on top of a release.
#[derive(Debug, Clone, Copy)]
enum Other {
    None,
    /// A torsional spring in the joint, stiffness × the gravity stiffness m·g·d.
    Torsion(f64),
    /// Dry friction fading linearly by this share over the record.
    Fade(f64),
}

fn held_release_with(
    rig: PendulumRig,
    law: FrictionLaw,
    release_deg: f64,
    hold_s: f64,
    strength: f64,
    seed: u64,
    other: Other,
) -> JointTest {
    let mgd = rig.mass_kg * rig.gravity_m_s2 * rig.com_distance_m;
    let dof = Dof {
        mech: Mechanism::Pendulum(rig),
        input: None,
        torsion: match other {
            Other::Torsion(k) => k * mgd,
            _ => 0.0,
        },
    };
    let period = dof.period_s(1.0);
    let t = grid(10.0 * period, 500.0);
    let a0 = release_deg / DEG;
    let hold_nm = strength * rig.mass_kg * rig.gravity_m_s2 * rig.com_distance_m * a0.sin();
    let value: Vec<f64> = t
        .iter()
        .map(|&x| {
            if hold_s > 0.0 && x < hold_s {
                hold_nm * (1.0 - x / hold_s).powi(2)
            } else {
                0.0
            }
        })
        .collect();
    let driven = Dof {
        input: Some(Input {
            t_s: t.clone(),
            value,
        }),
        ..dof.clone()
    };
    let truth = Truth {
        law,
        readout: Readout::default(),
        dry_fade: match other {
            Other::Fade(f) => f,
            _ => 0.0,
        },
    };
    let sensor = Sensor {
        scale: DEG,
        noise_sigma: 0.05,
        quantum: 0.01,
        offset: 0.0,
        seed,
    };
    let y = measure_truth(&driven, &truth, a0, 0.0, &t, &sensor).expect("simulates");
    JointTest {
        dof: Dof {
            torsion: 0.0,
            ..dof
        },
        t_s: t,
        y,
        scale: DEG,
        unit: "deg",
        initial_rate: None,
        release_t_s: None,
        body_sd: Vec::new(),
    }
}

/// Issue 36, point 4: a free release is never cut. The seven paper rigs and the rod, released
/// from 20° to 135°, friction at 0.3×, 1× and 3× Table 4 (the rod: of its 45° fit), at the
/// stand's noise: no first half-swing is flagged, and the check could be made on nearly all.
#[test]
fn free_releases_are_not_flagged() {
    let data = builtin_160ec();
    let mut rigs: Vec<(String, PendulumRig, FrictionLaw)> =
        ["J1", "J2", "J3", "J4", "J5", "J6", "J7"]
            .iter()
            .map(|j| {
                let jd = data.joint(j).expect("joint");
                (
                    j.to_string(),
                    PendulumRig::paper_default(data, j).expect("rig"),
                    FrictionLaw::base(jd.viscous_baseline(), jd.dry_mu),
                )
            })
            .collect();
    rigs.push(("rod".into(), rod(), rod_law()));
    let (mut checked, mut total) = (0, 0);
    let (mut max_e, mut max_p) = (0.0f64, 0.0f64);
    let mut seed = 9000;
    for noise in [1.0, 2.0] {
        for (name, rig, law) in &rigs {
            for release_deg in [20.0, 45.0, 90.0, 135.0] {
                for scale in [0.3, 1.0, 3.0] {
                    seed += 1;
                    let law = FrictionLaw::base(law.viscous * scale, law.dry * scale);
                    let mut test = held_release(*rig, law, release_deg, 0.0, 0.0, seed);
                    if noise > 1.0 {
                        // Twice the stand's noise: a second, independent draw of the same size.
                        let mut rng = crate::numerics::noise::Noise::new(seed + 77);
                        for y in &mut test.y {
                            *y = ((*y + 0.05 * rng.normal()) / 0.01).round() * 0.01;
                        }
                    }
                    let r = release_of(&test).expect("release");
                    total += 1;
                    let c = check_first_swing(
                        &test.t_s,
                        &test.y,
                        DEG,
                        find_release(&test.t_s, &test.y, test.dof.period_s(1.0)).index,
                        test.dof.period_s(1.0),
                        Restoring::Gravity,
                    );
                    if let Some(c) = &c {
                        checked += 1;
                        max_e = max_e.max(c.energy_ratio);
                        max_p = max_p.max(c.period_ratio);
                    }
                    assert_ne!(
                        r.rule,
                        ReleaseRule::Disturbed,
                        "{name} {release_deg}° ×{scale} noise ×{noise}: a free release cut: {:?}",
                        r.disturbance
                    );
                }
            }
        }
    }
    eprintln!(
        "free releases: {checked}/{total} checked, max energy ratio {max_e:.2}, max period ratio {max_p:.3}"
    );
    assert!(checked * 10 >= total * 8, "checked {checked} of {total}");
    assert!(max_e < ENERGY_RATIO && max_p < PERIOD_RATIO);
}

/// Issue 36, point 4: releases held back by a decaying torque for 0.1–0.4 s. Every hold that
/// matters — whose fit from the first motion leaves the dry friction's interval off the truth —
/// is found; where found, the fit starts at a turning point after the hold and its interval
/// holds the truth in at least 90 % of cases.
#[test]
fn held_releases_are_found_and_fitted_from_the_free_swing() {
    let mut rows = Vec::new();
    let (mut mattered, mut found_of_mattered, mut found, mut covered) = (0, 0, 0, 0);
    let mut seed = 9500;
    let baseline = Baseline {
        joint: "custom".into(),
        viscous: None,
        dry: None,
        viscous_unit: "N·m·s/rad",
    };
    let th = DriftThresholds::default();
    let opts = FitOptions::default();
    for release_deg in [45.0, 90.0, 135.0] {
        for hold_s in [0.1, 0.2, 0.3, 0.4] {
            for strength in [0.5, 0.9] {
                seed += 1;
                let test = held_release(rod(), rod_law(), release_deg, hold_s, strength, seed);
                let truth = rod_law().dry;
                let (res, _) =
                    crate::fit_joint_test(&test, &baseline, &th, "held", &opts).expect("fits");
                let dry = &res.joints[0].dry;
                let holds = dry.ci95[0] <= truth && truth <= dry.ci95[1];
                // The same record fitted from its first motion, as before the rule.
                let start = find_release(&test.t_s, &test.y, test.dof.period_s(1.0)).index;
                let plain = JointTest {
                    release_t_s: Some(test.t_s[start]),
                    ..test.clone()
                };
                let (res0, _) =
                    crate::fit_joint_test(&plain, &baseline, &th, "held", &opts).expect("fits");
                let dry0 = &res0.joints[0].dry;
                let held0 = dry0.ci95[0] <= truth && truth <= dry0.ci95[1];
                let cut = res.fit.release_rule == "disturbed";
                if cut {
                    found += 1;
                    covered += usize::from(holds);
                    let until = res.fit.release_disturbed_until_s.expect("until");
                    assert!(until > hold_s * 0.5, "cut at {until} s, hold {hold_s} s");
                }
                if !held0 {
                    mattered += 1;
                    found_of_mattered += usize::from(cut);
                }
                rows.push(format!(
                    "{release_deg:>5}° hold {hold_s:.1} s ×{strength}: from first motion μ {:.3} [{:.3}, {:.3}]; \
                     {} μ {:.3} [{:.3}, {:.3}]",
                    dry0.value,
                    dry0.ci95[0],
                    dry0.ci95[1],
                    if cut {
                        format!("cut to {:.3} s", res.fit.release_disturbed_until_s.unwrap_or(0.0))
                    } else {
                        "not cut".into()
                    },
                    dry.value,
                    dry.ci95[0],
                    dry.ci95[1]
                ));
            }
        }
    }
    for r in &rows {
        eprintln!("{r}");
    }
    eprintln!(
        "held releases: {found}/{} cut, {covered} of those cover μ; {found_of_mattered}/{mattered} of the holds that bias a fit from the first motion found",
        rows.len()
    );
    assert_eq!(
        found_of_mattered, mattered,
        "a hold that biases the fit was missed"
    );
    assert!(
        mattered >= 6,
        "the set must contain holds that matter ({mattered})"
    );
    assert!(
        covered * 10 >= found * 9,
        "{covered} of {found} cut fits cover the truth"
    );
}

/// Issue 36, point 4: physics outside the model's vocabulary does not read as a disturbed
/// release. The rod and J3 released from rest at 45°, 90° and 135° with Stribeck friction,
/// quadratic drag, direction-dependent friction, a torsional spring (±30 % of gravity's
/// stiffness) or friction fading by 40 % over the record, each at the stand's noise.
#[test]
fn effects_outside_the_vocabulary_are_not_a_disturbed_release() {
    let data = builtin_160ec();
    let jd = data.joint("J3").expect("J3");
    let j3 = (
        PendulumRig::paper_default(data, "J3").expect("rig"),
        FrictionLaw::base(jd.viscous_baseline(), jd.dry_mu),
    );
    let mut seed = 9700;
    let mut n = 0;
    for (rig, base) in [(rod(), rod_law()), j3] {
        let variants: Vec<(&str, FrictionLaw, Other)> = vec![
            (
                "stribeck",
                FrictionLaw {
                    stribeck: Some(crate::joint::friction::Stribeck {
                        ratio: 1.6,
                        speed: 0.3,
                    }),
                    ..base
                },
                Other::None,
            ),
            (
                "drag",
                FrictionLaw {
                    quadratic_drag: Some(base.viscous * 5.0 + 1e-5),
                    ..base
                },
                Other::None,
            ),
            (
                "asymmetry",
                FrictionLaw {
                    asymmetry: 0.4,
                    ..base
                },
                Other::None,
            ),
            ("stiffer", base, Other::Torsion(0.3)),
            ("softer", base, Other::Torsion(-0.3)),
            ("fade", base, Other::Fade(0.4)),
        ];
        for (name, law, other) in variants {
            for release_deg in [45.0, 90.0, 135.0] {
                seed += 1;
                let test = held_release_with(rig, law, release_deg, 0.0, 0.0, seed, other);
                let r = release_of(&test).expect("release");
                n += 1;
                assert_ne!(
                    r.rule,
                    ReleaseRule::Disturbed,
                    "{name} {release_deg}°: cut: {:?}",
                    r.disturbance
                );
            }
        }
    }
    assert_eq!(n, 36);
}

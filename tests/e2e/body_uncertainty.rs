//! A rig's stated body uncertainty in the friction intervals (issue 17, point 1): the
//! linearised propagation (`identify::body_uncertainty`) checked against refitting, and the
//! intervals' coverage over pendulums whose true inertia is off the stated one by the stated sd.

use pantowatch_models::data::builtin_160ec;
use pantowatch_models::dynamics::{Dof, Mechanism};
use pantowatch_models::friction::{DynParam, FrictionLaw};
use pantowatch_models::identify::{
    FitOptions, FitOutcome, JointTest, Param, carry_body_uncertainty, fit_base,
};
use pantowatch_models::noise::Noise;
use pantowatch_models::rig::{BodySpec, BodyUncertainty, PendulumRig};
use pantowatch_models::synth::{Sensor, grid, measure};
use pantowatch_models::testspec::PendulumSpec;

const DEG: f64 = 180.0 / std::f64::consts::PI;

/// A pendulum test of `joint` on the paper's rig, stated as its lumped body (mass, inertia
/// about the pin and centre-of-mass distance of body and attachments together) with the
/// inertia's uncertainty `inertia_sd` × the inertia (None: not stated), whose true inertia is
/// (1 + `inertia_off`) × the stated one; the stand's sensor (0.05° noise, 0.01° steps), 15 s at
/// 500 Hz.
fn pendulum(
    joint: &str,
    law: &FrictionLaw,
    release_deg: f64,
    inertia_off: f64,
    inertia_sd: Option<f64>,
    seed: u64,
) -> JointTest {
    let sd = inertia_sd.map(|sd| [0.0, sd]);
    pendulum_body(joint, law, release_deg, [0.0, inertia_off], sd, seed)
}

/// As [`pendulum`], the true body's mass and inertia (1 + `off[0]`, 1 + `off[1]`) × the
/// stated ones, and the rig stating their uncertainties `sd` × the stated values.
fn pendulum_body(
    joint: &str,
    law: &FrictionLaw,
    release_deg: f64,
    off: [f64; 2],
    sd: Option<[f64; 2]>,
    seed: u64,
) -> JointTest {
    let data = builtin_160ec();
    let rig = PendulumRig::paper_default(data, joint).unwrap();
    let truth = Dof {
        mech: Mechanism::Pendulum(PendulumRig {
            mass_kg: rig.mass_kg * (1.0 + off[0]),
            inertia_kgm2: rig.inertia_kgm2 * (1.0 + off[1]),
            ..rig
        }),
        input: None,
        torsion: 0.0,
    };
    let t = grid(15.0, 500.0);
    let sensor = Sensor {
        scale: DEG,
        noise_sigma: 0.05,
        quantum: 0.01,
        offset: 0.0,
        seed,
    };
    let (y, _) = measure(&truth, law, release_deg / DEG, 0.0, &t, &sensor).unwrap();
    let stated = |frac: f64, v: f64| (frac > 0.0).then_some(frac * v);
    let spec = PendulumSpec {
        joint: joint.into(),
        body: Some(BodySpec {
            mass_kg: rig.mass_kg,
            inertia_kgm2: rig.inertia_kgm2,
            com_distance_m: rig.com_distance_m,
        }),
        attachments: Some(Vec::new()),
        body_uncertainty: sd.map(|[m, j]| BodyUncertainty {
            mass_sd_kg: stated(m, rig.mass_kg),
            inertia_sd_kgm2: Some(j * rig.inertia_kgm2),
            com_distance_sd_m: None,
        }),
        ..Default::default()
    };
    spec.joint_test(Some(data), t, y).unwrap().0
}

/// The base model's fit with the stated body uncertainty carried (as a reported fit has it).
fn fit_carried(test: &JointTest, opts: &FitOptions) -> FitOutcome {
    carry_body_uncertainty(test, fit_base(test, opts).unwrap(), opts)
}

fn value(fit: &FitOutcome, p: DynParam) -> (f64, [f64; 2]) {
    let (v, _, ci) = fit.get(Param::Dyn(p)).unwrap();
    (v, ci)
}

/// The propagated shift per sd against refitting: traces of J3 and J5 made with the true body
/// inertia 1 sd above and below the stated one (same noise), fitted with the stated rig; half
/// the difference of the estimates is the shift a 1 sd error makes, which the propagation
/// (from the fit at the stated inertia) predicts within 15 % for μ and D.
#[test]
fn the_propagated_shift_matches_refitting_with_the_body_off_by_one_sd() {
    let opts = FitOptions::default();
    let mut report = Vec::new();
    for (joint, seed) in [("J1", 6u64), ("J3", 7u64), ("J5", 8), ("J7", 9)] {
        let jd = builtin_160ec().joint(joint).unwrap();
        let law = FrictionLaw::base(jd.viscous_baseline(), jd.dry_mu);
        let sd = 0.02;
        let at = |off: f64| fit_carried(&pendulum(joint, &law, 60.0, off, Some(sd), seed), &opts);
        let (mid, up, down) = (at(0.0), at(sd), at(-sd));
        let carried = &mid.body_uncertainty;
        assert_eq!(carried.len(), 1, "{carried:?}");
        assert!(carried[0].propagated && carried[0].quantity == "inertia_kgm2");
        for p in [DynParam::Viscous, DynParam::Dry] {
            let i = mid
                .spec_params
                .iter()
                .position(|x| *x == Param::Dyn(p))
                .unwrap();
            let predicted = carried[0].shift_per_sd[i];
            let refitted = 0.5 * (value(&up, p).0 - value(&down, p).0);
            let rel = predicted / refitted - 1.0;
            report.push(format!(
                "{joint} {p:?}: propagated {predicted:.4e} per sd, refitted {refitted:.4e} ({:+.1} %)",
                100.0 * rel
            ));
            assert!(rel.abs() < 0.15, "{report:#?}");
        }
    }
    eprintln!("{report:#?}");
}

/// Coverage over a set: 16 pendulums (J3 and J5, 8 seeds each, random friction around
/// Table 4, random release 50–80°) whose true body inertia is drawn off the stated one with sd
/// 2 %, the rig stating that 2 %. The base fit's 95 % intervals of μ and D are counted with
/// the propagation and without it (the same fit, the uncertainty not stated). A stated
/// uncertainty of 0 leaves the fit bit-identical.
#[test]
fn a_stated_inertia_uncertainty_keeps_the_friction_intervals_honest() {
    let opts = FitOptions::default();
    let mut rng = Noise::new(1717);
    let (mut with, mut without, mut total) = (0, 0, 0);
    let mut lines = Vec::new();
    let (mut reported, mut reported_without, mut inertia_named) = (0, 0, 0);
    let thresholds = pantowatch_models::drift::DriftThresholds::default();
    for i in 0..16u64 {
        let joint = if i % 2 == 0 { "J3" } else { "J5" };
        let jd = builtin_160ec().joint(joint).unwrap();
        let law = FrictionLaw::base(
            jd.viscous_baseline() * (0.7 + 0.8 * rng.uniform()),
            jd.dry_mu * (0.7 + 0.8 * rng.uniform()),
        );
        let release_deg = 50.0 + 30.0 * rng.uniform();
        let sd = 0.02;
        let off = sd * rng.normal();
        let stated = fit_carried(
            &pendulum(joint, &law, release_deg, off, Some(sd), 300 + i),
            &opts,
        );
        let plain = fit_carried(
            &pendulum(joint, &law, release_deg, off, None, 300 + i),
            &opts,
        );
        // The whole pipeline (the residual loop may name `inertia_error` and report its fit).
        let whole = |sd: Option<f64>| {
            let test = pendulum(joint, &law, release_deg, off, sd, 300 + i);
            let b = pantowatch_models::testspec::Baseline {
                joint: joint.into(),
                viscous: None,
                dry: None,
                viscous_unit: "N·m·s/rad",
            };
            pantowatch_models::fit_joint_test_with_finding(&test, &b, &thresholds, "t", &opts)
                .unwrap()
                .0
        };
        let (r_with, r_without) = (whole(Some(sd)), whole(None));
        // Named, `inertia_error` estimates J: the stated inertia is then not added again. So
        // too when the record is ambiguous (issue 36, point 3) and read with `inertia_error`:
        // the vocabulary explanation with the lowest BIC, whose fit is reported.
        let read_with = r_with.residual.ambiguity.as_ref().and_then(|a| {
            a.explanations
                .iter()
                .filter(|e| e.in_vocabulary)
                .min_by(|x, y| x.delta_bic.total_cmp(&y.delta_bic))
        });
        let named = r_with
            .residual
            .effects
            .iter()
            .any(|e| e.name == "inertia_error")
            || read_with.is_some_and(|e| e.name.split('+').any(|n| n == "inertia_error"));
        let echo = r_with.fit.body_uncertainty.as_ref().expect("echoed");
        let (carried, left) = (
            echo.propagated.contains_key("inertia_kgm2"),
            echo.not_propagated.contains_key("inertia_kgm2"),
        );
        assert_eq!((carried, left), (!named, named), "{joint} #{i}: {echo:?}");
        inertia_named += usize::from(named);
        for (r, n) in [
            (&r_with, &mut reported),
            (&r_without, &mut reported_without),
        ] {
            let j = &r.joints[0];
            let holds = |ci: [f64; 2], v: f64| ci[0] <= v && v <= ci[1];
            *n += usize::from(holds(j.dry.ci95, law.dry))
                + usize::from(holds(j.viscous.ci95, law.viscous));
        }
        for (p, truth) in [(DynParam::Viscous, law.viscous), (DynParam::Dry, law.dry)] {
            let holds = |f: &FitOutcome| {
                let (_, ci) = value(f, p);
                ci[0] <= truth && truth <= ci[1]
            };
            total += 1;
            with += usize::from(holds(&stated));
            without += usize::from(holds(&plain));
            assert_eq!(value(&stated, p).0, value(&plain, p).0, "the same estimate");
        }
        lines.push(format!(
            "{joint} J off {:+.2} %: dry {:.4} {:?} / {:?} (truth {:.4})",
            100.0 * off,
            value(&stated, DynParam::Dry).0,
            value(&stated, DynParam::Dry).1,
            value(&plain, DynParam::Dry).1,
            law.dry
        ));
        if i == 0 {
            // A stated 0 carries nothing: the fit as without a statement, to the bit.
            let zero = fit_carried(
                &pendulum(joint, &law, release_deg, off, Some(0.0), 300 + i),
                &opts,
            );
            assert!(zero.body_uncertainty.is_empty());
            assert_eq!(zero.values, plain.values);
            assert_eq!(zero.std, plain.std);
            assert_eq!(zero.ci95, plain.ci95);
        }
    }
    eprintln!(
        "{lines:#?}\ncoverage with the stated 2 % propagated {with}/{total}, without {without}/{total}; \
         the reported fit (residual loop) {reported}/{total}, without {reported_without}/{total} \
         (`inertia_error` named in {inertia_named} of {})",
        total / 2
    );
    assert!(
        with as f64 >= 0.85 * total as f64 && reported as f64 >= 0.85 * total as f64,
        "with {with}/{total}, without {without}/{total}, reported {reported}/{total}"
    );
    assert!(
        (without as f64) < 0.75 * total as f64,
        "without {without}/{total}: the set does not show the stated error"
    );
}

/// The whole pipeline with a stated mass uncertainty: 12 pendulums (J3 and J5) whose true mass
/// is drawn off the stated one with sd 2 %, the rig stating that 2 %. Divided by m, the swing
/// is (J/m)·α̈ = −g·d·sin α − (D/m)·ω − (N/m)·R·μ·sign ω, and N/m is kinematic: a mass error is
/// J/m and D/m off, μ untouched. `inertia_error` takes up J/m (named in each), the viscous D
/// carries the error, and nothing estimates the mass: propagated, the reported D intervals hold
/// the truth in 11 of 12 (5 of 12 without); μ's are the same either way (10 of 12).
#[test]
fn a_stated_mass_uncertainty_carries_into_the_reported_friction() {
    let opts = FitOptions::default();
    let thresholds = pantowatch_models::drift::DriftThresholds::default();
    let mut rng = Noise::new(1718);
    // Held by the interval: [viscous, dry], with and without the stated mass sd.
    let (mut with, mut without, mut n) = ([0usize; 2], [0usize; 2], 0);
    let mut lines = Vec::new();
    for i in 0..12u64 {
        let joint = if i % 2 == 0 { "J3" } else { "J5" };
        let jd = builtin_160ec().joint(joint).unwrap();
        let law = FrictionLaw::base(
            jd.viscous_baseline() * (0.7 + 0.8 * rng.uniform()),
            jd.dry_mu * (0.7 + 0.8 * rng.uniform()),
        );
        let release_deg = 50.0 + 30.0 * rng.uniform();
        let off = 0.02 * rng.normal();
        let whole = |sd: Option<[f64; 2]>| {
            let test = pendulum_body(joint, &law, release_deg, [off, 0.0], sd, 500 + i);
            let b = pantowatch_models::testspec::Baseline {
                joint: joint.into(),
                viscous: None,
                dry: None,
                viscous_unit: "N·m·s/rad",
            };
            pantowatch_models::fit_joint_test_with_finding(&test, &b, &thresholds, "t", &opts)
                .unwrap()
                .0
        };
        let (r_with, r_without) = (whole(Some([0.02, 0.0])), whole(None));
        let echo = r_with.fit.body_uncertainty.as_ref().expect("echoed");
        assert!(echo.propagated.contains_key("mass_kg"), "{echo:?}");
        let holds = |ci: [f64; 2], v: f64| ci[0] <= v && v <= ci[1];
        for (r, k) in [(&r_with, &mut with), (&r_without, &mut without)] {
            let j = &r.joints[0];
            k[0] += usize::from(holds(j.viscous.ci95, law.viscous));
            k[1] += usize::from(holds(j.dry.ci95, law.dry));
        }
        n += 1;
        let names: Vec<&str> = r_with
            .residual
            .effects
            .iter()
            .map(|e| e.name.as_str())
            .collect();
        lines.push(format!(
            "{joint} m off {:+.2} %: {names:?} viscous {:.4} {:?} / {:?} (truth {:.4})",
            100.0 * off,
            r_with.joints[0].viscous.value,
            r_with.joints[0].viscous.ci95,
            r_without.joints[0].viscous.ci95,
            law.viscous
        ));
    }
    eprintln!(
        "{lines:#?}\nreported intervals holding the truth with the stated 2 % mass sd: viscous \
         {}/{n}, dry {}/{n}; without: viscous {}/{n}, dry {}/{n}",
        with[0], with[1], without[0], without[1]
    );
    assert!(
        with[0] >= 10 && without[0] <= 7 && with[1] >= without[1],
        "viscous {}/{n} with, {}/{n} without; dry {}/{n} with, {}/{n} without",
        with[0],
        without[0],
        with[1],
        without[1]
    );
}

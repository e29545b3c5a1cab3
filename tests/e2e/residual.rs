//! The residual loop on traces with an undeclared effect: each vocabulary effect at a clear and a
//! weak strength on several joints, clean traces (false alarms), effects outside the vocabulary
//! (a torsional spring, fading friction), a stated inertia off, and the two shipped examples with
//! effects. Input-driven tests are in `driven.rs`.

use pantowatch_models::data::builtin_160ec;
use pantowatch_models::drift::DriftThresholds;
use pantowatch_models::dynamics::{Dof, Input, Mechanism};
use pantowatch_models::friction::{FrictionLaw, PositionProfile, Stribeck};
use pantowatch_models::identify::{FitOptions, JointTest, Readout};
use pantowatch_models::report::FitResult;
use pantowatch_models::rig::{PendulumRig, SliderRig};
use pantowatch_models::synth::{Sensor, Truth, grid, measure_truth};
use pantowatch_models::testspec::Baseline;

const DEG: f64 = 180.0 / std::f64::consts::PI;

fn pendulum_test(
    joint: &str,
    truth: &Truth,
    release_deg: f64,
    torsion: f64,
    seed: u64,
) -> (JointTest, Baseline) {
    pendulum_test_with_inertia(joint, truth, release_deg, torsion, 1.0, seed)
}

/// As [`pendulum_test`], the pendulum's true inertia about its pin `inertia_scale` × the rig's
/// stated one (the test states the rig's value: `inertia_error`, issue 17).
pub(crate) fn pendulum_test_with_inertia(
    joint: &str,
    truth: &Truth,
    release_deg: f64,
    torsion: f64,
    inertia_scale: f64,
    seed: u64,
) -> (JointTest, Baseline) {
    let data = builtin_160ec();
    let rig = PendulumRig::paper_default(data, joint).unwrap();
    let stated = Dof {
        mech: Mechanism::Pendulum(rig),
        input: None,
        torsion,
    };
    let dof = stated.with_inertia_scale(inertia_scale);
    let t = grid(20.0, 500.0);
    let sensor = Sensor {
        scale: DEG,
        noise_sigma: 0.05,
        quantum: 0.01,
        offset: 0.0,
        seed,
    };
    let y = measure_truth(&dof, truth, release_deg / DEG, 0.0, &t, &sensor).unwrap();
    let jd = data.joint(joint).unwrap();
    let dof = Dof {
        torsion: 0.0,
        ..stated
    };
    let b = Baseline {
        joint: joint.into(),
        viscous: Some(jd.viscous_baseline()),
        dry: Some(jd.dry_mu),
        viscous_unit: "N·m·s/rad",
    };
    (
        JointTest {
            dof,
            t_s: t,
            y,
            scale: DEG,
            unit: "deg",
            initial_rate: None,
            release_t_s: None,
            body_sd: Vec::new(),
        },
        b,
    )
}

/// The head-drop slider test: held by a 98.1 N pull that is released at 0.5 s (a step in F_N).
fn slider_test(truth: &Truth, seed: u64) -> (JointTest, Baseline) {
    let rig = SliderRig::new(10.5, 1, 4.0, 4.05).unwrap();
    let t = grid(4.0, 500.0);
    let f: Vec<f64> = t
        .iter()
        .map(|&x| if x < 0.5 { -98.1 } else { 0.0 })
        .collect();
    let dof = Dof {
        mech: Mechanism::Slider(rig),
        input: Some(Input {
            t_s: t.clone(),
            value: f,
        }),
        torsion: 0.0,
    };
    let sensor = Sensor {
        scale: 1000.0,
        noise_sigma: 0.05,
        quantum: 0.01,
        offset: 0.0,
        seed,
    };
    let y = measure_truth(&dof, truth, -98.1 / 4000.0, 0.0, &t, &sensor).unwrap();
    let b = Baseline {
        joint: "J8".into(),
        viscous: Some(3.99),
        dry: Some(0.5),
        viscous_unit: "N·s/m",
    };
    (
        JointTest {
            dof,
            t_s: t,
            y,
            scale: 1000.0,
            unit: "mm",
            initial_rate: None,
            release_t_s: None,
            body_sd: Vec::new(),
        },
        b,
    )
}

/// The fit's result; every fit also checks the one-verdict rule (issue 17, point 5): the
/// candidates reported `accepted` are exactly the named effects, none beside `unexplained`.
pub(crate) fn fit(test: &JointTest, b: &Baseline) -> FitResult {
    let (r, _, finding) = pantowatch_models::fit_joint_test_with_finding(
        test,
        b,
        &DriftThresholds::default(),
        "t",
        &FitOptions::default(),
    )
    .unwrap();
    let named = names(&r);
    // Issue 17, point 6: no effect below what the sensor resolves — every trace here is read
    // with 0.01 (deg or mm) steps, so a named zero is at least that.
    for e in r
        .residual
        .effects
        .iter()
        .filter(|e| e.name == "sensor_offset")
    {
        let v = e
            .params
            .iter()
            .find(|(k, _)| !k.ends_with("_ci95"))
            .and_then(|(_, v)| v.as_f64())
            .unwrap();
        assert!(
            v.abs() >= 0.01,
            "sensor_offset {v} below the 0.01 step named"
        );
    }
    for c in finding.candidates.iter().filter(|c| c.accepted) {
        let effects: Vec<String> = c.effects.iter().map(|e| e.name().to_string()).collect();
        assert!(
            r.residual.verdict.is_none() && named.iter().take(effects.len()).eq(effects.iter()),
            "candidate {effects:?} accepted beside verdict {:?}, named {named:?}",
            r.residual.verdict
        );
    }
    r
}

pub(crate) fn names(r: &FitResult) -> Vec<String> {
    r.residual.effects.iter().map(|e| e.name.clone()).collect()
}

pub(crate) fn base(joint: &str) -> FrictionLaw {
    let j = builtin_160ec().joint(joint).unwrap();
    FrictionLaw::base(j.viscous_baseline(), j.dry_mu)
}

/// (effect name, joint or "slider", truth at clear strength, truth at weak strength)
/// Release angles: Stribeck friction shows near rest, so its traces start low (as the shipped
/// example, 15°) and run down to rest.
fn release_for(name: &str) -> f64 {
    if name == "stribeck" { 15.0 } else { 60.0 }
}

fn cases() -> Vec<(&'static str, &'static str, Truth, Truth)> {
    let t = |law: FrictionLaw, ro: Readout| Truth {
        law,
        readout: ro,
        dry_fade: 0.0,
    };
    let none = Readout::default();
    let mut v = Vec::new();
    for joint in ["J1", "J3", "J5"] {
        let b = base(joint);
        let strib = |r: f64| FrictionLaw {
            stribeck: Some(Stribeck {
                ratio: r,
                speed: 0.3,
            }),
            ..b
        };
        // Stribeck shows as the body comes to rest; on J5 (μ = 0.88) a 2.5× static hump holds
        // the 15° release after a swing or two, leaving too little motion to fit: J1 and J3.
        if joint != "J5" {
            v.push(("stribeck", joint, t(strib(2.5), none), t(strib(1.15), none)));
        }
        let drag = |c: f64| FrictionLaw {
            quadratic_drag: Some(c),
            ..b
        };
        v.push((
            "quadratic_drag",
            joint,
            t(drag(0.4), none),
            t(drag(0.002), none),
        ));
        // Friction growing away from the bottom of the swing (a worn pin end).
        let pos = |a: f64| FrictionLaw {
            profile: Some(PositionProfile::Polynomial {
                linear: a,
                quadratic: 3.0 * a,
                scale: 1.0,
            }),
            ..b
        };
        // Position friction modulates the dry torque: on J1 (μ = 0.023, Table 4) it is lost in
        // the viscous part, so its clear case is on the joints with real dry friction.
        if joint != "J1" {
            v.push((
                "position_friction",
                joint,
                t(pos(1.0), none),
                t(pos(0.05), none),
            ));
        }
        let bl = |deg: f64| Readout {
            backlash: deg / DEG,
            ..none
        };
        v.push(("backlash", joint, t(b, bl(0.4)), t(b, bl(0.03))));
        let off = |deg: f64| Readout {
            offset: deg,
            ..none
        };
        v.push(("sensor_offset", joint, t(b, off(0.5)), t(b, off(0.01))));
    }
    let s = FrictionLaw::base(3.99, 0.5);
    v.push((
        "sensor_delay",
        "slider",
        t(
            s,
            Readout {
                delay_s: 0.008,
                ..none
            },
        ),
        t(
            s,
            Readout {
                delay_s: 0.0005,
                ..none
            },
        ),
    ));
    v
}

fn run(name: &str, joint: &str, truth: &Truth, seed: u64) -> (JointTest, Baseline) {
    if joint == "slider" {
        slider_test(truth, seed)
    } else {
        pendulum_test(joint, truth, release_for(name), 0.0, seed)
    }
}

#[test]
fn clear_effects_are_named_halve_the_error_and_keep_the_base_friction() {
    let mut failures = Vec::new();
    for (name, joint, clear, _) in cases() {
        let (test, b) = run(name, joint, &clear, 7);
        let r = fit(&test, &b);
        let res = &r.residual;
        eprintln!(
            "{name} on {joint}: {:?} {:?} rmse {:.4} -> {:.4}, held out {:.4} -> {:.4}",
            names(&r),
            res.effects
                .iter()
                .map(|e| serde_json::Value::Object(e.params.clone()))
                .collect::<Vec<_>>(),
            res.rmse_before,
            res.rmse_after,
            res.holdout_rmse_before,
            res.holdout_rmse_after
        );
        let mut fail = |why: String| failures.push(format!("{name} on {joint}: {why}"));
        // The named effect, and nothing else — but a sensor zero, which the contract reports
        // whenever its 95 % interval excludes 0 (a 5 % event on a clean trace).
        let got = names(&r);
        if got.first().map(String::as_str) != Some(name)
            || got.iter().skip(1).any(|n| n != "sensor_offset")
        {
            fail(format!("named {got:?}"));
        }
        // (The base model carries a sensor zero, so an offset costs it nothing: no before/after.)
        if name != "sensor_offset"
            && !(res.rmse_after <= 0.5 * res.rmse_before
                && res.holdout_rmse_after < res.holdout_rmse_before)
        {
            fail(format!(
                "error {:.4} -> {:.4}, held out {:.4} -> {:.4}",
                res.rmse_before, res.rmse_after, res.holdout_rmse_before, res.holdout_rmse_after
            ));
        }
        let j = &r.joints[0];
        let (tv, td) = (clear.law.viscous, clear.law.dry);
        if name == "position_friction" {
            // Friction that varies along the swing has no one "base" value: the fitted μ(q) is
            // checked against the truth's at the grid's knots instead.
            if let Err(why) = profile_recovered(&r, &clear.law) {
                fail(why);
            }
        } else if (j.dry.value / td - 1.0).abs() >= 0.05 {
            fail(format!("dry {} vs {td}", j.dry.value));
        }
        if j.viscous.identifiable && (j.viscous.value / tv - 1.0).abs() >= 0.15 {
            fail(format!("viscous {} vs {tv}", j.viscous.value));
        }
    }
    assert!(failures.is_empty(), "{failures:#?}");
}

#[test]
fn weak_effects_get_their_name_or_none_never_a_wrong_one() {
    let mut named = 0;
    for (name, joint, _, weak) in cases() {
        let (test, b) = run(name, joint, &weak, 8);
        let got = names(&fit(&test, &b));
        assert!(
            got.is_empty() || got == vec![name.to_string()],
            "weak {name} on {joint}: named {got:?}"
        );
        named += usize::from(!got.is_empty());
    }
    eprintln!("weak effects named: {named} of {}", cases().len());
}

#[test]
fn clean_traces_raise_at_most_5_percent_false_alarms() {
    let joints = ["J1", "J2", "J3", "J4", "J5", "J7"];
    let mut alarms = Vec::new();
    for i in 0..30u64 {
        let joint = joints[i as usize % joints.len()];
        let truth = Truth {
            law: base(joint),
            readout: Readout::default(),
            dry_fade: 0.0,
        };
        let (test, b) = pendulum_test(joint, &truth, 55.0 + i as f64, 0.0, 100 + i);
        let r = fit(&test, &b);
        if !r.residual.effects.is_empty() {
            alarms.push((joint, names(&r)));
        }
    }
    eprintln!("false alarms: {} of 30 {alarms:?}", alarms.len());
    assert!(
        alarms.len() <= 1,
        "false alarms in {} of 30: {alarms:?}",
        alarms.len()
    );
}

#[test]
fn effects_outside_the_vocabulary_get_no_wrong_name() {
    // A torsional spring in the joint (changes the frequency) and friction fading during the test.
    let b = base("J3");
    let spring = Truth {
        law: b,
        readout: Readout::default(),
        dry_fade: 0.0,
    };
    let (test, bl) = pendulum_test("J3", &spring, 60.0, 4.0, 9);
    let r = fit(&test, &bl);
    assert!(
        r.residual.effects.is_empty(),
        "torsional spring named {:?}",
        names(&r)
    );
    assert_eq!(
        r.residual.verdict.as_deref(),
        Some("unexplained"),
        "{:?}",
        r.residual
    );
    let fade = Truth {
        law: b,
        readout: Readout::default(),
        dry_fade: 0.6,
    };
    let (test, bl) = pendulum_test("J3", &fade, 60.0, 0.0, 10);
    let r = fit(&test, &bl);
    assert!(
        r.residual.effects.is_empty(),
        "fading friction named {:?}",
        names(&r)
    );
}

#[test]
fn the_two_shipped_examples_with_effects_are_found() {
    use pantowatch::trace::TraceDoc;
    for (file, effect) in [
        ("J1_stribeck.json", "stribeck"),
        ("J5_quadratic_drag.json", "quadratic_drag"),
    ] {
        let doc =
            TraceDoc::from_json(&std::fs::read(pantowatch_e2e::examples_dir().join(file)).unwrap())
                .unwrap();
        let (test, b) = doc.joint_test().unwrap();
        let r = fit(&test, &b);
        assert_eq!(
            names(&r),
            vec![effect.to_string()],
            "{file}: {:?}",
            r.residual
        );
        assert!(r.residual.rmse_after <= 0.5 * r.residual.rmse_before);
        // Base friction back within the single-joint accuracy once the effect is in.
        let j = &r.joints[0];
        let (tv, td) = if effect == "stribeck" {
            (0.034, 0.023)
        } else {
            (0.401, 0.88)
        };
        assert!(
            (j.dry.value / td - 1.0).abs() < 0.05 && (j.viscous.value / tv - 1.0).abs() < 0.15,
            "{file}: {j:?}"
        );
    }
}

/// Issue 17, point 4: a refit that adds a second effect never ends worse than the single effect
/// it adds to. Traces with two effects at once (J3, clear strengths, seeds 3–6), where both
/// singles pass and the pair is refitted: every pair candidate's fitted RMSE is at most its
/// first effect's — with the fit's usual budget and with the residual loop's LM held to 3
/// iterations, where a far start shows. Measured: before the pair started at the single's
/// solution, the 3-iteration drag + backlash pair ended at RMSE 0.476° above its single's 0.202°
/// (seed 3), and at 5 iterations 0.116° (not accepted, held-out +65 %) on all four seeds; from the
/// single's solution it ends at 0.050° and is named in every seed.
#[test]
fn a_pair_refit_never_ends_worse_than_its_single() {
    let b = base("J3");
    let drag = Some(0.4);
    let pos = Some(PositionProfile::Polynomial {
        linear: 1.0,
        quadratic: 3.0,
        scale: 1.0,
    });
    let strib = Some(Stribeck {
        ratio: 2.5,
        speed: 0.3,
    });
    let backlash = Readout {
        backlash: 0.4 / DEG,
        ..Readout::default()
    };
    let combos: Vec<(&str, FrictionLaw, Readout, f64)> = vec![
        (
            "drag+position",
            FrictionLaw {
                quadratic_drag: drag,
                profile: pos,
                ..b
            },
            Readout::default(),
            60.0,
        ),
        (
            "stribeck+drag",
            FrictionLaw {
                stribeck: strib,
                quadratic_drag: drag,
                ..b
            },
            Readout::default(),
            15.0,
        ),
        (
            "position+backlash",
            FrictionLaw { profile: pos, ..b },
            backlash,
            60.0,
        ),
        (
            "drag+backlash",
            FrictionLaw {
                quadratic_drag: drag,
                ..b
            },
            backlash,
            60.0,
        ),
        (
            "stribeck+backlash",
            FrictionLaw {
                stribeck: strib,
                ..b
            },
            backlash,
            15.0,
        ),
        (
            "stribeck+position",
            FrictionLaw {
                stribeck: strib,
                profile: pos,
                ..b
            },
            Readout::default(),
            15.0,
        ),
        (
            "position+drag@30",
            FrictionLaw {
                quadratic_drag: drag,
                profile: pos,
                ..b
            },
            Readout::default(),
            30.0,
        ),
    ];
    let mut pairs = 0;
    for max_iter in [60, 3] {
        for (what, law, readout, release) in combos.iter().copied() {
            for seed in [3, 4, 5, 6] {
                let truth = Truth {
                    law,
                    readout,
                    dry_fade: 0.0,
                };
                let (test, bl) = pendulum_test("J3", &truth, release, 0.0, seed);
                let full =
                    pantowatch_models::identify::fit_base(&test, &FitOptions::default()).unwrap();
                let mut budget = FitOptions::default();
                budget.lm.max_iter = max_iter;
                let finding = pantowatch_models::residual::analyse(&test, &full, &budget).unwrap();
                let _ = bl;
                for c in finding.candidates.iter().filter(|c| c.effects.len() == 2) {
                    eprintln!(
                        "{max_iter} iterations, {what} seed {seed}: {:?} rmse {:.4} accepted {} {}",
                        c.effects, c.rmse_fit, c.accepted, c.reason
                    );
                }
                if what == "drag+backlash" {
                    assert!(
                        finding
                            .candidates
                            .iter()
                            .any(|c| c.effects.len() == 2 && c.accepted),
                        "{max_iter} iterations, seed {seed}: the drag + backlash pair is not named"
                    );
                }
                for pair in finding.candidates.iter().filter(|c| c.effects.len() == 2) {
                    pairs += 1;
                    let single = finding
                        .candidates
                        .iter()
                        .find(|c| c.effects == pair.effects[..1])
                        .expect("the single the pair adds to");
                    assert!(
                        pair.rmse_fit <= single.rmse_fit * (1.0 + 1e-9),
                        "{what} seed {seed}: pair {:?} ended at {} above its single's {}",
                        pair.effects,
                        pair.rmse_fit,
                        single.rmse_fit
                    );
                }
            }
        }
    }
    eprintln!("{pairs} pair refits");
    assert!(
        pairs >= 2,
        "only {pairs} pair refits: the test must reach the pair step"
    );
}

/// Issue 17, point 1: a pendulum whose true inertia is off its stated value by 1–3 % (either
/// way; J1, J3, J5; the stand's 0.05° noise and 0.01° steps) swings at another period, which no
/// friction law can absorb: `inertia_error` is named with J/J_stated's interval holding the
/// truth, the error at least halves, and the friction comes back within its interval. Off by
/// 0.1 %, it is named right or not at all.
#[test]
fn a_stated_inertia_off_by_1_to_3_percent_is_named_and_the_friction_recovered() {
    let mut failures = Vec::new();
    let (mut n, mut covered, mut missed) = (0, 0, Vec::new());
    for (i, (joint, scale)) in [
        ("J1", 1.02),
        ("J3", 0.98),
        ("J3", 1.03),
        ("J5", 1.01),
        ("J5", 0.97),
        ("J1", 0.99),
    ]
    .into_iter()
    .enumerate()
    {
        n += 1;
        let truth = Truth {
            law: base(joint),
            readout: Readout::default(),
            dry_fade: 0.0,
        };
        let (test, b) = pendulum_test_with_inertia(joint, &truth, 60.0, 0.0, scale, 40 + i as u64);
        let r = fit(&test, &b);
        let res = &r.residual;
        let got = names(&r);
        let ratio = res
            .effects
            .iter()
            .find(|e| e.name == "inertia_error")
            .map(|e| {
                let v = e.params["inertia_ratio"].as_f64().unwrap();
                let ci = e.params["inertia_ratio_ci95"].as_array().unwrap();
                (v, ci[0].as_f64().unwrap(), ci[1].as_f64().unwrap())
            });
        let j = &r.joints[0];
        eprintln!(
            "inertia ×{scale} on {joint}: {got:?} {ratio:?} rmse {:.4} -> {:.4}, held out {:.4} -> {:.4}; dry {:.4} {:?} (truth {:.4}), viscous {:.4} {:?} (truth {:.4})",
            res.rmse_before,
            res.rmse_after,
            res.holdout_rmse_before,
            res.holdout_rmse_after,
            j.dry.value,
            j.dry.ci95,
            truth.law.dry,
            j.viscous.value,
            j.viscous.ci95,
            truth.law.viscous
        );
        let mut fail = |why: String| failures.push(format!("×{scale} on {joint}: {why}"));
        if got.first().map(String::as_str) != Some("inertia_error")
            || got.iter().skip(1).any(|n| n != "sensor_offset")
        {
            fail(format!("named {got:?}"));
        }
        match ratio {
            Some((_, lo, hi)) if lo <= scale && scale <= hi => {}
            other => fail(format!("ratio {other:?} misses {scale}")),
        }
        if !(res.rmse_after <= 0.5 * res.rmse_before
            && res.holdout_rmse_after < res.holdout_rmse_before)
        {
            fail(format!(
                "error {:.4} -> {:.4}, held out {:.4} -> {:.4}",
                res.rmse_before, res.rmse_after, res.holdout_rmse_before, res.holdout_rmse_after
            ));
        }
        let holds = |ci: [f64; 2], v: f64| ci[0] <= v && v <= ci[1];
        let friction_held = holds(j.dry.ci95, truth.law.dry)
            && (!j.viscous.identifiable || holds(j.viscous.ci95, truth.law.viscous));
        if friction_held {
            covered += 1;
        } else {
            missed.push(format!(
                "×{scale} on {joint}: dry {:?}, viscous {:?}",
                j.dry.ci95, j.viscous.ci95
            ));
        }
    }
    assert!(
        failures.is_empty(),
        "{} of {n}: {failures:#?}",
        failures.len()
    );
    // 95 % intervals over 6 traces: at most one trace may miss (dry and viscous are correlated
    // −0.9 or more in a swing, so a miss takes both). Measured: 5 of 6 (J1 ×0.99 missed by
    // 0.0005 in μ and 0.0007 N·m·s/rad).
    assert!(
        covered >= n - 1,
        "friction intervals held the truth in {covered} of {n}: {missed:?}"
    );
    // Off by 0.1 %: the right name or none.
    for (i, joint) in ["J1", "J3", "J5"].into_iter().enumerate() {
        let truth = Truth {
            law: base(joint),
            readout: Readout::default(),
            dry_fade: 0.0,
        };
        let (test, b) = pendulum_test_with_inertia(joint, &truth, 60.0, 0.0, 1.001, 60 + i as u64);
        let got = names(&fit(&test, &b));
        assert!(
            got.is_empty() || got[0] == "inertia_error",
            "inertia ×1.001 on {joint}: named {got:?}"
        );
    }
}

/// The truth's μ(q) projected (least squares in q) onto the piecewise-linear grid with these
/// knots (degrees): what a grid of that resolution can show of a shape, a band's sharp edges
/// included. Mass matrix tridiagonal (h/6, 2h/3, h/6; h/3 at the ends), solved by Thomas.
fn grid_projection(truth: &FrictionLaw, knots_deg: &[f64]) -> Vec<f64> {
    let n = knots_deg.len();
    let h = knots_deg[1] - knots_deg[0];
    let rhs: Vec<f64> = knots_deg
        .iter()
        .enumerate()
        .map(|(k, &q)| {
            let (lo, hi) = (
                if k == 0 { 0 } else { -400 },
                if k == n - 1 { 0 } else { 400 },
            );
            (lo..=hi)
                .map(|i| {
                    let x = f64::from(i) / 400.0;
                    (1.0 - x.abs()) * truth.static_mu((q + x * h) / DEG) * h / 400.0
                })
                .sum::<f64>()
        })
        .collect();
    let diag = |k: usize| {
        if k == 0 || k == n - 1 {
            h / 3.0
        } else {
            2.0 * h / 3.0
        }
    };
    let off = h / 6.0;
    let (mut c, mut d) = (vec![0.0; n], vec![0.0; n]);
    for k in 0..n {
        let m = diag(k) - if k > 0 { off * c[k - 1] } else { 0.0 };
        c[k] = off / m;
        d[k] = (rhs[k] - if k > 0 { off * d[k - 1] } else { 0.0 }) / m;
    }
    let mut x = vec![0.0; n];
    for k in (0..n).rev() {
        x[k] = d[k] - if k + 1 < n { c[k] * x[k + 1] } else { 0.0 };
    }
    x
}

/// The fitted position friction μ·(1 + c_k) at the grid's knots against the truth's μ(q) as the
/// grid resolves it ([`grid_projection`]), at the interior knots: their means within 10 % and the
/// highest friction at the same knot (unless the truth is flat there). Single knots are not held
/// to a bound: the grid has no smoothness prior, and where the swing gives little information
/// neighbouring knots trade off (measured: up to ±50 % beside a J5 band at the bottom, a few %
/// on smooth shapes where the swing dwells).
fn profile_recovered(r: &FitResult, truth: &FrictionLaw) -> Result<(), String> {
    let e = r
        .residual
        .effects
        .iter()
        .find(|e| e.name == "position_friction")
        .ok_or("no position_friction")?;
    let knots: Vec<f64> = serde_json::from_value(e.params["knots_deg"].clone()).unwrap();
    let factor: Vec<f64> = serde_json::from_value(e.params["factor"].clone()).unwrap();
    let mu = r.joints[0].dry.value;
    let projected = grid_projection(truth, &knots);
    let pairs: Vec<(f64, f64, f64)> = knots
        .iter()
        .zip(&factor)
        .zip(&projected)
        .map(|((q, f), p)| (*q, mu * f, *p))
        .collect();
    // The end knots: only the first swing reaches them.
    let pairs = &pairs[1..pairs.len() - 1];
    let mean = |i: usize| {
        pairs
            .iter()
            .map(|p| if i == 0 { p.1 } else { p.2 })
            .sum::<f64>()
            / pairs.len() as f64
    };
    let worst = pairs
        .iter()
        .map(|p| (p.1 / p.2 - 1.0).abs())
        .fold(0.0, f64::max);
    let peak = |i: usize| {
        (0..pairs.len())
            .max_by(|&a, &b| {
                let v = |k: usize| if i == 0 { pairs[k].1 } else { pairs[k].2 };
                v(a).total_cmp(&v(b))
            })
            .unwrap()
    };
    let flat = pairs.iter().all(|p| (p.2 / pairs[0].2 - 1.0).abs() < 0.05);
    let least = factor[1..factor.len() - 1]
        .iter()
        .cloned()
        .fold(f64::INFINITY, f64::min);
    eprintln!(
        "   μ(q) mean {:.3}/{:.3}, worst knot {:.0} %, least interior factor {least:.2}",
        mean(0),
        mean(1),
        100.0 * worst
    );
    if (mean(0) / mean(1) - 1.0).abs() < 0.10 && (flat || peak(0) == peak(1)) {
        Ok(())
    } else {
        Err(format!("μ(q) fitted/true at the knots: {pairs:.3?}"))
    }
}

/// Issue 17, point 6: friction that varies with angle — a band over part of the swing, a cosine
/// in angle, neither the shape the vocabulary's grid is written as — is named
/// `position_friction`, never `stribeck` (which depends on speed), with μ(q) recovered; and
/// Stribeck friction stays `stribeck` with no extra effect. J3 and J5 (Table 4 friction, stand
/// noise 0.05°, 0.01° steps), released at 60°; two seeds each.
#[test]
fn position_dependent_friction_is_named_and_told_from_stribeck() {
    let d = 1.0 / DEG;
    let shapes = [
        (
            "band +10°..30° ×2",
            PositionProfile::Band {
                gain: 1.0,
                from: 10.0 * d,
                to: 30.0 * d,
                edge: 1.0 * d,
            },
        ),
        (
            "band −5°..5° ×2",
            PositionProfile::Band {
                gain: 1.0,
                from: -5.0 * d,
                to: 5.0 * d,
                edge: 1.0 * d,
            },
        ),
        (
            "cosine 0.3, 120°",
            PositionProfile::Cosine {
                amplitude: 0.3,
                period: 120.0 * d,
                phase: 0.5,
            },
        ),
        (
            "cosine 0.3, 60°",
            PositionProfile::Cosine {
                amplitude: 0.3,
                period: 60.0 * d,
                phase: 0.0,
            },
        ),
    ];
    let (mut named, mut total, mut wrong) = (0, 0, Vec::new());
    for joint in ["J3", "J5"] {
        let b = base(joint);
        for (label, shape) in shapes {
            for seed in [21, 22] {
                let law = FrictionLaw {
                    profile: Some(shape),
                    ..b
                };
                let truth = Truth {
                    law,
                    readout: Readout::default(),
                    dry_fade: 0.0,
                };
                let (test, bl) = pendulum_test(joint, &truth, 60.0, 0.0, seed);
                let r = fit(&test, &bl);
                let got = names(&r);
                let res = &r.residual;
                eprintln!(
                    "{joint} {label} seed {seed}: {got:?} {:?}, error {:.4} -> {:.4}°, held out {:.4} -> {:.4}°",
                    res.verdict,
                    res.rmse_before,
                    res.rmse_after,
                    res.holdout_rmse_before,
                    res.holdout_rmse_after
                );
                total += 1;
                if got.first().map(String::as_str) == Some("position_friction") {
                    named += 1;
                    // At least half the held-out excess over the fitted error (≈ the noise) gone.
                    let excess = |h: f64| h * h - res.rmse_after * res.rmse_after;
                    assert!(
                        excess(res.holdout_rmse_after) <= 0.5 * excess(res.holdout_rmse_before),
                        "{joint} {label}: held out {:.4} -> {:.4}",
                        res.holdout_rmse_before,
                        res.holdout_rmse_after
                    );
                    if let Err(why) = profile_recovered(&r, &law) {
                        panic!("{joint} {label} seed {seed}: {why}");
                    }
                }
                if got
                    .iter()
                    .any(|n| n != "position_friction" && n != "sensor_offset")
                {
                    wrong.push(format!("{joint} {label} seed {seed}: {got:?}"));
                }
            }
        }
    }
    eprintln!("position friction named in {named} of {total}");
    assert!(wrong.is_empty(), "wrong names: {wrong:#?}");
    assert!(
        named * 10 >= total * 9,
        "named {named} of {total}: under 90 %"
    );
    // Stribeck friction on the same joints' rig, released low as its clear case: named alone.
    for (joint, seed) in [("J1", 23), ("J3", 24)] {
        let b = base(joint);
        let truth = Truth {
            law: FrictionLaw {
                stribeck: Some(Stribeck {
                    ratio: 2.5,
                    speed: 0.3,
                }),
                ..b
            },
            readout: Readout::default(),
            dry_fade: 0.0,
        };
        let (test, bl) = pendulum_test(joint, &truth, release_for("stribeck"), 0.0, seed);
        let got = names(&fit(&test, &bl));
        assert_eq!(got, vec!["stribeck".to_string()], "Stribeck on {joint}");
    }
}

/// Issue 17, point 3 (`asymmetric_friction`): a pendulum whose pin's friction differs by
/// direction, μ·(1 ± δ) with δ = ±0.3 (J3 and J5, Table 4, stand noise, 60° release). The
/// reaction force N changes through the swing, so the term is not a constant torque and the free
/// swing tells it from the sensor's zero: named, δ's interval holding the truth, the symmetric μ
/// within 5 %, the error fitted and held out reduced.
#[test]
fn direction_dependent_friction_is_named_on_a_pendulum() {
    let mut failures = Vec::new();
    for (joint, delta, seed) in [("J3", 0.3, 31), ("J5", -0.3, 32), ("J5", 0.3, 33)] {
        let b = base(joint);
        let truth = Truth {
            law: FrictionLaw {
                asymmetry: delta,
                ..b
            },
            readout: Readout::default(),
            dry_fade: 0.0,
        };
        let (test, bl) = pendulum_test(joint, &truth, 60.0, 0.0, seed);
        let r = fit(&test, &bl);
        let res = &r.residual;
        let got = names(&r);
        let e = res.effects.iter().find(|e| e.name == "asymmetric_friction");
        let d = e.and_then(|e| e.params["asymmetry"].as_f64());
        let ci: Option<[f64; 2]> =
            e.and_then(|e| serde_json::from_value(e.params["asymmetry_ci95"].clone()).ok());
        eprintln!(
            "{joint} δ {delta}: {got:?} δ {d:?} {ci:?}; error {:.4} -> {:.4}°, held out {:.4} -> {:.4}°; dry {:.4} (truth {:.4})",
            res.rmse_before,
            res.rmse_after,
            res.holdout_rmse_before,
            res.holdout_rmse_after,
            r.joints[0].dry.value,
            b.dry
        );
        if got.first().map(String::as_str) != Some("asymmetric_friction")
            || got.iter().skip(1).any(|n| n != "sensor_offset")
        {
            failures.push(format!("{joint} δ {delta}: named {got:?}"));
            continue;
        }
        if !ci.is_some_and(|c| c[0] <= delta && delta <= c[1]) {
            failures.push(format!("{joint} δ {delta}: δ {d:?} {ci:?}"));
        }
        if (r.joints[0].dry.value / b.dry - 1.0).abs() >= 0.05 {
            failures.push(format!("{joint}: dry {}", r.joints[0].dry.value));
        }
        // Most of a free swing's asymmetry hides in the sensor's zero (N varies by a few % over
        // a 60° swing): the plain fit's error is only just above the noise, and what is left
        // must go, fitted and held out.
        if res.rmse_after >= res.rmse_before || res.holdout_rmse_after >= res.holdout_rmse_before {
            failures.push(format!(
                "{joint}: error {} -> {}, held out {} -> {}",
                res.rmse_before, res.rmse_after, res.holdout_rmse_before, res.holdout_rmse_after
            ));
        }
    }
    assert!(failures.is_empty(), "{failures:#?}");
}

/// Issue 36, points 3 and 5: one rig released at two angles (30° and 90°), fitted pooled with
/// one set of physical parameters, at the stand's noise. A true 2 % inertia error is named
/// across both recordings with the friction recovered; a torsional spring in the joint (a
/// restoring torque that is not gravity: it shifts the period by an amount that depends on the
/// amplitude, which inertia cannot) is not named `inertia_error` — inertia cannot explain both
/// angles — and the verdict is `unexplained`.
#[test]
fn a_pooled_fit_names_only_what_explains_every_release_angle() {
    use pantowatch_models::residual::pooled::analyse_pooled;
    let law = base("J3");
    let truth = Truth {
        law,
        readout: Readout::default(),
        dry_fade: 0.0,
    };
    let opts = FitOptions::default();
    let names = |f: &pantowatch_models::residual::pooled::PooledFinding| -> Vec<&str> {
        f.effects.iter().map(|e| e.name()).collect()
    };
    for seed in [71, 72] {
        // A true inertia error: J = 1.02 × stated, both recordings.
        let (a, _) = pendulum_test_with_inertia("J3", &truth, 30.0, 0.0, 1.02, seed);
        let (b, _) = pendulum_test_with_inertia("J3", &truth, 90.0, 0.0, 1.02, seed + 100);
        let f = analyse_pooled(&[&a, &b], &opts).expect("pooled");
        assert_eq!(names(&f), ["inertia_error"], "{:?}", f.candidates);
        let (mu, ci) = f
            .reported
            .shared(pantowatch_models::identify::Param::Dyn(
                pantowatch_models::friction::DynParam::Dry,
            ))
            .expect("dry");
        assert!(
            ci[0] <= law.dry && law.dry <= ci[1],
            "μ {mu} {ci:?}, truth {}",
            law.dry
        );
        for r in &f.recordings {
            assert!(r.explained_share >= 0.75, "{r:?}");
        }
        // A torsional spring (4 N·m/rad): not an inertia error at both angles.
        let (a, _) = pendulum_test("J3", &truth, 30.0, 4.0, seed + 200);
        let (b, _) = pendulum_test("J3", &truth, 90.0, 4.0, seed + 300);
        let f = analyse_pooled(&[&a, &b], &opts).expect("pooled");
        eprintln!(
            "spring: named {:?}, verdict {:?}; per recording {:?}",
            names(&f),
            f.verdict,
            f.recordings
                .iter()
                .map(|r| (
                    r.named_alone.clone(),
                    r.rmse_pooled_before,
                    r.rmse_pooled_after
                ))
                .collect::<Vec<_>>()
        );
        assert!(!names(&f).contains(&"inertia_error"), "{:?}", f.candidates);
        assert_eq!(f.verdict.as_deref(), Some("unexplained"));
    }
}

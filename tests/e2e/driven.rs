//! Input-driven single-joint tests (issue 17, point 3): a positioning axis driven by a measured
//! force, its force sensor's zero, its moving mass, and the input's own noise in the intervals.

use pantowatch_models::dynamics::{Dof, Input, Mechanism};
use pantowatch_models::friction::FrictionLaw;
use pantowatch_models::identify::{JointTest, Readout};
use pantowatch_models::rig::SliderRig;
use pantowatch_models::synth::{Sensor, Truth, grid, measure_truth};
use pantowatch_models::testspec::Baseline;

use crate::residual::{fit, names};

/// The positioning axis of the published example's kind (issue 17): a slider with no spring,
/// 8 kg stated (`mass_scale` × that moving in truth), viscous 204 N·s/m, Coulomb 20.4 N (μ 0.5
/// on 40.8 N; `asymmetry` δ: μ·(1 ± δ) by direction), driven by a measured 150 N, 0.4 Hz force whose sensor reads `b_true` low; the
/// recorded force carries 0.2 N white noise and 0.05 N steps, the position 0.05 mm noise and
/// 0.01 mm steps.
fn axis_test(
    seed: u64,
    b_true: f64,
    mass_scale: f64,
    asymmetry: f64,
) -> (JointTest, Baseline, FrictionLaw) {
    let (viscous, normal_n, mu) = (204.0, 40.8, 0.5);
    let rig = SliderRig::new(8.0, 0, 0.0, normal_n).unwrap();
    let t = grid(6.0, 500.0);
    let actual: Vec<f64> = t
        .iter()
        .map(|&x| 150.0 * (2.0 * std::f64::consts::PI * 0.4 * x).sin())
        .collect();
    let truth = Truth {
        law: FrictionLaw {
            asymmetry,
            ..FrictionLaw::base(viscous, mu)
        },
        readout: Readout::default(),
        dry_fade: 0.0,
    };
    let stated = Dof {
        mech: Mechanism::Slider(rig),
        input: Some(Input {
            t_s: t.clone(),
            value: actual.clone(),
        }),
        torsion: 0.0,
    };
    let sensor = Sensor {
        scale: 1000.0,
        noise_sigma: 0.05,
        quantum: 0.01,
        offset: 0.0,
        seed: 300 + seed,
    };
    let y = measure_truth(
        &stated.with_inertia_scale(mass_scale),
        &truth,
        0.0,
        0.0,
        &t,
        &sensor,
    )
    .unwrap();
    // The logger's force: the acting force less the sensor's zero, with noise and steps.
    let mut rng = pantowatch_models::noise::Noise::new(900 + seed);
    let recorded: Vec<f64> = actual
        .iter()
        .map(|f| ((f - b_true + 0.2 * rng.normal()) / 0.05).round() * 0.05)
        .collect();
    let test = JointTest {
        dof: Dof {
            input: Some(Input {
                t_s: t.clone(),
                value: recorded,
            }),
            ..stated
        },
        t_s: t,
        y,
        scale: 1000.0,
        unit: "mm",
        initial_rate: None,
        release_t_s: None,
        body_sd: Vec::new(),
    };
    let b = Baseline {
        joint: "custom".into(),
        viscous: None,
        dry: None,
        viscous_unit: "N·s/m",
    };
    (test, b, truth.law)
}

/// Issue 17, point 3: an input-driven slider with no spring (`axis_test`, the force sensor's
/// zero −3.2 N). The fit starts at the first sample and carries the force's zero: over 4 seeds
/// its interval holds −3.2 N, and viscous and Coulomb friction come back within their intervals
/// (at most one trace may miss: 95 %).
#[test]
fn an_input_driven_slider_s_force_zero_is_fitted_with_its_friction() {
    let b_true = -3.2;
    let (mut held, mut friction_held, n) = (0, 0, 4u64);
    for seed in 0..n {
        let (test, b, law) = axis_test(seed, b_true, 1.0, 0.0);
        let r = fit(&test, &b);
        let off = r.fit.input_offset.as_ref().map(|q| q.value);
        let ci = r.fit.input_offset_ci95;
        let j = &r.joints[0];
        eprintln!(
            "seed {seed}: input offset {off:?} {ci:?} (truth {b_true}); viscous {:.2} {:?}, dry {:.4} {:?}; rmse {:.4} mm, effects {:?}",
            j.viscous.value,
            j.viscous.ci95,
            j.dry.value,
            j.dry.ci95,
            r.rmse.value,
            names(&r)
        );
        assert_eq!(
            r.fit.samples_fitted,
            test.t_s.len(),
            "starts at the first sample"
        );
        assert!(names(&r).is_empty(), "nothing to name: {:?}", names(&r));
        let holds = |ci: [f64; 2], v: f64| ci[0] <= v && v <= ci[1];
        if ci.is_some_and(|c| holds(c, b_true)) {
            held += 1;
        }
        if holds(j.viscous.ci95, law.viscous) && holds(j.dry.ci95, law.dry) {
            friction_held += 1;
        }
    }
    assert!(
        held >= n - 1,
        "the force zero's interval held −3.2 N in {held} of {n}"
    );
    assert!(
        friction_held >= n - 1,
        "friction intervals held the truth in {friction_held} of {n}"
    );
}

/// Issue 17, point 3 (mass estimation): the same axis moving 5 % more (or 4 % less) mass than
/// stated. `inertia_error` names it, the mass ratio's interval holds the truth, the error at
/// least halves, and the friction and the force's zero come back within their intervals.
#[test]
fn an_input_driven_slider_s_mass_error_is_named_and_the_friction_recovered() {
    let mut failures = Vec::new();
    for (seed, scale) in [(10u64, 1.05), (11, 0.96), (12, 1.05)] {
        let (test, b, law) = axis_test(seed, -3.2, scale, 0.0);
        let r = fit(&test, &b);
        let res = &r.residual;
        let got = names(&r);
        let ratio = res
            .effects
            .iter()
            .find(|e| e.name == "inertia_error")
            .map(|e| {
                let ci = e.params["inertia_ratio_ci95"].as_array().unwrap();
                (
                    e.params["inertia_ratio"].as_f64().unwrap(),
                    ci[0].as_f64().unwrap(),
                    ci[1].as_f64().unwrap(),
                )
            });
        let j = &r.joints[0];
        eprintln!(
            "mass ×{scale}: {got:?} {ratio:?} rmse {:.4} -> {:.4} mm; viscous {:.2} {:?}, dry {:.4} {:?}, b {:?}",
            res.rmse_before,
            res.rmse_after,
            j.viscous.value,
            j.viscous.ci95,
            j.dry.value,
            j.dry.ci95,
            r.fit.input_offset_ci95
        );
        let mut fail = |why: String| failures.push(format!("×{scale}: {why}"));
        if got != vec!["inertia_error".to_string()] {
            fail(format!("named {got:?}"));
        }
        match ratio {
            Some((_, lo, hi)) if lo <= scale && scale <= hi => {}
            other => fail(format!("ratio {other:?} misses {scale}")),
        }
        if res.rmse_after > 0.5 * res.rmse_before {
            fail(format!("error {} -> {}", res.rmse_before, res.rmse_after));
        }
        let holds = |ci: [f64; 2], v: f64| ci[0] <= v && v <= ci[1];
        if !(holds(j.viscous.ci95, law.viscous) && holds(j.dry.ci95, law.dry)) {
            fail(format!("friction {:?} {:?}", j.viscous.ci95, j.dry.ci95));
        }
        if !r.fit.input_offset_ci95.is_some_and(|c| holds(c, -3.2)) {
            fail(format!("force zero {:?}", r.fit.input_offset_ci95));
        }
    }
    assert!(failures.is_empty(), "{failures:#?}");
}

/// Issue 17, point 3 (`asymmetric_friction`): the axis's Coulomb friction 20 % higher moving up
/// than down (δ 0.2: 24.5 N and 16.3 N) with the force sensor's zero −3.2 N. While sliding,
/// μ·N·(s + δ) is a symmetric friction plus a constant μ·N·δ = 4.08 N — exactly what a force
/// zero does — so this test cannot tell them apart: the score test finds the effect collinear
/// with the fitted zero and does not try it, nothing is named, and the zero reads their sum,
/// −3.2 − 4.08 = −7.28 N, with the symmetric friction recovered (3 of 4 seeds at least).
#[test]
fn direction_dependent_friction_on_a_driven_axis_reads_as_its_force_zero() {
    let (b_true, delta, n) = (-3.2, 0.2, 4u64);
    let expected = b_true - 40.8 * 0.5 * delta;
    let (mut held, mut friction_held) = (0, 0);
    for seed in 0..n {
        let (test, b, law) = axis_test(seed, b_true, 1.0, delta);
        let (r, _, finding) = pantowatch_models::fit_joint_test_with_finding(
            &test,
            &b,
            &pantowatch_models::drift::DriftThresholds::default(),
            "t",
            &pantowatch_models::identify::FitOptions::default(),
        )
        .unwrap();
        let off = r.fit.input_offset.as_ref().map(|q| q.value);
        let ci = r.fit.input_offset_ci95;
        let j = &r.joints[0];
        eprintln!(
            "seed {seed}: input offset {off:?} {ci:?} (b + μNδ = {expected}); viscous {:.2} {:?}, dry {:.4} {:?}; effects {:?}",
            j.viscous.value,
            j.viscous.ci95,
            j.dry.value,
            j.dry.ci95,
            names(&r)
        );
        assert!(names(&r).is_empty(), "named {:?}", names(&r));
        let tried = finding
            .candidates
            .iter()
            .find(|c| c.effects == [pantowatch_models::residual::Effect::AsymmetricFriction]);
        if let Some(c) = tried {
            assert!(
                c.score.is_none() || !c.accepted,
                "asymmetric friction tried and accepted: {c:?}"
            );
        }
        let holds = |ci: [f64; 2], v: f64| ci[0] <= v && v <= ci[1];
        if ci.is_some_and(|c| holds(c, expected)) {
            held += 1;
        }
        // The symmetric part: μ = (μ₊ + μ₋)/2, the truth's μ.
        if holds(j.viscous.ci95, law.viscous) && holds(j.dry.ci95, law.dry) {
            friction_held += 1;
        }
    }
    assert!(held >= n - 1, "the zero held b + μNδ in {held} of {n}");
    assert!(
        friction_held >= n - 1,
        "friction held in {friction_held} of {n}"
    );
}

/// Issue 38's before/after table (run by hand, not a timed test): every example trace and a
/// measured-like set of input-driven axis records (`synth::DrivenAxis`: 1–5 kHz, 5–60 s, the
/// stand's 0.2 N force noise and the logger's steps, 0.05 or 0.5 mm position noise), each
/// through the whole fit (`fit_joint_test`: base fit, residual loop, intervals); one JSON line
/// each to `$PANTOWATCH_ISSUE38_OUT` (values, intervals, effects, seconds).
#[test]
#[ignore]
fn issue38_before_after_table() {
    use pantowatch_models::synth::DrivenAxis;
    let out = std::env::var("PANTOWATCH_ISSUE38_OUT").unwrap_or("/dev/stderr".into());
    let mut lines = Vec::new();
    let mut row = |name: &str, test: &JointTest, b: &Baseline| {
        let clock = std::time::Instant::now();
        let r = pantowatch_models::fit_joint_test(
            test,
            b,
            &pantowatch_models::drift::DriftThresholds::default(),
            "t",
            &pantowatch_models::identify::FitOptions::default(),
        );
        let secs = clock.elapsed().as_secs_f64();
        let line = match r {
            Ok((r, _)) => {
                let j = &r.joints[0];
                serde_json::json!({"name": name, "samples": test.t_s.len(), "seconds": secs,
                    "viscous": j.viscous.value, "viscous_ci95": j.viscous.ci95,
                    "dry": j.dry.value, "dry_ci95": j.dry.ci95,
                    "input_offset": r.fit.input_offset.as_ref().map(|q| q.value),
                    "input_offset_ci95": r.fit.input_offset_ci95,
                    "rmse": r.rmse.value, "effects": names(&r)})
            }
            Err(e) => serde_json::json!({"name": name, "error": e.to_string()}),
        };
        eprintln!("{line}");
        lines.push(line.to_string());
    };
    if let Some(ex) = pantowatch::cli::examples_dir() {
        let mut files: Vec<_> = std::fs::read_dir(&ex)
            .unwrap()
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| {
                p.extension().is_some_and(|x| x == "json")
                    && p.file_stem().is_some_and(|s| s != "truth")
            })
            .collect();
        files.sort();
        for f in files {
            let doc = pantowatch::cli::read_trace(&f).unwrap();
            let (test, b) = doc.joint_test().unwrap();
            row(&f.file_stem().unwrap().to_string_lossy(), &test, &b);
        }
    }
    let b = Baseline {
        joint: "custom".into(),
        viscous: None,
        dry: None,
        viscous_unit: "N·s/m",
    };
    for (fs_hz, duration_s, pos_noise, seed) in [
        (1000.0, 25.0, 0.05, 1u64),
        (1000.0, 25.0, 0.05, 2),
        (2000.0, 10.0, 0.05, 3),
        (5000.0, 5.0, 0.05, 4),
        (1000.0, 25.0, 0.5, 5),
        (1000.0, 60.0, 0.05, 6),
    ] {
        let axis = DrivenAxis {
            moving_mass_kg: 8.0,
            viscous: 204.0,
            normal_force_n: 40.8,
            dry: 0.5,
            input_offset_n: -3.2,
            force_n: 150.0,
            fs_hz,
            duration_s,
            force_noise_n: 0.2,
            force_step_n: 0.05,
            position_noise_mm: pos_noise,
            position_step_mm: 0.01,
            seed,
        };
        let test = axis.record().unwrap();
        row(
            &format!("axis {fs_hz} Hz {duration_s} s {pos_noise} mm seed {seed}"),
            &test,
            &b,
        );
    }
    std::fs::write(&out, lines.join("\n") + "\n").unwrap();
}

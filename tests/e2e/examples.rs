//! Every example trace fitted against its README's truth: dry within 5 %, viscous within 15 %
//! where identifiable, the truth inside the 95 % interval; traces with effects do not crash.

use pantowatch::cli::fit::fit_doc;
use pantowatch::trace::TraceDoc;
use pantowatch_e2e::{examples_dir, measured_dir, truth};
use pantowatch_models::drift::{DriftThresholds, Status};

fn load(path: &std::path::Path) -> TraceDoc {
    TraceDoc::from_json(&std::fs::read(path).unwrap())
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

#[test]
fn every_example_is_recovered_within_the_issue_accuracy() {
    let truth = truth();
    let th = DriftThresholds::default();
    let mut checked = 0;
    for (name, t) in truth.as_object().unwrap() {
        let doc = load(&examples_dir().join(t["file"].as_str().unwrap()));
        let (r, _) = fit_doc(&doc, &th).unwrap_or_else(|e| panic!("{name}: {e}"));
        let j = &r.joints[0];
        assert_eq!(j.joint, t["joint"].as_str().unwrap());
        if !t["effects"].as_array().unwrap().is_empty() {
            // Out of scope for the base model (residual issue); must fit without error.
            assert!(r.rmse.value.is_finite());
            continue;
        }
        let (tv, td) = (t["viscous"].as_f64().unwrap(), t["dry"].as_f64().unwrap());
        let dry_err = (j.dry.value / td - 1.0).abs();
        assert!(
            dry_err < 0.05,
            "{name}: dry {} vs {td} ({:.1} %)",
            j.dry.value,
            100.0 * dry_err
        );
        assert!(
            j.dry.ci95[0] <= td && td <= j.dry.ci95[1],
            "{name}: true dry {td} outside {:?}",
            j.dry.ci95
        );
        assert!(
            j.viscous.ci95[0] <= tv && tv <= j.viscous.ci95[1],
            "{name}: true viscous {tv} outside {:?}",
            j.viscous.ci95
        );
        if j.viscous.identifiable {
            let e = (j.viscous.value / tv - 1.0).abs();
            assert!(
                e < 0.15,
                "{name}: viscous {} vs {tv} ({:.1} %)",
                j.viscous.value,
                100.0 * e
            );
        }
        // The RMSE reaches the sensor noise (σ = 0.05 plus quantisation).
        assert!(
            r.rmse.value < 1.05 * t["noise_sigma"].as_f64().unwrap(),
            "{name}: rmse {}",
            r.rmse.value
        );
        // Drift status as the examples were made: baseline ok, ×1.8 dry watch, ×2.5 viscous alarm.
        let expect = match (
            t["viscous_factor"].as_f64().unwrap(),
            t["dry_factor"].as_f64().unwrap(),
        ) {
            (v, d) if v >= 2.0 || d >= 2.0 => Status::Alarm,
            (v, d) if v > 1.5 || d > 1.5 => Status::Watch,
            _ => Status::Ok,
        };
        assert_eq!(j.status, expect, "{name}");
        checked += 1;
    }
    assert_eq!(checked, 10, "ten effect-free examples");
}

#[test]
fn the_fit_result_follows_the_contract() {
    let doc = load(&examples_dir().join("J3_dry_x1.8.json"));
    let (r, _) = fit_doc(&doc, &DriftThresholds::default()).unwrap();
    let v = serde_json::to_value(&r).unwrap();
    assert_eq!(v["trace_id"], "example-J3_dry_x1.8");
    let j = &v["joints"][0];
    assert_eq!(j["joint"], "J3");
    for p in ["viscous", "dry"] {
        assert!(j[p]["value"].is_f64());
        assert_eq!(j[p]["ci95"].as_array().unwrap().len(), 2);
        assert!(j[p]["baseline"].is_f64());
        assert!(j[p]["unit"].is_string());
    }
    assert_eq!(j["viscous"]["unit"], "N·m·s/rad");
    assert_eq!(j["dry"]["unit"], "1");
    assert_eq!(j["dry"]["baseline"], 0.2);
    assert!(j["identifiable"].is_boolean());
    assert_eq!(j["status"], "watch");
    assert_eq!(v["rmse"]["unit"], "deg");
    assert!(v["rmse"]["value"].is_f64());
    let res = &v["residual"];
    assert!(res["effects"].is_array());
    for k in [
        "rmse_before",
        "rmse_after",
        "holdout_rmse_before",
        "holdout_rmse_after",
    ] {
        assert!(res[k].is_f64(), "{k}");
    }
}

#[test]
fn the_measured_pendulum_is_fitted_from_its_release() {
    let doc = load(&measured_dir().join("encoder-pendulum-45deg.json"));
    let (r, fit) = fit_doc(&doc, &DriftThresholds::default()).unwrap();
    // The hand lets go at the first turning point, about sample 120 (README of the data).
    assert!(
        (110..=140).contains(&fit.start),
        "release at sample {}",
        fit.start
    );
    // A custom joint has no baseline: never judged ok/watch/alarm.
    assert_eq!(r.joints[0].status, Status::Unknown);
    assert!(
        r.joints[0].dry.value > 0.0 && r.rmse.value < 3.0,
        "{:?}",
        r.rmse
    );
    // Issue 17, point 1: the loop closes on the real recording. Its residual was a phase drift
    // (the period set by the stated J/(m·d) and a logger clock of about 1 ms per sample);
    // `inertia_error` names it and at least halves the held-out error (measured: J/J_stated
    // 0.9887 [0.9882, 0.9891]; held out 2.39° → 0.33°, fitted part 1.25° → 0.23°).
    let res = &r.residual;
    let names: Vec<&str> = res.effects.iter().map(|e| e.name.as_str()).collect();
    assert_eq!(names.first(), Some(&"inertia_error"), "{res:?}");
    // Nothing beside it but the sensor zero: a position-friction grid fitted with it reads friction
    // vanishing from −47° to −32° (no wear pattern; `residual::POSITION_FLOOR`) and is not named.
    assert!(
        names.iter().skip(1).all(|n| *n == "sensor_offset"),
        "{names:?}"
    );
    let ratio = res.effects[0].params["inertia_ratio"].as_f64().unwrap();
    assert!((0.97..1.0).contains(&ratio), "J/J_stated {ratio}");
    assert!(
        res.holdout_rmse_after <= 0.5 * res.holdout_rmse_before,
        "held out {} -> {}",
        res.holdout_rmse_before,
        res.holdout_rmse_after
    );
}

/// Issue 36, point 4: the 90° recording's first half swing is not free (it loses about a
/// quarter of its energy and lasts 24 % long: the hand held it), so the fit starts at the next
/// turning point (0.72 s), says what it left out, and reads the rod as the 45° recording does;
/// the 45° recording's release is free and nothing is left out.
#[test]
fn the_90_degree_recording_starts_where_its_swing_is_free() {
    let doc = load(&measured_dir().join("encoder-pendulum-90deg.json"));
    let (r, fit) = fit_doc(&doc, &DriftThresholds::default()).unwrap();
    assert_eq!(r.fit.release_rule, "disturbed", "{:?}", r.fit);
    let until = r.fit.release_disturbed_until_s.expect("until");
    assert!((0.70..=0.74).contains(&until), "free from {until} s");
    assert!((fit.start as f64 / 1000.0 - until).abs() < 0.01);
    let d = r.fit.release_disturbance.as_ref().expect("evidence");
    assert!(d.from_s < 0.3, "left out from {}", d.from_s);
    let first = &d.half_swings[0];
    // Measured: the energy lost per unit path 3.3× the later swings' trend, the half period
    // 1.2× theirs.
    assert!(
        first.energy_ratio > 2.5 && first.period_ratio > 1.15,
        "{first:?}"
    );
    assert!(d.reason.contains("turning point"), "{}", d.reason);
    // From there it fits as the 45° recording does: within 0.5° and μ near its 0.74–0.85.
    assert!(r.rmse.value < 0.5, "RMSE {}", r.rmse.value);
    let mu = r.joints[0].dry.value;
    assert!((0.6..1.0).contains(&mu), "μ {mu}");

    let doc45 = load(&measured_dir().join("encoder-pendulum-45deg.json"));
    let (r45, _) = fit_doc(&doc45, &DriftThresholds::default()).unwrap();
    assert_eq!(r45.fit.release_rule, "turning_point");
    assert!(r45.fit.release_disturbance.is_none());
}

/// Our simulator with the examples' true parameters and true release reproduces the
/// independent simulator's traces to within the sensor noise.
#[test]
fn the_simulator_agrees_with_the_independent_one_at_the_truth() {
    use pantowatch_models::friction::FrictionLaw;
    use pantowatch_models::simulate::{SimOptions, simulate};
    for (name, t) in truth().as_object().unwrap() {
        if !t["effects"].as_array().unwrap().is_empty() {
            continue;
        }
        let doc = load(&examples_dir().join(t["file"].as_str().unwrap()));
        let (test, _) = doc.joint_test().unwrap();
        let law = FrictionLaw::base(t["viscous"].as_f64().unwrap(), t["dry"].as_f64().unwrap());
        let q0 = match t["kind"].as_str().unwrap() {
            "pendulum" => t["initial"]["theta0_deg"].as_f64().unwrap() / test.scale,
            _ => t["initial"]["h0_mm"].as_f64().unwrap() / test.scale,
        };
        let tr = simulate(&test.dof, &law, q0, 0.0, &test.t_s, &SimOptions::default()).unwrap();
        let n = test.y.len() as f64;
        let rmse = (tr
            .q
            .iter()
            .zip(&test.y)
            .map(|(q, y)| (test.scale * q - y).powi(2))
            .sum::<f64>()
            / n)
            .sqrt();
        let sigma = t["noise_sigma"].as_f64().unwrap();
        assert!(rmse < 1.05 * sigma, "{name}: rmse {rmse} vs noise {sigma}");
        if let Some(rest) = t["t_rest_s"].as_f64() {
            let ours = tr.rest_time_s().expect("comes to rest");
            assert!(
                (ours - rest).abs() < 0.01,
                "{name}: rests at {ours} s, truth {rest} s"
            );
        }
    }
}

/// Issue 36, point 5: the encoder pendulum's two recordings (45° and 90°, one rod, one day)
/// fitted with one set of physical parameters. One inertia error explains most of the phase
/// drift of both — at least 75 % of each recording's excess over the noise, in its large and
/// its small swings — where the pooled base model leaves 1.2–1.4°; but it leaves over 3× the
/// noise, so the verdict is `unexplained`, with that evidence, not a name.
#[test]
fn the_two_measured_recordings_share_one_model() {
    let docs: Vec<(String, TraceDoc)> = ["45", "90"]
        .iter()
        .map(|a| {
            let p = measured_dir().join(format!("encoder-pendulum-{a}deg.json"));
            (a.to_string(), load(&p))
        })
        .collect();
    let (r, f) = pantowatch::cli::pooled::pooled(&docs).expect("pooled");
    let table = pantowatch::cli::pooled::table(&r);
    assert!(r.effects.is_empty(), "{table}");
    assert_eq!(r.verdict.as_deref(), Some("unexplained"), "{table}");
    let inertia = f
        .candidates
        .iter()
        .find(|c| c.effects.len() == 1 && c.effects[0].name() == "inertia_error")
        .expect("inertia tried");
    for (i, rec) in r.recordings.iter().enumerate() {
        assert!(rec.rmse_pooled_before > 1.0, "{rec:?}");
        assert!(inertia.rmse[i] < 0.5, "{inertia:?}");
        assert!(inertia.explained_share[i] >= 0.75, "{inertia:?}");
        assert!(inertia.remainder_over_noise[i] > 3.0, "{inertia:?}");
    }
    // Recordings of another rig are refused, naming the field.
    let mut other = docs.clone();
    other[1].1.pantograph_serial = Some("another-rod".into());
    let e = pantowatch::cli::pooled::pooled(&other)
        .unwrap_err()
        .to_string();
    assert!(e.contains("pantograph.serial"), "{e}");
}

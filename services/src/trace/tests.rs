use super::*;
use serde_json::json;

fn doc() -> Value {
    json!({"format": FORMAT, "vehicle_id": "EN57-1021", "pantograph": {"model": "160EC", "serial": "160EC-0042"},
               "recorded_at": "2026-03-02T07:15:00Z", "test": {"kind": "pendulum", "joint": "J1", "rig": {}},
               "channels": {"t_s": [0.0, 0.002, 0.004], "alpha_deg": [74.2, 74.19, 74.17]}})
}

fn field_of(v: Value) -> String {
    TraceDoc::from_value(&v).unwrap_err().field
}

/// Issue 17, point 3: a slider that is not the pantograph's head says so (`test.joint`:
/// `custom`): it is reported under that label, with no Table 4 baseline to judge it by, the
/// same physics fitted; its rig is stated in full, a missing value named.
#[test]
fn a_custom_slider_is_reported_as_custom_with_its_own_rig() {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../shared/data/examples/slider_baseline.json"
    );
    let head: Value = serde_json::from_slice(&std::fs::read(path).unwrap()).unwrap();
    let mut custom = head.clone();
    custom["test"]["joint"] = json!("custom");
    let thresholds = pantowatch_models::drift::DriftThresholds::default();
    let fit = |v: &Value| {
        crate::fitting::fit_document(&TraceDoc::from_value(v).unwrap(), &thresholds).unwrap()
    };
    let (j8, mine) = (fit(&head), fit(&custom));
    assert_eq!(j8.joints[0].joint, "J8");
    let c = &mine.joints[0];
    assert_eq!(c.joint, "custom");
    assert_eq!(c.status, pantowatch_models::drift::Status::Unknown);
    assert!(c.dry.baseline.is_none() && c.viscous.baseline.is_none());
    assert!((c.dry.value - j8.joints[0].dry.value).abs() <= 1e-9 * j8.joints[0].dry.value);
    for key in [
        "moving_mass_kg",
        "springs",
        "spring_stiffness_n_per_mm",
        "normal_force_n",
    ] {
        let mut d = custom.clone();
        d["test"]["rig"].as_object_mut().unwrap().remove(key);
        assert_eq!(field_of(d), format!("test.rig.{key}"));
    }
    let mut d = custom.clone();
    d["test"]["joint"] = json!("J3");
    assert_eq!(field_of(d), "test.joint");
}

/// Issue 18: one rule for a slider's springs (`[rig_limits] springs` in models/data): a
/// custom slider's "0 for none" is accepted — the range check refused it while the parser
/// said "0 to 64" — and a count outside the span or not whole is refused naming the field.
#[test]
fn a_custom_slider_without_springs_is_accepted() {
    let mut d = doc();
    d["test"] = json!({"kind": "slider", "joint": "custom",
            "rig": {"moving_mass_kg": 2.0, "springs": 0, "normal_force_n": 10.0}});
    d["channels"] = json!({"t_s": [0.0, 0.002, 0.004], "h_mm": [1.0, 0.9, 0.8]});
    TraceDoc::from_value(&d).expect("a custom slider with no spring");
    for bad in [
        json!(17),
        json!(64),
        json!(4_294_967_296_u64),
        json!(1.5),
        json!(-1),
    ] {
        let mut d = d.clone();
        d["test"]["rig"]["springs"] = bad.clone();
        d["test"]["rig"]["spring_stiffness_n_per_mm"] = json!(4.0);
        assert_eq!(field_of(d), "test.rig.springs", "{bad}");
    }
}

#[test]
fn accepts_the_contract_example() {
    let d = TraceDoc::from_value(&doc()).unwrap();
    assert_eq!(d.kind, Kind::Pendulum);
    assert_eq!(d.channels[0].0, "t_s");
    assert_eq!(TraceDoc::from_value(&d.to_value()).unwrap(), d);
}

#[test]
fn every_rule_names_its_field() {
    let mut cases: Vec<(Value, &str)> = Vec::new();
    let mut d = doc();
    d["format"] = json!("pantograph-trace/2");
    cases.push((d, "format"));
    let mut d = doc();
    d.as_object_mut().unwrap().remove("vehicle_id");
    cases.push((d, "vehicle_id"));
    let mut d = doc();
    d["pantograph"].as_object_mut().unwrap().remove("model");
    cases.push((d, "pantograph.model"));
    let mut d = doc();
    d["recorded_at"] = json!("2026-02-30T07:15:00Z");
    cases.push((d, "recorded_at"));
    let mut d = doc();
    d["test"]["kind"] = json!("swing");
    cases.push((d, "test.kind"));
    let mut d = doc();
    d["test"]["joint"] = json!("J9");
    cases.push((d, "test.joint"));
    let mut d = doc();
    d["test"] = json!({"kind": "quadrangle_swing", "rig": {"incline_deg": 70.0}});
    cases.push((d, "channels.beta_deg"));
    let quad = |rig: Value| {
        let mut d = doc();
        d["test"] = json!({"kind": "quadrangle_swing", "rig": rig});
        d["channels"]["beta_deg"] = json!([1.0, 2.0, 3.0]);
        d
    };
    cases.push((quad(json!({"incline_deg": 95.0})), "test.rig.incline_deg"));
    cases.push((quad(json!({"incline": 70.0})), "test.rig.incline"));
    cases.push((
            quad(json!({"attachments": [{"kind": "point", "mass_kg": 10.0, "body": "head", "position_m": [1.0, 0.0]}]})),
            "test.rig.attachments[0].body",
        ));
    cases.push((
            quad(json!({"attachments": [{"kind": "point", "mass_kg": 0.0, "body": "lower_arm", "position_m": [1.0, 0.0]}]})),
            "test.rig.attachments[0].mass_kg",
        ));
    cases.push((
            quad(json!({"attachments": [{"kind": "point", "mass_kg": 1.0, "body": "lower_arm", "position_m": [1.0]}]})),
            "test.rig.attachments[0].position_m",
        ));
    let mut d = quad(json!({}));
    d["test"]["joint"] = json!("J3");
    cases.push((d, "test.joint"));
    let mut d = doc();
    d["test"] = json!({"kind": "lift", "rig": {"L1_m": 1.6}});
    d["channels"] =
        json!({"t_s": [0.0, 0.1], "H_m": [1.0, 1.0], "T_Nm": [0.0, 0.0], "Fs_N": [0.0, 0.0]});
    cases.push((d, "test.rig.L1_m"));
    let mut d = doc();
    d["channels"]["t_s"] = json!([0.0, 0.002, 0.002]);
    cases.push((d, "channels.t_s[2]"));
    let mut d = doc();
    d["channels"]["alpha_deg"] = json!([1.0, 2.0]);
    cases.push((d, "channels.alpha_deg"));
    let mut d = doc();
    d["channels"]["alpha_deg"] = json!([1.0, "x", 2.0]);
    cases.push((d, "channels.alpha_deg[1]"));
    let mut d = doc();
    d["channels"].as_object_mut().unwrap().remove("alpha_deg");
    cases.push((d, "channels.alpha_deg"));
    let mut d = doc();
    d["test"]["rig"] =
        json!({"body": {"mass_kg": -1.0, "inertia_kgm2": 1.0, "com_distance_m": 0.1}});
    cases.push((d, "test.rig.body.mass_kg"));
    let mut d = doc();
    d["test"]["rig"] = json!({"pin_radius": 0.01});
    cases.push((d, "test.rig.pin_radius"));
    let mut d = doc();
    d["test"]["joint"] = json!("custom");
    cases.push((d, "test.rig.body"));
    let mut d = doc();
    d["trace_id"] = json!("a b; DROP TABLE traces");
    cases.push((d, "trace_id"));
    for (v, field) in cases {
        assert_eq!(field_of(v.clone()), field, "{v}");
    }
    assert_eq!(
        TraceDoc::from_json(b"{\"format\": ").unwrap_err().field,
        "body"
    );
    assert_eq!(
        TraceDoc::from_json(b"{\"a\": NaN}").unwrap_err().field,
        "body"
    );
}

/// A quadrangle swing with its rig is accepted as written in docs/TRACE_FORMAT.md and
/// round-trips; its channels and stand reach the model.
#[test]
fn accepts_a_quadrangle_swing() {
    let mut d = doc();
    d["test"] = json!({"kind": "quadrangle_swing", "rig": {"incline_deg": 65.0,
            "attachments": [{"kind": "point", "mass_kg": 5.0, "body": "upper_arm", "position_m": [0.5, 0.0]}]}});
    d["channels"]["beta_deg"] = json!([-3.6, -3.6, -3.59]);
    let doc = TraceDoc::from_value(&d).unwrap();
    assert_eq!(doc.kind, Kind::QuadrangleSwing);
    let (ch, rig) = doc.quadrangle_channels().unwrap();
    assert_eq!(ch.beta_deg, [-3.6, -3.6, -3.59]);
    assert_eq!(rig.incline_deg, 65.0);
    assert_eq!(rig.attachments.len(), 1);
    assert_eq!(TraceDoc::from_value(&doc.to_value()).unwrap(), doc);
}

/// A force-gauge test (issue 20): 6 readings raising to 1.8 m, 5 lowering.
fn gauge() -> Value {
    let h = [0.85, 1.0, 1.2, 1.4, 1.6, 1.8, 1.6, 1.4, 1.2, 1.0, 0.85];
    let f = [
        80.1, 79.5, 78.9, 78.0, 77.2, 76.4, 104.3, 105.2, 106.0, 106.9, 107.5,
    ];
    let t: Vec<f64> = (0..h.len()).map(|i| i as f64).collect();
    let mut d = doc();
    d["test"] = json!({"kind": "static_force", "gauge_resolution_n": 0.1});
    d["channels"] = json!({"t_s": t, "H_m": h, "F_N": f});
    d
}

#[test]
fn every_kind_parses_by_its_name() {
    for k in Kind::ALL {
        assert_eq!(Kind::parse(k.as_str()), Some(k));
    }
    assert_eq!(Kind::parse("gauge"), None);
    assert_eq!(Kind::StaticForce.as_str(), STATIC_FORCE);
}

/// Issue 20: a force gauge's readings, raising then lowering, are accepted as written in
/// docs/TRACE_FORMAT.md, round-trip, and split at the highest reading; every bad one is
/// refused naming its field.
#[test]
fn a_static_force_test_is_accepted_and_each_bad_reading_named() {
    let d = TraceDoc::from_value(&gauge()).expect("a gauge test");
    assert_eq!(d.kind, Kind::StaticForce);
    assert_eq!(TraceDoc::from_value(&d.to_value()).unwrap(), d);
    let g = d.static_force_channels().unwrap();
    assert_eq!(g.raise_len, 6);
    assert_eq!(g.gauge_resolution_n, 0.1);
    let [up, down] = g.branches();
    assert_eq!((up.len(), down.len()), (6, 5));
    assert_eq!(up[5], (1.8, 76.4));
    assert_eq!(down[0], (1.6, 104.3));
    // A height read twice in a branch is no turn (the gauge's scale is coarse).
    let mut twice = gauge();
    twice["channels"]["H_m"][2] = json!(1.0);
    twice["channels"]["H_m"][8] = json!(1.4);
    TraceDoc::from_value(&twice).expect("a height read twice in a branch");
    let min = data::builtin_160ec()
        .static_force
        .as_ref()
        .expect("[static_force]")
        .min_points_per_branch;
    assert_eq!(min, 5);
    // `path` as `/a/b/c`: objects keyed by name, arrays by index; a missing key is added.
    let set = |path: &str, v: Value| {
        let mut d = gauge();
        let mut at = &mut d;
        for k in path.trim_start_matches('/').split('/') {
            at = match k.parse::<usize>() {
                Ok(i) => &mut at[i],
                Err(_) => &mut at[k],
            };
        }
        *at = v;
        d
    };
    let keep = |n: std::ops::Range<usize>| {
        let mut d = gauge();
        for c in ["t_s", "H_m", "F_N"] {
            let a = d["channels"][c].as_array().unwrap()[n.clone()].to_vec();
            d["channels"][c] = Value::Array(a);
        }
        d
    };
    let mut no_res = gauge();
    no_res["test"]
        .as_object_mut()
        .unwrap()
        .remove("gauge_resolution_n");
    let mut no_force = gauge();
    no_force["channels"].as_object_mut().unwrap().remove("F_N");
    let cases = [
        (set("/channels/H_m/2", json!(1.85)), "channels.H_m[2]"),
        (set("/channels/H_m/10", json!(0.79)), "channels.H_m[10]"),
        (keep(0..6), "channels.H_m"),
        (keep(5..11), "channels.H_m"),
        (keep(2..11), "channels.H_m"),
        (keep(0..10), "channels.H_m"),
        (set("/channels/H_m/3", json!(1.1)), "channels.H_m[3]"),
        (set("/channels/H_m/8", json!(1.5)), "channels.H_m[8]"),
        (no_res, "test.gauge_resolution_n"),
        (
            set("/test/gauge_resolution_n", json!(0)),
            "test.gauge_resolution_n",
        ),
        (
            set("/test/gauge_resolution_n", json!("0.1")),
            "test.gauge_resolution_n",
        ),
        (
            set("/test/gauge_resolution_n", json!(10.0)),
            "test.gauge_resolution_n",
        ),
        (no_force, "channels.F_N"),
        (set("/channels/F_N/1", json!(-2000.0)), "channels.F_N[1]"),
        (set("/test/joint", json!("J3")), "test.joint"),
        (set("/test/rig", json!({"L1_m": 1.6})), "test.rig.L1_m"),
        (set("/pantograph/model", json!("200EC")), "pantograph.model"),
        (set("/test/kind", json!("lift")), "test.gauge_resolution_n"),
    ];
    for (v, field) in cases {
        assert_eq!(field_of(v.clone()), field, "{v}");
    }
    // Read by hand: readings a minute apart are a gauge test (a logger's channel may not
    // pause over 1 s); a pause over `gauge_reading_interval_s` is refused at its reading.
    let spaced = |dt: f64| {
        let t: Vec<f64> = (0..11).map(|i| i as f64 * 60.0).collect();
        let mut d = set("/channels/t_s", json!(t));
        d["channels"]["t_s"][7] = json!(6.0 * 60.0 + dt);
        for i in 8..11 {
            d["channels"]["t_s"][i] = json!(6.0 * 60.0 + dt + (i - 7) as f64 * 60.0);
        }
        d
    };
    TraceDoc::from_value(&spaced(60.0)).expect("readings a minute apart");
    assert_eq!(field_of(spaced(601.0)), "channels.t_s[7]");
    let mut logger = doc();
    logger["channels"]["t_s"][1] = json!(60.0);
    assert!(
        field_of(logger).starts_with("channels.t_s["),
        "a logger's channel keeps its 1 s rule"
    );
    // A pendulum states no gauge.
    let mut d = doc();
    d["test"]["gauge_resolution_n"] = json!(0.1);
    assert_eq!(field_of(d), "test.gauge_resolution_n");
}

/// docs/API.md "Input limits" lists the `[static_force]` limits an upload is checked against.
#[test]
fn the_api_doc_lists_the_static_force_limits() {
    let doc = include_str!("../../../docs/API.md");
    let sf = data::builtin_160ec()
        .static_force
        .as_ref()
        .expect("[static_force]");
    let [lo, hi] = sf.working_height_m;
    for row in [
        format!("| `[static_force] working_height_m` | [{lo}, {hi}] |"),
        format!(
            "| `[static_force] min_points_per_branch` | {} |",
            sf.min_points_per_branch
        ),
        format!(
            "| `[static_force] gauge_resolution_range_n` | [{}, {}] |",
            sf.gauge_resolution_range_n[0], sf.gauge_resolution_range_n[1]
        ),
        format!(
            "| `[static_force] gauge_reading_interval_s` | [{}, {}] |",
            sf.gauge_reading_interval_s[0], sf.gauge_reading_interval_s[1]
        ),
    ] {
        assert!(
            doc.contains(&row),
            "docs/API.md \"Input limits\" lacks {row}"
        );
    }
}

#[test]
fn rfc3339() {
    for ok in [
        "2026-03-02T07:15:00Z",
        "2024-02-29T23:59:60.123+01:00",
        "2026-03-02t07:15:00z",
    ] {
        assert!(check_rfc3339(ok), "{ok}");
    }
    for no in [
        "2026-03-02",
        "2026-03-02T07:15:00",
        "2025-02-29T00:00:00Z",
        "2026-13-01T00:00:00Z",
        "2026-03-02T07:15:00+0100",
        "2026-03-02T07:15:00.Z",
        // Issue 18: outside the years 1…9999 once the offset is applied.
        "9999-12-31T23:59:59-23:59",
        "0000-06-01T00:00:00Z",
        "0001-01-01T00:30:00+01:00",
    ] {
        assert!(!check_rfc3339(no), "{no}");
    }
    for edge in [
        "9999-12-31T23:59:59Z",
        "0001-01-01T00:00:00Z",
        "0001-01-01T00:30:00-01:00",
    ] {
        assert!(check_rfc3339(edge), "{edge}");
    }
    let why = rfc3339_problem("9999-12-31T23:59:59-23:59").unwrap();
    assert!(why.contains("year 10000"), "{why}");
}

/// Issue 17, points 1 and 7: a rig may state its body's 1 σ errors (`test.rig.body_uncertainty`
/// for a pendulum, of the stated body or the paper's default one; `moving_mass_uncertainty_kg`
/// for a slider). One that is negative, not a number, or not below the value it qualifies is
/// refused naming its exact path; 0 is accepted and carries nothing.
#[test]
fn a_body_uncertainty_is_refused_naming_its_path_when_negative_or_not_below_its_value() {
    let with = |rig: Value| {
        let mut d = doc();
        d["test"]["rig"] = rig;
        d
    };
    let body = json!({"mass_kg": 2.0, "inertia_kgm2": 0.6, "com_distance_m": 0.5});
    let u = "test.rig.body_uncertainty";
    let refused = [
        (
            json!({"body_uncertainty": {"inertia_kgm2": -0.01}}),
            format!("{u}.inertia_kgm2"),
        ),
        (
            json!({"body_uncertainty": {"mass_kg": "0.1"}}),
            format!("{u}.mass_kg"),
        ),
        (
            json!({"body_uncertainty": {"com_distance_m": 1e3}}),
            format!("{u}.com_distance_m"),
        ),
        (
            json!({"body_uncertainty": {"mass": 0.1}}),
            format!("{u}.mass"),
        ),
        (json!({"body_uncertainty": [0.1]}), u.to_owned()),
        (
            json!({"body": body, "body_uncertainty": {"inertia_kgm2": 0.6}}),
            format!("{u}.inertia_kgm2"),
        ),
        (
            json!({"body": body, "body_uncertainty": {"mass_kg": 2.5}}),
            format!("{u}.mass_kg"),
        ),
    ];
    for (rig, field) in refused {
        let e = TraceDoc::from_value(&with(rig.clone())).unwrap_err();
        assert_eq!(e.field, field, "{rig}: {e}");
    }
    for rig in [
        json!({"body": body, "body_uncertainty": {"mass_kg": 0.02, "inertia_kgm2": 0.59, "com_distance_m": 0.0}}),
        json!({"body_uncertainty": {"inertia_kgm2": 0.0}}),
        json!({"body_uncertainty": {}}),
    ] {
        TraceDoc::from_value(&with(rig.clone())).unwrap_or_else(|e| panic!("{rig}: {e}"));
    }
    // The paper's default body's value bounds it: J1's inertia about its pin.
    let data = pantowatch_models::data::builtin_160ec();
    let j1 = &data.bodies[&data.rigs["J1"].body];
    let inertia = j1.inertia_axis_kgm2.unwrap();
    let (test, _) = TraceDoc::from_value(&with(json!({"body_uncertainty":
        {"inertia_kgm2": 0.5 * inertia, "mass_kg": 0.0}})))
    .unwrap()
    .joint_test()
    .unwrap();
    let carried: Vec<_> = test.body_sd.iter().map(|b| (b.quantity, b.sd)).collect();
    assert_eq!(
        carried,
        [("inertia_kgm2", 0.5 * inertia)],
        "a 0 sd carries nothing"
    );
    let e = TraceDoc::from_value(&with(
        json!({"body_uncertainty": {"inertia_kgm2": inertia}}),
    ))
    .unwrap_err();
    assert_eq!(e.field, format!("{u}.inertia_kgm2"), "{e}");
    // A slider's moving mass: the head's default (`[slider] moving_mass_kg`) or the stated one.
    let slider = |rig: Value| {
        let mut d = doc();
        d["test"] = json!({"kind": "slider", "joint": "J8", "rig": rig});
        d["channels"] = json!({"t_s": [0.0, 0.002, 0.004], "h_mm": [1.0, 0.9, 0.8]});
        d
    };
    let m = data.slider.moving_mass_kg;
    const S: &str = "test.rig.moving_mass_uncertainty_kg";
    for (rig, ok) in [
        (json!({"moving_mass_uncertainty_kg": -0.1}), false),
        (json!({"moving_mass_uncertainty_kg": m}), false),
        (json!({"moving_mass_uncertainty_kg": true}), false),
        (
            json!({"moving_mass_kg": 2.0, "moving_mass_uncertainty_kg": 2.0}),
            false,
        ),
        (
            json!({"moving_mass_kg": 2.0, "moving_mass_uncertainty_kg": 0.1}),
            true,
        ),
        (json!({"moving_mass_uncertainty_kg": 0.0}), true),
        (json!({"moving_mass_uncertainty_kg": 0.05 * m}), true),
    ] {
        match TraceDoc::from_value(&slider(rig.clone())) {
            Ok(_) if ok => {}
            Err(e) if !ok => assert_eq!(e.field, S, "{rig}: {e}"),
            other => panic!("{rig}: {other:?}"),
        }
    }
}

/// Issue 17, point 1, through the service's fit (the shared J5 example): stated uncertainties
/// of 0 give the fit result unchanged, to the bit; a stated body-mass uncertainty is echoed in
/// `fit.body_uncertainty` and widens the intervals about the same estimates.
#[test]
fn a_stated_body_uncertainty_is_echoed_and_widens_the_intervals_and_zero_changes_nothing() {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../shared/data/examples/J5_baseline.json"
    );
    let plain: Value = serde_json::from_slice(&std::fs::read(path).unwrap()).unwrap();
    let thresholds = pantowatch_models::drift::DriftThresholds::default();
    let fit = |v: &Value| {
        crate::fitting::fit_document(&TraceDoc::from_value(v).unwrap(), &thresholds).unwrap()
    };
    let with = |u: Value| {
        let mut d = plain.clone();
        d["test"]["rig"]["body_uncertainty"] = u;
        d
    };
    let base = fit(&plain);
    assert!(base.fit.body_uncertainty.is_none());
    let zero = fit(&with(json!({"inertia_kgm2": 0.0, "mass_kg": 0.0})));
    assert_eq!(zero, base, "a stated 0 carries nothing");
    let stated = fit(&with(json!({"mass_kg": 0.1})));
    let echo = serde_json::to_value(&stated.fit.body_uncertainty).unwrap();
    assert_eq!(echo, json!({"propagated": {"mass_kg": 0.1}}));
    let (b, s) = (&base.joints[0], &stated.joints[0]);
    for (pb, ps) in [(&b.viscous, &s.viscous), (&b.dry, &s.dry)] {
        assert_eq!(pb.value, ps.value, "the same estimate");
        assert!(
            ps.ci95[0] <= pb.ci95[0] && ps.ci95[1] >= pb.ci95[1],
            "{:?} within {:?}",
            pb.ci95,
            ps.ci95
        );
    }
    assert!(s.dry.ci95[1] - s.dry.ci95[0] > b.dry.ci95[1] - b.dry.ci95[0]);
}

/// Issue 17, point 1, a slider: the head's stated moving-mass uncertainty is carried by the fit
/// and echoed — propagated, or listed as not propagated when `inertia_error` estimates the mass.
#[test]
fn a_slider_s_moving_mass_uncertainty_is_carried_and_echoed() {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../shared/data/examples/slider_baseline.json"
    );
    let mut d: Value = serde_json::from_slice(&std::fs::read(path).unwrap()).unwrap();
    let m = d["test"]["rig"]["moving_mass_kg"].as_f64().unwrap_or(
        pantowatch_models::data::builtin_160ec()
            .slider
            .moving_mass_kg,
    );
    d["test"]["rig"]["moving_mass_uncertainty_kg"] = json!(0.02 * m);
    let thresholds = pantowatch_models::drift::DriftThresholds::default();
    let r = crate::fitting::fit_document(&TraceDoc::from_value(&d).unwrap(), &thresholds).unwrap();
    let echo = r.fit.body_uncertainty.expect("echoed");
    let named = r.residual.effects.iter().any(|e| e.name == "inertia_error");
    let (into, other) = if named {
        (&echo.not_propagated, &echo.propagated)
    } else {
        (&echo.propagated, &echo.not_propagated)
    };
    assert_eq!(into.get("moving_mass_kg"), Some(&(0.02 * m)), "{echo:?}");
    assert!(other.is_empty(), "{echo:?}");
}

/// Issue 19, point 1: the test is typed once, where the document is parsed — the views read
/// the typed [`TestSpec`], not the JSON again. A parsed pendulum document whose `test` JSON is
/// afterwards replaced by one the parser refuses (a negative pin radius) still gives the parsed
/// joint's test; a stored
/// trace (`ingest::stored_doc`) is typed the same way, and one that no longer reads is an error,
/// not a later surprise in the fit.
#[test]
fn the_test_is_typed_once_where_the_document_is_parsed() {
    let mut d = TraceDoc::from_value(&doc()).unwrap();
    let TestSpec::Joint(j) = &d.spec else {
        panic!("a pendulum types as a joint test: {:?}", d.spec)
    };
    assert_eq!(j.1.joint, "J1");
    let typed = d.joint_test().unwrap();
    let bad = json!({"kind": "pendulum", "joint": "J1", "rig": {"pin_radius_m": -1.0}});
    let mut v = doc();
    v["test"] = bad.clone();
    assert_eq!(
        field_of(v),
        "test.rig.pin_radius_m",
        "the parser refuses it"
    );
    d.test = bad;
    assert_eq!(
        d.joint_test().unwrap(),
        typed,
        "the view reads the typed test"
    );
    assert!(d.lift_channels().is_err() && d.static_force_channels().is_err());
    // Typing again from the (now bad) JSON is where it would be checked.
    assert_eq!(d.typed().unwrap_err().field, "test.rig.pin_radius_m");
}

/// Issue 39, point 3: the document is read by serde into typed structs, closed where the
/// contract lists the keys; a value of the wrong shape or a key the object does not have is
/// named by its path, the same from JSON bytes as from a parsed value. An array where the
/// contract has an object is refused (a struct serde derives would read it by position).
#[test]
fn the_typed_document_names_a_wrong_shape_or_an_unknown_key_by_its_path() {
    let quad = |attachment: Value| {
        let mut d = doc();
        d["test"] = json!({"kind": "quadrangle_swing", "rig": {"attachments": [attachment]}});
        d["channels"]["beta_deg"] = json!([1.0, 2.0, 3.0]);
        d
    };
    // `path` as `/a/b/1`: objects keyed by name (a missing key added), arrays by index.
    let with = |path: &str, v: Value| {
        let mut d = doc();
        let mut at = &mut d;
        for k in path.trim_start_matches('/').split('/') {
            at = match k.parse::<usize>() {
                Ok(i) => &mut at[i],
                Err(_) => &mut at[k],
            };
        }
        *at = v;
        d
    };
    let mut cases = vec![
        (with("/pantograph", json!(["160EC"])), "pantograph"),
        (with("/pantograph/serial", json!(42)), "pantograph.serial"),
        (with("/test/kind", json!(5)), "test.kind"),
        (with("/test/rig", json!([])), "test.rig"),
        (
            with("/test/rig/body", json!([18.8, 5.61, 0.272])),
            "test.rig.body",
        ),
        (
            with("/test/rig/body_uncertainty", json!([0.1])),
            "test.rig.body_uncertainty",
        ),
        (
            with(
                "/test/rig/attachments",
                json!([{"kind": "rod", "mass_kg": 1.0, "length_m": 0.5, "distance_m": 0.1}]),
            ),
            "test.rig.attachments[0].distance_m",
        ),
        (
            with(
                "/test/rig/attachments",
                json!([{"kind": "disc", "mass_kg": 1.0}]),
            ),
            "test.rig.attachments[0].kind",
        ),
        (
            with(
                "/test/rig/attachments",
                json!([{"mass_kg": 1.0, "length_m": 0.5}]),
            ),
            "test.rig.attachments[0].kind",
        ),
        (
            with(
                "/test/rig/attachments",
                json!([{"kind": "rod", "mass_kg": 1.0}]),
            ),
            "test.rig.attachments[0].length_m",
        ),
        (
            with("/channels/alpha_deg/1", json!("74.19")),
            "channels.alpha_deg[1]",
        ),
        (
            with("/channels/alpha_deg", json!({"0": 74.2})),
            "channels.alpha_deg",
        ),
        (with("/channels", json!([[0.0, 0.002]])), "channels"),
        (
            quad(
                json!({"kind": "point", "mass_kg": 1.0, "body": "upper_arm", "position_m": [0.5, "0"]}),
            ),
            "test.rig.attachments[0].position_m",
        ),
        (
            quad(
                json!({"kind": "point", "mass_kg": 1.0, "body": "upper_arm", "position_m": {"x": 0.5}}),
            ),
            "test.rig.attachments[0].position_m",
        ),
        (quad(json!([1.0])), "test.rig.attachments[0]"),
    ];
    let mut d = doc();
    d["test"]["rig"]["body"] = json!({"mass_kg": 18.8, "inertia_kgm2": 5.6, "com_m": 0.27});
    cases.push((d, "test.rig.body.com_m"));
    for (v, field) in cases {
        assert_eq!(field_of(v.clone()), field, "from a value: {v}");
        let bytes = serde_json::to_vec(&v).unwrap();
        match TraceDoc::parse_json(&bytes) {
            Err(JsonError::Invalid(e)) => assert_eq!(e.field, field, "from JSON: {v}: {e}"),
            other => panic!("{v}: {other:?}"),
        }
    }
    // The root must be an object: JSON that is not one is a contract error naming `body`;
    // text that is not JSON (trailing characters included) is malformed.
    assert!(
        matches!(TraceDoc::parse_json(b"[1, 2]"), Err(JsonError::Invalid(e)) if e.field == "body")
    );
    for text in [&b"{} {}"[..], b"{\"format\": 1e999}", b"[1,"] {
        assert!(
            matches!(TraceDoc::parse_json(text), Err(JsonError::Malformed(e)) if e.field == "body"),
            "{text:?}"
        );
    }
}

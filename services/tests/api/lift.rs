//! Lift traces over HTTP (issue 5): the reference lift is fitted like any other kind, with
//! every joint J1…J9 in the result (the `quadrangle_swing` kind: `quadrangle.rs`).

use reqwest::{Method, StatusCode};
use serde_json::{Value, json};

use crate::harness::*;

pub async fn lift_trace_is_fitted_with_every_joint(b: Backend) {
    let app = spawn_app(b).await;
    let r = app
        .upload_json(&shared("reference/lift-example.json"))
        .await;
    assert_eq!(r.status(), StatusCode::ACCEPTED);
    let id: String = r.json::<Value>().await.expect("json")["trace_id"]
        .as_str()
        .expect("id")
        .to_owned();
    let fit = app.wait_for_fit(&id).await;
    let joints = fit["joints"].as_array().expect("joints");
    let names: Vec<&str> = joints.iter().filter_map(|j| j["joint"].as_str()).collect();
    assert_eq!(
        names[..10],
        ["J1", "J2", "J2'", "J3", "J4", "J5", "J6", "J7", "J8", "J9"],
        "{fit}"
    );
    // Then the combinations the lift informs (issue 15): J1+J3 dry, judged like a joint.
    assert_eq!(names[10..], ["J1+J3"], "{fit}");
    assert_eq!(fit["combinations"][0]["label"], "J1+J3 dry", "{fit}");
    for j in joints {
        let status = j["status"].as_str().unwrap_or("");
        assert!(status == "ok" || status == "unknown", "{j}");
        if j["identifiable"] == false {
            assert_eq!(status, "unknown", "{j}");
        }
    }
    let j3 = joints.iter().find(|j| j["joint"] == "J3").expect("J3");
    assert_eq!(j3["dry"]["combination"], "J1+J3 dry", "{j3}");
    let both = joints
        .iter()
        .find(|j| j["joint"] == "J1+J3")
        .expect("J1+J3");
    assert_eq!(both["identifiable"], true, "{both}");
    assert_eq!(fit["rmse"]["unit"], "m");
    assert!(fit["rmse"]["value"].as_f64().expect("rmse") < 1e-3, "{fit}");
    assert_eq!(fit["residual"]["effects"], json!([]));
    // The lift's stored curve is H measured and modelled; its page draws it (no refit).
    let (s, c) = app.get_json(&format!("/v1/traces/{id}/fit/curve")).await;
    assert_eq!(s, StatusCode::OK, "{c}");
    assert_eq!(c["channel"], "H_m");
    let res = c["residual"].as_array().expect("residual");
    let rms = (res
        .iter()
        .map(|r| r.as_f64().unwrap_or(f64::NAN).powi(2))
        .sum::<f64>()
        / res.len() as f64)
        .sqrt();
    let fit_rmse = fit["rmse"]["value"].as_f64().expect("rmse");
    assert!(
        rms < 2.0 * fit_rmse + 1e-6,
        "curve RMS {rms} against the fit's {fit_rmse}"
    );
    let page = app.web_page(&format!("/traces/{id}")).await;
    assert!(page.contains("Measured vs model"), "{page}");
    // The joint history holds the lift's verdicts like any other fit's.
    let (s, h) = app
        .get_json("/v1/pantographs/160EC-REFERENCE/joints/J3/history")
        .await;
    if s == StatusCode::OK {
        assert!(h.to_string().contains(&id), "{h}");
    }
    // A re-fit by the same model version queues nothing: the fit is written.
    let r = app
        .req(Method::POST, "/v1/admin/refit", Some(&app.keys.admin))
        .json(&json!({"vehicle_id": "REFERENCE-SIM"}))
        .send()
        .await
        .expect("refit");
    assert_eq!(r.status(), StatusCode::ACCEPTED);
    assert_eq!(r.json::<Value>().await.expect("json")["queued"], 0);

    app.stop().await;
}

/// Issue 15, point 7: a lift whose inputs carry a non-finite value, a gap of missing samples,
/// a torque the drive cannot make, a protocol outside the stand's limits or a record longer
/// than its fit is validated for is refused 422 naming the field; nothing is stored.
pub async fn bad_lift_inputs_are_refused_naming_the_sample(b: Backend) {
    let app = spawn_app(b).await;
    let base: Value = serde_json::from_slice(&shared("reference/lift-example.json")).expect("lift");
    let before = app.counts().await;
    let edit = |f: &dyn Fn(&mut Value)| {
        let mut d = base.clone();
        d["trace_id"] = "bad-lift".into();
        f(&mut d);
        serde_json::to_vec(&d).expect("json")
    };
    let n = base["channels"]["t_s"].as_array().expect("t_s").len();
    let cases: Vec<(Vec<u8>, String)> = vec![
        // 40 samples dropped after sample 1000: a gap of 41 intervals.
        (
            edit(&|d| {
                for c in ["t_s", "H_m", "T_Nm", "Fs_N", "Fm_N"] {
                    if let Some(a) = d["channels"][c].as_array_mut() {
                        a.drain(1001..1041);
                    }
                }
            }),
            "channels.t_s[1001]".into(),
        ),
        (
            edit(&|d| d["channels"]["T_Nm"][412] = json!(-50.0)),
            "channels.T_Nm[412]".into(),
        ),
        (
            edit(&|d| d["channels"]["T_Nm"][n - 1] = json!(1e6)),
            format!("channels.T_Nm[{}]", n - 1),
        ),
        (
            edit(&|d| d["channels"]["Fs_N"][7] = json!("NaN")),
            "channels.Fs_N[7]".into(),
        ),
        // A stated drive protocol outside the stand's limits (issue 15 point 7,
        // `lift::design::ProtocolLimits::stand`): a pressure step faster than the drive's
        // response, a dwell height outside the working range, a field that is no protocol's.
        (
            edit(&|d| {
                let mut p = stated_protocol();
                p["moves"][0]["tau_s"] = json!(0.05);
                d["test"]["protocol"] = p;
            }),
            "test.protocol.moves[0].tau_s".into(),
        ),
        (
            edit(&|d| {
                let mut p = stated_protocol();
                p["moves"][0]["height_m"] = json!(2.3);
                d["test"]["protocol"] = p;
            }),
            "test.protocol.moves[0].height_m".into(),
        ),
        (
            edit(&|d| {
                let mut p = stated_protocol();
                p["pressure_bar"] = json!(6);
                d["test"]["protocol"] = p;
            }),
            "test.protocol".into(),
        ),
        // Longer than the 12 s a lift's fit is validated for (`[stand] duration_max_s`): a
        // stated protocol of 19.5 s, and a record of 16 s with no protocol stated (the
        // reference lift twice over).
        (
            edit(&|d| {
                let mut p = stated_protocol();
                p["t_end_s"] = json!(19.5);
                d["test"]["protocol"] = p;
            }),
            "test.protocol.t_end_s".into(),
        ),
        (
            edit(&|d| {
                let t: Vec<f64> = d["channels"]["t_s"]
                    .as_array()
                    .expect("t_s")
                    .iter()
                    .map(|v| v.as_f64().expect("a time"))
                    .collect();
                let shift = t[t.len() - 1] - t[0] + (t[1] - t[0]);
                let later: Vec<Value> = t.iter().map(|v| json!(v + shift)).collect();
                d["channels"]["t_s"]
                    .as_array_mut()
                    .expect("t_s")
                    .extend(later);
                for c in ["H_m", "T_Nm", "Fs_N", "Fm_N"] {
                    if let Some(a) = d["channels"][c].as_array_mut() {
                        let again = a.clone();
                        a.extend(again);
                    }
                }
            }),
            "channels.t_s".into(),
        ),
    ];
    for (body, field) in cases {
        let r = app.upload_json(&body).await;
        assert_problem(r, StatusCode::UNPROCESSABLE_ENTITY, Some(&field), &field).await;
    }
    // The same lift as CSV with `nan` in a torque sample.
    let doc = pantowatch::trace::TraceDoc::from_value(&base).expect("doc");
    let csv = pantowatch::trace_csv::write(&doc);
    let mut lines: Vec<String> = csv.lines().map(str::to_owned).collect();
    let header = lines
        .iter()
        .position(|l| l.starts_with("t_s"))
        .expect("header");
    let names: Vec<&str> = lines[header].split(',').collect::<Vec<_>>();
    let col = names
        .iter()
        .position(|c| *c == "T_Nm")
        .expect("T_Nm column");
    let row = header + 1 + 20;
    let mut cells: Vec<String> = lines[row].split(',').map(str::to_owned).collect();
    cells[col] = "nan".into();
    lines[row] = cells.join(",");
    let r = app
        .req(Method::POST, "/v1/traces", Some(&app.keys.writer))
        .header("content-type", "text/csv")
        .body(lines.join("\n"))
        .send()
        .await
        .expect("POST csv");
    assert_problem(
        r,
        StatusCode::UNPROCESSABLE_ENTITY,
        Some("channels.T_Nm[20]"),
        "csv nan",
    )
    .await;
    assert_eq!(app.counts().await, before, "nothing stored");
    app.stop().await;
}

/// The raise and lower as a trace states it (`test.protocol`).
fn stated_protocol() -> Value {
    let g = pantowatch_models::lift::geometry::builtin_160ec();
    let m = pantowatch_models::lift::dynamics::LiftModel::new(g);
    serde_json::to_value(
        pantowatch_models::lift::protocol::LiftProtocol::raise_and_lower(&m, g).expect("protocol"),
    )
    .expect("json")
}

/// Issue 15, point 3: a lift run by a designed protocol (`pantowatch design-test`'s moves,
/// stated in `test.protocol`, realistic sensor noise on every channel) is accepted, fitted and
/// served; the protocol survives storage and the CSV round trip.
pub async fn a_designed_lift_is_accepted_and_fitted(b: Backend) {
    use pantowatch_models::lift::protocol::Move;
    let app = spawn_app(b).await;
    let g = pantowatch_models::lift::geometry::builtin_160ec();
    let m = pantowatch_models::lift::dynamics::LiftModel::new(g);
    let mut p = pantowatch_models::lift::protocol::LiftProtocol::reference(g);
    // The moves `design-test` chose on the stand's space (docs/VALIDATION.md, "A designed lift test").
    for (t_s, h) in [(3.5, 1.424), (5.5, 1.216)] {
        p.moves.push(Move {
            t_s,
            torque_nm: pantowatch_models::lift::design::holding_torque_nm(&m, g, &p, h)
                .expect("torque"),
            tau_s: 1.0,
            height_m: Some(h),
        });
    }
    p.t_end_s = 7.5;
    let file = std::env::temp_dir().join(format!("pw-designed-{}.json", std::process::id()));
    std::fs::write(&file, serde_json::to_vec(&p).expect("json")).expect("write");
    let defaults = pantowatch::cli::simulate::docs::simulate_defaults().expect("defaults");
    let doc = pantowatch::cli::simulate::simulate_doc(&pantowatch::cli::simulate::SimulateArgs {
        kind: "lift".into(),
        protocol: file.display().to_string(),
        sensor_noise: 1.0,
        h_noise_mm: 0.0,
        seed: 11,
        trace_id: Some("designed-1".into()),
        ..defaults
    })
    .expect("designed lift");
    let _ = std::fs::remove_file(&file);
    assert_eq!(doc.test["protocol"]["moves"][1]["height_m"], json!(1.216));
    let csv = pantowatch::trace_csv::write(&doc);
    let back = pantowatch::trace_csv::parse(csv.as_bytes()).expect("csv doc");
    assert_eq!(back.test["protocol"], doc.test["protocol"]);
    let r = app
        .upload_json(&serde_json::to_vec(&doc.to_value()).expect("json"))
        .await;
    assert_eq!(r.status(), StatusCode::ACCEPTED);
    let id: String = r.json::<Value>().await.expect("json")["trace_id"]
        .as_str()
        .expect("id")
        .into();
    let fit = app.wait_for_fit(&id).await;
    let j3 = fit["joints"]
        .as_array()
        .expect("joints")
        .iter()
        .find(|j| {
            j["joint"]
                .as_str()
                .is_some_and(|n| n.split('+').any(|p| p == "J3"))
                && j["dry"]["ci95"].is_array()
                && j["identifiable"] == json!(true)
        })
        .unwrap_or_else(|| panic!("an informed entry holding J3: {fit}"));
    let ci = &j3["dry"]["ci95"];
    let (lo, hi) = (ci[0].as_f64().expect("lo"), ci[1].as_f64().expect("hi"));
    let truth = if j3["joint"] == json!("J3") {
        0.20
    } else {
        1.0
    };
    assert!(lo <= truth && truth <= hi, "{j3}");
    app.stop().await;
}

/// Issue 15, point 4: three lifts of one pantograph with realistic sensor noise on every
/// channel, a month apart. The first is fitted alone; the third's current fit pools all three
/// (newest first, within the stated window), says so, fits the newest lift to its noise
/// (under 0.8 mm of H), informs J3's dry friction, and is written once.
pub async fn recent_lifts_are_pooled(b: Backend) {
    let app = spawn_app(b).await;
    let defaults = pantowatch::cli::simulate::docs::simulate_defaults().expect("defaults");
    let ids = ["pool-jan", "pool-feb", "pool-mar"];
    for (k, id) in ids.iter().enumerate() {
        let doc =
            pantowatch::cli::simulate::simulate_doc(&pantowatch::cli::simulate::SimulateArgs {
                kind: "lift".into(),
                protocol: "raise-and-lower".into(),
                sensor_noise: 1.0,
                h_noise_mm: 0.0,
                seed: 40 + k as u64,
                vehicle: "EN57-POOL".into(),
                serial: "160EC-POOL".into(),
                trace_id: Some((*id).into()),
                recorded_at: format!("2026-0{}-05T06:00:00Z", k + 1),
                ..defaults.clone()
            })
            .expect("lift");
        let r = app
            .upload_json(&serde_json::to_vec(&doc.to_value()).unwrap())
            .await;
        assert_eq!(r.status(), StatusCode::ACCEPTED);
        app.wait_for_fit(id).await;
    }
    // The pooled fit is written after the lift's own: wait for it to become the current fit.
    let t0 = std::time::Instant::now();
    let pooled = loop {
        let (s, f) = app.get_json("/v1/traces/pool-mar/fit").await;
        assert_eq!(s, StatusCode::OK);
        if f["pooled"].is_object() {
            break f;
        }
        assert!(t0.elapsed().as_secs() < 60, "no pooled fit: {f}");
        tokio::time::sleep(std::time::Duration::from_millis(100)).await;
    };
    assert_eq!(
        pooled["pooled"]["trace_ids"],
        json!(["pool-mar", "pool-feb", "pool-jan"]),
        "{pooled}"
    );
    assert_eq!(pooled["trace_id"], "pool-mar");
    app.assert_fit_serves_the_stored_json(&pooled).await;
    let (_, single) = app.get_json("/v1/traces/pool-jan/fit").await;
    app.assert_fit_serves_the_stored_json(&single).await;
    assert!(
        single["pooled"].is_null(),
        "the first lift had nothing to pool: {single}"
    );
    let width = |f: &Value, joint: &str| {
        let j = f["joints"]
            .as_array()
            .unwrap()
            .iter()
            .find(|j| j["joint"] == joint)
            .unwrap()
            .clone();
        let ci = &j["dry"]["ci95"];
        ci[1].as_f64().unwrap() - ci[0].as_f64().unwrap()
    };
    // What pooling buys is measured, not asserted here: with the inputs' noise propagated into
    // the intervals, three realistic-noise lifts do not narrow J3/J5/J8 dry (docs/VALIDATION.md, "Pooled
    // lifts"); the pooled fit still informs J3's dry friction and reports it.
    for joint in ["J3", "J5", "J8"] {
        let (w1, w3) = (width(&single, joint), width(&pooled, joint));
        eprintln!("{joint} dry 95 % width: one lift {w1:.4}, three pooled {w3:.4}");
    }
    // Each lift in the pool has its own J8 dry deviation (`POOLED_PER_TRACE`): the newest
    // lift is fitted to its noise, as its own fit is (with every coefficient shared, pools of
    // such lifts left up to 4.4 mm: docs/VALIDATION.md, "Pooled lifts").
    let rmse_m = pooled["rmse"]["value"].as_f64().expect("rmse");
    eprintln!("H RMSE of the newest lift in the pool: {rmse_m:.2e} m");
    assert!(rmse_m < 0.8e-3, "pooled RMSE {rmse_m} m");
    // J3's dry friction is informed together with J1's (issue 15): the J1+J3 entry.
    let j3 = pooled["joints"]
        .as_array()
        .unwrap()
        .iter()
        .find(|j| j["joint"] == "J1+J3")
        .unwrap();
    assert_eq!(
        j3["dry"]["identifiable"], true,
        "{j3} {}",
        pooled["residual"]
    );
    // Written once: the next poll finds the same fit.
    let (_, again) = app.get_json("/v1/traces/pool-mar/fit").await;
    assert_eq!(again["fit_id"], pooled["fit_id"]);
    app.stop().await;
}

/// Issue 16, points 3–4, over HTTP: a lift of an unworn pantograph with realistic sensor noise
/// whose H channel reads 5 % high (a mis-scaled sensor: outside the lift vocabulary). The fit
/// result says `unexplained` with no effect named, gives the reason its joints are withheld and
/// what the residual follows, reports every joint not identified and `unknown`; no alert is
/// opened and fleet health shows nothing drifted.
pub async fn a_model_error_raises_no_wear_alarm(b: Backend) {
    let app = spawn_app(b).await;
    let defaults = pantowatch::cli::simulate::docs::simulate_defaults().expect("defaults");
    let doc = pantowatch::cli::simulate::simulate_doc(&pantowatch::cli::simulate::SimulateArgs {
        kind: "lift".into(),
        protocol: "raise-and-lower".into(),
        sensor_noise: 1.0,
        h_noise_mm: 0.0,
        seed: 23,
        vehicle: "EN57-GAIN".into(),
        serial: "160EC-GAIN".into(),
        trace_id: Some("gain-h".into()),
        ..defaults
    })
    .expect("lift");
    let mut v = doc.to_value();
    let h: Vec<f64> = v["channels"]["H_m"]
        .as_array()
        .expect("H_m")
        .iter()
        .map(|x| x.as_f64().expect("number"))
        .collect();
    let scaled: Vec<f64> = h.iter().map(|x| x * 1.05).collect();
    v["channels"]["H_m"] = json!(scaled);
    let r = app.upload_json(&serde_json::to_vec(&v).unwrap()).await;
    assert_eq!(r.status(), StatusCode::ACCEPTED);
    let fit = app.wait_for_fit("gain-h").await;
    let res = &fit["residual"];
    assert_eq!(res["verdict"], "unexplained", "{res}");
    assert_eq!(res["effects"], json!([]), "{res}");
    assert!(
        res["joints_withheld"]
            .as_str()
            .is_some_and(|w| w.contains("sensor noise")),
        "{res}"
    );
    assert!(res["excess_ratio"].as_f64().unwrap() > 3.0, "{res}");
    assert!(!res["correlates_with"].as_array().unwrap().is_empty());
    for j in fit["joints"].as_array().expect("joints") {
        assert_eq!(j["status"], "unknown", "{j}");
        assert_eq!(j["identifiable"], false, "{j}");
    }
    let (s, alerts) = app.get_json("/v1/alerts?vehicle=EN57-GAIN").await;
    assert_eq!(s, StatusCode::OK, "{alerts}");
    let open = alerts
        .get("alerts")
        .or_else(|| alerts.get("rows"))
        .and_then(|a| a.as_array())
        .map_or(0, |a| a.len());
    assert_eq!(open, 0, "{alerts}");
    let (s, h) = app.get_json("/v1/fleet/health?vehicle=EN57-GAIN").await;
    assert_eq!(s, StatusCode::OK, "{h}");
    for row in h["rows"].as_array().unwrap() {
        assert!(
            !matches!(row["worst_status"].as_str(), Some("watch" | "alarm")),
            "{row}"
        );
    }
    app.stop().await;
}

/// Issue 16, point 4, over HTTP: a realistic-noise lift of an unworn pantograph whose H channel
/// lags the inputs by 20 ms (`simulate --effect sensor_delay:delay_s=0.02`). The fit names
/// `sensor_delay` (the truth in its interval), flags no joint, and the service opens one
/// `watch` alert named `H sensor` — a sensor finding, no joint alert — while fleet health shows
/// nothing drifted. The next lift of the pantograph, without the delay, resolves it.
pub async fn a_sensor_delay_is_a_sensor_finding_not_a_joint_alarm(b: Backend) {
    let app = spawn_app(b).await;
    let defaults = pantowatch::cli::simulate::docs::simulate_defaults().expect("defaults");
    let lift = |seed: u64, id: &str, at: &str, effects: Vec<String>| {
        pantowatch::cli::simulate::simulate_doc(&pantowatch::cli::simulate::SimulateArgs {
            kind: "lift".into(),
            protocol: "raise-and-lower".into(),
            sensor_noise: 1.0,
            h_noise_mm: 0.0,
            seed,
            vehicle: "EN57-LAG".into(),
            serial: "160EC-LAG".into(),
            trace_id: Some(id.into()),
            recorded_at: at.into(),
            effects,
            ..defaults.clone()
        })
        .expect("lift")
    };
    let late = lift(
        31,
        "lag-h",
        "2026-03-02T07:00:00Z",
        vec!["sensor_delay:delay_s=0.02".into()],
    );
    let r = app
        .upload_json(&serde_json::to_vec(&late.to_value()).unwrap())
        .await;
    assert_eq!(r.status(), StatusCode::ACCEPTED);
    let fit = app.wait_for_fit("lag-h").await;
    let res = &fit["residual"];
    assert_eq!(res["effects"][0]["name"], "sensor_delay", "{res}");
    let ci = &res["effects"][0]["params"]["delay_s_ci95"];
    let (lo, hi) = (ci[0].as_f64().unwrap(), ci[1].as_f64().unwrap());
    assert!(lo <= 0.02 && 0.02 <= hi, "{res}");
    for j in fit["joints"].as_array().expect("joints") {
        assert!(
            !matches!(j["status"].as_str(), Some("watch" | "alarm")),
            "{j}"
        );
    }
    // The residual's autocorrelation before and after (issue 16, point 5): the lag left by the
    // delay correlates the plain residual over 50 ms; the refit's is near white there.
    let acf = |k: &str| -> Vec<(f64, f64)> {
        res[k]
            .as_array()
            .unwrap_or_else(|| panic!("{k}: {res}"))
            .iter()
            .map(|p| (p[0].as_f64().unwrap(), p[1].as_f64().unwrap()))
            .collect()
    };
    let (after, before) = (acf("autocorrelation"), acf("autocorrelation_before"));
    assert_eq!(after.len(), 6, "{res}");
    assert_eq!(before.len(), 6, "{res}");
    let at_50ms = |v: &[(f64, f64)]| v.iter().find(|p| p.0 == 0.05).unwrap().1;
    assert!(at_50ms(&before) > 0.5 && at_50ms(&after) < 0.5, "{res}");
    // The web trace page shows the effect with its interval and the autocorrelation table.
    let page = app.web_page("/traces/lag-h").await;
    assert!(page.contains("sensor_delay (delay_s "), "{page}");
    assert!(page.contains(r#"<table id="acf">"#) && page.contains("before the effect"));
    // Alerts are raised after the fit is stored: wait for the finding.
    let rows =
        crate::alerts::wait_alerts(&app, "vehicle=EN57-LAG", |l: &[Value]| !l.is_empty()).await;
    assert_eq!(rows.len(), 1, "{rows:?}");
    assert_eq!(rows[0]["joint"], pantowatch::alerts::LIFT_H_SENSOR);
    assert_eq!(rows[0]["severity"], "watch");
    assert_eq!(rows[0]["state"], "open");
    assert!(rows[0]["reason"].as_str().unwrap().contains("sensor_delay"));
    let (s, h) = app.get_json("/v1/fleet/health?vehicle=EN57-LAG").await;
    assert_eq!(s, StatusCode::OK, "{h}");
    for row in h["rows"].as_array().unwrap() {
        assert!(
            !matches!(row["worst_status"].as_str(), Some("watch" | "alarm")),
            "{row}"
        );
    }
    // A month later, the sensor fixed: the finding is resolved.
    let fixed = lift(32, "lag-fixed", "2026-04-02T07:00:00Z", Vec::new());
    let r = app
        .upload_json(&serde_json::to_vec(&fixed.to_value()).unwrap())
        .await;
    assert_eq!(r.status(), StatusCode::ACCEPTED);
    let fit = app.wait_for_fit("lag-fixed").await;
    assert_eq!(fit["residual"]["effects"], json!([]), "{}", fit["residual"]);
    let resolved =
        crate::alerts::wait_alerts(&app, "vehicle=EN57-LAG&state=resolved", |l| l.len() == 1).await;
    assert_eq!(resolved[0]["joint"], pantowatch::alerts::LIFT_H_SENSOR);
    let (_, alerts) = app.get_json("/v1/alerts?vehicle=EN57-LAG&state=live").await;
    assert_eq!(alerts["alerts"], json!([]), "{alerts}");
    // Another month, the sensor's zero 20 mm off: `sensor_offset`, a sensor finding again.
    let off = lift(
        33,
        "zero-h",
        "2026-05-02T07:00:00Z",
        vec!["sensor_offset:offset=0.02".into()],
    );
    let r = app
        .upload_json(&serde_json::to_vec(&off.to_value()).unwrap())
        .await;
    assert_eq!(r.status(), StatusCode::ACCEPTED);
    let fit = app.wait_for_fit("zero-h").await;
    let res = &fit["residual"];
    assert_eq!(res["effects"][0]["name"], "sensor_offset", "{res}");
    let ci = &res["effects"][0]["params"]["offset_m_ci95"];
    let (lo, hi) = (ci[0].as_f64().unwrap(), ci[1].as_f64().unwrap());
    assert!(lo <= 0.02 && 0.02 <= hi, "{res}");
    for j in fit["joints"].as_array().expect("joints") {
        assert!(
            !matches!(j["status"].as_str(), Some("watch" | "alarm")),
            "{j}"
        );
    }
    let live =
        crate::alerts::wait_alerts(&app, "vehicle=EN57-LAG&state=live", |l| !l.is_empty()).await;
    // Only the sensor finding, for as long as a pooled fit would take to land (before lifts
    // with a named effect were kept out of pools, the pool of these lifts raised a J1+J3 watch
    // within seconds): no joint alert, and the trace's current fit is its own, not a pool's.
    for _ in 0..20 {
        let (_, live) = app.get_json("/v1/alerts?vehicle=EN57-LAG&state=live").await;
        let live = live["alerts"].as_array().expect("alerts").clone();
        assert!(
            live.iter()
                .all(|a| a["joint"] == pantowatch::alerts::LIFT_H_SENSOR),
            "{live:?}"
        );
        tokio::time::sleep(std::time::Duration::from_millis(250)).await;
    }
    let (_, current) = app.get_json("/v1/traces/zero-h/fit").await;
    assert!(current.get("pooled").is_none(), "{current}");
    assert_eq!(live[0]["joint"], pantowatch::alerts::LIFT_H_SENSOR);
    assert!(
        live[0]["reason"]
            .as_str()
            .unwrap()
            .contains("sensor_offset")
    );
    app.stop().await;
}

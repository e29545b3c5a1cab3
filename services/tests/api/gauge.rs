//! The force-gauge measurement of the static contact force over HTTP (issue 20, points 3 and
//! 4): a `static_force` trace is stored losslessly (JSON and CSV), every bad one is refused
//! naming its field with nothing stored, and the pantograph page draws the measured points over
//! the predicted band.

use reqwest::{Method, StatusCode};
use serde_json::{Value, json};

use crate::harness::*;

/// The combination a gauge record of the built-in type informs (`models::lift::gauge`, issue 39).
const GAUGE_LEVEL: &str = "J1+J2+J2'+J3+J4+J5";

/// A simulated gauge measurement (`simulate --kind static_force`): 15 readings raising, 14
/// lowering, 0.2 N noise, 0.1 N resolution.
pub fn gauge_doc(serial: &str, trace_id: &str, scale: &[&str]) -> pantowatch::trace::TraceDoc {
    let defaults = pantowatch::cli::simulate::docs::simulate_defaults().expect("defaults");
    pantowatch::cli::simulate::simulate_doc(&pantowatch::cli::simulate::SimulateArgs {
        kind: "static_force".into(),
        scale_joints: scale.iter().map(|s| s.to_string()).collect(),
        seed: 7,
        vehicle: format!("V-{serial}"),
        serial: serial.into(),
        trace_id: Some(trace_id.into()),
        recorded_at: "2026-03-02T08:00:00Z".into(),
        ..defaults
    })
    .expect("gauge trace")
}

fn floats(v: &Value) -> Vec<f64> {
    v.as_array()
        .unwrap_or_else(|| panic!("not an array: {v}"))
        .iter()
        .map(|x| x.as_f64().expect("number"))
        .collect()
}

/// Keeps readings `keep` of every channel.
fn readings(d: &mut Value, keep: std::ops::Range<usize>) {
    for c in ["t_s", "H_m", "F_N"] {
        let a: Vec<Value> = d["channels"][c].as_array().expect(c)[keep.clone()].to_vec();
        d["channels"][c] = Value::Array(a);
    }
    // Times from 0 again, as a gauge logger would start.
    let t0 = d["channels"]["t_s"][0].as_f64().expect("t");
    let t: Vec<f64> = floats(&d["channels"]["t_s"])
        .iter()
        .map(|t| t - t0)
        .collect();
    d["channels"]["t_s"] = json!(t);
}

pub async fn a_gauge_measurement_is_stored_refused_and_drawn(b: Backend) {
    let app = spawn_app(b).await;
    let serial = "160EC-G-1";
    let doc = gauge_doc(serial, "gauge-1", &["J3:dry=2"]);
    let n = doc.channel("t_s").expect("t_s").len();
    assert_eq!(n, 29, "15 raising and 14 lowering readings");
    let base = doc.to_value();
    let before = app.stored().await;

    // Each bad document: 422 naming its field, nothing stored.
    let edit = |f: &dyn Fn(&mut Value)| {
        let mut d = base.clone();
        d["trace_id"] = json!("gauge-bad");
        f(&mut d);
        serde_json::to_vec(&d).expect("json")
    };
    let cases: Vec<(&str, Vec<u8>, &str)> = vec![
        (
            "a height above the working range",
            edit(&|d| d["channels"]["H_m"][3] = json!(1.9)),
            "channels.H_m[3]",
        ),
        (
            "a height below the working range",
            edit(&|d| d["channels"]["H_m"][0] = json!(0.5)),
            "channels.H_m[0]",
        ),
        (
            "no lowering branch",
            edit(&|d| readings(d, 0..15)),
            "channels.H_m",
        ),
        (
            "no raising branch",
            edit(&|d| readings(d, 14..29)),
            "channels.H_m",
        ),
        (
            "a raising branch of 4 readings",
            edit(&|d| readings(d, 11..29)),
            "channels.H_m",
        ),
        (
            "a lowering branch of 4 readings",
            edit(&|d| readings(d, 0..19)),
            "channels.H_m",
        ),
        (
            "a raising reading below the one before",
            edit(&|d| d["channels"]["H_m"][5] = json!(0.86)),
            "channels.H_m[5]",
        ),
        (
            "a lowering reading above the one before",
            edit(&|d| d["channels"]["H_m"][20] = json!(1.79)),
            "channels.H_m[20]",
        ),
        (
            "no gauge resolution",
            edit(&|d| {
                d["test"]
                    .as_object_mut()
                    .expect("test")
                    .remove("gauge_resolution_n");
            }),
            "test.gauge_resolution_n",
        ),
        (
            "a zero gauge resolution",
            edit(&|d| d["test"]["gauge_resolution_n"] = json!(0.0)),
            "test.gauge_resolution_n",
        ),
        (
            "a negative gauge resolution",
            edit(&|d| d["test"]["gauge_resolution_n"] = json!(-0.1)),
            "test.gauge_resolution_n",
        ),
        (
            "a gauge resolution as text",
            edit(&|d| d["test"]["gauge_resolution_n"] = json!("0.1")),
            "test.gauge_resolution_n",
        ),
        (
            "no force channel",
            edit(&|d| {
                d["channels"].as_object_mut().expect("ch").remove("F_N");
            }),
            "channels.F_N",
        ),
        (
            "a force that is not a number",
            edit(&|d| d["channels"]["F_N"][4] = json!("NaN")),
            "channels.F_N[4]",
        ),
        (
            "a force no strip can carry",
            edit(&|d| d["channels"]["F_N"][2] = json!(1e6)),
            "channels.F_N[2]",
        ),
        (
            "a joint named",
            edit(&|d| d["test"]["joint"] = json!("J3")),
            "test.joint",
        ),
        (
            "a type without the static-force data",
            edit(&|d| d["pantograph"]["model"] = json!("200EC")),
            "pantograph.model",
        ),
        (
            "a gauge resolution on a lift",
            edit(&|d| d["test"]["kind"] = json!("lift")),
            "test.gauge_resolution_n",
        ),
    ];
    for (what, body, field) in cases {
        let r = app.upload_json(&body).await;
        assert_problem(r, StatusCode::UNPROCESSABLE_ENTITY, Some(field), what).await;
        assert_eq!(app.stored().await, before, "{what}: stored something");
    }
    // The same as CSV: a gauge resolution that is not a number is refused naming it.
    let csv = pantowatch::trace_csv::write(&doc);
    assert!(csv.contains("# test.gauge_resolution_n: 0.1\n"), "{csv}");
    let r = app
        .req(Method::POST, "/v1/traces", Some(&app.keys.writer))
        .header("content-type", "text/csv")
        .body(csv.replace(
            "# test.gauge_resolution_n: 0.1",
            "# test.gauge_resolution_n: fine",
        ))
        .send()
        .await
        .expect("POST csv");
    let status = r.status();
    assert!(status.is_client_error(), "{status}");
    assert_problem(r, status, Some("test.gauge_resolution_n"), "csv resolution").await;
    assert_eq!(app.stored().await, before, "bad csv stored something");

    // The valid one is accepted, and the same document as CSV is the same upload.
    let r = app
        .upload_json(&serde_json::to_vec(&base).expect("json"))
        .await;
    assert_eq!(
        r.status(),
        StatusCode::ACCEPTED,
        "{}",
        r.text().await.unwrap_or_default()
    );
    let r = app
        .req(Method::POST, "/v1/traces", Some(&app.keys.writer))
        .header("content-type", "text/csv")
        .body(csv)
        .send()
        .await
        .expect("POST csv");
    assert_eq!(r.status(), StatusCode::ACCEPTED);
    assert_eq!(app.counts().await.traces, before[2] + 1);
    // Read back as stored: the test object as sent and every sample bit-identical.
    let (s, meta) = app.get_json("/v1/traces/gauge-1").await;
    assert_eq!(s, StatusCode::OK, "{meta}");
    assert_eq!(meta["test"], base["test"], "{meta}");
    let (s, samples) = app.get_json("/v1/traces/gauge-1/samples").await;
    assert_eq!(s, StatusCode::OK, "{samples}");
    for (name, values) in &doc.channels {
        let got = floats(&samples["channels"][name]);
        assert_eq!(got.len(), values.len(), "{name}");
        assert!(
            got.iter()
                .zip(values)
                .all(|(a, b)| a.to_bits() == b.to_bits()),
            "{name} differs"
        );
    }
    // The fit (`models::lift::gauge`): the hysteresis informs the gap's level, J3 with J1, J2,
    // J2', J4 and J5 (issue 39: every joint the gap tells of); J3 ×2 puts it near
    // 0.24 × 1 + 0.76 × 2 ≈ 1.76, past the watch band, and the RMSE is the gauge's noise (0.2 N
    // with its 0.1 N steps).
    let fit = app.wait_for_fit("gauge-1").await;
    assert_eq!(fit["rmse"]["unit"], "N", "{fit}");
    let rmse = fit["rmse"]["value"].as_f64().expect("rmse");
    assert!((0.05..0.5).contains(&rmse), "{fit}");
    let combo = fit["joints"]
        .as_array()
        .expect("joints")
        .iter()
        .find(|j| j["joint"] == GAUGE_LEVEL)
        .cloned()
        .unwrap_or_else(|| panic!("no {GAUGE_LEVEL} combination: {fit}"));
    let level = combo["dry"]["value"].as_f64().expect("level");
    let ci = floats(&combo["dry"]["ci95"]);
    assert!(
        (1.6..2.1).contains(&level) && ci[0] > 1.5,
        "{GAUGE_LEVEL} level {level} {ci:?}: {combo}"
    );
    assert_eq!(combo["status"], "watch", "{combo}");
    // The pantograph's predicted static force takes its members' dry friction from it, as from
    // a lift's combination (level × Table 4 each).
    let (s, v) = app
        .get_json(&format!("/v1/pantographs/{serial}/static-force"))
        .await;
    assert_eq!(s, StatusCode::OK, "{v}");
    let j3 = v["parameters"]
        .as_array()
        .expect("parameters")
        .iter()
        .find(|p| p["joint"] == "J3")
        .cloned()
        .expect("J3");
    assert_eq!(j3["source"], format!("combination {GAUGE_LEVEL}"), "{j3}");
    assert_eq!(j3["trace_id"], "gauge-1", "{j3}");
    // … and carries the gauge's readings as stored, split at the turn.
    assert_eq!(v["measured"]["trace_id"], "gauge-1", "{v}");
    assert_eq!(v["measured"]["gauge_resolution_n"], 0.1, "{v}");
    let raise = v["measured"]["raise"].as_array().expect("raise");
    let lower = v["measured"]["lower"].as_array().expect("lower");
    assert_eq!((raise.len(), lower.len()), (15, 14), "{v}");
    let h = doc.channel("H_m").expect("H_m");
    let f = doc.channel("F_N").expect("F_N");
    assert_eq!(floats(&raise[3]), [h[3], f[3]], "{v}");
    assert_eq!(floats(&lower[0]), [h[15], f[15]], "{v}");

    // The pantograph page: the measured points over the predicted band, a class per branch,
    // one marker per reading, and the legend naming both.
    let html = app.web_page(&format!("/pantographs/{serial}")).await;
    let section = html
        .split("id=\"static-force\"")
        .nth(1)
        .expect("static force section");
    assert!(
        section.contains("<polygon"),
        "the predicted band: {section}"
    );
    let raise = section.matches("class=\"gauge-raise\"").count();
    let lower = section.matches("class=\"gauge-lower\"").count();
    assert_eq!((raise, lower), (15, 14), "{section}");
    assert!(
        section.contains("raising, gauge (15 readings)")
            && section.contains("lowering, gauge (14 readings)"),
        "{section}"
    );
    assert!(section.contains("gauge-1"), "{section}");
    // A pantograph without a gauge measurement shows no measured points.
    let t: Vec<f64> = (0..200).map(|i| f64::from(i) * 0.004).collect();
    let a: Vec<f64> = t
        .iter()
        .map(|t| 30.0 * (-0.3 * t).exp() * (2.0 * t).cos())
        .collect();
    let pendulum = json!({"format": "pantograph-trace/1", "trace_id": "g2-pendulum",
        "vehicle_id": "V-2", "pantograph": {"model": "160EC", "serial": "160EC-G-2"},
        "recorded_at": "2026-03-02T07:15:00Z", "test": {"kind": "pendulum", "joint": "J1", "rig": {}},
        "channels": {"t_s": t, "alpha_deg": a}});
    let r = app
        .upload_json(&serde_json::to_vec(&pendulum).expect("json"))
        .await;
    assert_eq!(r.status(), StatusCode::ACCEPTED);
    let html = app.web_page("/pantographs/160EC-G-2").await;
    assert!(!html.contains("gauge-raise"), "no gauge on 160EC-G-2");
    app.stop().await;
}

/// Issue 20: a force-gauge record pools with the pantograph's next lift (`services::pooled`,
/// `models::lift::report::fit_pooled_lift_and_gauge_traces`): one lift and one gauge record
/// in the window are a pool, written as the lift's current fit naming both tests.
pub async fn a_gauge_record_pools_with_the_next_lift(b: Backend) {
    let app = spawn_app(b).await;
    let serial = "160EC-GP-1";
    let mut gauge = gauge_doc(serial, "gp-gauge", &[]).to_value();
    gauge["vehicle_id"] = json!("EN57-GP");
    gauge["recorded_at"] = json!("2026-03-01T06:00:00Z");
    let r = app
        .upload_json(&serde_json::to_vec(&gauge).expect("json"))
        .await;
    assert_eq!(r.status(), StatusCode::ACCEPTED);
    app.wait_for_fit("gp-gauge").await;
    let defaults = pantowatch::cli::simulate::docs::simulate_defaults().expect("defaults");
    let lift = pantowatch::cli::simulate::simulate_doc(&pantowatch::cli::simulate::SimulateArgs {
        kind: "lift".into(),
        protocol: "raise-and-lower".into(),
        sensor_noise: 1.0,
        h_noise_mm: 0.0,
        seed: 40,
        vehicle: "EN57-GP".into(),
        serial: serial.into(),
        trace_id: Some("gp-lift".into()),
        recorded_at: "2026-03-02T06:00:00Z".into(),
        ..defaults
    })
    .expect("lift");
    let r = app
        .upload_json(&serde_json::to_vec(&lift.to_value()).expect("json"))
        .await;
    assert_eq!(r.status(), StatusCode::ACCEPTED);
    app.wait_for_fit("gp-lift").await;
    let t0 = std::time::Instant::now();
    let pooled = loop {
        let (s, f) = app.get_json("/v1/traces/gp-lift/fit").await;
        assert_eq!(s, StatusCode::OK, "{f}");
        if f["pooled"].is_object() {
            break f;
        }
        assert!(t0.elapsed().as_secs() < 60, "no pooled fit: {f}");
        tokio::time::sleep(std::time::Duration::from_millis(100)).await;
    };
    assert_eq!(
        pooled["pooled"]["trace_ids"],
        json!(["gp-lift", "gp-gauge"]),
        "{pooled}"
    );
    assert!(
        pooled["model_version"]
            .as_str()
            .is_some_and(|v| v.ends_with("pooled over 2 tests")),
        "{pooled}"
    );
    app.stop().await;
}

fn live_alerts(alerts: &Value, serial: &str, joint: &str) -> usize {
    alerts
        .as_array()
        .or_else(|| alerts["alerts"].as_array())
        .expect("alerts")
        .iter()
        .filter(|a| a["serial"] == serial && a["joint"] == joint)
        .count()
}

/// Issue 20: what a gauge fit's residual loop names is a finding on the pantograph, not a joint
/// alarm: a gauge reading 3 N high opens one `force gauge` alert, a drive spring at 1.3 × the
/// type's rate one `spring rate` alert; a later gauge test that does not name one resolves it.
pub async fn a_gauge_zero_or_spring_rate_is_a_finding_not_a_joint_alarm(b: Backend) {
    let app = spawn_app(b).await;
    let serial = "160EC-GZ-1";
    let defaults = pantowatch::cli::simulate::docs::simulate_defaults().expect("defaults");
    let gauge = |id: &str, day: u32, effects: &[&str]| {
        pantowatch::cli::simulate::simulate_doc(&pantowatch::cli::simulate::SimulateArgs {
            kind: "static_force".into(),
            effects: effects.iter().map(|e| e.to_string()).collect(),
            seed: 5 + u64::from(day),
            vehicle: "EN57-GZ".into(),
            serial: serial.into(),
            trace_id: Some(id.into()),
            recorded_at: format!("2026-03-{day:02}T06:00:00Z"),
            ..defaults.clone()
        })
        .expect("gauge")
    };
    let wait_alerts = |want: (usize, usize)| {
        let app = &app;
        async move {
            let t0 = std::time::Instant::now();
            loop {
                let (s, alerts) = app.get_json("/v1/alerts?state=live").await;
                assert_eq!(s, StatusCode::OK, "{alerts}");
                let got = (
                    live_alerts(&alerts, serial, "force gauge"),
                    live_alerts(&alerts, serial, "spring rate"),
                );
                if got == want || t0.elapsed().as_secs() > 30 {
                    return (got, alerts);
                }
                tokio::time::sleep(std::time::Duration::from_millis(100)).await;
            }
        }
    };
    for (id, day, effects, want) in [
        ("gz-offset", 1, vec!["sensor_offset:offset=3"], (1, 0)),
        // The gauge's zero is fine in this one: that alert is resolved, the spring's opened.
        ("gz-spring", 2, vec!["spring_rate:factor=1.3"], (0, 1)),
        ("gz-clean", 3, vec![], (0, 0)),
    ] {
        let doc = gauge(id, day, &effects);
        let r = app
            .upload_json(&serde_json::to_vec(&doc.to_value()).expect("json"))
            .await;
        assert_eq!(r.status(), StatusCode::ACCEPTED);
        let fit = app.wait_for_fit(id).await;
        let named: Vec<&str> = fit["residual"]["effects"]
            .as_array()
            .expect("effects")
            .iter()
            .filter_map(|e| e["name"].as_str())
            .collect();
        let expected: Vec<&str> = effects
            .iter()
            .map(|e| e.split(':').next().unwrap_or(""))
            .collect();
        assert_eq!(named, expected, "{id}: {fit}");
        let (got, alerts) = wait_alerts(want).await;
        assert_eq!(got, want, "{id}: {alerts}");
        // Neither is a joint's alarm: no joint alert on the pantograph.
        let joints = alerts["alerts"]
            .as_array()
            .or_else(|| alerts.as_array())
            .expect("alerts")
            .iter()
            .filter(|a| {
                a["serial"] == serial && a["joint"].as_str().is_some_and(|j| j.starts_with('J'))
            })
            .count();
        assert_eq!(joints, 0, "{id}: {alerts}");
    }
    app.stop().await;
}

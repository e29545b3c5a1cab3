//! Alerts and webhooks over HTTP, each case on SQLite and PostgreSQL: the alert lifecycle raised
//! by the worker, and webhook delivery to real receivers on 127.0.0.1 (accepting, failing twice,
//! never answering).

use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use axum::http::{HeaderMap, StatusCode as AxStatus};
use reqwest::{Method, StatusCode};
use serde_json::{Value, json};

use crate::harness::*;

/// An example trace moved to another pantograph, time and id.
fn example_as(name: &str, id: &str, serial: &str, recorded_at: &str) -> Vec<u8> {
    let mut v: Value = serde_json::from_slice(&example(name)).expect("example json");
    v["trace_id"] = json!(id);
    v["pantograph"]["serial"] = json!(serial);
    v["recorded_at"] = json!(recorded_at);
    serde_json::to_vec(&v).expect("json")
}

async fn post_json(app: &TestApp, path: &str, key: &str, body: Value) -> reqwest::Response {
    app.req(Method::POST, path, Some(key))
        .json(&body)
        .send()
        .await
        .expect("POST")
}

/// Polls `GET /v1/alerts?{query}` until `pred` holds.
pub(crate) async fn wait_alerts(
    app: &TestApp,
    query: &str,
    pred: impl Fn(&[Value]) -> bool,
) -> Vec<Value> {
    let t0 = Instant::now();
    loop {
        let (s, v) = app.get_json(&format!("/v1/alerts?{query}")).await;
        assert_eq!(s, StatusCode::OK, "{v}");
        let list = v["alerts"].as_array().cloned().unwrap_or_default();
        if pred(&list) {
            return list;
        }
        assert!(
            t0.elapsed() < Duration::from_secs(30),
            "alerts never matched: {v}"
        );
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
}

pub async fn alert_lifecycle_over_http(b: Backend) {
    let app = spawn_app(b).await;
    // J3 dry ×1.8 → `watch`: the worker opens an alert with its evidence.
    let body = example_as(
        "J3_dry_x1.8.json",
        "j3-worn",
        "160EC-0051",
        "2026-03-02T08:30:00Z",
    );
    assert_eq!(app.upload_json(&body).await.status(), StatusCode::ACCEPTED);
    app.wait_for_fit("j3-worn").await;
    let open = wait_alerts(&app, "state=open", |l| !l.is_empty()).await;
    assert_eq!(open.len(), 1, "{open:?}");
    let a = &open[0];
    let id = a["id"].as_i64().expect("id");
    assert_eq!(
        (a["serial"].as_str(), a["joint"].as_str()),
        (Some("160EC-0051"), Some("J3"))
    );
    assert_eq!(a["severity"], "watch");
    assert_eq!(a["vehicle_id"], "EN57-1030");
    let ev = &a["evidence"];
    assert!(
        ev["model_version"].as_str().is_some_and(|m| !m.is_empty()),
        "{ev}"
    );
    assert_eq!(ev["trace_id"], "j3-worn");
    assert!(
        ev["dry"]["ci95"].is_array() && ev["viscous"]["ci95"].is_array(),
        "{ev}"
    );
    assert!(ev["residual"].is_object(), "{ev}");
    assert!(ev["trends"].is_array(), "{ev}");

    // Filters.
    let (s, v) = app.get_json("/v1/alerts?severity=alarm").await;
    assert_eq!(
        (s, v["alerts"].as_array().map(Vec::len)),
        (StatusCode::OK, Some(0))
    );
    let (s, v) = app
        .get_json("/v1/alerts?vehicle=EN57-1030&state=live")
        .await;
    assert_eq!(
        (s, v["alerts"].as_array().map(Vec::len)),
        (StatusCode::OK, Some(1))
    );
    let r = app.get("/v1/alerts?state=closed", &app.keys.reader).await;
    assert_problem_param(r, StatusCode::BAD_REQUEST, "state", "bad state").await;
    let r = app.get("/v1/alerts/999999", &app.keys.reader).await;
    assert_problem(r, StatusCode::NOT_FOUND, None, "no alert").await;

    // Acknowledge: writers only; who is the key; twice is a conflict.
    let path = format!("/v1/alerts/{id}/acknowledge");
    let r = post_json(&app, &path, &app.keys.reader, json!({"note": "x"})).await;
    assert_problem(
        r,
        StatusCode::FORBIDDEN,
        Some("Authorization"),
        "reader acknowledges",
    )
    .await;
    let r = post_json(&app, &path, &app.keys.writer, json!({"note": "on it"})).await;
    assert_eq!(r.status(), StatusCode::OK);
    let v: Value = r.json().await.expect("json");
    assert_eq!(v["state"], "acknowledged");
    assert!(
        v["acknowledged_by"]
            .as_str()
            .is_some_and(|w| w.contains("(key ")),
        "{v}"
    );
    let r = post_json(&app, &path, &app.keys.writer, json!({"note": "again"})).await;
    assert_problem(r, StatusCode::CONFLICT, Some("state"), "acknowledged twice").await;
    let r = post_json(&app, &path, &app.keys.writer, json!({"nope": 1})).await;
    assert_problem(r, StatusCode::BAD_REQUEST, Some("nope"), "unknown field").await;

    // A later test of the same joint back in band resolves it automatically.
    let body = example_as(
        "J3_baseline.json",
        "j3-fixed",
        "160EC-0051",
        "2026-04-02T08:30:00Z",
    );
    assert_eq!(app.upload_json(&body).await.status(), StatusCode::ACCEPTED);
    app.wait_for_fit("j3-fixed").await;
    wait_alerts(&app, "state=resolved", |l| l.len() == 1).await;
    let (s, d) = app.get_json(&format!("/v1/alerts/{id}")).await;
    assert_eq!(s, StatusCode::OK);
    assert_eq!(d["alert"]["resolved_by"], "system");
    let kinds: Vec<&str> = d["events"]
        .as_array()
        .expect("events")
        .iter()
        .filter_map(|e| e["kind"].as_str())
        .collect();
    assert_eq!(kinds, ["opened", "acknowledged", "resolved"], "{d}");
    assert_eq!(d["events"][2]["trace_id"], "j3-fixed");

    // J5 viscous ×2.5 → `alarm`; resolved by hand, then resolving again is a conflict.
    let body = example_as(
        "J5_viscous_x2.5.json",
        "j5-worn",
        "160EC-0050",
        "2026-03-02T08:20:00Z",
    );
    assert_eq!(app.upload_json(&body).await.status(), StatusCode::ACCEPTED);
    app.wait_for_fit("j5-worn").await;
    let alarms = wait_alerts(&app, "severity=alarm", |l| !l.is_empty()).await;
    let id5 = alarms[0]["id"].as_i64().expect("id");
    let r = post_json(
        &app,
        &format!("/v1/alerts/{id5}/resolve"),
        &app.keys.writer,
        json!({"note": "joint replaced"}),
    )
    .await;
    assert_eq!(r.status(), StatusCode::OK);
    let r = post_json(
        &app,
        &format!("/v1/alerts/{id5}/resolve"),
        &app.keys.writer,
        json!({}),
    )
    .await;
    assert_problem(r, StatusCode::CONFLICT, Some("state"), "resolved twice").await;

    // The history carries the trends.
    let (s, h) = app
        .get_json("/v1/pantographs/160EC-0051/joints/J3/history")
        .await;
    assert_eq!(s, StatusCode::OK);
    assert_eq!(
        h["trends"]["dry"]["no_trend"], true,
        "two points: no trend {h}"
    );
    assert!(h["trends"]["viscous"]["baseline"].as_f64().is_some(), "{h}");
    app.stop().await;
}

/// What a receiver saw.
#[derive(Default)]
struct Seen {
    /// (idempotency key, event, signature valid)
    requests: Vec<(String, String, bool)>,
}

#[derive(Clone, Copy, PartialEq)]
enum Behaviour {
    Accept,
    FailTwice,
    Silent,
}

/// A receiver on 127.0.0.1:0 that checks the signature with `secret` (set once known).
async fn receiver(behaviour: Behaviour, secret: Arc<Mutex<String>>) -> (String, Arc<Mutex<Seen>>) {
    let seen = Arc::new(Mutex::new(Seen::default()));
    let s2 = seen.clone();
    let handler = move |headers: HeaderMap, body: String| {
        let (seen, secret) = (s2.clone(), secret.clone());
        async move {
            let h = |n: &str| {
                headers
                    .get(n)
                    .and_then(|v| v.to_str().ok())
                    .unwrap_or("")
                    .to_owned()
            };
            let ts = h("x-pantowatch-timestamp");
            let sig = h("x-pantowatch-signature");
            let key = secret.lock().expect("lock").clone();
            let valid = !key.is_empty() && sig == pantowatch::webhooks::signature(&key, &ts, &body);
            let event = serde_json::from_str::<Value>(&body)
                .ok()
                .and_then(|v| v["event"].as_str().map(str::to_owned))
                .unwrap_or_default();
            let n = {
                let mut s = seen.lock().expect("lock");
                s.requests.push((h("idempotency-key"), event, valid));
                s.requests.len()
            };
            match behaviour {
                Behaviour::Silent => {
                    tokio::time::sleep(Duration::from_secs(3600)).await;
                    AxStatus::OK
                }
                Behaviour::FailTwice if n <= 2 => AxStatus::SERVICE_UNAVAILABLE,
                _ if !valid => AxStatus::UNAUTHORIZED,
                _ => AxStatus::NO_CONTENT,
            }
        }
    };
    let app = axum::Router::new().route("/hook", axum::routing::post(handler));
    let l = tokio::net::TcpListener::bind("127.0.0.1:0")
        .await
        .expect("bind");
    let addr = l.local_addr().expect("addr");
    tokio::spawn(async move {
        let _ = axum::serve(l, app).await;
    });
    (format!("http://{addr}/hook"), seen)
}

async fn deliveries(app: &TestApp, hook: i64) -> Vec<Value> {
    let r = app
        .get(
            &format!("/v1/admin/webhooks/{hook}/deliveries"),
            &app.keys.admin,
        )
        .await;
    assert_eq!(r.status(), StatusCode::OK);
    let v: Value = r.json().await.expect("json");
    v["deliveries"].as_array().cloned().unwrap_or_default()
}

/// Polls a subscription's delivery log until every delivery is in a final state.
async fn wait_settled(app: &TestApp, hook: i64, n: usize) -> Vec<Value> {
    let t0 = Instant::now();
    loop {
        let d = deliveries(app, hook).await;
        if d.len() >= n && d.iter().all(|d| d["state"] != "pending") {
            return d;
        }
        assert!(
            t0.elapsed() < Duration::from_secs(30),
            "deliveries never settled: {d:?}"
        );
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
}

pub async fn webhooks_signed_retried_and_logged(b: Backend) {
    let app = spawn_app(b).await;
    let mut hooks = Vec::new();
    for behaviour in [Behaviour::Accept, Behaviour::FailTwice, Behaviour::Silent] {
        let secret = Arc::new(Mutex::new(String::new()));
        let (url, seen) = receiver(behaviour, secret.clone()).await;
        let r = post_json(
            &app,
            "/v1/admin/webhooks",
            &app.keys.admin,
            json!({"url": url, "severities": ["watch", "alarm"]}),
        )
        .await;
        assert_eq!(r.status(), StatusCode::CREATED);
        let v: Value = r.json().await.expect("json");
        *secret.lock().expect("lock") = v["secret"].as_str().expect("secret").to_owned();
        hooks.push((v["id"].as_i64().expect("id"), seen));
    }
    // Rejections and roles.
    let r = post_json(
        &app,
        "/v1/admin/webhooks",
        &app.keys.writer,
        json!({"url": "http://x/"}),
    )
    .await;
    assert_problem(
        r,
        StatusCode::FORBIDDEN,
        Some("Authorization"),
        "writer subscribes",
    )
    .await;
    let r = post_json(
        &app,
        "/v1/admin/webhooks",
        &app.keys.admin,
        json!({"url": "ftp://x/"}),
    )
    .await;
    assert_problem(r, StatusCode::BAD_REQUEST, Some("url"), "ftp url").await;
    let r = post_json(
        &app,
        "/v1/admin/webhooks",
        &app.keys.admin,
        json!({"url": "http://x/", "severities": ["fatal"]}),
    )
    .await;
    assert_problem(
        r,
        StatusCode::BAD_REQUEST,
        Some("severities[0]"),
        "bad severity",
    )
    .await;
    let r = app.get("/v1/admin/webhooks", &app.keys.admin).await;
    let list: Value = r.json().await.expect("json");
    assert_eq!(list["webhooks"].as_array().map(Vec::len), Some(3));
    assert!(
        !list.to_string().contains("whsec_"),
        "secrets are shown once"
    );

    // An alarm: one delivery per subscription.
    let body = example_as(
        "J5_viscous_x2.5.json",
        "j5-worn",
        "160EC-0050",
        "2026-03-02T08:20:00Z",
    );
    let t0 = Instant::now();
    assert_eq!(app.upload_json(&body).await.status(), StatusCode::ACCEPTED);
    app.wait_for_fit("j5-worn").await;

    let (accept, flaky, silent) = (&hooks[0], &hooks[1], &hooks[2]);
    let d = wait_settled(&app, accept.0, 1).await;
    assert_eq!(
        (d[0]["state"].as_str(), d[0]["attempts"].as_i64()),
        (Some("delivered"), Some(1))
    );
    assert_eq!(d[0]["event"], "alert.opened");
    let id = d[0]["id"].as_i64().expect("id").to_string();
    {
        let s = accept.1.lock().expect("lock");
        assert_eq!(s.requests.len(), 1);
        assert_eq!(
            s.requests[0],
            (id, "alert.opened".to_owned(), true),
            "signature verified"
        );
    }

    let d = wait_settled(&app, flaky.0, 1).await;
    assert_eq!(
        (d[0]["state"].as_str(), d[0]["attempts"].as_i64()),
        (Some("delivered"), Some(3)),
        "{d:?}"
    );
    {
        let s = flaky.1.lock().expect("lock");
        assert_eq!(s.requests.len(), 3);
        let key = d[0]["id"].as_i64().expect("id").to_string();
        assert!(
            s.requests.iter().all(|r| r.0 == key && r.2),
            "same idempotency key, signed"
        );
    }

    let d = wait_settled(&app, silent.0, 1).await;
    assert_eq!(
        (d[0]["state"].as_str(), d[0]["attempts"].as_i64()),
        (Some("failed"), Some(3)),
        "{d:?}"
    );
    assert!(
        d[0]["last_error"]
            .as_str()
            .is_some_and(|e| e.contains("no answer")),
        "{d:?}"
    );
    assert_eq!(silent.1.lock().expect("lock").requests.len(), 3);
    // Three attempts: 3 × 0.5 s timeouts plus 0.1 s and 0.2 s back-off at least.
    assert!(t0.elapsed() >= Duration::from_millis(1800));

    // Resolved by hand: the accepting receiver is told.
    let alert = wait_alerts(&app, "severity=alarm", |l| !l.is_empty()).await;
    let aid = alert[0]["id"].as_i64().expect("id");
    let r = post_json(
        &app,
        &format!("/v1/alerts/{aid}/resolve"),
        &app.keys.writer,
        json!({"note": "done"}),
    )
    .await;
    assert_eq!(r.status(), StatusCode::OK);
    let d = wait_settled(&app, accept.0, 2).await;
    assert_eq!(d[0]["event"], "alert.resolved");
    assert_eq!(d[0]["state"], "delivered");

    // Deleted: gone from deliveries, 404 the second time.
    let r = app
        .req(
            Method::DELETE,
            &format!("/v1/admin/webhooks/{}", silent.0),
            Some(&app.keys.admin),
        )
        .send()
        .await
        .expect("DELETE");
    assert_eq!(r.status(), StatusCode::NO_CONTENT);
    let r = app
        .req(
            Method::DELETE,
            &format!("/v1/admin/webhooks/{}", silent.0),
            Some(&app.keys.admin),
        )
        .send()
        .await
        .expect("DELETE");
    assert_problem(r, StatusCode::NOT_FOUND, None, "deleted twice").await;
    app.stop().await;
}

/// Issue 15, point 5: a workshop pendulum of J5 measures viscous ×2.5 → alarm and an open
/// alert; a month later a lift of the same pantograph with realistic sensor noise on every
/// channel (it cannot inform J5's viscous damping) changes nothing: J5 stays `alarm` in fleet
/// health, the vehicle, the web page and the alert list, decided by the pendulum test, and
/// alerts and fleet health agree.
pub async fn an_uninformative_lift_leaves_a_workshop_alarm_standing(b: Backend) {
    let app = spawn_app(b).await;
    let (serial, vehicle) = ("160EC-WEAR-5", "EN57-9005");
    let mut pendulum: Value =
        serde_json::from_slice(&example("J5_viscous_x2.5.json")).expect("example");
    pendulum["trace_id"] = "wear-j5-pendulum".into();
    pendulum["vehicle_id"] = vehicle.into();
    pendulum["pantograph"]["serial"] = serial.into();
    pendulum["recorded_at"] = "2026-03-02T07:00:00Z".into();
    assert_eq!(
        app.upload_json(&serde_json::to_vec(&pendulum).unwrap())
            .await
            .status(),
        202
    );
    let fit = app.wait_for_fit("wear-j5-pendulum").await;
    let j5 = |f: &Value| {
        f["joints"]
            .as_array()
            .unwrap()
            .iter()
            .find(|j| j["joint"] == "J5")
            .cloned()
            .unwrap()
    };
    assert_eq!(j5(&fit)["status"], "alarm", "{fit}");
    let defaults = pantowatch::cli::simulate::docs::simulate_defaults().expect("defaults");
    let lift = pantowatch::cli::simulate::simulate_doc(&pantowatch::cli::simulate::SimulateArgs {
        kind: "lift".into(),
        protocol: "raise-and-lower".into(),
        sensor_noise: 1.0,
        h_noise_mm: 0.0,
        seed: 11,
        vehicle: vehicle.into(),
        serial: serial.into(),
        trace_id: Some("wear-lift-april".into()),
        recorded_at: "2026-04-02T07:00:00Z".into(),
        ..defaults
    })
    .expect("lift");
    let r = app
        .upload_json(&serde_json::to_vec(&lift.to_value()).unwrap())
        .await;
    assert_eq!(r.status(), 202, "{}", r.text().await.unwrap_or_default());
    let lift_fit = app.wait_for_fit("wear-lift-april").await;
    // The lift does not inform J5's viscous damping (its J5 may carry a dry estimate, but
    // never a verdict on viscous).
    let lj5 = j5(&lift_fit);
    assert_ne!(lj5["viscous"]["identifiable"], true, "{lj5}");
    // Fleet health: the pantograph is at alarm with J5 alarm.
    let (s, h) = app
        .get_json(&format!("/v1/fleet/health?vehicle={vehicle}"))
        .await;
    assert_eq!(s, 200, "{h}");
    let row = h["rows"]
        .as_array()
        .unwrap()
        .iter()
        .find(|r| r["serial"] == serial)
        .cloned()
        .expect("row");
    assert_eq!(row["worst_status"], "alarm", "{row}");
    assert!(
        row["not_ok"]
            .as_array()
            .unwrap()
            .iter()
            .any(|j| j["joint"] == "J5" && j["status"] == "alarm"),
        "{row}"
    );
    // The vehicle: J5's state is decided by the pendulum, with its date and kind.
    let (s, v) = app.get_json(&format!("/v1/vehicles/{vehicle}")).await;
    assert_eq!(s, 200, "{v}");
    let p = &v["pantographs"][0];
    assert_eq!(p["worst_status"], "alarm", "{p}");
    let st = p["joint_states"]
        .as_array()
        .unwrap()
        .iter()
        .find(|j| j["joint"] == "J5")
        .cloned()
        .expect("J5 state");
    assert_eq!(
        (
            st["status"].as_str(),
            st["kind"].as_str(),
            st["trace_id"].as_str()
        ),
        (Some("alarm"), Some("pendulum"), Some("wear-j5-pendulum")),
        "{st}"
    );
    // The alert list: J5's alarm still open, and every live alert's pantograph is not ok in
    // fleet health at that alert's severity (one state for both).
    let (s, alerts) = app.get_json("/v1/alerts?state=live").await;
    assert_eq!(s, 200, "{alerts}");
    let list = alerts
        .as_array()
        .or_else(|| alerts["alerts"].as_array())
        .cloned()
        .expect("alerts");
    let mine: Vec<&Value> = list.iter().filter(|a| a["serial"] == serial).collect();
    assert!(
        mine.iter()
            .any(|a| a["joint"] == "J5" && a["severity"] == "alarm" && a["state"] == "open"),
        "{alerts}"
    );
    for a in &mine {
        let joint = a["joint"].as_str().unwrap();
        let s = p["joint_states"]
            .as_array()
            .unwrap()
            .iter()
            .find(|j| j["joint"] == joint)
            .expect("state");
        assert_eq!(s["status"], a["severity"], "alert {a} vs state {s}");
    }
    // The web page shows J5 at alarm, decided by the pendulum test.
    let html = app.web_page(&format!("/pantographs/{serial}")).await;
    let section = html.split("id=\"joint-J5\"").nth(1).expect("J5 section");
    let section = section.split("</section>").next().unwrap_or("");
    assert!(section.contains("alarm"), "{section}");
    assert!(section.contains("pendulum test"), "{section}");
    // The lift's own page names the test and shows no internal error (issue 18).
    let page = app.web_page("/traces/wear-lift-april").await;
    assert!(page.contains("lift test of the whole pantograph"), "{page}");
    assert!(
        !page.contains("No model curve") && !page.contains("not a single-joint"),
        "{page}"
    );
    app.stop().await;
}

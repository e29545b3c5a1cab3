//! Recordings of one rig fitted pooled through the service (issue 36, point 5): the two measured
//! encoder-pendulum recordings (`../shared/data/measured`, 45° and 90°) uploaded with one
//! `test.rig_id`; the pooled fit is the newer trace's fit, serving each recording's RMSE before
//! and after and the pooled verdict; a refused pooled upload names `test.rig_id` and writes
//! nothing.

use std::time::{Duration, Instant};

use reqwest::StatusCode;
use serde_json::{Value, json};

use crate::harness::*;

fn measured(angle: &str, rig_id: &str) -> Value {
    let mut v: Value = serde_json::from_slice(&shared(&format!(
        "data/measured/encoder-pendulum-{angle}deg.json"
    )))
    .expect("measured json");
    v["test"]["rig_id"] = json!(rig_id);
    v
}

/// Polls the trace's fit until it is the pooled one.
async fn wait_for_pooled(app: &TestApp, trace_id: &str) -> Value {
    let t0 = Instant::now();
    loop {
        let (s, v) = app.get_json(&format!("/v1/traces/{trace_id}/fit")).await;
        if s == StatusCode::OK && v["pooled_rig"].is_object() {
            return v;
        }
        assert!(v["job"]["state"] != "failed", "fit failed: {v}");
        assert!(
            t0.elapsed() < Duration::from_secs(120),
            "no pooled fit after 120 s: {v}"
        );
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
}

pub async fn recordings_of_one_rig_are_fitted_pooled(b: Backend) {
    let app = spawn_app(b).await;
    let rig = "encoder-rod-1";
    // Refused before anything is written: a rig id without a pantograph serial, on a lift.
    let before = app.stored().await;
    let mut v = measured("45", rig);
    v["pantograph"].as_object_mut().unwrap().remove("serial");
    let r = app.upload_json(&serde_json::to_vec(&v).unwrap()).await;
    assert_problem(
        r,
        StatusCode::UNPROCESSABLE_ENTITY,
        Some("test.rig_id"),
        "no serial",
    )
    .await;
    let mut v = measured("45", "");
    v["test"]["rig_id"] = json!(7);
    let r = app.upload_json(&serde_json::to_vec(&v).unwrap()).await;
    assert_problem(
        r,
        StatusCode::UNPROCESSABLE_ENTITY,
        Some("test.rig_id"),
        "not text",
    )
    .await;
    assert_eq!(app.stored().await, before);

    for a in ["45", "90"] {
        let r = app
            .upload_json(&serde_json::to_vec(&measured(a, rig)).unwrap())
            .await;
        assert_eq!(r.status(), 202, "{}", r.text().await.unwrap_or_default());
    }
    let (ids, newer) = (
        [
            "measured-encoder-pendulum-45deg",
            "measured-encoder-pendulum-90deg",
        ],
        "measured-encoder-pendulum-90deg",
    );
    let fit = wait_for_pooled(&app, newer).await;
    let p = &fit["pooled_rig"];
    assert_eq!(p["rig_id"], rig, "{p}");
    let recs = p["recordings"].as_array().expect("recordings");
    assert_eq!(recs.len(), 2, "{p}");
    assert_eq!(recs[0]["trace_id"], newer, "{p}");
    for rec in recs {
        assert!(ids.contains(&rec["trace_id"].as_str().unwrap()), "{rec}");
        let (before, after) = (
            rec["rmse_pooled_before"].as_f64().unwrap(),
            rec["rmse_pooled_after"].as_f64().unwrap(),
        );
        // The pooled base model misses by over a degree on each; the best tried (an inertia
        // error) takes each under half a degree, but leaves over 3× the noise in a half: no
        // effect explains both recordings, the verdict is `unexplained` (as the CLI's).
        assert!(before > 1.0 && after < 0.5, "{rec}");
        assert!(rec["rmse_alone"].as_f64().unwrap() > 0.0, "{rec}");
    }
    assert_eq!(p["verdict"], "unexplained", "{p}");
    assert_eq!(p["effects"], json!([]), "{p}");
    assert!(
        p["best_tried"]
            .as_array()
            .unwrap()
            .contains(&json!("inertia_error")),
        "{p}"
    );
    assert!(p["tried"].as_array().unwrap().len() >= 7, "{p}");
    assert_eq!(fit["residual"]["verdict"], "unexplained", "{fit}");
    assert_eq!(fit["joints"][0]["status"], "unknown", "{fit}");
    assert!(fit["residual"]["joints_withheld"].is_string(), "{fit}");
    assert!(
        fit["model_version"].as_str().unwrap().contains(rig),
        "{fit}"
    );
    app.assert_fit_serves_the_stored_json(&fit).await;

    // Another pin under the same rig id: refused, naming the field, nothing written.
    let before = app.stored().await;
    let mut v = measured("45", rig);
    v["trace_id"] = json!("another-body");
    v["test"]["rig"]["pin_radius_m"] = json!(0.003);
    let r = app.upload_json(&serde_json::to_vec(&v).unwrap()).await;
    let body = assert_problem(
        r,
        StatusCode::UNPROCESSABLE_ENTITY,
        Some("test.rig_id"),
        "other body",
    )
    .await;
    assert!(
        body["detail"].as_str().unwrap().contains("test.rig"),
        "{body}"
    );
    assert_eq!(app.stored().await, before);

    // The trace page links the recordings pooled.
    let page = app.web_page(&format!("/traces/{newer}")).await;
    assert!(page.contains("Pooled over rig"), "{page}");
    for id in ids {
        assert!(page.contains(&format!("/traces/{id}")), "{id}");
    }
    app.stop().await;
}

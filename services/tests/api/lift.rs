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
        names,
        ["J1", "J2", "J2'", "J3", "J4", "J5", "J6", "J7", "J8", "J9"],
        "{fit}"
    );
    for j in joints {
        let status = j["status"].as_str().unwrap_or("");
        assert!(status == "ok" || status == "unknown", "{j}");
        if j["identifiable"] == false {
            assert_eq!(status, "unknown", "{j}");
        }
    }
    let j3 = joints.iter().find(|j| j["joint"] == "J3").expect("J3");
    assert_eq!(j3["identifiable"], true, "{j3}");
    assert_eq!(fit["rmse"]["unit"], "m");
    assert!(fit["rmse"]["value"].as_f64().expect("rmse") < 1e-3, "{fit}");
    assert_eq!(fit["residual"]["effects"], json!([]));
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

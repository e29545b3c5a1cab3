//! Issue 37 over HTTP: each joint's evidence (what it rests on, how old, the interval now), the
//! test plan of a pantograph and of the fleet, and the `test due` alert's lifecycle.

use reqwest::StatusCode;
use serde_json::Value;

use crate::alerts::wait_alerts;
use crate::harness::{Backend, TestApp, assert_problem_param, spawn_app};

/// A pendulum swing of `joint` at Table 4, the stand's noise (`pantowatch simulate`'s
/// defaults), uploaded and fitted.
async fn swing(app: &TestApp, joint: &str, trace_id: &str, serial: &str, at: &str, seed: u64) {
    let defaults = pantowatch::cli::simulate::docs::simulate_defaults().expect("defaults");
    let doc = pantowatch::cli::simulate::simulate_doc(&pantowatch::cli::simulate::SimulateArgs {
        kind: "pendulum".into(),
        joint: joint.into(),
        seed,
        vehicle: "EN57-3701".into(),
        serial: serial.into(),
        trace_id: Some(trace_id.into()),
        recorded_at: at.into(),
        ..defaults
    })
    .expect("pendulum");
    let r = app
        .upload_json(&serde_json::to_vec(&doc.to_value()).expect("json"))
        .await;
    assert_eq!(r.status(), 202, "{}", r.text().await.unwrap_or_default());
    app.wait_for_fit(trace_id).await;
}

fn joint<'a>(ev: &'a Value, name: &str) -> &'a Value {
    ev["joints"]
        .as_array()
        .expect("joints")
        .iter()
        .find(|j| j["joint"] == name)
        .unwrap_or_else(|| panic!("no {name} in {ev}"))
}

pub async fn evidence_plan_and_test_due_over_http(b: Backend) {
    let app = spawn_app(b).await;
    let serial = "160EC-PLAN-1";
    // J5 swung in January, J1 in June: at June J5's evidence is 151 days old (allowed 120).
    swing(
        &app,
        "J5",
        "plan-j5-jan",
        serial,
        "2026-01-01T08:00:00Z",
        501,
    )
    .await;
    swing(
        &app,
        "J1",
        "plan-j1-jun",
        serial,
        "2026-06-01T08:00:00Z",
        502,
    )
    .await;

    let (s, ev) = app
        .get_json(&format!(
            "/v1/pantographs/{serial}/evidence?at=2026-06-01T08:00:00Z"
        ))
        .await;
    assert_eq!(s, StatusCode::OK, "{ev}");
    assert_eq!(ev["model"], "160EC", "{ev}");
    let j5 = joint(&ev, "J5");
    for p in ["viscous", "dry"] {
        let e = &j5[p];
        assert_eq!(e["test"]["kind"], "pendulum", "{e}");
        assert_eq!(e["test"]["trace_id"], "plan-j5-jan", "{e}");
        assert!(
            (e["age_days"].as_f64().expect("age") - 151.0).abs() < 0.01,
            "{e}"
        );
        // The interval now is the interval then widened, never narrower.
        let then = e["test"]["ci95"][1].as_f64().unwrap() - e["test"]["ci95"][0].as_f64().unwrap();
        let now = e["now"]["ci95"][1].as_f64().unwrap() - e["now"]["ci95"][0].as_f64().unwrap();
        assert!(now > then, "{e}");
        assert_eq!(e["rate"]["source"], "fleet", "{e}");
        assert!(
            e["summary"]
                .as_str()
                .unwrap()
                .starts_with("measured on 2026-01-01"),
            "{e}"
        );
    }
    assert_eq!(j5["test_due"], true, "{j5}");
    assert_eq!(j5["max_age_days"], 120.0, "{j5}");
    let j1 = joint(&ev, "J1");
    assert_eq!(j1["test_due"], false, "{j1}");
    assert!(j1["age_days"].as_f64().unwrap() < 0.01, "{j1}");
    assert_eq!(j1["dry"]["standing"], "measured", "{j1}");
    // Never swung: `never_measured`, no test, no age — not `unknown` with a date.
    let j2 = joint(&ev, "J2");
    assert_eq!(j2["dry"]["standing"], "never_measured", "{j2}");
    assert_eq!(j2["dry"]["test"], Value::Null, "{j2}");
    assert_eq!(j2["age_days"], Value::Null, "{j2}");
    assert_eq!(j2["test_due"], false, "{j2}");
    // Two years on, J5's interval is wider than the watch band: measured, now uncertain.
    let (s, later) = app
        .get_json(&format!(
            "/v1/pantographs/{serial}/evidence?at=2028-01-01T00:00:00Z"
        ))
        .await;
    assert_eq!(s, StatusCode::OK, "{later}");
    let j5_later = joint(&later, "J5");
    assert_eq!(j5_later["dry"]["standing"], "uncertain", "{j5_later}");
    assert_eq!(j5_later["dry"]["status_now"], "unknown", "{j5_later}");
    assert!(
        j5_later["dry"]["summary"]
            .as_str()
            .unwrap()
            .ends_with("now uncertain"),
        "{j5_later}"
    );

    // The plan: the old J5 swing buys more than the fresh J1 one; only kinds seen to inform.
    let (s, plan) = app
        .get_json(&format!(
            "/v1/pantographs/{serial}/plan?at=2026-06-01T08:00:00Z"
        ))
        .await;
    assert_eq!(s, StatusCode::OK, "{plan}");
    let tests = plan["tests"].as_array().expect("tests");
    let order: Vec<_> = tests
        .iter()
        .map(|t| t["joint"].as_str().unwrap_or(""))
        .collect();
    assert_eq!(order, ["J5", "J1"], "{plan}");
    assert!(tests.iter().all(|t| t["kind"] == "pendulum"), "{plan}");
    assert!(
        tests[0]["buys"].as_f64().unwrap() > tests[1]["buys"].as_f64().unwrap(),
        "{plan}"
    );
    assert!(tests[0]["info_bits"].as_f64().unwrap() > 0.0, "{plan}");
    assert_eq!(tests[0]["params"].as_array().unwrap().len(), 2, "{plan}");

    // The fleet plan: this pantograph's best test is the J5 swing.
    let (s, fleet) = app
        .get_json("/v1/fleet/plan?at=2026-06-01T08:00:00Z&limit=10")
        .await;
    assert_eq!(s, StatusCode::OK, "{fleet}");
    assert_eq!(fleet["pantographs"], 1, "{fleet}");
    let first = &fleet["tests"][0];
    assert_eq!(
        (first["serial"].as_str(), first["joint"].as_str()),
        (Some(serial), Some("J5")),
        "{fleet}"
    );
    assert!(
        (first["oldest_evidence_days"].as_f64().unwrap() - 151.0).abs() < 0.01,
        "{fleet}"
    );

    // `J5 test due`: opened by the June fit, with its evidence; J1 has none.
    let live = wait_alerts(&app, "state=live", |l| {
        l.iter().any(|a| a["joint"] == "J5 test due")
    })
    .await;
    let due = live
        .iter()
        .find(|a| a["joint"] == "J5 test due")
        .expect("J5 test due");
    assert_eq!(due["severity"], "watch", "{due}");
    assert_eq!(due["evidence"]["due"]["joint"], "J5", "{due}");
    assert!(
        due["reason"].as_str().unwrap().contains("151 days old"),
        "{due}"
    );
    assert!(
        !live.iter().any(|a| a["joint"] == "J1 test due"),
        "{live:?}"
    );
    // Swinging J5 again resolves it.
    swing(
        &app,
        "J5",
        "plan-j5-jun",
        serial,
        "2026-06-02T08:00:00Z",
        503,
    )
    .await;
    wait_alerts(&app, "state=resolved", |l| {
        l.iter().any(|a| a["joint"] == "J5 test due")
    })
    .await;

    // Bad input: problems naming the parameter; an unknown pantograph is 404.
    for (path, param) in [
        (
            format!("/v1/pantographs/{serial}/evidence?at=yesterday"),
            "at",
        ),
        (format!("/v1/pantographs/{serial}/plan?at=2026-13-01"), "at"),
        ("/v1/fleet/plan?limit=0".to_owned(), "limit"),
        ("/v1/fleet/plan?limit=x".to_owned(), "limit"),
    ] {
        let r = app.get(&path, &app.keys.reader).await;
        assert_problem_param(r, StatusCode::BAD_REQUEST, param, &path).await;
    }
    let r = app
        .get("/v1/pantographs/160EC-NONE/plan", &app.keys.reader)
        .await;
    assert_eq!(r.status(), 404);
    app.stop().await;
}

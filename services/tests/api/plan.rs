//! Issue 37 over HTTP: each joint's evidence (what it rests on, how old, the interval now), the
//! test plan of a pantograph and of the fleet, and the `test due` alert's lifecycle.

use chrono::{DateTime, TimeZone, Utc};
use pantowatch::store::{NewFit, NewTrace, Status, Store};
use pantowatch_models::report::{FitResult, JointResult, ParamResult, Quantity};
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

/// A fit result of `joints` at the 160EC's baselines × a factor in 0.4–2.4 each (from `r`),
/// a relative interval of 2–40 %, each parameter's status from its interval; a lift's J6 not
/// informed.
fn random_fit(trace_id: &str, joints: &[&str], lift: bool, r: &mut u64) -> FitResult {
    let t = pantowatch_models::data::builtin("160EC").expect("160EC");
    let mut next = || {
        *r = r.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = *r;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
    };
    let th = pantowatch_models::drift::DriftThresholds::default();
    let joints = joints
        .iter()
        .map(|j| {
            let data = t.joint(j).expect("joint");
            let informed = !(lift && *j == "J6");
            let mut param = |base: f64| {
                let value = base * (0.4 + 2.0 * next());
                let rel = 0.02 + 0.38 * next();
                let ci95 = [value * (1.0 - rel), value * (1.0 + rel)];
                let status = if informed {
                    th.judge(ci95, value, Some(base)).status
                } else {
                    Status::Unknown
                };
                ParamResult {
                    value,
                    ci95,
                    baseline: Some(base),
                    unit: String::new(),
                    identifiable: informed,
                    status,
                    combination: None,
                }
            };
            let viscous = param(data.viscous_baseline());
            let dry = param(data.dry_mu);
            let status = viscous.status.max(dry.status);
            JointResult {
                joint: (*j).to_owned(),
                viscous,
                dry,
                identifiable: informed,
                status,
            }
        })
        .collect();
    FitResult {
        trace_id: trace_id.to_owned(),
        joints,
        rmse: Quantity {
            value: 0.5,
            unit: "mm".into(),
        },
        ..FitResult::default()
    }
}

/// Stores a trace of `kind` and its fit (no fitting: the fit result given).
async fn put_fit(
    store: &Store,
    serial: &str,
    id: &str,
    kind: &str,
    joint: Option<&str>,
    recorded_at: DateTime<Utc>,
    fit: FitResult,
) {
    let t: Vec<f64> = (0..20).map(|i| f64::from(i) * 0.01).collect();
    let h: Vec<f64> = (0..20).map(|i| f64::from(i % 5)).collect();
    let sha = hex_of(id);
    store
        .insert_trace(NewTrace {
            trace_id: Some(id.to_owned()),
            vehicle_id: "EN57-9001".into(),
            serial: Some(serial.to_owned()),
            model: "160EC".into(),
            recorded_at,
            kind: kind.into(),
            joint: joint.map(str::to_owned),
            test_json: format!(r#"{{"kind":"{kind}"}}"#),
            content_sha256: sha,
            channels: vec![("t_s".into(), t), ("H_mm".into(), h)],
            model_version: "test".into(),
        })
        .await
        .expect("trace");
    store
        .insert_fit(id, "test", &NewFit::from_result(fit))
        .await
        .expect("fit");
}

/// A content hash stand-in: 64 hex digits, one per trace id (FNV-1a).
fn hex_of(s: &str) -> String {
    let h = s.bytes().fold(0xcbf2_9ce4_8422_2325u64, |h, b| {
        (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3)
    });
    format!("{h:064x}")
}

/// `GET /v1/fleet/plan?at=&limit=` answers `evidence::fleet_plan` from every evidence row.
async fn same_plan(app: &TestApp, at: &str, limit: usize) {
    let path = format!("/v1/fleet/plan?at={at}&limit={limit}");
    let (s, served) = app.get_json(&path).await;
    assert_eq!(s, StatusCode::OK, "{served}");
    let rows = app.store.param_evidence(None).await.expect("rows");
    let at = DateTime::parse_from_rfc3339(at)
        .expect("at")
        .with_timezone(&Utc);
    let scratch = pantowatch::evidence::fleet_plan(&rows, at, limit);
    assert!(scratch.tests.len() > 1, "{path}: {served}");
    assert_eq!(
        served,
        serde_json::to_value(&scratch).expect("json"),
        "{path}"
    );
}

/// `GET /v1/fleet/plan` (the evidence grouped once per evidence version and kept, the plan per
/// `at`) answers what `evidence::fleet_plan` computes from scratch from every evidence row, on
/// a random store: pantographs with random tests of random kinds, dates and outcomes, trends on
/// some; at several times and limits; and again after a new fit moves the evidence.
pub async fn the_kept_fleet_plan_is_the_plan_from_scratch(b: Backend) {
    let app = spawn_app(b).await;
    let store = &app.store.clone();
    let t0 = Utc
        .with_ymd_and_hms(2025, 3, 1, 8, 0, 0)
        .single()
        .expect("date");
    let joints = ["J1", "J2", "J3", "J4", "J5", "J6", "J7", "J8"];
    let mut r = 37u64;
    let mut pick = |n: u64| {
        r = r.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1);
        (r >> 33) % n
    };
    let mut seed = 11u64;
    for p in 0..12 {
        let serial = format!("160EC-RND{p:02}");
        for k in 0..(2 + pick(6)) {
            let id = format!("{serial}-{k}");
            let at = t0 + chrono::TimeDelta::days(pick(300) as i64);
            let (kind, joint) = match pick(4) {
                0 | 1 => ("pendulum", Some(joints[pick(7) as usize])),
                2 => ("slider", Some("J8")),
                _ => ("lift", None),
            };
            let fit = match joint {
                Some(j) => random_fit(&id, &[j], false, &mut seed),
                None => random_fit(&id, &joints, true, &mut seed),
            };
            put_fit(store, &serial, &id, kind, joint, at, fit).await;
        }
        if p % 3 == 0 {
            pantowatch::evidence::refresh_trends(store, &serial)
                .await
                .expect("trends");
        }
    }
    for (at, limit) in [
        ("2026-01-15T00:00:00Z", 1000),
        ("2026-01-15T00:01:00Z", 3),
        // The same `at` again: from the kept ranking, other limits.
        ("2026-01-15T00:01:00Z", 9),
        ("2026-01-15T00:01:00Z", 2),
        ("2025-06-01T12:00:00Z", 1000),
        ("2028-01-01T00:00:00Z", 7),
        ("2026-01-15T00:00:00Z", 5),
    ] {
        same_plan(&app, at, limit).await;
    }
    // A new fit moves the evidence: the kept plan is dropped, the next answer is the new plan.
    let id = "160EC-RND00-late";
    let fit = random_fit(id, &["J4"], false, &mut seed);
    let late = Utc
        .with_ymd_and_hms(2026, 1, 10, 8, 0, 0)
        .single()
        .expect("date");
    put_fit(store, "160EC-RND00", id, "pendulum", Some("J4"), late, fit).await;
    same_plan(&app, "2026-01-15T00:00:00Z", 1000).await;
    app.stop().await;
}

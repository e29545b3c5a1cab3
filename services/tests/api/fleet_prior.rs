//! Issue 37, point 3 over HTTP: the fleet prior learned from the store's workshop fits,
//! versioned, used by every lift, pooled-lift and force-gauge fit and recorded on it
//! (`fit.prior`, `fits.prior_version`), and those refitted when a new version is published.
//!
//! The simulated fleet: J5's viscous and dry coefficients of each workshop unit are Table 4 ×
//! a known ratio (the fleet's truth), swung on the pendulum rig at the stand's noise
//! (`pantowatch simulate`'s defaults); the lifts are raise-and-lower lifts at the stand's noise
//! on every channel.

use std::time::{Duration, Instant};

use reqwest::{Method, StatusCode};
use serde_json::{Value, json};

use crate::harness::{Backend, TestApp, assert_problem_param, spawn_app};

/// Table 4's J5 (viscous, dry) in the units the pendulum's document takes.
fn j5_baseline() -> (f64, f64) {
    let t = pantowatch_models::data::builtin_160ec();
    let j = t.joint("J5").expect("J5");
    (j.viscous_baseline(), j.dry_mu)
}

/// A pendulum swing of J5 on `serial` with both coefficients Table 4 × `ratio`, uploaded.
async fn swing_j5(app: &TestApp, serial: &str, ratio: f64, seed: u64) -> String {
    let (v0, d0) = j5_baseline();
    let trace_id = format!("prior-{serial}-j5");
    let defaults = pantowatch::cli::simulate::docs::simulate_defaults().expect("defaults");
    let doc = pantowatch::cli::simulate::simulate_doc(&pantowatch::cli::simulate::SimulateArgs {
        kind: "pendulum".into(),
        joint: "J5".into(),
        viscous: Some(v0 * ratio),
        dry: Some(d0 * ratio),
        seed,
        vehicle: "EN57-3702".into(),
        serial: serial.into(),
        trace_id: Some(trace_id.clone()),
        recorded_at: "2026-02-01T08:00:00Z".into(),
        ..defaults
    })
    .expect("pendulum");
    let r = app
        .upload_json(&serde_json::to_vec(&doc.to_value()).expect("json"))
        .await;
    assert_eq!(r.status(), 202, "{}", r.text().await.unwrap_or_default());
    trace_id
}

/// A raise-and-lower lift of `serial` at the stand's noise, uploaded.
async fn lift(app: &TestApp, serial: &str, trace_id: &str, seed: u64) {
    let doc = pantowatch::cli::simulate::docs::noisy_lift_doc(seed, &[], 1.0, serial, trace_id)
        .expect("lift");
    let r = app
        .upload_json(&serde_json::to_vec(&doc.to_value()).expect("json"))
        .await;
    assert_eq!(r.status(), 202, "{}", r.text().await.unwrap_or_default());
}

/// Polls the trace's current fit until its `fit.prior.version` is `version`.
async fn fit_under_prior(app: &TestApp, trace_id: &str, version: i64) -> Value {
    fit_under_prior_where(app, trace_id, version, |_| true).await
}

/// Polls the trace's current fit until its `fit.prior.version` is `version` and `ok` holds.
async fn fit_under_prior_where(
    app: &TestApp,
    trace_id: &str,
    version: i64,
    ok: impl Fn(&Value) -> bool,
) -> Value {
    let t0 = Instant::now();
    loop {
        let (s, v) = app.get_json(&format!("/v1/traces/{trace_id}/fit")).await;
        if s == StatusCode::OK && v["fit"]["prior"]["version"] == version && ok(&v) {
            return v;
        }
        assert!(
            t0.elapsed() < Duration::from_secs(120),
            "{trace_id}: no fit under prior version {version} after 120 s: {v}"
        );
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
}

async fn relearn(app: &TestApp, body: Value) -> (StatusCode, Value) {
    let r = app
        .req(Method::POST, "/v1/fleet/prior", Some(&app.keys.admin))
        .json(&body)
        .send()
        .await
        .expect("POST /v1/fleet/prior");
    let s = r.status();
    (s, r.json().await.unwrap_or(Value::Null))
}

fn param<'a>(prior: &'a Value, joint: &str, kind: &str) -> &'a Value {
    prior["params"]
        .as_array()
        .expect("params")
        .iter()
        .find(|p| p["joint"] == joint && p["kind"] == kind)
        .unwrap_or_else(|| panic!("no {joint} {kind} in {prior}"))
}

fn mean_sd(x: &[f64]) -> (f64, f64) {
    let n = x.len() as f64;
    let m = x.iter().sum::<f64>() / n;
    let v = x.iter().map(|v| (v - m).powi(2)).sum::<f64>() / (n - 1.0);
    (m, v.sqrt())
}

fn f(v: &Value) -> f64 {
    v.as_f64().unwrap_or_else(|| panic!("not a number: {v}"))
}

pub async fn a_fleet_prior_is_learned_versioned_recorded_and_refitted(b: Backend) {
    let app = spawn_app(b).await;

    // No workshop test yet: version 0, the type file's Table 4 ± floor for every parameter.
    let (s, p0) = app.get_json("/v1/fleet/prior").await;
    assert_eq!(s, StatusCode::OK, "{p0}");
    assert_eq!(p0["version"], 0, "{p0}");
    assert_eq!(p0["source"], "type_file", "{p0}");
    let floor = f(&p0["floor_relative_sd"]);
    for p in p0["params"].as_array().expect("params") {
        assert_eq!(f(&p["mean_ratio"]), 1.0, "{p}");
        assert_eq!(f(&p["sd_ratio"]), floor, "{p}");
        assert_eq!(p["learned"], false, "{p}");
    }
    // A lift fitted now records version 0 from the type file, unwidened.
    lift(&app, "160EC-PRIOR-L1", "prior-lift-1", 11).await;
    let l1 = fit_under_prior(&app, "prior-lift-1", 0).await;
    assert_eq!(
        l1["fit"]["prior"],
        json!({"version": 0, "source": "type_file", "sd_scale": 1.0}),
        "{l1}"
    );
    // Relearning with no workshop fits changes nothing: the type file's floor stands.
    let (s, r) = relearn(&app, json!({})).await;
    assert_eq!(s, StatusCode::OK, "{r}");
    assert_eq!(r["published"], false, "{r}");
    assert_eq!(r["queued"], 0, "{r}");
    assert_eq!(r["n_estimates"], 0, "{r}");
    assert_eq!(r["prior"]["version"], 0, "{r}");
    assert_eq!(r["prior"]["source"], "type_file", "{r}");

    // Five workshop units whose J5 is Table 4 × these (the fleet's truth: mean 1.40, sd 0.12).
    let truth1 = [1.25, 1.40, 1.55, 1.30, 1.50];
    let mut ids = Vec::new();
    for (i, r) in truth1.iter().enumerate() {
        ids.push(swing_j5(&app, &format!("160EC-PRIOR-W{i}"), *r, 700 + i as u64).await);
    }
    for id in &ids {
        app.wait_for_fit(id).await;
    }
    let (s, r) = relearn(&app, json!({"model": "160EC"})).await;
    assert_eq!(s, StatusCode::CREATED, "{r}");
    assert_eq!(r["published"], true, "{r}");
    // The lift fitted under version 0 is queued again.
    assert_eq!(r["queued"], 1, "{r}");
    let p1 = &r["prior"];
    assert_eq!(p1["version"], 1, "{r}");
    assert_eq!(p1["source"], "learned", "{r}");
    assert_eq!(p1["n_units"], 5, "{r}");
    let (m1, sd1) = mean_sd(&truth1);
    for kind in ["viscous", "dry"] {
        let q = param(p1, "J5", kind);
        eprintln!("{b:?} version 1 J5 {kind}: {q} (truth mean {m1:.3}, sd {sd1:.3})");
        assert_eq!(q["n_fits"], 5, "{q}");
        assert_eq!(q["learned"], true, "{q}");
        // The fleet's mean and spread, from five units' fits at the stand's noise.
        assert!(
            (f(&q["mean_ratio"]) - m1).abs() < 0.02,
            "J5 {kind}: {q} (truth {m1})"
        );
        let spread = f(&q["spread_ratio"]);
        assert!(
            (spread - sd1).abs() < 0.03,
            "J5 {kind}: {q} (truth {sd1:.3})"
        );
        // The predictive sd holds the spread and the mean's own uncertainty.
        assert!(f(&q["sd_ratio"]) >= spread, "{q}");
    }
    // A joint no workshop test swung keeps the type file's floor.
    let j1 = param(p1, "J1", "dry");
    assert_eq!(j1["n_fits"], 0, "{j1}");
    assert_eq!(j1["learned"], false, "{j1}");
    assert_eq!(f(&j1["sd_ratio"]), floor, "{j1}");
    assert_eq!(f(&j1["mean_ratio"]), 1.0, "{j1}");

    // The old lift is refitted under version 1 and says so; the lift does not inform J5, so
    // its J5 entries are the prior's: centred on the fleet's mean, not on Table 4.
    let l1 = fit_under_prior(&app, "prior-lift-1", 1).await;
    assert_eq!(l1["fit"]["prior"]["source"], "learned", "{l1}");
    assert_eq!(l1["fit"]["prior"]["sd_scale"], 1.5, "{l1}");
    let (_, d0) = j5_baseline();
    let j5 = l1["joints"]
        .as_array()
        .expect("joints")
        .iter()
        .find(|j| j["joint"] == "J5")
        .expect("J5");
    assert_eq!(j5["dry"]["identifiable"], false, "{j5}");
    let read = f(&j5["dry"]["value"]) / d0;
    assert!(
        (read - f(&param(p1, "J5", "dry")["mean_ratio"])).abs() < 1e-9,
        "J5 dry read {read} × Table 4: {j5}"
    );
    let stored = app
        .store
        .get_fit("prior-lift-1")
        .await
        .expect("get")
        .expect("fit");
    assert!(
        stored.model_version.ends_with("; fleet prior v1"),
        "{}",
        stored.model_version
    );
    // A new lift takes the newest version.
    lift(&app, "160EC-PRIOR-L2", "prior-lift-2", 12).await;
    fit_under_prior(&app, "prior-lift-2", 1).await;

    // Three more units, worn further: the fleet's J5 moves, version 2, both lifts refitted.
    let truth2 = [1.85, 1.95, 1.80];
    let mut ids = Vec::new();
    for (i, r) in truth2.iter().enumerate() {
        ids.push(swing_j5(&app, &format!("160EC-PRIOR-W{}", 5 + i), *r, 800 + i as u64).await);
    }
    for id in &ids {
        app.wait_for_fit(id).await;
    }
    let (s, r) = relearn(&app, json!({})).await;
    assert_eq!(s, StatusCode::CREATED, "{r}");
    assert_eq!(r["prior"]["version"], 2, "{r}");
    assert_eq!(r["queued"], 2, "{r}");
    let all: Vec<f64> = truth1.iter().chain(&truth2).copied().collect();
    let (m2, _) = mean_sd(&all);
    let q = param(&r["prior"], "J5", "dry");
    eprintln!("{b:?} version 2 J5 dry: {q} (truth mean {m2:.3})");
    assert_eq!(q["n_fits"], 8, "{q}");
    assert!((f(&q["mean_ratio"]) - m2).abs() < 0.02, "{q} (truth {m2})");
    fit_under_prior(&app, "prior-lift-1", 2).await;
    fit_under_prior(&app, "prior-lift-2", 2).await;
    // Relearning again changes nothing: no version, no refit.
    let (s, r) = relearn(&app, json!({})).await;
    assert_eq!(s, StatusCode::OK, "{r}");
    assert_eq!(r["prior"]["version"], 2, "{r}");
    assert_eq!(r["queued"], 0, "{r}");

    // Every version stays readable; the current one is the newest.
    let (s, v1) = app.get_json("/v1/fleet/prior?version=1").await;
    assert_eq!(s, StatusCode::OK, "{v1}");
    assert_eq!(v1["version"], 1, "{v1}");
    assert_eq!(param(&v1, "J5", "dry")["n_fits"], 5, "{v1}");
    let (_, cur) = app.get_json("/v1/fleet/prior").await;
    assert_eq!(cur["version"], 2, "{cur}");
    assert!(cur["learned_at"].is_string(), "{cur}");
    let (s, none) = app.get_json("/v1/fleet/prior?version=9").await;
    assert_eq!(s, StatusCode::NOT_FOUND, "{none}");
    let (s, nope) = app.get_json("/v1/fleet/prior?model=NOPE").await;
    assert_eq!(s, StatusCode::NOT_FOUND, "unknown type: {nope}");
    assert!(
        nope["detail"].as_str().is_some_and(|d| d.contains("NOPE")),
        "{nope}"
    );
    let r = app
        .get("/v1/fleet/prior?version=-1", &app.keys.reader)
        .await;
    assert_problem_param(r, StatusCode::BAD_REQUEST, "version", "negative version").await;
    app.stop().await;
}

/// The dry μ entry of `joint` in a fit result.
fn dry_of<'a>(fit: &'a Value, joint: &str) -> &'a Value {
    &fit["joints"]
        .as_array()
        .expect("joints")
        .iter()
        .find(|j| j["joint"] == joint)
        .unwrap_or_else(|| panic!("no {joint} in {fit}"))["dry"]
}

/// A force-gauge record (`simulate --kind static_force`, 0.2 N noise, 0.1 N resolution) of
/// `serial`, uploaded.
async fn gauge(app: &TestApp, serial: &str, trace_id: &str, recorded_at: &str) {
    let mut doc = crate::gauge::gauge_doc(serial, trace_id, &[]).to_value();
    doc["recorded_at"] = json!(recorded_at);
    let r = app
        .upload_json(&serde_json::to_vec(&doc).expect("json"))
        .await;
    assert_eq!(r.status(), 202, "{}", r.text().await.unwrap_or_default());
}

/// Issue 37, point 3 for the force gauge and the pooled lift: a gauge record's fit records the
/// prior it used and is refitted under a new version, its unreported joints at the new prior's
/// centre; a lift pooled with a gauge record is pooled again under the new version (its pool
/// stays the current fit and records the version), and nothing is queued while no newer
/// version is published.
pub async fn a_gauge_fit_and_a_pooled_lift_follow_the_fleet_prior(b: Backend) {
    let app = spawn_app(b).await;
    let (_, d0) = j5_baseline();
    // A gauge record alone, and a gauge record with the lift after it (a pool of two).
    gauge(
        &app,
        "160EC-PRIOR-G1",
        "prior-gauge-1",
        "2026-03-01T06:00:00Z",
    )
    .await;
    gauge(
        &app,
        "160EC-PRIOR-P1",
        "prior-pool-gauge",
        "2026-03-01T06:00:00Z",
    )
    .await;
    let mut l = pantowatch::cli::simulate::docs::noisy_lift_doc(
        21,
        &[],
        1.0,
        "160EC-PRIOR-P1",
        "prior-pool-lift",
    )
    .expect("lift")
    .to_value();
    l["recorded_at"] = json!("2026-03-02T06:00:00Z");
    let r = app
        .upload_json(&serde_json::to_vec(&l).expect("json"))
        .await;
    assert_eq!(r.status(), 202, "{}", r.text().await.unwrap_or_default());

    // Version 0: the gauge fit records the type file's prior; its J5 (in the record's level,
    // not separately identified) is at Table 4 with the prior's interval, as before priors.
    let g0 = fit_under_prior(&app, "prior-gauge-1", 0).await;
    assert_eq!(
        g0["fit"]["prior"],
        json!({"version": 0, "source": "type_file", "sd_scale": 1.0}),
        "{g0}"
    );
    assert_eq!(dry_of(&g0, "J5")["identifiable"], false, "{g0}");
    assert!(
        (f(&dry_of(&g0, "J5")["value"]) / d0 - 1.0).abs() < 1e-12,
        "{g0}"
    );
    let pooled = |v: &Value| v["pooled"].is_object();
    let p0 = fit_under_prior_where(&app, "prior-pool-lift", 0, pooled).await;
    assert_eq!(
        p0["pooled"]["trace_ids"],
        json!(["prior-pool-lift", "prior-pool-gauge"]),
        "{p0}"
    );
    app.wait_for_fit("prior-pool-gauge").await;

    // Five workshop units with J5 at 1.4× Table 4 on average: version 1.
    let truth = [1.25, 1.40, 1.55, 1.30, 1.50];
    let mut ids = Vec::new();
    for (i, r) in truth.iter().enumerate() {
        ids.push(swing_j5(&app, &format!("160EC-PRIOR-GW{i}"), *r, 900 + i as u64).await);
    }
    for id in &ids {
        app.wait_for_fit(id).await;
    }
    let (s, r) = relearn(&app, json!({})).await;
    assert_eq!(s, StatusCode::CREATED, "{r}");
    assert_eq!(r["prior"]["version"], 1, "{r}");
    // Both gauge records and the pooled lift: every fit under an older prior, once each.
    assert_eq!(r["queued"], 3, "{r}");
    let m5 = f(&param(&r["prior"], "J5", "dry")["mean_ratio"]);
    assert!((m5 - 1.4).abs() < 0.05, "J5 dry prior mean {m5}");

    // The gauge record refitted under version 1: J5 at the fleet's centre, not Table 4.
    let g1 = fit_under_prior(&app, "prior-gauge-1", 1).await;
    assert_eq!(g1["fit"]["prior"]["source"], "learned", "{g1}");
    let j5 = dry_of(&g1, "J5");
    assert_eq!(j5["identifiable"], false, "{g1}");
    assert!(
        (f(&j5["value"]) / d0 - m5).abs() < 1e-9,
        "J5 dry {j5} (prior mean {m5})"
    );
    let stored = app
        .store
        .get_fit("prior-gauge-1")
        .await
        .expect("get")
        .expect("fit");
    assert!(
        stored.model_version.ends_with("; fleet prior v1"),
        "{}",
        stored.model_version
    );
    // The lift's pool, fitted again under version 1, is its current fit again and says so.
    let p1 = fit_under_prior_where(&app, "prior-pool-lift", 1, pooled).await;
    assert_eq!(
        p1["pooled"]["trace_ids"],
        json!(["prior-pool-lift", "prior-pool-gauge"]),
        "{p1}"
    );
    let stored = app
        .store
        .get_fit("prior-pool-lift")
        .await
        .expect("get")
        .expect("fit");
    assert_eq!(
        stored.model_version,
        pantowatch::pooled::pooled_version_under(2, Some(1)),
        "{p1}"
    );
    fit_under_prior(&app, "prior-pool-gauge", 1).await;
    // Nothing newer: nothing queued.
    let (s, r) = relearn(&app, json!({})).await;
    assert_eq!(s, StatusCode::OK, "{r}");
    assert_eq!(r["queued"], 0, "{r}");
    app.stop().await;
}

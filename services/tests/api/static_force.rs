//! The predicted static contact force over HTTP (issue 20): a pantograph's characteristic from
//! its current parameters, and a band outside the type's limits as a finding with an alert.

use reqwest::StatusCode;
use serde_json::Value;

use crate::harness::*;

async fn upload_j3_pendulum(app: &TestApp, serial: &str, trace_id: &str, dry: Option<f64>) {
    let defaults = pantowatch::cli::simulate::docs::simulate_defaults().expect("defaults");
    let doc = pantowatch::cli::simulate::simulate_doc(&pantowatch::cli::simulate::SimulateArgs {
        kind: "pendulum".into(),
        joint: "J3".into(),
        dry,
        seed: 5,
        vehicle: format!("V-{serial}"),
        serial: serial.into(),
        trace_id: Some(trace_id.into()),
        recorded_at: "2026-03-02T07:00:00Z".into(),
        ..defaults
    })
    .expect("pendulum");
    let r = app
        .upload_json(&serde_json::to_vec(&doc.to_value()).unwrap())
        .await;
    assert_eq!(r.status(), 202, "{}", r.text().await.unwrap_or_default());
    app.wait_for_fit(trace_id).await;
}

fn nums(v: &Value, k: &str) -> Vec<f64> {
    v[k].as_array()
        .unwrap_or_else(|| panic!("{k}: {v}"))
        .iter()
        .map(|x| x.as_f64().expect("number"))
        .collect()
}

fn static_force_alerts(alerts: &Value, serial: &str) -> usize {
    alerts
        .as_array()
        .or_else(|| alerts["alerts"].as_array())
        .expect("alerts")
        .iter()
        .filter(|a| {
            a["serial"] == serial && a["joint"] == pantowatch::static_force::STATIC_FORCE_ALERT
        })
        .count()
}

pub async fn static_force_is_predicted_and_judged_against_the_limits(b: Backend) {
    let app = spawn_app(b).await;
    // Baseline J3 (Table 4 μ): a characteristic with J3 from its pendulum fit, no finding.
    upload_j3_pendulum(&app, "160EC-SF-1", "sf-baseline", None).await;
    let (s, v) = app
        .get_json("/v1/pantographs/160EC-SF-1/static-force")
        .await;
    assert_eq!(s, StatusCode::OK, "{v}");
    let h = nums(&v, "heights_m");
    assert!(h.len() >= 5 && h.windows(2).all(|w| w[1] > w[0]), "{v}");
    let (r, rl, rh) = (
        nums(&v, "raise_n"),
        nums(&v, "raise_lo_n"),
        nums(&v, "raise_hi_n"),
    );
    let (l, ll, lh) = (
        nums(&v, "lower_n"),
        nums(&v, "lower_lo_n"),
        nums(&v, "lower_hi_n"),
    );
    let f0 = nums(&v, "frictionless_n");
    for i in 0..h.len() {
        assert!(
            rl[i] <= r[i] && r[i] <= rh[i] && ll[i] <= l[i] && l[i] <= lh[i],
            "{v}"
        );
        assert!(r[i] < f0[i] && f0[i] < l[i], "{v}");
        // Tens of newtons on the strip, a gap of tens of newtons (Table 4 friction).
        assert!((50.0..150.0).contains(&f0[i]), "{v}");
        assert!((10.0..60.0).contains(&(l[i] - r[i])), "{v}");
    }
    assert_eq!(nums(&v["limits"], "nominal_n").len(), h.len(), "{v}");
    let j3 = v["parameters"]
        .as_array()
        .expect("parameters")
        .iter()
        .find(|p| p["joint"] == "J3")
        .cloned()
        .expect("J3");
    assert_eq!(j3["source"], "fit", "{j3}");
    assert_eq!(j3["trace_id"], "sf-baseline", "{j3}");
    assert_eq!(v["findings"], serde_json::json!([]), "{v}");
    // J3's dry friction ×3: the gap widens past the limits, a finding and a `static force` alert.
    upload_j3_pendulum(&app, "160EC-SF-3", "sf-worn", Some(0.6)).await;
    let (s, w) = app
        .get_json("/v1/pantographs/160EC-SF-3/static-force")
        .await;
    assert_eq!(s, StatusCode::OK, "{w}");
    let gap = |x: &Value| nums(x, "lower_n")[0] - nums(x, "raise_n")[0];
    assert!(gap(&w) > gap(&v) + 30.0, "{} vs {}", gap(&w), gap(&v));
    assert!(
        !w["findings"].as_array().expect("findings").is_empty(),
        "{w}"
    );
    // The worker raises alerts after writing the fit: wait for it.
    let t0 = std::time::Instant::now();
    let alerts = loop {
        let (s, alerts) = app.get_json("/v1/alerts?state=live").await;
        assert_eq!(s, 200, "{alerts}");
        if static_force_alerts(&alerts, "160EC-SF-3") > 0 || t0.elapsed().as_secs() > 30 {
            break alerts;
        }
        tokio::time::sleep(std::time::Duration::from_millis(100)).await;
    };
    assert_eq!(static_force_alerts(&alerts, "160EC-SF-3"), 1, "{alerts}");
    assert_eq!(static_force_alerts(&alerts, "160EC-SF-1"), 0, "{alerts}");
    // The pantograph page plots it: raise and lower with their bands and the limit lines.
    let html = app.web_page("/pantographs/160EC-SF-3").await;
    let section = html
        .split("id=\"static-force\"")
        .nth(1)
        .expect("static force section");
    assert!(
        section.contains("<svg") && section.contains("<polygon"),
        "{section}"
    );
    assert!(section.contains("leaves the limits"), "{section}");
    // No such pantograph: 404.
    let (s, _) = app.get_json("/v1/pantographs/NOPE-1/static-force").await;
    assert_eq!(s, StatusCode::NOT_FOUND);
    app.stop().await;
}

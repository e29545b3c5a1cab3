//! The bad-input corpus (`tests/corpus/`) over HTTP: every upload answered 4xx in problem form
//! naming the manifest's field, never a 5xx, and nothing stored.

use std::path::PathBuf;

use reqwest::{Method, StatusCode};
use serde_json::Value;

use crate::harness::*;

/// Every corpus upload is refused in problem form naming its field; around each one the rows an
/// upload writes are unchanged (issue 18, H.1: checked per case, so one case that stored
/// something and a later one that removed it cannot cancel out), and over the whole corpus not
/// one answer is a 5xx.
pub async fn corpus_uploads_are_refused_and_store_nothing(b: Backend) {
    let app = spawn_app(b).await;
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../tests/corpus");
    let manifest = std::fs::read_to_string(dir.join("MANIFEST.tsv")).expect("manifest");
    let before = app.counts().await;
    let mut failures = Vec::new();
    let mut server_errors = Vec::new();
    let mut n = 0;
    for line in manifest
        .lines()
        .filter(|l| !l.starts_with('#') && !l.is_empty())
    {
        let cols: Vec<&str> = line.split('\t').collect();
        let (file, ct, expected) = (cols[0], cols[1], cols[2]);
        let body = std::fs::read(dir.join(file)).expect("corpus file");
        n += 1;
        let stored = app.stored().await;
        let r = app
            .req(Method::POST, "/v1/traces", Some(&app.keys.writer))
            .header("content-type", ct)
            .body(body)
            .send()
            .await
            .expect("POST");
        let status = r.status();
        if status.is_server_error() {
            server_errors.push(format!("{file}: {status}"));
        }
        let media = r
            .headers()
            .get("content-type")
            .and_then(|v| v.to_str().ok())
            .unwrap_or("")
            .to_owned();
        let v: Value = r.json().await.unwrap_or(Value::Null);
        let field = v["field"].as_str().unwrap_or("");
        let field_ok = match expected.strip_suffix('*') {
            Some("") => !field.is_empty(),
            Some(prefix) => field.starts_with(prefix),
            None => field == expected,
        };
        if !status.is_client_error() || !media.starts_with("application/problem+json") || !field_ok
        {
            failures.push(format!(
                "{file}: {status} {media} field `{field}` (expected `{expected}`): {v}"
            ));
        }
        let after = app.stored().await;
        if after != stored {
            failures.push(format!("{file}: stored {stored:?} → {after:?}"));
        }
    }
    assert!(n >= 99, "{n} corpus cases");
    assert!(server_errors.is_empty(), "5xx answers: {server_errors:#?}");
    assert!(failures.is_empty(), "{failures:#?}");
    assert_eq!(app.counts().await, before, "nothing stored");
    app.stop().await;
}

/// Issue 18, point 2: a stored trace can never make its vehicle answer 500. Dates at the very
/// edges of the stored years (0001-01-01 and 9999-12-31 in UTC) are accepted and stored; the
/// vehicle, the fleet and further uploads keep answering; one past the edge once its offset is
/// applied is refused naming `recorded_at`, and stores nothing.
pub async fn edge_dates_never_break_their_vehicle(b: Backend) {
    let app = spawn_app(b).await;
    let base: Value = serde_json::from_slice(&example("J1_baseline.json")).expect("example");
    let upload = |id: &str, at: &str| {
        let mut d = base.clone();
        d["trace_id"] = id.into();
        d["vehicle_id"] = "EN57-EDGE".into();
        d["recorded_at"] = at.into();
        serde_json::to_vec(&d).expect("json")
    };
    for (id, at) in [
        ("edge-last", "9999-12-31T23:59:59Z"),
        ("edge-first", "0001-01-01T00:00:00Z"),
        ("edge-west", "9999-12-31T00:00:00-23:59"),
    ] {
        let r = app.upload_json(&upload(id, at)).await;
        assert_eq!(
            r.status(),
            202,
            "{at}: {}",
            r.text().await.unwrap_or_default()
        );
        // Fitted, health and alerts updated: every read below sees the stored dates.
        app.wait_for_fit(id).await;
    }
    let before = app.counts().await;
    for at in ["9999-12-31T23:59:59-23:59", "0001-01-01T00:30:00+01:00"] {
        let r = app.upload_json(&upload("edge-over", at)).await;
        assert_problem(r, StatusCode::UNPROCESSABLE_ENTITY, Some("recorded_at"), at).await;
    }
    assert_eq!(app.counts().await, before, "nothing stored");
    for path in ["/v1/vehicles/EN57-EDGE", "/v1/vehicles", "/v1/fleet/health"] {
        let (s, v) = app.get_json(path).await;
        assert_eq!(s, 200, "{path}: {v}");
    }
    let r = app
        .upload_json(&upload("edge-after", "2026-03-02T07:15:00Z"))
        .await;
    assert_eq!(r.status(), 202);
    let (s, v) = app.get_json("/v1/vehicles/EN57-EDGE").await;
    assert_eq!(s, 200, "{v}");
    app.stop().await;
}

/// Issue 18, point 3: every refusal names what to change (`field`, or `parameter` for the
/// address) in problem form — 403, 404, 405, 409, 413, 414, 415 included; gzip bodies are read;
/// a repeated key is refused naming it; ids are NFC and hold no invisible characters; a CSV
/// with `;` separators and decimal commas is the same trace. Around every refused request the
/// rows an upload writes are unchanged, and not one answer of the whole test is a 5xx (H.1).
pub async fn hostile_requests_answer_problems_naming_their_field(b: Backend) {
    use std::io::Write as _;
    let app = spawn_app(b).await;
    let base = example("J1_baseline.json");
    // No pooled connections: a refusal answered before the body is read closes its connection,
    // which a pooled client would reuse for the next request.
    let client = reqwest::Client::builder()
        .pool_max_idle_per_host(0)
        .build()
        .unwrap();
    // Every answer of the test, for the check that no hostile request got a 5xx.
    let answered = std::sync::Mutex::new(Vec::<(String, StatusCode)>::new());
    let note = |what: &str, r: reqwest::Response| {
        answered.lock().unwrap().push((what.to_owned(), r.status()));
        r
    };
    let send = |method: Method, path: &str, key: &str| {
        client.request(method, app.url(path)).bearer_auth(key)
    };
    // A refused request: sent, noted, and the rows an upload writes the same after it.
    let refused = |what: &'static str, req: reqwest::RequestBuilder| {
        let app = &app;
        async move {
            let before = app.stored().await;
            let r = note(what, req.send().await.expect(what));
            assert!(!r.status().is_success(), "{what}: {}", r.status());
            assert_eq!(
                app.stored().await,
                before,
                "{what}: a refusal stored something"
            );
            r
        }
    };
    // An accepted upload: 202.
    let accepted = |what: &'static str, req: reqwest::RequestBuilder| async move {
        let r = note(what, req.send().await.expect(what));
        let status = r.status();
        assert_eq!(
            status,
            202,
            "{what}: {}",
            r.text().await.unwrap_or_default()
        );
    };
    let upload = |body: Vec<u8>| {
        send(Method::POST, "/v1/traces", &app.keys.writer)
            .header("content-type", "application/json")
            .body(body)
    };
    let check = |v: &Value, what: &str| {
        assert!(
            v["field"].is_string() || v["parameter"].is_string(),
            "{what}: no field or parameter: {v}"
        );
    };
    let problem = |r: reqwest::Response, status: u16, what: &'static str| async move {
        assert_eq!(r.status().as_u16(), status, "{what}");
        let ct = r
            .headers()
            .get("content-type")
            .and_then(|v| v.to_str().ok())
            .unwrap_or("")
            .to_owned();
        assert!(ct.starts_with("application/problem+json"), "{what}: {ct}");
        r.json::<Value>().await.expect("problem body")
    };
    // 404 (unknown trace, unknown route), 403 (reader uploads), 405.
    let get = |path: &str| send(Method::GET, path, &app.keys.reader);
    // Security headers on API answers and pages alike.
    for path in ["/v1/traces/nope", "/", "/healthz"] {
        let r = note(path, get(path).send().await.unwrap());
        let h = |n: &str| {
            r.headers()
                .get(n)
                .and_then(|v| v.to_str().ok())
                .unwrap_or("")
                .to_owned()
        };
        assert!(
            h("content-security-policy").contains("frame-ancestors 'none'"),
            "{path}"
        );
        assert_eq!(h("x-content-type-options"), "nosniff", "{path}");
    }
    let v = problem(refused("404", get("/v1/traces/nope")).await, 404, "404").await;
    assert_eq!(v["parameter"], "path", "{v}");
    let v = problem(refused("route", get("/v1/nowhere")).await, 404, "route").await;
    check(&v, "route");
    let r = refused(
        "403",
        send(Method::POST, "/v1/traces", &app.keys.reader)
            .header("content-type", "application/json")
            .body(base.clone()),
    )
    .await;
    let v = problem(r, 403, "403").await;
    assert_eq!(v["field"], "Authorization", "{v}");
    let r = refused(
        "405",
        send(Method::PUT, "/v1/fleet/health", &app.keys.reader),
    )
    .await;
    let v = problem(r, 405, "405").await;
    check(&v, "405");
    // 409: the same trace id with other content.
    accepted("base", upload(base.clone())).await;
    let mut other: Value = serde_json::from_slice(&base).unwrap();
    other["vehicle_id"] = "EN57-OTHER".into();
    let r = refused("409", upload(serde_json::to_vec(&other).unwrap())).await;
    let v = problem(r, 409, "409").await;
    assert_eq!(v["field"], "trace_id", "{v}");
    // 414 in problem form.
    let long = format!("/v1/traces/{}", "a".repeat(9000));
    let v = problem(refused("414", get(&long)).await, 414, "414").await;
    check(&v, "414");
    // 413 (over the body limit) in problem form, also when it only grows that large inflated.
    let huge = vec![b' '; (BODY_LIMIT_MIB as usize) * 1024 * 1024 + 1];
    let v = problem(refused("413", upload(huge.clone())).await, 413, "413").await;
    assert_eq!(v["field"], "body", "{v}");
    let gz = |bytes: &[u8]| {
        let mut e = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::default());
        e.write_all(bytes).unwrap();
        e.finish().unwrap()
    };
    let r = refused(
        "413 inflated",
        upload(gz(&huge)).header("content-encoding", "gzip"),
    )
    .await;
    assert_eq!(r.status(), 413, "inflated past the limit");
    // gzip read; another encoding 415.
    let mut zipped: Value = serde_json::from_slice(&base).unwrap();
    zipped["trace_id"] = "gzipped-upload".into();
    accepted(
        "gzip",
        upload(gz(&serde_json::to_vec(&zipped).unwrap())).header("content-encoding", "gzip"),
    )
    .await;
    let r = refused("br", upload(base.clone()).header("content-encoding", "br")).await;
    let v = problem(r, 415, "br").await;
    check(&v, "415");
    for id in ["example-J1_baseline", "gzipped-upload"] {
        app.wait_for_fit(id).await;
    }
    let before = app.counts().await;
    // A repeated key: 422 naming it.
    let text = String::from_utf8(base.clone()).unwrap().replacen(
        "\"vehicle_id\":",
        "\"vehicle_id\": \"EN57-DUP\", \"vehicle_id\":",
        1,
    );
    assert_ne!(
        text.as_bytes(),
        &base[..],
        "the example has a vehicle_id key"
    );
    let v = problem(refused("dup", upload(text.into_bytes())).await, 422, "dup").await;
    assert_eq!(v["field"], "vehicle_id", "{v}");
    // Ids: `..` alone and invisible characters refused.
    for (key, bad) in [
        ("trace_id", ".."),
        ("vehicle_id", "EN57\u{200B}1021"),
        ("vehicle_id", "EN57\u{202E}1021"),
    ] {
        let mut d: Value = serde_json::from_slice(&base).unwrap();
        d[key] = bad.into();
        let r = refused("id", upload(serde_json::to_vec(&d).unwrap())).await;
        let v = problem(r, 422, "id").await;
        assert_eq!(v["field"], key, "{bad:?}: {v}");
    }
    assert_eq!(app.counts().await, before, "nothing stored");
    // NFC: two spellings of one vehicle are one vehicle.
    for (id, vehicle) in [("nfc-1", "Z\u{00FC}rich-1"), ("nfc-2", "Zu\u{0308}rich-1")] {
        let mut d: Value = serde_json::from_slice(&base).unwrap();
        d["trace_id"] = id.into();
        d["vehicle_id"] = vehicle.into();
        accepted("nfc", upload(serde_json::to_vec(&d).unwrap())).await;
    }
    let (s, v) = app.get_json("/v1/vehicles").await;
    assert_eq!(s, 200);
    let named: Vec<&str> = v
        .as_array()
        .or_else(|| v["vehicles"].as_array())
        .expect("vehicle list")
        .iter()
        .filter_map(|x| x["id"].as_str().or_else(|| x["vehicle_id"].as_str()))
        .filter(|id| id.contains("rich-1"))
        .collect();
    assert_eq!(named, ["Z\u{00FC}rich-1"], "{v}");
    // Pages answer refusals as pages in the site's style, not problem JSON (issue 18).
    let html_of = |r: reqwest::Response, status: u16| async move {
        assert_eq!(r.status().as_u16(), status);
        let ct = r
            .headers()
            .get("content-type")
            .and_then(|v| v.to_str().ok())
            .unwrap_or("")
            .to_owned();
        assert!(ct.starts_with("text/html"), "{status}: {ct}");
        r.text().await.expect("html")
    };
    let r = refused(
        "login",
        client
            .post(app.url("/login"))
            .header("content-type", "application/x-www-form-urlencoded")
            .body("key=pw_not-a-key"),
    )
    .await;
    let html = html_of(r, 401).await;
    assert!(
        html.contains("Unknown or revoked API key") && html.contains("<form"),
        "{html}"
    );
    let r = refused(
        "page 404",
        client
            .get(app.url("/nowhere"))
            .header("accept", "text/html"),
    )
    .await;
    let html = html_of(r, 404).await;
    assert!(html.contains("Back to the fleet"), "{html}");
    // A trace with no pantograph serial says so in words on its page (not "on pantograph —").
    let t: Vec<f64> = (0..200).map(|i| f64::from(i) * 0.004).collect();
    let a: Vec<f64> = t
        .iter()
        .map(|t| 30.0 * (-0.3 * t).exp() * (2.0 * t).cos())
        .collect();
    let doc = serde_json::json!({"format": "pantograph-trace/1", "trace_id": "no-serial",
        "vehicle_id": "Depot's 7", "pantograph": {"model": "160EC"},
        "recorded_at": "2026-03-02T07:15:00Z", "test": {"kind": "pendulum", "joint": "J1", "rig": {}},
        "channels": {"t_s": t, "alpha_deg": a}});
    let r = app.upload_json(&serde_json::to_vec(&doc).unwrap()).await;
    assert_eq!(r.status(), 202);
    let html = app.web_page("/traces/no-serial").await;
    assert!(
        html.contains(
            "pendulum test of joint J1 on vehicle Depot's 7 (no pantograph serial recorded), recorded 2026-03-02"
        ) && !html.contains("pantograph —"),
        "{html}"
    );
    let r = refused(
        "api 404 for a browser",
        client
            .get(app.url("/v1/nowhere"))
            .header("accept", "text/html"),
    )
    .await;
    assert_eq!(r.status(), 404);
    assert!(
        r.headers()["content-type"]
            .to_str()
            .unwrap()
            .starts_with("application/problem+json")
    );
    // European CSV: `;` and decimal commas.
    let csv = "# format: pantograph-trace/1\n# trace_id: eu-csv\n# vehicle_id: EN57-1021\n\
        # pantograph.model: 160EC\n# pantograph.serial: 160EC-0042\n\
        # recorded_at: 2026-03-02T07:15:00Z\n# test.kind: pendulum\n# test.joint: J1\n\
        t_s;alpha_deg\n0;74,2\n0,002;74,19\n0,004;74,17\n";
    accepted(
        "eu csv",
        send(Method::POST, "/v1/traces", &app.keys.writer)
            .header("content-type", "text/csv")
            .body(csv),
    )
    .await;
    let (s, v) = app.get_json("/v1/traces/eu-csv/samples").await;
    assert_eq!(s, 200, "{v}");
    assert_eq!(
        v["channels"]["alpha_deg"],
        serde_json::json!([74.2, 74.19, 74.17]),
        "{v}"
    );
    // H.1: not one answer of this test was a 5xx.
    let answered = answered.into_inner().unwrap();
    assert!(answered.len() >= 20, "{} answers noted", answered.len());
    let server_errors: Vec<_> = answered
        .iter()
        .filter(|(_, s)| s.is_server_error())
        .collect();
    assert!(server_errors.is_empty(), "5xx answers: {server_errors:?}");
    app.stop().await;
}

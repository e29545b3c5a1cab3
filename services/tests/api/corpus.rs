//! The bad-input corpus (`tests/corpus/`) over HTTP: every upload answered 4xx in problem form
//! naming the manifest's field, never a 5xx, and nothing stored.

use std::path::PathBuf;

use reqwest::Method;
use serde_json::Value;

use crate::harness::*;

pub async fn corpus_uploads_are_refused_and_store_nothing(b: Backend) {
    let app = spawn_app(b).await;
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../tests/corpus");
    let manifest = std::fs::read_to_string(dir.join("MANIFEST.tsv")).expect("manifest");
    let before = app.counts().await;
    let mut failures = Vec::new();
    let mut n = 0;
    for line in manifest
        .lines()
        .filter(|l| !l.starts_with('#') && !l.is_empty())
    {
        let cols: Vec<&str> = line.split('\t').collect();
        let (file, ct, expected) = (cols[0], cols[1], cols[2]);
        let body = std::fs::read(dir.join(file)).expect("corpus file");
        n += 1;
        let r = app
            .req(Method::POST, "/v1/traces", Some(&app.keys.writer))
            .header("content-type", ct)
            .body(body)
            .send()
            .await
            .expect("POST");
        let status = r.status();
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
    }
    assert!(n >= 60, "{n} corpus cases");
    assert!(failures.is_empty(), "{failures:#?}");
    assert_eq!(app.counts().await, before, "nothing stored");
    app.stop().await;
}

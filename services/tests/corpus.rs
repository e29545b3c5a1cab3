//! The bad-input corpus (`tests/corpus/`: malformed, hostile or physically absurd uploads,
//! written by `tests/corpus/generate.py`): every one is refused with an error naming the field
//! its manifest says, by the same parser the upload route uses — never accepted, never a panic.
//! Plus a 10⁷-sample channel, made here rather than stored.

use std::path::PathBuf;

use pantowatch::ingest::{BodyFormat, IngestError, parse_body_blocking};

fn corpus() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../tests/corpus")
}

fn refusal_field(format: BodyFormat, body: &[u8]) -> Result<String, String> {
    match std::panic::catch_unwind(|| parse_body_blocking(format, body)) {
        Err(_) => Err("panicked".into()),
        Ok(Ok(_)) => Err("accepted".into()),
        Ok(Err(IngestError::Malformed(e) | IngestError::Invalid(e))) => Ok(e.field),
        Ok(Err(other)) => Err(format!("refused for another reason: {other}")),
    }
}

#[test]
fn every_corpus_upload_is_refused_naming_its_field() {
    let manifest = std::fs::read_to_string(corpus().join("MANIFEST.tsv")).unwrap();
    let mut failures = Vec::new();
    let mut n = 0;
    for line in manifest
        .lines()
        .filter(|l| !l.starts_with('#') && !l.is_empty())
    {
        let cols: Vec<&str> = line.split('\t').collect();
        let (file, ct, expected) = (cols[0], cols[1], cols[2]);
        let body = std::fs::read(corpus().join(file)).unwrap();
        let format = BodyFormat::from_content_type(ct).unwrap();
        n += 1;
        match refusal_field(format, &body) {
            Err(why) => failures.push(format!("{file}: {why}")),
            Ok(field) => {
                let ok = match expected.strip_suffix('*') {
                    Some("") => !field.is_empty(),
                    Some(prefix) => field.starts_with(prefix),
                    None => field == expected,
                };
                if !ok {
                    failures.push(format!("{file}: named `{field}`, expected `{expected}`"));
                }
            }
        }
    }
    assert!(n >= 60, "the corpus has {n} cases");
    assert!(failures.is_empty(), "{failures:#?}");
}

#[test]
fn ten_million_samples_are_refused_by_the_limit() {
    let n = 10_000_000;
    let mut body = String::with_capacity(n * 4);
    body.push_str(r#"{"format":"pantograph-trace/1","vehicle_id":"V","pantograph":{"model":"160EC"},"recorded_at":"2026-01-01T00:00:00Z","test":{"kind":"pendulum","joint":"J1"},"channels":{"t_s":["#);
    for i in 0..n {
        if i > 0 {
            body.push(',');
        }
        body.push('1');
    }
    body.push_str(r#"],"alpha_deg":[1,2]}}"#);
    let field = refusal_field(BodyFormat::Json, body.as_bytes()).unwrap();
    assert_eq!(field, "channels.t_s");
}

//! Uploads: the one path from a request body (contract JSON or logger CSV) to a stored trace and
//! its queued fit. `POST /v1/traces` and `pantowatch demo` both go through [`Intake::upload`].

use std::sync::Arc;

use bytes::Bytes;
use chrono::{DateTime, Utc};
use pantowatch_models::report::MODEL_VERSION;
use serde_json::Value;
use sha2::{Digest, Sha256};
use tokio::sync::Notify;

use crate::store::{InsertOutcome, JobState, NewTrace, Store, StoreError, TraceMeta};
use crate::trace::{JsonError, Kind, TraceDoc, TraceError};
use crate::trace_csv::{self, CsvError};

/// The media types an upload may have.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BodyFormat {
    /// `application/json`: the contract's document.
    Json,
    /// `text/csv`: the logger shape of [`crate::trace_csv`].
    Csv,
}

impl BodyFormat {
    /// The format named by a `Content-Type` value (parameters such as `charset` ignored).
    pub fn from_content_type(ct: &str) -> Option<Self> {
        let essence = ct
            .split(';')
            .next()
            .unwrap_or("")
            .trim()
            .to_ascii_lowercase();
        match essence.as_str() {
            "application/json" => Some(BodyFormat::Json),
            "text/csv" => Some(BodyFormat::Csv),
            _ => None,
        }
    }
}

/// Why an upload was refused. Nothing is stored in any of these cases.
#[derive(Debug, thiserror::Error)]
pub enum IngestError {
    /// The body is not JSON / not CSV of the documented shape.
    #[error("malformed body: {0}")]
    Malformed(TraceError),
    /// The document breaks a rule of the contract.
    #[error("invalid trace: {0}")]
    Invalid(TraceError),
    /// A trace with this id and other content is already stored.
    #[error("trace `{0}` is already stored with other content")]
    Conflict(String),
    /// The database failed.
    #[error(transparent)]
    Store(#[from] StoreError),
}

/// A document ready to store, with its content hash.
#[derive(Debug, Clone)]
pub struct Parsed {
    pub doc: TraceDoc,
    /// Lowercase hex SHA-256 of the canonical JSON of the document.
    pub sha256: String,
}

/// What an accepted upload answers: the same for a repeated identical upload.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Accepted {
    pub trace_id: String,
    /// The state of the trace's latest fit job (`queued` right after a first upload).
    pub job_state: JobState,
    /// False when the same document was already stored (nothing was written).
    pub created: bool,
}

/// Parses and validates a body off the async runtime (a 64 MiB JSON body is ~0.5 s of CPU).
pub async fn parse_body(format: BodyFormat, body: Bytes) -> Result<Parsed, IngestError> {
    tokio::task::spawn_blocking(move || parse_body_blocking(format, &body))
        .await
        .map_err(|e| IngestError::Store(StoreError::Task(e.to_string())))?
}

/// [`parse_body`] on the calling thread.
pub fn parse_body_blocking(format: BodyFormat, body: &[u8]) -> Result<Parsed, IngestError> {
    let doc = match format {
        BodyFormat::Json => TraceDoc::parse_json(body).map_err(|e| match e {
            JsonError::Malformed(e) => IngestError::Malformed(e),
            JsonError::Invalid(e) => IngestError::Invalid(e),
        })?,
        BodyFormat::Csv => trace_csv::parse(body).map_err(|e| match e {
            CsvError::Malformed(e) => IngestError::Malformed(e),
            CsvError::Invalid(e) => IngestError::Invalid(e),
        })?,
    };
    let sha256 = content_sha256(&doc);
    Ok(Parsed { doc, sha256 })
}

/// SHA-256 of the document's canonical JSON (object keys sorted at every level), so the same
/// content hashes the same whether it came as JSON or CSV, in any key order.
pub fn content_sha256(doc: &TraceDoc) -> String {
    fn canonical(v: &Value) -> Value {
        match v {
            Value::Object(m) => {
                let mut keys: Vec<&String> = m.keys().collect();
                keys.sort();
                let mut out = serde_json::Map::new();
                for k in keys {
                    out.insert(k.clone(), canonical(&m[k]));
                }
                Value::Object(out)
            }
            Value::Array(a) => Value::Array(a.iter().map(canonical).collect()),
            other => other.clone(),
        }
    }
    let text = serde_json::to_vec(&canonical(&doc.to_value())).unwrap_or_default();
    hex::encode(Sha256::digest(&text))
}

/// Stores uploads and wakes the in-process workers.
#[derive(Debug, Clone)]
pub struct Intake {
    store: Store,
    wake: Arc<Notify>,
}

impl Intake {
    pub fn new(store: Store, wake: Arc<Notify>) -> Self {
        Intake { store, wake }
    }

    /// Parses, validates and stores an upload; its fit job is queued in the same transaction.
    /// Idempotent on `trace_id`: the same content answers the same, other content is a
    /// [`IngestError::Conflict`].
    pub async fn upload(&self, format: BodyFormat, body: Bytes) -> Result<Accepted, IngestError> {
        let parsed = parse_body(format, body).await?;
        self.store_parsed(parsed).await
    }

    /// Stores an already parsed document (the second half of [`Intake::upload`]).
    pub async fn store_parsed(&self, parsed: Parsed) -> Result<Accepted, IngestError> {
        let Parsed { doc, sha256 } = parsed;
        let recorded_at = DateTime::parse_from_rfc3339(&doc.recorded_at)
            .map(|t| t.with_timezone(&Utc))
            .map_err(|e| {
                IngestError::Invalid(TraceError {
                    field: "recorded_at".into(),
                    message: format!("`{}`: {e}", doc.recorded_at),
                })
            })?;
        // Recordings of one rig (issue 36, point 5): refused, naming `test.rig_id`, before
        // anything is written, when the rig id is another test's, joint's or rig's.
        if let (Some(rig), Some(serial)) = (doc.rig_id(), doc.pantograph_serial.as_deref())
            && let Err(message) = check_same_rig(
                &self.store,
                serial,
                doc.kind.as_str(),
                doc.joint.as_deref(),
                rig,
                doc.test.get("rig"),
                doc.trace_id.as_deref(),
            )
            .await?
        {
            return Err(IngestError::Invalid(TraceError {
                field: "test.rig_id".into(),
                message,
            }));
        }
        let test_json = doc.test.to_string();
        let new = NewTrace {
            trace_id: doc.trace_id,
            vehicle_id: doc.vehicle_id,
            serial: doc.pantograph_serial,
            model: doc.pantograph_model,
            recorded_at,
            kind: doc.kind.as_str().to_owned(),
            joint: doc.joint,
            test_json,
            content_sha256: sha256,
            channels: doc.channels,
            model_version: MODEL_VERSION.to_owned(),
        };
        let outcome = self.store.insert_trace(new).await?;
        metrics::counter!("pantowatch_uploads_total", "outcome" => outcome_label(&outcome))
            .increment(1);
        match outcome {
            InsertOutcome::Created { trace_id, .. } => {
                self.wake.notify_waiters();
                Ok(Accepted {
                    trace_id,
                    job_state: JobState::Queued,
                    created: true,
                })
            }
            InsertOutcome::Existing { trace_id } => {
                let job_state = match self.store.latest_job(&trace_id).await? {
                    Some(j) => j.state,
                    None if self.store.get_fit(&trace_id).await?.is_some() => JobState::Done,
                    None => JobState::Queued,
                };
                Ok(Accepted {
                    trace_id,
                    job_state,
                    created: false,
                })
            }
            InsertOutcome::Conflict { trace_id } => Err(IngestError::Conflict(trace_id)),
        }
    }
}

fn outcome_label(o: &InsertOutcome) -> &'static str {
    match o {
        InsertOutcome::Created { .. } => "created",
        InsertOutcome::Existing { .. } => "existing",
        InsertOutcome::Conflict { .. } => "conflict",
    }
}

/// The stored trace as a document again (metadata + decoded samples), its test typed
/// ([`TraceDoc::typed`]) for fits and views: a stored trace that no longer reads is an error
/// naming the field.
pub fn stored_doc(meta: &TraceMeta, channels: Vec<(String, Vec<f64>)>) -> Result<TraceDoc, String> {
    stored_doc_as_sent(meta, channels)?
        .typed()
        .map_err(|e| format!("stored trace no longer reads: {e}"))
}

/// The stored trace as it was sent, its test not typed ([`crate::trace::TestSpec::Unchecked`]):
/// for downloads, which serve what was stored whatever today's rules say.
pub fn stored_doc_as_sent(
    meta: &TraceMeta,
    channels: Vec<(String, Vec<f64>)>,
) -> Result<TraceDoc, String> {
    let kind = Kind::parse(&meta.kind)
        .ok_or_else(|| format!("stored trace has unknown kind `{}`", meta.kind))?;
    let test: Value = serde_json::from_str(&meta.test_json)
        .map_err(|e| format!("stored test object is not JSON: {e}"))?;
    Ok(TraceDoc {
        trace_id: Some(meta.trace_id.clone()),
        vehicle_id: meta.vehicle_id.clone(),
        pantograph_model: meta.model.clone(),
        pantograph_serial: meta.serial.clone(),
        recorded_at: meta
            .recorded_at
            .to_rfc3339_opts(chrono::SecondsFormat::AutoSi, true),
        kind,
        joint: meta.joint.clone(),
        test,
        spec: crate::trace::TestSpec::Unchecked,
        channels,
    })
}

/// Most traces of one kind scanned for a rig's recordings (newest first).
pub const RIG_SCAN: i64 = 500;

/// A stored test's `rig_id` and its `rig` object (`{}` when absent): what makes recordings
/// one rig's (issue 36, point 5).
pub fn rig_of(test_json: &str) -> Option<(String, serde_json::Value)> {
    let test: serde_json::Value = serde_json::from_str(test_json).ok()?;
    let id = test.get("rig_id")?.as_str()?.to_owned();
    let rig = test
        .get("rig")
        .cloned()
        .filter(|r| !r.is_null())
        .unwrap_or_else(|| serde_json::json!({}));
    Some((id, rig))
}

/// The upload's `test.rig_id` against the pantograph's stored recordings of that rig: they
/// must be the same kind of test, of the same joint, on the same stated rig (body, pin,
/// attachments). `Err(message)` names what differs; the caller refuses the upload, naming
/// `test.rig_id`, before anything is written. (Two uploads racing with one new rig id are not
/// checked against each other: the pooled fit then refuses the pair, logged.)
pub async fn check_same_rig(
    store: &Store,
    serial: &str,
    kind: &str,
    joint: Option<&str>,
    rig_id: &str,
    rig: Option<&serde_json::Value>,
    trace_id: Option<&str>,
) -> Result<Result<(), String>, StoreError> {
    let empty = serde_json::json!({});
    let rig = rig.filter(|r| !r.is_null()).unwrap_or(&empty);
    for k in ["pendulum", "slider"] {
        for m in store.traces_of_kind(serial, k, RIG_SCAN).await? {
            if Some(m.trace_id.as_str()) == trace_id {
                continue;
            }
            let Some((id, stored_rig)) = rig_of(&m.test_json) else {
                continue;
            };
            if id != rig_id {
                continue;
            }
            let what = if m.kind != kind {
                Some("test.kind")
            } else if m.joint.as_deref() != joint {
                Some("test.joint")
            } else if &stored_rig != rig {
                Some("test.rig")
            } else {
                None
            };
            if let Some(what) = what {
                return Ok(Err(format!(
                    "`{rig_id}` is the rig of trace `{}` of pantograph {serial}, whose {what} \
                     differs: recordings of one rig share the test kind, the joint and the \
                     stated rig",
                    m.trace_id
                )));
            }
        }
    }
    Ok(Ok(()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn content_types() {
        assert_eq!(
            BodyFormat::from_content_type("application/json; charset=utf-8"),
            Some(BodyFormat::Json)
        );
        assert_eq!(
            BodyFormat::from_content_type("Text/CSV"),
            Some(BodyFormat::Csv)
        );
        assert_eq!(BodyFormat::from_content_type("text/plain"), None);
    }

    #[test]
    fn json_and_csv_of_one_document_hash_the_same() {
        let json = br#"{"test": {"rig": {}, "joint": "J1", "kind": "pendulum"}, "format": "pantograph-trace/1",
            "trace_id": "t-1", "vehicle_id": "V", "pantograph": {"serial": "S", "model": "160EC"},
            "recorded_at": "2026-03-02T07:15:00Z", "channels": {"alpha_deg": [74.2, 74.19, 74.17], "t_s": [0, 0.002, 0.004]}}"#;
        let a = parse_body_blocking(BodyFormat::Json, json).expect("json");
        let csv = trace_csv::write(&a.doc);
        let b = parse_body_blocking(BodyFormat::Csv, csv.as_bytes()).expect("csv");
        assert_eq!(a.doc, b.doc);
        assert_eq!(a.sha256, b.sha256);
        assert!(matches!(
            parse_body_blocking(BodyFormat::Json, b"{"),
            Err(IngestError::Malformed(e)) if e.field == "body"
        ));
    }

    /// Lossless storage did not change when the parser became typed (issue 39, point 3): the
    /// canonical SHA-256 of these documents, as JSON and as CSV, is the one the parser over
    /// `serde_json::Value` gave (computed with it, commit 119290c, before the change).
    #[test]
    fn the_canonical_hash_is_the_one_the_value_parser_gave() {
        let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
        for (file, format, sha256) in [
            (
                "../shared/data/examples/J1_baseline.json",
                BodyFormat::Json,
                "e7ed2490c0f43adef997a39b966443dfe17a1d5a25ce9668e11e2e096f2045f7",
            ),
            (
                "fuzz/seeds/trace_json/J5_baseline.json",
                BodyFormat::Json,
                "9f813886797292a8595ae9c37224a150b7441fc64a4a5c52f2c2f0517e68ecef",
            ),
            (
                "fuzz/seeds/trace_json/lift-example.json",
                BodyFormat::Json,
                "1c3168aed257d5a98ac462ead8dcf0ff60b53fd285adfc998df269dbc58032ea",
            ),
            (
                "fuzz/seeds/trace_csv/lift-example.csv",
                BodyFormat::Csv,
                "1c3168aed257d5a98ac462ead8dcf0ff60b53fd285adfc998df269dbc58032ea",
            ),
            (
                "fuzz/seeds/trace_csv/slider_baseline.csv",
                BodyFormat::Csv,
                "5573fb436fbec3d37af16298351c40a3e1a466332eb54c764f2e98ad206cdbef",
            ),
        ] {
            let body = std::fs::read(root.join(file)).expect(file);
            let parsed = parse_body_blocking(format, &body).expect(file);
            assert_eq!(parsed.sha256, sha256, "{file}");
        }
    }
}

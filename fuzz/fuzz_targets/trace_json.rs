//! Fuzz target: bytes → the JSON upload's parse + validate (`ingest::parse_body_blocking`, what
//! `POST /v1/traces` runs). Any panic is a crash; an accepted document must survive the round trips
//! the service relies on (stored → document again; served as CSV → uploaded again).
#![no_main]

use libfuzzer_sys::fuzz_target;
use pantowatch::ingest::{BodyFormat, content_sha256, parse_body_blocking};
use pantowatch::trace::TraceDoc;
use pantowatch::trace_csv;

fuzz_target!(|data: &[u8]| {
    let Ok(parsed) = parse_body_blocking(BodyFormat::Json, data) else {
        return;
    };
    let doc = parsed.doc;
    // The store keeps the document's fields and rebuilds it: its JSON must validate to itself.
    let again = TraceDoc::from_value(&doc.to_value()).expect("an accepted document re-validates");
    assert_eq!(again, doc, "JSON round trip changed the document");
    assert_eq!(content_sha256(&again), parsed.sha256, "hash is not stable");
    // The CSV download of an accepted trace must be accepted as an upload.
    let csv = trace_csv::write(&doc);
    if let Err(e) = trace_csv::parse(csv.as_bytes()) {
        panic!("the CSV of an accepted document is refused: {e}\n{csv}");
    }
});

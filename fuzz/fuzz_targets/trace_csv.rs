//! Fuzz target: bytes → the CSV upload's parse + validate (`ingest::parse_body_blocking` with
//! `text/csv`). Any panic is a crash; an accepted CSV written back out must read back identical.
#![no_main]

use libfuzzer_sys::fuzz_target;
use pantowatch::ingest::{BodyFormat, parse_body_blocking};
use pantowatch::trace::TraceDoc;
use pantowatch::trace_csv;

fuzz_target!(|data: &[u8]| {
    let Ok(parsed) = parse_body_blocking(BodyFormat::Csv, data) else {
        return;
    };
    let doc = parsed.doc;
    let csv = trace_csv::write(&doc);
    let again = trace_csv::parse(csv.as_bytes()).expect("written CSV parses");
    assert_eq!(again, doc, "CSV round trip changed the document");
    let json = TraceDoc::from_value(&doc.to_value()).expect("the JSON form validates");
    assert_eq!(json, doc, "CSV → JSON changed the document");
});

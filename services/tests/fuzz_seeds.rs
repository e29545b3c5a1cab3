//! The fuzzers' invariants on their committed seeds (fuzz/seeds), without libFuzzer: every seed
//! is accepted and re-validates to itself as JSON and as CSV.

use std::path::{Path, PathBuf};

use pantowatch::ingest::{BodyFormat, parse_body_blocking};
use pantowatch::trace::TraceDoc;
use pantowatch::trace_csv;

fn files(dir: &str) -> Vec<PathBuf> {
    let d = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../fuzz")
        .join(dir);
    let Ok(rd) = std::fs::read_dir(&d) else {
        return Vec::new();
    };
    let mut v: Vec<PathBuf> = rd.filter_map(|e| e.ok().map(|e| e.path())).collect();
    v.sort();
    v
}

/// What both fuzz targets assert on an accepted document.
fn round_trips(doc: &TraceDoc, what: &Path) {
    let json = TraceDoc::from_value(&doc.to_value())
        .unwrap_or_else(|e| panic!("{}: JSON form refused: {e}", what.display()));
    assert_eq!(&json, doc, "{}: JSON round trip", what.display());
    let csv = trace_csv::write(doc);
    let again = trace_csv::parse(csv.as_bytes())
        .unwrap_or_else(|e| panic!("{}: CSV form refused: {e}", what.display()));
    assert_eq!(
        (again.trace_id.as_deref(), &again.channels),
        (doc.trace_id.as_deref(), &doc.channels),
        "{}: CSV round trip",
        what.display()
    );
}

#[test]
fn seeds_are_accepted_and_round_trip() {
    for (dir, format) in [
        ("seeds/trace_json", BodyFormat::Json),
        ("seeds/trace_csv", BodyFormat::Csv),
    ] {
        let seeds = files(dir);
        assert!(seeds.len() >= 10, "{dir}: {} seeds", seeds.len());
        for p in seeds {
            let bytes = std::fs::read(&p).expect("read seed");
            let parsed = parse_body_blocking(format, &bytes)
                .unwrap_or_else(|e| panic!("{}: refused: {e}", p.display()));
            round_trips(&parsed.doc, &p);
        }
    }
}

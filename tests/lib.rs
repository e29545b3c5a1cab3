//! Helpers for the end-to-end tests: where the shared example data lives, and its truth.

use std::path::PathBuf;

/// `../shared/data/examples` beside the repository (or `$PANTOWATCH_EXAMPLES`).
pub fn examples_dir() -> PathBuf {
    if let Ok(p) = std::env::var("PANTOWATCH_EXAMPLES") {
        return p.into();
    }
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../shared/data/examples")
}

/// `../shared/data/measured`.
pub fn measured_dir() -> PathBuf {
    examples_dir().join("../measured")
}

/// The examples' `truth.json`.
pub fn truth() -> serde_json::Value {
    let p = examples_dir().join("truth.json");
    let bytes = std::fs::read(&p).unwrap_or_else(|e| {
        panic!(
            "{}: {e} — the shared example data must sit beside the repository",
            p.display()
        )
    });
    serde_json::from_slice(&bytes).expect("truth.json parses")
}

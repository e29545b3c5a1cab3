//! The `pantowatch` command line: one module per subcommand; only this layer knows about
//! terminals, progress bars and files.

pub mod demo;
pub mod design;
pub mod examples;
pub mod fit;
pub mod keys;
pub mod migrate;
pub mod pooled;
pub mod prior;
pub mod refit;
pub mod report;
pub mod serve;
pub mod simulate;
pub mod static_force;

use std::path::Path;

use anyhow::Context;

use crate::trace::TraceDoc;

/// Read and validate a trace document from a file.
pub fn read_trace(path: &Path) -> anyhow::Result<TraceDoc> {
    let bytes = std::fs::read(path).with_context(|| format!("reading {}", path.display()))?;
    TraceDoc::from_json(&bytes).map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))
}

/// Where the shared example traces are: `$PANTOWATCH_EXAMPLES`, or `../shared/data/examples`
/// from the working directory or from the repository root.
pub fn examples_dir() -> Option<std::path::PathBuf> {
    if let Ok(p) = std::env::var("PANTOWATCH_EXAMPLES") {
        return Some(p.into());
    }
    let here = Path::new("../shared/data/examples");
    if here.is_dir() {
        return Some(here.into());
    }
    let from_root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/data/examples");
    from_root.is_dir().then_some(from_root)
}

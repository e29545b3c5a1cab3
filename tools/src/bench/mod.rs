//! `pantowatch-tools bench`: `bench FILE…` times the fit of trace files on one core; `bench suite`
//! runs every measure of issue 8 (fits vs the SciPy peer, fleet re-processing, ingest, storage,
//! fleet-health query, the fleet test plan) and prints one table against the targets.

pub mod files;
pub mod fits;
pub mod fleet;
pub mod harness;
pub mod ingest;
pub mod lift;
pub mod machine;
pub mod plan;
pub mod query;
pub mod records;
pub mod scaling;
pub mod suite;
pub mod table;

pub use table::{BenchArgs, BenchCommand};

use pantowatch::config::{LogSettings, init_logging};

/// `bench FILE…` or `bench suite`. The suite logs warnings only (`RUST_LOG` still wins): its
/// in-process service would otherwise log every timed request.
pub fn run(a: BenchArgs) -> anyhow::Result<()> {
    match a.command {
        Some(BenchCommand::Suite(s)) => {
            init_logging(&LogSettings {
                filter: "warn".into(),
                ..LogSettings::default()
            });
            suite::run(s)
        }
        Some(BenchCommand::Records { dir }) => {
            let records = records::write(&dir)?;
            let truth = pantowatch::cli::examples_dir()
                .and_then(|ex| std::fs::read(ex.join("truth.json")).ok())
                .and_then(|b| serde_json::from_slice(&b).ok())
                .unwrap_or_else(|| serde_json::json!({}));
            let truth = records::truth_with(truth, &records);
            std::fs::write(dir.join("truth.json"), serde_json::to_vec_pretty(&truth)?)?;
            for r in &records {
                println!("{}", r.path.display());
            }
            Ok(())
        }
        None => {
            init_logging(&LogSettings::default());
            files::run(a)
        }
    }
}

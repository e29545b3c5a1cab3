//! `pantowatch bench`: `bench FILE…` times the fit of trace files on one core; `bench suite`
//! runs every measure of issue 8 (fits vs the SciPy peer, fleet re-processing, ingest, storage,
//! fleet-health query) and prints one table against the targets.

pub mod files;
pub mod fits;
pub mod fleet;
pub mod harness;
pub mod ingest;
pub mod lift;
pub mod machine;
pub mod query;
pub mod suite;

use std::path::PathBuf;

use crate::config::{LogSettings, init_logging};

#[derive(Debug, clap::Args)]
#[command(args_conflicts_with_subcommands = true)]
pub struct BenchArgs {
    #[command(subcommand)]
    pub command: Option<BenchCommand>,
    /// Trace documents to fit.
    pub files: Vec<PathBuf>,
    /// Fits per file; the median time is reported.
    #[arg(long, default_value_t = 5)]
    pub repeat: usize,
    /// One JSON line per file instead of a table.
    #[arg(long)]
    pub json: bool,
}

#[derive(Debug, clap::Subcommand)]
pub enum BenchCommand {
    /// Every measure of the performance targets, one table (docs/PERFORMANCE.md).
    Suite(suite::SuiteArgs),
}

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
        None => {
            init_logging(&LogSettings::default());
            files::run(a)
        }
    }
}

/// Median of a sample (the lower middle of an even count); NaN when empty.
pub(crate) fn median(v: Vec<f64>) -> f64 {
    quantile(v, 0.5)
}

/// The `q` quantile by the nearest-rank rule (`q` = 0.99: the value 99 % of the sample is at or
/// below); NaN when empty.
pub(crate) fn quantile(mut v: Vec<f64>, q: f64) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    let rank = (q * v.len() as f64).ceil() as usize;
    v[rank.clamp(1, v.len()) - 1]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nearest_rank_quantiles() {
        let v: Vec<f64> = (1..=100).map(f64::from).collect();
        assert_eq!(quantile(v.clone(), 0.99), 99.0);
        assert_eq!(quantile(v.clone(), 0.5), 50.0);
        assert_eq!(quantile(v, 1.0), 100.0);
        assert_eq!(median(vec![3.0, 1.0, 2.0]), 2.0);
        assert!(quantile(Vec::new(), 0.5).is_nan());
    }
}

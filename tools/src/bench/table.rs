//! The bench suite's vocabulary, below every measure: its arguments ([`BenchArgs`],
//! [`SuiteArgs`]), the sizes of a run, one table [`Row`], and the quantiles its figures use.
//! The measures (fits, lift, fleet, ingest, query) and the suite that runs them import this;
//! it imports none of them.

use std::path::PathBuf;

use serde::Serialize;

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
    Suite(SuiteArgs),
    /// Write the peer comparison's own records (a 30 s slider, an input-driven axis) into DIR,
    /// with `truth.json` (the examples' truth and theirs): `bench/run.sh` times them too.
    Records {
        /// Directory to write into (created).
        dir: PathBuf,
    },
}

/// A year of monthly lift tests for 1,000 pantographs.
pub const FLEET_YEAR: usize = 12_000;

/// Default administrative PostgreSQL URL; the suite creates and drops its own databases.
pub const DEFAULT_PG: &str = "postgres://postgres@127.0.0.1:5432/postgres";

#[derive(Debug, Clone, clap::Args)]
pub struct SuiteArgs {
    /// A scaled-down run of about a minute (sizes below are then the quick defaults).
    #[arg(long)]
    pub quick: bool,
    /// Fleet re-processing: fit all 12,000 lift traces instead of timing a sample and projecting.
    #[arg(long)]
    pub full: bool,
    /// Print the run as JSON (machine, settings, rows) instead of the table.
    #[arg(long)]
    pub json: bool,
    /// Also write the run as JSON to this file (the table still printed): one run gives the
    /// README's table and the per-file figures behind it.
    #[arg(long, value_name = "FILE")]
    pub json_out: Option<PathBuf>,
    /// Sections to run, comma-separated: fits, fleet, ingest (with storage), query, plan; or
    /// scaling (the fit-time-against-length rows alone, which fits includes).
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "fits,fleet,ingest,query,plan"
    )]
    pub only: Vec<Section>,
    /// Fits per file for the per-kind timing (median reported); default 3, quick 1.
    #[arg(long)]
    pub repeat: Option<usize>,
    /// Lift fits per input-noise level (clean, realistic, 2×) for the lift rows; default 12,
    /// quick 3.
    #[arg(long)]
    pub lift_seeds: Option<usize>,
    /// Lift traces fitted for the fleet re-processing (projected to 12,000); default 200, quick 8.
    #[arg(long)]
    pub fleet_traces: Option<usize>,
    /// Trace documents uploaded for the ingest measure; default 400, quick 40.
    #[arg(long)]
    pub ingest_traces: Option<usize>,
    /// Concurrent uploads for the ingest measure.
    #[arg(long, default_value_t = 8)]
    pub concurrency: usize,
    /// Pantographs in the fleet-health store (12 fits each); default 1000, quick 100.
    #[arg(long)]
    pub pantographs: Option<usize>,
    /// Fleet-health queries timed per backend and path; default 500, quick 100.
    #[arg(long)]
    pub queries: Option<usize>,
    /// Administrative PostgreSQL URL (`$PANTOWATCH_BENCH_PG_URL`); fresh databases are created
    /// on it and dropped afterwards.
    #[arg(long, env = "PANTOWATCH_BENCH_PG_URL", default_value = DEFAULT_PG)]
    pub pg_url: String,
    /// The SciPy peer script (default: bench/scipy_peer.py of the source tree).
    #[arg(long)]
    pub peer: Option<PathBuf>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Section {
    Fits,
    Fleet,
    Ingest,
    Query,
    /// Fit time against record length per test kind alone (`bench::scaling`; `fits` runs it
    /// too): issue 38's rows in one short run.
    Scaling,
    /// The fleet test plan (issue 37).
    Plan,
}

/// The sizes of a run after `--quick` and the explicit flags.
#[derive(Debug, Clone, Serialize)]
pub struct Sizes {
    pub repeat: usize,
    pub lift_seeds: usize,
    pub fleet_traces: usize,
    pub ingest_traces: usize,
    pub concurrency: usize,
    pub pantographs: usize,
    pub queries: usize,
}

impl SuiteArgs {
    pub fn sizes(&self) -> Sizes {
        let q = self.quick;
        Sizes {
            repeat: self.repeat.unwrap_or(if q { 1 } else { 3 }).max(1),
            lift_seeds: self.lift_seeds.unwrap_or(if q { 3 } else { 12 }).max(1),
            fleet_traces: if self.full {
                FLEET_YEAR
            } else {
                self.fleet_traces.unwrap_or(if q { 8 } else { 200 }).max(1)
            },
            ingest_traces: self
                .ingest_traces
                .unwrap_or(if q { 40 } else { 400 })
                .max(1),
            concurrency: self.concurrency.max(1),
            pantographs: self
                .pantographs
                .unwrap_or(if q { 100 } else { 1000 })
                .max(1),
            queries: self.queries.unwrap_or(if q { 100 } else { 500 }).max(1),
        }
    }
}

/// One measure of the table.
#[derive(Debug, Clone, Serialize)]
pub struct Row {
    pub measure: String,
    /// What was measured, human-readable.
    pub measured: String,
    pub target: String,
    /// `None`: not judged (no target, or the comparison was unavailable).
    pub pass: Option<bool>,
    /// The figure judged against the target, in `unit`.
    pub value: Option<f64>,
    pub unit: String,
    /// Everything behind the figure (per file, per backend, …).
    pub detail: serde_json::Value,
}

impl Row {
    /// A row that could not be measured, saying why.
    pub fn failed(measure: &str, target: &str, why: &str) -> Row {
        Row {
            measure: measure.into(),
            measured: format!("not measured: {why}"),
            target: target.into(),
            pass: None,
            value: None,
            unit: String::new(),
            detail: serde_json::Value::Null,
        }
    }
}

/// Median of a sample (the lower middle of an even count); NaN when empty.
pub fn median(v: Vec<f64>) -> f64 {
    quantile(v, 0.5)
}

/// The `q` quantile by the nearest-rank rule (`q` = 0.99: the value 99 % of the sample is at or
/// below); NaN when empty.
pub fn quantile(mut v: Vec<f64>, q: f64) -> f64 {
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

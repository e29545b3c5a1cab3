//! `pantowatch bench suite`: runs the sections (fits, fleet, ingest + storage, query) at the
//! issue's sizes (or `--quick`), then prints one table — measured / target / pass — under the
//! machine line, or the same as JSON (`--json`) for docs/PERFORMANCE.md and the README.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::Context;
use serde::Serialize;

use super::machine::Machine;

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
    /// Sections to run, comma-separated: fits, fleet, ingest (with storage), query.
    #[arg(long, value_delimiter = ',', default_value = "fits,fleet,ingest,query")]
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
                super::fleet::FLEET_YEAR
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

#[derive(Debug, Serialize)]
struct Report<'a> {
    machine: &'a Machine,
    command: String,
    sizes: &'a Sizes,
    seconds: f64,
    rows: &'a [Row],
}

pub fn run(a: SuiteArgs) -> anyhow::Result<()> {
    let machine = Machine::detect();
    let sizes = a.sizes();
    let t0 = Instant::now();
    if !a.json {
        eprintln!("{}", machine.line());
    }
    let mut rows = Vec::new();
    for s in [
        Section::Fits,
        Section::Fleet,
        Section::Ingest,
        Section::Query,
    ] {
        if !a.only.contains(&s) {
            continue;
        }
        eprintln!("== {s:?}");
        let r = match s {
            Section::Fits => super::fits::run(&a, &sizes),
            Section::Fleet => super::fleet::run(&sizes),
            Section::Ingest => super::ingest::run(&a, &sizes),
            Section::Query => super::query::run(&a, &sizes),
        };
        rows.extend(r);
    }
    let command = std::env::args().collect::<Vec<_>>().join(" ");
    let report = Report {
        machine: &machine,
        command: command.clone(),
        sizes: &sizes,
        seconds: t0.elapsed().as_secs_f64(),
        rows: &rows,
    };
    let json = serde_json::to_string_pretty(&report)?;
    if let Some(path) = &a.json_out {
        std::fs::write(path, format!("{json}\n"))
            .with_context(|| format!("writing {}", path.display()))?;
    }
    if a.json {
        println!("{json}");
    } else {
        println!("{}", machine.line());
        println!("Command: {command} ({:.0} s)\n", t0.elapsed().as_secs_f64());
        print!("{}", table(&rows));
    }
    Ok(())
}

/// The rows as a Markdown table (readable in a terminal, pasteable into the README).
pub fn table(rows: &[Row]) -> String {
    let mut out = String::from("| measure | measured | target | pass |\n|---|---|---|---|\n");
    for r in rows {
        let pass = match r.pass {
            Some(true) => "yes",
            Some(false) => "**no**",
            None => "–",
        };
        out.push_str(&format!(
            "| {} | {} | {} | {pass} |\n",
            r.measure, r.measured, r.target
        ));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Parser)]
    struct Cli {
        #[command(flatten)]
        a: SuiteArgs,
    }

    #[test]
    fn quick_scales_down_and_full_runs_the_year() {
        let q = Cli::parse_from(["x", "--quick"]).a.sizes();
        let d = Cli::parse_from(["x"]).a.sizes();
        assert!(q.fleet_traces < d.fleet_traces && q.pantographs < d.pantographs);
        assert_eq!(d.pantographs, 1000);
        let f = Cli::parse_from(["x", "--full"]).a.sizes();
        assert_eq!(f.fleet_traces, 12_000);
        let only = Cli::parse_from(["x", "--only", "fits,query"]).a.only;
        assert_eq!(only, [Section::Fits, Section::Query]);
        assert!(Cli::try_parse_from(["x", "--only", "nope"]).is_err());
    }

    #[test]
    fn table_marks_failures() {
        let mut ok = Row::failed("a", "≤ 1 s", "x");
        ok.pass = Some(true);
        let mut bad = ok.clone();
        bad.pass = Some(false);
        let t = table(&[ok, bad, Row::failed("c", "t", "no PostgreSQL")]);
        assert!(t.contains("| yes |") && t.contains("| **no** |"));
        assert!(t.contains("not measured: no PostgreSQL"));
    }
}

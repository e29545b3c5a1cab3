//! `pantowatch-tools bench suite`: runs the sections (fits, fleet, ingest + storage, query) at the
//! issue's sizes (or `--quick`), then prints one table — measured / target / pass — under the
//! machine line, or the same as JSON (`--json`) for docs/PERFORMANCE.md and the README.

use std::time::Instant;

use anyhow::Context;
use serde::Serialize;

use super::machine::Machine;
use super::table::{Row, Section, Sizes, SuiteArgs};

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
        Section::Scaling,
        Section::Plan,
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
            Section::Scaling => super::scaling::rows(&sizes, a.quick),
            Section::Plan => super::plan::run(&a, &sizes),
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

//! `pantowatch`: the command line of the pantograph joint-wear service.

use clap::{Parser, Subcommand};
use pantowatch::cli;
use pantowatch_models::drift::DriftThresholds;

#[derive(Debug, Parser)]
#[command(
    name = "pantowatch",
    version,
    about = "Watches the wear of railway pantograph joints: fits joint friction to test traces."
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Identify a trace's joint friction (viscous and dry, 95 % intervals, drift status).
    Fit(cli::fit::FitArgs),
    /// Write a synthetic trace document.
    Simulate(Box<cli::simulate::SimulateArgs>),
    /// Time the identification of trace files.
    Bench(cli::bench::BenchArgs),
    /// Fit the example traces and show the results against their truth.
    Demo,
}

fn main() {
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env().unwrap_or_else(|_| "info".into()),
        )
        .with_writer(std::io::stderr)
        .init();
    let cli = Cli::parse();
    let thresholds = DriftThresholds::default();
    let res = match cli.command {
        Command::Fit(a) => cli::fit::run(a, &thresholds),
        Command::Simulate(a) => cli::simulate::run(*a),
        Command::Bench(a) => cli::bench::run(a),
        Command::Demo => cli::demo::run(&thresholds),
    };
    if let Err(e) = res {
        eprintln!("error: {e:#}");
        std::process::exit(1);
    }
}

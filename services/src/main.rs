//! `pantowatch`: the command line of the pantograph joint-wear service. The benchmark suite and
//! the load generator are not the service: they are `pantowatch-tools` (tools/).

use clap::{Parser, Subcommand};
use pantowatch::cli;
use pantowatch::config::{LogSettings, init_logging};
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
    /// A synthetic fleet's year on a fresh SQLite database: fit, fleet health, then serve the API.
    Demo(cli::demo::DemoArgs),
    /// Serve the REST API with fitting workers.
    Serve(cli::serve::ServeArgs),
    /// Run fitting workers only (against a shared database).
    Worker(cli::serve::WorkerArgs),
    /// Apply the database migrations and exit (the one-shot step before scaling out).
    Migrate(cli::migrate::MigrateArgs),
    /// Queue re-fits by the current model version (all traces, or one vehicle's).
    Refit(cli::refit::RefitArgs),
    /// Relearn the fleet prior from the workshop fits (refits queued when it moved), or show it.
    Prior(cli::prior::PriorArgs),
    /// Create, list or revoke API keys.
    Keys(cli::keys::KeysArgs),
    /// Identify a trace's joint friction (viscous and dry, 95 % intervals, drift status).
    Fit(cli::fit::FitArgs),
    /// Design an on-vehicle lift test: D-optimal drive moves within the stand's limits, and
    /// what it and the raise and lower tell per Table 4 parameter (issue 15).
    DesignTest(cli::design::DesignArgs),
    /// The predicted static contact force over the working range, raising and lowering, with
    /// 95 % bands and the type's limits, from a trace (fitted first) or a fit result (issue 20).
    StaticForce(cli::static_force::StaticForceArgs),
    /// Write a synthetic trace document.
    Simulate(Box<cli::simulate::SimulateArgs>),
    /// Fit the shared example traces and show the results against their truth.
    Examples,
}

fn main() {
    // Freed memory is kept for the next fit, not returned to the OS (issue 38; `alloc`).
    pantowatch::alloc::tune();
    let cli = Cli::parse();
    // The pantograph type data (Table 2, Table 4, the rigs) is validated before any work.
    if let Err(e) = pantowatch_models::data::PantographType::from_toml(
        pantowatch_models::data::PANTOGRAPH_160EC_TOML,
    ) {
        eprintln!("error: {e}");
        std::process::exit(2);
    }
    let thresholds = DriftThresholds::default();
    let res = match cli.command {
        Command::Demo(a) => cli::demo::run(a),
        Command::Serve(a) => cli::serve::serve(a),
        Command::Worker(a) => cli::serve::worker(a),
        Command::Migrate(a) => cli::migrate::run(a),
        Command::Refit(a) => cli::refit::run(a),
        Command::Prior(a) => cli::prior::run(a),
        Command::Keys(a) => cli::keys::run(a),
        Command::Fit(a) => {
            init_logging(&LogSettings::default());
            cli::fit::run(a, &thresholds)
        }
        Command::Simulate(a) => {
            init_logging(&LogSettings::default());
            cli::simulate::run(*a)
        }
        Command::DesignTest(a) => cli::design::run(&a),
        Command::StaticForce(a) => {
            init_logging(&LogSettings::default());
            cli::static_force::run(a, &thresholds)
        }
        Command::Examples => {
            init_logging(&LogSettings::default());
            cli::examples::run(&thresholds)
        }
    };
    if let Err(e) = res {
        eprintln!("error: {e:#}");
        std::process::exit(1);
    }
}

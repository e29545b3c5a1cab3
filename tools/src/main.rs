//! `pantowatch-tools`: the benchmark suite and the load generator, beside (not in) the
//! `pantowatch` service binary.

use clap::{Parser, Subcommand};
use pantowatch_tools::{bench, load};

#[derive(Debug, Parser)]
#[command(
    name = "pantowatch-tools",
    version,
    about = "pantowatch's tools that are not the service: the benchmark suite and the load generator."
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Time the identification of trace files; `bench suite`: every performance target, one table.
    Bench(Box<bench::BenchArgs>),
    /// Concurrent uploaders against a running service, then a read-back check (counts, SHA-256).
    Load(Box<load::LoadArgs>),
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
    let res = match cli.command {
        // The suite's in-process service would log every timed request: bench sets its own.
        Command::Bench(a) => bench::run(*a),
        Command::Load(a) => load::run(*a),
    };
    if let Err(e) = res {
        eprintln!("error: {e:#}");
        std::process::exit(1);
    }
}

//! `pantowatch prior learn|show [--model 160EC]`: relearn the fleet prior from the store's
//! workshop fits (a new version when it moved, the refits it queues; `--run` fits them here), or
//! show the current one (issue 37, point 3; `crate::fleet_prior`).

use super::serve::{ConfigArgs, open_store, runtime};
use crate::fleet_prior::{self, FleetPriorView};
use crate::server::worker_options;

#[derive(Debug, clap::Args)]
pub struct PriorArgs {
    #[command(subcommand)]
    pub action: PriorAction,
}

#[derive(Debug, clap::Subcommand)]
pub enum PriorAction {
    /// Relearn the prior from the workshop fits; publish a new version when it moved and queue
    /// the refit of every lift fitted under an older one.
    Learn {
        #[command(flatten)]
        config: ConfigArgs,
        /// The pantograph type.
        #[arg(long, default_value = "160EC")]
        model: String,
        /// Fit the queued refits here (every core) and exit when the queue is empty.
        #[arg(long)]
        run: bool,
    },
    /// Show the current prior (or version `--version`; 0 is the type file's).
    Show {
        #[command(flatten)]
        config: ConfigArgs,
        #[arg(long, default_value = "160EC")]
        model: String,
        #[arg(long)]
        version: Option<i64>,
    },
}

fn print_prior(p: &FleetPriorView) {
    println!(
        "fleet prior of {} version {} ({}, {} units; floor {}, learned sds × {} in fits)",
        p.model, p.version, p.source, p.n_units, p.floor_relative_sd, p.fit_sd_scale
    );
    println!("  joint param     mean     sd  spread  fits  learned");
    for q in &p.params {
        println!(
            "  {:<5} {:<7} {:>7.3} {:>6.3} {:>7.3} {:>5}  {}",
            q.joint, q.kind, q.mean_ratio, q.sd_ratio, q.spread_ratio, q.n_fits, q.learned
        );
    }
}

pub fn run(a: PriorArgs) -> anyhow::Result<()> {
    match a.action {
        PriorAction::Learn { config, model, run } => {
            let s = config.settings()?;
            runtime()?.block_on(async {
                let store = open_store(&s).await?;
                let r = fleet_prior::relearn(&store, &model).await?;
                print_prior(&r.prior);
                if r.published {
                    println!(
                        "published version {} from {} workshop estimates; {} refits queued (lifts and gauge records)",
                        r.prior.version, r.n_estimates, r.queued
                    );
                } else {
                    println!(
                        "unchanged (within [fleet_prior] version_tolerance_relative) from {} workshop estimates",
                        r.n_estimates
                    );
                }
                if run && r.queued > 0 {
                    let workers = std::thread::available_parallelism().map_or(1, usize::from);
                    super::refit::drain_queue(&store, worker_options(&s, workers)).await?;
                }
                store.close().await;
                Ok(())
            })
        }
        PriorAction::Show {
            config,
            model,
            version,
        } => {
            let s = config.settings()?;
            runtime()?.block_on(async {
                let store = open_store(&s).await?;
                let p = fleet_prior::view(&store, &model, version).await?;
                print_prior(&p);
                store.close().await;
                Ok(())
            })
        }
    }
}

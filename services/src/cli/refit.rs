//! `pantowatch refit [--vehicle ID] [--run]`: queue a fit by the current model version for every
//! trace (or one vehicle's) that has none — after a model change. Running workers pick them up;
//! `--run` fits the queue here on every core with a progress bar until it is empty (issue 8: a
//! depot re-fits its fleet's history in minutes).

use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant};

use indicatif::{ProgressBar, ProgressStyle};
use pantowatch_models::report::MODEL_VERSION;
use tokio::sync::{Notify, watch};

use super::serve::{ConfigArgs, open_store, runtime};
use crate::ids::VehicleId;
use crate::server::worker_options;
use crate::store::Store;
use crate::worker::{JobEvent, OnJob, WorkerPool, wait_until_drained};

#[derive(Debug, clap::Args)]
pub struct RefitArgs {
    #[command(flatten)]
    pub config: ConfigArgs,
    /// Only this vehicle's traces.
    #[arg(long)]
    pub vehicle: Option<String>,
    /// Fit the whole queue in this process (every core, a progress bar) and exit when it is
    /// empty, instead of leaving the jobs to running workers.
    #[arg(long)]
    pub run: bool,
    /// Fitting workers for `--run` (default: every core).
    #[arg(long, requires = "run")]
    pub workers: Option<usize>,
}

pub fn run(a: RefitArgs) -> anyhow::Result<()> {
    let s = a.config.settings()?;
    let vehicle = a
        .vehicle
        .as_deref()
        .map(|v| VehicleId::parse("--vehicle", v))
        .transpose()?;
    let workers = a
        .workers
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, usize::from))
        .max(1);
    runtime()?.block_on(async {
        let store = open_store(&s).await?;
        let n = match &vehicle {
            Some(v) => store.requeue_vehicle(v.as_str(), MODEL_VERSION).await?,
            None => store.requeue_all(MODEL_VERSION).await?,
        };
        println!("queued {n} fits (model version {MODEL_VERSION})");
        if a.run {
            drain_queue(&store, worker_options(&s, workers)).await?;
        }
        store.close().await;
        Ok(())
    })
}

/// Fits the queue on `store` until it is empty and prints what was done (`prior learn --run`).
pub(crate) async fn drain_queue(
    store: &Store,
    opts: crate::worker::WorkerOptions,
) -> anyhow::Result<()> {
    let workers = opts.workers;
    let done = drain(store, opts).await?;
    println!(
        "fitted {} traces in {:.1} s ({:.2} fits/s on {workers} workers), {} failed",
        done.fitted,
        done.seconds,
        done.fitted as f64 / done.seconds.max(1e-9),
        done.failed
    );
    if let Some(e) = done.first_error {
        println!("first failure: {e}");
    }
    Ok(())
}

/// What [`drain`] did.
struct Drained {
    fitted: usize,
    failed: usize,
    seconds: f64,
    first_error: Option<String>,
}

/// Runs a worker pool on `store` until no job is queued or running (jobs other processes hold
/// are waited for too), a progress bar ticking per job this process finishes.
async fn drain(store: &Store, opts: crate::worker::WorkerOptions) -> anyhow::Result<Drained> {
    let c = store.job_counts().await?;
    let bar = ProgressBar::new((c.queued + c.running).max(0) as u64);
    bar.set_style(
        ProgressStyle::with_template("   fit [{bar:40}] {pos}/{len} {per_sec:>10} eta {eta} {msg}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let fitted = Arc::new(AtomicUsize::new(0));
    let failed = Arc::new(AtomicUsize::new(0));
    let first_error = Arc::new(std::sync::Mutex::new(None::<String>));
    let on_job: OnJob = {
        let (bar, fitted, failed, first_error) = (
            bar.clone(),
            fitted.clone(),
            failed.clone(),
            first_error.clone(),
        );
        Arc::new(move |ev: &JobEvent| match ev {
            JobEvent::Done { .. } => {
                fitted.fetch_add(1, Ordering::Relaxed);
                bar.inc(1);
            }
            JobEvent::Failed { trace_id, error } => {
                let k = failed.fetch_add(1, Ordering::Relaxed) + 1;
                if let Ok(mut e) = first_error.lock() {
                    e.get_or_insert_with(|| format!("{trace_id}: {error}"));
                }
                bar.set_message(format!("{k} failed"));
                bar.inc(1);
            }
            JobEvent::LeaseLost { .. } | JobEvent::Released { .. } => {}
        })
    };
    let t0 = Instant::now();
    let (stop_tx, stop_rx) = watch::channel(false);
    let pool = WorkerPool::spawn(
        store.clone(),
        opts,
        Arc::new(Notify::new()),
        stop_rx,
        Some(on_job),
    );
    wait_until_drained(store, Duration::from_millis(100)).await?;
    let _ = stop_tx.send(true);
    pool.join().await;
    bar.finish_and_clear();
    let first_error = first_error.lock().ok().and_then(|mut e| e.take());
    Ok(Drained {
        fitted: fitted.load(Ordering::Relaxed),
        failed: failed.load(Ordering::Relaxed),
        seconds: t0.elapsed().as_secs_f64(),
        first_error,
    })
}

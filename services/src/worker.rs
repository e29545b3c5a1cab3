//! Background fitting: a pool of workers that claim jobs from the durable queue under a lease,
//! fit off the async runtime (`spawn_blocking`) and write each result once with `complete`.
//!
//! A worker that dies keeps its job only until the lease runs out; then another claims it.
//! On shutdown a worker finishes the fit it is running if it ends within the grace period, else
//! (and for a job claimed but not started) it releases the job to the queue, then stops.

use std::sync::Arc;
use std::time::{Duration, Instant};

use pantowatch_models::budget::Budget;
use pantowatch_models::drift::DriftThresholds;
use tokio::sync::{Notify, watch};
use tokio::task::JoinSet;

use crate::alerts::{self, AlertAction, AlertOptions};
use crate::fitting::{self, FitFailure};
use crate::ingest::stored_doc_as_sent;
use crate::store::{CompleteOutcome, FailOutcome, JobState, NewFit, Status, Store, StoreError};

/// How the pool works.
#[derive(Debug, Clone)]
pub struct WorkerOptions {
    /// Number of worker tasks (each runs one fit at a time).
    pub workers: usize,
    /// Lease of a claimed job.
    pub lease: Duration,
    /// Idle poll interval (jobs queued by other processes; in-process uploads wake at once).
    pub poll: Duration,
    /// After shutdown starts, how long a running fit may take before its job is released.
    pub shutdown_grace: Duration,
    /// Longest one fit may run; then it is stopped and its job fails with that reason
    /// (`worker.fit_budget_secs`).
    pub fit_budget: Duration,
    /// Most model evaluations one fit may spend (`worker.fit_max_evaluations`).
    pub fit_max_evaluations: u64,
    pub thresholds: DriftThresholds,
    /// The alert rules run after each fit written.
    pub alerts: AlertOptions,
    /// Woken when an alert changed (the webhook deliverer of this process).
    pub alert_wake: Option<Arc<Notify>>,
}

/// What happened to one claimed job.
#[derive(Debug, Clone, PartialEq)]
pub enum JobEvent {
    /// Fit written (or found written) and the job done.
    Done {
        trace_id: String,
        status: Option<Status>,
        fit_seconds: f64,
    },
    /// The job failed for good with this message (e.g. a `lift` trace).
    Failed { trace_id: String, error: String },
    /// Another worker took the job over after this one's lease ran out: nothing written.
    LeaseLost { trace_id: String },
    /// Shutdown: the job went back to the queue unfinished (its attempt counted only if its fit
    /// had started).
    Released { trace_id: String },
}

/// The highest attempt number used as a metric label (`MAX_ATTEMPTS`; a later claim of an
/// expired lease is labelled with it too, so the label set stays bounded).
const MAX_ATTEMPT_LABEL: i64 = crate::store::MAX_ATTEMPTS;

impl WorkerOptions {
    /// The limits of one fit, for the fits this worker runs besides its jobs (pooled lifts).
    pub fn limits(&self) -> crate::fitting::FitLimits {
        crate::fitting::FitLimits {
            max_evaluations: self.fit_max_evaluations,
            wall: self.fit_budget,
        }
    }
}

/// Called after every job (the demo's progress bar; only the CLI knows about terminals).
pub type OnJob = Arc<dyn Fn(&JobEvent) + Send + Sync>;

/// Running workers.
pub struct WorkerPool {
    tasks: JoinSet<()>,
}

impl WorkerPool {
    /// Starts `opts.workers` workers; they stop when `shutdown` turns true.
    pub fn spawn(
        store: Store,
        opts: WorkerOptions,
        wake: Arc<Notify>,
        shutdown: watch::Receiver<bool>,
        on_job: Option<OnJob>,
    ) -> WorkerPool {
        let mut tasks = JoinSet::new();
        let tag = instance_tag();
        for n in 0..opts.workers {
            let id = format!("{tag}-{n}");
            tasks.spawn(run_worker(
                store.clone(),
                id,
                opts.clone(),
                wake.clone(),
                shutdown.clone(),
                on_job.clone(),
            ));
        }
        WorkerPool { tasks }
    }

    /// Waits until every worker has stopped.
    pub async fn join(mut self) {
        while let Some(r) = self.tasks.join_next().await {
            if let Err(e) = r {
                tracing::error!(error = %e, "worker task ended abnormally");
            }
        }
    }
}

/// Waits until no job is queued or running in `store` (jobs other processes hold included),
/// looking every `poll`: the moment a pool that fits a known backlog can be stopped (the demo,
/// `refit --run`).
pub async fn wait_until_drained(store: &Store, poll: Duration) -> Result<(), StoreError> {
    loop {
        let c = store.job_counts().await?;
        if c.queued + c.running == 0 {
            return Ok(());
        }
        tokio::time::sleep(poll).await;
    }
}

/// `host-pid-random`: unique per process start, so a restarted service never holds the jobs of
/// its previous life.
fn instance_tag() -> String {
    let mut b = [0u8; 3];
    let _ = getrandom::fill(&mut b);
    let host = std::env::var("HOSTNAME").unwrap_or_else(|_| "pw".into());
    format!("{host}-{}-{}", std::process::id(), hex::encode(b))
}

async fn run_worker(
    store: Store,
    id: String,
    opts: WorkerOptions,
    wake: Arc<Notify>,
    mut shutdown: watch::Receiver<bool>,
    on_job: Option<OnJob>,
) {
    tracing::debug!(worker = %id, "worker started");
    let mut backoff = opts.poll;
    loop {
        if *shutdown.borrow() {
            break;
        }
        // Register for wake-ups before looking, so an upload between the claim and the wait
        // is not missed.
        let notified = wake.notified();
        tokio::pin!(notified);
        notified.as_mut().enable();
        match process_next(&store, &id, &opts, &shutdown).await {
            Ok(Some(ev)) => {
                backoff = opts.poll;
                if let Some(cb) = &on_job {
                    cb(&ev);
                }
                continue;
            }
            Ok(None) => {
                tokio::select! {
                    _ = notified => {}
                    _ = tokio::time::sleep(opts.poll) => {}
                    _ = shutdown.changed() => {}
                }
            }
            Err(e) => {
                // The database is unreachable or failed: the job (if any) stays leased and is
                // reclaimed when the lease runs out. Back off up to 30 s.
                tracing::error!(worker = %id, error = %e, "job processing failed");
                tokio::select! {
                    _ = tokio::time::sleep(backoff) => {}
                    _ = shutdown.changed() => {}
                }
                backoff = (backoff * 2).min(Duration::from_secs(30));
            }
        }
    }
    tracing::debug!(worker = %id, "worker stopped");
}

/// Claims one job and processes it; `None` when the queue is empty. Once `shutdown` is true a
/// job not yet started is released, and a running fit gets `opts.shutdown_grace` to finish.
pub async fn process_next(
    store: &Store,
    worker: &str,
    opts: &WorkerOptions,
    shutdown: &watch::Receiver<bool>,
) -> Result<Option<JobEvent>, StoreError> {
    let Some(job) = store.claim(worker, opts.lease).await? else {
        return Ok(None);
    };
    // Attempts by their number (1 = first claim): retries and takeovers show as 2 and 3.
    metrics::counter!("pantowatch_job_attempts_total", "attempt" => job.attempts.min(MAX_ATTEMPT_LABEL).to_string())
        .increment(1);
    let trace_id = job.trace_id.clone();
    // Shutdown between the claim and the start of the work: give the job back untouched.
    if *shutdown.borrow() {
        return release(
            store,
            worker,
            job.id,
            trace_id,
            "before its fit started",
            false,
        )
        .await
        .map(Some);
    }
    let doc = match (
        store.get_trace(&trace_id).await?,
        load_samples(store, &trace_id).await?,
    ) {
        (Some(meta), Ok(Some(channels))) => stored_doc_as_sent(&meta, channels),
        (None, _) | (_, Ok(None)) => Err("trace or its samples are missing".to_owned()),
        (_, Err(e)) => Err(e),
    };
    let doc = match doc {
        Ok(d) => d,
        Err(msg) => {
            return fail_because(store, worker, job.id, trace_id, msg, "samples")
                .await
                .map(Some);
        }
    };
    // The test typed (and checked) here, once: a stored trace today's rules refuse fails as
    // invalid, naming the field.
    let doc = match doc.typed() {
        Ok(d) => d,
        Err(e) => {
            let msg = format!("invalid trace: {e}");
            return fail_because(store, worker, job.id, trace_id, msg, "invalid")
                .await
                .map(Some);
        }
    };
    let thresholds = opts.thresholds;
    let kind = doc.kind.as_str();
    // A lift or a force-gauge record is fitted under its type's fleet prior: the version a
    // refit job names, else the newest (`fleet_prior`; recorded in `fit.prior`). A lift's pooled
    // fit takes the same.
    let prior = if crate::fleet_prior::PRIOR_KINDS.contains(&kind) {
        crate::fleet_prior::for_job(store, &doc.pantograph_model, &job.model_version).await?
    } else {
        None
    };
    let pooled_prior = prior.clone();
    let t0 = Instant::now();
    // The fit runs under its evaluation budget; the canceller stops it (within ~1 ms) when
    // the wall-time budget or the shutdown grace runs out, so its thread is freed too.
    let budget = Budget::new(opts.fit_max_evaluations);
    let stop = budget.canceller();
    let spent = budget.clone();
    let mut fit_task = tokio::task::spawn_blocking(move || {
        fitting::fit_document_within_prior(&doc, &thresholds, prior.as_ref(), &budget)
    });
    // The lease is renewed every third of its length while the fit runs.
    let renew_every = (opts.lease / 3).max(Duration::from_millis(100));
    let wall = tokio::time::sleep(opts.fit_budget);
    tokio::pin!(wall);
    let grace = grace_over(shutdown.clone(), opts.shutdown_grace);
    tokio::pin!(grace);
    let fitted = loop {
        tokio::select! {
            r = &mut fit_task => break r,
            () = &mut grace => {
                stop.cancel();
                // Its attempt stays counted: a fit that outlasts every shutdown fails at the
                // attempt limit instead of looping.
                return release(store, worker, job.id, trace_id, "its fit outlasted the shutdown grace period", true)
                    .await
                    .map(Some);
            }
            () = &mut wall => {
                stop.cancel();
                let msg = format!(
                    "the fit ran past its budget of {} s (worker.fit_budget_secs) and was stopped",
                    opts.fit_budget.as_secs_f64()
                );
                return fail_because(store, worker, job.id, trace_id, msg, "wall_time").await.map(Some);
            }
            () = tokio::time::sleep(renew_every) => {
                match store.renew_lease(job.id, worker, opts.lease).await {
                    Ok(true) => {}
                    Ok(false) => {
                        // Another worker holds the job now: stop fitting it.
                        stop.cancel();
                        metrics::counter!("pantowatch_jobs_processed_total", "outcome" => "lease_lost").increment(1);
                        tracing::warn!(job = job.id, trace = %trace_id, "lease lost while fitting: the fit is stopped");
                        return Ok(Some(JobEvent::LeaseLost { trace_id }));
                    }
                    // The database is away for a moment: the fit goes on; the lease may lapse
                    // and the job be taken over, which `complete` then reports.
                    Err(e) => tracing::warn!(job = job.id, error = %e, "could not renew the lease"),
                }
            }
        }
    };
    let fit_seconds = t0.elapsed().as_secs_f64();
    let evaluations = spent.evaluations();
    metrics::histogram!("pantowatch_fit_duration_seconds", "kind" => kind).record(fit_seconds);
    // What the evaluation budget is measured against (worker.fit_max_evaluations).
    metrics::histogram!("pantowatch_fit_evaluations", "kind" => kind).record(evaluations as f64);
    let fitted = match fitted {
        Ok(Ok(r)) => r,
        Ok(Err(f)) => {
            let msg = match &f {
                FitFailure::Unsupported(m) => m.clone(),
                FitFailure::Budget(e) => format!(
                    "{e} (worker.fit_max_evaluations = {}) and was stopped",
                    opts.fit_max_evaluations
                ),
                other => other.to_string(),
            };
            return fail_because(store, worker, job.id, trace_id, msg, f.reason())
                .await
                .map(Some);
        }
        Err(e) => {
            let msg = format!("the fit panicked or was cancelled: {e}");
            return fail_because(store, worker, job.id, trace_id, msg, "panic")
                .await
                .map(Some);
        }
    };
    // The result stays typed: the store serialises it, the alert rules read it.
    let fit = NewFit::from_result(fitted.result).with_curve(fitted.curve);
    let status = fit.status();
    match store.complete(job.id, worker, &fit).await? {
        CompleteOutcome::Completed(w) => {
            metrics::counter!("pantowatch_jobs_processed_total", "outcome" => "done").increment(1);
            tracing::info!(job = job.id, trace = %trace_id, fit_id = w.fit_id,
                status = status.map_or("none", Status::as_str), ms = fit_seconds * 1e3, evaluations, "fit written");
            if w.created {
                // The fit is durable; an alert-rule failure is logged and the next fit of the
                // joint decides again.
                match alerts::after_fit(store, &trace_id, w.fit_id, &fit.result, &opts.alerts).await
                {
                    Ok(actions) => {
                        let changed = actions.iter().any(|a| match a {
                            AlertAction::Raised(r) => {
                                !matches!(**r, crate::store::RaiseOutcome::Updated(_))
                            }
                            AlertAction::Resolved { .. } => true,
                        });
                        if let (true, Some(wake)) = (changed, &opts.alert_wake) {
                            wake.notify_waiters();
                        }
                    }
                    Err(e) => {
                        tracing::error!(trace = %trace_id, error = %e, "alert rules failed after the fit")
                    }
                }
            }
            // A lift also gets the pooled fit of its pantograph's recent lifts (`pooled`); its
            // own fit is durable already, so a failure here is logged, not the job's.
            if kind == "lift"
                && let Err(e) = crate::pooled::after_lift(
                    store,
                    &trace_id,
                    opts.thresholds,
                    &opts.alerts,
                    opts.limits(),
                    pooled_prior.as_ref(),
                )
                .await
            {
                tracing::error!(trace = %trace_id, error = %e, "pooled lift fit failed");
            }
            // A single-joint test stating `test.rig_id` gets the pooled fit of its rig's
            // recordings (issue 36, point 5); its own fit is durable already.
            if matches!(kind, "pendulum" | "slider")
                && let Err(e) = crate::pooled::after_rig(
                    store,
                    &trace_id,
                    opts.thresholds,
                    &opts.alerts,
                    opts.limits(),
                )
                .await
            {
                tracing::error!(trace = %trace_id, error = %e, "pooled rig fit failed");
            }
            Ok(Some(JobEvent::Done {
                trace_id,
                status,
                fit_seconds,
            }))
        }
        CompleteOutcome::LeaseLost => {
            metrics::counter!("pantowatch_jobs_processed_total", "outcome" => "lease_lost")
                .increment(1);
            tracing::warn!(job = job.id, trace = %trace_id, "lease lost: another worker took the job");
            Ok(Some(JobEvent::LeaseLost { trace_id }))
        }
    }
}

/// Resolves `grace` after shutdown starts (never if the shutdown sender is gone unsent).
async fn grace_over(mut shutdown: watch::Receiver<bool>, grace: Duration) {
    if shutdown.wait_for(|s| *s).await.is_err() {
        std::future::pending::<()>().await;
    }
    tokio::time::sleep(grace).await;
}

/// Gives the job back to the queue at shutdown; a failed release is logged (the lease expiry
/// hands the job on instead).
async fn release(
    store: &Store,
    worker: &str,
    job_id: i64,
    trace_id: String,
    why: &str,
    fit_started: bool,
) -> Result<JobEvent, StoreError> {
    let released = if fit_started {
        store
            .release_counted(job_id, worker)
            .await
            .map(|s| match s {
                Some(JobState::Failed) => {
                    // At the attempt limit the release failed the job for good.
                    metrics::counter!("pantowatch_jobs_failed_total", "reason" => "attempts")
                        .increment(1);
                    true
                }
                other => other.is_some(),
            })
    } else {
        store.release(job_id, worker).await
    };
    match released {
        Ok(true) => {
            metrics::counter!("pantowatch_jobs_processed_total", "outcome" => "released")
                .increment(1);
            tracing::info!(job = job_id, trace = %trace_id, "shutdown: job released to the queue {why}");
            Ok(JobEvent::Released { trace_id })
        }
        Ok(false) => Ok(JobEvent::LeaseLost { trace_id }),
        Err(e) => {
            tracing::warn!(job = job_id, trace = %trace_id, error = %e,
                "shutdown: could not release the job; it is claimable again when its lease expires");
            Err(e)
        }
    }
}

/// Samples, with an undecodable blob (checksum, codec) as a job failure rather than an outage.
async fn load_samples(
    store: &Store,
    trace_id: &str,
) -> Result<Result<Option<Vec<(String, Vec<f64>)>>, String>, StoreError> {
    match store.get_samples(trace_id).await {
        Ok(c) => Ok(Ok(c)),
        Err(StoreError::Codec(e)) => Ok(Err(format!("stored samples unreadable: {e}"))),
        Err(e) => Err(e),
    }
}

/// Fails the job for good, counted in `pantowatch_jobs_failed_total{reason}` under `reason`.
async fn fail_because(
    store: &Store,
    worker: &str,
    job_id: i64,
    trace_id: String,
    error: String,
    reason: &'static str,
) -> Result<JobEvent, StoreError> {
    match store.fail(job_id, worker, &error, false).await? {
        FailOutcome::Failed | FailOutcome::Requeued => {
            metrics::counter!("pantowatch_jobs_processed_total", "outcome" => "failed")
                .increment(1);
            metrics::counter!("pantowatch_jobs_failed_total", "reason" => reason).increment(1);
            tracing::warn!(job = job_id, trace = %trace_id, %error, "fit job failed");
            Ok(JobEvent::Failed { trace_id, error })
        }
        FailOutcome::LeaseLost => Ok(JobEvent::LeaseLost { trace_id }),
    }
}

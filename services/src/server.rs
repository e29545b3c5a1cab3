//! The service process: the HTTP API and the fitting workers on one runtime, started by [`run`]
//! on a bound listener and stopped gracefully when the shutdown future resolves (in-flight
//! requests are answered, each worker finishes its current fit).

use std::future::Future;
use std::sync::Arc;
use std::time::Duration;

use pantowatch_models::report::MODEL_VERSION;
use tokio::net::TcpListener;
use tokio::sync::{Notify, watch};

use crate::alerts::AlertOptions;
use crate::api::AppState;
use crate::config::Settings;
use crate::store::{BackendKind, Store};
use crate::webhooks::{self, DeliveryOptions};
use crate::worker::{OnJob, WorkerOptions, WorkerPool};

/// The workers' options from the settings, with `workers` tasks.
pub fn worker_options(settings: &Settings, workers: usize) -> WorkerOptions {
    WorkerOptions {
        workers,
        lease: settings.lease(),
        poll: settings.poll(),
        shutdown_grace: settings.shutdown_grace(),
        fit_budget: settings.fit_budget(),
        fit_max_evaluations: settings.worker.fit_max_evaluations,
        thresholds: settings.thresholds(),
        alerts: AlertOptions {
            horizon_days: settings.alerts.horizon_days,
            alarm: settings.drift.alarm,
        },
        alert_wake: None,
    }
}

/// The webhook deliverer's options from the settings.
pub fn delivery_options(settings: &Settings) -> DeliveryOptions {
    let w = &settings.webhooks;
    DeliveryOptions {
        backoff_base: Duration::from_millis(w.backoff_base_ms),
        max_attempts: w.max_attempts,
        timeout: Duration::from_millis(w.timeout_ms),
        poll: Duration::from_millis(w.poll_ms),
    }
}

/// `sqlite` or `postgresql`: what may be logged about the database.
pub fn backend_label(store: &Store) -> &'static str {
    match store.kind() {
        BackendKind::Sqlite => "sqlite",
        BackendKind::Postgres => "postgresql",
    }
}

/// Serves the API on `listener` with `settings.workers` fitting workers until `shutdown`
/// resolves; then stops accepting, answers what is in flight and waits for the workers.
/// The store stays open (the caller closes it).
pub async fn run(
    listener: TcpListener,
    store: Store,
    settings: &Settings,
    shutdown: impl Future<Output = ()> + Send + 'static,
) -> anyhow::Result<()> {
    run_with(listener, store, settings, shutdown, Hooks::default()).await
}

/// What a command running the service in its own process adds to it (`pantowatch demo`): the
/// wake-up its own uploads share with the workers, and a call after every job (its progress
/// bar; only the CLI knows about terminals).
#[derive(Default)]
pub struct Hooks {
    pub wake: Option<Arc<Notify>>,
    pub on_job: Option<OnJob>,
}

/// [`run`] with the [`Hooks`] of an in-process caller.
pub async fn run_with(
    listener: TcpListener,
    store: Store,
    settings: &Settings,
    shutdown: impl Future<Output = ()> + Send + 'static,
    hooks: Hooks,
) -> anyhow::Result<()> {
    let (stop_tx, stop_rx) = watch::channel(false);
    tokio::spawn(async move {
        shutdown.await;
        let _ = stop_tx.send(true);
    });
    let wake = hooks.wake.unwrap_or_default();
    let alert_wake = Arc::new(Notify::new());
    let mut opts = worker_options(settings, settings.workers);
    opts.alert_wake = Some(alert_wake.clone());
    let pool = WorkerPool::spawn(
        store.clone(),
        opts,
        wake.clone(),
        stop_rx.clone(),
        hooks.on_job,
    );
    let deliverer = tokio::spawn(webhooks::run(
        store.clone(),
        delivery_options(settings),
        alert_wake.clone(),
        stop_rx.clone(),
    ));
    let state = AppState::new(
        store.clone(),
        wake,
        settings.body_limit_bytes(),
        Duration::from_secs(settings.http.request_timeout_secs),
    )
    .configure(settings, alert_wake)?;
    let addr = listener.local_addr()?;
    tracing::info!(%addr, workers = settings.workers, database = backend_label(&store),
        model_version = MODEL_VERSION, "pantowatch serving");
    let mut stop = stop_rx;
    // Connect info: the rate limit charges callers without a key to their peer address.
    let app =
        crate::app::router(state).into_make_service_with_connect_info::<std::net::SocketAddr>();
    let served = axum::serve(listener, app)
        .with_graceful_shutdown(async move {
            let _ = stop.wait_for(|s| *s).await;
            tracing::info!("shutting down: finishing requests and fits in flight");
        })
        .await;
    pool.join().await;
    if let Err(e) = deliverer.await {
        tracing::error!(error = %e, "webhook deliverer ended abnormally");
    }
    tracing::info!("pantowatch stopped");
    served.map_err(Into::into)
}

/// Runs only the fitting workers until `shutdown` resolves.
pub async fn run_workers(
    store: Store,
    settings: &Settings,
    workers: usize,
    shutdown: impl Future<Output = ()> + Send + 'static,
) {
    let (stop_tx, stop_rx) = watch::channel(false);
    let alert_wake = Arc::new(Notify::new());
    let mut opts = worker_options(settings, workers);
    opts.alert_wake = Some(alert_wake.clone());
    let pool = WorkerPool::spawn(
        store.clone(),
        opts,
        Arc::new(Notify::new()),
        stop_rx.clone(),
        None,
    );
    let deliverer = tokio::spawn(webhooks::run(
        store.clone(),
        delivery_options(settings),
        alert_wake,
        stop_rx,
    ));
    tracing::info!(
        workers,
        database = backend_label(&store),
        model_version = MODEL_VERSION,
        "pantowatch workers running"
    );
    shutdown.await;
    tracing::info!("shutting down: finishing fits in flight");
    let _ = stop_tx.send(true);
    pool.join().await;
    let _ = deliverer.await;
    tracing::info!("workers stopped");
}

/// What a worker process serves for its operators (issue 18): `/metrics` — its fits (duration
/// by test kind, outcomes, failures by reason) and the queue gauges read from the store — and
/// `/healthz`. No keys: bind it where only the scraper reaches (deploy's NetworkPolicy).
pub fn worker_metrics_router(store: Store) -> axum::Router {
    use axum::routing::get;
    let handle = crate::api::telemetry::prometheus();
    axum::Router::new()
        .route(
            "/metrics",
            get(move || {
                let (store, handle) = (store.clone(), handle.clone());
                async move { crate::api::ops::prometheus_answer(&store, &handle).await }
            }),
        )
        .route("/healthz", get(|| async { "ok" }))
}

/// Resolves on Ctrl-C (SIGINT) or SIGTERM.
pub async fn shutdown_signal() {
    let ctrl_c = async {
        if tokio::signal::ctrl_c().await.is_err() {
            std::future::pending::<()>().await;
        }
    };
    #[cfg(unix)]
    let term = async {
        match tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate()) {
            Ok(mut s) => {
                s.recv().await;
            }
            Err(_) => std::future::pending::<()>().await,
        }
    };
    #[cfg(not(unix))]
    let term = std::future::pending::<()>();
    tokio::select! {
        _ = ctrl_c => {}
        _ = term => {}
    }
}

//! `pantowatch serve` (API + workers) and `pantowatch worker` (workers only), configured from
//! defaults, `--config FILE`, `PANTOWATCH__…` variables and flags; both stop on SIGINT/SIGTERM.

use std::net::SocketAddr;
use std::path::PathBuf;

use anyhow::Context;

use crate::config::{Settings, backend_name, init_logging};
use crate::server;
use crate::store::Store;

/// Where the configuration comes from (shared by every command that opens the database).
#[derive(Debug, Clone, clap::Args)]
pub struct ConfigArgs {
    /// TOML configuration file (see deploy/pantowatch.example.toml).
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,
    /// Database: a SQLite file path or a postgres:// URL (overrides the configuration).
    #[arg(long, value_name = "URL")]
    pub database: Option<String>,
}

impl ConfigArgs {
    /// The layered settings with this command's flags on top, logging installed.
    pub fn settings(&self) -> anyhow::Result<Settings> {
        let mut s = Settings::load(self.config.as_deref()).context("configuration")?;
        if let Some(url) = &self.database {
            s.database.url = crate::config::SecretString::new(url.clone());
        }
        s.validate()
            .map_err(|m| anyhow::anyhow!("configuration: {m}"))?;
        init_logging(&s.log);
        Ok(s)
    }
}

/// Opens (and migrates) the configured database; logs only which backend it is.
pub async fn open_store(s: &Settings) -> anyhow::Result<Store> {
    tracing::info!(
        database = backend_name(&s.database.url),
        "opening the database"
    );
    Store::connect_with(s.database.url.expose_secret(), s.pool_options())
        .await
        .with_context(|| format!("opening the {} database", backend_name(&s.database.url)))
}

/// A multi-threaded runtime for the async commands.
pub fn runtime() -> anyhow::Result<tokio::runtime::Runtime> {
    tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .context("starting the async runtime")
}

#[derive(Debug, clap::Args)]
pub struct ServeArgs {
    #[command(flatten)]
    pub config: ConfigArgs,
    /// Address to listen on (overrides `listen`).
    #[arg(long, value_name = "ADDR")]
    pub listen: Option<SocketAddr>,
    /// Fitting workers in this process, 0 for the API only (overrides `workers`).
    #[arg(long)]
    pub workers: Option<usize>,
}

pub fn serve(a: ServeArgs) -> anyhow::Result<()> {
    let mut s = a.config.settings()?;
    if let Some(l) = a.listen {
        s.listen = l;
    }
    if let Some(w) = a.workers {
        s.workers = w;
    }
    let rt = runtime()?;
    let res = rt.block_on(async {
        let store = open_store(&s).await?;
        let listener = tokio::net::TcpListener::bind(s.listen)
            .await
            .with_context(|| format!("binding {}", s.listen))?;
        eprintln!("pantowatch serving on http://{}", listener.local_addr()?);
        let res = server::run(listener, store.clone(), &s, server::shutdown_signal()).await;
        store.close().await;
        res
    });
    // A fit abandoned after the grace period (its job released) must not hold the exit.
    rt.shutdown_timeout(ABANDONED_FIT_WAIT);
    res
}

/// How long the exit waits for blocking work left running after the shutdown grace period.
pub const ABANDONED_FIT_WAIT: std::time::Duration = std::time::Duration::from_millis(200);

#[derive(Debug, clap::Args)]
pub struct WorkerArgs {
    #[command(flatten)]
    pub config: ConfigArgs,
    /// Fitting workers (overrides `workers`; at least 1).
    #[arg(long)]
    pub workers: Option<usize>,
    /// Serve `/metrics` and `/healthz` on this address (overrides `worker.metrics_listen`).
    #[arg(long, value_name = "ADDR")]
    pub metrics_listen: Option<SocketAddr>,
}

pub fn worker(a: WorkerArgs) -> anyhow::Result<()> {
    let s = a.config.settings()?;
    let n = a.workers.unwrap_or(s.workers);
    if n == 0 {
        anyhow::bail!("`pantowatch worker` with 0 workers has nothing to do (--workers N)");
    }
    let metrics_listen = a.metrics_listen.or(s.worker.metrics_listen);
    let rt = runtime()?;
    rt.block_on(async {
        let store = open_store(&s).await?;
        let (stop_tx, mut stop_rx) = tokio::sync::watch::channel(false);
        let metrics = match metrics_listen {
            Some(addr) => {
                let listener = tokio::net::TcpListener::bind(addr)
                    .await
                    .with_context(|| format!("binding {addr} for the worker's metrics"))?;
                eprintln!(
                    "pantowatch worker metrics on http://{}",
                    listener.local_addr()?
                );
                let app = server::worker_metrics_router(store.clone());
                Some(tokio::spawn(async move {
                    axum::serve(listener, app)
                        .with_graceful_shutdown(async move {
                            let _ = stop_rx.wait_for(|stop| *stop).await;
                        })
                        .await
                }))
            }
            None => None,
        };
        server::run_workers(store.clone(), &s, n, server::shutdown_signal()).await;
        let _ = stop_tx.send(true);
        if let Some(m) = metrics {
            let _ = m.await;
        }
        store.close().await;
        anyhow::Ok(())
    })?;
    rt.shutdown_timeout(ABANDONED_FIT_WAIT);
    Ok(())
}

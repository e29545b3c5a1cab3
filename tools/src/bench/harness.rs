//! What the ingest and query sections stand on: a fresh PostgreSQL database (created on the
//! admin URL, dropped afterwards) and the service started in-process on port 0 with no workers.

use std::net::SocketAddr;
use std::time::Duration;

use anyhow::Context;
use sqlx::{AssertSqlSafe, Connection, Executor};
use tokio::sync::oneshot;
use tokio::task::JoinHandle;

use pantowatch::config::{SecretString, Settings};
use pantowatch::store::{Role, Store};

/// A PostgreSQL database of this run; [`FreshPg::drop_now`] removes it.
pub struct FreshPg {
    admin: String,
    name: String,
    pub url: String,
}

/// `name` if it is a benchmark database name (`pw_bench_` + 12 lowercase hex digits): the only
/// text ever spliced into SQL here (CREATE/DROP DATABASE take no bound parameters).
fn bench_database_name(name: &str) -> anyhow::Result<String> {
    let ok = name.strip_prefix("pw_bench_").is_some_and(|h| {
        h.len() == 12
            && h.bytes()
                .all(|c| c.is_ascii_digit() || (b'a'..=b'f').contains(&c))
    });
    if ok {
        Ok(name.to_owned())
    } else {
        anyhow::bail!("not a benchmark database name: {name:?}")
    }
}

/// The admin URL with its database name replaced.
fn with_database(url: &str, name: &str) -> String {
    let (base, query) = match url.split_once('?') {
        Some((b, q)) => (b, format!("?{q}")),
        None => (url, String::new()),
    };
    let scheme_end = base.find("://").map_or(0, |i| i + 3);
    let host = match base[scheme_end..].find('/') {
        Some(i) => &base[..scheme_end + i],
        None => base,
    };
    format!("{host}/{name}{query}")
}

impl FreshPg {
    /// Creates `pw_bench_<random>` on the server of `admin`.
    pub async fn create(admin: &str) -> anyhow::Result<FreshPg> {
        let mut b = [0u8; 6];
        getrandom::fill(&mut b).map_err(|e| anyhow::anyhow!("random name: {e}"))?;
        let name = bench_database_name(&format!("pw_bench_{}", hex::encode(b)))?;
        let mut c = sqlx::PgConnection::connect(admin)
            .await
            .with_context(|| "PostgreSQL unreachable (set --pg-url)".to_string())?;
        c.execute(AssertSqlSafe(format!("CREATE DATABASE {name}")))
            .await
            .context("CREATE DATABASE")?;
        c.close().await.ok();
        Ok(FreshPg {
            url: with_database(admin, &name),
            admin: admin.to_owned(),
            name,
        })
    }

    /// Drops the database (after every connection to it is closed or forced out).
    pub async fn drop_now(self) {
        if let Ok(mut c) = sqlx::PgConnection::connect(&self.admin).await {
            let Ok(name) = bench_database_name(&self.name) else {
                return;
            };
            let sql = format!("DROP DATABASE IF EXISTS {name} WITH (FORCE)");
            if let Err(e) = c.execute(AssertSqlSafe(sql)).await {
                eprintln!("   warning: could not drop {}: {e}", self.name);
            }
            c.close().await.ok();
        }
    }
}

/// The service on 127.0.0.1:0 over `store`, no fitting workers (nothing but the measured
/// requests uses the cores), with a key of `role`.
pub struct Server {
    pub addr: SocketAddr,
    pub key: String,
    pub client: reqwest::Client,
    stop: Option<oneshot::Sender<()>>,
    handle: Option<JoinHandle<anyhow::Result<()>>>,
}

impl Server {
    pub async fn start(store: &Store, role: Role) -> anyhow::Result<Server> {
        let (_, key) = store.create_api_key(role, "bench").await?;
        let mut settings = Settings {
            workers: 0,
            ..Settings::default()
        };
        settings.web.session_secret = SecretString::new("bench session secret");
        // One key sends every measured request: the per-key rate limit (default 20/s) is off, so
        // the suite measures the service, not the limiter.
        settings.http.rate_limit_per_s = 0.0;
        let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await?;
        let addr = listener.local_addr()?;
        let (tx, rx) = oneshot::channel::<()>();
        let run_store = store.clone();
        let handle = tokio::spawn(async move {
            pantowatch::server::run(listener, run_store, &settings, async {
                let _ = rx.await;
            })
            .await
        });
        let client = reqwest::Client::builder()
            .timeout(Duration::from_secs(60))
            .connect_timeout(Duration::from_secs(5))
            .no_proxy()
            .pool_max_idle_per_host(64)
            .build()?;
        Ok(Server {
            addr,
            key,
            client,
            stop: Some(tx),
            handle: Some(handle),
        })
    }

    pub fn url(&self, path: &str) -> String {
        format!("http://{}{path}", self.addr)
    }

    /// Stops accepting, answers what is in flight and waits for the server task.
    pub async fn stop(mut self) -> anyhow::Result<()> {
        if let Some(tx) = self.stop.take() {
            let _ = tx.send(());
        }
        if let Some(h) = self.handle.take() {
            h.await.context("server task")??;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::bench_database_name;

    #[test]
    fn only_generated_names_reach_sql() {
        assert!(bench_database_name("pw_bench_0123456789ab").is_ok());
        for bad in [
            "pw_bench_0123456789AB",
            "pw_bench_0123456789a",
            "pw_bench_0123456789abc",
            "pw_bench_01234567; DROP",
            "postgres",
            "",
        ] {
            assert!(bench_database_name(bad).is_err(), "{bad:?} accepted");
        }
    }
}

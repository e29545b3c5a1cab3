//! `pantowatch migrate`: connect to the configured database, apply every pending migration, exit
//! 0 — the one-shot step before API and worker replicas start (Kubernetes Job, compose service).

use anyhow::Context;

use super::serve::{ConfigArgs, open_store, runtime};
use crate::config::backend_name;

#[derive(Debug, clap::Args)]
pub struct MigrateArgs {
    #[command(flatten)]
    pub config: ConfigArgs,
}

/// Opening the store migrates it (concurrent migrators wait on the database's migration lock);
/// the check after it makes "exit 0" mean "every migration this binary knows is applied".
pub fn run(a: MigrateArgs) -> anyhow::Result<()> {
    let s = a.config.settings()?;
    runtime()?.block_on(async {
        let store = open_store(&s).await?;
        let applied = store
            .migrations_applied()
            .await
            .context("reading the migration state");
        store.close().await;
        if !applied? {
            anyhow::bail!("the database is not fully migrated (a failed or foreign migration?)");
        }
        eprintln!(
            "pantowatch: {} database migrated",
            backend_name(&s.database.url)
        );
        Ok(())
    })
}

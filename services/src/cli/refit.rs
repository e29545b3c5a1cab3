//! `pantowatch refit [--vehicle ID]`: queue a fit by the current model version for every trace
//! (or one vehicle's) that has none — after a model change. Running workers pick them up.

use pantowatch_models::report::MODEL_VERSION;

use super::serve::{ConfigArgs, open_store, runtime};
use crate::ids::VehicleId;

#[derive(Debug, clap::Args)]
pub struct RefitArgs {
    #[command(flatten)]
    pub config: ConfigArgs,
    /// Only this vehicle's traces.
    #[arg(long)]
    pub vehicle: Option<String>,
}

pub fn run(a: RefitArgs) -> anyhow::Result<()> {
    let s = a.config.settings()?;
    let vehicle = a
        .vehicle
        .as_deref()
        .map(|v| VehicleId::parse("--vehicle", v))
        .transpose()?;
    runtime()?.block_on(async {
        let store = open_store(&s).await?;
        let n = match &vehicle {
            Some(v) => store.requeue_vehicle(v.as_str(), MODEL_VERSION).await?,
            None => store.requeue_all(MODEL_VERSION).await?,
        };
        store.close().await;
        println!("queued {n} fits (model version {MODEL_VERSION})");
        Ok(())
    })
}

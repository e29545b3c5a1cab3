//! `pantowatch keys create|list|revoke`: API keys. A created key is printed once, on stdout
//! alone (`KEY=$(pantowatch keys create --role reader)`); only its hash is stored.

use super::serve::{ConfigArgs, open_store, runtime};
use crate::store::Role;

#[derive(Debug, clap::Args)]
pub struct KeysArgs {
    #[command(subcommand)]
    pub command: KeysCommand,
}

#[derive(Debug, clap::Subcommand)]
pub enum KeysCommand {
    /// Create a key and print it (once).
    Create {
        #[command(flatten)]
        config: ConfigArgs,
        /// reader (reads), writer (also uploads) or admin (also keys and re-fits).
        #[arg(long, value_parser = parse_role)]
        role: Role,
        /// Who or what uses the key.
        #[arg(long, default_value = "")]
        label: String,
    },
    /// List keys (never the keys themselves).
    List {
        #[command(flatten)]
        config: ConfigArgs,
    },
    /// Revoke a key by id.
    Revoke {
        #[command(flatten)]
        config: ConfigArgs,
        id: i64,
    },
}

fn parse_role(s: &str) -> Result<Role, String> {
    s.parse::<Role>()
        .map_err(|_| "reader, writer or admin".to_owned())
}

pub fn run(a: KeysArgs) -> anyhow::Result<()> {
    let config = match &a.command {
        KeysCommand::Create { config, .. }
        | KeysCommand::List { config }
        | KeysCommand::Revoke { config, .. } => config.clone(),
    };
    let s = config.settings()?;
    runtime()?.block_on(async {
        let store = open_store(&s).await?;
        let res = match a.command {
            KeysCommand::Create { role, label, .. } => {
                let (k, secret) = store.create_api_key(role, &label).await?;
                eprintln!(
                    "created {} key {} (prefix {}); it is shown once:",
                    k.role, k.id, k.prefix
                );
                println!("{secret}");
                Ok(())
            }
            KeysCommand::List { .. } => {
                println!(
                    "{:>4} {:<8} {:<7} {:<25} {:<10} label",
                    "id", "prefix", "role", "created", "revoked"
                );
                for k in store.list_api_keys().await? {
                    println!(
                        "{:>4} {:<8} {:<7} {:<25} {:<10} {}",
                        k.id,
                        k.prefix,
                        k.role,
                        k.created_at.format("%Y-%m-%d %H:%M:%S UTC"),
                        if k.revoked_at.is_some() { "yes" } else { "no" },
                        k.label
                    );
                }
                Ok(())
            }
            KeysCommand::Revoke { id, .. } => {
                if store.revoke_api_key(id).await? {
                    println!("key {id} revoked");
                    Ok(())
                } else {
                    Err(anyhow::anyhow!("no unrevoked key with id {id}"))
                }
            }
        };
        store.close().await;
        res
    })
}

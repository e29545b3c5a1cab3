//! pantowatch service library: trace documents, storage, the HTTP API, background fitting.
//! The binary in `main.rs` wires these modules into the CLI.

pub mod alerts;
pub mod alloc;
pub mod api;
pub mod app;
pub mod cli;
pub mod config;
pub mod evidence;
pub mod fitting;
pub mod fleet_prior;
pub mod health;
pub mod ids;
pub mod ingest;
pub mod json_keys;
pub mod plan_index;
pub mod plot;
pub mod pooled;
pub mod server;
pub mod static_force;
pub mod store;
pub mod trace;
pub mod trace_csv;
pub mod web;
pub mod webhooks;
pub mod worker;

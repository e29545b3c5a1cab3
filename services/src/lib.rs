//! pantowatch service library: trace storage, HTTP API, background fitting.
//! The binary in `main.rs` wires these modules into the CLI.

pub mod cli;
pub mod plot;
pub mod store;
pub mod trace;

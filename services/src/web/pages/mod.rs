//! One module per page: the handler and the `maud` markup of its body.

pub mod alerts;
pub mod fleet;
pub mod login;
pub mod pantograph;
pub mod trace;

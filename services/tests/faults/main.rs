//! Fault drills as tests (issue 7): graceful shutdown, a worker killed mid-fit, two APIs and two
//! workers on one PostgreSQL, PostgreSQL restarted under load, a full or read-only database.
//!
//! Real processes are the `pantowatch` binary of this build; PostgreSQL is the shared server
//! (`PANTOWATCH_TEST_PG_URL`, as in `tests/api`) except for the restart drill, which starts a
//! private throw-away cluster (the shared one is never restarted). Figures are printed on
//! stderr (`-- --nocapture`) and recorded in docs/reliability/faults.md.

#[allow(dead_code)]
#[path = "../api/harness.rs"]
mod harness;
mod procs;

mod every_job_ends;
mod kill;
mod metrics;
mod pg_restart;
mod scale;
mod shutdown;
mod storage;

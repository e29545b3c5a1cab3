//! # pantowatch-models
//!
//! The physics of pantowatch: the 160EC pantograph as data, single-joint test simulation with
//! the paper's friction laws and true stick–slip, and friction identification with confidence
//! intervals. Pure computation: no I/O, no async, no knowledge of storage or HTTP.
//!
//! # Layout
//! - [`data`] — the pantograph type file (Table 2, Table 4, test rigs), parsed and validated.
//! - [`rig`] — a test rig's body and attachments lumped into the equation's totals.
//! - [`friction`] — friction laws and their parameter derivatives.
//! - [`dynamics`] — the one-degree-of-freedom equation of motion, implicit in the reaction force.
//! - [`ode`] — Dormand–Prince 5(4) with dense output.
//! - [`simulate`] — event-driven stick–slip simulation with forward sensitivities.
//! - [`signal`] — local polynomial smoothing and differentiation of sampled signals.
//! - [`identify`] — first estimate by inverse dynamics, bounded Levenberg–Marquardt, intervals.
//! - [`drift`] — drift status of identified parameters against the Table 4 baseline.
//! - [`noise`] — a small deterministic random source for synthetic traces.

pub mod data;
pub mod drift;
pub mod dynamics;
pub mod friction;
pub mod identify;
pub mod noise;
pub mod ode;
pub mod rig;
pub mod signal;
pub mod simulate;

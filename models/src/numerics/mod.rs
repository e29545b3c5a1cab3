//! Numerical building blocks with no pantograph in them: the integrators, statistics, signal
//! smoothing, a deterministic noise source, and a fit's evaluation budget.

pub mod budget;
pub mod noise;
pub mod ode;
pub mod signal;
pub mod stats;

//! The lower articulated quadrangle swing test (paper, Fig 12 and Section 5.1): the frame, lower
//! arm, coupling rod and upper arm (joints J1, J2, J2′, J3), a one-DOF four-bar, swinging freely.
//!
//! - [`model`] — the four-bar on a frame inclined at γ: closed-form loop closure, derivatives in
//!   α, equation of motion with every joint's reaction and reaction-driven friction.
//! - [`simulate`] — a free swing with true stick–slip (events at each rate reversal).
//! - [`identify`] — MAP fit of the four joints' friction (Table 4 prior), release and sensor
//!   zeros as nuisance, informed/uninformed verdicts.
//! - [`report`] — the fit as the contract's fit result (joints J1, J2, J2′, J3).
//!
//! Data: the 160EC geometry file of the lift model (`models/data/160ec-geometry.toml`), whose
//! lower-loop bodies and joints this test detaches; the lift's upper loop, head and drive are
//! not part of it.

pub mod identify;
pub mod model;
pub mod report;
pub mod simulate;

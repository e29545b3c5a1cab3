//! The complete pantograph (issue 5): the two articulated quadrangles, the suspension shaft
//! and assemblies, and the head on its spring suspension, as a planar closed-chain model.
//!
//! - [`geometry`] — the geometry file (assumed links, Table 2 masses, Table 4 friction).
//! - [`topology`] — bodies and joints of Fig 3.
//! - [`vec2`] — the plane's vectors and rotations.
//! - [`kinematics`] — loop closure in closed form, derivatives in α.
//! - [`dynamics`] — equations of motion in (α, h), reactions, friction from the reactions.
//! - [`statics`] — static drive torque (frictionless or at impending motion), equilibria.
//! - [`static_force`] — the strip force over height, raising and lowering (EN 50206-1), with a band.
//! - [`gauge`] — the `static_force` test kind: a force-gauge record fitted for the joints' dry μ.
//! - [`simulate`] — a lift test driven by its recorded inputs, with dissipated energies.
//! - [`protocol`] — a lift test as the stand records it (drive damper, spring, cut weight).
//! - [`design`] — what a protocol tells (Fisher, predicted sds), the stand's limits, D-optimal moves.
//! - [`sensors`] — the stand's sensor noise and logger steps on every channel, inputs too.
//! - [`sensitivity`] — ∂H/∂θ along a simulated lift (friction of every joint, torque offset).
//! - [`readout`] — H and its partials tabulated over α (geometry only), read at every sample.
//! - [`report`] — a lift fit as the contract's fit result (every joint J1…J9).
//! - [`effects`] — effects a lift fit can name on a model error (`quadratic_drag`, `sensor_delay`).
//! - [`residual`] — what a fit leaves in H against the noise; when joint statuses are withheld.
//! - [`holdout`] — the held-out test: refit without every fourth 0.5 s block, judged on them.
//! - [`inputs`] — measured inputs reconstructed before a fit: noise per channel, smoothing, steps.
//! - [`input_noise`] — the inputs' sensor noise propagated into a lift fit's intervals.
//! - [`attribution`] — which friction parameters a fit tells apart; combinations of the rest.
//! - [`identify`] — Fisher information per trace, MAP fit with Table 4 as prior, verdicts.
//! - [`posterior`] — an effect's prior, the information's inverse, correlations: below every fit.
//! - [`batch`] — many lift fits on all cores, results in input order, progress by callback.
//! - `integrate` — DOPRI5 or Rosenbrock-W over a sampled record, dense output at the samples.

pub mod absorbed;
pub mod attribution;
pub mod batch;
pub mod design;
pub mod dynamics;
pub mod effects;
pub mod fit;
pub mod fleet_prior;
pub mod gauge;
pub mod geometry;
pub mod holdout;
pub mod identify;
pub mod input_noise;
pub mod inputs;
mod integrate;
pub mod kinematics;
pub mod posterior;
pub mod protocol;
pub mod readout;
pub mod report;
pub mod residual;
pub mod sensitivity;
pub mod sensors;
pub mod simulate;
pub mod static_force;
pub mod statics;
pub mod topology;
pub mod vec2;

//! # pantowatch-models
//!
//! The physics of pantowatch: the 160EC pantograph as data, single-joint test simulation with
//! the paper's friction laws and true stick–slip, and friction identification with confidence
//! intervals. Pure computation: no I/O, no async, no knowledge of storage or HTTP.
//!
//! # Layout
//! - [`budget`] — a fit's evaluation budget and stop flag, charged by the fitters.
//! - [`data`] — the pantograph type file (Table 2, Table 4, test rigs), parsed and validated.
//! - [`rig`] — a test rig's body and attachments lumped into the equation's totals.
//! - [`friction`] — friction laws and their parameter derivatives.
//! - [`dynamics`] — the one-degree-of-freedom equation of motion, implicit in the reaction force.
//! - [`ode`] — Dormand–Prince 5(4) with dense output.
//! - [`simulate`] — event-driven stick–slip simulation with forward sensitivities.
//! - [`signal`] — local polynomial smoothing and differentiation of sampled signals.
//! - [`identify`] — first estimate by inverse dynamics, bounded Levenberg–Marquardt, intervals.
//! - [`lift`] — the complete pantograph: closed-chain multibody model, lift-test simulation.
//! - [`quadrangle`] — the lower quadrangle's free swing (Fig 12): four-bar model, stick–slip
//!   simulation, MAP friction fit of J1, J2, J2′, J3.
//! - [`drift`] — drift status of identified parameters against the Table 4 baseline.
//! - [`testspec`] — a test described as data, completed with the pantograph type's defaults.
//! - [`report`] — the contract's fit result.
//! - [`synth`] — synthetic traces: simulate, add sensor noise and quantisation.
//! - [`stats`] — shared statistics (a leaf): whiteness, noise from differences, t/χ²/normal
//!   quantiles.
//! - [`trend`] — wear trends over a joint's history, forecasts of the alarm-band crossing.
//! - [`noise`] — a small deterministic random source for synthetic traces.

// Numerical kernels index several arrays with one counter; iterator chains would hide that.
#![allow(clippy::needless_range_loop)]

pub mod budget;
pub mod data;
pub mod drift;
pub mod dynamics;
pub mod friction;
pub mod identify;
pub mod lift;
pub mod noise;
pub mod ode;
pub mod quadrangle;
pub mod report;
pub mod residual;
pub mod rig;
pub mod signal;
pub mod simulate;
pub mod stats;
pub mod synth;
pub mod testspec;
pub mod trend;

use drift::DriftThresholds;
use identify::{FitError, FitOptions, FitOutcome, JointTest};
use report::FitResult;
use testspec::Baseline;

/// Identify a single-joint test end to end: release, first estimate, base fit with intervals,
/// the residual loop (effects held out and judged), drift status against `baseline`.
///
/// When the residual loop accepts an effect, the joint's parameters are those of the model with
/// the effect (the base model's would be biased by what it lacks); otherwise the base model's.
pub fn fit_joint_test(
    test: &JointTest,
    baseline: &Baseline,
    thresholds: &DriftThresholds,
    trace_id: &str,
    opts: &FitOptions,
) -> Result<(FitResult, FitOutcome), FitError> {
    let (result, fit, _) = fit_joint_test_with_finding(test, baseline, thresholds, trace_id, opts)?;
    Ok((result, fit))
}

/// As [`fit_joint_test`], also returning the residual loop's full finding (candidates tried,
/// diagnosis, split fits) for reports.
pub fn fit_joint_test_with_finding(
    test: &JointTest,
    baseline: &Baseline,
    thresholds: &DriftThresholds,
    trace_id: &str,
    opts: &FitOptions,
) -> Result<(FitResult, FitOutcome, residual::Finding), FitError> {
    let full = identify::fit_base(test, opts)?;
    let finding = residual::analyse(test, &full, opts)?;
    // The rig's stated body uncertainty (issue 17, point 1) in the reported fit's intervals.
    let reported =
        identify::carry_body_uncertainty(test, finding.augmented.clone().unwrap_or(full), opts);
    let units = match test.dof.mech {
        dynamics::Mechanism::Pendulum(_) => ("rad", "rad/s"),
        dynamics::Mechanism::Slider(_) => ("m", "m/s"),
    };
    let result = FitResult {
        trace_id: trace_id.to_string(),
        joints: vec![report::joint_result(&reported, baseline, thresholds)],
        rmse: report::Quantity {
            value: reported.rmse,
            unit: test.unit.to_string(),
        },
        residual: finding.residual.clone(),
        fit: report::details(
            &reported,
            test.t_s[reported.start],
            &identify::release_of(test)?,
            units,
            test.unit,
        ),
        pooled: None,
        combinations: Vec::new(),
    };
    Ok((result, reported, finding))
}

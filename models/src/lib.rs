//! # pantowatch-models
//!
//! The physics of pantowatch: the 160EC pantograph as data, single-joint test simulation with
//! the paper's friction laws and true stick–slip, and friction identification with confidence
//! intervals. Pure computation: no I/O, no async, no knowledge of storage or HTTP.
//!
//! # Layout
//! Grouped by what a reader looks for; the crate root re-exports each module under its own name
//! (`pantowatch_models::friction`), so callers need not know the folder.
//! - [`data`] — the pantograph type file (Table 2, Table 4, test rigs), parsed and validated.
//! - [`numerics`] — no pantograph inside: [`ode`] (Dormand–Prince 5(4), Rosenbrock-W),
//!   [`stats`] (a leaf: whiteness, noise from differences, t/χ²/normal quantiles), [`signal`]
//!   (local polynomial smoothing and differentiation), [`noise`] (a deterministic random
//!   source), [`budget`] (a fit's evaluation budget and stop flag).
//! - [`joint`] — one joint on its rig: [`rig`], [`friction`] (laws and their derivatives),
//!   [`dynamics`] (the one-degree-of-freedom equation, implicit in the reaction force),
//!   [`simulate`] (event-driven stick–slip with forward sensitivities), [`synth`] (synthetic
//!   traces), [`identify`] (inverse-dynamics start, bounded Levenberg–Marquardt, intervals),
//!   [`residual`] (the residual loop and its effect vocabulary).
//! - [`lift`] — the complete pantograph: closed-chain multibody model, lift tests, force gauges.
//! - [`quadrangle`] — the lower quadrangle's free swing (Fig 12): four-bar model, stick–slip
//!   simulation, MAP friction fit of J1, J2, J2′, J3.
//! - [`contract`] — what a fit means to the service: [`report`] (the contract's fit result),
//!   [`testspec`] (a test as data, with the type's defaults), [`drift`] (status against Table 4),
//!   [`trend`] (wear trends, forecasts of the alarm-band crossing).

// Numerical kernels index several arrays with one counter; iterator chains would hide that.
#![allow(clippy::needless_range_loop)]

pub mod contract;
pub mod data;
pub mod joint;
pub mod lift;
pub mod numerics;
pub mod quadrangle;

pub use contract::{drift, evidence, plan, report, testspec, trend};
pub use joint::{dynamics, friction, identify, residual, rig, simulate, synth};
pub use numerics::{budget, noise, ode, signal, stats};

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
    let mut result = FitResult {
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
        pooled_rig: None,
    };
    contract::withhold::if_unexplained(&mut result, finding.diagnosis.noise_sigma);
    Ok((result, reported, finding))
}

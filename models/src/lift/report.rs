//! A lift trace's fit as the contract's fit result (`../shared/contract/TRACE_FORMAT.md`, "Fit
//! result"): every joint J1…J9 with value, 95 % interval, Table 4 baseline, unit, whether the
//! trace informed it, and its drift status.
//!
//! Mapping (stated here so the service knows no physics):
//! - A parameter the trace informed (posterior sd < prior sd / 2, [`super::identify`]) is
//!   reported at its MAP estimate with the posterior interval and judged against Table 4 by the
//!   drift bands. An uninformed one is reported at baseline with the prior's interval,
//!   `identifiable: false`, status `unknown` — never flagged.
//! - J6 is locked in a lift (the spring assemblies ride on the shaft): nothing to estimate, it
//!   is reported at baseline, not identified.
//! - J9 is a spring with damping: the model has no dry friction there (Table 4 gives none), so
//!   its `dry` is 0 with no baseline, not identified.
//! - J8's coefficients are per slide (Table 4: four slides in parallel), J9's per spring.
//! - `rmse` is the H residual RMS, m. The torque-sensor offset (a nuisance parameter) is the
//!   result's `fit.sensor_offset`, N·m.
//! - `residual`: diagnosed by [`super::residual`]. When the residual exceeds the sensor noise
//!   by [`super::residual::MODEL_ERROR_RATIO`] the model is missing something a friction refit
//!   has absorbed: the verdict is `unexplained` with what the residual correlates with, and
//!   every joint (combinations included) is withheld — not identified, `unknown` — so the fit
//!   raises no alert and changes no joint's health. Above [`super::residual::EFFECT_TRY_RATIO`]
//!   the lift vocabulary is tried ([`super::effects`]: `quadratic_drag`, then `sensor_delay`);
//!   a named effect's fit replaces the plain one (joints from it; `rmse_before` the plain fit's,
//!   `rmse_after` the augmented one's). The `holdout_` pair comes from [`super::holdout`]: every
//!   fourth 0.5 s block left out of a refit, its error there — run where effects are tried;
//!   elsewhere (and on a record too short for it) `holdout_note` says so and the pair repeats
//!   the fitted RMSE.

use std::ops::ControlFlow;
use std::sync::OnceLock;

use super::attribution::Combination;
use super::dynamics::LiftModel;
use super::identify::{JointEstimate, LiftFit, LiftFitError, LiftFitOptions, LiftTrace, fit_map};
use super::sensitivity::LiftParam;
use super::simulate::LiftInputs;
use super::topology::RevJoint;
use crate::contract::drift::{DriftThresholds, Status};
use crate::contract::report::{
    CombinationResult, FitDetails, FitResult, JointResult, MODEL_VERSION, ParamResult, Quantity,
    ResidualResult,
};
use crate::numerics::stats::Z95;

mod candidates;
mod channels;
mod pooled;
mod residual_loop;
mod work;
use candidates::{Candidate, Named, STOP_RATIO, tried_in_order, try_candidate};
pub use channels::LiftChannels;
pub use pooled::{
    fit_pooled_lift_and_gauge_traces, fit_pooled_lift_and_gauge_traces_with, fit_pooled_lift_traces,
};
pub use residual_loop::NO_HOLDOUT_NEEDED;
use residual_loop::residual_loop;
pub use work::LoopStep;
use work::Meter;

/// A lift fit: the contract result, the MAP fit, and the fitted H (for plots).
#[derive(Debug, Clone)]
pub struct LiftReport {
    pub result: FitResult,
    pub fit: LiftFit,
    /// Model H at the fitted parameters, m (the fit's last accepted evaluation).
    pub fitted_height_m: Vec<f64>,
    /// When an effect is named: the plain model's fitted H, m (before), for plots.
    pub plain_fitted_height_m: Option<Vec<f64>>,
    /// What each step of the residual loop cost, in order ([`LoopStep`]; empty for a pooled
    /// fit): where a lift's time goes, measured in work that does not depend on the machine.
    pub work: Vec<LoopStep>,
}

/// The built-in 160EC model, made once per process: its H read-out table (2,000 closed-form
/// poses, ~1 ms) is geometry only and serves every fit after the first.
fn builtin_model() -> &'static LiftModel {
    static MODEL: OnceLock<LiftModel> = OnceLock::new();
    MODEL.get_or_init(|| LiftModel::new(super::geometry::builtin_160ec()))
}

/// The plain model's fit of one lift trace alone: the first step of [`fit_lift_trace`], the
/// same code, without the residual loop after it (the bench suite times the loop against it).
pub fn fit_plain_lift(
    channels: &LiftChannels,
    thresholds: &DriftThresholds,
) -> Result<LiftFit, LiftFitError> {
    let (trace, opts) = lift_trace(channels, thresholds)?;
    fit_map(builtin_model(), &[trace], &opts)
}

/// The trace of `channels`, checked, and the fit's options with these drift bands.
fn lift_trace<'a>(
    channels: &LiftChannels<'a>,
    thresholds: &DriftThresholds,
) -> Result<(LiftTrace<'a>, LiftFitOptions), LiftFitError> {
    let opts = LiftFitOptions {
        thresholds: *thresholds,
        ..LiftFitOptions::default()
    };
    let inputs = LiftInputs {
        t_s: channels.t_s,
        torque_nm: channels.torque_nm,
        fs_n: channels.fs_n,
        fm_n: channels.fm_n,
    };
    inputs.validate()?;
    if channels.strip_height_m.len() != channels.t_s.len() {
        return Err(LiftFitError::Invalid(format!(
            "H has {} samples, t has {}",
            channels.strip_height_m.len(),
            channels.t_s.len()
        )));
    }
    let trace = LiftTrace {
        inputs,
        strip_height_m: channels.strip_height_m,
    };
    Ok((trace, opts))
}

/// Fit one lift trace with the MAP identification (Table 4 prior, [`LiftFitOptions::default`]
/// with these drift bands) and map it to the contract's fit result; where the plain model
/// leaves a model error, the residual loop (vocabulary, refit, held-out test). Then what the
/// record can vouch for (`absorbed::judge`): a flag the data do not demand, or whose fit leaves a
/// phase unexplained, is withdrawn; on a record that does not lower the strip the level carries
/// the raise's systematic term, on one that does a term grown with what the check saw.
pub fn fit_lift_trace(
    channels: &LiftChannels,
    thresholds: &DriftThresholds,
    trace_id: &str,
) -> Result<LiftReport, LiftFitError> {
    fit_lift_trace_with(channels, thresholds, trace_id, &[])
}

/// [`fit_lift_trace`] with `friction_prior` for the parameters it names
/// (`LiftFitOptions::friction_prior`: the fleet's, `fleet_prior::FleetPrior::for_fit`).
pub fn fit_lift_trace_with(
    channels: &LiftChannels,
    thresholds: &DriftThresholds,
    trace_id: &str,
    friction_prior: &[(LiftParam, f64, f64)],
) -> Result<LiftReport, LiftFitError> {
    let mut report = residual_loop(channels, thresholds, trace_id, friction_prior)?;
    let (trace, mut opts) = lift_trace(channels, thresholds)?;
    opts.friction_prior = friction_prior.to_vec();
    let judge = super::absorbed::judge::undemanded_flags;
    judge(
        builtin_model(),
        &trace,
        &report.fit,
        &opts,
        &mut report.result,
    )?;
    super::absorbed::judge::widen_level(
        &mut report.result,
        thresholds,
        channels.t_s,
        &report.fitted_height_m,
    );
    Ok(report)
}

fn unit_of(joint: &str, kind: &str) -> &'static str {
    match (joint, kind) {
        (_, "dry") => "1",
        ("J8" | "J9", _) => "N·s/m",
        _ => "N·m·s/rad",
    }
}

/// A parameter the lift does not estimate: at baseline, the prior's interval, not identified.
fn not_estimated(baseline: Option<f64>, unit: &str, prior_relative_sd: f64) -> ParamResult {
    let b = baseline.unwrap_or(0.0);
    let half = Z95 * prior_relative_sd * b;
    ParamResult {
        value: b,
        ci95: [(b - half).max(0.0), b + half],
        baseline,
        unit: unit.into(),
        identifiable: false,
        status: Status::Unknown,
        combination: None,
    }
}

fn joint_result(
    model: &LiftModel,
    j: &JointEstimate,
    combos: &[Combination],
    prior_relative_sd: f64,
) -> JointResult {
    let f = &model.friction;
    let baseline = |kind: &str| -> Option<f64> {
        match (j.joint, kind) {
            ("J8", "viscous") => Some(f.j8_viscous_ns_per_m_each),
            ("J8", _) => Some(f.j8_dry_mu),
            ("J9", "viscous") => Some(f.j9_damping_ns_per_m_each),
            ("J9", _) => None,
            (name, kind) => RevJoint::ALL
                .iter()
                .find(|r| r.name() == name)
                .map(|r| match kind {
                    "viscous" => f.viscous_nms_per_rad[r.index()],
                    _ => f.dry_mu[r.index()],
                }),
        }
    };
    let param = |kind: &str, e: &Option<super::identify::ParamEstimate>| match e {
        Some(e) => ParamResult {
            value: e.value,
            ci95: e.ci95,
            baseline: Some(e.baseline),
            unit: unit_of(j.joint, kind).into(),
            identifiable: e.informed,
            // Judged by the drift bands when informed (`unknown` if its interval is still wider
            // than the watch band); an uninformed parameter is never flagged.
            status: e.status,
            combination: e.combination.and_then(|c| combos.get(c)).map(|c| c.label()),
        },
        None => not_estimated(baseline(kind), unit_of(j.joint, kind), prior_relative_sd),
    };
    let viscous = param("viscous", &j.viscous);
    let mut dry = param("dry", &j.dry);
    if j.joint == "J9" {
        dry.ci95 = [0.0, 0.0];
    }
    let status = [&viscous, &dry]
        .iter()
        .filter(|p| p.identifiable)
        .map(|p| p.status)
        .max()
        .unwrap_or(Status::Unknown);
    JointResult {
        joint: j.joint.to_string(),
        identifiable: viscous.identifiable || dry.identifiable,
        status,
        viscous,
        dry,
    }
}

/// A joint whose statuses a model error makes untrustworthy: its estimates stay for reading,
/// but it counts as not informed by this fit (status `unknown`, no alert, health unchanged).
fn withhold(j: &mut JointResult) {
    for p in [&mut j.viscous, &mut j.dry] {
        p.identifiable = false;
        p.status = Status::Unknown;
    }
    j.identifiable = false;
    j.status = Status::Unknown;
}

/// The contract's fit result of a one-trace lift fit, its joints withheld when the residual
/// shows a model error (module doc).
pub fn fit_result(
    model: &LiftModel,
    fit: &LiftFit,
    trace: &LiftTrace,
    fitted_height_m: &[f64],
    opts: &LiftFitOptions,
    trace_id: &str,
) -> FitResult {
    build_result(model, fit, trace, fitted_height_m, opts, trace_id, true)
}

/// [`fit_result`], with the model-error gate on (`gate`) or only reported.
fn build_result(
    model: &LiftModel,
    fit: &LiftFit,
    trace: &LiftTrace,
    fitted_height_m: &[f64],
    opts: &LiftFitOptions,
    trace_id: &str,
    gate: bool,
) -> FitResult {
    let mut joints: Vec<JointResult> = fit
        .joints
        .iter()
        .map(|j| joint_result(model, j, &fit.combinations, opts.prior_relative_sd))
        .collect();
    joints.extend(fit.combinations.iter().map(|c| combination_joint(c, opts)));
    let combinations: Vec<CombinationResult> = fit
        .combinations
        .iter()
        .map(Combination::to_result)
        .collect();
    let rmse = fit.rmse_m.first().copied().unwrap_or(f64::NAN);
    let offset = fit.offsets.first();
    let residual: Vec<f64> = if fitted_height_m.len() == trace.strip_height_m.len() {
        fitted_height_m
            .iter()
            .zip(trace.strip_height_m)
            .map(|(a, b)| b - a)
            .collect()
    } else {
        Vec::new()
    };
    let diag = super::residual::diagnose(
        trace.inputs.t_s,
        &residual,
        fitted_height_m,
        trace.inputs.torque_nm,
        opts.h_noise_m.max(super::residual::GATE_FLOOR_M),
    );
    let withheld = gate && !diag.trusted;
    if withheld {
        for j in &mut joints {
            withhold(j);
        }
    }
    let combinations = if !withheld {
        combinations
    } else {
        combinations
            .into_iter()
            .map(|mut c| {
                c.identifiable = false;
                c.status = Status::Unknown;
                c
            })
            .collect()
    };
    FitResult {
        trace_id: trace_id.to_string(),
        joints,
        rmse: Quantity {
            value: rmse,
            unit: "m".into(),
        },
        residual: ResidualResult {
            effects: Vec::new(),
            rmse_before: rmse,
            rmse_after: rmse,
            holdout_rmse_before: rmse,
            holdout_rmse_after: rmse,
            verdict: withheld.then(|| "unexplained".to_string()),
            correlates_with: if withheld {
                diag.correlates_with.clone()
            } else {
                Vec::new()
            },
            excess_ratio: Some(diag.excess_ratio).filter(|v| v.is_finite()),
            joints_withheld: withheld.then(|| {
                format!(
                    "the fit leaves {:.1}× the sensor noise in H (RMS {:.2} mm against {:.2} mm; \
                     over {:.0}× means the model misses an effect the friction estimates absorbed): \
                     joint statuses from this fit are not trustworthy and raise no alert",
                    diag.excess_ratio,
                    diag.rms_m * 1e3,
                    diag.rms_m / diag.excess_ratio * 1e3,
                    super::residual::MODEL_ERROR_RATIO
                )
            }),
            holdout_note: None,
            autocorrelation: super::residual::autocorrelation(trace.inputs.t_s, &residual),
            autocorrelation_before: Vec::new(),
            ambiguity: None,
            halves: None,
        },
        fit: FitDetails {
            model_version: MODEL_VERSION.to_string(),
            release_t_s: trace.inputs.t_s.first().copied().unwrap_or(0.0),
            release_rule: crate::joint::identify::release::ReleaseRule::FirstSample.as_str().to_owned(),
            release_warning: None,
            release_disturbed_until_s: None,
            release_disturbance: None,
            release_position: Quantity {
                value: trace.strip_height_m.first().copied().unwrap_or(f64::NAN),
                unit: "m".into(),
            },
            release_rate: Quantity {
                value: 0.0,
                unit: "m/s".into(),
            },
            sensor_offset: Quantity {
                value: offset.map_or(0.0, |o| o.value),
                unit: "N·m".into(),
            },
            sensor_offset_ci95: offset.map(|o| o.ci95),
            input_offset: None,
            input_offset_ci95: None,
            samples_fitted: trace.strip_height_m.len(),
            termination: format!("{:?}", fit.termination),
            iterations: fit.iterations,
            residual_rho1: diag.rho1,
            // Noise scale over the stated σ_H (≥ 1): the posterior is widened by it.
            interval_inflation: fit.noise_m / opts.h_noise_m,
            // Not defined for a many-joint fit (null in JSON); the posterior correlations are
            // in `LiftFit::posterior_correlation`.
            viscous_dry_correlation: f64::NAN,
            body_uncertainty: None,
            absorption: None,
            prior: None,
        },
        pooled: None,
        combinations,
        pooled_rig: None,
    }
}

/// A combination as an entry of `joints`, so health, trends and alerts judge it like a joint:
/// named by its members' joints (`J1+J3`), the level (relative to Table 4, baseline 1) in the
/// slot of its members' kind (`dry` when the kinds differ, the name then carrying the kinds:
/// `J3 dry+J8 viscous`), the other slot not estimated.
fn combination_joint(c: &Combination, opts: &LiftFitOptions) -> JointResult {
    let label = c.label();
    let kind = c.params[0].kind();
    let same_kind = c.params.iter().all(|p| p.kind() == kind);
    let name = if same_kind {
        label.trim_end_matches(&format!(" {kind}")).to_string()
    } else {
        label.clone()
    };
    let level = ParamResult {
        value: c.value,
        ci95: c.ci95,
        baseline: Some(1.0),
        unit: "× Table 4".into(),
        identifiable: c.informed,
        status: c.status,
        combination: Some(label),
    };
    let other = not_estimated(None, "× Table 4", opts.prior_relative_sd);
    let (viscous, dry) = if same_kind && kind == "viscous" {
        (level, other)
    } else {
        (other, level)
    };
    let identifiable = viscous.identifiable || dry.identifiable;
    JointResult {
        joint: name,
        status: if identifiable {
            c.status
        } else {
            Status::Unknown
        },
        identifiable,
        viscous,
        dry,
    }
}

#[cfg(test)]
mod tests;

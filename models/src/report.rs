//! The fit result of the trace format (contract `Fit result`): each joint's parameters with
//! 95 % intervals, baseline, identifiability and drift status; the RMSE; the residual block.

use serde::Serialize;

use crate::drift::{DriftThresholds, Status};
use crate::friction::DynParam;
use crate::identify::{FitOutcome, Param};
use crate::testspec::Baseline;

/// Version of the model and identification method; a fit is stored per trace and version.
/// 0.2: lift fits integrate their sensitivities with the Rosenbrock-W method (estimates move
/// by up to 0.3 posterior sd against 0.1's DOPRI5), so `pantowatch refit` queues them again.
pub const MODEL_VERSION: &str =
    "pantowatch-models/0.2 single-joint output-error LM; lift MAP (Rosenbrock-W); quadrangle MAP";

#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct ParamResult {
    pub value: f64,
    pub ci95: [f64; 2],
    pub baseline: Option<f64>,
    pub unit: String,
    pub identifiable: bool,
    pub status: Status,
    /// Set when the test informs this parameter only together with others: the label of the
    /// combination it is reported in (issue 15; a lift's `J1+J3 dry`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub combination: Option<String>,
}

/// A combination of parameters a test informs together (issue 15): the level the data pin,
/// each member over its Table 4 baseline weighted by its share (1 = every member at baseline).
/// It is also listed in `joints` under its label's joints (e.g. `J1+J3`), so health and alerts
/// judge it like a joint.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct CombinationResult {
    pub label: String,
    pub members: Vec<CombinationMember>,
    pub value: f64,
    pub ci95: [f64; 2],
    pub identifiable: bool,
    pub status: Status,
}

/// One member of a [`CombinationResult`].
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct CombinationMember {
    pub joint: String,
    /// `viscous` or `dry`.
    pub kind: String,
    pub weight: f64,
}

#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct JointResult {
    pub joint: String,
    pub viscous: ParamResult,
    pub dry: ParamResult,
    pub identifiable: bool,
    pub status: Status,
}

#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct Quantity {
    pub value: f64,
    pub unit: String,
}

#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct EffectResult {
    pub name: String,
    pub params: serde_json::Map<String, serde_json::Value>,
}

#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct ResidualResult {
    pub effects: Vec<EffectResult>,
    pub rmse_before: f64,
    pub rmse_after: f64,
    pub holdout_rmse_before: f64,
    pub holdout_rmse_after: f64,
    /// `unexplained` when structure remains that no candidate explains; otherwise absent.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub verdict: Option<String>,
    /// With `unexplained`: the signals the residual correlates with most (name, correlation).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub correlates_with: Vec<(String, f64)>,
    /// Residual RMS over the sensor noise estimated from its first differences (lift fits,
    /// issue 16); absent where not computed.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub excess_ratio: Option<f64>,
    /// Set when the fit's joint statuses are withheld (reported `unknown`, not identified, no
    /// alert) because the residual shows a model error: the reason, in words.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub joints_withheld: Option<String>,
    /// Set when no held-out test was run (lift fits: a segment too short, `lift::holdout`): the
    /// reason, in words; the `holdout_` pair then repeats the fitted RMSE.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub holdout_note: Option<String>,
    /// Lift fits (issue 16, point 5): the final residual's autocorrelation, (lag s, ρ) at
    /// `lift::residual::ACF_LAGS_S`; white noise reads ≈ 0 at every lag.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub autocorrelation: Vec<(f64, f64)>,
    /// With a named lift effect: the plain model's residual autocorrelation, the same lags.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub autocorrelation_before: Vec<(f64, f64)>,
}

/// How the fit was made: the release, the fitted start and sensor zero, the optimiser's end.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct FitDetails {
    pub model_version: String,
    /// Time of the first sample of free motion used in the fit.
    pub release_t_s: f64,
    /// How the release was decided: `stated` (`test.release_t_s`), `first_sample`,
    /// `after_hold` or `turning_point` (`identify::release`).
    pub release_rule: &'static str,
    /// Why the release may be wrong, when the data do not decide it clearly.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub release_warning: Option<String>,
    pub release_position: Quantity,
    pub release_rate: Quantity,
    pub sensor_offset: Quantity,
    pub sensor_offset_ci95: Option<[f64; 2]>,
    pub samples_fitted: usize,
    pub termination: String,
    pub iterations: usize,
    /// Residual lag-1 autocorrelation and the interval inflation applied for it.
    pub residual_rho1: f64,
    pub interval_inflation: f64,
    /// Correlation of the viscous and dry estimates.
    pub viscous_dry_correlation: f64,
}

#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct FitResult {
    pub trace_id: String,
    pub joints: Vec<JointResult>,
    pub rmse: Quantity,
    pub residual: ResidualResult,
    pub fit: FitDetails,
    /// Set on a pooled fit: the tests it fitted together (issue 15).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub pooled: Option<PooledTests>,
    /// Parameters the test informs only together (lift fits; issue 15).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub combinations: Vec<CombinationResult>,
}

/// The tests a pooled fit combined: the friction shared, one torque offset per test.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct PooledTests {
    /// Trace ids, newest first (the fit's `trace_id` is the first).
    pub trace_ids: Vec<String>,
    /// The window the tests were taken from, days before the newest.
    pub window_days: f64,
}

fn param(
    fit: &FitOutcome,
    p: DynParam,
    baseline: Option<f64>,
    unit: &str,
    th: &DriftThresholds,
) -> ParamResult {
    let (value, _, ci95) = fit
        .get(Param::Dyn(p))
        .unwrap_or((f64::NAN, f64::NAN, [f64::NAN; 2]));
    let v = th.judge(ci95, value, baseline);
    ParamResult {
        value,
        ci95,
        baseline,
        unit: unit.to_string(),
        identifiable: v.identifiable,
        status: v.status,
        combination: None,
    }
}

/// The joint's verdict from its parameters: identifiable when any parameter is; status the
/// worst of the identifiable parameters' (`unknown` when none is judged).
pub fn joint_result(fit: &FitOutcome, b: &Baseline, th: &DriftThresholds) -> JointResult {
    let viscous = param(fit, DynParam::Viscous, b.viscous, b.viscous_unit, th);
    let dry = param(fit, DynParam::Dry, b.dry, "1", th);
    let identifiable = viscous.identifiable || dry.identifiable;
    let status = [&viscous, &dry]
        .iter()
        .filter(|p| p.identifiable)
        .map(|p| p.status)
        .max()
        .unwrap_or(Status::Unknown);
    JointResult {
        joint: b.joint.clone(),
        viscous,
        dry,
        identifiable,
        status,
    }
}

/// Fit details for the report.
pub fn details(
    fit: &FitOutcome,
    t_release: f64,
    release: &crate::identify::release::Release,
    model_unit: (&str, &str),
    channel_unit: &str,
) -> FitDetails {
    let off = fit.get(Param::Offset);
    let corr = fit.covariance.correlation();
    let iv = fit
        .spec_params
        .iter()
        .position(|p| *p == Param::Dyn(DynParam::Viscous));
    let id = fit
        .spec_params
        .iter()
        .position(|p| *p == Param::Dyn(DynParam::Dry));
    FitDetails {
        model_version: MODEL_VERSION.to_string(),
        release_t_s: t_release,
        release_rule: release.rule.as_str(),
        release_warning: release.warning.clone(),
        release_position: Quantity {
            value: fit.q0,
            unit: model_unit.0.into(),
        },
        release_rate: Quantity {
            value: fit.v0,
            unit: model_unit.1.into(),
        },
        sensor_offset: Quantity {
            value: fit.offset,
            unit: channel_unit.into(),
        },
        sensor_offset_ci95: off.map(|o| o.2),
        samples_fitted: fit.n_fit,
        termination: format!("{:?}", fit.termination),
        iterations: fit.iterations,
        residual_rho1: fit.covariance.rho1,
        interval_inflation: fit.covariance.inflation,
        viscous_dry_correlation: match (iv, id) {
            (Some(a), Some(b)) => corr[(a, b)],
            _ => f64::NAN,
        },
    }
}

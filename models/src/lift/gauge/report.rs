//! A force-gauge record's fit as the contract's fit result, shaped as a lift's
//! (`lift::report`): every joint J1…J9, the combination the record informs, the residual block.
//!
//! Mapping (stated here so the service knows no physics):
//! - dry μ of J1, J2, J2', J3, J4, J5, J7: from the fit ([`super::fit`]); one separately
//!   identified is reported at its MAP with the posterior interval and judged by the drift bands;
//!   one that is not is at the prior's centre (Table 4, or the fleet's: [`fit_gauge_trace_with`])
//!   with the prior's interval, `identifiable: false`, `unknown`,
//!   and names its combination (`"combination": "J1+J3+… dry"`) where it is in one;
//! - every viscous coefficient, J6's dry (locked) and J8's dry (the slide rests at its
//!   frictionless travel): not estimated by a quasi-static test — the prior's centre (baseline ×
//!   m) and interval (± 1.96 s × baseline), not identified, `unknown`. J9 has no dry friction: 0,
//!   no baseline;
//! - each informed combination: in `combinations` and as an entry of `joints` named by its
//!   members (`J1+J2+J2'+J3+J4+J5`), the level in the `dry` slot, unit `× Table 4`, baseline 1;
//! - `rmse` in N; `residual.effects` the named effects (`sensor_offset`: `offset_n`,
//!   `offset_n_ci95`; `spring_rate`: `rate_factor`, `rate_factor_ci95`) with `rmse_before` the
//!   plain model's (no zero, no k) and `rmse_after` the final fit's; `verdict: "unexplained"` and every joint
//!   withheld (not identified, `unknown`) when the plain model leaves a model error no effect
//!   explains (`effects`); `excess_ratio` the final residual's RMS over the noise; no held-out test
//!   (`holdout_note` says why, the pair repeats the RMSE); read back by [`named_effect`] and
//!   [`spring_rate_of`] (the static-force prediction takes a named spring rate from there);
//! - `fit`: `sensor_offset` the gauge's zero b (N) with its interval, always fitted (a nuisance,
//!   as a lift's torque offset; named as the `sensor_offset` effect only by its margins);
//!   `interval_inflation` the noise scale over σ₀; release fields: the first reading.

use std::sync::OnceLock;

use super::super::attribution::Combination;
use super::super::dynamics::LiftModel;
use super::super::fit::ParamEstimate;
use super::super::geometry::{Geometry, builtin_160ec};
use super::super::sensitivity::LiftParam;
use super::super::static_force::{DriveLine, RateEstimate};
use super::super::topology::RevJoint;
use super::effects::{GaugeLoop, GaugeResidual, GaugeVerdict, fit_with_effects};
use super::fit::{GaugeFit, GaugeFitOptions};
use super::terms::{GaugeEffect, GaugeEffectEstimate};
use super::{GaugeError, GaugeRecord};
use crate::contract::drift::{DriftThresholds, Status};
use crate::contract::report::{
    CombinationResult, EffectResult, FitDetails, FitResult, JointResult, MODEL_VERSION,
    ParamResult, Quantity, ResidualResult,
};
use crate::numerics::stats::Z95;

/// The channels of a `static_force` trace: strip heights and gauge readings in reading order,
/// and the gauge's stated resolution (contract `test.gauge_resolution_n`).
#[derive(Debug, Clone, Copy)]
pub struct GaugeChannels<'a> {
    pub strip_height_m: &'a [f64],
    pub force_n: &'a [f64],
    pub resolution_n: f64,
}

/// A gauge record's fit: the contract result, the fit the joints come from, the plain one
/// when an effect was named, the verdict, and the record as split.
#[derive(Debug, Clone)]
pub struct GaugeReport {
    pub result: FitResult,
    pub verdict: GaugeVerdict,
    pub fit: GaugeFit,
    /// The plain model's fit when an effect was named (its readings for plots).
    pub plain_fit: Option<GaugeFit>,
    pub residual: GaugeResidual,
    pub record: GaugeRecord,
}

/// The built-in 160EC model, made once per process (its read-out table is geometry only).
fn builtin_model() -> &'static LiftModel {
    static MODEL: OnceLock<LiftModel> = OnceLock::new();
    MODEL.get_or_init(|| LiftModel::new(builtin_160ec()))
}

/// The built-in type's drive line and lower-arm range.
fn builtin_setup() -> (&'static Geometry, DriveLine, (f64, f64)) {
    let g = builtin_160ec();
    (
        g,
        DriveLine::from_lift_test(g),
        (g.alpha_min_rad, g.alpha_max_rad),
    )
}

/// The `holdout_note` of every gauge fit.
pub const NO_HOLDOUT: &str = "no held-out test: a force-gauge record has too few readings to \
     leave some out; the held-out pair repeats the fitted RMSE";

/// Check `channels` as a record of the built-in 160EC, fit it (the residual loop, `effects`)
/// and map it to the contract's fit result (module doc). Refusals name their field
/// ([`GaugeError::field`]).
pub fn fit_gauge_trace(
    channels: &GaugeChannels,
    thresholds: &DriftThresholds,
    trace_id: &str,
) -> Result<GaugeReport, GaugeError> {
    fit_gauge_trace_with(channels, thresholds, trace_id, &[])
}

/// [`fit_gauge_trace`] under `friction_prior` for the parameters it names
/// ([`GaugeFitOptions::friction_prior`]: the fleet's, `fleet_prior::FleetPrior::for_fit`); the
/// rest keep Table 4's. Empty: [`fit_gauge_trace`].
pub fn fit_gauge_trace_with(
    channels: &GaugeChannels,
    thresholds: &DriftThresholds,
    trace_id: &str,
    friction_prior: &[(LiftParam, f64, f64)],
) -> Result<GaugeReport, GaugeError> {
    let record = GaugeRecord::new(
        channels.strip_height_m.to_vec(),
        channels.force_n.to_vec(),
        channels.resolution_n,
    )?;
    let model = builtin_model();
    let (_, drive, ar) = builtin_setup();
    let opts = GaugeFitOptions {
        thresholds: *thresholds,
        friction_prior: friction_prior.to_vec(),
        ..GaugeFitOptions::default()
    };
    let lp = fit_with_effects(model, ar, &drive, &record, &opts)?;
    let result = gauge_result(model, &lp, &record, &opts, trace_id);
    Ok(GaugeReport {
        result,
        verdict: lp.verdict,
        plain_fit: lp.plain.map(|(f, _)| f),
        fit: lp.fit,
        residual: lp.residual,
        record,
    })
}

/// The contract's result of a residual loop's outcome on `record`.
pub fn gauge_result(
    model: &LiftModel,
    lp: &GaugeLoop,
    record: &GaugeRecord,
    opts: &GaugeFitOptions,
    trace_id: &str,
) -> FitResult {
    let fit = &lp.fit;
    let s = opts.prior_relative_sd;
    let mut joints: Vec<JointResult> = Vec::new();
    let f = &model.friction;
    for j in RevJoint::ALL {
        let i = j.index();
        let viscous = not_estimated(
            Some(f.viscous_nms_per_rad[i]),
            "N·m·s/rad",
            opts.prior_of(LiftParam::Viscous(j)),
        );
        let dry = match fit.params.iter().find(|p| p.param.joint() == j.name()) {
            Some(e) => estimated(e, &fit.combinations),
            None => not_estimated(Some(f.dry_mu[i]), "1", opts.prior_of(LiftParam::Dry(j))),
        };
        joints.push(joint(j.name(), viscous, dry));
    }
    joints.push(joint(
        "J8",
        not_estimated(
            Some(f.j8_viscous_ns_per_m_each),
            "N·s/m",
            opts.prior_of(LiftParam::J8Viscous),
        ),
        not_estimated(Some(f.j8_dry_mu), "1", opts.prior_of(LiftParam::J8Dry)),
    ));
    let mut j9_dry = not_estimated(None, "1", (1.0, s));
    j9_dry.ci95 = [0.0, 0.0];
    joints.push(joint(
        "J9",
        not_estimated(
            Some(f.j9_damping_ns_per_m_each),
            "N·s/m",
            opts.prior_of(LiftParam::J9Damping),
        ),
        j9_dry,
    ));
    joints.extend(fit.combinations.iter().map(|c| combination_joint(c, s)));
    let mut combinations: Vec<CombinationResult> = fit
        .combinations
        .iter()
        .map(Combination::to_result)
        .collect();
    let withheld = lp.verdict == GaugeVerdict::Unexplained;
    if withheld {
        for j in &mut joints {
            for p in [&mut j.viscous, &mut j.dry] {
                p.identifiable = false;
                p.status = Status::Unknown;
            }
            j.identifiable = false;
            j.status = Status::Unknown;
        }
        for c in &mut combinations {
            c.identifiable = false;
            c.status = Status::Unknown;
        }
    }
    let rmse_after = fit.rmse_n;
    let rmse_before = lp.plain.as_ref().map_or(rmse_after, |(p, _)| p.rmse_n);
    let effects: Vec<EffectResult> = lp
        .named
        .iter()
        .filter_map(|e| fit.estimate(*e))
        .map(effect_result)
        .collect();
    let res = &lp.residual;
    let offset = fit.offset;
    FitResult {
        trace_id: trace_id.to_string(),
        joints,
        rmse: Quantity {
            value: rmse_after,
            unit: "N".into(),
        },
        residual: ResidualResult {
            effects,
            rmse_before,
            rmse_after,
            holdout_rmse_before: rmse_before,
            holdout_rmse_after: rmse_after,
            verdict: withheld.then(|| "unexplained".to_string()),
            correlates_with: Vec::new(),
            excess_ratio: Some(res.excess_ratio).filter(|v| v.is_finite()),
            joints_withheld: withheld.then(|| {
                format!(
                    "the fit leaves {:.1}× the gauge's noise (RMS {:.2} N against {:.2} N, lag-1 \
                     correlation {:.2}) and neither sensor_offset nor spring_rate explains it: \
                     joint statuses from this record are not trustworthy and raise no alert",
                    res.excess_ratio,
                    res.rms_n,
                    res.noise_n.max(fit.noise_floor_n),
                    res.rho1
                )
            }),
            holdout_note: Some(NO_HOLDOUT.into()),
            autocorrelation: Vec::new(),
            autocorrelation_before: Vec::new(),
            ambiguity: None,
            halves: None,
        },
        fit: FitDetails {
            model_version: MODEL_VERSION.to_string(),
            release_t_s: 0.0,
            release_rule: crate::joint::identify::release::ReleaseRule::FirstSample
                .as_str()
                .to_owned(),
            release_warning: None,
            release_disturbed_until_s: None,
            release_disturbance: None,
            release_position: Quantity {
                value: record.heights_m.first().copied().unwrap_or(f64::NAN),
                unit: "m".into(),
            },
            release_rate: Quantity {
                value: 0.0,
                unit: "m/s".into(),
            },
            sensor_offset: Quantity {
                value: offset.map_or(0.0, |o| o.value),
                unit: "N".into(),
            },
            sensor_offset_ci95: offset.map(|o| o.ci95),
            input_offset: None,
            input_offset_ci95: None,
            samples_fitted: record.len(),
            termination: format!("{:?}", fit.termination),
            iterations: fit.iterations,
            residual_rho1: res.rho1,
            interval_inflation: fit.noise_n / fit.noise_floor_n,
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

/// The keys of an effect's value and interval in `residual.effects[].params`.
fn param_keys(effect: GaugeEffect) -> (&'static str, &'static str) {
    match effect {
        GaugeEffect::SensorOffset => ("offset_n", "offset_n_ci95"),
        GaugeEffect::SpringRate => ("rate_factor", "rate_factor_ci95"),
    }
}

fn effect_result(e: GaugeEffectEstimate) -> EffectResult {
    use serde_json::json;
    let (k, kci) = param_keys(e.effect);
    let mut params = serde_json::Map::new();
    params.insert(k.into(), json!(e.value));
    params.insert(kci.into(), json!(e.ci95));
    EffectResult {
        name: e.effect.name().into(),
        params,
    }
}

fn joint(name: &str, viscous: ParamResult, dry: ParamResult) -> JointResult {
    let status = [&viscous, &dry]
        .iter()
        .filter(|p| p.identifiable)
        .map(|p| p.status)
        .max()
        .unwrap_or(Status::Unknown);
    JointResult {
        joint: name.to_string(),
        identifiable: viscous.identifiable || dry.identifiable,
        status,
        viscous,
        dry,
    }
}

/// A fitted joint's dry μ.
fn estimated(e: &ParamEstimate, combos: &[Combination]) -> ParamResult {
    ParamResult {
        value: e.value,
        ci95: e.ci95,
        baseline: Some(e.baseline),
        unit: "1".into(),
        identifiable: e.informed,
        status: e.status,
        combination: e.combination.and_then(|c| combos.get(c)).map(|c| c.label()),
    }
}

/// A parameter the test does not estimate (as a lift's): at the prior's centre m × baseline,
/// the prior's interval (± 1.96 s × baseline; `prior` = (m, s), Table 4 units), not identified.
fn not_estimated(baseline: Option<f64>, unit: &str, prior: (f64, f64)) -> ParamResult {
    let b = baseline.unwrap_or(0.0);
    let (m, sd) = prior;
    let half = Z95 * sd * b;
    let centre = b * m;
    ParamResult {
        value: centre,
        ci95: [(centre - half).max(0.0), centre + half],
        baseline,
        unit: unit.into(),
        identifiable: false,
        status: Status::Unknown,
        combination: None,
    }
}

/// A combination as an entry of `joints` (as a lift's): named by its members' joints, the level
/// in the `dry` slot.
fn combination_joint(c: &Combination, prior_relative_sd: f64) -> JointResult {
    let label = c.label();
    let name = label.trim_end_matches(" dry").to_string();
    let dry = ParamResult {
        value: c.value,
        ci95: c.ci95,
        baseline: Some(1.0),
        unit: "× Table 4".into(),
        identifiable: c.informed,
        status: c.status,
        combination: Some(label),
    };
    let viscous = not_estimated(None, "× Table 4", (1.0, prior_relative_sd));
    JointResult {
        joint: name,
        status: if c.informed {
            c.status
        } else {
            Status::Unknown
        },
        identifiable: c.informed,
        viscous,
        dry,
    }
}

/// A gauge record's named `effect` read back from its contract result (`residual.effects`, as
/// [`gauge_result`] writes it): the value and its 95 % interval; `None` when the record did not
/// name it, when its joints were withheld (`unexplained`), or when the entry does not read
/// (a lift's `sensor_offset` is an H offset in metres, not a gauge's zero: no `offset_n`).
pub fn named_effect(result: &FitResult, effect: GaugeEffect) -> Option<(f64, [f64; 2])> {
    if result.residual.verdict.is_some() {
        return None;
    }
    let (k, kci) = param_keys(effect);
    let e = result
        .residual
        .effects
        .iter()
        .find(|e| e.name == effect.name())?;
    let v = e.params.get(k)?.as_f64()?;
    let ci = e.params.get(kci)?.as_array()?;
    let (lo, hi) = (ci.first()?.as_f64()?, ci.get(1)?.as_f64()?);
    (v.is_finite() && lo.is_finite() && hi.is_finite() && lo <= v && v <= hi)
        .then_some((v, [lo, hi]))
}

/// The spring-rate factor a gauge record's fit named (`spring_rate`), as the static-force
/// prediction takes it ([`super::super::static_force::predict_rated`]); `None`: not named.
pub fn spring_rate_of(result: &FitResult) -> Option<RateEstimate> {
    let (factor, ci) = named_effect(result, GaugeEffect::SpringRate)?;
    (factor > 0.0 && ci[0] > 0.0).then_some(RateEstimate {
        factor,
        ci95: Some(ci),
    })
}

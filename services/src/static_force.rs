//! A pantograph's predicted static contact force (issue 20): its current joint friction, each
//! parameter from the latest test that informed it, and its drive spring's rate — the type's, or
//! the `spring_rate` its latest force-gauge record named (issue 39, point 5) — mapped into
//! `models::lift::static_force`. The gauge's zero that record named (`sensor_offset`) is the
//! gauge's, not the pantograph's: the prediction is the true force, and the measured points are
//! shown with that zero taken off ([`GaugeMeasurement::zero_n`]).
//!
//! No physics here: the models compute the characteristic and the findings against the type's
//! `[static_force]` limits; this module picks the parameters, runs the models off the runtime and
//! shapes the answer.

use chrono::{DateTime, Utc};
use pantowatch_models::data;
use pantowatch_models::lift::gauge::{GaugeEffect, named_effect, spring_rate_of};
use pantowatch_models::lift::geometry::{self, Geometry};
use pantowatch_models::lift::static_force::{
    self, LimitFinding, MuEstimate, RateEstimate, StaticForceCurve,
};
use pantowatch_models::lift::topology::{N_REV, RevJoint};
use pantowatch_models::report::FitResult;
use serde::Serialize;
use utoipa::ToSchema;

use crate::health::Param;
use crate::store::{JointPoint, Store, StoreError};

/// The alert name of a static-force finding (one live alert per pantograph), a pseudo-joint as
/// the lift's `H sensor` finding is.
pub const STATIC_FORCE_ALERT: &str = "static force";

/// Where one joint's dry friction coefficient came from.
#[derive(Debug, Clone, PartialEq, Serialize, serde::Deserialize, ToSchema)]
pub struct MuSource {
    pub joint: String,
    pub dry_mu: f64,
    /// The 95 % interval of the fit that informed it; `null` for the type's baseline.
    pub dry_mu_ci95: Option<[f64; 2]>,
    /// `fit`: the latest test that informed it; `combination J1+J3`: a lift's informed combination
    /// of joints it cannot tell apart, each member at the level × its baseline; `baseline`: no
    /// test has (Table 4 value, no band).
    pub source: String,
    pub trace_id: Option<String>,
    pub recorded_at: Option<DateTime<Utc>>,
}

/// The drive spring's rate the prediction used: the drive line's slope × `rate_factor`.
#[derive(Debug, Clone, PartialEq, Serialize, serde::Deserialize, ToSchema)]
pub struct SpringSource {
    /// 1 for the type's spring.
    pub rate_factor: f64,
    /// The 95 % interval of the named rate; `null` for the type's (no band).
    pub rate_factor_ci95: Option<[f64; 2]>,
    /// `type`: the type's drive characteristic (no gauge record, or the latest named no other
    /// rate); `gauge record`: the `spring_rate` the latest force-gauge record's fit named.
    pub source: String,
    /// The gauge record whose fit decided it (none for `type` without a gauge record).
    pub trace_id: Option<String>,
    pub recorded_at: Option<DateTime<Utc>>,
}

impl SpringSource {
    /// The type's spring, no gauge record.
    pub fn type_spring() -> Self {
        Self {
            rate_factor: 1.0,
            rate_factor_ci95: None,
            source: "type".to_owned(),
            trace_id: None,
            recorded_at: None,
        }
    }

    /// The spring a gauge record's fit `result` tells: its named `spring_rate`, else the type's.
    pub fn of_gauge_fit(result: &FitResult, trace_id: &str, recorded_at: DateTime<Utc>) -> Self {
        let (rate_factor, rate_factor_ci95, source) = match spring_rate_of(result) {
            Some(r) => (r.factor, r.ci95, "gauge record"),
            None => (1.0, None, "type"),
        };
        Self {
            rate_factor,
            rate_factor_ci95,
            source: source.to_owned(),
            trace_id: Some(trace_id.to_owned()),
            recorded_at: Some(recorded_at),
        }
    }

    fn estimate(&self) -> RateEstimate {
        RateEstimate {
            factor: self.rate_factor,
            ci95: self.rate_factor_ci95,
        }
    }
}

/// The predicted characteristic: forces on the strip, N, at `heights_m`.
#[derive(Debug, Clone, PartialEq, Serialize, ToSchema)]
pub struct StaticForceView {
    pub serial: String,
    pub model: String,
    pub heights_m: Vec<f64>,
    /// The drive torque assumed at each height (the line through the lift-test states), N·m.
    pub drive_torque_nm: Vec<f64>,
    pub frictionless_n: Vec<f64>,
    pub raise_n: Vec<f64>,
    pub raise_lo_n: Vec<f64>,
    pub raise_hi_n: Vec<f64>,
    pub lower_n: Vec<f64>,
    pub lower_lo_n: Vec<f64>,
    pub lower_hi_n: Vec<f64>,
    pub limits: LimitsView,
    /// Every height and edge where a 95 % band leaves the limits; empty: within them.
    pub findings: Vec<FindingView>,
    /// Each revolute joint's dry μ used, with its source.
    pub parameters: Vec<MuSource>,
    /// The drive spring's rate used (the drive torque above is the line with it).
    pub spring: SpringSource,
    /// The latest force-gauge measurement of the pantograph (its latest `static_force` trace's
    /// readings as stored, not refitted); absent when it has none. Filled by the API route.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub measured: Option<GaugeMeasurement>,
}

/// The type's limits (`[static_force]` of its data file), evaluated at `heights_m`.
#[derive(Debug, Clone, PartialEq, Serialize, serde::Deserialize, ToSchema)]
pub struct LimitsView {
    pub nominal_n: Vec<f64>,
    pub min_n: Vec<f64>,
    pub max_n: Vec<f64>,
    pub max_raise_lower_difference_n: f64,
    pub source: String,
}

/// A band leaving a limit.
#[derive(Debug, Clone, PartialEq, Serialize, serde::Deserialize, ToSchema)]
pub struct FindingView {
    pub height_m: f64,
    /// `raise_below_min`, `lower_below_min`, `raise_above_max`, `lower_above_max`,
    /// `difference_above_max`.
    pub what: String,
    pub value_n: f64,
    pub limit_n: f64,
}

impl From<&LimitFinding> for FindingView {
    fn from(f: &LimitFinding) -> Self {
        FindingView {
            height_m: f.height_m,
            what: f.what.to_owned(),
            value_n: f.value_n,
            limit_n: f.limit_n,
        }
    }
}

/// Why no prediction.
#[derive(Debug, thiserror::Error)]
pub enum PredictError {
    #[error("no pantograph `{0}`")]
    NoPantograph(String),
    #[error("pantograph type `{0}` has no complete-pantograph model or no [static_force] limits")]
    NoModel(String),
    #[error("the static force could not be computed: {0}")]
    Model(String),
    #[error(transparent)]
    Store(#[from] StoreError),
}

/// The type's data and lift geometry, when the type has both.
pub fn type_models(model: &str) -> Option<(&'static data::StaticForceData, &'static Geometry)> {
    let d = data::builtin(model)?.static_force.as_ref()?;
    let g = match model {
        "160EC" => geometry::builtin_160ec(),
        _ => return None,
    };
    Some((d, g))
}

/// Each revolute joint's dry μ: from the latest test in `history` (oldest first) that informed
/// it ([`Param::of`], as fleet health takes each parameter), else the type's baseline.
pub fn current_mu(g: &Geometry, history: &[JointPoint]) -> ([MuEstimate; N_REV], Vec<MuSource>) {
    let mut mu: [MuEstimate; N_REV] = std::array::from_fn(|i| MuEstimate {
        value: g.revolute[i].dry_mu,
        ci95: None,
    });
    let mut src: Vec<MuSource> = RevJoint::ALL
        .iter()
        .map(|j| MuSource {
            joint: j.name().to_owned(),
            dry_mu: g.revolute[j.index()].dry_mu,
            dry_mu_ci95: None,
            source: "baseline".to_owned(),
            trace_id: None,
            recorded_at: None,
        })
        .collect();
    for p in history {
        let Some((v, lo, hi)) = Param::Dry.of(p) else {
            continue;
        };
        if !(v >= 0.0 && lo <= v && v <= hi) {
            continue;
        }
        // A lift's combination (`J1+J3`, level × Table 4, issue 15): the members a lift does
        // not tell apart move together, each at level × its baseline (the level is wᵀx with
        // Σw = 1, so all members at that level reproduce it), with the level's interval.
        let members: Vec<RevJoint> = p
            .fit
            .joint
            .split('+')
            .filter_map(|n| RevJoint::ALL.into_iter().find(|j| j.name() == n))
            .collect();
        let combination = members.len() > 1;
        if members.is_empty() || (!combination && p.fit.joint.contains('+')) {
            continue;
        }
        for j in members {
            if j == RevJoint::J6 {
                // Locked in the plane: its friction does no work in the statics.
                continue;
            }
            let i = j.index();
            let b = g.revolute[i].dry_mu;
            let (v, lo, hi) = if combination {
                (v * b, lo * b, hi * b)
            } else {
                (v, lo, hi)
            };
            mu[i] = MuEstimate {
                value: v,
                ci95: Some([lo, hi]),
            };
            src[i] = MuSource {
                joint: j.name().to_owned(),
                dry_mu: v,
                dry_mu_ci95: Some([lo, hi]),
                source: if combination {
                    format!("combination {}", p.fit.joint)
                } else {
                    "fit".to_owned()
                },
                trace_id: Some(p.trace_id.clone()),
                recorded_at: Some(p.recorded_at),
            };
        }
    }
    (mu, src)
}

fn view(
    serial: &str,
    model: &str,
    d: &data::StaticForceData,
    c: StaticForceCurve,
    findings: &[LimitFinding],
    parameters: Vec<MuSource>,
    spring: SpringSource,
) -> StaticForceView {
    let lim = static_force::ForceLimits::from(d);
    let nominal_n: Vec<f64> = c.heights_m.iter().map(|&h| lim.nominal_at_n(h)).collect();
    StaticForceView {
        serial: serial.to_owned(),
        model: model.to_owned(),
        limits: LimitsView {
            min_n: nominal_n.iter().map(|n| n - d.tolerance_n).collect(),
            max_n: nominal_n.iter().map(|n| n + d.tolerance_n).collect(),
            nominal_n,
            max_raise_lower_difference_n: d.max_raise_lower_difference_n,
            source: d.source.clone(),
        },
        findings: findings.iter().map(FindingView::from).collect(),
        parameters,
        spring,
        measured: None,
        heights_m: c.heights_m,
        drive_torque_nm: c.drive_torque_nm,
        frictionless_n: c.frictionless_n,
        raise_n: c.raise_n,
        raise_lo_n: c.raise_lo_n,
        raise_hi_n: c.raise_hi_n,
        lower_n: c.lower_n,
        lower_lo_n: c.lower_lo_n,
        lower_hi_n: c.lower_hi_n,
    }
}

/// The prediction for `mu` and the drive spring `spring` on the type `model` (blocking: call
/// off the runtime).
pub fn predict_blocking(
    serial: &str,
    model: &str,
    mu: &[MuEstimate; N_REV],
    parameters: Vec<MuSource>,
    spring: SpringSource,
) -> Result<StaticForceView, PredictError> {
    let (d, g) = type_models(model).ok_or_else(|| PredictError::NoModel(model.to_owned()))?;
    let p = static_force::predict_rated(g, d, mu, &spring.estimate())
        .map_err(|e| PredictError::Model(e.to_string()))?;
    Ok(view(
        serial,
        model,
        d,
        p.curve,
        &p.findings,
        parameters,
        spring,
    ))
}

/// A stored pantograph's prediction from its current parameters: the friction from
/// [`current_mu`], the spring from its latest force-gauge record's fit ([`latest_gauge_fit`]).
pub async fn predict(store: &Store, serial: &str) -> Result<StaticForceView, PredictError> {
    let model = store
        .pantograph_model(serial)
        .await?
        .ok_or_else(|| PredictError::NoPantograph(serial.to_owned()))?;
    let (_, g) = type_models(&model).ok_or_else(|| PredictError::NoModel(model.clone()))?;
    let history = store.serial_history(serial).await?;
    let (mu, sources) = current_mu(g, &history);
    let spring = match latest_gauge_fit(store, serial).await? {
        Some((meta, result)) => {
            SpringSource::of_gauge_fit(&result, &meta.trace_id, meta.recorded_at)
        }
        None => SpringSource::type_spring(),
    };
    let serial = serial.to_owned();
    tokio::task::spawn_blocking(move || predict_blocking(&serial, &model, &mu, sources, spring))
        .await
        .map_err(|e| PredictError::Model(e.to_string()))?
}

/// The latest `static_force` trace of `serial` with its fit's result; `None` when it has none
/// or that trace is not fitted yet. The spring rate and the gauge's zero are the gauge's latest
/// word: a later record that names no other rate puts the type's spring back.
pub async fn latest_gauge_fit(
    store: &Store,
    serial: &str,
) -> Result<Option<(crate::store::TraceMeta, FitResult)>, StoreError> {
    let Some(meta) = store
        .latest_trace_of_kind(serial, crate::trace::STATIC_FORCE)
        .await?
    else {
        return Ok(None);
    };
    let Some(fit) = store.get_fit(&meta.trace_id).await? else {
        return Ok(None);
    };
    let result = fit.result()?;
    Ok(Some((meta, result)))
}

/// A force gauge's readings of a pantograph's static contact force: its latest stored
/// `static_force` trace, read back as uploaded (the store keeps every sample losslessly), split
/// into the raising and the lowering branch. Not a fit: the points the gauge showed.
#[derive(Debug, Clone, PartialEq, Serialize, ToSchema)]
pub struct GaugeMeasurement {
    pub trace_id: String,
    pub recorded_at: DateTime<Utc>,
    /// The gauge's stated resolution, N.
    pub gauge_resolution_n: f64,
    /// `[H m, F N]` readings raising the strip, in recorded order (the highest reading last).
    pub raise: Vec<[f64; 2]>,
    /// `[H m, F N]` readings lowering it after the highest, in recorded order.
    pub lower: Vec<[f64; 2]>,
    /// The gauge's zero b its fit named (`sensor_offset`), N: the readings are F + b, so F is a
    /// reading less b (the page draws them so). `null`: none named, or the trace not fitted yet.
    pub zero_n: Option<f64>,
    pub zero_n_ci95: Option<[f64; 2]>,
}

/// The latest `static_force` trace of `serial` as measured points; `None` when it has none, or
/// when its stored samples no longer read as a gauge test (logged: a limit changed since the
/// upload, or unreadable samples), so a page never fails on it.
pub async fn latest_measurement(
    store: &Store,
    serial: &str,
) -> Result<Option<GaugeMeasurement>, StoreError> {
    let Some(meta) = store
        .latest_trace_of_kind(serial, crate::trace::STATIC_FORCE)
        .await?
    else {
        return Ok(None);
    };
    let channels = match store.get_samples(&meta.trace_id).await {
        Ok(Some(c)) => c,
        Ok(None) => return Ok(None),
        Err(StoreError::Codec(e)) => {
            tracing::warn!(trace = %meta.trace_id, error = %e, "gauge samples unreadable");
            return Ok(None);
        }
        Err(e) => return Err(e),
    };
    let mut m = measurement_of(&meta, channels);
    if let Some(m) = m.as_mut()
        && let Some(fit) = store.get_fit(&meta.trace_id).await?
    {
        match fit.result() {
            Ok(r) => (m.zero_n, m.zero_n_ci95) = gauge_zero_of(&r).unzip(),
            Err(e) => tracing::warn!(trace = %meta.trace_id, error = %e, "gauge fit unreadable"),
        }
    }
    Ok(m)
}

/// The gauge's zero a gauge fit `result` named (`sensor_offset`), N, with its interval.
pub fn gauge_zero_of(result: &FitResult) -> Option<(f64, [f64; 2])> {
    named_effect(result, GaugeEffect::SensorOffset)
}

/// The measured points of a stored `static_force` trace (see [`latest_measurement`]).
pub fn measurement_of(
    meta: &crate::store::TraceMeta,
    channels: Vec<(String, Vec<f64>)>,
) -> Option<GaugeMeasurement> {
    let doc = match crate::ingest::stored_doc(meta, channels) {
        Ok(d) => d,
        Err(e) => {
            tracing::warn!(trace = %meta.trace_id, error = %e, "stored gauge trace unreadable");
            return None;
        }
    };
    let g = match doc.static_force_channels() {
        Ok(g) => g,
        Err(e) => {
            tracing::warn!(trace = %meta.trace_id, error = %e, "stored gauge trace no longer valid");
            return None;
        }
    };
    let [raise, lower] = g.branches();
    let pts = |b: Vec<(f64, f64)>| b.into_iter().map(|(h, f)| [h, f]).collect();
    Some(GaugeMeasurement {
        trace_id: meta.trace_id.clone(),
        recorded_at: meta.recorded_at,
        gauge_resolution_n: g.gauge_resolution_n,
        raise: pts(raise),
        lower: pts(lower),
        zero_n: None,
        zero_n_ci95: None,
    })
}

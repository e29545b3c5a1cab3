//! The fit result of the trace format (contract `Fit result`): each joint's parameters with
//! 95 % intervals, baseline, identifiability and drift status; the RMSE; the residual block.

use serde::{Deserialize, Serialize};

use crate::contract::drift::{DriftThresholds, Status};
use crate::contract::testspec::Baseline;
use crate::joint::friction::DynParam;
use crate::joint::identify::{FitOutcome, Param};

/// Version of the model and identification method; a fit is stored per trace and version.
/// 0.2: lift fits integrate their sensitivities with the Rosenbrock-W method (estimates move
/// by up to 0.3 posterior sd against 0.1's DOPRI5), so `pantowatch refit` queues them again.
pub const MODEL_VERSION: &str =
    "pantowatch-models/0.2 single-joint output-error LM; lift MAP (Rosenbrock-W); quadrangle MAP";

#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct ParamResult {
    #[serde(deserialize_with = "nullable::f64")]
    #[cfg_attr(feature = "openapi", schema(nullable))]
    pub value: f64,
    #[serde(deserialize_with = "nullable::pair")]
    #[cfg_attr(
        feature = "openapi",
        schema(value_type = Vec<Option<f64>>, min_items = 2, max_items = 2)
    )]
    pub ci95: [f64; 2],
    pub baseline: Option<f64>,
    pub unit: String,
    pub identifiable: bool,
    pub status: Status,
    /// Set when the test informs this parameter only together with others: the label of the
    /// combination it is reported in (issue 15; a lift's `J1+J3 dry`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub combination: Option<String>,
}

/// A combination of parameters a test informs together (issue 15): the level the data pin,
/// each member over its Table 4 baseline weighted by its share (1 = every member at baseline).
/// It is also listed in `joints` under its label's joints (e.g. `J1+J3`), so health and alerts
/// judge it like a joint.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct CombinationResult {
    pub label: String,
    pub members: Vec<CombinationMember>,
    #[serde(deserialize_with = "nullable::f64")]
    #[cfg_attr(feature = "openapi", schema(nullable))]
    pub value: f64,
    #[serde(deserialize_with = "nullable::pair")]
    #[cfg_attr(
        feature = "openapi",
        schema(value_type = Vec<Option<f64>>, min_items = 2, max_items = 2)
    )]
    pub ci95: [f64; 2],
    pub identifiable: bool,
    pub status: Status,
}

/// One member of a [`CombinationResult`].
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct CombinationMember {
    pub joint: String,
    /// `viscous` or `dry`.
    pub kind: String,
    #[serde(deserialize_with = "nullable::f64")]
    #[cfg_attr(feature = "openapi", schema(nullable))]
    pub weight: f64,
}

#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct JointResult {
    pub joint: String,
    pub viscous: ParamResult,
    pub dry: ParamResult,
    pub identifiable: bool,
    pub status: Status,
}

#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct Quantity {
    #[serde(deserialize_with = "nullable::f64")]
    #[cfg_attr(feature = "openapi", schema(nullable))]
    pub value: f64,
    pub unit: String,
}

#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct EffectResult {
    pub name: String,
    pub params: serde_json::Map<String, serde_json::Value>,
}

impl EffectResult {
    /// The finite number `params[key]`, if any.
    pub fn param(&self, key: &str) -> Option<f64> {
        self.params
            .get(key)
            .and_then(serde_json::Value::as_f64)
            .filter(|v| v.is_finite())
    }

    /// The 95 % interval `params["{key}_ci95"]`, when it holds two finite numbers.
    pub fn ci95(&self, key: &str) -> Option<[f64; 2]> {
        let ci = self.params.get(&format!("{key}_ci95"))?.as_array()?;
        match ci.as_slice() {
            [lo, hi] => {
                Some([lo.as_f64()?, hi.as_f64()?]).filter(|c| c.iter().all(|v| v.is_finite()))
            }
            _ => None,
        }
    }
}

#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct ResidualResult {
    pub effects: Vec<EffectResult>,
    #[serde(deserialize_with = "nullable::f64")]
    #[cfg_attr(feature = "openapi", schema(nullable))]
    pub rmse_before: f64,
    #[serde(deserialize_with = "nullable::f64")]
    #[cfg_attr(feature = "openapi", schema(nullable))]
    pub rmse_after: f64,
    #[serde(deserialize_with = "nullable::f64")]
    #[cfg_attr(feature = "openapi", schema(nullable))]
    pub holdout_rmse_before: f64,
    #[serde(deserialize_with = "nullable::f64")]
    #[cfg_attr(feature = "openapi", schema(nullable))]
    pub holdout_rmse_after: f64,
    /// `unexplained` when structure remains that no candidate explains; `ambiguous` (single
    /// joints) when two explanations fit equally (`ambiguity`); otherwise absent.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub verdict: Option<String>,
    /// With `unexplained`: the signals the residual correlates with most (name, correlation).
    #[serde(
        default,
        skip_serializing_if = "Vec::is_empty",
        deserialize_with = "nullable::named"
    )]
    #[cfg_attr(feature = "openapi", schema(schema_with = schema::named_numbers))]
    pub correlates_with: Vec<(String, f64)>,
    /// Residual RMS over the sensor noise estimated from its first differences (lift fits,
    /// issue 16); absent where not computed.
    #[serde(
        default,
        skip_serializing_if = "Option::is_none",
        deserialize_with = "nullable::some_f64"
    )]
    pub excess_ratio: Option<f64>,
    /// Set when the fit's joint statuses are withheld (reported `unknown`, not identified, no
    /// alert) because the residual shows a model error: the reason, in words.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub joints_withheld: Option<String>,
    /// Set when no held-out test was run (lift fits: a segment too short, `lift::holdout`): the
    /// reason, in words; the `holdout_` pair then repeats the fitted RMSE.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub holdout_note: Option<String>,
    /// Lift fits (issue 16, point 5): the final residual's autocorrelation, (lag s, ρ) at
    /// `lift::residual::ACF_LAGS_S`; white noise reads ≈ 0 at every lag.
    #[serde(
        default,
        skip_serializing_if = "Vec::is_empty",
        deserialize_with = "nullable::lags"
    )]
    #[cfg_attr(feature = "openapi", schema(schema_with = schema::number_pairs))]
    pub autocorrelation: Vec<(f64, f64)>,
    /// With a named lift effect: the plain model's residual autocorrelation, the same lags.
    #[serde(
        default,
        skip_serializing_if = "Vec::is_empty",
        deserialize_with = "nullable::lags"
    )]
    #[cfg_attr(feature = "openapi", schema(schema_with = schema::number_pairs))]
    pub autocorrelation_before: Vec<(f64, f64)>,
    /// Single-joint fits (issue 36, point 3): two explanations fit the record equally (BIC and
    /// held-out error within the stated margins); the verdict is then `ambiguous`, no effect is
    /// named, and this says which, and the test that would tell them apart.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ambiguity: Option<Ambiguity>,
    /// Single-joint fits (issue 36, point 3): the best model tried judged on the early (large
    /// swings) and late (small swings) halves of the free motion separately; absent when no
    /// effect was tried.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub halves: Option<HalvesCheck>,
}

/// Explanations a record cannot tell apart (`joint::residual::ambiguity`).
#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct Ambiguity {
    /// Lowest BIC first.
    pub explanations: Vec<Explanation>,
    /// The margins two explanations fell within, in words (ΔBIC and held-out RMSE).
    pub margin: String,
    /// The test that would tell them apart, derived from how their predictions differ.
    pub separating_test: String,
}

/// One explanation of an ambiguous record.
#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct Explanation {
    /// An effect of the vocabulary, or a physical term outside it (`restoring_torque`).
    pub name: String,
    pub in_vocabulary: bool,
    /// BIC above the lowest's (0 for the first).
    #[serde(deserialize_with = "nullable::f64")]
    #[cfg_attr(feature = "openapi", schema(nullable))]
    pub delta_bic: f64,
    #[serde(deserialize_with = "nullable::f64")]
    #[cfg_attr(feature = "openapi", schema(nullable))]
    pub holdout_rmse: f64,
    /// Its fitted parameters, named with units, each with its `…_ci95` where fitted with one.
    pub params: serde_json::Map<String, serde_json::Value>,
}

/// Share of the base model's excess over the noise (σ²) the best model tried explains, and the
/// RMS it leaves over the noise, in the early and the late half of the free motion.
#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct HalvesCheck {
    /// The model judged: effect names joined by `+`.
    pub model: String,
    #[serde(deserialize_with = "nullable::f64")]
    #[cfg_attr(feature = "openapi", schema(nullable))]
    pub early_explained_share: f64,
    #[serde(deserialize_with = "nullable::f64")]
    #[cfg_attr(feature = "openapi", schema(nullable))]
    pub late_explained_share: f64,
    #[serde(deserialize_with = "nullable::f64")]
    #[cfg_attr(feature = "openapi", schema(nullable))]
    pub early_remainder_over_noise: f64,
    #[serde(deserialize_with = "nullable::f64")]
    #[cfg_attr(feature = "openapi", schema(nullable))]
    pub late_remainder_over_noise: f64,
    /// False when a half the base model misfits is explained under the loop's share: the model
    /// is then not the record's explanation, whatever its average.
    pub holds: bool,
}

/// A release that was not free (`joint::identify::release::disturbed`): the part of the record
/// left out of the fit and the evidence, per half-swing left out.
#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct ReleaseDisturbance {
    /// The release first found, s: the left-out part runs from here to `until_s`.
    pub from_s: f64,
    pub until_s: f64,
    /// One sentence: why.
    pub reason: String,
    pub half_swings: Vec<DisturbedSwing>,
    /// Set when even the start used is not known to be free.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub warning: Option<String>,
}

/// One half-swing left out: its loss per unit path and its duration against a free one's.
#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct DisturbedSwing {
    pub from_s: f64,
    pub to_s: f64,
    /// Loss per unit path over the later half-swings' trend at its energy (free: ≤ the bound).
    pub energy_ratio: f64,
    pub energy_ratio_bound: f64,
    /// Its duration's T₀/2 over the later half-swings' median (free: ≤ the bound).
    pub period_ratio: f64,
    pub period_ratio_bound: f64,
}

impl ReleaseDisturbance {
    pub fn of(d: &crate::joint::identify::release::Disturbance) -> Self {
        use crate::joint::identify::release::disturbed::{ENERGY_RATIO, PERIOD_RATIO};
        let finite = |x: f64| if x.is_finite() { x } else { f64::MAX };
        ReleaseDisturbance {
            from_s: d.from_t_s,
            until_s: d.until_t_s,
            reason: d.reason(),
            half_swings: d
                .left_out
                .iter()
                .map(|c| DisturbedSwing {
                    from_s: c.from_t_s,
                    to_s: c.to_t_s,
                    energy_ratio: finite(c.energy_ratio),
                    energy_ratio_bound: ENERGY_RATIO,
                    period_ratio: finite(c.period_ratio),
                    period_ratio_bound: PERIOD_RATIO,
                })
                .collect(),
            warning: d.warning.clone(),
        }
    }
}

/// How the fit was made: the release, the fitted start and sensor zero, the optimiser's end.
#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct FitDetails {
    pub model_version: String,
    /// Time of the first sample of free motion used in the fit.
    #[serde(deserialize_with = "nullable::f64")]
    #[cfg_attr(feature = "openapi", schema(nullable))]
    pub release_t_s: f64,
    /// How the release was decided: `stated` (`test.release_t_s`), `first_sample`,
    /// `after_hold` or `turning_point` (`identify::release`).
    pub release_rule: String,
    /// Why the release may be wrong, when the data do not decide it clearly.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub release_warning: Option<String>,
    /// With `release_rule` `disturbed` (issue 36, point 4): the end of the part left out, s —
    /// the first motion was not a free swing, the fit starts here.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub release_disturbed_until_s: Option<f64>,
    /// What the left-out half-swings did against a free one's bounds.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub release_disturbance: Option<ReleaseDisturbance>,
    pub release_position: Quantity,
    pub release_rate: Quantity,
    pub sensor_offset: Quantity,
    #[serde(deserialize_with = "nullable::opt_pair")]
    #[cfg_attr(feature = "openapi", schema(schema_with = schema::optional_interval))]
    pub sensor_offset_ci95: Option<[f64; 2]>,
    /// Input-driven tests whose position has no reference (issue 17, point 3): the measured
    /// input's zero b — the force or torque acting is the recorded one + b — with its interval.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub input_offset: Option<Quantity>,
    #[serde(
        default,
        skip_serializing_if = "Option::is_none",
        deserialize_with = "nullable::opt_pair"
    )]
    #[cfg_attr(feature = "openapi", schema(schema_with = schema::optional_interval))]
    pub input_offset_ci95: Option<[f64; 2]>,
    pub samples_fitted: usize,
    pub termination: String,
    pub iterations: usize,
    /// Residual lag-1 autocorrelation and the interval inflation applied for it.
    #[serde(deserialize_with = "nullable::f64")]
    #[cfg_attr(feature = "openapi", schema(nullable))]
    pub residual_rho1: f64,
    #[serde(deserialize_with = "nullable::f64")]
    #[cfg_attr(feature = "openapi", schema(nullable))]
    pub interval_inflation: f64,
    /// Correlation of the viscous and dry estimates.
    #[serde(deserialize_with = "nullable::f64")]
    #[cfg_attr(feature = "openapi", schema(nullable))]
    pub viscous_dry_correlation: f64,
    /// The rig's stated body uncertainties (issue 17, point 1) as the intervals carry them;
    /// absent when the rig states none (single-joint fits only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub body_uncertainty: Option<BodyUncertaintyResult>,
    /// Lift fits (issue 36, point 1): what the fit had to do to reach the noise — the trace
    /// refitted with only the reported parameters free (`lift::absorbed`); absent elsewhere.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub absorption: Option<AbsorptionCheck>,
    /// Lift and gauge fits (issue 37, point 3): the fleet prior the joints it does not report
    /// were fitted under; absent elsewhere (`contract::evidence::PriorUsed`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub prior: Option<super::evidence::PriorUsed>,
}

/// A lift fit's check that no effect was absorbed in silence by the joints it does not report
/// (`fit.absorption`, `lift::absorbed`).
#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct AbsorptionCheck {
    /// The check: `reported_only_refit`.
    pub check: String,
    /// Whether it fired (`ratio` ≥ `threshold`, or `worst_phase_ratio` ≥ `phase_threshold`): the
    /// lift then names an effect or is `unexplained` with its joints withheld, never clean.
    pub fired: bool,
    /// The refit's H residual RMS over the sensor noise.
    #[serde(deserialize_with = "nullable::f64")]
    #[cfg_attr(feature = "openapi", schema(nullable))]
    pub ratio: f64,
    /// The ratio at or above which it fires.
    pub threshold: f64,
    /// The plain fit's ratio (every joint free), for comparison.
    #[serde(deserialize_with = "nullable::f64")]
    #[cfg_attr(feature = "openapi", schema(nullable))]
    pub plain_ratio: f64,
    /// The parameters left free (`J1 dry`, …); every other at its Table 4 value.
    pub free: Vec<String>,
    /// The phase of the record the refit misfits most (`rising`, `first half`, …;
    /// `lift::absorbed::judge`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub worst_phase: Option<String>,
    /// The refit's H residual RMS over the noise in `worst_phase`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub worst_phase_ratio: Option<f64>,
    /// The phase ratio at or above which it fires too (set on a record that does not lower the
    /// strip, where an effect confined to the motion is diluted by the dwell in the average).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub phase_threshold: Option<f64>,
}

/// The stated body uncertainties a single-joint fit carried (`fit.body_uncertainty`), each
/// keyed by the quantity it qualifies as the rig names it (`mass_kg`, `inertia_kgm2`,
/// `com_distance_m`, `moving_mass_kg`), valued by its stated sd in that quantity's unit.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct BodyUncertaintyResult {
    /// Propagated into every parameter's interval (`identify::body_uncertainty`).
    pub propagated: std::collections::BTreeMap<String, f64>,
    /// Stated but not propagated: the inertia when the reported fit estimates it (`inertia_error`
    /// named, or an `ambiguous` record read with it; its interval holds it), or a perturbed
    /// model that could not be simulated.
    #[serde(default, skip_serializing_if = "std::collections::BTreeMap::is_empty")]
    pub not_propagated: std::collections::BTreeMap<String, f64>,
}

impl BodyUncertaintyResult {
    /// What `fit` carried; `None` when nothing was stated (or every stated sd was 0).
    pub fn of(fit: &FitOutcome) -> Option<Self> {
        if fit.body_uncertainty.is_empty() {
            return None;
        }
        let (mut propagated, mut not_propagated) = (Default::default(), Default::default());
        for b in &fit.body_uncertainty {
            let to: &mut std::collections::BTreeMap<String, f64> = if b.propagated {
                &mut propagated
            } else {
                &mut not_propagated
            };
            to.insert(b.quantity.to_owned(), b.sd);
        }
        Some(Self {
            propagated,
            not_propagated,
        })
    }
}

#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct FitResult {
    pub trace_id: String,
    pub joints: Vec<JointResult>,
    pub rmse: Quantity,
    pub residual: ResidualResult,
    pub fit: FitDetails,
    /// Set on a pooled fit: the tests it fitted together (issue 15).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pooled: Option<PooledTests>,
    /// Parameters the test informs only together (lift fits; issue 15).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub combinations: Vec<CombinationResult>,
    /// Set on a pooled single-joint fit (issue 36, point 5): recordings of one rig fitted with
    /// one set of physical parameters, and the pooled residual loop's finding.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pooled_rig: Option<PooledRig>,
}

/// A pooled single-joint fit across recordings of one rig (`joint::residual::pooled`): the
/// fit's `joints` are the rig's shared parameters, `residual` this recording's part.
#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct PooledRig {
    /// The upload's `test.rig_id`.
    pub rig_id: String,
    /// The recordings pooled (this fit's trace first), each with its errors.
    pub recordings: Vec<PooledRigRecording>,
    /// Effects named across every recording (each explains ≥ 75 % of every recording's excess
    /// over the noise in its early and late halves, leaving ≤ 3× the noise).
    pub effects: Vec<String>,
    /// `unexplained` when a misfit above the noise remains that no effect explains on every
    /// recording; `ambiguous` when models that pass every rule have pooled BICs within 10 of
    /// each other (`tried` says which, and what would tell them apart); absent when the base
    /// model fits them all or an effect is named.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub verdict: Option<String>,
    /// The model whose errors `rmse_pooled_after` are: the named one, else the best tried.
    pub best_tried: Vec<String>,
    /// Each model tried on the pool, and why it was or was not named.
    pub tried: Vec<PooledRigModel>,
}

/// One recording of a pooled rig fit.
#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct PooledRigRecording {
    pub trace_id: String,
    #[serde(deserialize_with = "nullable::f64")]
    #[cfg_attr(feature = "openapi", schema(nullable))]
    pub release_t_s: f64,
    pub samples_fitted: usize,
    /// Sensor noise from the pooled base residual's first differences, channel units.
    #[serde(deserialize_with = "nullable::f64")]
    #[cfg_attr(feature = "openapi", schema(nullable))]
    pub noise_sigma: f64,
    /// Fitted alone (base model), and what its own loop named alone.
    #[serde(deserialize_with = "nullable::f64")]
    #[cfg_attr(feature = "openapi", schema(nullable))]
    pub rmse_alone: f64,
    pub named_alone: Vec<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub verdict_alone: Option<String>,
    /// RMSE, channel units: the pooled base model, and the pooled model of `best_tried`.
    #[serde(deserialize_with = "nullable::f64")]
    #[cfg_attr(feature = "openapi", schema(nullable))]
    pub rmse_pooled_before: f64,
    #[serde(deserialize_with = "nullable::f64")]
    #[cfg_attr(feature = "openapi", schema(nullable))]
    pub rmse_pooled_after: f64,
    /// Share of the pooled base residual's excess over the noise `best_tried` explains here.
    #[serde(deserialize_with = "nullable::f64")]
    #[cfg_attr(feature = "openapi", schema(nullable))]
    pub explained_share: f64,
}

/// One model tried on a pool.
#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct PooledRigModel {
    pub effects: Vec<String>,
    #[serde(deserialize_with = "nullable::f64")]
    #[cfg_attr(feature = "openapi", schema(nullable))]
    pub delta_bic: f64,
    pub accepted: bool,
    pub reason: String,
}

/// Measured vs fitted model of one fit, stored with the fit so a page draws it without
/// refitting (issue 19, point 4). Thinned to at most [`FitCurve::MAX_POINTS`] samples, evenly
/// by index (first and last kept): a plot's width, not the record.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct FitCurve {
    /// What the channel is (`alpha_deg`, `H_m`, …) and its unit (`deg`, `m`).
    pub channel: String,
    pub unit: String,
    pub t_s: Vec<f64>,
    pub measured: Vec<f64>,
    pub model: Vec<f64>,
}

impl FitCurve {
    /// Samples kept: ~3 KB per 100 points as JSON; 600 points draw a 1,000 px chart smoothly.
    pub const MAX_POINTS: usize = 600;

    /// The curve over the fitted samples; `None` when the three series do not line up or hold
    /// fewer than 2 finite points (nothing to draw).
    pub fn thinned(
        channel: &str,
        unit: &str,
        t_s: &[f64],
        measured: &[f64],
        model: &[f64],
    ) -> Option<Self> {
        let n = t_s.len().min(measured.len()).min(model.len());
        if n < 2 {
            return None;
        }
        let idx: Vec<usize> = if n <= Self::MAX_POINTS {
            (0..n).collect()
        } else {
            (0..Self::MAX_POINTS)
                .map(|k| k * (n - 1) / (Self::MAX_POINTS - 1))
                .collect()
        };
        let keep: Vec<usize> = idx
            .into_iter()
            .filter(|&i| t_s[i].is_finite() && measured[i].is_finite() && model[i].is_finite())
            .collect();
        if keep.len() < 2 {
            return None;
        }
        Some(Self {
            channel: channel.to_owned(),
            unit: unit.to_owned(),
            t_s: keep.iter().map(|&i| t_s[i]).collect(),
            measured: keep.iter().map(|&i| measured[i]).collect(),
            model: keep.iter().map(|&i| model[i]).collect(),
        })
    }

    /// Model − measured at every kept sample, channel units.
    pub fn residual(&self) -> Vec<f64> {
        self.model
            .iter()
            .zip(&self.measured)
            .map(|(m, y)| m - y)
            .collect()
    }

    /// Root-mean-square of [`FitCurve::residual`].
    pub fn rmse(&self) -> f64 {
        let r = self.residual();
        (r.iter().map(|v| v * v).sum::<f64>() / r.len().max(1) as f64).sqrt()
    }
}

/// The tests a pooled fit combined: the friction shared but for each test's own J8 dry deviation
/// (not reported), one torque offset per test (`lift::identify::POOLED_PER_TRACE`).
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct PooledTests {
    /// Trace ids, newest first (the fit's `trace_id` is the first).
    pub trace_ids: Vec<String>,
    /// The window the tests were taken from, days before the newest.
    #[serde(deserialize_with = "nullable::f64")]
    #[cfg_attr(feature = "openapi", schema(nullable))]
    pub window_days: f64,
}

/// Schemas of the fields whose JSON shape the derive cannot spell: pairs (`[name, number]`,
/// `[lag, ρ]`) and an optional interval. Every number may be `null`: serde_json writes a
/// non-finite `f64` so.
#[cfg(feature = "openapi")]
mod schema {
    use utoipa::openapi::schema::{ArrayBuilder, ArrayItems, ObjectBuilder, SchemaType, Type};
    use utoipa::openapi::{Array, Object};

    fn number() -> Object {
        ObjectBuilder::new()
            .schema_type(SchemaType::from_iter([Type::Number, Type::Null]))
            .build()
    }

    fn pairs(first: Object, description: &str) -> Array {
        let pair = ArrayBuilder::new()
            .prefix_items([first, number()])
            .items(ArrayItems::False)
            .min_items(Some(2))
            .max_items(Some(2));
        ArrayBuilder::new()
            .items(pair)
            .description(Some(description))
            .build()
    }

    /// `[[name, correlation], …]`.
    pub fn named_numbers() -> Array {
        let name = ObjectBuilder::new().schema_type(Type::String).build();
        pairs(name, "`[signal name, correlation]` pairs")
    }

    /// `[[lag_s, rho], …]`.
    pub fn number_pairs() -> Array {
        pairs(number(), "`[lag s, autocorrelation]` pairs")
    }

    /// `[low, high]` or `null`.
    pub fn optional_interval() -> Array {
        ArrayBuilder::new()
            .schema_type(SchemaType::from_iter([Type::Array, Type::Null]))
            .items(number())
            .min_items(Some(2))
            .max_items(Some(2))
            .description(Some("95 % interval `[low, high]`, or `null`"))
            .build()
    }
}

/// Reading back what serde_json writes: a non-finite `f64` is written as `null`, so a stored
/// `null` reads back as NaN (and `[null, null]` as `[NaN, NaN]`) — the value that writes the
/// same JSON again. A field read with these must be present (or be given `default`).
mod nullable {
    use serde::{Deserialize, Deserializer};

    fn or_nan(v: Option<f64>) -> f64 {
        v.unwrap_or(f64::NAN)
    }

    pub fn f64<'de, D: Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
        Option::<f64>::deserialize(d).map(or_nan)
    }

    pub fn pair<'de, D: Deserializer<'de>>(d: D) -> Result<[f64; 2], D::Error> {
        let [a, b] = <[Option<f64>; 2]>::deserialize(d)?;
        Ok([or_nan(a), or_nan(b)])
    }

    /// `null` is `None`; `[a, b]` with either `null` is `Some` with NaN there.
    pub fn opt_pair<'de, D: Deserializer<'de>>(d: D) -> Result<Option<[f64; 2]>, D::Error> {
        Ok(Option::<[Option<f64>; 2]>::deserialize(d)?.map(|[a, b]| [or_nan(a), or_nan(b)]))
    }

    /// For a field skipped when `None`: present as `null`, it was a non-finite `Some`.
    pub fn some_f64<'de, D: Deserializer<'de>>(d: D) -> Result<Option<f64>, D::Error> {
        f64(d).map(Some)
    }

    pub fn named<'de, D: Deserializer<'de>>(d: D) -> Result<Vec<(String, f64)>, D::Error> {
        let v = Vec::<(String, Option<f64>)>::deserialize(d)?;
        Ok(v.into_iter().map(|(n, x)| (n, or_nan(x))).collect())
    }

    pub fn lags<'de, D: Deserializer<'de>>(d: D) -> Result<Vec<(f64, f64)>, D::Error> {
        let v = Vec::<(Option<f64>, Option<f64>)>::deserialize(d)?;
        Ok(v.into_iter().map(|(a, b)| (or_nan(a), or_nan(b))).collect())
    }
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
    release: &crate::joint::identify::release::Release,
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
        release_rule: release.rule.as_str().to_owned(),
        release_warning: release.warning.clone(),
        release_disturbed_until_s: release.disturbance.as_ref().map(|d| d.until_t_s),
        release_disturbance: release.disturbance.as_ref().map(ReleaseDisturbance::of),
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
        input_offset: fit.get(Param::InputOffset).map(|(v, _, _)| Quantity {
            value: v,
            unit: if model_unit.0 == "rad" { "N·m" } else { "N" }.into(),
        }),
        input_offset_ci95: fit.get(Param::InputOffset).map(|o| o.2),
        samples_fitted: fit.n_fit,
        termination: format!("{:?}", fit.termination),
        iterations: fit.iterations,
        residual_rho1: fit.covariance.rho1,
        interval_inflation: fit.covariance.inflation,
        viscous_dry_correlation: match (iv, id) {
            (Some(a), Some(b)) => corr[(a, b)],
            _ => f64::NAN,
        },
        body_uncertainty: BodyUncertaintyResult::of(fit),
        absorption: None,
        prior: None,
    }
}

#[cfg(test)]
#[path = "report_curve_tests.rs"]
mod curve_tests;

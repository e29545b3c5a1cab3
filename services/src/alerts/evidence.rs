//! What an alert rests on, typed: written by the alert rules ([`super::after_fit`]), stored as
//! JSON with the alert (`alerts.evidence_json`), served with it by the API and read back by the
//! pages ([`Evidence::of`]). One shape per kind of alert; the JSON of each is the object the
//! rules wrote before it was typed (issue 39, point 3), so alerts stored then still read.

use chrono::{DateTime, Utc};
use pantowatch_models::drift::Status;
use pantowatch_models::report::{EffectResult, ParamResult, Quantity, ResidualResult};
use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use crate::health::ParamTrend;
use crate::static_force::{FindingView, LimitsView, MuSource};

/// An alert's evidence: which test and fit raised or last updated it, and the numbers it rests
/// on. Told apart by their keys (no tag: the stored objects have none).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(untagged)]
pub enum Evidence {
    /// A joint at `watch` or `alarm`, or forecast to reach its alarm band.
    Joint(Box<JointEvidence>),
    /// The predicted static contact force outside the type's limits (`static force`).
    StaticForce(Box<StaticForceEvidence>),
    /// A named effect that is a finding on the pantograph, not a joint: a lift's `H sensor`
    /// (`sensor_delay`, `sensor_offset`), a gauge's zero (`force gauge`), a spring's rate
    /// (`spring rate`).
    Effect(Box<EffectEvidence>),
    /// A joint whose evidence is older than its type allows (`J5 test due`, issue 37).
    TestDue(Box<TestDueEvidence>),
}

/// A joint's test due: its evidence at the pantograph's newest test.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct TestDueEvidence {
    /// The newest test of the pantograph, the time the evidence is judged at.
    pub trace_id: String,
    pub at: DateTime<Utc>,
    /// The joint's evidence then (`GET /v1/pantographs/{serial}/evidence`'s shape).
    pub due: crate::evidence::EvidenceJoint,
}

/// A joint's alert.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct JointEvidence {
    pub model_version: String,
    pub fit_id: i64,
    /// The test that decides the joint's state.
    pub trace_id: String,
    pub recorded_at: DateTime<Utc>,
    /// The joint's state as fleet health shows it.
    pub status: Status,
    /// The joint's parameters in that fit, with intervals and baselines.
    #[schema(value_type = Object)]
    pub viscous: ParamResult,
    #[schema(value_type = Object)]
    pub dry: ParamResult,
    /// The fit's residual finding.
    #[schema(value_type = Object)]
    pub residual: ResidualResult,
    #[schema(value_type = Object)]
    pub rmse: Quantity,
    /// Each parameter's trend and forecast over the joint's history.
    pub trends: Vec<ParamTrend>,
    pub horizon_days: f64,
    /// Tests in the joint's history.
    pub tests: usize,
}

/// The static-force finding: where the predicted band leaves the limits, with what it used.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct StaticForceEvidence {
    pub fit_id: i64,
    pub trace_id: String,
    pub recorded_at: DateTime<Utc>,
    pub findings: Vec<FindingView>,
    pub parameters: Vec<MuSource>,
    /// The drive spring the prediction used (a gauge record's named `spring_rate`, or the
    /// type's); absent in findings stored before it was recorded.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub spring: Option<crate::static_force::SpringSource>,
    pub limits: LimitsView,
}

/// A finding named by a fit's residual loop.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct EffectEvidence {
    pub model_version: String,
    pub fit_id: i64,
    pub trace_id: String,
    pub recorded_at: DateTime<Utc>,
    /// The named effect, its parameters and intervals.
    #[schema(value_type = Object)]
    pub effect: EffectResult,
    #[schema(value_type = Object)]
    pub residual: ResidualResult,
}

impl Evidence {
    /// The JSON stored with the alert.
    pub fn to_json(&self) -> serde_json::Value {
        // Every field is a number, a string or a struct of them: the conversion cannot fail
        // (a non-finite number serialises as `null`).
        serde_json::to_value(self).unwrap_or(serde_json::Value::Null)
    }

    /// The evidence of a stored alert; `Err` when its JSON is none of the shapes above.
    pub fn of(alert: &crate::store::Alert) -> Result<Self, serde_json::Error> {
        Self::deserialize(&alert.evidence)
    }

    /// The earliest forecast crossing of the alarm band (a joint's alert; `None` for the others
    /// and for a joint with no forecast).
    pub fn earliest_forecast(&self) -> Option<DateTime<Utc>> {
        match self {
            Evidence::Joint(j) => j
                .trends
                .iter()
                .filter_map(|t| Some(t.forecast.as_ref()?.date))
                .min(),
            Evidence::StaticForce(_) | Evidence::Effect(_) | Evidence::TestDue(_) => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::health::{ForecastView, Param};
    use serde_json::json;

    fn at(s: &str) -> DateTime<Utc> {
        s.parse().expect("a date")
    }

    fn param(value: f64, unit: &str) -> ParamResult {
        ParamResult {
            value,
            ci95: [0.9 * value, 1.1 * value],
            baseline: Some(value),
            unit: unit.to_owned(),
            identifiable: true,
            status: Status::Watch,
            combination: None,
        }
    }

    fn trend(param: Param, forecast: Option<&str>) -> ParamTrend {
        ParamTrend {
            param,
            baseline: Some(0.02),
            alarm_band: Some([0.01, 0.04]),
            trend: None,
            no_trend: forecast.is_none(),
            forecast: forecast.map(|d| ForecastView {
                threshold: 0.04,
                date: at(d),
                date_ci95: [Some(at(d)), None],
            }),
            crossed_on: None,
        }
    }

    fn effect() -> EffectResult {
        EffectResult {
            name: "sensor_offset".into(),
            params: json!({"offset_n": 1.5, "offset_n_ci95": [1.0, 2.0]})
                .as_object()
                .cloned()
                .unwrap_or_default(),
        }
    }

    /// Issue 39, point 3: each kind of evidence is the JSON object the alert rules wrote with
    /// `json!` before it was typed (the same keys from the same values), so an alert stored then
    /// reads as the same evidence; and it reads back to itself.
    #[test]
    fn each_evidence_is_the_object_the_rules_wrote_and_reads_back() {
        let recorded_at = at("2026-03-02T07:15:00Z");
        let (viscous, dry) = (param(0.036, "N·m·s/rad"), param(0.024, "1"));
        let residual = ResidualResult {
            effects: vec![effect()],
            rmse_before: 0.42,
            rmse_after: 0.11,
            holdout_rmse_before: 0.45,
            holdout_rmse_after: 0.12,
            ..ResidualResult::default()
        };
        let rmse = Quantity {
            value: 0.42,
            unit: "deg".into(),
        };
        let trends = vec![
            trend(Param::Viscous, Some("2026-09-01T00:00:00Z")),
            trend(Param::Dry, Some("2026-06-01T00:00:00Z")),
        ];
        let joint = Evidence::Joint(Box::new(JointEvidence {
            model_version: "v1".into(),
            fit_id: 7,
            trace_id: "t-1".into(),
            recorded_at,
            status: Status::Watch,
            viscous: viscous.clone(),
            dry: dry.clone(),
            residual: residual.clone(),
            rmse: rmse.clone(),
            trends: trends.clone(),
            horizon_days: 90.0,
            tests: 4,
        }));
        let joint_before = json!({
            "model_version": "v1", "fit_id": 7, "trace_id": "t-1", "recorded_at": recorded_at,
            "status": Status::Watch, "viscous": viscous, "dry": dry, "residual": residual,
            "rmse": rmse, "trends": trends, "horizon_days": 90.0, "tests": 4,
        });
        let finding = FindingView {
            height_m: 1.2,
            what: "raise_below_min".into(),
            value_n: 60.0,
            limit_n: 70.0,
        };
        let parameters = vec![MuSource {
            joint: "J1".into(),
            dry_mu: 0.02,
            dry_mu_ci95: Some([0.01, 0.03]),
            source: "fit".into(),
            trace_id: Some("t-1".into()),
            recorded_at: Some(recorded_at),
        }];
        let limits = LimitsView {
            nominal_n: vec![90.0],
            min_n: vec![70.0],
            max_n: vec![120.0],
            max_raise_lower_difference_n: 30.0,
            source: "160EC".into(),
        };
        let static_force = Evidence::StaticForce(Box::new(StaticForceEvidence {
            fit_id: 8,
            trace_id: "t-2".into(),
            recorded_at,
            findings: vec![finding.clone()],
            parameters: parameters.clone(),
            spring: None,
            limits: limits.clone(),
        }));
        let static_force_before = json!({
            "fit_id": 8, "trace_id": "t-2", "recorded_at": recorded_at, "findings": [finding],
            "parameters": parameters, "limits": limits,
        });
        let named = Evidence::Effect(Box::new(EffectEvidence {
            model_version: "v1".into(),
            fit_id: 9,
            trace_id: "t-3".into(),
            recorded_at,
            effect: effect(),
            residual: residual.clone(),
        }));
        let named_before = json!({
            "model_version": "v1", "fit_id": 9, "trace_id": "t-3", "recorded_at": recorded_at,
            "effect": effect(), "residual": residual,
        });
        for (typed, before) in [
            (&joint, joint_before),
            (&static_force, static_force_before),
            (&named, named_before),
        ] {
            assert_eq!(typed.to_json(), before);
            assert_eq!(&Evidence::deserialize(&before).expect("reads"), typed);
        }
        assert_eq!(joint.earliest_forecast(), Some(at("2026-06-01T00:00:00Z")));
        assert_eq!(static_force.earliest_forecast(), None);
        assert_eq!(named.earliest_forecast(), None);
        // An object of none of these shapes does not read (the page shows no forecast).
        assert!(Evidence::deserialize(&json!({"model_version": "v1", "trace_id": "t1"})).is_err());
    }
}

//! The fit of one trace document: the models' identification and the contract's fit result.
//! Pure CPU work (pendulum and slider 5–30 ms, lift ~0.5 s, quadrangle swing ~1–3 s): async callers run it with
//! `tokio::task::spawn_blocking`.

use pantowatch_models::drift::DriftThresholds;
use pantowatch_models::identify::{FitOptions, FitOutcome};
use pantowatch_models::lift::report::{LiftReport, fit_lift_trace};
use pantowatch_models::quadrangle::report::{QuadReport, fit_quadrangle_trace};
use pantowatch_models::report::FitResult;
use pantowatch_models::residual::Finding;

use crate::trace::{Kind, TraceDoc, TraceError};

/// Why a document could not be fitted. None of these improves on retry.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FitFailure {
    /// The test kind has no identification of this kind here (a lift has no single-joint
    /// outcome: see [`fit_lift`]).
    #[error("{0}")]
    Unsupported(String),
    /// The document breaks a rule that only the rig check sees.
    #[error("invalid trace: {0}")]
    Invalid(TraceError),
    /// The identification itself failed (no free motion, no convergence, …).
    #[error("fit failed: {0}")]
    Model(String),
}

/// Fits a validated document and returns the contract's fit result.
pub fn fit_document(doc: &TraceDoc, thresholds: &DriftThresholds) -> Result<FitResult, FitFailure> {
    match doc.kind {
        Kind::Lift => return fit_lift(doc, thresholds).map(|r| r.result),
        Kind::QuadrangleSwing => return fit_quadrangle(doc, thresholds).map(|r| r.result),
        Kind::Pendulum | Kind::Slider => {}
    }
    fit_with_outcome(doc, thresholds).map(|(r, _)| r)
}

/// Fits a `lift` document: the complete-pantograph MAP identification (Table 4 prior), every
/// joint J1…J9 in the result (`models::lift::report` holds the mapping).
pub fn fit_lift(doc: &TraceDoc, thresholds: &DriftThresholds) -> Result<LiftReport, FitFailure> {
    let channels = doc.lift_channels().map_err(FitFailure::Invalid)?;
    let id = doc.trace_id.clone().unwrap_or_default();
    fit_lift_trace(&channels, thresholds, &id).map_err(|e| FitFailure::Model(e.to_string()))
}

/// Fits a `quadrangle_swing` document: the lower quadrangle's MAP identification (Table 4
/// prior), joints J1, J2, J2', J3 in the result (`models::quadrangle::report` holds the mapping).
pub fn fit_quadrangle(
    doc: &TraceDoc,
    thresholds: &DriftThresholds,
) -> Result<QuadReport, FitFailure> {
    let (channels, rig) = doc.quadrangle_channels().map_err(FitFailure::Invalid)?;
    let id = doc.trace_id.clone().unwrap_or_default();
    fit_quadrangle_trace(&channels, &rig, thresholds, &id)
        .map_err(|e| FitFailure::Model(e.to_string()))
}

/// As [`fit_document`], also returning the identification (fitted curve, residual) for plots.
pub fn fit_with_outcome(
    doc: &TraceDoc,
    thresholds: &DriftThresholds,
) -> Result<(FitResult, FitOutcome), FitFailure> {
    fit_with_finding(doc, thresholds).map(|(r, f, _)| (r, f))
}

/// As [`fit_with_outcome`], also returning the residual loop's finding (candidates tried,
/// diagnosis, split fits) for the report.
pub fn fit_with_finding(
    doc: &TraceDoc,
    thresholds: &DriftThresholds,
) -> Result<(FitResult, FitOutcome, Finding), FitFailure> {
    match doc.kind {
        Kind::Lift => {
            return Err(FitFailure::Unsupported(
                "a lift test has no single-joint fit outcome: fit it with `fit_lift`".into(),
            ));
        }
        Kind::QuadrangleSwing => {
            return Err(FitFailure::Unsupported(
                "a quadrangle swing has no single-joint fit outcome: fit it with `fit_quadrangle`"
                    .into(),
            ));
        }
        Kind::Pendulum | Kind::Slider => {}
    }
    let (test, baseline) = doc.joint_test().map_err(FitFailure::Invalid)?;
    let id = doc.trace_id.clone().unwrap_or_default();
    pantowatch_models::fit_joint_test_with_finding(
        &test,
        &baseline,
        thresholds,
        &id,
        &FitOptions::default(),
    )
    .map_err(|e| FitFailure::Model(e.to_string()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_lift_too_short_to_fit_is_a_clear_failure_not_a_crash() {
        let v = serde_json::json!({"format": "pantograph-trace/1", "vehicle_id": "V", "pantograph": {"model": "160EC"},
            "recorded_at": "2026-03-02T07:15:00Z", "test": {"kind": "lift"},
            "channels": {"t_s": [0.0, 0.1], "H_m": [1.0, 1.0], "T_Nm": [0.0, 0.0], "Fs_N": [0.0, 0.0]}});
        let doc = TraceDoc::from_value(&v).expect("valid lift document");
        let e = fit_document(&doc, &DriftThresholds::default()).unwrap_err();
        assert!(matches!(e, FitFailure::Model(_)), "{e}");
    }

    #[test]
    fn a_quadrangle_swing_too_short_to_fit_is_a_clear_failure_not_a_crash() {
        let v = serde_json::json!({"format": "pantograph-trace/1", "vehicle_id": "V", "pantograph": {"model": "160EC"},
            "recorded_at": "2026-03-02T07:15:00Z", "test": {"kind": "quadrangle_swing"},
            "channels": {"t_s": [0.0, 0.1], "alpha_deg": [-10.1, -10.1], "beta_deg": [-3.6, -3.6]}});
        let doc = TraceDoc::from_value(&v).expect("valid swing document");
        let e = fit_document(&doc, &DriftThresholds::default()).unwrap_err();
        assert!(
            matches!(&e, FitFailure::Model(m) if m.contains("t_s")),
            "{e}"
        );
        assert!(matches!(
            fit_with_outcome(&doc, &DriftThresholds::default()),
            Err(FitFailure::Unsupported(_))
        ));
    }
}

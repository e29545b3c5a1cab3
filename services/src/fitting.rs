//! The fit of one trace document: the models' identification and the contract's fit result.
//! Pure CPU work (5–30 ms): async callers run it with `tokio::task::spawn_blocking`.

use pantowatch_models::drift::DriftThresholds;
use pantowatch_models::identify::{FitOptions, FitOutcome};
use pantowatch_models::report::FitResult;

use crate::trace::{Kind, TraceDoc, TraceError};

/// Why a document could not be fitted. None of these improves on retry.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FitFailure {
    /// The test kind has no identification yet (`lift`).
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
    fit_with_outcome(doc, thresholds).map(|(r, _)| r)
}

/// As [`fit_document`], also returning the identification (fitted curve, residual) for plots.
pub fn fit_with_outcome(
    doc: &TraceDoc,
    thresholds: &DriftThresholds,
) -> Result<(FitResult, FitOutcome), FitFailure> {
    if doc.kind == Kind::Lift {
        return Err(FitFailure::Unsupported(
            "lift-test identification is not available yet (the complete-pantograph model is \
             another issue); the trace is stored and will be fitted by a later model version"
                .into(),
        ));
    }
    let (test, baseline) = doc.joint_test().map_err(FitFailure::Invalid)?;
    let id = doc.trace_id.clone().unwrap_or_default();
    pantowatch_models::fit_joint_test(&test, &baseline, thresholds, &id, &FitOptions::default())
        .map_err(|e| FitFailure::Model(e.to_string()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lift_is_a_clear_failure_not_a_crash() {
        let v = serde_json::json!({"format": "pantograph-trace/1", "vehicle_id": "V", "pantograph": {"model": "160EC"},
            "recorded_at": "2026-03-02T07:15:00Z", "test": {"kind": "lift"},
            "channels": {"t_s": [0.0, 0.1], "H_m": [1.0, 1.0], "T_Nm": [0.0, 0.0], "Fs_N": [0.0, 0.0]}});
        let doc = TraceDoc::from_value(&v).expect("valid lift document");
        let e = fit_document(&doc, &DriftThresholds::default()).unwrap_err();
        assert!(matches!(e, FitFailure::Unsupported(_)), "{e}");
        assert!(e.to_string().contains("lift"));
    }
}

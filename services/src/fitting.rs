//! The fit of one trace document: the models' identification and the contract's fit result.
//! Pure CPU work (pendulum and slider 5–30 ms, lift ~0.5 s, quadrangle swing ~1–3 s, force gauge ~35 ms in a debug build): async callers run it with
//! `tokio::task::spawn_blocking`, under a budget ([`fit_document_within`]).

use pantowatch_models::budget::{Budget, Exhausted};
use pantowatch_models::drift::DriftThresholds;
use pantowatch_models::identify::{FitOptions, FitOutcome};
use pantowatch_models::lift::gauge::report::GaugeChannels as ModelGaugeChannels;
use pantowatch_models::lift::gauge::{GaugeReport, fit_gauge_trace_with};
use pantowatch_models::lift::report::{LiftReport, fit_lift_trace_with};
use pantowatch_models::quadrangle::report::{QuadReport, fit_quadrangle_trace};
use pantowatch_models::report::{FitCurve, FitResult};
use pantowatch_models::residual::Finding;

use crate::fleet_prior::FitPrior;
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
    /// The fit spent its budget ([`fit_document_within`]): its result, computed with stages
    /// cut short, is not used.
    #[error("{0}")]
    Budget(Exhausted),
}

impl FitFailure {
    /// The label of `pantowatch_jobs_failed_total{reason}` for this failure.
    pub fn reason(&self) -> &'static str {
        match self {
            FitFailure::Unsupported(_) => "unsupported",
            FitFailure::Invalid(_) => "invalid",
            FitFailure::Model(_) => "model",
            FitFailure::Budget(Exhausted::Evaluations(_)) => "evaluations",
            FitFailure::Budget(Exhausted::Cancelled) => "wall_time",
        }
    }
}

/// The limits of one fit (`worker.fit_max_evaluations`, `worker.fit_budget_secs`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FitLimits {
    pub max_evaluations: u64,
    pub wall: std::time::Duration,
}

/// [`fit_document`] under `budget` (`models::budget`): at most its model evaluations, and
/// stopped within ~1 ms of its canceller firing (the caller's wall-time limit or a shutdown).
/// Every fitter charges the same budget, so no document can hold a worker for good. Returns the
/// curve too: the worker stores it with the fit.
pub fn fit_document_within(
    doc: &TraceDoc,
    thresholds: &DriftThresholds,
    budget: &Budget,
) -> Result<Fitted, FitFailure> {
    fit_document_within_prior(doc, thresholds, None, budget)
}

/// [`fit_document_within`] with the fleet prior `prior` for the unreported joints of a lift or
/// a force-gauge record (`services::fleet_prior`; recorded in `fit.prior`); other kinds ignore
/// it. `None`: Table 4.
pub fn fit_document_within_prior(
    doc: &TraceDoc,
    thresholds: &DriftThresholds,
    prior: Option<&FitPrior>,
    budget: &Budget,
) -> Result<Fitted, FitFailure> {
    pantowatch_models::budget::run(budget, || {
        fit_document_with_curve_prior(doc, thresholds, prior)
    })
    .unwrap_or_else(|e| Err(FitFailure::Budget(e)))
}

/// A fit as the worker stores it: the contract's result and the measured-vs-model curve that
/// pages draw (issue 19, point 4: stored with the fit, never refitted to draw).
#[derive(Debug, Clone)]
pub struct Fitted {
    pub result: FitResult,
    /// `None` when the fit has no curve to draw (fewer than 2 finite fitted samples).
    pub curve: Option<FitCurve>,
}

/// Fits a validated document and returns the contract's fit result.
pub fn fit_document(doc: &TraceDoc, thresholds: &DriftThresholds) -> Result<FitResult, FitFailure> {
    fit_document_with_curve(doc, thresholds).map(|f| f.result)
}

/// [`fit_document`] with the fit's curve: the fitted channel measured and modelled over the
/// fitted samples (pendulum and slider: the joint's channel from the release; lift: `H_m`;
/// quadrangle swing: `alpha_deg`).
pub fn fit_document_with_curve(
    doc: &TraceDoc,
    thresholds: &DriftThresholds,
) -> Result<Fitted, FitFailure> {
    fit_document_with_curve_prior(doc, thresholds, None)
}

/// [`fit_document_with_curve`] with a lift's or gauge's fleet prior (see
/// [`fit_document_within_prior`]).
pub fn fit_document_with_curve_prior(
    doc: &TraceDoc,
    thresholds: &DriftThresholds,
    prior: Option<&FitPrior>,
) -> Result<Fitted, FitFailure> {
    match doc.kind {
        Kind::Lift => {
            let rep = fit_lift_with(doc, thresholds, prior)?;
            let ch = doc.lift_channels().map_err(FitFailure::Invalid)?;
            let curve =
                FitCurve::thinned("H_m", "m", ch.t_s, ch.strip_height_m, &rep.fitted_height_m);
            Ok(Fitted {
                result: rep.result,
                curve,
            })
        }
        Kind::QuadrangleSwing => {
            let rep = fit_quadrangle(doc, thresholds)?;
            let (ch, _) = doc.quadrangle_channels().map_err(FitFailure::Invalid)?;
            let model: Vec<f64> = rep
                .fit
                .fitted_alpha_rad
                .iter()
                .map(|v| v.to_degrees())
                .collect();
            let curve = FitCurve::thinned("alpha_deg", "deg", ch.t_s, ch.alpha_deg, &model);
            Ok(Fitted {
                result: rep.result,
                curve,
            })
        }
        Kind::StaticForce => {
            // The gauge's readings in the order taken: measured and modelled force over the
            // readings' times (raising, then lowering).
            let rep = fit_static_force_with(doc, thresholds, prior)?;
            let t = doc.channel("t_s").unwrap_or_default();
            let curve = FitCurve::thinned("F_N", "N", t, &rep.record.forces_n, &rep.fit.fitted_n);
            Ok(Fitted {
                result: rep.result,
                curve,
            })
        }
        Kind::Pendulum | Kind::Slider => {
            let (test, _) = doc.joint_test().map_err(FitFailure::Invalid)?;
            let (result, o) = fit_with_outcome(doc, thresholds)?;
            let end = (o.start + o.n_fit)
                .min(test.t_s.len())
                .min(test.y.len())
                .min(o.start + o.model_y.len());
            // The contract's channel of each kind (`TRACE_FORMAT.md`): deg is a pendulum's α,
            // mm a slider's h.
            let channel = if test.unit == "deg" {
                "alpha_deg"
            } else {
                "h_mm"
            };
            let curve = (end > o.start)
                .then(|| {
                    FitCurve::thinned(
                        channel,
                        test.unit,
                        &test.t_s[o.start..end],
                        &test.y[o.start..end],
                        &o.model_y[..end - o.start],
                    )
                })
                .flatten();
            Ok(Fitted { result, curve })
        }
    }
}

/// Fits a `static_force` document (a force gauge's raising and lowering readings, issue 20):
/// the MAP fit of the revolute joints' dry friction from the hysteresis, with the residual
/// loop's `sensor_offset` and `spring_rate` (`models::lift::gauge` holds the mapping: every
/// joint J1…J9 and the combination it informs, as a lift's result).
pub fn fit_static_force(
    doc: &TraceDoc,
    thresholds: &DriftThresholds,
) -> Result<GaugeReport, FitFailure> {
    fit_static_force_with(doc, thresholds, None)
}

/// [`fit_static_force`] under the fleet prior `prior` for the joints the record does not
/// report, recorded in the result's `fit.prior`; `None`: Table 4 ± `prior_relative_sd`,
/// nothing recorded.
pub fn fit_static_force_with(
    doc: &TraceDoc,
    thresholds: &DriftThresholds,
    prior: Option<&FitPrior>,
) -> Result<GaugeReport, FitFailure> {
    let g = doc.static_force_channels().map_err(FitFailure::Invalid)?;
    let channels = ModelGaugeChannels {
        strip_height_m: g.strip_height_m,
        force_n: g.force_n,
        resolution_n: g.gauge_resolution_n,
    };
    let id = doc.trace_id.clone().unwrap_or_default();
    let friction_prior = prior.map_or(&[][..], |p| &p.friction_prior[..]);
    let mut rep =
        fit_gauge_trace_with(&channels, thresholds, &id, friction_prior).map_err(|e| {
            match e.field_path() {
                Some(field) => FitFailure::Invalid(TraceError {
                    field,
                    message: e.to_string(),
                }),
                None => FitFailure::Model(e.to_string()),
            }
        })?;
    rep.result.fit.prior = prior.map(|p| p.used.clone());
    Ok(rep)
}

/// Fits a `lift` document: the complete-pantograph MAP identification (Table 4 prior), every
/// joint J1…J9 in the result (`models::lift::report` holds the mapping).
pub fn fit_lift(doc: &TraceDoc, thresholds: &DriftThresholds) -> Result<LiftReport, FitFailure> {
    fit_lift_with(doc, thresholds, None)
}

/// [`fit_lift`] under the fleet prior `prior` for the joints it does not report, recorded in
/// the result's `fit.prior`; `None`: Table 4 ± `prior_relative_sd`, nothing recorded.
pub fn fit_lift_with(
    doc: &TraceDoc,
    thresholds: &DriftThresholds,
    prior: Option<&FitPrior>,
) -> Result<LiftReport, FitFailure> {
    let channels = doc.lift_channels().map_err(FitFailure::Invalid)?;
    let id = doc.trace_id.clone().unwrap_or_default();
    let friction_prior = prior.map_or(&[][..], |p| &p.friction_prior[..]);
    let mut rep = fit_lift_trace_with(&channels, thresholds, &id, friction_prior)
        .map_err(|e| FitFailure::Model(e.to_string()))?;
    rep.result.fit.prior = prior.map(|p| p.used.clone());
    Ok(rep)
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
        Kind::StaticForce => {
            return Err(FitFailure::Unsupported(
                "a static_force test has no single-joint fit outcome: fit it with \
                 `fit_static_force`"
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

    /// A raise-and-lower lift with J3 dry friction ×1.8 and the stand's sensor noise on every
    /// channel (`cli::simulate::docs::noisy_lift_doc`): a fit of ~20 evaluations.
    fn noisy_lift() -> TraceDoc {
        crate::cli::simulate::docs::noisy_lift_doc(3, &["J3:dry=1.8"], 1.0, "160EC-T", "budget")
            .expect("simulated lift")
    }

    #[test]
    fn a_fit_past_its_evaluation_budget_fails_and_says_so() {
        let doc = noisy_lift();
        let roomy = Budget::new(10_000);
        let ok = fit_document_within(&doc, &DriftThresholds::default(), &roomy);
        assert!(ok.is_ok(), "{ok:?}");
        let needed = roomy.evaluations();
        assert!(needed > 3, "{needed} evaluations");
        let tight = Budget::new(3);
        let e = fit_document_within(&doc, &DriftThresholds::default(), &tight).unwrap_err();
        assert_eq!(e, FitFailure::Budget(Exhausted::Evaluations(3)));
        assert_eq!(e.reason(), "evaluations");
        // Spent, every later stage stopped at once: a few charges past the limit, not the
        // whole fit's.
        assert!(
            tight.evaluations() < needed,
            "{} charged under a budget of 3 (the fit needs {needed})",
            tight.evaluations()
        );
    }

    #[test]
    fn a_cancelled_fit_stops_and_its_result_is_not_used() {
        let doc = noisy_lift();
        let b = Budget::new(u64::MAX);
        let stop = b.canceller();
        stop.cancel();
        let e = fit_document_within(&doc, &DriftThresholds::default(), &b).unwrap_err();
        assert_eq!(e, FitFailure::Budget(Exhausted::Cancelled));
        assert_eq!(e.reason(), "wall_time");
        // Cancelled before it started: no evaluation ran past the first charge.
        assert!(b.evaluations() <= 1, "{}", b.evaluations());
    }

    #[test]
    fn a_fit_cancelled_midway_stops_within_its_current_stage() {
        let doc = noisy_lift();
        let roomy = Budget::new(10_000);
        fit_document_within(&doc, &DriftThresholds::default(), &roomy).expect("fits");
        let needed = roomy.evaluations();
        let b = Budget::new(u64::MAX);
        let stop = b.canceller();
        let watched = b.clone();
        let fit =
            std::thread::spawn(move || fit_document_within(&doc, &DriftThresholds::default(), &b));
        // Cancelled after its second evaluation, long before the ~20 it needs.
        while watched.evaluations() < 2 {
            std::thread::yield_now();
        }
        stop.cancel();
        let e = fit.join().expect("no panic").unwrap_err();
        assert_eq!(e, FitFailure::Budget(Exhausted::Cancelled));
        assert!(
            watched.evaluations() < needed,
            "{} evaluations after the cancel (the whole fit needs {needed})",
            watched.evaluations()
        );
    }
}

//! Withholding a fit's statuses: every joint `unknown`, no alert, no evidence, the reason said,
//! where the friction fitted may carry a model error the fit could not name.

use crate::contract::drift::Status;
use crate::contract::report::FitResult;

/// Withhold every joint and combination of `r`: not identified, status `unknown` (no alert,
/// health unchanged, no evidence for the plan), the verdict `unexplained`, and `reason` in
/// `residual.joints_withheld` (kept if one is already there). Used where the fit's friction
/// may carry a model error it could not name: the lift's absorption check
/// (`lift::absorbed`) and a single-joint record whose residual loop ends `unexplained`
/// (`fit_joint_test`): an unmodelled effect must not become a wear alarm.
pub fn withhold_all(r: &mut FitResult, reason: String) {
    for j in &mut r.joints {
        for p in [&mut j.viscous, &mut j.dry] {
            p.identifiable = false;
            p.status = Status::Unknown;
        }
        j.identifiable = false;
        j.status = Status::Unknown;
    }
    for c in &mut r.combinations {
        c.identifiable = false;
        c.status = Status::Unknown;
    }
    r.residual.verdict = Some("unexplained".into());
    if r.residual.joints_withheld.is_none() {
        r.residual.joints_withheld = Some(reason);
    }
}

/// A single-joint record the residual loop leaves `unexplained` has a model error the
/// vocabulary cannot name; the friction fitted to it may carry that error (measured: the
/// 90° encoder pendulum's held first swing read dry friction 0 [0, 0.78] before the release
/// check). Its statuses are withheld (`unknown`, no alert, no evidence), as a lift's are
/// ([`withhold_all`]): an unmodelled effect must not become a wear alarm. The
/// values and intervals stay in the report for the engineer; `noise_sigma` is the residual
/// loop's noise estimate (channel units), quoted in the reason.
pub fn if_unexplained(result: &mut FitResult, noise_sigma: f64) {
    if result.residual.verdict.as_deref() != Some("unexplained") {
        return;
    }
    let r = &result.residual;
    let reason = format!(
        "the residual loop could not name what the model lacks (held-out RMSE {:.4} {unit}, \
         noise {:.4} {unit}): the friction fitted may carry it, so no status is given",
        r.holdout_rmse_after,
        noise_sigma,
        unit = result.rmse.unit
    );
    withhold_all(result, reason);
}

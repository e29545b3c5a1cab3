//! What a rig's stated body-parameter uncertainty adds to a single-joint fit's covariance
//! (issue 17, point 1): each stated error of mass, inertia or centre-of-mass distance, propagated.
//!
//! The fit holds the body at its stated values; a body off them moves the simulated motion,
//! which the fit absorbs into the friction where it can — the residual barely shows that part,
//! so the sandwich of the residual misses it. Per stated uncertainty b with sd σ: the fit is
//! run again from its optimum with b stated at +σ and at −σ, and half the difference of the two
//! estimates, s = −(θ̂(b+σ) − θ̂(b−σ))/2, is the parameters' shift when the true body is 1 σ
//! above the stated one (the estimator's own central difference over the stated range); Σ s·sᵀ
//! is added to the covariance.
//! Why refits, not the fit's linear response (JᵀJ)⁻¹Jᵀ·∂y/∂b: an inertia error changes the
//! period, which no friction parameter can absorb; its projection onto the Jacobian's columns
//! asks for large moves of D and μ that the bounded, nonlinear fit does not make (measured, e2e
//! `body_uncertainty`: a 2 % inertia sd on J1, J3 and J7 gave 15–140× the shift refitting
//! shows; on J5, 17 %). Each refit is warm-started (a few evaluations). Applied to the fit a
//! test reports (`identify::carry_body_uncertainty`), not inside the residual loop.
//! Assumptions (stated): the errors are independent and Gaussian with the stated sd; the
//! estimate's response is linear between −σ and +σ (a secant, not a tangent); the data do not
//! update the body (no posterior on b — conservative when the trace itself informs b). When
//! `inertia_error` is fitted, the inertia it estimates (a pendulum's about its pin, a slider's
//! moving mass) is not propagated: the augmented fit's own interval already holds it.

use nalgebra::{DMatrix, DVector};

use crate::joint::dynamics::Mechanism;

/// One stated body-parameter uncertainty of a test, ready to propagate.
#[derive(Debug, Clone, PartialEq)]
pub struct BodySd {
    /// The quantity it qualifies, as the rig states it: `mass_kg`, `inertia_kgm2`,
    /// `com_distance_m` (a pendulum's body) or `moving_mass_kg` (a slider).
    pub quantity: &'static str,
    /// The stated standard uncertainty, the quantity's unit.
    pub sd: f64,
    /// The `inertia_error` effect estimates this quantity (a pendulum's inertia about its pin, a
    /// slider's moving mass): not propagated when that effect is fitted.
    pub inertia: bool,
    /// The test's mechanism with the quantity at its stated value + sd, all else as stated.
    pub plus: Mechanism,
    /// … and at its stated value − sd.
    pub minus: Mechanism,
}

/// One stated uncertainty as a fit carried it.
#[derive(Debug, Clone, PartialEq)]
pub struct BodyShift {
    pub quantity: &'static str,
    pub sd: f64,
    /// Added to the covariance; `false`: estimated by the fit instead (`inertia_error`).
    pub propagated: bool,
    /// The parameters' shift (in the fit's parameter order) when the true quantity is 1 sd
    /// above the stated one; empty when not propagated.
    pub shift_per_sd: Vec<f64>,
}

/// The covariance the stated uncertainties add, and what was carried. `refit` fits the test
/// again with a mechanism and returns the estimate (the fit's parameter order; `None`: it
/// failed, and that uncertainty is reported not propagated); `inertia_fitted`: the fit
/// estimates the inertia (`inertia_error`). `None` for the covariance when nothing was added.
pub fn covariance(
    terms: &[BodySd],
    inertia_fitted: bool,
    refit: impl Fn(&Mechanism) -> Option<Vec<f64>>,
) -> (Option<DMatrix<f64>>, Vec<BodyShift>) {
    let mut shifts = Vec::new();
    let mut sum: Option<DMatrix<f64>> = None;
    for t in terms {
        let skip = BodyShift {
            quantity: t.quantity,
            sd: t.sd,
            propagated: false,
            shift_per_sd: Vec::new(),
        };
        if t.inertia && inertia_fitted {
            shifts.push(skip);
            continue;
        }
        let (Some(up), Some(down)) = (refit(&t.plus), refit(&t.minus)) else {
            shifts.push(skip);
            continue;
        };
        // Stated high, the estimate moves as if the truth were low: the shift for a true body
        // 1 sd above the stated one is minus half the difference.
        let s = DVector::from_iterator(up.len(), up.iter().zip(&down).map(|(a, b)| -0.5 * (a - b)));
        if up.len() != down.len() || s.iter().any(|v| !v.is_finite()) {
            shifts.push(skip);
            continue;
        }
        let add = &s * s.transpose();
        sum = Some(match sum {
            Some(m) if m.shape() == add.shape() => m + add,
            _ => add,
        });
        shifts.push(BodyShift {
            quantity: t.quantity,
            sd: t.sd,
            propagated: true,
            shift_per_sd: s.iter().copied().collect(),
        });
    }
    (sum, shifts)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::joint::rig::SliderRig;

    /// A model whose estimate a = 2 − 0.5·m moves with the stated mass m: the shift for a true
    /// mass 1 sd high is +0.5·σ; an inertia term is left out when the inertia is fitted.
    #[test]
    fn the_shift_is_the_refits_half_difference() {
        let rig = |m: f64| Mechanism::Slider(SliderRig::new(m, 1, 4.0, 1.0).unwrap());
        let term = BodySd {
            quantity: "moving_mass_kg",
            sd: 0.5,
            inertia: true,
            plus: rig(10.5),
            minus: rig(9.5),
        };
        let refit = |m: &Mechanism| match m {
            Mechanism::Slider(r) => Some(vec![2.0 - 0.5 * r.moving_mass_kg, 1.0]),
            Mechanism::Pendulum(_) => None,
        };
        let (cov, carried) = covariance(std::slice::from_ref(&term), false, refit);
        assert!(
            (carried[0].shift_per_sd[0] - 0.25).abs() < 1e-12,
            "{carried:?}"
        );
        assert_eq!(carried[0].shift_per_sd[1], 0.0);
        let cov = cov.unwrap();
        assert!((cov[(0, 0)] - 0.0625).abs() < 1e-12 && cov[(1, 1)] == 0.0);
        let (cov, carried) = covariance(&[term], true, refit);
        assert!(cov.is_none() && !carried[0].propagated);
        let (cov, carried) = covariance(&[], false, refit);
        assert!(cov.is_none() && carried.is_empty());
    }
}

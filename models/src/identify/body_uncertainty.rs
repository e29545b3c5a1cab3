//! What a rig's stated body-parameter uncertainty adds to a single-joint fit's covariance
//! (issue 17, point 1): each stated error of mass, inertia or centre-of-mass distance, propagated.
//!
//! The fit holds the body at its stated values; a body off them moves the simulated motion, which
//! the fit absorbs into the friction (a 2 % inertia error shifts the period, and the damping
//! with it) — the residual barely shows it, so the sandwich of the residual misses it. Linearised
//! propagation, per stated uncertainty b with sd σ: the readings at the estimate with b at +σ and
//! at −σ (central difference over the stated range), and the fit's own linear response
//! maps their half-difference to the parameters: s = (JᵀJ)⁻¹Jᵀ·(y(b+σ) − y(b−σ))/2, the
//! parameters' shift when the true body is 1 σ off; Σ s·sᵀ is added to the covariance.
//! Assumptions (stated): the errors are independent and Gaussian with the stated sd; the
//! response is linear over ±1 σ; the data do not update the body (no posterior on b — a
//! conservative width when the trace itself informs b). The fit's least squares is unweighted,
//! so the response is too (as `input_noise`). When `inertia_error` is fitted, the inertia it
//! estimates (a pendulum's about its pin, a slider's moving mass) is not propagated: the
//! augmented fit's own interval already holds it.

use nalgebra::{DMatrix, DVector};

use crate::dynamics::Mechanism;

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

/// The covariance the stated uncertainties add, and what was carried. `run` simulates the
/// model at the estimate with a mechanism and returns its readings over the fitted samples
/// (`None`: it could not be run; that uncertainty is then left out and reported not
/// propagated); `jac` is the fit's Jacobian at the estimate; `inertia_fitted`: the fit
/// estimates the inertia (`inertia_error`). `None` for the covariance when nothing was added.
pub fn covariance(
    terms: &[BodySd],
    inertia_fitted: bool,
    jac: &DMatrix<f64>,
    run: impl Fn(&Mechanism) -> Option<Vec<f64>>,
) -> (Option<DMatrix<f64>>, Vec<BodyShift>) {
    let mut shifts = Vec::new();
    if terms.is_empty() {
        return (None, shifts);
    }
    let p = jac.ncols();
    let svd = jac.tr_mul(jac).svd(true, true);
    let smax = svd.singular_values.max();
    let ainv = svd.pseudo_inverse(smax * 1e-13).ok();
    let mut sum = DMatrix::zeros(p, p);
    let mut added = false;
    for t in terms {
        let skip = BodyShift {
            quantity: t.quantity,
            sd: t.sd,
            propagated: false,
            shift_per_sd: Vec::new(),
        };
        let response = ainv.as_ref().filter(|_| !(t.inertia && inertia_fitted));
        let Some(ainv) = response else {
            shifts.push(skip);
            continue;
        };
        let (Some(up), Some(down)) = (run(&t.plus), run(&t.minus)) else {
            shifts.push(skip);
            continue;
        };
        if up.len() != jac.nrows() || down.len() != jac.nrows() {
            shifts.push(skip);
            continue;
        }
        let dy = DVector::from_iterator(up.len(), up.iter().zip(&down).map(|(a, b)| 0.5 * (a - b)));
        let s = ainv * jac.tr_mul(&dy);
        if s.iter().any(|v| !v.is_finite()) {
            shifts.push(skip);
            continue;
        }
        sum += &s * s.transpose();
        added = true;
        shifts.push(BodyShift {
            quantity: t.quantity,
            sd: t.sd,
            propagated: true,
            shift_per_sd: s.iter().copied().collect(),
        });
    }
    (added.then_some(sum), shifts)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rig::SliderRig;

    /// A linear model y = a·x + b·c(x) with c's coefficient b stated ± σ: the shift is the
    /// regression of b's column on the fitted one, exactly, and an inertia term is left out
    /// when the inertia is fitted.
    #[test]
    fn the_shift_is_the_fits_linear_response_to_the_stated_error() {
        let n = 50;
        let x: Vec<f64> = (0..n).map(|k| k as f64 / n as f64).collect();
        let jac = DMatrix::from_fn(n, 1, |k, _| x[k]);
        let rig = |m: f64| Mechanism::Slider(SliderRig::new(m, 1, 4.0, 1.0).unwrap());
        let term = BodySd {
            quantity: "moving_mass_kg",
            sd: 0.5,
            inertia: true,
            plus: rig(10.5),
            minus: rig(9.5),
        };
        // y = 2x + m·x²: ∂y/∂m·σ = σ x²; the shift on a is Σx³/Σx² · σ.
        let run = |m: &Mechanism| match m {
            Mechanism::Slider(r) => Some(
                x.iter()
                    .map(|x| 2.0 * x + r.moving_mass_kg * x * x)
                    .collect(),
            ),
            Mechanism::Pendulum(_) => None,
        };
        let (cov, carried) = covariance(std::slice::from_ref(&term), false, &jac, run);
        let want =
            0.5 * x.iter().map(|v| v.powi(3)).sum::<f64>() / x.iter().map(|v| v * v).sum::<f64>();
        assert!(
            (carried[0].shift_per_sd[0] - want).abs() < 1e-9,
            "{carried:?}"
        );
        assert!((cov.unwrap()[(0, 0)] - want * want).abs() < 1e-9);
        let (cov, carried) = covariance(&[term], true, &jac, run);
        assert!(cov.is_none() && !carried[0].propagated);
        let (cov, carried) = covariance(&[], false, &jac, run);
        assert!(cov.is_none() && carried.is_empty());
    }
}

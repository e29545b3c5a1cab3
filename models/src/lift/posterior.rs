//! The prior of a term fitted besides the friction and the posterior's linear algebra, shared by
//! the lift fit ([`super::identify`]) and the gauge fit ([`super::gauge::fit`]) so that neither
//! imports the other (issue 39, point 4): an [`EffectPrior`]; the inverse of an information
//! matrix, [`inverse_spd`] (Cholesky, else the pseudo-inverse [`pinv`]); [`correlation`].
//!
//! Below every fit: it imports nothing of the crate.

use nalgebra::DMatrix;

/// The prior of one parameter fitted besides the friction (a lift's effect,
/// `lift::fit::effect_prior`; a gauge's zero or spring-rate factor, `gauge::terms`): a normal
/// N(mean, sd²) in the parameter's own units, cut to [lower, upper] (the fit's box bounds).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EffectPrior {
    pub mean: f64,
    pub sd: f64,
    pub lower: f64,
    pub upper: f64,
}

/// Inverse of a symmetric positive-definite matrix (Cholesky), or its pseudo-inverse when the
/// factorisation fails (a direction without information and without prior).
pub fn inverse_spd(a: &DMatrix<f64>) -> DMatrix<f64> {
    match a.clone().cholesky() {
        Some(c) => c.inverse(),
        None => pinv(a),
    }
}

/// Pseudo-inverse of a symmetric positive semi-definite matrix (directions below 10⁻¹² of the
/// largest dropped).
pub fn pinv(a: &DMatrix<f64>) -> DMatrix<f64> {
    let svd = a.clone().svd(true, true);
    let smax = svd.singular_values.max();
    svd.pseudo_inverse(smax * 1e-12)
        .unwrap_or_else(|_| DMatrix::zeros(a.nrows(), a.ncols()))
}

/// The correlation matrix of a covariance (0 where a variance is 0).
pub fn correlation(cov: &DMatrix<f64>) -> DMatrix<f64> {
    let n = cov.nrows();
    DMatrix::from_fn(n, n, |i, j| {
        let d = (cov[(i, i)] * cov[(j, j)]).sqrt();
        if d > 0.0 { cov[(i, j)] / d } else { 0.0 }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_inverse_is_exact_and_a_singular_matrix_gets_its_pseudo_inverse() {
        let a = DMatrix::from_row_slice(2, 2, &[4.0, 2.0, 2.0, 3.0]);
        let inv = inverse_spd(&a);
        let id = &a * &inv;
        assert!((id - DMatrix::identity(2, 2)).norm() < 1e-12);
        // Rank one: the pseudo-inverse, A·A⁺·A = A.
        let s = DMatrix::from_row_slice(2, 2, &[1.0, 1.0, 1.0, 1.0]);
        let p = inverse_spd(&s);
        assert!((&s * &p * &s - &s).norm() < 1e-12);
        let c = correlation(&a);
        assert!((c[(0, 1)] - 2.0 / 12f64.sqrt()).abs() < 1e-12);
        assert_eq!(c[(0, 0)], 1.0);
    }
}

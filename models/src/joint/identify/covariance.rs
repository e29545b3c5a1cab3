//! Parameter covariance from the final Jacobian, corrected for correlated residuals.
//!
//! Sandwich estimator Cov = (JᵀJ)⁻¹ S (JᵀJ)⁻¹ with S the long-run covariance of the scores
//! gₜ = Jₜ·rₜ, estimated by overlapping batch means (equivalent to Newey–West's Bartlett kernel)
//! with the batch length from Andrews' AR(1) plug-in rule. White residuals give batch length 1
//! and the classical s²(JᵀJ)⁻¹ up to noise; a misfit's slow residual widens the intervals.

use nalgebra::DMatrix;

/// The covariance and how it was formed.
#[derive(Debug, Clone)]
pub struct Covariance {
    pub cov: DMatrix<f64>,
    /// Lag-1 autocorrelation of the residual.
    pub rho1: f64,
    /// Batch length (samples) of the long-run score covariance.
    pub batch: usize,
    /// Ratio of the corrected to the classical variance, averaged over parameters.
    pub inflation: f64,
}

/// Standard error of parameter i.
impl Covariance {
    pub fn std(&self, i: usize) -> f64 {
        self.cov[(i, i)].max(0.0).sqrt()
    }
    /// Correlation matrix.
    pub fn correlation(&self) -> DMatrix<f64> {
        let n = self.cov.nrows();
        DMatrix::from_fn(n, n, |i, j| {
            let d = self.std(i) * self.std(j);
            if d > 0.0 { self.cov[(i, j)] / d } else { 0.0 }
        })
    }
}

/// Pseudo-inverse of a symmetric positive semi-definite matrix by SVD (singular directions dropped).
fn pinv_sym(a: &DMatrix<f64>) -> DMatrix<f64> {
    let svd = a.clone().svd(true, true);
    let smax = svd.singular_values.max();
    svd.pseudo_inverse(smax * 1e-13)
        .unwrap_or_else(|_| DMatrix::zeros(a.nrows(), a.ncols()))
}

pub use crate::numerics::stats::dot;

/// Covariance of the least-squares estimate at its optimum.
pub fn sandwich(jac: &DMatrix<f64>, r: &[f64]) -> Covariance {
    sandwich_with(jac, r, None)
}

/// [`sandwich`] with JᵀJ given when the caller has it ([`super::lm::LmReport::gram`]: the
/// LM's last iteration formed it from the same Jacobian; session 22).
pub fn sandwich_with(jac: &DMatrix<f64>, r: &[f64], gram: Option<&DMatrix<f64>>) -> Covariance {
    let (n, p) = (jac.nrows(), jac.ncols());
    let dof = (n as f64 - p as f64).max(1.0);
    let ainv = match gram.filter(|g| g.shape() == (p, p)) {
        Some(g) => pinv_sym(g),
        None => pinv_sym(&super::lm::gram(jac)),
    };
    let ssr: f64 = r.iter().map(|v| v * v).sum();
    let classical = &ainv * (ssr / dof);

    let mean = r.iter().sum::<f64>() / n as f64;
    let (mut c0, mut c1) = (0.0, 0.0);
    for k in 0..n {
        c0 += (r[k] - mean).powi(2);
        if k > 0 {
            c1 += (r[k] - mean) * (r[k - 1] - mean);
        }
    }
    let rho1 = if c0 > 0.0 {
        (c1 / c0).clamp(-0.99, 0.99)
    } else {
        0.0
    };
    // Andrews (1991), Bartlett kernel, AR(1) plug-in: bandwidth 1.1447·(α n)^(1/3),
    // α = 4ρ²/((1−ρ)²(1+ρ)²).
    let alpha = 4.0 * rho1 * rho1 / ((1.0 - rho1).powi(2) * (1.0 + rho1).powi(2));
    let batch = ((1.1447 * (alpha * n as f64).cbrt()).ceil() as usize).clamp(1, (n / 5).max(1));

    // Overlapping batch means of the scores via prefix sums: S = n/(n−b+1) · (1/b) Σⱼ BⱼBⱼᵀ,
    // as BᵀB with B the (n−b+1)×p matrix of the batch sums, one column per parameter: p column
    // passes and p(p+1)/2 dot products over contiguous slices (issue 38, session 21: the sum
    // over batches, each adding its p(p+1)/2 products, was a seventh of a pendulum's
    // identification; the same sums, added in another order).
    let nb = n + 1 - batch;
    let mut sums = Vec::with_capacity(nb * p);
    let mut prefix = Vec::with_capacity(n + 1);
    for col in jac.as_slice().chunks_exact(n.max(1)) {
        prefix.clear();
        prefix.push(0.0);
        let mut acc = 0.0;
        for (jk, rk) in col.iter().zip(r) {
            acc += jk * rk;
            prefix.push(acc);
        }
        sums.extend(
            prefix[batch..]
                .iter()
                .zip(&prefix[..nb])
                .map(|(hi, lo)| hi - lo),
        );
    }
    let mut s = DMatrix::<f64>::zeros(p, p);
    let cols: Vec<&[f64]> = sums.chunks_exact(nb.max(1)).collect();
    for a in 0..p {
        for b in a..p {
            s[(a, b)] = dot(cols[a], cols[b]);
        }
    }
    let scale = n as f64 / ((n - batch + 1) as f64 * batch as f64) * (n as f64 / dof);
    for a in 0..p {
        for b in a..p {
            s[(a, b)] *= scale;
            s[(b, a)] = s[(a, b)];
        }
    }
    let cov = &ainv * s * &ainv;
    let inflation = (0..p)
        .filter(|&i| classical[(i, i)] > 0.0)
        .map(|i| cov[(i, i)] / classical[(i, i)])
        .sum::<f64>()
        / p.max(1) as f64;
    Covariance {
        cov,
        rho1,
        batch,
        inflation,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::numerics::noise::Noise;

    /// Straight-line regression: with white noise the sandwich agrees with s²(XᵀX)⁻¹; with AR(1)
    /// noise (ρ = 0.9) it widens the slope's interval by about √((1+ρ)/(1−ρ)) ≈ 4.4.
    #[test]
    fn white_and_correlated_residuals() {
        let n = 4000;
        let jac = DMatrix::from_fn(n, 2, |k, j| if j == 0 { 1.0 } else { k as f64 / n as f64 });
        let mut rng = Noise::new(3);
        let white: Vec<f64> = (0..n).map(|_| rng.normal()).collect();
        let c = sandwich(&jac, &white);
        assert!(c.batch <= 4, "batch {} for rho1 {}", c.batch, c.rho1);
        assert!((c.inflation - 1.0).abs() < 0.15, "{}", c.inflation);
        let mut e = 0.0;
        let ar: Vec<f64> = (0..n)
            .map(|_| {
                e = 0.9 * e + rng.normal();
                e
            })
            .collect();
        let c = sandwich(&jac, &ar);
        assert!(c.batch > 10);
        assert!(
            c.inflation > 8.0 && c.inflation < 40.0,
            "variance inflation {}",
            c.inflation
        );
    }
}

//! Shared statistics, a leaf module: residual whiteness (Ljung–Box), noise from first
//! differences, correlation, and the Student-t, χ² and normal quantiles (from `statrs`).
//!
//! Nothing here knows about joints, fits or reports; `identify`, `residual`, `lift` and
//! `trend` all read it, so none of them has to import another for a statistic.

use statrs::distribution::{ChiSquared, ContinuousCDF, Normal, StudentsT};

/// Lags of the Ljung–Box whiteness test used throughout (20: a few oscillation periods of a
/// joint test at the sampling rates in use, as in the standard choice min(20, n/4)).
pub const LB_LAGS: usize = 20;

/// Upper-tail probability at which a residual is called not white (p = 0.001: a fit is
/// refitted with an effect only on strong evidence).
pub const WHITENESS_P: f64 = 0.001;

/// Standard normal 0.975 quantile, the half-width of a two-sided 95 % interval in sd units
/// (1.959 963 98…; `normal_quantile(0.975)` computes it, this constant is checked against it).
pub const Z95: f64 = 1.959_963_984_540_054;

/// Standard normal quantile at probability `p` ∈ (0, 1).
pub fn normal_quantile(p: f64) -> f64 {
    Normal::standard().inverse_cdf(p)
}

/// Student-t quantile at probability `p` for `dof` degrees of freedom; `+∞` for `dof = 0`
/// (no residual degree of freedom: no finite interval).
pub fn student_t_quantile(p: f64, dof: usize) -> f64 {
    if dof == 0 {
        return f64::INFINITY;
    }
    match StudentsT::new(0.0, 1.0, dof as f64) {
        Ok(t) => t.inverse_cdf(p),
        Err(_) => f64::INFINITY,
    }
}

/// χ²ₖ quantile at upper-tail probability `p_upper` (e.g. 0.001 → the 0.999 quantile).
pub fn chi2_upper_quantile(k: usize, p_upper: f64) -> f64 {
    match ChiSquared::new(k.max(1) as f64) {
        Ok(c) => c.inverse_cdf(1.0 - p_upper),
        Err(_) => f64::INFINITY,
    }
}

/// Ljung–Box Q over `lags` lags.
/// A χ²ₖ statistic as the standard-normal z of its upper tail (Wilson–Hilferty), so statistics
/// with different degrees of freedom rank by how unlikely they are under the null.
pub fn chi2_to_z(stat: f64, k: usize) -> f64 {
    let k = k.max(1) as f64;
    let a = 2.0 / (9.0 * k);
    ((stat.max(0.0) / k).cbrt() - (1.0 - a)) / a.sqrt()
}

pub fn ljung_box(r: &[f64], lags: usize) -> f64 {
    let n = r.len();
    if n < 2 {
        return 0.0;
    }
    let mean = r.iter().sum::<f64>() / n as f64;
    // Centred once (issue 38: it was recomputed twice per lag and sample); the sums run in the
    // same order as before, so the statistic is the same to the bit.
    let d: Vec<f64> = r.iter().map(|x| x - mean).collect();
    let c0: f64 = d.iter().map(|x| x.powi(2)).sum();
    if c0 == 0.0 {
        return 0.0;
    }
    (1..=lags.min(n - 1))
        .map(|k| {
            // Eight running sums ([`dot`]): the statistic
            // moves in its last bits only (issue 38, session 22: a sequential sum per lag was
            // a twentieth of a short pendulum's fit).
            let ck = dot(&d[k..], &d[..n - k]);
            (ck / c0).powi(2) / (n - k) as f64
        })
        .sum::<f64>()
        * (n * (n + 2)) as f64
}

/// The Ljung–Box critical value over [`LB_LAGS`] lags at [`WHITENESS_P`].
pub fn whiteness_critical() -> f64 {
    chi2_upper_quantile(LB_LAGS, WHITENESS_P)
}

/// Σ aₖ·bₖ over two slices (the shorter's length), summed as nalgebra's `dot` sums (eight
/// running sums over blocks of eight, paired 0+4, 1+5, 2+6, 3+7, then the tail in order), so
/// the same number to the bit, but over plain slices: nalgebra's dot on a dynamic view reads
/// each element through the view's strides, three instructions an element that does not vectorise
/// (issue 38, session 22: the Gram matrix and gradient of every LM iteration, the sandwich's sums).
pub fn dot(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len().min(b.len());
    let (a, b) = (&a[..n], &b[..n]);
    let mut acc = [0.0f64; 8];
    let (ca, cb) = (a.chunks_exact(8), b.chunks_exact(8));
    let (ta, tb) = (ca.remainder(), cb.remainder());
    for (x, y) in ca.zip(cb) {
        for l in 0..8 {
            acc[l] += x[l] * y[l];
        }
    }
    let mut res = 0.0;
    res += acc[0] + acc[4];
    res += acc[1] + acc[5];
    res += acc[2] + acc[6];
    res += acc[3] + acc[7];
    for (x, y) in ta.iter().zip(tb) {
        res += x * y;
    }
    res
}

/// Whether a residual is white by Ljung–Box over [`LB_LAGS`] lags at p = [`WHITENESS_P`].
pub fn is_white(r: &[f64]) -> bool {
    ljung_box(r, LB_LAGS) <= whiteness_critical()
}

/// Pearson correlation of two equally long signals (0 when either is constant).
pub fn corr(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len() as f64;
    let (ma, mb) = (a.iter().sum::<f64>() / n, b.iter().sum::<f64>() / n);
    let (mut sab, mut saa, mut sbb) = (0.0, 0.0, 0.0);
    for (x, y) in a.iter().zip(b) {
        sab += (x - ma) * (y - mb);
        saa += (x - ma).powi(2);
        sbb += (y - mb).powi(2);
    }
    if saa > 0.0 && sbb > 0.0 {
        sab / (saa * sbb).sqrt()
    } else {
        0.0
    }
}

/// Sensor noise of a residual from its first differences, √(mean(Δr²)/2): white noise passes
/// through, a slow misfit hardly contributes.
pub fn noise_sigma(r: &[f64]) -> f64 {
    let d2: f64 =
        r.windows(2).map(|w| (w[1] - w[0]).powi(2)).sum::<f64>() / (r.len().max(2) - 1) as f64;
    (d2 / 2.0).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::numerics::noise::Noise;

    /// Golden values from SciPy 1.17 (`scipy.stats.t.ppf`, `chi2.ppf`, `norm.ppf`).
    #[test]
    fn quantiles_match_scipy() {
        let close = |a: f64, b: f64, tol: f64| (a - b).abs() < tol;
        assert!(
            close(normal_quantile(0.975), Z95, 1e-9),
            "{}",
            normal_quantile(0.975)
        );
        for (dof, want) in [
            (1, 12.706_204_736),
            (2, 4.302_652_730),
            (5, 2.570_581_836),
            (30, 2.042_272_456),
            (120, 1.979_930_405),
        ] {
            let got = student_t_quantile(0.975, dof);
            assert!(close(got, want, 1e-6), "t({dof}) {got} vs {want}");
        }
        assert_eq!(student_t_quantile(0.975, 0), f64::INFINITY);
        // χ²₂₀ 0.999 quantile 45.314 746 (the Wilson–Hilferty approximation it replaces gave
        // 45.28, within 0.2).
        assert!(
            close(chi2_upper_quantile(20, 0.001), 45.314_746_6, 1e-4),
            "{}",
            chi2_upper_quantile(20, 0.001)
        );
        assert!(close(chi2_upper_quantile(1, 0.05), 3.841_458_821, 1e-6));
    }

    #[test]
    fn ljung_box_tells_white_from_ar() {
        let mut rng = Noise::new(5);
        let w: Vec<f64> = (0..5000).map(|_| rng.normal()).collect();
        assert!(is_white(&w));
        let mut e = 0.0;
        let ar: Vec<f64> = (0..5000)
            .map(|_| {
                e = 0.3 * e + rng.normal();
                e
            })
            .collect();
        assert!(!is_white(&ar));
        assert!(ljung_box(&ar, LB_LAGS) > whiteness_critical());
    }

    #[test]
    fn noise_sigma_reads_white_noise_and_ignores_a_slow_trend() {
        let mut rng = Noise::new(11);
        let r: Vec<f64> = (0..20_000)
            .map(|k| 0.3 * rng.normal() + (k as f64 * 1e-3).sin())
            .collect();
        let s = noise_sigma(&r);
        assert!((s - 0.3).abs() < 0.01, "{s}");
        assert_eq!(corr(&[1.0, 2.0, 3.0], &[2.0, 4.0, 6.5]).signum(), 1.0);
        assert_eq!(corr(&[1.0, 1.0, 1.0], &[2.0, 4.0, 6.0]), 0.0);
    }
}

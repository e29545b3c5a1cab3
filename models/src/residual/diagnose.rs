//! Diagnosis of a fit's residual: whiteness (Ljung–Box), the sensor noise from first
//! differences, and correlations with the signals an unmodelled effect would follow.

use serde::Serialize;

use crate::identify::{FitOutcome, JointTest};

const LB_LAGS: usize = 20;

/// The residual's diagnosis.
#[derive(Debug, Clone, Serialize)]
pub struct Diagnosis {
    pub ljung_box_q: f64,
    pub ljung_box_lags: usize,
    /// χ² critical value at p = 0.001.
    pub ljung_box_critical: f64,
    pub white: bool,
    /// Sensor noise estimated from first differences of the residual, channel units.
    pub noise_sigma: f64,
    /// Correlation of the residual with candidate signals.
    pub correlations: Vec<(String, f64)>,
}

/// Ljung–Box Q over `lags` lags.
pub fn ljung_box(r: &[f64], lags: usize) -> f64 {
    let n = r.len();
    let mean = r.iter().sum::<f64>() / n as f64;
    let c0: f64 = r.iter().map(|x| (x - mean).powi(2)).sum();
    if c0 == 0.0 {
        return 0.0;
    }
    (1..=lags.min(n - 1))
        .map(|k| {
            let ck: f64 = (k..n).map(|i| (r[i] - mean) * (r[i - k] - mean)).sum();
            (ck / c0).powi(2) / (n - k) as f64
        })
        .sum::<f64>()
        * (n * (n + 2)) as f64
}

/// χ²ₖ critical value at upper-tail p = 0.001 (Wilson–Hilferty).
pub fn chi2_critical_001(k: usize) -> f64 {
    let k = k as f64;
    let z = 3.090_232; // standard normal quantile at 0.999
    k * (1.0 - 2.0 / (9.0 * k) + z * (2.0 / (9.0 * k)).sqrt()).powi(3)
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

/// Whether a residual is white by Ljung–Box over the standard lags at p = 0.001.
pub fn is_white(r: &[f64]) -> bool {
    ljung_box(r, LB_LAGS) <= chi2_critical_001(LB_LAGS)
}

/// Whiteness and correlations of a fit's residual with the candidate signals.
pub fn diagnose(test: &JointTest, fit: &FitOutcome) -> Diagnosis {
    let r = &fit.residual;
    let q = ljung_box(r, LB_LAGS);
    let crit = chi2_critical_001(LB_LAGS);
    let noise_sigma = noise_sigma(r);
    let tr = &fit.trajectory;
    let t = &test.t_s[fit.start..fit.start + fit.n_fit];
    let v = &tr.v;
    let acc: Vec<f64> = (0..v.len())
        .map(|k| {
            if k + 1 < v.len() {
                (v[k + 1] - v[k]) / (t[k + 1] - t[k])
            } else {
                0.0
            }
        })
        .collect();
    let sig = |f: &dyn Fn(usize) -> f64| (0..v.len()).map(f).collect::<Vec<f64>>();
    let signals: Vec<(&str, Vec<f64>)> = vec![
        ("angle_or_position", tr.q.clone()),
        ("rate", v.clone()),
        ("abs_rate", sig(&|k| v[k].abs())),
        ("rate_abs_rate", sig(&|k| v[k] * v[k].abs())),
        ("sign_rate", sig(&|k| v[k].signum())),
        ("acceleration", acc),
        ("time", t.to_vec()),
    ];
    let correlations = signals
        .into_iter()
        .map(|(n, s)| (n.to_string(), corr(r, &s)))
        .collect();
    Diagnosis {
        ljung_box_q: q,
        ljung_box_lags: LB_LAGS,
        ljung_box_critical: crit,
        white: q <= crit,
        noise_sigma,
        correlations,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::noise::Noise;

    #[test]
    fn ljung_box_white_vs_ar() {
        let mut rng = Noise::new(5);
        let w: Vec<f64> = (0..5000).map(|_| rng.normal()).collect();
        assert!(ljung_box(&w, 20) < chi2_critical_001(20));
        let mut e = 0.0;
        let ar: Vec<f64> = (0..5000)
            .map(|_| {
                e = 0.3 * e + rng.normal();
                e
            })
            .collect();
        assert!(ljung_box(&ar, 20) > chi2_critical_001(20));
        // Wilson–Hilferty against the exact χ²₂₀ 0.999 quantile 45.315.
        assert!(
            (chi2_critical_001(20) - 45.315).abs() < 0.2,
            "{}",
            chi2_critical_001(20)
        );
    }
}

//! Diagnosis of a fit's residual: whiteness (Ljung–Box), the sensor noise from first
//! differences, and correlations with the signals an unmodelled effect would follow.

use serde::Serialize;

use crate::joint::identify::{FitOutcome, JointTest};
use crate::numerics::stats::{LB_LAGS, corr, ljung_box, noise_sigma, whiteness_critical};

/// The residual's diagnosis.
#[derive(Debug, Clone, Serialize)]
pub struct Diagnosis {
    pub ljung_box_q: f64,
    pub ljung_box_lags: usize,
    /// χ² critical value at p = 0.001 (`stats::whiteness_critical`).
    pub ljung_box_critical: f64,
    pub white: bool,
    /// Sensor noise estimated from first differences of the residual, channel units.
    pub noise_sigma: f64,
    /// Correlation of the residual with candidate signals.
    pub correlations: Vec<(String, f64)>,
}

/// Whiteness and correlations of a fit's residual with the candidate signals.
pub fn diagnose(test: &JointTest, fit: &FitOutcome) -> Diagnosis {
    let r = &fit.residual;
    let q = ljung_box(r, LB_LAGS);
    let crit = whiteness_critical();
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

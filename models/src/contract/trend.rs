//! Wear trends: a joint parameter's history against time, each point weighted by its interval,
//! a robust straight-line trend with an interval, and a forecast of the date it crosses its
//! alarm band — or "no trend" when the data do not support one.
//!
//! Method (stated choices): weighted least squares with weights 1/σᵢ² (σᵢ from each 95 %
//! interval, half-width/1.96), made robust by Huber iteratively-reweighted LS (k = 1.345 on
//! standardised residuals); the slope's standard error is scaled up by √(χ²/dof) when the points
//! scatter more than their intervals say (never down); a Student-t 95 % interval. A trend exists
//! when the slope's interval excludes 0; then the forecast is the time the fitted line reaches
//! the band edge, with the interval from the slope's interval (the line pivoting on the weighted
//! centroid).

use crate::numerics::stats::Z95;
use serde::Serialize;

/// One identified value of a parameter at a time.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Point {
    /// Days since an epoch (any), so slopes are per day.
    pub t_days: f64,
    pub value: f64,
    pub ci95: [f64; 2],
}

/// The fitted trend.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Trend {
    /// Per day.
    pub slope: f64,
    pub slope_ci95: [f64; 2],
    /// Value of the line at `t_ref_days`.
    pub level: f64,
    pub t_ref_days: f64,
    pub n_points: usize,
    /// Whether the slope's interval excludes zero.
    pub significant: bool,
}

/// When the trend reaches a band edge.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Forecast {
    /// The edge crossed (a value of the parameter).
    pub threshold: f64,
    pub t_days: f64,
    /// Earliest and latest crossing consistent with the slope's interval; `None` for "not
    /// within the horizon the data support" (the slope's interval reaches 0).
    pub t_days_ci95: [Option<f64>; 2],
}

/// Student-t 0.975 quantile for `dof` degrees of freedom (`statrs`; +∞ for none).
fn t975(dof: usize) -> f64 {
    crate::numerics::stats::student_t_quantile(0.975, dof)
}

/// Fit the trend; `None` with fewer than 3 usable points.
pub fn fit(points: &[Point]) -> Option<Trend> {
    let pts: Vec<(f64, f64, f64)> = points
        .iter()
        .filter(|p| p.t_days.is_finite() && p.value.is_finite())
        .map(|p| {
            let sigma = ((p.ci95[1] - p.ci95[0]) / (2.0 * Z95)).abs();
            (
                p.t_days,
                p.value,
                if sigma.is_finite() && sigma > 0.0 {
                    sigma
                } else {
                    f64::NAN
                },
            )
        })
        .collect();
    let n = pts.len();
    if n < 3 {
        return None;
    }
    // Points without a usable interval get the median interval.
    let mut sig: Vec<f64> = pts.iter().map(|p| p.2).filter(|s| s.is_finite()).collect();
    sig.sort_by(f64::total_cmp);
    let med = sig.get(sig.len() / 2).copied().unwrap_or(1.0);
    let sigma: Vec<f64> = pts
        .iter()
        .map(|p| if p.2.is_finite() { p.2 } else { med })
        .collect();
    let mut robust = vec![1.0; n];
    let (mut a, mut b, mut tbar) = (0.0, 0.0, 0.0);
    let mut s_bb = 0.0;
    for _ in 0..20 {
        let w: Vec<f64> = (0..n).map(|i| robust[i] / (sigma[i] * sigma[i])).collect();
        let sw: f64 = w.iter().sum();
        tbar = (0..n).map(|i| w[i] * pts[i].0).sum::<f64>() / sw;
        let ybar = (0..n).map(|i| w[i] * pts[i].1).sum::<f64>() / sw;
        s_bb = (0..n)
            .map(|i| w[i] * (pts[i].0 - tbar).powi(2))
            .sum::<f64>();
        if s_bb <= 0.0 {
            return None;
        }
        let nb = (0..n)
            .map(|i| w[i] * (pts[i].0 - tbar) * (pts[i].1 - ybar))
            .sum::<f64>()
            / s_bb;
        let converged = (nb - b).abs() <= 1e-12 * (nb.abs() + 1e-300)
            && (ybar - a).abs() <= 1e-12 * (ybar.abs() + 1e-300);
        a = ybar;
        b = nb;
        // Huber weights on standardised residuals.
        for i in 0..n {
            let z = ((pts[i].1 - a - b * (pts[i].0 - tbar)) / sigma[i]).abs();
            robust[i] = if z <= 1.345 { 1.0 } else { 1.345 / z };
        }
        if converged {
            break;
        }
    }
    let dof = n - 2;
    let chi2: f64 = (0..n)
        .map(|i| robust[i] * ((pts[i].1 - a - b * (pts[i].0 - tbar)) / sigma[i]).powi(2))
        .sum();
    let scale = (chi2 / dof as f64).max(1.0);
    let se = (scale / s_bb).sqrt();
    let half = t975(dof) * se;
    let ci = [b - half, b + half];
    Some(Trend {
        slope: b,
        slope_ci95: ci,
        level: a,
        t_ref_days: tbar,
        n_points: n,
        significant: ci[0] > 0.0 || ci[1] < 0.0,
    })
}

impl Trend {
    /// The line's value at `t_days`.
    pub fn at(&self, t_days: f64) -> f64 {
        self.level + self.slope * (t_days - self.t_ref_days)
    }

    /// When the trend reaches the band `[lo, hi]` (absolute values, e.g. 0.5× and 2× the Table 4
    /// baseline), if it is heading there: `None` without a significant trend, or when moving away.
    pub fn forecast(&self, lo: f64, hi: f64) -> Option<Forecast> {
        if !self.significant {
            return None;
        }
        let threshold = if self.slope > 0.0 { hi } else { lo };
        let reach = |slope: f64| {
            let t = self.t_ref_days + (threshold - self.level) / slope;
            (slope.signum() == self.slope.signum() && slope != 0.0).then_some(t)
        };
        let t = reach(self.slope)?;
        // Steeper slope → earlier; the slope bound nearer 0 → later (or never).
        let (steep, shallow) = if self.slope > 0.0 {
            (self.slope_ci95[1], self.slope_ci95[0])
        } else {
            (self.slope_ci95[0], self.slope_ci95[1])
        };
        Some(Forecast {
            threshold,
            t_days: t,
            t_days_ci95: [reach(steep), reach(shallow)],
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::numerics::noise::Noise;

    /// Monthly tests over a year, each with σ = 0.004 and an interval that says so.
    fn series(rng: &mut Noise, slope_per_day: f64, start: f64) -> Vec<Point> {
        (0..12)
            .map(|m| {
                let t = 30.4 * m as f64;
                let v = start + slope_per_day * t + 0.004 * rng.normal();
                Point {
                    t_days: t,
                    value: v,
                    ci95: [v - 1.96 * 0.004, v + 1.96 * 0.004],
                }
            })
            .collect()
    }

    #[test]
    fn slope_interval_covers_the_truth_and_the_forecast_covers_the_crossing() {
        let mut rng = Noise::new(42);
        let (mut covered, mut fc_covered, mut fc_total) = (0, 0, 0);
        let truth = 0.0001; // per day: 0.034 → 0.068 (2× J1's viscous baseline) in 340 days
        for _ in 0..400 {
            let tr = fit(&series(&mut rng, truth, 0.034)).unwrap();
            covered += usize::from(tr.slope_ci95[0] <= truth && truth <= tr.slope_ci95[1]);
            if let Some(f) = tr.forecast(0.017, 0.068) {
                fc_total += 1;
                let t_true = (0.068 - 0.034) / truth;
                let [lo, hi] = f.t_days_ci95;
                fc_covered +=
                    usize::from(lo.is_none_or(|l| l <= t_true) && hi.is_none_or(|h| t_true <= h));
            }
        }
        let rate = covered as f64 / 400.0;
        assert!((0.90..=0.98).contains(&rate), "slope coverage {rate}");
        assert!(fc_total > 390, "a clear trend is found: {fc_total}");
        assert!(
            fc_covered as f64 / fc_total as f64 >= 0.9,
            "forecast coverage {fc_covered}/{fc_total}"
        );
    }

    #[test]
    fn a_flat_history_has_no_trend_and_an_outlier_does_not_make_one() {
        let mut rng = Noise::new(7);
        let mut trends = 0;
        for _ in 0..200 {
            let tr = fit(&series(&mut rng, 0.0, 0.034)).unwrap();
            trends += usize::from(tr.significant);
            assert!(tr.forecast(0.017, 0.068).is_none() || tr.significant);
        }
        assert!(trends <= 16, "false trends {trends}/200");
        let mut s = series(&mut Noise::new(3), 0.0, 0.034);
        // One wild test at the end (a bad test day), with an ordinary interval.
        s[11].value = 0.060;
        s[11].ci95 = [0.060 - 1.96 * 0.004, 0.060 + 1.96 * 0.004];
        let tr = fit(&s).unwrap();
        assert!(tr.slope < 0.00003, "robust: slope {}", tr.slope);
        assert!(fit(&s[..2]).is_none());
    }
}

//! Where free motion starts in a recorded trace.
//!
//! A workshop pendulum is often held by hand while the logger already records: the first
//! samples are not free motion. Free motion starts at the release, near a turning point.

use crate::signal::{half_window, local_cubic, local_cubic_at};

/// Index of the first sample of free motion.
///
/// Rule (documented assumption): the release is at the first turning point at or after the
/// first sample. If the smoothed rate at the first sample is below 5 % of the trace's peak rate,
/// the trace starts at release (index 0, the examples' case). Otherwise the first sign change of
/// the smoothed rate is the release (the hand carried the body up to that turning point).
/// Smoothing: local cubic over 20 ms.
pub fn detect_release(t: &[f64], y: &[f64]) -> usize {
    let n = t.len();
    if n < 20 {
        return 0;
    }
    let half = half_window(t, 0.02);
    let stride = (half / 2).max(1);
    let idx: Vec<usize> = (0..n).step_by(stride).collect();
    let rate: Vec<f64> = local_cubic_at(t, y, &idx, half)
        .into_iter()
        .map(|d| d.1)
        .collect();
    let peak = rate.iter().fold(0.0f64, |m, r| m.max(r.abs()));
    if peak == 0.0 || rate[0].abs() < 0.05 * peak {
        return 0;
    }
    let s0 = rate[0].signum();
    let Some(w) = rate.iter().position(|r| r.signum() != s0 && *r != 0.0) else {
        return 0;
    };
    // Refine between the two strided samples: the sample of the extreme value.
    let (a, b) = (idx[w.saturating_sub(1)], idx[w]);
    (a..=b)
        .max_by(|&i, &j| {
            (s0 * local_cubic(t, y, i, half).0).total_cmp(&(s0 * local_cubic(t, y, j, half).0))
        })
        .unwrap_or(b)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn release_from_rest_is_the_first_sample_and_a_carried_start_is_its_turning_point() {
        let t: Vec<f64> = (0..2000).map(|i| i as f64 * 0.001).collect();
        let at_rest: Vec<f64> = t.iter().map(|x| 40.0 * (11.0 * x).cos()).collect();
        assert_eq!(detect_release(&t, &at_rest), 0);
        // Carried: starts mid-swing, turning point at 11 t + 1 = π → t = 0.1947 s.
        let carried: Vec<f64> = t.iter().map(|x| 40.0 * (11.0 * x + 1.0).cos()).collect();
        let i = detect_release(&t, &carried);
        assert!(
            (t[i] - (std::f64::consts::PI - 1.0) / 11.0).abs() < 0.003,
            "release at {}",
            t[i]
        );
    }
}

//! Where free motion starts in a recorded trace.
//!
//! A workshop pendulum is often held by hand while the logger already records: the first
//! samples are not free motion. Free motion starts at the release, at a turning point.

use crate::signal::{half_window, local_cubic_at};

/// Index of the first sample of free motion, for a test whose small-amplitude period is
/// `period_s` (from the rig).
///
/// Rule (documented assumption): released from rest, a body first reverses half a period
/// after the release; carried by a hand and let go at a turning point, the recording shows that
/// turning point well before. So: smooth the trace (local cubic over period/20), find the first
/// reversal of the rate; if it comes within 0.4 of a period of the first sample, the body
/// was carried up to it and that turning point (the extreme sample) is the release; otherwise
/// the trace starts at release (index 0, the examples' case). Reversals in a stretch where the
/// trace does not move beyond its noise do not count.
pub fn detect_release(t: &[f64], y: &[f64], period_s: f64) -> usize {
    let n = t.len();
    if n < 20 || !(period_s.is_finite() && period_s > 0.0) {
        return 0;
    }
    let half = half_window(t, period_s / 20.0);
    let stride = (half / 4).max(1);
    let idx: Vec<usize> = (0..n)
        .take_while(|&i| t[i] - t[0] <= 0.75 * period_s)
        .step_by(stride)
        .collect();
    if idx.len() < 4 {
        return 0;
    }
    let sm = local_cubic_at(t, y, &idx, half);
    let range = sm.iter().map(|s| s.0).fold(f64::NEG_INFINITY, f64::max)
        - sm.iter().map(|s| s.0).fold(f64::INFINITY, f64::min);
    if range <= 0.0 {
        return 0;
    }
    let peak = sm.iter().fold(0.0f64, |m, s| m.max(s.1.abs()));
    // The first sign change of the rate among samples moving faster than 5 % of the peak.
    let moving: Vec<(usize, f64)> = idx
        .iter()
        .zip(&sm)
        .filter(|(_, s)| s.1.abs() > 0.05 * peak)
        .map(|(i, s)| (*i, s.1))
        .collect();
    let Some(w) = moving
        .windows(2)
        .position(|p| p[0].1.signum() != p[1].1.signum())
    else {
        return 0;
    };
    let (a, b) = (moving[w].0, moving[w + 1].0);
    // Too late: a free swing's first reversal. Too early (inside the first smoothing window,
    // where the one-sided fit is noisy): the trace starts at its turning point anyway.
    if t[b] - t[0] > 0.4 * period_s || b < 2 * half {
        return 0;
    }
    // The extreme sample between the two: the turning point.
    let s0 = moving[w].1.signum();
    let lo = a.saturating_sub(half);
    let hi = (b + half).min(n - 1);
    let near: Vec<usize> = (lo..=hi).collect();
    let vals = local_cubic_at(t, y, &near, half);
    near.iter()
        .zip(&vals)
        .max_by(|x, z| (s0 * x.1.0).total_cmp(&(s0 * z.1.0)))
        .map_or(0, |(i, _)| *i)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::noise::Noise;

    #[test]
    fn release_from_rest_is_the_first_sample_and_a_carried_start_is_its_turning_point() {
        let period = 2.0 * std::f64::consts::PI / 11.0;
        let t: Vec<f64> = (0..2000).map(|i| i as f64 * 0.001).collect();
        let mut rng = Noise::new(1);
        // From rest, with noise at the start (the case that fooled a short window).
        let at_rest: Vec<f64> = t
            .iter()
            .map(|x| 40.0 * (11.0 * x).cos() + 0.05 * rng.normal())
            .collect();
        assert_eq!(detect_release(&t, &at_rest, period), 0);
        // Carried: starts mid-swing, turning point at 11 t + 1 = π → t = 0.1947 s.
        let carried: Vec<f64> = t
            .iter()
            .map(|x| 40.0 * (11.0 * x + 1.0).cos() + 0.05 * rng.normal())
            .collect();
        let i = detect_release(&t, &carried, period);
        assert!(
            (t[i] - (std::f64::consts::PI - 1.0) / 11.0).abs() < 0.005,
            "release at {}",
            t[i]
        );
    }
}

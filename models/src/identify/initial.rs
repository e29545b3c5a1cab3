//! A fast first estimate by inverse dynamics: smooth the measured motion, differentiate it,
//! and solve the equation of motion — linear in D, μ and a small sensor zero — by least squares.

use nalgebra::{DMatrix, DVector};

use crate::dynamics::Dof;
use crate::signal::{half_window, local_cubic, local_cubic_at};

/// Starting values for the output-error fit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct InitialEstimate {
    pub viscous: f64,
    pub dry: f64,
    /// Sensor zero, channel units.
    pub offset: f64,
    /// Release position and rate, model units (rad or m; rad/s or m/s).
    pub q0: f64,
    pub v0: f64,
}

/// Inverse-dynamics estimate over samples `t[start..]`, `y` in channel units (`scale` channel
/// units per model unit).
///
/// Each used sample gives one equation
/// `M·a − G(q_m, t) = −D·v − lever·N·μ·sign(v) − ∂G/∂q·o`, with q_m = y/scale the measured
/// position, o the sensor zero (linearised: G(q_m − o) ≈ G(q_m) − G_q·o), v and a from a local
/// cubic over ~1/12 of the period. Samples slower than 10 % of the peak rate are skipped (the
/// sign of the friction is uncertain there). `v0` is the given initial rate (default: released
/// from rest).
pub fn inverse_dynamics(
    dof: &Dof,
    t: &[f64],
    y: &[f64],
    scale: f64,
    start: usize,
    v0: Option<f64>,
    fit_offset: bool,
) -> InitialEstimate {
    let (t, y) = (&t[start..], &y[start..]);
    let n = t.len();
    let duration = t[n - 1] - t[0];
    let half = half_window(t, (dof.period_s(duration) / 12.0).clamp(0.01, 0.2));
    let stride = (n / 800).max(1);
    let mut rows: Vec<([f64; 3], f64)> = Vec::with_capacity(n / stride + 1);
    let mut vmax: f64 = 0.0;
    let idx: Vec<usize> = (half..n.saturating_sub(half)).step_by(stride).collect();
    let pts: Vec<(f64, f64, f64, f64)> = local_cubic_at(t, y, &idx, half)
        .into_iter()
        .zip(&idx)
        .map(|((q, v, a), &i)| {
            vmax = vmax.max((v / scale).abs());
            (t[i], q / scale, v / scale, a / scale)
        })
        .collect();
    for &(ti, q, v, a) in &pts {
        if v.abs() < 0.1 * vmax {
            continue;
        }
        let s = v.signum();
        let (g, g_q, _) = dof.load(q, ti);
        let (nrm, ..) = dof.normal(q, v, a);
        rows.push((
            [
                -v,
                -dof.lever() * nrm * s,
                if fit_offset { -g_q / scale } else { 0.0 },
            ],
            dof.inertia() * a - g,
        ));
    }
    let (q_start, _, _) = local_cubic(t, y, 0, half);
    let mut est = InitialEstimate {
        viscous: 0.0,
        dry: 0.0,
        offset: 0.0,
        q0: q_start / scale,
        v0: v0.unwrap_or(0.0),
    };
    if rows.len() < 5 {
        return est;
    }
    let a = DMatrix::from_fn(rows.len(), 3, |r, c| rows[r].0[c]);
    let b = DVector::from_fn(rows.len(), |r, _| rows[r].1);
    // Column scaling, then SVD least squares (the offset column is zero without a restoring force).
    let norms: Vec<f64> = (0..3).map(|c| a.column(c).norm().max(1e-300)).collect();
    let an = DMatrix::from_fn(rows.len(), 3, |r, c| a[(r, c)] / norms[c]);
    if let Ok(x) = an.svd(true, true).solve(&b, 1e-10) {
        est.viscous = (x[0] / norms[0]).max(0.0);
        est.dry = (x[1] / norms[1]).max(0.0);
        est.offset = if fit_offset { x[2] / norms[2] } else { 0.0 };
        if !est.offset.is_finite() {
            est.offset = 0.0;
        }
    }
    est.q0 = q_start / scale - est.offset / scale;
    est
}

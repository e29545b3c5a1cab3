//! A fast first estimate by inverse dynamics: smooth the measured motion, differentiate it,
//! and solve the equation of motion — linear in D, μ and a small sensor zero — by least squares.

use nalgebra::{DMatrix, DVector};

use crate::joint::dynamics::{Dof, Mechanism};
use crate::joint::friction::{POSITION_KNOTS, PositionFriction};
use crate::numerics::signal::{half_window, local_cubic, local_cubic_at, local_cubic_rate_at};

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
    // About 800 points over the record; then, when the motion ended in the record's first half
    // (a free decay held by dry friction, then a long rest: a 30 s slider record moves for 3 s),
    // about 800 points over the motion alone (issue 38: with the stride of the whole record
    // a 30 s slider's estimate rested on ~60 points of motion, and its fit went to the wrong
    // stick–slip piece, beyond what the restarts reach). A record in motion past its middle keeps
    // the first points, so its estimate is unchanged (every pendulum example: J6's, moving for
    // 18 of its 20 s, taken over its motion alone, sent its first fit to the wrong piece).
    let stride = (n / 800).max(1);
    let end = n.saturating_sub(half);
    let (mut pts, mut vmax) = points(t, y, scale, half, end, stride);
    let moving_until = moving_until(pts.iter().map(|p| p.2), vmax, half, stride, end);
    let motion_stride = (moving_until.saturating_sub(half) / 800).max(1);
    if 2 * moving_until <= n && motion_stride < stride {
        (pts, vmax) = points(t, y, scale, half, moving_until, motion_stride);
    }
    let mut rows: Vec<([f64; 3], f64)> = Vec::with_capacity(pts.len());
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

/// Local-cubic (t, q, v, a) in model units at samples `half, half + stride, …` below `end`, and
/// the largest |v| among them.
fn points(
    t: &[f64],
    y: &[f64],
    scale: f64,
    half: usize,
    end: usize,
    stride: usize,
) -> (Vec<(f64, f64, f64, f64)>, f64) {
    let idx: Vec<usize> = (half..end).step_by(stride).collect();
    let mut vmax: f64 = 0.0;
    let pts = local_cubic_at(t, y, &idx, half)
        .into_iter()
        .zip(&idx)
        .map(|((q, v, a), &i)| {
            vmax = vmax.max((v / scale).abs());
            (t[i], q / scale, v / scale, a / scale)
        })
        .collect();
    (pts, vmax)
}

/// The sample (exclusive) up to which the motion lasts: one half-window past the last of the
/// `rates` (taken every `stride` samples from `half`) at ≥ 10 % of the peak rate `vmax`; `end`
/// when none.
fn moving_until(
    rates: impl DoubleEndedIterator<Item = f64> + ExactSizeIterator,
    vmax: f64,
    half: usize,
    stride: usize,
    end: usize,
) -> usize {
    let mut rates = rates;
    rates
        .rposition(|v| v.abs() >= 0.1 * vmax)
        .map_or(end, |k| (half + (k + 1) * stride + half).min(end))
}

/// Energy-balance start for a slider's free decay (a spring, no measured input; issue 38): over
/// the motion, with E = ½·m·v² + ½·k·(q − o)² and q the measured position,
/// `E(t) = E(t₀) − μ·N·∫|v| dt − D·∫v² dt`, which is linear in E(t₀) − ½·k·o², o, μ and D once
/// ½·k·(q − o)² is expanded; least squares over ~1600 local-cubic points of the motion, the
/// integrals by the trapezoid rule. Only rates enter (no accelerations), and the integrals average
/// the noise: the inverse-dynamics estimate of a J8 slider ran 15–30 % high in viscous (its
/// accelerations, smoothed across each reversal's friction step, carry a force error of the
/// viscous force's size) and sent the first fit to the neighbouring stick–slip piece. Assumes the
/// slider's constant normal force (`Dof::normal` at rest) and the model's viscous + Coulomb law.
/// None when the trace is not of this kind, or too short, or the solve fails.
pub fn energy_balance(
    dof: &Dof,
    t: &[f64],
    y: &[f64],
    scale: f64,
    start: usize,
    v0: Option<f64>,
) -> Option<InitialEstimate> {
    if !matches!(dof.mech, Mechanism::Slider(_)) || dof.input.is_some() {
        return None;
    }
    let (t, y) = (t.get(start..)?, y.get(start..)?);
    let n = t.len();
    let stiffness = -dof.load(0.0, 0.0).1;
    if n < 40 || stiffness.is_nan() || stiffness <= 0.0 {
        return None;
    }
    let duration = t[n - 1] - t[0];
    let half = half_window(t, (dof.period_s(duration) / 12.0).clamp(0.01, 0.2));
    let stride = (n / 800).max(1);
    let end = n.saturating_sub(half);
    // Where the motion lasts needs the rates alone (a third of the local cubics' work, the
    // same numbers: issue 38, session 22).
    let idx: Vec<usize> = (half..end).step_by(stride).collect();
    let rates: Vec<f64> = local_cubic_rate_at(t, y, &idx, half)
        .into_iter()
        .map(|v| v / scale)
        .collect();
    let vmax = rates.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let until = moving_until(rates.iter().copied(), vmax, half, stride, end);
    let (pts, _) = points(
        t,
        y,
        scale,
        half,
        until,
        (until.saturating_sub(half) / 1600).max(1),
    );
    if pts.len() < 20 || vmax.is_nan() || vmax <= 0.0 {
        return None;
    }
    let (mass, normal) = (dof.inertia(), dof.lever() * dof.normal_at_rest(0.0));
    // Rows (1, k·q, −N·∫|v|, −∫v²) · (E₀ − ½·k·o², o, μ, D) = ½·m·v² + ½·k·q².
    let (mut int_abs, mut int_sq) = (0.0, 0.0);
    let mut a = DMatrix::zeros(pts.len(), 4);
    let mut b = DVector::zeros(pts.len());
    for (r, p) in pts.iter().enumerate() {
        if r > 0 {
            let w = &pts[r - 1];
            let dt = p.0 - w.0;
            int_abs += 0.5 * dt * (p.2.abs() + w.2.abs());
            int_sq += 0.5 * dt * (p.2 * p.2 + w.2 * w.2);
        }
        a[(r, 0)] = 1.0;
        a[(r, 1)] = stiffness * p.1;
        a[(r, 2)] = -normal * int_abs;
        a[(r, 3)] = -int_sq;
        b[r] = 0.5 * mass * p.2 * p.2 + 0.5 * stiffness * p.1 * p.1;
    }
    let norms: Vec<f64> = (0..4).map(|c| a.column(c).norm().max(1e-300)).collect();
    for (c, nc) in norms.iter().enumerate() {
        a.column_mut(c).scale_mut(1.0 / nc);
    }
    let x = a.svd(true, true).solve(&b, 1e-10).ok()?;
    let (o, dry, viscous) = (x[1] / norms[1], x[2] / norms[2], x[3] / norms[3]);
    if !(o.is_finite() && dry.is_finite() && viscous.is_finite()) {
        return None;
    }
    let (q_start, _, _) = local_cubic(t, y, 0, half);
    Some(InitialEstimate {
        viscous: viscous.max(0.0),
        dry: dry.max(0.0),
        offset: o * scale,
        q0: q_start / scale - o,
        v0: v0.unwrap_or(0.0),
    })
}

/// The first estimate of a fit: [`energy_balance`] for a slider's free decay, where it applies;
/// else [`inverse_dynamics`].
pub fn first_estimate(
    dof: &Dof,
    t: &[f64],
    y: &[f64],
    scale: f64,
    start: usize,
    v0: Option<f64>,
    fit_offset: bool,
) -> InitialEstimate {
    energy_balance(dof, t, y, scale, start, v0)
        .filter(|_| fit_offset)
        .unwrap_or_else(|| inverse_dynamics(dof, t, y, scale, start, v0, fit_offset))
}

/// Starting values for a fit with position friction ([`PositionFriction`]): the same inverse
/// dynamics with μ free at every knot, `M·a − G = −D·v − lever·N·sign(v)·Σ_k μ_k·w_k(q)` (w_k the
/// grid's hat weights), solved by least squares over samples `start .. start + n`; then
/// μ = μ_anchor and c_k = μ_k/μ − 1. The output-error fit from the plain model's solution can
/// stop in a poorer basin when the shape is large (measured: friction ×5 at 60° on J3 ended at
/// RMSE 0.073° where the noise is 0.05°). `offset` (channel units) is the plain fit's sensor zero.
/// Knots the motion hardly visits keep c = 0. None when the anchor's μ is not positive.
#[allow(clippy::too_many_arguments)]
pub fn position_friction_start(
    dof: &Dof,
    t: &[f64],
    y: &[f64],
    scale: f64,
    start: usize,
    n: usize,
    offset: f64,
    grid: &PositionFriction,
) -> Option<(f64, f64, [f64; POSITION_KNOTS])> {
    let end = (start + n).min(t.len());
    let (t, y) = (&t[start..end], &y[start..end]);
    let n = t.len();
    if n < 20 {
        return None;
    }
    let duration = t[n - 1] - t[0];
    let half = half_window(t, (dof.period_s(duration) / 12.0).clamp(0.01, 0.2));
    let stride = (n / 1600).max(1);
    let idx: Vec<usize> = (half..n.saturating_sub(half)).step_by(stride).collect();
    let yc: Vec<f64> = y.iter().map(|v| v - offset).collect();
    let pts: Vec<(f64, f64, f64, f64)> = local_cubic_at(t, &yc, &idx, half)
        .into_iter()
        .zip(&idx)
        .map(|((q, v, a), &i)| (t[i], q / scale, v / scale, a / scale))
        .collect();
    let vmax = pts.iter().fold(0.0f64, |m, p| m.max(p.2.abs()));
    let cols = 1 + POSITION_KNOTS;
    let mut rows: Vec<(Vec<f64>, f64)> = Vec::with_capacity(pts.len());
    for &(ti, q, v, a) in &pts {
        if v.abs() < 0.1 * vmax {
            continue;
        }
        let (g, _, _) = dof.load(q, ti);
        let (nrm, ..) = dof.normal(q, v, a);
        let mut row = vec![0.0; cols];
        row[0] = -v;
        for (k, w) in grid.hat_weights(q) {
            row[1 + k] = -dof.lever() * nrm * v.signum() * w;
        }
        rows.push((row, dof.inertia() * a - g));
    }
    if rows.len() < 5 * cols {
        return None;
    }
    let a = DMatrix::from_fn(rows.len(), cols, |r, c| rows[r].0[c]);
    let b = DVector::from_fn(rows.len(), |r, _| rows[r].1);
    let norms: Vec<f64> = (0..cols).map(|c| a.column(c).norm()).collect();
    let top = norms.iter().cloned().fold(0.0, f64::max);
    // A knot the motion hardly visits has no column to speak of: it keeps c = 0.
    let used: Vec<usize> = (0..cols).filter(|&c| norms[c] > 1e-3 * top).collect();
    let an = DMatrix::from_fn(rows.len(), used.len(), |r, j| {
        a[(r, used[j])] / norms[used[j]]
    });
    let x = an.svd(true, true).solve(&b, 1e-10).ok()?;
    let mut full = vec![f64::NAN; cols];
    for (j, &c) in used.iter().enumerate() {
        full[c] = x[j] / norms[c];
    }
    let mu = full[1 + grid.anchor()];
    if !(mu.is_finite() && mu > 0.0) {
        return None;
    }
    let mut coeffs = [0.0; POSITION_KNOTS];
    for (k, c) in coeffs.iter_mut().enumerate() {
        let m = full[1 + k];
        *c = if m.is_finite() {
            (m / mu - 1.0).max(-1.0)
        } else {
            0.0
        };
    }
    coeffs[grid.anchor()] = 0.0;
    Some((full[0].max(0.0), mu, coeffs))
}

//! A release that is not free (issue 36, point 4): the first half-swing after the found release
//! loses more energy, or lasts longer, than the later half-swings say a free one would.
//!
//! A workshop pendulum let go by hand is often held back for a moment after it starts to move
//! (a hand that opens slowly, a rod that rubs the hand, a catch). The swing out of such a start
//! is not the model's free motion: fitted with it, the friction absorbs the hand. The rule reads
//! the record's own half-swings, before any fit, so a fit cannot hide it:
//!
//! - **energy**: half-swing k, from turning point A_k to A_{k+1} (amplitudes about the rest
//!   position, model units), loses `W_k = (P(A_k) − P(A_{k+1})) / (A_k + A_{k+1})` per unit of
//!   path — the mean friction torque over the half-swing in units of the restoring stiffness
//!   (P = 1 − cos A for gravity, A²/2 for a spring). Friction's loss per unit path grows with the
//!   swing's energy (the pin's reaction grows with ω², the viscous torque with ω), so the later
//!   half-swings' `W` against their mean energy `E`, fitted as a line, bounds what a free first
//!   half-swing loses from below. Assumption (documented): a free first half-swing loses at most
//!   [`ENERGY_RATIO`] times that line's value at its energy, and at least the larger of the line
//!   and the later swings' median.
//! - **time**: a free half-swing from A_a to A_b lasts `(T(A_a) + T(A_b))/4`, with `T(A)` the
//!   ideal pendulum's period at amplitude A (`T₀·2K(sin(A/2))/π`, K the complete elliptic
//!   integral), a spring's T₀ at every amplitude. Each half-swing's duration divided by that shape
//!   is its `T₀/2`; a free first half-swing reads the later ones' median within
//!   [`PERIOD_RATIO`] (friction changes a half-swing's duration by well under 1 %).
//!
//! A first half-swing past either bound, by more than [`MIN_Z`] of the later half-swings'
//! scatter, or past both of two tighter bounds ([`ENERGY_RATIO_BOTH`], [`PERIOD_RATIO_BOTH`]),
//! is disturbed: the free motion starts at its end, a turning point, and the check is
//! repeated from there (at most [`MAX_SKIPPED`] half-swings are left out).

use crate::numerics::signal::{half_window, local_cubic_rate_at};

/// What restores the body toward rest: the shape of its potential energy in the amplitude.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Restoring {
    /// A pendulum: P(A) ∝ 1 − cos A, the period grows with amplitude.
    Gravity,
    /// A linear spring: P(A) ∝ A²/2, the period does not depend on amplitude.
    Spring,
}

/// A free first half-swing loses at most this multiple of the later half-swings' loss per unit
/// path at its energy (assumption; on simulated free releases of the seven Table 2 pendulums from
/// 20° to 135°, Table 4 friction at 0.3–3×, the stand's noise, the ratio stayed below 1.3 —
/// `tests::free_releases_are_not_flagged`).
pub const ENERGY_RATIO: f64 = 1.8;

/// A free first half-swing's duration, divided by the amplitude shape, is within this ratio of
/// the later half-swings' median (assumption; free releases read at most 1.009 in the same
/// tests, twice the stand's noise included).
pub const PERIOD_RATIO: f64 = 1.03;

/// The excess must also be this many standard deviations of the later half-swings' scatter
/// (with floors: 5 % of the loss, 0.5 % of the duration), so a noisy record is not cut.
pub const MIN_Z: f64 = 5.0;

/// A half-swing that both loses and lasts more than a free one, each by these ratios and by
/// [`MIN_Z_BOTH`] standard deviations, is disturbed too: a hold drains energy and delays the
/// swing together, while the out-of-vocabulary effects and the noise seen on free releases move
/// one or neither (free releases: energy ≤ 1.2 with period ≤ 1.01).
pub const ENERGY_RATIO_BOTH: f64 = 1.15;
pub const PERIOD_RATIO_BOTH: f64 = 1.03;
pub const MIN_Z_BOTH: f64 = 3.0;

/// At most this many half-swings are left out; a record still disturbed after them is fitted
/// from there with a warning (the check needs later swings to compare with).
pub const MAX_SKIPPED: usize = 2;

/// Half-swings after the one checked that the trend needs.
const MIN_LATER: usize = 4;

/// Half-swings after the one checked that the trend uses (the first few periods: the amplitude
/// nearest the checked swing's, where the extrapolation is shortest).
const MAX_LATER: usize = 8;

/// The first half-swing checked, and what it showed.
#[derive(Debug, Clone, PartialEq)]
pub struct SwingCheck {
    /// Start (the release) and end (the next turning point) of the half-swing, s.
    pub from_t_s: f64,
    pub to_t_s: f64,
    /// The turning point's sample: where a fit starts if the half-swing is disturbed.
    pub to_index: usize,
    /// Loss per unit path against the later half-swings' trend at its energy.
    pub energy_ratio: f64,
    /// Its excess in standard deviations of the trend's scatter.
    pub energy_z: f64,
    /// Its duration's `T₀/2` against the later half-swings' median.
    pub period_ratio: f64,
    /// Its excess in standard deviations of the later half-swings' scatter.
    pub period_z: f64,
    /// The amplitudes it swung between, model units (rad or m), about the rest position.
    pub amplitudes: [f64; 2],
}

impl SwingCheck {
    /// Whether the half-swing is not a free one (either test past its bound, significantly).
    pub fn disturbed(&self) -> bool {
        let energy = |r: f64, z: f64| self.energy_ratio > r && self.energy_z > z;
        let period = |r: f64, z: f64| self.period_ratio > r && self.period_z > z;
        energy(ENERGY_RATIO, MIN_Z)
            || period(PERIOD_RATIO, MIN_Z)
            || (energy(ENERGY_RATIO_BOTH, MIN_Z_BOTH) && period(PERIOD_RATIO_BOTH, MIN_Z_BOTH))
    }

    /// One sentence: what the half-swing did against what a free one does.
    pub fn describe(&self) -> String {
        format!(
            "the half-swing from {:.3} s to {:.3} s lost {:.2}x the energy per unit path and \
             lasted {:.2}x the time that the later half-swings say a free one would (bounds \
             {ENERGY_RATIO:.2}x and {PERIOD_RATIO:.2}x)",
            self.from_t_s, self.to_t_s, self.energy_ratio, self.period_ratio
        )
    }
}

/// A release found not to be free, and where the free motion starts.
#[derive(Debug, Clone, PartialEq)]
pub struct Disturbance {
    /// The release the rule first found, s: the left-out part runs from here.
    pub from_t_s: f64,
    /// Where the fit starts (a turning point), s, and its sample.
    pub until_t_s: f64,
    pub until_index: usize,
    /// The half-swings left out, each with its check.
    pub left_out: Vec<SwingCheck>,
    /// Set when the record is still disturbed after [`MAX_SKIPPED`] half-swings, or the check
    /// of the new start could not be made.
    pub warning: Option<String>,
}

impl Disturbance {
    /// Why the part was left out, for reports.
    pub fn reason(&self) -> String {
        let first = &self.left_out[0];
        format!(
            "release not free: {}; the fit starts at the turning point at {:.3} s ({} half-swing{} \
             left out)",
            first.describe(),
            self.until_t_s,
            self.left_out.len(),
            if self.left_out.len() == 1 { "" } else { "s" }
        )
    }
}

/// The complete elliptic integral of the first kind K(k), by the arithmetic–geometric mean.
fn ellipk(k: f64) -> f64 {
    let (mut a, mut b) = (1.0f64, (1.0 - k * k).max(0.0).sqrt());
    for _ in 0..40 {
        if (a - b).abs() <= 1e-15 * a {
            break;
        }
        let (an, bn) = ((a + b) / 2.0, (a * b).sqrt());
        a = an;
        b = bn;
    }
    std::f64::consts::PI / (2.0 * a)
}

impl Restoring {
    /// Potential energy at amplitude `a` (model units), in units of the restoring stiffness.
    fn potential(self, a: f64) -> f64 {
        match self {
            Restoring::Gravity => 1.0 - a.cos(),
            Restoring::Spring => 0.5 * a * a,
        }
    }

    /// The period at amplitude `a` over the small-amplitude period (1 for a spring). Amplitudes
    /// at or past the upright (π) have no period: capped just below.
    fn period_factor(self, a: f64) -> f64 {
        match self {
            Restoring::Gravity => {
                let k = (a.abs().min(3.1) / 2.0).sin();
                2.0 * ellipk(k) / std::f64::consts::PI
            }
            Restoring::Spring => 1.0,
        }
    }
}

/// A turning point: time (vertex of the local parabola), smoothed value and its standard error
/// (channel units), nearest sample.
#[derive(Debug, Clone, Copy)]
struct Turn {
    t_s: f64,
    y: f64,
    sd: f64,
    index: usize,
}

/// The turning points of the motion from `start` (a release: at rest there) over at most
/// `MAX_LATER + MAX_SKIPPED + 2` half-swings, the release itself first. Smoothing as the release
/// rule's (local cubic over period/20); a reversal counts between points moving beyond 10 % of
/// the stretch's peak rate.
fn turning_points(t: &[f64], y: &[f64], start: usize, period_s: f64) -> Vec<Turn> {
    let n = t.len();
    if start + 20 >= n {
        return Vec::new();
    }
    let half = half_window(&t[start..], period_s / 20.0).max(2);
    let stride = (half / 4).max(1);
    let want = MAX_LATER + MAX_SKIPPED + 3;
    let horizon_s = t[start] + (want as f64 + 1.0) * period_s / 2.0 * 1.6;
    let idx: Vec<usize> = (start..n)
        .take_while(|&i| t[i] <= horizon_s)
        .step_by(stride)
        .collect();
    if idx.len() < 8 {
        return Vec::new();
    }
    // The rates alone (issue 38, session 22: the same numbers, a third of the work).
    let sm = local_cubic_rate_at(t, y, &idx, half);
    let peak = sm.iter().fold(0.0f64, |m, s| m.max(s.abs()));
    if !(peak > 0.0 && peak.is_finite()) {
        return Vec::new();
    }
    let moving = |k: usize| sm[k].abs() > 0.1 * peak;
    let mut turns = vec![at_rest(t, y, start, period_s / 20.0)];
    let Some(first) = (0..idx.len()).find(|&k| moving(k)) else {
        return turns;
    };
    let mut last = first;
    for k in first + 1..idx.len() {
        if !moving(k) {
            continue;
        }
        if sm[k].signum() != sm[last].signum() {
            let s0 = sm[last].signum();
            let ext = (idx[last]..=idx[k])
                .max_by(|&i, &j| (s0 * y[i]).total_cmp(&(s0 * y[j])))
                .unwrap_or(idx[last]);
            let turn = vertex(t, y, ext, period_s / 20.0);
            // A reversal within a fifth of a period of the last turn is the noise of a start
            // at rest (a one-sided smoothing window), not a half-swing.
            let prev = turns[turns.len() - 1].t_s;
            if turn.t_s - prev >= 0.2 * period_s {
                turns.push(turn);
            }
            if turns.len() >= want {
                break;
            }
        }
        last = k;
    }
    turns
}

impl Turn {
    /// Sample `i` as it was read, of unknown error: where a local fit cannot be made.
    fn raw(t: &[f64], y: &[f64], i: usize) -> Turn {
        Turn {
            t_s: t[i],
            y: y[i],
            sd: f64::INFINITY,
            index: i,
        }
    }
}

/// The release at sample `i`, where the motion leaves rest: `y = c + a·(t − tᵢ)²` (no linear
/// term: at rest) fitted over the `w_s` after it (within period/20 of a release the free motion
/// differs from its parabola by under 0.05 % of the amplitude); its value is c.
fn at_rest(t: &[f64], y: &[f64], i: usize, w_s: f64) -> Turn {
    let hi = t.partition_point(|&x| x <= t[i] + w_s).min(t.len());
    let fallback = Turn::raw(t, y, i);
    if hi < i + 4 {
        return fallback;
    }
    let (mut s0, mut s2, mut s4, mut r0, mut r2) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for k in i..hi {
        let u2 = (t[k] - t[i]).powi(2);
        s0 += 1.0;
        s2 += u2;
        s4 += u2 * u2;
        r0 += y[k];
        r2 += u2 * y[k];
    }
    let det = s0 * s4 - s2 * s2;
    if det.abs() < f64::MIN_POSITIVE {
        return fallback;
    }
    let c = (s4 * r0 - s2 * r2) / det;
    let a = (s0 * r2 - s2 * r0) / det;
    let ssr: f64 = (i..hi)
        .map(|k| (y[k] - c - a * (t[k] - t[i]).powi(2)).powi(2))
        .sum();
    let sigma = (ssr / (s0 - 2.0).max(1.0)).sqrt();
    Turn {
        t_s: t[i],
        y: c,
        sd: sigma * (s4 / det).sqrt(),
        index: i,
    }
}

/// The vertex of a parabola fitted to the samples within ±`w_s` of sample `i`.
fn vertex(t: &[f64], y: &[f64], i: usize, w_s: f64) -> Turn {
    let lo = t.partition_point(|&x| x < t[i] - w_s);
    let hi = t.partition_point(|&x| x <= t[i] + w_s).min(t.len());
    let fallback = Turn::raw(t, y, i);
    if hi < lo + 5 {
        return fallback;
    }
    // Least squares y = c0 + c1·u + c2·u², u = t − t_i.
    let mut s = [0.0f64; 5];
    let mut r = [0.0f64; 3];
    for k in lo..hi {
        let u = t[k] - t[i];
        let mut p = 1.0;
        for sk in s.iter_mut() {
            *sk += p;
            p *= u;
        }
        r[0] += y[k];
        r[1] += u * y[k];
        r[2] += u * u * y[k];
    }
    let m = nalgebra::Matrix3::new(s[0], s[1], s[2], s[1], s[2], s[3], s[2], s[3], s[4]);
    let Some(c) = m.lu().solve(&nalgebra::Vector3::new(r[0], r[1], r[2])) else {
        return fallback;
    };
    if c[2].abs() < f64::MIN_POSITIVE {
        return fallback;
    }
    let u = -c[1] / (2.0 * c[2]);
    if u.abs() > w_s {
        return fallback;
    }
    let t_v = t[i] + u;
    let index = t.partition_point(|&x| x < t_v).min(t.len() - 1);
    let ssr: f64 = (lo..hi)
        .map(|k| {
            let v = t[k] - t[i];
            (y[k] - c[0] - c[1] * v - c[2] * v * v).powi(2)
        })
        .sum();
    let sigma = (ssr / ((hi - lo) as f64 - 3.0).max(1.0)).sqrt();
    // The value's standard error, at u = 0 (the vertex lies within w_s of it).
    let sd = m
        .try_inverse()
        .map_or(f64::INFINITY, |inv| sigma * inv[(0, 0)].max(0.0).sqrt());
    Turn {
        t_s: t_v,
        y: c[0] + c[1] * u + c[2] * u * u,
        sd,
        index,
    }
}

/// Median of a non-empty slice.
fn median(v: &[f64]) -> f64 {
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    let m = s.len() / 2;
    if s.len() % 2 == 1 {
        s[m]
    } else {
        0.5 * (s[m - 1] + s[m])
    }
}

/// Check the first half-swing of the motion released at `start` against the later ones. `y` in
/// channel units, `scale` channel units per model unit, `period_s` the small-amplitude period.
/// `None` when the record has too few half-swings to judge (fewer than five after the release).
pub fn check_first_swing(
    t: &[f64],
    y: &[f64],
    scale: f64,
    start: usize,
    period_s: f64,
    restoring: Restoring,
) -> Option<SwingCheck> {
    if !(scale.is_finite() && scale > 0.0 && period_s.is_finite() && period_s > 0.0) {
        return None;
    }
    let turns = turning_points(t, y, start, period_s);
    if turns.len() < MIN_LATER + 2 {
        return None;
    }
    let last = turns.len().min(MAX_LATER + 2);
    let turns = &turns[..last];
    // The rest position: consecutive midpoints averaged in pairs cancel dry friction's
    // alternating shift of each half-swing's centre (turning points after the first).
    let centres: Vec<f64> = turns[1..]
        .windows(3)
        .map(|w| (w[0].y + 2.0 * w[1].y + w[2].y) / 4.0)
        .collect();
    if centres.is_empty() {
        return None;
    }
    let c = median(&centres);
    let amp: Vec<f64> = turns.iter().map(|p| (p.y - c).abs() / scale).collect();
    // Turning points must alternate about the rest position and shrink (a free decay).
    let alternates = turns
        .windows(2)
        .all(|w| (w[0].y - c).signum() != (w[1].y - c).signum());
    if !alternates || amp.iter().any(|a| !a.is_finite() || *a <= 0.0) {
        return None;
    }
    let swings = turns.len() - 1;
    let loss: Vec<f64> = (0..swings)
        .map(|k| {
            (restoring.potential(amp[k]) - restoring.potential(amp[k + 1])) / (amp[k] + amp[k + 1])
        })
        .collect();
    let energy: Vec<f64> = (0..swings)
        .map(|k| 0.5 * (restoring.potential(amp[k]) + restoring.potential(amp[k + 1])))
        .collect();
    let half_t0: Vec<f64> = (0..swings)
        .map(|k| {
            let shape =
                0.5 * (restoring.period_factor(amp[k]) + restoring.period_factor(amp[k + 1]));
            (turns[k + 1].t_s - turns[k].t_s) / shape
        })
        .collect();
    // The later half-swings' trend of loss against energy (least squares line).
    let (xs, ws) = (&energy[1..], &loss[1..]);
    let m = xs.len() as f64;
    let (mx, mw) = (xs.iter().sum::<f64>() / m, ws.iter().sum::<f64>() / m);
    let sxx: f64 = xs.iter().map(|x| (x - mx).powi(2)).sum();
    let sxw: f64 = xs.iter().zip(ws).map(|(x, w)| (x - mx) * (w - mw)).sum();
    let slope = if sxx > 0.0 { (sxw / sxx).max(0.0) } else { 0.0 };
    let line = |x: f64| mw + slope * (x - mx);
    let resid_sd = (xs
        .iter()
        .zip(ws)
        .map(|(x, w)| (w - line(*x)).powi(2))
        .sum::<f64>()
        / (m - 2.0).max(1.0))
    .sqrt();
    let predicted = line(energy[0]).max(median(ws));
    let leverage = 1.0 / m
        + if sxx > 0.0 {
            (energy[0] - mx).powi(2) / sxx
        } else {
            0.0
        };
    // The first half-swing's own measurement error: its two amplitudes' standard errors
    // through W's derivative (P′ = sin A for gravity, A for a spring; the path's share left out).
    let slope_p = |a: f64| match restoring {
        Restoring::Gravity => a.sin(),
        Restoring::Spring => a,
    };
    let path = amp[0] + amp[1];
    let w0_sd = ((slope_p(amp[0]) * turns[0].sd / scale).powi(2)
        + (slope_p(amp[1]) * turns[1].sd / scale).powi(2))
    .sqrt()
        / path;
    let energy_sd = (resid_sd.powi(2) * (1.0 + leverage) + w0_sd.powi(2))
        .sqrt()
        .max(0.05 * predicted.abs());
    let (energy_ratio, energy_z) = if predicted > 0.0 {
        (loss[0] / predicted, (loss[0] - predicted) / energy_sd)
    } else {
        // The later swings lose nothing measurable: only a clear loss counts.
        (
            f64::INFINITY,
            if loss[0] > 0.0 { f64::INFINITY } else { 0.0 },
        )
    };
    let later = &half_t0[1..];
    let med = median(later);
    let mad_sd = 1.4826 * median(&later.iter().map(|d| (d - med).abs()).collect::<Vec<_>>());
    let period_sd = mad_sd.max(0.005 * med);
    let period_ratio = half_t0[0] / med;
    let period_z = (half_t0[0] - med) / period_sd;
    Some(SwingCheck {
        from_t_s: turns[0].t_s,
        to_t_s: turns[1].t_s,
        to_index: turns[1].index,
        energy_ratio,
        energy_z,
        period_ratio,
        period_z,
        amplitudes: [amp[0], amp[1]],
    })
}

/// Whether the motion released at `start` swings freely from there; if not, where it does: the
/// first half-swing is checked, and while it is disturbed the start moves to its end (at most
/// [`MAX_SKIPPED`] times). `None`: free, or too few half-swings to tell.
pub fn find_disturbance(
    t: &[f64],
    y: &[f64],
    scale: f64,
    start: usize,
    period_s: f64,
    restoring: Restoring,
) -> Option<Disturbance> {
    let mut left_out = Vec::new();
    let mut at = start;
    let mut warning = None;
    loop {
        match check_first_swing(t, y, scale, at, period_s, restoring) {
            Some(c) if c.disturbed() => {
                if left_out.len() == MAX_SKIPPED {
                    warning = Some(format!(
                        "still not free after {MAX_SKIPPED} half-swings: {}; fitted from {:.3} s",
                        c.describe(),
                        t[at]
                    ));
                    break;
                }
                at = c.to_index;
                left_out.push(c);
            }
            Some(_) => break,
            None => {
                if !left_out.is_empty() {
                    warning = Some(format!(
                        "the swing from {:.3} s could not be checked (too few half-swings after \
                         it)",
                        t[at]
                    ));
                }
                break;
            }
        }
    }
    (!left_out.is_empty()).then(|| Disturbance {
        from_t_s: t[start],
        until_t_s: t[at],
        until_index: at,
        left_out,
        warning,
    })
}

#[cfg(test)]
mod tests;

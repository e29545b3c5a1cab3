//! Where free motion starts in a recorded trace: the first sample a single-joint fit may use.
//!
//! A workshop pendulum is often held or carried by hand while the logger already records: the
//! first samples are not free motion. The release is found from the data's own swing times.

use nalgebra::{Matrix3, Vector3};

use crate::numerics::signal::{half_window, local_cubic_rate_at};

pub mod disturbed;
pub use disturbed::{Disturbance, Restoring, SwingCheck};

/// How the release was decided ([`Release::rule`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ReleaseRule {
    /// The trace states it (`test.release_t_s`).
    Stated,
    /// The trace starts at the release: its first motion is a free half-swing from rest.
    FirstSample,
    /// Held at rest by hand, then let go: the first motion, a free half-swing from rest,
    /// starts after the hold.
    AfterHold,
    /// Carried by hand into a turning point and let go there (or after a pause there): the
    /// first motion was not free, the swing out of the first turning point is.
    TurningPoint,
    /// Found by one of the rules above, but the swing out of it was not free (held back, issue
    /// 36 point 4: [`disturbed`]): the fit starts at a later turning point.
    Disturbed,
}

impl ReleaseRule {
    pub fn as_str(self) -> &'static str {
        match self {
            ReleaseRule::Stated => "stated",
            ReleaseRule::FirstSample => "first_sample",
            ReleaseRule::AfterHold => "after_hold",
            ReleaseRule::TurningPoint => "turning_point",
            ReleaseRule::Disturbed => "disturbed",
        }
    }
}

/// The first sample of free motion, how it was found, and why it may be wrong.
#[derive(Debug, Clone, PartialEq)]
pub struct Release {
    pub index: usize,
    pub rule: ReleaseRule,
    /// A sentence when the data do not decide the release clearly (the fit then starts where
    /// the rule says, and the user can state `test.release_t_s`).
    pub warning: Option<String>,
    /// With [`ReleaseRule::Disturbed`]: the part left out and why.
    pub disturbance: Option<Disturbance>,
}

impl Release {
    pub fn at(index: usize, rule: ReleaseRule) -> Self {
        Release {
            index,
            rule,
            warning: None,
            disturbance: None,
        }
    }

    /// This release checked for a first half-swing that is not free ([`disturbed`]); when one
    /// is found, the release moves to the free motion's start and says what was left out.
    pub fn checked(
        self,
        t: &[f64],
        y: &[f64],
        scale: f64,
        period_s: f64,
        restoring: Restoring,
    ) -> Release {
        match disturbed::find_disturbance(t, y, scale, self.index, period_s, restoring) {
            None => self,
            Some(d) => {
                let warning = match (&self.warning, &d.warning) {
                    (Some(a), Some(b)) => Some(format!("{a}; {b}")),
                    (a, b) => a.clone().or_else(|| b.clone()),
                };
                Release {
                    index: d.until_index,
                    rule: ReleaseRule::Disturbed,
                    warning,
                    disturbance: Some(d),
                }
            }
        }
    }
}

/// A free half-swing into the first turning point lasts between these fractions of the next
/// one (their ratio): above 1 at large amplitude (the period grows with it: ×1.18 at 90°,
/// ×1.53 at 135° for an ideal pendulum, and the next swing is smaller by the friction), below
/// 1 only by noise. A carried start is shorter, a slow hand longer.
const FREE_RATIO: [f64; 2] = [0.75, 1.45];

/// A free half-swing into the first turning point spans between these fractions of the next
/// one's size (above 1 by what friction takes per half-swing: 1.02–1.04 for J3 at Table 4,
/// 45–135°); a hand's carry spans what the hand moved.
const SPAN_RATIO: [f64; 2] = [0.85, 1.4];

/// Within this of a `FREE_RATIO` or `SPAN_RATIO` bound the decision is reported as ambiguous.
const AMBIGUOUS_BAND: f64 = 0.08;

/// "Moving": the smoothed rate above this share of the scanned stretch's peak rate (a hand's
/// tremor, 0.1° at 6 Hz, and the smoothed noise of a 0.05° sensor stay below it at 45°).
const MOVING: f64 = 0.1;

/// "At rest": the smoothed rate at or below this share of the peak (a free swing leaves rest
/// within 0.3 % of its period).
const AT_REST: f64 = 0.02;

/// The release of a test whose small-amplitude period is `period_s` (from the rig): only the
/// smoothing window and the stretch scanned (the first 6 periods) depend on it.
///
/// Rule (documented assumption): free motion from rest reaches its first turning point after
/// a half-swing of about the same duration as the next one (`FREE_RATIO`). The trace is
/// smoothed (local cubic over period/20); its first motion (rate above 10 % of the peak) and the
/// first two turning points r₁, r₂ are found. If the motion into r₁ started from rest (the
/// trace's start, or a hold by hand) and lasted a free half-swing, the release is where it
/// left rest. If it was shorter (carried into r₁, or the trace starts mid-swing) or longer (a
/// slow hand), the release is where the swing out of r₁ leaves rest: r₁ itself, or the end of
/// a pause there. Near a bound of `FREE_RATIO`, and where fewer than two turning points are
/// found, the choice is reported with a warning. Reversals in a stretch where the trace does
/// not move beyond its noise do not count.
pub fn find_release(t: &[f64], y: &[f64], period_s: f64) -> Release {
    let mut r = coarse(t, y, period_s);
    if r.index > 0 {
        let held = r.rule == ReleaseRule::AfterHold;
        r.index = refine(t, y, r.index, period_s / 20.0, held);
    }
    r
}

/// [`find_release`] at the smoothing stride's resolution.
fn coarse(t: &[f64], y: &[f64], period_s: f64) -> Release {
    let n = t.len();
    let first = Release::at(0, ReleaseRule::FirstSample);
    if n < 20 || !(period_s.is_finite() && period_s > 0.0) {
        return first;
    }
    let half = half_window(t, period_s / 20.0);
    let stride = (half / 4).max(1);
    let idx: Vec<usize> = (0..n)
        .take_while(|&i| t[i] - t[0] <= 6.0 * period_s)
        .step_by(stride)
        .collect();
    if idx.len() < 8 {
        return first;
    }
    // The rates alone (issue 38, session 22: the same numbers, a third of the work).
    let rate = local_cubic_rate_at(t, y, &idx, half);
    let peak = rate.iter().fold(0.0f64, |m, r| m.max(r.abs()));
    if !(peak > 0.0 && peak.is_finite()) {
        return first;
    }
    let moving = |k: usize| rate[k].abs() > MOVING * peak;
    let resting = |k: usize| rate[k].abs() <= AT_REST * peak;
    // The first moving point, and the turning points: sign changes of the rate between
    // consecutive moving points (k indexes `idx`).
    let Some(m_in) = (0..idx.len()).find(|&k| moving(k)) else {
        return first;
    };
    let mut turns = Vec::new();
    let mut last = m_in;
    for k in m_in + 1..idx.len() {
        if !moving(k) {
            continue;
        }
        if rate[k].signum() != rate[last].signum() {
            turns.push((last, k));
            if turns.len() == 2 {
                break;
            }
        }
        last = k;
    }
    // Where the motion that is moving at `k` left rest: back from k to the first point at rest
    // (the sample `floor` if none).
    let left_rest = |k: usize, floor: usize| (floor..=k).rev().find(|&j| resting(j));
    // The extreme sample between two moving points of opposite sign: the turning point.
    let extreme = |a: usize, b: usize| {
        let s0 = rate[a].signum();
        (idx[a]..=idx[b])
            .max_by(|&i, &j| (s0 * y[i]).total_cmp(&(s0 * y[j])))
            .unwrap_or(idx[a])
    };
    // A trace moving fast at its first points did not start at rest (the first point alone is
    // noisy: a one-sided smoothing window).
    let starts_moving = (1..3.min(idx.len())).all(|k| rate[k].abs() > 0.2 * peak);
    let start_in = if starts_moving {
        None
    } else {
        Some(left_rest(m_in, 0).unwrap_or(0))
    };
    let [(a1, b1), (a2, b2)] = match turns[..] {
        [x, y] => [x, y],
        _ => {
            // No swing to compare with: a trace that starts at rest starts at its release
            // (an overdamped or short record); a later start of motion is said.
            return match start_in {
                Some(k) if t[idx[k]] - t[0] > 0.02 * period_s => Release {
                    index: idx[k],
                    rule: ReleaseRule::AfterHold,
                    disturbance: None,
                    warning: Some(format!(
                        "fewer than two turning points in the first {:.1} s: the release is \
                         taken where the first motion starts ({:.3} s), unchecked; state \
                         test.release_t_s if that is wrong",
                        t[idx[idx.len() - 1]] - t[0],
                        t[idx[k]]
                    )),
                },
                _ => first,
            };
        }
    };
    let r1 = extreme(a1, b1);
    let r2 = extreme(a2, b2);
    // The swing out of r₁ leaves rest at r₁ or, after a pause there, where it starts moving.
    let out_start = {
        let k = left_rest(b1, a1).unwrap_or(a1);
        let pause = t[idx[k]] - t[r1];
        if pause > 0.02 * period_s { idx[k] } else { r1 }
    };
    let next = t[r2] - t[out_start];
    let mut carried = Release::at(out_start, ReleaseRule::TurningPoint);
    let Some(k_in) = start_in else {
        return carried;
    };
    let into = t[r1] - t[idx[k_in]];
    let ratio = into / next;
    // The swing's size: a free half-swing from rest spans about what the next one does (a
    // little more: friction takes some each time); a hand's carry spans what the hand did.
    let span_ratio = (y[r1] - y[idx[k_in]]).abs() / (y[r2] - y[r1]).abs().max(f64::MIN_POSITIVE);
    let near = |x: f64, b: [f64; 2]| {
        (x - b[0]).abs() <= AMBIGUOUS_BAND || (x - b[1]).abs() <= AMBIGUOUS_BAND
    };
    let ambiguous = near(ratio, FREE_RATIO) || near(span_ratio, SPAN_RATIO);
    let inside = |x: f64, b: [f64; 2]| (b[0]..=b[1]).contains(&x);
    let free = inside(ratio, FREE_RATIO) && inside(span_ratio, SPAN_RATIO);
    let what = format!(
        "the motion into the first turning point lasted {into:.3} s and spanned {:.2} of the \
         next half-swing's size in {ratio:.2} of its time (a free half-swing from rest: \
         {:.2}–{:.2} of its size, {:.2}–{:.2} of its time)",
        span_ratio, SPAN_RATIO[0], SPAN_RATIO[1], FREE_RATIO[0], FREE_RATIO[1]
    );
    if !free {
        // Shorter and smaller than a free swing: carried into the turning point, the usual
        // case. Anything else, or near a bound, is said.
        if ambiguous || ratio > FREE_RATIO[0] {
            carried.warning = Some(format!(
                "{what}: not free; the release is taken at the turning point ({:.3} s); state \
                 test.release_t_s if that is wrong",
                t[out_start]
            ));
        }
        return carried;
    }
    let (index, rule) = if idx[k_in] > 0 && t[idx[k_in]] - t[0] > 0.02 * period_s {
        (idx[k_in], ReleaseRule::AfterHold)
    } else {
        (0, ReleaseRule::FirstSample)
    };
    Release {
        index,
        rule,
        disturbance: None,
        warning: ambiguous.then(|| {
            format!(
                "ambiguous release: {what}; taken where the first motion starts ({:.3} s); state \
                 test.release_t_s to decide",
                t[index]
            )
        }),
    }
}

/// The release near sample `i0` at the sampling resolution: the point t_r where the motion
/// leaves rest, fitted as y = c + ½·a₋·(t − t_r)² before and c + ½·a₊·(t − t_r)² after (zero
/// rate at t_r; a₋ = 0 for a hold (`held`), the hand's deceleration for a carry, a₊ the free
/// swing's acceleration) over ±`w_s`, t_r scanned over ±`w_s`/2 around `t[i0]`. Within
/// w_s = period/20 of a release the free motion differs from its parabola by under 0.05 % of
/// the amplitude.
fn refine(t: &[f64], y: &[f64], i0: usize, w_s: f64, held: bool) -> usize {
    let n = t.len();
    let lo = t.partition_point(|&x| x < t[i0] - w_s / 2.0);
    let hi = t.partition_point(|&x| x <= t[i0] + w_s / 2.0).min(n);
    let mut best = (f64::INFINITY, i0);
    for r in lo..hi {
        let a = t.partition_point(|&x| x < t[r] - w_s);
        let b = t.partition_point(|&x| x <= t[r] + w_s).min(n);
        // Least squares in (c, a₋, a₊): columns 1, u₋ = ½(t−t_r)² before, u₊ after.
        let (mut m, mut v) = (Matrix3::<f64>::zeros(), Vector3::<f64>::zeros());
        for k in a..b {
            let u = 0.5 * (t[k] - t[r]).powi(2);
            let row = if k < r {
                Vector3::new(1.0, if held { 0.0 } else { u }, 0.0)
            } else {
                Vector3::new(1.0, 0.0, u)
            };
            v += row * y[k];
            m += row * row.transpose();
        }
        if held {
            // a₋ is not fitted: keep the system regular.
            m[(1, 1)] = 1.0;
        }
        let Some(x) = m.lu().solve(&v) else {
            continue;
        };
        let ssr: f64 = (a..b)
            .map(|k| {
                let u = 0.5 * (t[k] - t[r]).powi(2);
                let f = if k < r {
                    x[0] + x[1] * u
                } else {
                    x[0] + x[2] * u
                };
                (y[k] - f).powi(2)
            })
            .sum();
        if ssr < best.0 {
            best = (ssr, r);
        }
    }
    best.1
}

/// The index of a stated release time: the first sample at or after `release_t_s`. `None` when
/// the time lies outside the trace or leaves fewer than `min_samples` after it.
pub fn stated_release(t: &[f64], release_t_s: f64, min_samples: usize) -> Option<usize> {
    let (t0, t1) = (*t.first()?, *t.last()?);
    if !(release_t_s.is_finite() && release_t_s >= t0 && release_t_s <= t1) {
        return None;
    }
    let i = t.partition_point(|&x| x < release_t_s);
    (t.len() - i >= min_samples).then_some(i)
}

#[cfg(test)]
mod tests;

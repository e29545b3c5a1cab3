//! Which workshop test to do next (issue 37, point 2): each candidate test ranked by what it
//! buys — the probability that a joint it informs has crossed its watch band unseen, resolved
//! by the information the test gives.
//!
//! Rule (stated):
//! - every joint parameter has a belief now ([`super::evidence`]: the last informing test
//!   widened by the wear since, or the prior for one never measured); its probability past the
//!   watch band `p_watch` and past the alarm band `p_alarm` (bands × Table 4 baseline, the drift
//!   thresholds); the crossing *unseen* is the one past what its last test already showed:
//!   `p_watch` for a parameter last judged `ok` or `unknown`, `p_alarm` for one at `watch`, none
//!   for one at `alarm` (its alert stands; a test shows nothing new);
//! - a test informs some parameters with Fisher information I each (1/unit²: what that kind of
//!   test returned on that parameter, read from its interval, [`super::evidence::
//!   information_of_interval`]); after it the sd is σ' = (1/σ² + I)^−½;
//! - what the test buys is Σ p_unseen · (1 − σ'/σ) over the parameters it informs: the chance
//!   an unseen crossing is there times the share of the uncertainty the test removes — a test of a joint
//!   that cannot have crossed buys nothing, nor does a test that cannot see the joint; its
//!   information, Σ ½·log₂(σ²/σ'²) bits, breaks ties and is reported;
//! - tests are ranked by what they buy, then by bits, then by kind and joint (stable order).

use serde::{Deserialize, Serialize};

use super::drift::{DriftThresholds, Status};
use super::evidence::Belief;

/// One joint parameter's state now.
#[derive(Debug, Clone, PartialEq)]
pub struct ParamNow {
    pub joint: String,
    /// `viscous` or `dry`.
    pub param: String,
    /// Table 4 baseline, in the parameter's unit.
    pub baseline: f64,
    pub belief: Belief,
    /// The status its last informing test gave (`unknown` when never measured).
    pub seen: Status,
}

impl ParamNow {
    /// Probability of a crossing its last test did not show (the module's rule).
    pub fn p_unseen(&self, th: &DriftThresholds) -> f64 {
        p_unseen_of(self.seen, self.p_past(th))
    }

    /// Probabilities past the watch and the alarm band (`[p_watch, p_alarm]`).
    pub fn p_past(&self, th: &DriftThresholds) -> [f64; 2] {
        p_past(&self.belief, self.baseline, th)
    }
}

/// [`ParamNow::p_past`] of a belief about a parameter with this `baseline` (the bands × the
/// baseline): `[p_watch, p_alarm]`.
pub fn p_past(belief: &Belief, baseline: f64, th: &DriftThresholds) -> [f64; 2] {
    [
        belief.p_outside(band(th.watch, baseline)),
        belief.p_outside(band(th.alarm, baseline)),
    ]
}

/// A relative band (× the baseline) in the parameter's unit.
fn band(relative: [f64; 2], baseline: f64) -> [f64; 2] {
    [relative[0] * baseline, relative[1] * baseline]
}

/// `p_unseen_of(seen, p_past(belief, baseline, th))` computing only the band `seen` needs (one
/// [`Belief::p_outside`], none for `alarm`): the same number with half the `erfc` calls or
/// none — what ranking a fleet needs, where `p_watch`/`p_alarm` are reported only for the
/// tests served.
pub fn p_unseen_at(belief: &Belief, baseline: f64, seen: Status, th: &DriftThresholds) -> f64 {
    match seen {
        Status::Unknown | Status::Ok => belief.p_outside(band(th.watch, baseline)),
        Status::Watch => belief.p_outside(band(th.alarm, baseline)),
        Status::Alarm => 0.0,
    }
}

/// [`ParamNow::p_unseen`] from `[p_watch, p_alarm]` and the status its last test gave.
pub fn p_unseen_of(seen: Status, [p_watch, p_alarm]: [f64; 2]) -> f64 {
    match seen {
        Status::Unknown | Status::Ok => p_watch,
        Status::Watch => p_alarm,
        Status::Alarm => 0.0,
    }
}

/// What one test informs: a parameter and the Fisher information it gives on it (1/unit²).
#[derive(Debug, Clone, PartialEq)]
pub struct Informs {
    pub joint: String,
    pub param: String,
    pub info: f64,
}

/// A test a depot can do: its kind (`pendulum`, `slider`, `lift`, `static_force`, …), the joint
/// it swings when it is a single-joint test, and what it informs.
#[derive(Debug, Clone, PartialEq)]
pub struct TestOption {
    pub kind: String,
    pub joint: Option<String>,
    pub informs: Vec<Informs>,
}

/// One parameter a planned test informs: its risk now and its sd now and after.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct PlanParam {
    pub joint: String,
    pub param: String,
    /// Probability the parameter is past its watch band now (alarm included).
    pub p_watch: f64,
    /// Probability it is past its alarm band now.
    pub p_alarm: f64,
    /// Probability of a crossing its last test did not show.
    pub p_unseen: f64,
    pub sd_now: f64,
    pub sd_after: f64,
}

/// A ranked test.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct PlanItem {
    pub kind: String,
    /// The joint to swing (single-joint tests); `null` for a whole-pantograph test.
    pub joint: Option<String>,
    /// What the test buys: Σ p_unseen · (1 − sd_after/sd_now) over what it informs.
    pub buys: f64,
    /// Largest p_unseen among the parameters it informs.
    pub p_unseen: f64,
    /// Largest p_watch / p_alarm among the parameters it informs.
    pub p_watch: f64,
    pub p_alarm: f64,
    /// Information the test gives, bits (Σ ½·log₂(sd_now²/sd_after²)).
    pub info_bits: f64,
    pub params: Vec<PlanParam>,
}

/// Ranks `options` against the parameters' beliefs (the module's rule). Options that inform
/// none of `params` are left out.
pub fn rank(params: &[ParamNow], options: &[TestOption], th: &DriftThresholds) -> Vec<PlanItem> {
    let mut out: Vec<PlanItem> = options
        .iter()
        .filter_map(|o| {
            let mut item = PlanItem {
                kind: o.kind.clone(),
                joint: o.joint.clone(),
                buys: 0.0,
                p_unseen: 0.0,
                p_watch: 0.0,
                p_alarm: 0.0,
                info_bits: 0.0,
                params: Vec::new(),
            };
            for inf in &o.informs {
                let Some(p) = params
                    .iter()
                    .find(|p| p.joint == inf.joint && p.param == inf.param)
                else {
                    continue;
                };
                let sd_now = p.belief.sd;
                let sd_after = p.belief.sd_after(inf.info);
                let shrinks = sd_now > 0.0 && sd_after < sd_now;
                if !shrinks {
                    continue;
                }
                let [p_watch, p_alarm] = p.p_past(th);
                let p_unseen = p.p_unseen(th);
                item.buys += p_unseen * (1.0 - sd_after / sd_now);
                item.p_unseen = item.p_unseen.max(p_unseen);
                item.info_bits += (sd_now / sd_after).log2();
                item.p_watch = item.p_watch.max(p_watch);
                item.p_alarm = item.p_alarm.max(p_alarm);
                item.params.push(PlanParam {
                    joint: p.joint.clone(),
                    param: p.param.clone(),
                    p_watch,
                    p_alarm,
                    p_unseen,
                    sd_now,
                    sd_after,
                });
            }
            (!item.params.is_empty()).then_some(item)
        })
        .collect();
    out.sort_by(|a, b| {
        b.buys
            .total_cmp(&a.buys)
            .then(b.info_bits.total_cmp(&a.info_bits))
            .then_with(|| a.kind.cmp(&b.kind))
            .then_with(|| a.joint.cmp(&b.joint))
    });
    out
}

#[cfg(test)]
#[path = "plan_tests.rs"]
mod tests;

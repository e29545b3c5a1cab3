//! Saying ambiguity (issue 36, point 3): when two explanations fit a record equally the loop
//! names neither, reports both and the test that would tell them apart; and a named effect must
//! explain the record across its range, early large swings and late small ones judged apart.
//!
//! Stated choices:
//! - Two explanations are equal when their BICs differ by less than [`AMBIGUITY_BIC`] (the
//!   margin an effect must earn over the base model: a difference under it is no evidence) and
//!   their held-out RMSEs by less than [`AMBIGUITY_HOLDOUT`] of the better one.
//! - Besides the vocabulary's effects, an `inertia_error` is weighed against the physics the
//!   issue names as its look-alike: a restoring torque linear in angle beside gravity (a torsion
//!   spring, a cable, a stiff seal — `Dof::torsion`), outside the vocabulary. Its stiffness is
//!   found by a golden-section search of the split's fitted RMSE around the stiffness that gives
//!   the inertia error's small-swing period, k₀ = m·g·d·(1/r − 1), within 0.25–1.75 k₀ (a
//!   restoring torque whose period shift at small swings is not within that of the inertia
//!   error's is no look-alike: the record already tells them apart). Pendulums only (a slider's
//!   spring error and mass error are both linear: no amplitude separates them, and the loop's
//!   own rule for the slider stands).
//! - Halves: the free motion from release, split at its middle sample; each half's share of
//!   the base model's excess over σ² (σ from the base residual's first differences) that the
//!   model explains. A half whose base excess is under σ²/2 is not judged (nothing to explain).

use serde_json::{Map, Value, json};

use super::effects::Effect;
use super::{Split, bic, split_fit};
use crate::contract::report::{Ambiguity, Explanation, HalvesCheck};
use crate::joint::dynamics::Mechanism;
use crate::joint::identify::{FitOptions, FitSpec, JointTest};

/// Two BICs closer than this are equal (the same margin an effect must earn to be named).
pub const AMBIGUITY_BIC: f64 = 10.0;
/// Two held-out RMSEs within this fraction of the better one are equal.
pub const AMBIGUITY_HOLDOUT: f64 = 0.10;
/// Golden-section steps of the restoring-torque search over [0.25 k₀, 1.75 k₀] (the bracket
/// shrinks to 0.618²⁶ ≈ 4·10⁻⁶ of its width). The stiffness must be found this finely: a 0.3 %
/// error in a spring of 5 % of m·g·d drifts the phase by ~0.3° over a 20 s record, six times
/// the stand's noise, and its BIC then loses to an inertia error it equals (measured: with 12
/// steps over [0, 2 k₀], a J5 spring at 30° was named `inertia_error` in 1 of 3 seeds).
const TORSION_STEPS: usize = 26;

/// One explanation fitted on the split.
#[derive(Debug, Clone)]
pub struct Fitted {
    pub name: String,
    pub in_vocabulary: bool,
    pub bic: f64,
    pub split: Split,
    pub params: Map<String, Value>,
}

/// m·g·d of a pendulum, N·m (its small-angle gravitational stiffness, N·m/rad).
fn gravity_stiffness(test: &JointTest) -> Option<f64> {
    match test.dof.mech {
        Mechanism::Pendulum(r) => Some(r.mass_kg * r.gravity_m_s2 * r.com_distance_m),
        Mechanism::Slider(_) => None,
    }
}

/// The base model with a restoring torque −k·q beside gravity, k fitted (see the module's
/// choices). `None` for a slider, or when no fit converged.
pub fn restoring_torque(
    test: &JointTest,
    base_split: &Split,
    base: &FitSpec,
    inertia_ratio: f64,
    opts: &FitOptions,
) -> Option<Fitted> {
    let mgd = gravity_stiffness(test)?;
    let k0 = mgd * (1.0 / inertia_ratio - 1.0);
    if !k0.is_finite() || k0 == 0.0 {
        return None;
    }
    let fit_at = |k: f64| -> Option<Split> {
        let mut t = test.clone();
        t.dof.torsion = k;
        split_fit(&t, &base_split.fit, base, opts).ok()
    };
    let cost = |s: &Option<Split>| s.as_ref().map_or(f64::INFINITY, |s| s.rmse_fit);
    let g = 0.5 * (5f64.sqrt() - 1.0);
    let (mut a, mut b) = (0.25 * k0, 1.75 * k0);
    let (mut c, mut d) = (b - g * (b - a), a + g * (b - a));
    let (mut fc, mut fd) = (fit_at(c), fit_at(d));
    for _ in 0..TORSION_STEPS {
        if cost(&fc) < cost(&fd) {
            b = d;
            d = c;
            fd = fc;
            c = b - g * (b - a);
            fc = fit_at(c);
        } else {
            a = c;
            c = d;
            fc = fd;
            d = a + g * (b - a);
            fd = fit_at(d);
        }
    }
    let (k, split) = if cost(&fc) < cost(&fd) {
        (c, fc?)
    } else {
        (d, fd?)
    };
    // The stiffness is one parameter more than the base model's.
    let n = split.fit.n_fit as f64;
    let mut params = Map::new();
    params.insert("stiffness_nm_per_rad".into(), json!(k));
    params.insert("stiffness_over_gravity".into(), json!(k / mgd));
    Some(Fitted {
        name: "restoring_torque".into(),
        in_vocabulary: false,
        bic: bic(&split.fit) + n.ln(),
        split,
        params,
    })
}

/// Whether `b` fits the record as well as `a` (within both margins).
pub fn equal(a: &Fitted, b: &Fitted) -> bool {
    let best = a.split.rmse_holdout.min(b.split.rmse_holdout);
    (a.bic - b.bic).abs() < AMBIGUITY_BIC
        && (a.split.rmse_holdout - b.split.rmse_holdout).abs() <= AMBIGUITY_HOLDOUT * best
}

/// Whether `a` fits the record clearly better than `b`: BIC lower by [`AMBIGUITY_BIC`] or more,
/// and a held-out RMSE no worse than `b`'s by more than [`AMBIGUITY_HOLDOUT`] (measured: a J5
/// spring at 30° fitted as a restoring torque had a BIC 325–350 lower than as an inertia error
/// and held-out RMSEs within 0.0001° of each other, both at the noise).
pub fn better(a: &Fitted, b: &Fitted) -> bool {
    a.bic <= b.bic - AMBIGUITY_BIC
        && a.split.rmse_holdout <= (1.0 + AMBIGUITY_HOLDOUT) * b.split.rmse_holdout
}

/// What an explanation's signature depends on, and the record that shows it.
fn signature(name: &str) -> (&'static str, &'static str) {
    match name {
        "inertia_error" => (
            "shifts the period by one fraction at every amplitude",
            "a release from another angle",
        ),
        "restoring_torque" => (
            "shifts the period by a fraction that grows as the swings shrink (linear in angle, \
             where gravity goes as sin)",
            "a release from another angle",
        ),
        "stribeck" => (
            "acts at low speed (near each turning point)",
            "a longer record with more small, slow swings",
        ),
        "quadratic_drag" => (
            "grows with speed squared",
            "a release from a larger angle (faster swings)",
        ),
        "position_friction" => (
            "depends on where the joint is",
            "a release from another angle (other travel)",
        ),
        "backlash" => (
            "acts at each reversal",
            "a longer record with more reversals",
        ),
        "sensor_delay" => (
            "grows with speed",
            "a release from a larger angle (faster swings)",
        ),
        "asymmetric_friction" => (
            "depends on the direction of motion",
            "a release from the other side",
        ),
        _ => ("", "another release angle or a longer record"),
    }
}

/// Bessel J₁ by its power series (|x| ≤ π here: 20 terms are exact to machine precision).
fn bessel_j1(x: f64) -> f64 {
    let (mut term, mut sum) = (x / 2.0, x / 2.0);
    for m in 1..20 {
        term *= -(x * x / 4.0) / (m as f64 * (m + 1) as f64);
        sum += term;
    }
    sum
}

/// The period of an explanation relative to the stated model's for swings of amplitude
/// `amplitude_rad`, by harmonic balance: the period ∝ √(J/κ(A)), gravity's stiffness at
/// amplitude A being κ_g(A) = m·g·d·2·J₁(A)/A (its describing function; within 0.5 % of the exact
/// pendulum period up to 120°), a restoring torque adding k at every amplitude and an inertia
/// error scaling J by r.
fn period_ratio(e: &Fitted, mgd: f64, amplitude_rad: f64) -> Option<f64> {
    let grav = if amplitude_rad < 1e-6 {
        mgd
    } else {
        mgd * 2.0 * bessel_j1(amplitude_rad) / amplitude_rad
    };
    match e.name.as_str() {
        "inertia_error" => e
            .params
            .get("inertia_ratio")
            .and_then(Value::as_f64)
            .map(f64::sqrt),
        "restoring_torque" => e
            .params
            .get("stiffness_nm_per_rad")
            .and_then(Value::as_f64)
            .map(|k| (grav / (grav + k)).sqrt()),
        _ => None,
    }
}

/// In words, what each named explanation's signature depends on and the record that would tell
/// them apart (no amplitudes: the pooled loop's ties).
pub fn telling_apart(names: &[&str]) -> String {
    let mut s = String::new();
    for n in names {
        let (what, _) = signature(n);
        if !what.is_empty() {
            s += &format!("{n} {what}; ");
        }
    }
    let (_, record) = signature(names.first().copied().unwrap_or(""));
    s + record + " would tell them apart"
}

/// The test that would tell `explanations` apart, from how they differ. For an inertia error
/// against a restoring torque, their predicted periods at the record's largest swing, at small
/// swings and at a release of 90° (or 1.5× the record's, if larger; at most 120°).
pub fn separating_test(test: &JointTest, explanations: &[Fitted], amplitude_rad: f64) -> String {
    let names: Vec<&str> = explanations.iter().map(|e| e.name.as_str()).collect();
    let mut s = String::new();
    for n in &names {
        let (what, _) = signature(n);
        if !what.is_empty() {
            s += &format!("{n} {what}; ");
        }
    }
    let (_, record) = signature(names.first().copied().unwrap_or(""));
    if let Some(mgd) = gravity_stiffness(test)
        && names.contains(&"inertia_error")
        && names.contains(&"restoring_torque")
    {
        // Another angle where the two part: 90°, or 1.5× the record's, at most 120°.
        let far = (1.5 * amplitude_rad)
            .max(std::f64::consts::FRAC_PI_2)
            .min(120f64.to_radians());
        let at = |a: f64| -> Vec<String> {
            explanations
                .iter()
                .filter_map(|e| period_ratio(e, mgd, a).map(|p| format!("{} ×{p:.4}", e.name)))
                .collect()
        };
        s += &format!(
            "their periods against the stated model's: small swings {}; at this record's largest \
             swing ({:.0}°) {}; released from {:.0}° {}. Release the same rig from {:.0}° (and \
             let it swing down to small amplitudes): the explanation whose period shift holds is \
             the rig's.",
            at(0.0).join(", "),
            amplitude_rad.to_degrees(),
            at(amplitude_rad).join(", "),
            far.to_degrees(),
            at(far).join(", "),
            far.to_degrees()
        );
    } else {
        s += &format!("{record} would tell them apart.");
    }
    s
}

/// The contract's block for explanations the record cannot tell apart.
pub fn ambiguity(test: &JointTest, explanations: &[Fitted], amplitude_rad: f64) -> Ambiguity {
    let best = explanations
        .iter()
        .map(|e| e.bic)
        .fold(f64::INFINITY, f64::min);
    Ambiguity {
        explanations: explanations
            .iter()
            .map(|e| Explanation {
                name: e.name.clone(),
                in_vocabulary: e.in_vocabulary,
                delta_bic: e.bic - best,
                holdout_rmse: e.split.rmse_holdout,
                params: e.params.clone(),
            })
            .collect(),
        margin: format!(
            "neither is clearly better: none has a BIC lower by {AMBIGUITY_BIC} or more with a \
             held-out RMSE no more than {:.0} % above the other's",
            100.0 * AMBIGUITY_HOLDOUT
        ),
        separating_test: separating_test(test, explanations, amplitude_rad),
    }
}

/// Share of the excess over σ² that `after` explains (1: all of it; ≤ 0: none).
pub fn explained(before: f64, after: f64, sigma: f64) -> f64 {
    let s2 = sigma * sigma;
    let b = (before * before - s2).max(0.0);
    if b <= 0.0 {
        return 1.0;
    }
    1.0 - (after * after - s2).max(0.0) / b
}

fn rms(v: impl Iterator<Item = f64>) -> f64 {
    let (s, n) = v.fold((0.0, 0usize), |(s, n), x| (s + x * x, n + 1));
    (s / n.max(1) as f64).sqrt()
}

/// The model `sp` against the base `base` on the early and late halves of the free motion
/// (fitted and held-out parts together: each split's prediction over all of it).
pub fn halves(
    test: &JointTest,
    start: usize,
    base: &Split,
    sp: &Split,
    effects: &[Effect],
    sigma: f64,
    least_share: f64,
) -> HalvesCheck {
    let y = &test.y[start..];
    let n = y.len().min(base.prediction.len()).min(sp.prediction.len());
    let m = n / 2;
    let half_rms = |p: &[f64], lo: usize, hi: usize| rms((lo..hi).map(|i| p[i] - y[i]));
    let (b_early, b_late) = (
        half_rms(&base.prediction, 0, m),
        half_rms(&base.prediction, m, n),
    );
    let (a_early, a_late) = (
        half_rms(&sp.prediction, 0, m),
        half_rms(&sp.prediction, m, n),
    );
    let material = |b: f64| b * b - sigma * sigma > 0.5 * sigma * sigma;
    let early = explained(b_early, a_early, sigma);
    let late = explained(b_late, a_late, sigma);
    let holds =
        (!material(b_early) || early >= least_share) && (!material(b_late) || late >= least_share);
    let names: Vec<&str> = effects.iter().map(|e| e.name()).collect();
    HalvesCheck {
        model: names.join("+"),
        early_explained_share: early,
        late_explained_share: late,
        early_remainder_over_noise: a_early / sigma.max(1e-300),
        late_remainder_over_noise: a_late / sigma.max(1e-300),
        holds,
    }
}

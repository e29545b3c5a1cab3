//! What a lift fit had to do to reach the noise (issue 36, point 1): no effect absorbed in
//! silence.
//!
//! A lift fit reports few parameters (on the paper's protocols the J1+J3 dry level; the torque
//! sensor's offset is a nuisance) but fits every joint's friction inside the Table 4 prior
//! (sd 0.5 × baseline), so an effect the model lacks can be absorbed by the joints it does not
//! report: the residual comes out at the noise and the verdict clean while the reported level
//! moves off its truth. The check here refits the trace with only the *reported* parameters
//! free — the members of the informed combinations and the separately informed parameters, with
//! the sensor offset — and every other coefficient at its prior mean (Table 4, the model's
//! value, or a fleet prior's mean: issue 37). Where that refit leaves at least [`ABSORBED_RATIO`] × the noise, the plain fit's
//! agreement with the data was bought with parameters nobody reads: the lift must end with an
//! effect named (`lift::effects`) or `unexplained` with its joints withheld
//! (`report::fit_lift_trace`).
//!
//! Stated choices:
//! - The noise is the one the residual gate uses ([`super::residual::diagnose`]: σ̂ from first
//!   differences, floored at max(σ_H, [`super::residual::GATE_FLOOR_M`])).
//! - [`ABSORBED_RATIO`] 2: the rule. Measured on clean lifts (Table 4, and one joint
//!   drifted within the watch band) by `examples/lift_loop_probe`, docs/VALIDATION.md.
//! - The refit starts at the plain fit's MAP of the reported parameters (no continuation): one
//!   basin, a few evaluations. Not always (a plain fit at a bound, its other joints absorbing
//!   the effect): where that refit fires, it is repeated from the plain fit's own start and the
//!   better kept ([`reported_only`]).
//! - A drift of an unreported joint beyond what the restricted model can follow fires it too:
//!   the lift cannot tell it from a missing effect, and says so rather than report a level
//!   whose interval it cannot vouch for.

use super::dynamics::LiftModel;
use super::fit::{LiftFit, LiftFitError, LiftFitOptions, LiftTrace};
use super::identify::fit_map;
use super::sensitivity::LiftParam;
use crate::contract::report::AbsorptionCheck;

/// The restricted refit's residual over the noise at or above which the check fires.
pub const ABSORBED_RATIO: f64 = 2.0;

/// A named effect, reported with every joint free, must leave the record within this ratio to
/// the noise, else the lift is `unexplained` (`report::fit_lift_trace`). Measured
/// (`examples/lift_loop_probe`, seeds 100–102, the stand's noise and twice it): right names left
/// 0.70–1.01× (one Stribeck on a raise and lower 1.46×); wrong ones 1.40–1.70× (a friction
/// fading over the paper's raise named `drive_compliance`, a 2 % torque gain error on the
/// designed protocol `sensor_offset`). A 2 % spring-force gain error named `sensor_offset` or
/// `drive_compliance` left 0.75–0.85×: not caught by this.
pub const NAMED_MAX_RATIO: f64 = 1.35;

/// The name of the check in the contract (`fit.absorption.check`).
pub const CHECK_NAME: &str = "reported_only_refit";

/// The restricted refit's outcome.
#[derive(Debug, Clone)]
pub struct Absorption {
    /// Parameters left free (friction; the offset is always fitted).
    pub free: Vec<LiftParam>,
    /// Its H residual RMS, m.
    pub rms_m: f64,
    /// The noise it is judged against, m.
    pub noise_m: f64,
    /// `rms_m / noise_m`.
    pub ratio: f64,
    /// The phase the refit misfits most and its ratio (`judge::by_phase`), if any is judged.
    pub worst_phase: Option<(&'static str, f64)>,
    /// Whether the worst phase can fire the check: on a record that does not lower the strip
    /// (`judge::PHASE_FIRE_RATIO`).
    pub phase_fires: bool,
    /// The plain fit's ratio, for the report.
    pub plain_ratio: f64,
    /// The restricted fit and its options: where the vocabulary is tried when the check fires
    /// (an effect must explain what the unreported joints absorbed, with them at Table 4).
    pub fit: LiftFit,
    pub opts: LiftFitOptions,
    /// The model the refit held the unreported joints in: `None` when at Table 4 (the model's
    /// own values), else at a fleet prior's means (`LiftFitOptions::friction_prior`).
    pub model: Option<LiftModel>,
}

impl Absorption {
    /// Did the check fire?
    pub fn fired(&self) -> bool {
        self.ratio >= ABSORBED_RATIO
            || self.phase_fires
                && self
                    .worst_phase
                    .is_some_and(|(_, r)| r >= judge::PHASE_FIRE_RATIO)
    }

    /// The contract's view.
    pub fn to_result(&self) -> AbsorptionCheck {
        AbsorptionCheck {
            check: CHECK_NAME.into(),
            fired: self.fired(),
            ratio: self.ratio,
            threshold: ABSORBED_RATIO,
            plain_ratio: self.plain_ratio,
            free: self
                .free
                .iter()
                .map(|p| format!("{} {}", p.joint(), p.kind()))
                .collect(),
            worst_phase: self.worst_phase.map(|(p, _)| p.to_string()),
            worst_phase_ratio: self.worst_phase.map(|(_, r)| r),
            phase_threshold: self.phase_fires.then_some(judge::PHASE_FIRE_RATIO),
        }
    }

    /// Why the joints are withheld, in words (when it fired and nothing was named).
    pub fn reason(&self) -> String {
        format!(
            "refitted with only the reported parameters free ({}; the others at their prior means), the \
             lift leaves {:.1}× the sensor noise in H (RMS {:.2} mm against {:.2} mm; the plain \
             fit {:.1}×{}): the fit reached the noise by moving joints it does not report — an \
             effect the model lacks, or a drift of an unreported joint, that no named effect \
             explains. Joint statuses from this fit are not trustworthy and raise no alert",
            self.free
                .iter()
                .map(|p| format!("{} {}", p.joint(), p.kind()))
                .collect::<Vec<_>>()
                .join(", "),
            self.ratio,
            self.rms_m * 1e3,
            self.noise_m * 1e3,
            self.plain_ratio,
            self.worst_phase
                .map(|(p, r)| format!("; {r:.1}× in its worst phase, {p}"))
                .unwrap_or_default(),
        )
    }
}

/// The friction parameters `fit` reports: the members of its informed combinations and the
/// separately informed parameters, in the fit's order.
pub fn reported_params(fit: &LiftFit) -> Vec<LiftParam> {
    fit.params
        .iter()
        .filter(|p| {
            p.informed
                || p.combination
                    .and_then(|c| fit.combinations.get(c))
                    .is_some_and(|c| c.informed)
        })
        .map(|p| p.param)
        .collect()
}

/// `opts` with only `free` of the friction parameters fitted (no effect), started from `fit`'s
/// values of them and of the torque offsets: the refits that ask what a lift needs free.
fn restricted_options(
    fit: &LiftFit,
    free: Vec<LiftParam>,
    opts: &LiftFitOptions,
) -> LiftFitOptions {
    let start: Vec<f64> = fit
        .params
        .iter()
        .filter(|p| free.contains(&p.param))
        .map(|p| p.map_value / p.baseline)
        .chain(fit.offsets.iter().map(|o| o.map_value))
        .collect();
    LiftFitOptions {
        friction_params: free,
        effect_params: Vec::new(),
        start: Some(start),
        ..opts.clone()
    }
}

/// Refit `trace` (whose plain fit with `opts` is `plain`) with only the reported parameters
/// free and judge its residual. `None` where the plain fit reports nothing (then there is no
/// level to protect) or the refit cannot run (the plain verdict stands).
pub fn reported_only(
    model: &LiftModel,
    trace: &LiftTrace,
    plain: &LiftFit,
    opts: &LiftFitOptions,
    plain_ratio: f64,
) -> Result<Option<Absorption>, LiftFitError> {
    let free = reported_params(plain);
    if free.is_empty() {
        return Ok(None);
    }
    let restricted = restricted_options(plain, free.clone(), opts);
    // The unreported joints held at their prior means: Table 4, or the fleet's
    // (`LiftFitOptions::friction_prior`, issue 37), on a copy of the model.
    let held_model = held_at_prior(model, &free, opts);
    let held = held_model.as_ref().unwrap_or(model);
    let judged = |o: &LiftFitOptions| -> Result<Option<Absorption>, LiftFitError> {
        let fit = match fit_map(held, std::slice::from_ref(trace), o) {
            Ok(f) => f,
            Err(LiftFitError::Failed(_) | LiftFitError::Sim(_)) => return Ok(None),
            Err(e) => return Err(e),
        };
        Ok(
            judge_refit(trace, fit, &free, opts, plain_ratio).map(|a| Absorption {
                opts: LiftFitOptions {
                    start: None,
                    ..restricted.clone()
                },
                model: held_model.clone(),
                ..a
            }),
        )
    };
    let warm = judged(&restricted)?;
    // The warm start assumes the plain fit's reported values lie in the restricted fit's basin
    // (module doc). Where the refit from there fires the check, that assumption is tested: a
    // second refit from the plain fit's own start (the reported parameters at their prior
    // means, the torque offset 0, the horizon continuation `identify::fit_map` runs from a
    // start far from the data), the one leaving less kept — the check asks what the restricted
    // model can reach, not where one start stopped. Measured (`examples/lift_loop_probe design
    // 2 400 1 delay:20`): the plain fit had J1 dry at its bound 0 and J3 at 0.63 (its other
    // joints absorbing the delay); with those at Table 4 that start is far off the data, and
    // the warm refit ended at 454 mm RMS (407× the noise, J1 3.4, J3 0) where the cold one
    // reached 3.36 mm (3.4×, J1 0, J3 1.14). Only where it fires: below the check a stuck
    // refit can only have said too much, never too little, and clean lifts keep their cost.
    if !warm.as_ref().is_some_and(Absorption::fired) {
        return Ok(warm);
    }
    let cold = judged(&LiftFitOptions {
        start: None,
        ..restricted.clone()
    })?;
    Ok(match (warm, cold) {
        (Some(w), Some(c)) => Some(if c.rms_m < w.rms_m { c } else { w }),
        (w, c) => w.or(c),
    })
}

/// The reported-only refit `fit` of `trace` judged (its residual's ratio to the noise and its
/// worst phase); `None` where it has no fitted H or no finite ratio. Its `opts` and `model` are
/// the caller's to set (here left at the defaults of `fit`'s).
fn judge_refit(
    trace: &LiftTrace,
    fit: LiftFit,
    free: &[LiftParam],
    opts: &LiftFitOptions,
    plain_ratio: f64,
) -> Option<Absorption> {
    let fitted = fit.fitted_height_m.first()?;
    let residual: Vec<f64> = trace
        .strip_height_m
        .iter()
        .zip(fitted)
        .map(|(m, f)| m - f)
        .collect();
    let diag = super::residual::diagnose(
        trace.inputs.t_s,
        &residual,
        fitted,
        trace.inputs.torque_nm,
        opts.h_noise_m.max(super::residual::GATE_FLOOR_M),
    );
    if !diag.excess_ratio.is_finite() {
        return None;
    }
    let worst_phase = judge::by_phase(
        trace.inputs.t_s,
        trace.strip_height_m,
        fitted,
        opts.h_noise_m.max(super::residual::GATE_FLOOR_M),
    )
    .into_iter()
    .max_by(|a, b| a.1.total_cmp(&b.1));
    Some(Absorption {
        free: free.to_vec(),
        rms_m: diag.rms_m,
        noise_m: diag.rms_m / diag.excess_ratio,
        ratio: diag.excess_ratio,
        worst_phase,
        phase_fires: !judge::lowers(trace.inputs.t_s, fitted),
        plain_ratio,
        fit,
        opts: opts.clone(),
        model: None,
    })
}

/// `model` with every friction parameter of `opts` not in `free` at its prior mean where that
/// is not Table 4 (a fleet prior, `LiftFitOptions::friction_prior`); `None` when none is.
fn held_at_prior(
    model: &LiftModel,
    free: &[LiftParam],
    opts: &LiftFitOptions,
) -> Option<LiftModel> {
    let moved: Vec<(LiftParam, f64)> = opts
        .friction_prior
        .iter()
        .filter(|(p, m, _)| !free.contains(p) && opts.friction_params.contains(p) && *m != 1.0)
        .map(|&(p, m, _)| (p, m))
        .collect();
    if moved.is_empty() {
        return None;
    }
    let mut m = model.clone();
    let mut unused = 0.0;
    for (p, ratio) in moved {
        let v = p.get(model, 0.0) * ratio;
        p.set(&mut m, &mut unused, v);
    }
    Some(m)
}

/// The fit a named effect is reported from: the effect held at the value the search found
/// (with the unreported joints at Table 4), every friction parameter of `full` (the plain
/// fit's options) free again, started at the search's fit. Held fixed because, free with
/// every joint, it trades off with them again (measured: a 20 ms delay on the paper's raise,
/// refitted with both free, put the J1+J3 level at 0.55 [0.40, 0.77] of its truth 1); the
/// reported levels' intervals then carry the unreported joints' uncertainty, which the search's
/// fit with them held leaves out (a J1+J3 level read ±0.5 %). Read-out effects are held by
/// correcting the record (an H offset subtracted, a delay advanced: `effects::advance`); the
/// model's effects (drag, Stribeck, a compliant drive) by setting them on a copy of `model`.
/// Returns that model, the record's H as fitted, the fit and its options; `None` where the fit
/// fails (the search's fit stands).
#[allow(clippy::type_complexity)]
pub fn fixed_effect_refit(
    model: &LiftModel,
    trace: &LiftTrace,
    found: &LiftFit,
    found_opts: &LiftFitOptions,
    full: &LiftFitOptions,
) -> Result<Option<(LiftModel, Vec<f64>, LiftFit, LiftFitOptions)>, LiftFitError> {
    let mut m = model.clone();
    let mut h = trace.strip_height_m.to_vec();
    let mut unused = 0.0;
    for e in &found.effects {
        match e.param {
            LiftParam::SensorOffset => h.iter_mut().for_each(|v| *v -= e.value),
            LiftParam::SensorDelay => h = super::effects::advance(trace.inputs.t_s, &h, e.value),
            p => p.set(&mut m, &mut unused, e.value),
        }
    }
    // Started where the search's fit ended (its reported values, every other joint at its
    // prior mean — Table 4 or the fleet's — as the search held it: a point already at the noise). From the plain fit's MAP — the basin where the joints had
    // absorbed the effect — a 20 ms delay's refit stayed at 3–5× the noise.
    let start: Vec<f64> = full
        .friction_params
        .iter()
        .map(|p| {
            found
                .params
                .iter()
                .find(|q| q.param == *p)
                .map_or(full.prior_of(*p).0, |q| q.map_value / q.baseline)
        })
        .chain(found.offsets.iter().map(|o| o.map_value))
        .collect();
    let opts = LiftFitOptions {
        friction_params: full.friction_params.clone(),
        effect_params: Vec::new(),
        start: Some(start),
        ..found_opts.clone()
    };
    let corrected = LiftTrace {
        inputs: trace.inputs,
        strip_height_m: &h,
    };
    match fit_map(&m, std::slice::from_ref(&corrected), &opts) {
        Ok(f) => Ok(Some((
            m,
            h,
            f,
            LiftFitOptions {
                start: None,
                ..opts
            },
        ))),
        Err(LiftFitError::Failed(_) | LiftFitError::Sim(_)) => Ok(None),
        Err(e) => Err(e),
    }
}

pub mod judge;

#[cfg(test)]
mod tests;

//! Joint friction from lift traces: each trace's Fisher information (what it can tell apart),
//! a maximum-a-posteriori fit with Table 4 as a Gaussian prior, and which joints it informed.
//!
//! A joint's friction enters a lift through its rate ratio and its reaction force, so the dry
//! coefficients move H almost alike: the data pin a combination, the prior holds the rest.
//! Prior (stated): every friction coefficient ~ N(baseline, (0.5·baseline)²), the torque-sensor
//! offset of each trace ~ N(0, (10 N·m)²). A parameter is *informed* when its posterior sd is
//! below its prior sd / 2; an uninformed one is reported at baseline, not identified, and is
//! never flagged. H noise: stated σ_H (1 mm), inflated to the residual RMS if the fit is worse.

use std::cell::RefCell;

use nalgebra::DMatrix;

use super::attribution::AtTable4;
pub use super::attribution::Shown;
use super::dynamics::LiftModel;
pub use super::fit::{
    EffectEstimate, EffectPrior, Identifiability, JointEstimate, LiftFit, LiftFitError,
    LiftFitOptions, LiftTrace, POOLED_INTERVAL_SCALE, POOLED_PER_TRACE, ParamEstimate, PooledGauge,
    effect_prior,
};
use super::inputs::{InputReconstruction, reconstruct_cached};
// Re-exported for the fits that took it from here (`design`, `quadrangle::identify`).
pub(crate) use super::posterior::inverse_spd;
use super::posterior::{correlation, pinv};
use super::sensitivity::{
    LiftParam, SensWorkspace, simulate_sensitivities, simulate_sensitivities_in,
};
use super::simulate::{LiftInputs, SimOptions};
use super::topology::RevJoint;
use crate::contract::drift::Status;
use crate::joint::identify::lm::{
    LmOptions, Problem, Termination, minimize, minimize_evaluated, project,
};
use crate::numerics::stats::Z95;

/// Most integrator steps per second of trace an evaluation may take (`fit_map_in`).
const MAX_STEPS_PER_S: f64 = 1000.0;

/// Upper bound of a friction coefficient as a multiple of its baseline.
const MAX_MULTIPLE: f64 = 10.0;

/// Forward-difference step of a pooled gauge record's Jacobian, in units of Table 4 (the gauge
/// fit's, `lift::gauge::terms::FD_STEP`).
const GAUGE_FD_STEP: f64 = super::gauge::terms::FD_STEP;

/// The prior of a pooled gauge record's zero: the gauge fit's (`gauge::terms::GaugeEffect::prior`).
const GAUGE_ZERO_PRIOR: EffectPrior = super::gauge::terms::SENSOR_OFFSET_PRIOR;

/// Friction parameters in scaled units: x = θ/θ₀.
fn baseline_of(model: &LiftModel, params: &[LiftParam]) -> Result<Vec<f64>, LiftFitError> {
    params
        .iter()
        .map(|p| {
            let v = p.get(model, 0.0);
            if *p == LiftParam::TorqueOffset {
                Err(LiftFitError::Invalid(
                    "the offset is a per-trace nuisance, not a friction parameter".into(),
                ))
            } else if v > 0.0 && v.is_finite() {
                Ok(v)
            } else {
                Err(LiftFitError::Invalid(format!(
                    "{}.{} baseline {v} must be > 0 to scale its prior",
                    p.joint(),
                    p.kind()
                )))
            }
        })
        .collect()
}

mod problem;
mod work;
use problem::MapProblem;
pub(crate) use work::count_on_this_thread;
use work::count_work;
pub use work::{FitWork, join, work_on_this_thread};

/// Check a trace's channels.
fn check(traces: &[LiftTrace]) -> Result<usize, LiftFitError> {
    if traces.is_empty() {
        return Err(LiftFitError::Invalid("no trace".into()));
    }
    let mut n = 0;
    for (i, t) in traces.iter().enumerate() {
        t.inputs.validate()?;
        if t.strip_height_m.len() != t.inputs.t_s.len() {
            return Err(LiftFitError::Invalid(format!(
                "trace {i}: `H_m` has {} samples, `t_s` {}",
                t.strip_height_m.len(),
                t.inputs.t_s.len()
            )));
        }
        if let Some(k) = t.strip_height_m.iter().position(|v| !v.is_finite()) {
            return Err(LiftFitError::Invalid(format!(
                "trace {i}: `H_m`[{k}] is not finite"
            )));
        }
        n += t.strip_height_m.len();
    }
    Ok(n)
}

/// End indices of the continuation stages: where each trace's measured H first reaches 10, 30,
/// 60 and 90 % of its largest excursion from its starting level (the model's drift from the
/// data grows with the motion, not with time). Traces that hardly move (excursion under
/// 20 σ_H) are fitted whole from the start.
fn horizon_schedule(traces: &[LiftTrace], h_noise_m: f64) -> Vec<Vec<usize>> {
    let mut stages = Vec::new();
    for frac in [0.1, 0.3, 0.6, 0.9] {
        let mut ends = Vec::with_capacity(traces.len());
        for t in traces {
            let h = t.strip_height_m;
            let n0 = h.len().min(10);
            let h0 = h[..n0].iter().sum::<f64>() / n0 as f64;
            let excursion = h.iter().map(|v| (v - h0).abs()).fold(0.0, f64::max);
            if excursion < 20.0 * h_noise_m {
                return Vec::new();
            }
            let k = h
                .iter()
                .position(|v| (v - h0).abs() >= frac * excursion)
                .unwrap_or(h.len());
            ends.push(k.max(2));
        }
        if ends
            .iter()
            .zip(traces)
            .all(|(e, t)| *e < t.strip_height_m.len())
        {
            stages.push(ends);
        }
    }
    stages
}

/// Continuation in time after `last` (the excursion's last stage, or the start): each trace
/// cut at a quarter, half and three quarters of what remains ([`fit_map_in`]'s fallback).
fn time_schedule(traces: &[LiftTrace], last: Option<&Vec<usize>>) -> Vec<Vec<usize>> {
    (1..4)
        .map(|k| {
            traces
                .iter()
                .enumerate()
                .map(|(i, t)| {
                    let (from, n) = (last.map_or(2, |l| l[i]), t.strip_height_m.len());
                    (from + (n - from.min(n)) * k / 4).max(2)
                })
                .collect()
        })
        .collect()
}

/// One trace's ∂H/∂x over σ_H at the model's parameters, n × p, with x in the fit's scaled
/// units (friction relative to its baseline, then the torque offset in N·m): the rows of the
/// fit's Jacobian a design computes from the inputs alone.
pub fn scaled_jacobian(
    model: &LiftModel,
    inputs: &LiftInputs,
    opts: &LiftFitOptions,
) -> Result<(Vec<LiftParam>, DMatrix<f64>), LiftFitError> {
    let baseline = baseline_of(model, &opts.friction_params)?;
    let mut params = opts.friction_params.clone();
    params.push(LiftParam::TorqueOffset);
    let run = simulate_sensitivities(model, inputs, &params, 0.0, &opts.sim)?;
    let p = params.len();
    let n = inputs.t_s.len();
    let scale = |i: usize| if i < baseline.len() { baseline[i] } else { 1.0 };
    let jd = DMatrix::from_fn(n, p, |k, i| {
        run.d_height[k * p + i] * scale(i) / opts.h_noise_m
    });
    Ok((params, jd))
}

/// The Fisher information of one trace at the model's parameters (a design question: it needs
/// the trace's inputs only; its H is not used).
pub fn identifiability(
    model: &LiftModel,
    inputs: &LiftInputs,
    opts: &LiftFitOptions,
) -> Result<Identifiability, LiftFitError> {
    let (params, jd) = scaled_jacobian(model, inputs, opts)?;
    let p = params.len();
    let n_fric = p - 1;
    let fisher = jd.tr_mul(&jd);
    let prior_sd = |i: usize| {
        if i < n_fric {
            opts.prior_of(params[i]).1
        } else {
            opts.offset_prior_sd_nm
        }
    };
    let mut post = fisher.clone();
    for i in 0..p {
        post[(i, i)] += 1.0 / prior_sd(i).powi(2);
    }
    let post_cov = inverse_spd(&post);
    let posterior_sd: Vec<f64> = (0..p).map(|i| post_cov[(i, i)].max(0.0).sqrt()).collect();
    Ok(Identifiability {
        sd_alone: (0..p)
            .map(|i| {
                if fisher[(i, i)] > 0.0 {
                    1.0 / fisher[(i, i)].sqrt()
                } else {
                    f64::INFINITY
                }
            })
            .collect(),
        data_correlation: correlation(&pinv(&fisher)),
        informed: (0..p)
            .map(|i| posterior_sd[i] < prior_sd(i) / opts.informed_factor)
            .collect(),
        posterior_sd,
        params,
        fisher,
    })
}

thread_local! {
    /// This thread's buffers for lift fits ([`fit_map`]): the worker pool's threads, the batch
    /// threads and the CLI each reuse theirs from one fit to the next (issue 8).
    static WORKSPACE: RefCell<SensWorkspace> = RefCell::default();
}

/// The most a thread keeps between fits: a workspace grown past it (a trace far longer than a
/// lift test's ~8 s at 500 Hz, which needs ~0.6 MB) is given back after its fit.
const KEEP_BYTES: usize = 64 << 20;

/// MAP fit of one or more lift traces of one pantograph (friction shared, one torque offset
/// per trace), from the model's current parameters. Runs on this thread's reused buffers;
/// [`fit_map_in`] takes them explicitly and gives the same result bit for bit.
pub fn fit_map(
    model: &LiftModel,
    traces: &[LiftTrace],
    opts: &LiftFitOptions,
) -> Result<LiftFit, LiftFitError> {
    WORKSPACE.with(|cell| match cell.try_borrow_mut() {
        Ok(mut ws) => {
            let fit = fit_map_in(&mut ws, model, traces, opts);
            if ws.capacity_bytes() > KEEP_BYTES {
                *ws = SensWorkspace::default();
            }
            fit
        }
        // Only if a fit were started from inside another on this thread: buffers of its own.
        Err(_) => fit_map_in(&mut SensWorkspace::default(), model, traces, opts),
    })
}

/// [`fit_map`] on the buffers of `ws`: its evaluations allocate no simulation buffers once
/// `ws` has held a trace as long (what allocates per fit is the LM's Jacobian and the result).
pub fn fit_map_in(
    ws: &mut SensWorkspace,
    model: &LiftModel,
    traces: &[LiftTrace],
    opts: &LiftFitOptions,
) -> Result<LiftFit, LiftFitError> {
    let n_data = check(traces)?;
    // Every fit runs on reconstructed inputs: sensor noise on T/Fs/Fm would otherwise drive the
    // integrator's step control (issue 15; `lift::inputs` states the assumptions).
    let rebuilt = traces
        .iter()
        .map(|t| reconstruct_cached(&t.inputs, &opts.inputs))
        .collect::<Result<Vec<_>, _>>()?;
    let traces: Vec<LiftTrace> = traces
        .iter()
        .zip(&rebuilt)
        .map(|(t, r)| LiftTrace {
            inputs: r.inputs(),
            strip_height_m: t.strip_height_m,
        })
        .collect();
    let traces = &traces[..];
    // A trial whose run needs over 1000 integrator steps per second of trace is in a stiff
    // corner of the parameters (a raise and lower takes ~90/s, noisy inputs reconstructed or
    // not): it fails and the LM rejects it, instead of one trial costing ~500 evaluations
    // (measured: 58 s → 1.4 s on a 2×-noise trace, same estimates; `examples/lift_inputs_probe`).
    let longest_s = traces
        .iter()
        .map(|t| t.inputs.t_s[t.inputs.t_s.len() - 1] - t.inputs.t_s[0])
        .fold(0.0, f64::max);
    let capped = LiftFitOptions {
        sim: SimOptions {
            max_steps: opts
                .sim
                .max_steps
                .min((MAX_STEPS_PER_S * longest_s) as usize + 1000),
            ..opts.sim
        },
        ..opts.clone()
    };
    let opts = &capped;
    let fric = &opts.friction_params;
    let baseline = baseline_of(model, fric)?;
    let pf = fric.len();
    let effect_priors = opts
        .effect_params
        .iter()
        .map(|p| {
            effect_prior(*p).ok_or_else(|| {
                LiftFitError::Invalid(format!("{}.{} is not a lift effect", p.joint(), p.kind()))
            })
        })
        .collect::<Result<Vec<_>, _>>()?;
    if !effect_priors.is_empty() && opts.input_noise_draws > 0 {
        return Err(LiftFitError::Invalid(
            "input-noise draws are not propagated through effect parameters".into(),
        ));
    }
    if !opts.per_trace.is_empty() && opts.input_noise_draws > 0 {
        return Err(LiftFitError::Invalid(
            "input-noise draws are not propagated through per-trace deviations".into(),
        ));
    }
    if !opts.gauge_records.is_empty() && opts.input_noise_draws > 0 {
        return Err(LiftFitError::Invalid(
            "input-noise draws are not propagated through pooled gauge records".into(),
        ));
    }
    let ne = effect_priors.len();
    let mut with_offset = fric.clone();
    with_offset.push(LiftParam::TorqueOffset);
    // Output effects (the H delay) are applied to the read-out, not simulated.
    with_offset.extend(
        opts.effect_params
            .iter()
            .copied()
            .filter(|p| !p.is_output()),
    );
    let gauge_warm = opts
        .gauge_records
        .iter()
        .map(|g| {
            super::gauge::solve::warm_starts(model, model.alpha_range_rad, &g.drive, &g.record)
        })
        .collect::<Result<Vec<_>, _>>()
        .map_err(|e| LiftFitError::Invalid(format!("pooled gauge record: {e}")))?;
    let n_gauge: usize = opts.gauge_records.iter().map(|g| g.record.len()).sum();
    let per_trace_ix = opts
        .per_trace
        .iter()
        .map(|(p, tau)| {
            fric.iter()
                .position(|f| f == p)
                .filter(|_| *tau > 0.0 && tau.is_finite())
                .ok_or_else(|| {
                    LiftFitError::Invalid(format!(
                        "per-trace {}.{} is not a fitted friction parameter with τ > 0",
                        p.joint(),
                        p.kind()
                    ))
                })
        })
        .collect::<Result<Vec<_>, _>>()?;
    let mut problem = MapProblem {
        per_trace_ix: &per_trace_ix,
        ws,
        base: model,
        traces,
        fric,
        baseline: &baseline,
        opts,
        with_offset,
        effect_priors: &effect_priors,
        n_data,
        gauge_warm: &gauge_warm,
        n_gauge,
    };
    let mut x = vec![1.0; pf];
    x.extend(std::iter::repeat_n(0.0, traces.len()));
    // Effects start at the model's values (0 in the paper's model), within their bounds.
    x.extend(
        opts.effect_params
            .iter()
            .zip(&effect_priors)
            .map(|(p, pr)| p.get(model, 0.0).clamp(pr.lower, pr.upper)),
    );
    // Each pooled gauge record's zero starts at 0, each trace's deviations too.
    x.extend(opts.gauge_records.iter().map(|_| 0.0));
    x.extend(std::iter::repeat_n(0.0, traces.len() * per_trace_ix.len()));
    // Continuation in the horizon: driven open-loop by the recorded torque, a lift drifts away
    // from the data with the smallest friction error (the net stiffness is nearly zero), so
    // output error over the whole trace is far from quadratic around the baseline (J3 ×1.8
    // seen from ×1: H off by 0.3–1 m, with a bump in between). Over the first part of the
    // motion it is nearly linear; each longer stretch starts from the last one's estimate.
    // A trace the starting model already follows (H RMS within 5 σ_H: a joint near its
    // baseline) needs no continuation: the whole-trace problem is already nearly quadratic.
    // The whole-trace evaluation at the start tells, and is the LM's first when it is close.
    let warm = opts
        .start
        .as_ref()
        .filter(|s| s.len() == x.len() && s.iter().all(|v| v.is_finite()));
    if let Some(s) = warm {
        x.clone_from(s);
    }
    let x0 = project(&problem, &x);
    let mut r0 = vec![0.0; problem.n_residuals()];
    let mut jac0 = DMatrix::zeros(problem.n_residuals(), problem.n_params());
    let start = problem.eval(&x0, &mut r0, &mut jac0).is_ok().then(|| {
        let mut row = 0;
        traces.iter().all(|t| {
            let n = t.strip_height_m.len();
            let ss: f64 = r0[row..row + n].iter().map(|v| v * v).sum();
            row += n;
            // r = (H_model − H)/σ_H: the RMS in units of σ_H.
            (ss / n as f64).sqrt() < 5.0
        })
    });
    let close = start == Some(true) || (warm.is_some() && start.is_some());
    // The data's information at Table 4 (the first evaluation, when it ran): what the test
    // informs at the prior's mean, which `lift::attribution` also asks of an estimate.
    let info_table4 = (warm.is_none() && start.is_some()).then(|| {
        let j0 = jac0.rows(0, n_data + n_gauge);
        j0.tr_mul(&j0)
    });
    let schedule = if close {
        Vec::new()
    } else {
        horizon_schedule(traces, opts.h_noise_m)
    };
    // Evaluations, iterations, rejected trials and cliffs of the stages.
    let mut spent = [0usize; 4];
    let stages = |problem: &mut MapProblem,
                  schedule: &[Vec<usize>],
                  x: &mut Vec<f64>,
                  spent: &mut [usize; 4]| {
        for ends in schedule {
            let rep = problem.stage(ends, x);
            let add = [rep.evaluations, rep.iterations, rep.rejected, rep.cliffs];
            spent.iter_mut().zip(add).for_each(|(s, a)| *s += a);
            if let Termination::EvaluationFailed(e) = &rep.termination {
                return Err(LiftFitError::Failed(e.clone()));
            }
            *x = rep.x;
        }
        Ok(())
    };
    stages(&mut problem, &schedule, &mut x, &mut spent)?;
    let mut rep = if close {
        minimize_evaluated(&mut problem, x0, r0, jac0, &opts.lm)
    } else {
        // The start's evaluation was spent on the check.
        spent[0] += 1;
        minimize(&mut problem, &x, &opts.lm)
    };
    // The excursion's stages end within the raise. Where the record goes on to further moves
    // (a protocol of several, `lift::design::rounds_of_moves`), their estimate can drive the
    // whole record into a stiff stop the integrator cannot pass; continue in time from there
    // instead. Measured on 18 lifts of 2–6 rounds (docs/VALIDATION.md, "Long protocols fit"): 11 failed
    // before, none after. Only a fit that could not start takes this path. Not for a fit that
    // ran but stopped far from its data (3 of those 18, 40–78 mm: withheld as `unexplained`):
    // refitted in time they came within the noise, but one then flagged a viscous combination
    // on an unworn pantograph (`watch`), which a withheld fit cannot.
    if matches!(rep.termination, Termination::EvaluationFailed(_)) && !close {
        spent[0] += rep.evaluations;
        let more = time_schedule(traces, schedule.last());
        stages(&mut problem, &more, &mut x, &mut spent)?;
        rep = minimize(&mut problem, &x, &opts.lm);
    }
    if let Termination::EvaluationFailed(e) = &rep.termination {
        return Err(LiftFitError::Failed(e.clone()));
    }
    rep.evaluations += spent[0];
    rep.iterations += spent[1];
    (rep.rejected, rep.cliffs) = (rep.rejected + spent[2], rep.cliffs + spent[3]);
    let e0 = pf + traces.len();
    let z0 = e0 + ne;
    let u0 = z0 + opts.gauge_records.len();
    let p = u0 + traces.len() * per_trace_ix.len();
    // Noise scale: the stated σ_H, or the residual RMS if the fit is worse than that.
    let ssr: f64 = rep.residuals[..n_data].iter().map(|v| v * v).sum();
    let kappa2 = (ssr / n_data as f64).max(1.0);
    let jd = rep.jacobian.rows(0, n_data);
    // The data's information, corrected for what the H residual carries besides white H noise
    // (issue 15): the sensors' noise on the inputs (T, Fs, Fm), smoothed but not removed by
    // `lift::inputs`, drives the model open-loop, so its effect on H is slow and correlated and
    // JᵀJ/σ² overstates what the trace tells. The sandwich Cov_d = A⁺ S A⁺ (A = JᵀJ, S the
    // long-run covariance of the scores by overlapping batch means: `identify::covariance`)
    // is the data-only estimate's covariance under that residual; its pseudo-inverse is the
    // information the data actually hold, to which the prior's is added. White residuals give
    // back JᵀJ/s² (up to sampling noise).
    let mut post = if opts.robust_covariance {
        let c = crate::joint::identify::covariance::sandwich(
            &jd.into_owned(),
            &rep.residuals[..n_data],
        );
        pinv(&c.cov)
    } else {
        jd.tr_mul(&jd) / kappa2
    };
    // Pooled gauge records: their information, at their own noise scale (the residual RMS over
    // σ_g where the fit is worse than that, as κ² for H).
    if n_gauge > 0 {
        let jg = rep.jacobian.rows(n_data, n_gauge);
        let ssr_g: f64 = rep.residuals[n_data..n_data + n_gauge]
            .iter()
            .map(|v| v * v)
            .sum();
        let kappa2_g = (ssr_g / n_gauge as f64).max(1.0);
        post += jg.tr_mul(&jg) / kappa2_g;
    }
    let prior_sd = |i: usize| {
        if i < pf {
            opts.prior_of(fric[i]).1
        } else if i < e0 {
            opts.offset_prior_sd_nm
        } else if i < z0 {
            effect_priors[i - e0].sd
        } else if i < u0 {
            GAUGE_ZERO_PRIOR.sd
        } else {
            opts.per_trace[(i - u0) % per_trace_ix.len()].1
        }
    };
    for i in 0..p {
        post[(i, i)] += 1.0 / prior_sd(i).powi(2);
    }
    let mut cov = inverse_spd(&post);
    if opts.interval_scale > 1.0 {
        cov *= opts.interval_scale * opts.interval_scale;
    }
    // H noise only: the directions the data pin (`lift::attribution`).
    let cov_h = cov.clone();
    // Per-parameter widening measured for this kind of fit (`param_interval_scale`, ≥ 1): the
    // intervals and the contraction test read it; the directions the data pin do not.
    for (q, s) in &opts.param_interval_scale {
        if let Some(i) = fric.iter().position(|f| f == q) {
            let s = s.max(1.0);
            for j in 0..p {
                cov[(i, j)] *= s;
                cov[(j, i)] *= s;
            }
        }
    }
    let cov_table4 = info_table4.map(|mut a| {
        for i in 0..p {
            a[(i, i)] += 1.0 / prior_sd(i).powi(2);
        }
        inverse_spd(&a) * opts.interval_scale.max(1.0).powi(2)
    });
    if opts.input_noise_draws > 0 {
        let at = problem.model_at(&rep.x);
        let jd = rep.jacobian.rows(0, n_data).into_owned();
        let offsets = &rep.x[pf..];
        let infos: Vec<InputReconstruction> = rebuilt.iter().map(|r| r.info).collect();
        cov +=
            super::input_noise::covariance(&at, traces, &infos, offsets, &jd, &cov, kappa2, opts)?;
    }
    let cov = cov;
    // Contraction alone is not identification: parameters the posterior ties together are
    // reported as their combination (`lift::attribution`, issue 15 point 2).
    // Contracted both on θ and on ln θ (the intervals are log-normal): sd < prior sd / factor
    // in baseline units and relative to the estimate. An estimate pushed near zero with an
    // absolute sd that looks small is not informed (measured: J8 dry at 0.02× baseline read as
    // "alarm" from a J1 drift), nor one pushed to several times its baseline with a relative
    // sd that looks small (J4 dry at 4× from input noise, truth 1×).
    let contracted: Vec<bool> = (0..pf)
        .map(|i| {
            let sd = cov[(i, i)].max(0.0).sqrt();
            // A coefficient each trace has its own deviation of (`per_trace`) absorbs what
            // each trace's input noise did: its shared level is no wear reading (measured, J8
            // ×1.8 pools read 1.22–1.43 with intervals below 1.8: docs/VALIDATION.md, "Pooled lifts").
            !per_trace_ix.contains(&i)
                && sd < prior_sd(i) / opts.informed_factor * rep.x[i].min(1.0)
        })
        .collect();
    let attribution = super::attribution::attribute(
        fric,
        &rep.x[..pf],
        &cov_h,
        match (&cov_table4, warm) {
            (Some(c), _) => AtTable4::Posterior(c),
            (None, None) => AtTable4::RunFailed,
            (None, Some(_)) => AtTable4::NotEvaluated,
        },
        &cov,
        &contracted,
        &vec![opts.prior_relative_sd; pf],
        opts.informed_factor,
        &opts.thresholds,
        &opts.attribution,
    );
    let estimate = |i: usize, param: LiftParam, base: f64| -> ParamEstimate {
        let sd_x = cov[(i, i)].max(0.0).sqrt();
        let informed = if i < pf {
            attribution.separate[i]
        } else {
            sd_x < prior_sd(i) / opts.informed_factor
        };
        let (map_value, posterior_sd, prior) = (rep.x[i] * base, sd_x * base, prior_sd(i) * base);
        let (value, ci95, status) = if informed {
            // A friction coefficient is positive: its interval is the log-normal one with the
            // same median and relative sd (delta method on ln θ), so it never reaches below 0
            // (issue 15); the offset, a signed quantity, keeps the symmetric one.
            let ci = if param == LiftParam::TorqueOffset || map_value <= 0.0 {
                [
                    map_value - Z95 * posterior_sd,
                    map_value + Z95 * posterior_sd,
                ]
            } else {
                let rel = posterior_sd / map_value;
                [
                    map_value * (-Z95 * rel).exp(),
                    map_value * (Z95 * rel).exp(),
                ]
            };
            let status = if param == LiftParam::TorqueOffset {
                Status::Unknown
            } else {
                let v = opts.thresholds.judge(ci, map_value, Some(base));
                if v.identifiable {
                    v.status
                } else {
                    Status::Unknown
                }
            };
            (map_value, ci, status)
        } else {
            // The prior's interval, log-normal for a coefficient likewise, about the prior's
            // mean (Table 4, or the fleet's: `LiftFitOptions::friction_prior`).
            let centre = if i < pf {
                opts.prior_of(param).0 * base
            } else {
                base
            };
            let (lo, hi) = if param == LiftParam::TorqueOffset {
                (-Z95 * prior, Z95 * prior)
            } else {
                let rel = prior / centre;
                (centre * (-Z95 * rel).exp(), centre * (Z95 * rel).exp())
            };
            let b = if param == LiftParam::TorqueOffset {
                0.0
            } else {
                centre
            };
            (b, [lo, hi], Status::Unknown)
        };
        ParamEstimate {
            param,
            baseline: if param == LiftParam::TorqueOffset {
                0.0
            } else {
                base
            },
            prior_sd: prior,
            value,
            map_value,
            posterior_sd,
            ci95,
            informed,
            status,
            combination: attribution.group.get(i).copied().flatten(),
        }
    };
    let params: Vec<ParamEstimate> = (0..pf).map(|i| estimate(i, fric[i], baseline[i])).collect();
    let offsets = (0..traces.len())
        .map(|t| estimate(pf + t, LiftParam::TorqueOffset, 1.0))
        .collect();
    let effects = opts
        .effect_params
        .iter()
        .zip(&effect_priors)
        .enumerate()
        .map(|(e, (param, pr))| {
            let (value, sd) = (rep.x[e0 + e], cov[(e0 + e, e0 + e)].max(0.0).sqrt());
            EffectEstimate {
                param: *param,
                value,
                posterior_sd: sd,
                ci95: [
                    (value - Z95 * sd).max(pr.lower),
                    (value + Z95 * sd).min(pr.upper),
                ],
            }
        })
        .collect();
    let mut joints = Vec::new();
    let names = RevJoint::ALL.iter().map(|j| j.name()).chain(["J8", "J9"]);
    for name in names {
        let find = |kind: &str| {
            params
                .iter()
                .find(|e| e.param.joint() == name && e.param.kind() == kind)
                .cloned()
        };
        let (viscous, dry) = (find("viscous"), find("dry"));
        let informed: Vec<&ParamEstimate> = [&viscous, &dry]
            .into_iter()
            .flatten()
            .filter(|e| e.informed)
            .collect();
        let status = informed
            .iter()
            .map(|e| e.status)
            .max()
            .unwrap_or(Status::Unknown);
        joints.push(JointEstimate {
            joint: name,
            identifiable: !informed.is_empty(),
            status,
            viscous,
            dry,
        });
    }
    let mut rmse_m = Vec::new();
    let mut fitted_height_m = Vec::new();
    let mut row = 0;
    for t in traces {
        let n = t.strip_height_m.len();
        let r = &rep.residuals[row..row + n];
        let s: f64 = r.iter().map(|v| v * v).sum();
        rmse_m.push((s / n as f64).sqrt() * opts.h_noise_m);
        fitted_height_m.push(
            t.strip_height_m
                .iter()
                .zip(r)
                .map(|(h, r)| h + opts.h_noise_m * r)
                .collect(),
        );
        row += n;
    }
    let gauge_offsets = (0..opts.gauge_records.len())
        .map(|gi| {
            let (i, pr) = (z0 + gi, GAUGE_ZERO_PRIOR);
            let (v, sd) = (rep.x[i], cov[(i, i)].max(0.0).sqrt());
            super::gauge::terms::GaugeEffectEstimate {
                effect: super::gauge::terms::GaugeEffect::SensorOffset,
                value: v,
                posterior_sd: sd,
                ci95: [(v - Z95 * sd).max(pr.lower), (v + Z95 * sd).min(pr.upper)],
            }
        })
        .collect();
    let mut gauge_fitted_n = Vec::new();
    let mut gauge_rmse_n = Vec::new();
    let mut row = n_data;
    for g in &opts.gauge_records {
        let n = g.record.len();
        let sigma = g.sigma_n();
        let r = &rep.residuals[row..row + n];
        gauge_rmse_n.push((r.iter().map(|v| v * v).sum::<f64>() / n as f64).sqrt() * sigma);
        gauge_fitted_n.push(
            g.record
                .forces_n
                .iter()
                .zip(r)
                .map(|(f, r)| f + sigma * r)
                .collect(),
        );
        row += n;
    }
    Ok(LiftFit {
        gauge_fitted_n,
        gauge_rmse_n,
        gauge_offsets,
        params,
        offsets,
        effects,
        joints,
        posterior_correlation: correlation(&cov),
        rmse_m,
        fitted_height_m,
        noise_m: opts.h_noise_m * kappa2.sqrt(),
        iterations: rep.iterations,
        evaluations: rep.evaluations,
        rejected: rep.rejected,
        cliffs: rep.cliffs,
        termination: rep.termination,
        inputs: rebuilt.iter().map(|r| r.info).collect(),
        combinations: attribution.combinations,
    })
}

#[cfg(test)]
mod tests;

/// The LM's noise floor (`LmOptions::noise_sd`) ends a fit only near its minimum.
#[cfg(test)]
mod noise_floor_tests;

#[cfg(test)]
mod pooled_tests;

//! The lift's residual loop: the plain fit judged against the noise, the vocabulary tried on
//! the reported-only model, held-out tests, and the named effect's result or `unexplained`.

use super::super::absorbed::Absorption;
use super::candidates::Found;
use super::*;

/// [`fit_lift_trace`] up to the named effect or `unexplained`.
pub(super) fn residual_loop(
    channels: &LiftChannels,
    thresholds: &DriftThresholds,
    trace_id: &str,
    friction_prior: &[(LiftParam, f64, f64)],
) -> Result<LiftReport, LiftFitError> {
    let model = builtin_model();
    let (trace, mut opts) = lift_trace(channels, thresholds)?;
    opts.friction_prior = friction_prior.to_vec();
    let mut meter = Meter::start();
    let fit = fit_map(model, &[trace], &opts)?;
    meter.mark("plain");
    let fitted_height_m = fit.fitted_height_m.first().cloned().unwrap_or_default();
    let mut result = fit_result(model, &fit, &trace, &fitted_height_m, &opts, trace_id);
    // What the fit had to do (`lift::absorbed`): refitted with only what it reports free.
    let plain_ratio = result.residual.excess_ratio.unwrap_or(f64::NAN);
    let absorption =
        super::super::absorbed::reported_only(model, &trace, &fit, &opts, plain_ratio)?;
    meter.mark("reported_only");
    result.fit.absorption = absorption.as_ref().map(|a| a.to_result());
    let absorbed = absorption.as_ref().filter(|a| a.fired());
    // The effect-free fit that leaves the record closest judges it (session 23). The reported-
    // only refit is nested in the plain fit (the same model, fewer parameters free), so where it
    // leaves less the plain fit stopped short of its optimum, and its excess is the optimiser's,
    // not the record's: the vocabulary is then tried (or not) as that refit calls for — issue
    // 36, point 1: an effect is detectable when the reported-only refit leaves ≥ 2× the noise.
    // Measured (`examples/lift_loop_probe rl 1 400 1 j9stiff:3`): head springs 3× stiffer, plain
    // fit 3.48× (over the gate) while the reported-only refit left 1.09×; the vocabulary, tried
    // with every joint free from the plain fit, named a 7.1 mm `sensor_offset` (outside the
    // vocabulary: a wrong name). And (`rl 2 400 1 delay:20`) a 20 ms delay: plain 6.6×, the
    // reported-only 3.8×; the delay refitted from the plain fit left a phase at 1.35×, not named.
    let plain_rms_m = fit.rmse_m.first().copied().unwrap_or(f64::INFINITY);
    let nested_better = absorption.as_ref().is_some_and(|a| a.rms_m < plain_rms_m);
    let effect_free_ratio = match &absorption {
        Some(a) if nested_better => a.ratio,
        _ => plain_ratio,
    };
    let try_effects =
        absorbed.is_some() || effect_free_ratio > super::super::residual::EFFECT_TRY_RATIO;
    if !try_effects {
        // Nothing to judge: the held-out test is run only where an effect is tried. Measured
        // (`bench suite --only fits,fleet --lift-seeds 12`): run on every lift it doubled the
        // fit (p50 0.124 → 0.257 s at the stand's noise; fleet year 11.9 → 26.6 min).
        result.residual.holdout_note = Some(NO_HOLDOUT_NEEDED.into());
        return Ok(LiftReport {
            result,
            fit,
            fitted_height_m,
            plain_fitted_height_m: None,
            work: meter.steps,
        });
    }
    // The held-out test of the plain model (`lift::holdout`): refit without every fourth
    // 0.5 s block, judged on them.
    // The vocabulary is tried on the model with only the reported parameters free (the others at
    // Table 4, `lift::absorbed`): a named effect must explain what the unreported joints would
    // otherwise absorb. Measured (`examples/lift_loop_probe`, raise, seed 0): with every joint
    // free, a friction fading over the raise was named `drive_compliance` and a 2 % spring-force
    // gain error `sensor_offset` — wrong names the joints made room for.
    // Where the plain fit is itself over the residual gate, the record shows the effect without
    // the check, and the vocabulary is tried as before, every joint free: against the
    // reported-only model a Stribeck ×1.2 with J3 dry ×2 was named a 41 mm `sensor_offset`
    // (`residual::tests`), the drift left out of the model taken for an effect.
    // Not where the reported-only refit left less (`nested_better`, above): that is the base.
    let gated = plain_ratio > super::super::residual::MODEL_ERROR_RATIO && !nested_better;
    // The vocabulary searched on a base: the reported-only refit where `restricted` is given,
    // else the plain fit; `tag` prefixes its loop steps.
    let mut search = |restricted: Option<&Absorption>, tag: &str| -> Result<Search, LiftFitError> {
        // The search runs on the model the reported-only refit held the other joints in (their
        // prior means: Table 4, or a fleet prior's).
        let (base_model, base_fit, base_opts) = match restricted {
            Some(a) => (a.model.as_ref().unwrap_or(model), &a.fit, &a.opts),
            None => (model, &fit, &opts),
        };
        let hold = super::super::holdout::blocks(base_model, &trace, base_fit, base_opts)?;
        meter.mark(format!("{tag}holdout"));
        // A model error: try the vocabulary (`lift::effects`), one fit each, in an order and with a
        // stop: `sensor_delay` first where the plain residual correlates most with the strip speed
        // (its signature, r ≈ −τ·Ḣ), else `quadratic_drag`, `sensor_delay`, `sensor_offset`,
        // `stribeck`. A candidate passes the margins (`lift::effects`) and must do better on the
        // held-out segment by the stated margin (`holdout::MAX_HOLDOUT_RATIO`); of those that pass,
        // the one with the lowest BIC is named (n·ln(RSS/n) + k·ln n, k its parameter count). The
        // search stops at a passing candidate whose refit leaves the residual at the noise
        // ([`STOP_RATIO`]): no other can do better than noise. Taking the first that passed named
        // a −10 mm H offset `quadratic_drag` on 2 of 3 lifts (its refit left 1.44–1.71× the
        // noise); trying every candidate on every lift cost 4.1× the plain fit (bench loop row).
        // What none names stays as the plain fit left it (withheld above the gate).
        let before = base_fit
            .rmse_m
            .first()
            .copied()
            .unwrap_or(result.rmse.value);
        let n = channels.strip_height_m.len() as f64;
        let base_height_m = base_fit.fitted_height_m.first().unwrap_or(&fitted_height_m);
        let residual: Vec<f64> = channels
            .strip_height_m
            .iter()
            .zip(base_height_m)
            .map(|(m, f)| m - f)
            .collect();
        let delay_first = super::super::residual::diagnose(
            channels.t_s,
            &residual,
            base_height_m,
            channels.torque_nm,
            opts.h_noise_m.max(super::super::residual::GATE_FLOOR_M),
        )
        .correlates_with
        .first()
        .is_some_and(|(name, _)| name == super::super::residual::SPEED);
        let order = if delay_first {
            [
                Candidate::Delay,
                Candidate::Drag,
                Candidate::Offset,
                Candidate::Stribeck,
                Candidate::Compliance,
            ]
        } else {
            Candidate::ALL
        };
        // An H zero offset is not tried against the reported-only model (the plain fit under the
        // residual gate): the reported parameters (J1+J3 and the torque offset) absorb a real one
        // (measured, `examples/lift_loop_probe`, seeds 0–1: +5 mm left the reported-only refit at
        // 0.72–0.80× the noise, +10 mm at 0.81–1.43×, on every protocol) or the plain fit cannot
        // (−10 mm: 5× the noise, `residual::tests`); tried there, it was the wrong name for a 2 %
        // spring-force gain error and a 2 % heavier head on the paper's raise (seeds 0–1 and
        // 200–202).
        //
        // On a record that lowers the strip it is tried there (session 23): friction's torque
        // reverses with the direction of motion and an H offset's reading does not, so a record
        // moving both ways tells the offset from the J1+J3 level that absorbs it on a raise.
        // Measured (`examples/lift_loop_probe rl 2 401 1 offset:10`): a +10 mm offset left the
        // reported-only refit at 3.1× (detectable), the plain fit 1.6× (under the gate): with the
        // offset never tried the lift ended `unexplained`. The offset's size rule and the phase
        // judge (`absorbed::judge`) still refuse a gain error read as one.
        let lowers = super::super::absorbed::judge::lowers(channels.t_s, &fitted_height_m);
        let order: Vec<Candidate> = order
            .into_iter()
            .filter(|c| restricted.is_none() || lowers || !matches!(c, Candidate::Offset))
            .collect();
        let mut best: Option<(f64, Named, Candidate)> = None;
        let mut too_big_offset: Option<String> = None;
        // The candidates' refits run ahead of this loop on other threads (`tried_in_order`: the
        // same refits, the same order of judging, the spare ones cancelled once it stops).
        let try_one = |c: Candidate| try_candidate(c, base_model, &trace, base_fit, base_opts);
        let spare = tried_in_order(&order, try_one, |candidate, tried| {
            let tried = tried?;
            meter.mark(format!("{tag}try:{}", candidate.name()));
            let Some(found) = tried else {
                return Ok(ControlFlow::Continue(()));
            };
            // An H offset at a size a stand cannot have (`absorbed::judge::MAX_NAMED_OFFSET_M`, its
            // interval's end nearest zero) is no candidate (session 23): were it kept, it could win
            // the BIC and be refused after, leaving a right name behind it untold. Measured
            // (`residual::tests`, Stribeck ×1.2 with J3 dry ×2, the search on the reported-only
            // model): a 38 mm offset chosen over the Stribeck, then refused.
            let too_big = found.fit.effects.iter().any(|e| {
                e.param == LiftParam::SensorOffset
                    && (e.ci95[0] > super::super::absorbed::judge::MAX_NAMED_OFFSET_M
                        || e.ci95[1] < -super::super::absorbed::judge::MAX_NAMED_OFFSET_M)
            });
            if too_big {
                // Said, if nothing is named (the record cannot tell it from a gain error).
                let near: Vec<(LiftParam, f64)> = found
                    .fit
                    .effects
                    .iter()
                    .map(|e| {
                        (
                            e.param,
                            if e.ci95[0] > 0.0 {
                                e.ci95[0]
                            } else {
                                e.ci95[1]
                            },
                        )
                    })
                    .collect();
                too_big_offset =
                    super::super::absorbed::judge::objection(found.name, &near, &[], &[], &[], 0.0);
                return Ok(ControlFlow::Continue(()));
            }
            // The named model must pass the check itself.
            if found.excess_ratio >= super::super::absorbed::ABSORBED_RATIO {
                return Ok(ControlFlow::Continue(()));
            }
            let hold_after =
                super::super::holdout::blocks(base_model, &trace, &found.fit, &found.opts)?;
            meter.mark(format!("{tag}holdout:{}", candidate.name()));
            let rmse = found.fit.rmse_m.first().copied().unwrap_or(f64::INFINITY);
            let noise_m = rmse / found.excess_ratio;
            if !super::super::holdout::improves(&hold, &hold_after, noise_m) {
                return Ok(ControlFlow::Continue(()));
            }
            let k = found.fit.effects.len() as f64;
            let bic = n * (rmse * rmse).ln() + k * n.ln();
            let at_noise = found.excess_ratio <= STOP_RATIO;
            if best.as_ref().is_none_or(|(b, _, _)| bic < *b) {
                best = Some((bic, Named { found, hold_after }, candidate));
            }
            // Stribeck and a compliant drive both change how the lower arm leaves rest, and are
            // tried last: after a Stribeck at the noise the drive is still tried, the lower BIC
            // named. Measured (`examples/lift_effects_probe compliance:8000`, J_d 3 kg·m², c 50,
            // seeds 20–27): stopping at the Stribeck named it on one compliant-drive lift (ratio
            // 1.07), a wrong name.
            Ok(if at_noise && !matches!(candidate, Candidate::Stribeck) {
                ControlFlow::Break(())
            } else {
                ControlFlow::Continue(())
            })
        })?;
        // What was tried ahead and not judged, after the loop's own steps.
        for s in spare {
            meter.spare(format!("spare:{tag}{}", s.candidate.name()), s.work);
        }
        Ok(Search {
            best,
            too_big_offset,
            hold,
            before,
        })
    };
    let mut restricted = absorption.as_ref().filter(|_| !gated);
    let mut out = search(restricted, "")?;
    // Session 24: where the plain fit is over the gate, its every-joint search names nothing
    // and the reported-only refit fired, the vocabulary is tried on that refit as well (as on
    // a lift under the gate), the name then reported as there. The every-joint refits start in
    // no basin of their own: a candidate's refit is nested over the plain fit, and one left more
    // than the plain fit did it stopped short, not the record. Measured
    // (`examples/lift_loop_probe design 2 400 1 delay:20`): the plain fit left 3.16× with J1 dry
    // at its bound 0, the delay refitted with every joint free stopped at a cliff at 4.43× (J1,
    // three more joints at 0); on the reported-only refit (3.42×) the delay left 1.01×, τ 20.7
    // [19.4, 21.9] ms. Only after the first search named nothing: its names stand where it named.
    if out.best.is_none() && gated && absorbed.is_some() {
        let again = search(absorbed, "reported_only_base:")?;
        if again.best.is_some() {
            (out, restricted) = (again, absorbed);
        } else if out.too_big_offset.is_none() {
            out.too_big_offset = again.too_big_offset;
        }
    }
    let Search {
        best,
        too_big_offset,
        hold,
        before,
    } = out;
    set_holdout(&mut result, &hold, &hold);
    let Some((_, Named { found, hold_after }, chosen)) = best else {
        // Nothing named: an absorbed effect leaves the lift `unexplained`, never clean.
        if let Some(a) = absorbed {
            let reason = match &too_big_offset {
                Some(why) => format!("{} ({why})", a.reason()),
                None => a.reason(),
            };
            crate::contract::withhold::withhold_all(&mut result, reason);
        } else if let Some(why) = too_big_offset.filter(|_| result.residual.verdict.is_some()) {
            let w = result.residual.joints_withheld.take();
            result.residual.joints_withheld = Some(match w {
                Some(gate) => format!("{gate}; no named effect explains the record: {why}"),
                None => format!("no named effect explains the record: {why}"),
            });
        }
        return Ok(LiftReport {
            result,
            fit,
            fitted_height_m,
            plain_fitted_height_m: None,
            work: meter.steps,
        });
    };
    // The effect named, reported with every joint free: the same candidate refitted from the
    // plain fit, where it passes the vocabulary's margins and the check's ratio (its effect's
    // intervals then carry the joints' uncertainty: from the reported-only search a 4 N/(m/s)²
    // drag read 4.32 [4.11, 4.52]); else a refit with the effect held where the search found it
    // (`absorbed::fixed_effect_refit`), the effect's own parameters the search's.
    let search = found;
    let mut full_refit: Option<Found> = None;
    let mut fixed = None;
    if restricted.is_some() {
        match try_candidate(chosen, model, &trace, &fit, &opts)? {
            Some(f) if f.excess_ratio < super::super::absorbed::ABSORBED_RATIO => {
                full_refit = Some(f)
            }
            _ => {
                fixed = super::super::absorbed::fixed_effect_refit(
                    model,
                    &trace,
                    &search.fit,
                    &search.opts,
                    &opts,
                )?
            }
        }
    }
    meter.mark(format!("report:{}", chosen.name()));
    // The named result of `found` (held by `fixed`, if it is one) and why it is not the
    // explanation (`absorbed::judge`), if it is not.
    let judge_named = |found: &Found, fixed: &Option<FixedRefit>| {
        let (named, refitted) = match fixed {
            Some((_, h, full, _)) => {
                let corrected = LiftTrace {
                    inputs: trace.inputs,
                    strip_height_m: h,
                };
                let (named, _) = named_result(
                    model,
                    full,
                    &corrected,
                    &opts,
                    trace_id,
                    found.name,
                    found.params.clone(),
                    before,
                    (&hold, &hold_after),
                );
                // The plot shows the search's fit: H as the logger would have recorded it.
                let sensor_h = found
                    .fit
                    .fitted_height_m
                    .first()
                    .cloned()
                    .unwrap_or_default();
                (named, sensor_h)
            }
            // A delay's or an offset's refitted H is the sensor's: what the logger would have
            // recorded.
            None => named_result(
                model,
                &found.fit,
                &trace,
                &opts,
                trace_id,
                found.name,
                found.params.clone(),
                before,
                (&hold, &hold_after),
            ),
        };
        // The named model, as reported, must leave the record at the noise
        // (`absorbed::NAMED_MAX_RATIO`): else the name is not the explanation.
        let left = named.residual.excess_ratio.unwrap_or(f64::INFINITY);
        // And in every phase of the lift, at a size a stand can have (`absorbed::judge`).
        let (judged_h, judged_fit) = match fixed {
            Some((_, h, full, _)) => (h.as_slice(), full.fitted_height_m.first()),
            None => (channels.strip_height_m, found.fit.fitted_height_m.first()),
        };
        let judged = (
            channels.t_s,
            judged_h,
            judged_fit.map_or(&[][..], |v| v.as_slice()),
        );
        let why = super::super::absorbed::judge::rejected(
            &found.fit,
            found.name,
            judged,
            left,
            absorption.as_ref(),
            &opts,
        );
        (named, refitted, why)
    };
    let (mut named, mut refitted, mut why) =
        judge_named(full_refit.as_ref().unwrap_or(&search), &fixed);
    // Session 23: where the every-joint refit from the plain fit is turned down and leaves
    // more than the search's fit, which is nested in it, it stopped in the plain fit's basin
    // (where the joints had absorbed the effect): the effect is reported from the search's fit
    // instead (`absorbed::fixed_effect_refit`, started there) and judged again. Measured
    // (`examples/lift_loop_probe rl 1 402 1 stribeck:0.5`, `rl 2 400 1 delay:20`): the search
    // left 0.72× and 1.03×, the refit from the plain fit 1.15× with a phase over the judge's
    // 1.35× — both right names turned down. Only then: where the every-joint refit passes, its
    // intervals carry the joints' uncertainty and stand.
    let search_rms_m = search.fit.rmse_m.first().copied().unwrap_or(f64::INFINITY);
    let stopped_short = full_refit
        .as_ref()
        .is_some_and(|f| f.fit.rmse_m.first().is_some_and(|r| *r > search_rms_m));
    if why.is_some() && stopped_short {
        let alt = super::super::absorbed::fixed_effect_refit(
            model,
            &trace,
            &search.fit,
            &search.opts,
            &opts,
        )?;
        meter.mark(format!("report_from_search:{}", chosen.name()));
        if alt.is_some() {
            let (n, r, w) = judge_named(&search, &alt);
            if w.is_none() {
                (named, refitted, why) = (n, r, None);
                fixed = alt;
                full_refit = None;
            }
        }
    }
    if let Some(why) = why {
        let reason = match result.residual.joints_withheld.take() {
            Some(gate) => format!("{gate}; {why}"),
            None => why,
        };
        crate::contract::withhold::withhold_all(&mut result, reason);
        return Ok(LiftReport {
            result,
            fit,
            fitted_height_m,
            plain_fitted_height_m: None,
            work: meter.steps,
        });
    }
    named.residual.autocorrelation_before = result.residual.autocorrelation;
    named.fit.absorption = result.fit.absorption;
    Ok(LiftReport {
        result: named,
        fit: match fixed {
            Some((_, _, f, _)) => f,
            None => full_refit.unwrap_or(search).fit,
        },
        fitted_height_m: refitted,
        plain_fitted_height_m: Some(fitted_height_m),
        work: meter.steps,
    })
}

/// What a search of the vocabulary on one base left: the best passing candidate (its BIC, the
/// name, the candidate), an H offset too big to name if one was found, the base's held-out test
/// and its fitted RMS, m.
struct Search {
    best: Option<(f64, Named, Candidate)>,
    too_big_offset: Option<String>,
    hold: super::super::holdout::Holdout,
    before: f64,
}

/// What `absorbed::fixed_effect_refit` returns: the model, the record's H as fitted, the fit
/// and its options.
type FixedRefit = (LiftModel, Vec<f64>, LiftFit, LiftFitOptions);

/// The `holdout_note` of a lift whose plain model explains the record (no effect tried).
pub const NO_HOLDOUT_NEEDED: &str = "no held-out test: the plain model explains the record \
     (residual within 1.5× the noise, no effect to judge); the held-out pair repeats the fitted RMSE";

/// The held-out pair of `r` from the plain model's test and the augmented one's (the same when
/// nothing is named); where a test was not run, the fitted RMSE and the reason.
fn set_holdout(
    r: &mut FitResult,
    before: &super::super::holdout::Holdout,
    after: &super::super::holdout::Holdout,
) {
    let res = &mut r.residual;
    res.holdout_rmse_before = before.holdout_rmse_m().unwrap_or(res.rmse_before);
    res.holdout_rmse_after = after.holdout_rmse_m().unwrap_or(res.rmse_after);
    res.holdout_note = [before, after].into_iter().find_map(|h| match h {
        super::super::holdout::Holdout::Short(why) => Some(why.clone()),
        super::super::holdout::Holdout::Judged { .. } => None,
    });
}

/// The result of `fit` (the fit with one named effect, on `trace`, the record it fitted) and
/// its fitted H: joints from that fit; the residual block names the effect with `params` and
/// tells the error before (`rmse_before_m`, the plain fit's) and after, on the whole trace and on
/// the held-out blocks (`holds`: the plain model's test, the augmented one's).
#[allow(clippy::too_many_arguments)]
fn named_result(
    model: &LiftModel,
    fit: &LiftFit,
    trace: &LiftTrace,
    opts: &LiftFitOptions,
    trace_id: &str,
    name: &str,
    params: Vec<(&'static str, serde_json::Value)>,
    rmse_before_m: f64,
    holds: (
        &super::super::holdout::Holdout,
        &super::super::holdout::Holdout,
    ),
) -> (FitResult, Vec<f64>) {
    let refitted = fit.fitted_height_m.first().cloned().unwrap_or_default();
    let mut named = fit_result(model, fit, trace, &refitted, opts, trace_id);
    let after = named.rmse.value;
    named.residual.effects = vec![crate::contract::report::EffectResult {
        name: name.into(),
        params: params
            .into_iter()
            .map(|(k, v)| (k.to_string(), v))
            .collect(),
    }];
    named.residual.rmse_before = rmse_before_m;
    named.residual.rmse_after = after;
    set_holdout(&mut named, holds.0, holds.1);
    (named, refitted)
}

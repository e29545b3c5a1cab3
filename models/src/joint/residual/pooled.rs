//! The residual loop across recordings of one rig (issue 36, point 5): one set of physical
//! parameters for every recording, and an effect named only if it explains every one of them.
//!
//! Protocol (stated choices):
//! - Each recording is first fitted alone (release found and checked, base fit, its own loop),
//!   which gives its window, its starting values and what it would name alone.
//! - The base model is fitted pooled ([`crate::joint::identify::pooled`]); each effect of the
//!   searched vocabulary is added, shared, and fitted pooled; then the pairs of the three best.
//! - An effect (or pair) is named when it lowers the pooled BIC by ≥ [`BIC_MARGIN`], its
//!   parameter's interval excludes the null, and on **every** recording whose base residual
//!   exceeds the noise materially (excess over σ² above half of σ²) it explains at least
//!   [`EXPLAINED_SHARE`] of that excess — in its early (large swings) and late (small swings)
//!   halves separately — and leaves at most [`REMAINDER_MAX`]× the noise in each half. An
//!   effect that fits one recording and not another, or most of a misfit but not all, is not
//!   the rig's: the verdict is then `unexplained`, with each recording's errors as evidence.

use serde::Serialize;

use super::effects::Effect;
use super::{BIC_MARGIN, EXPLAINED_SHARE, Finding, analyse, base_spec, scales, vanishing_knot};
use crate::joint::identify::pooled::{PooledFit, Recording, fit_pooled};
use crate::joint::identify::{
    FitError, FitOptions, FitOutcome, FitSpec, InitialEstimate, JointTest, fit_base, release_of,
};
use crate::numerics::stats::noise_sigma;

/// One recording in the pooled loop's report.
#[derive(Debug, Clone, Serialize)]
pub struct PooledRecording {
    pub release_t_s: f64,
    pub release_rule: String,
    pub samples_fitted: usize,
    /// Sensor noise from the base residual's first differences, channel units.
    pub noise_sigma: f64,
    /// Fitted alone (base model), and what its own loop named alone.
    pub rmse_alone: f64,
    pub named_alone: Vec<String>,
    pub verdict_alone: Option<String>,
    /// Fitted pooled: the base model, and the model with the effect named (or the best tried).
    pub rmse_pooled_before: f64,
    pub rmse_pooled_after: f64,
    /// Share of the base residual's excess over the noise the effect explains here.
    pub explained_share: f64,
}

/// One model tried on the pool.
#[derive(Debug, Clone, Serialize)]
pub struct PooledCandidate {
    pub effects: Vec<Effect>,
    pub delta_bic: f64,
    /// Per recording: RMSE with this model.
    pub rmse: Vec<f64>,
    pub explained_share: Vec<f64>,
    /// Worst half's remaining RMS over the noise, per recording.
    pub remainder_over_noise: Vec<f64>,
    /// False when the model's parameters read as no physical rig's (a vanishing friction).
    pub plausible: bool,
    pub accepted: bool,
    pub reason: String,
}

/// The pooled loop's result.
#[derive(Debug, Clone)]
pub struct PooledFinding {
    pub recordings: Vec<PooledRecording>,
    pub effects: Vec<Effect>,
    /// `unexplained` when a misfit above the noise remains that no effect explains on every
    /// recording; `ambiguous` when models that pass tie ([`tied`]); `None` when the pooled base
    /// model fits them all, or an effect is named.
    pub verdict: Option<String>,
    pub candidates: Vec<PooledCandidate>,
    /// The model whose errors `recordings` show as `rmse_pooled_after`: the named one, else the
    /// plausible one with the lowest BIC (empty: none beat the base model).
    pub best_tried: Vec<Effect>,
    pub base: PooledFit,
    /// The pooled fit reported: the named effect's, else the base's.
    pub reported: PooledFit,
    pub alone: Vec<(FitOutcome, Finding)>,
}

/// A named effect must leave at most this × the noise (RMS, each half of each recording): a
/// model that explains most of a large misfit but leaves a structured remainder far above the
/// noise has not found the rig's physics (measured: a torsional spring fitted as an inertia
/// error explains 99 % of the excess at 30° and 90° and leaves 17–20× the noise).
pub const REMAINDER_MAX: f64 = 3.0;

/// The models that passed every rule and whose pooled BICs lie within
/// [`super::ambiguity::AMBIGUITY_BIC`] of the lowest such (issue 36, point 3): indices into
/// `candidates`, the lowest included; empty when one model stands alone (or none passed). A
/// pair that does not beat its better single by the BIC margin has not passed (it is nested).
pub fn tied(candidates: &[PooledCandidate]) -> Vec<usize> {
    let passed: Vec<usize> = (0..candidates.len())
        .filter(|&i| candidates[i].accepted && candidates[i].delta_bic.is_finite())
        .collect();
    let Some(best) = passed
        .iter()
        .map(|&i| candidates[i].delta_bic)
        .min_by(f64::total_cmp)
    else {
        return Vec::new();
    };
    let ties: Vec<usize> = passed
        .into_iter()
        .filter(|&i| candidates[i].delta_bic - best < super::ambiguity::AMBIGUITY_BIC)
        .collect();
    if ties.len() > 1 { ties } else { Vec::new() }
}

/// Share of the excess over σ² that `after` explains (1: all of it; ≤ 0: none).
fn explained(before: f64, after: f64, sigma: f64) -> f64 {
    let s2 = sigma * sigma;
    let b = (before * before - s2).max(0.0);
    if b <= 0.0 {
        return 1.0;
    }
    1.0 - (after * after - s2).max(0.0) / b
}

/// RMS of the first and the second half of a residual (the record's large and small swings).
fn halves(r: &[f64]) -> [f64; 2] {
    let m = r.len() / 2;
    let rms = |v: &[f64]| (v.iter().map(|x| x * x).sum::<f64>() / v.len().max(1) as f64).sqrt();
    [rms(&r[..m]), rms(&r[m..])]
}

/// The pooled loop over recordings of one rig (one pendulum or slider: the same `dof`).
pub fn analyse_pooled(tests: &[&JointTest], opts: &FitOptions) -> Result<PooledFinding, FitError> {
    if tests.len() < 2 {
        return Err(FitError::Start(
            "a pooled fit needs at least two recordings".into(),
        ));
    }
    let mut alone = Vec::new();
    for t in tests {
        let full = fit_base(t, opts)?;
        let finding = analyse(t, &full, opts)?;
        alone.push((full, finding));
    }
    let recs: Vec<Recording> = tests
        .iter()
        .zip(&alone)
        .map(|(t, (f, _))| Recording {
            test: t,
            start: f.start,
            n_fit: f.n_fit,
            init: InitialEstimate {
                viscous: f.law.viscous,
                dry: f.law.dry,
                offset: f.offset,
                q0: f.q0,
                v0: f.v0,
            },
        })
        .collect();
    // The shared start: the recordings' friction averaged.
    let k = alone.len() as f64;
    let shared_init = InitialEstimate {
        viscous: alone.iter().map(|(f, _)| f.law.viscous).sum::<f64>() / k,
        dry: alone.iter().map(|(f, _)| f.law.dry).sum::<f64>() / k,
        ..recs[0].init
    };
    let mut spec = base_spec(&alone[0].0);
    spec.law.viscous = shared_init.viscous;
    spec.law.dry = shared_init.dry;
    spec.fit_offset = alone.iter().all(|(f, _)| {
        f.spec_params
            .contains(&crate::joint::identify::Param::Offset)
    });
    let base = fit_pooled(&recs, &spec, &shared_init, opts)?;
    let sigma: Vec<f64> = base
        .per_recording
        .iter()
        .map(|f| noise_sigma(&f.residual))
        .collect();
    let rmse_of = |p: &PooledFit| -> Vec<f64> { p.per_recording.iter().map(|f| f.rmse).collect() };
    let base_rmse = rmse_of(&base);
    let material: Vec<bool> = base_rmse
        .iter()
        .zip(&sigma)
        .map(|(r, s)| r * r - s * s > 0.5 * s * s)
        .collect();
    // Starting values' scales from the recording with the widest travel.
    let widest = (0..tests.len())
        .max_by(|&a, &b| {
            let span = |i: usize| {
                let q = &alone[i].0.trajectory.q;
                q.iter().fold(f64::NEG_INFINITY, |m, x| m.max(x.abs()))
            };
            span(a).total_cmp(&span(b))
        })
        .unwrap_or(0);
    let sc = scales(tests[widest], &alone[widest].0, sigma[widest]);
    let with = |effects: &[Effect]| -> FitSpec {
        let mut s = spec.clone();
        for e in effects {
            e.add_to(&mut s, &sc, false);
        }
        s
    };
    let judge = |effects: &[Effect], fit: &PooledFit, reference: &PooledFit| -> PooledCandidate {
        let rmse = rmse_of(fit);
        // Each recording judged on its early (large swings) and late (small swings) halves
        // separately (issue 36, point 3): its share is the worse half's.
        let share: Vec<f64> = fit
            .per_recording
            .iter()
            .zip(&base.per_recording)
            .zip(&sigma)
            .map(|((a, b), s)| {
                halves(&a.residual)
                    .iter()
                    .zip(halves(&b.residual))
                    .filter(|(_, before)| before * before - s * s > 0.5 * s * s)
                    .map(|(after, before)| explained(before, *after, *s))
                    .fold(1.0f64, f64::min)
            })
            .collect();
        // The worst half's remainder over the noise, per recording.
        let remainder: Vec<f64> = fit
            .per_recording
            .iter()
            .zip(&sigma)
            .map(|(a, s)| halves(&a.residual).iter().fold(0.0f64, |m, h| m.max(h / s)))
            .collect();
        let small = remainder.iter().all(|x| *x <= REMAINDER_MAX);
        let delta_bic = fit.bic - reference.bic;
        let significant = effects.iter().all(|e| {
            e.nulls().iter().any(|(p, null)| match fit.shared(*p) {
                Some((_, ci)) => ci[0] > *null || ci[1] < *null,
                None => false,
            })
        });
        let everywhere = share
            .iter()
            .zip(&material)
            .all(|(s, m)| !m || *s >= EXPLAINED_SHARE);
        // The single loop's rule: a position-friction grid whose μ all but vanishes at an
        // interior knot is absorbing something else (`vanishing_knot`).
        let vanishing = effects
            .contains(&Effect::PositionFriction)
            .then(|| fit.per_recording.first().and_then(vanishing_knot))
            .flatten();
        let accepted =
            delta_bic <= -BIC_MARGIN && significant && everywhere && small && vanishing.is_none();
        let rem: Vec<String> = remainder.iter().map(|x| format!("{x:.1}")).collect();
        let shares: Vec<String> = share
            .iter()
            .map(|s| format!("{:.0} %", 100.0 * s))
            .collect();
        PooledCandidate {
            effects: effects.to_vec(),
            delta_bic,
            rmse,
            explained_share: share.clone(),
            remainder_over_noise: remainder.clone(),
            plausible: vanishing.is_none(),
            accepted,
            reason: format!(
                "ΔBIC {delta_bic:.1}, interval {} its null, explains {} of each recording's \
                 excess over the noise (needs {:.0} % on each){}{}{}",
                if significant { "excludes" } else { "includes" },
                shares.join(" / "),
                100.0 * EXPLAINED_SHARE,
                if everywhere || !significant || delta_bic > -BIC_MARGIN {
                    ""
                } else {
                    ": it does not explain every recording, so it is not the rig's"
                },
                vanishing.map_or(String::new(), |q| format!(
                    "; position friction's μ vanishes at {q:.4} (model units): no wear pattern"
                )),
                if small {
                    String::new()
                } else {
                    format!(
                        "; leaves {}× the noise (worst half of each recording; at most \
                         {REMAINDER_MAX}×): not all of the misfit",
                        rem.join(" / ")
                    )
                }
            ),
        }
    };
    let mut candidates = Vec::new();
    let mut fits: Vec<(Vec<Effect>, PooledFit)> = Vec::new();
    if material.iter().any(|m| *m) {
        for e in Effect::SEARCHED {
            match fit_pooled(&recs, &with(&[e]), &shared_init, opts) {
                Ok(f) => {
                    candidates.push(judge(&[e], &f, &base));
                    fits.push((vec![e], f));
                }
                Err(err) => candidates.push(PooledCandidate {
                    effects: vec![e],
                    delta_bic: f64::NAN,
                    rmse: Vec::new(),
                    explained_share: Vec::new(),
                    remainder_over_noise: Vec::new(),
                    plausible: false,
                    accepted: false,
                    reason: format!("fit failed: {err}"),
                }),
            }
        }
        // Pairs of the three best singles (by BIC), judged against the base.
        let mut order: Vec<usize> = (0..fits.len()).collect();
        order.sort_by(|&a, &b| fits[a].1.bic.total_cmp(&fits[b].1.bic));
        let top: Vec<Effect> = order.iter().take(3).map(|&i| fits[i].0[0]).collect();
        for i in 0..top.len() {
            for j in i + 1..top.len() {
                let pair = [top[i], top[j]];
                if let Ok(f) = fit_pooled(&recs, &with(&pair), &shared_init, opts) {
                    let mut c = judge(&pair, &f, &base);
                    // A pair must also earn its place over its better single.
                    let single = fits
                        .iter()
                        .filter(|(e, _)| e[0] == pair[0] || e[0] == pair[1])
                        .map(|(_, f)| f.bic)
                        .fold(f64::INFINITY, f64::min);
                    if c.accepted && f.bic - single > -BIC_MARGIN {
                        c.accepted = false;
                        c.reason += "; not over its better single effect by the BIC margin";
                    }
                    candidates.push(c);
                    fits.push((pair.to_vec(), f));
                }
            }
        }
    }
    // The accepted model with the lowest BIC.
    let best = candidates
        .iter()
        .filter(|c| c.accepted)
        .filter_map(|c| fits.iter().find(|(e, _)| *e == c.effects))
        .min_by(|a, b| a.1.bic.total_cmp(&b.1.bic))
        .cloned();
    // Issue 36, point 3: models that pass and whose pooled BICs tie are not told apart by
    // these recordings; none is named.
    let ties = tied(&candidates);
    let best = if ties.is_empty() { best } else { None };
    if !ties.is_empty() {
        let names: Vec<String> = ties
            .iter()
            .map(|&i| {
                let n: Vec<&str> = candidates[i].effects.iter().map(|e| e.name()).collect();
                n.join("+")
            })
            .collect();
        let refs: Vec<&str> = names.iter().map(String::as_str).collect();
        let why = format!(
            "; not named: the recordings cannot tell apart {} (pooled BICs within {}): {}",
            names.join(" and "),
            super::ambiguity::AMBIGUITY_BIC,
            super::ambiguity::telling_apart(&refs)
        );
        for &i in &ties {
            candidates[i].accepted = false;
            candidates[i].reason += &why;
        }
    }
    for c in &mut candidates {
        if c.accepted && best.as_ref().is_some_and(|(e, _)| *e != c.effects) {
            c.accepted = false;
            c.reason += "; not named: a model with a lower BIC was";
        }
    }
    let verdict = if !ties.is_empty() {
        Some("ambiguous".to_string())
    } else if best.is_none() && material.iter().any(|m| *m) {
        Some("unexplained".to_string())
    } else {
        None
    };
    // The evidence when nothing is named: the best model tried (lowest BIC).
    let plausible = |e: &Vec<Effect>| {
        candidates
            .iter()
            .any(|c| c.effects == *e && c.plausible && c.delta_bic <= -BIC_MARGIN)
    };
    let shown = best.clone().or_else(|| {
        fits.iter()
            .filter(|(e, _)| plausible(e))
            .min_by(|a, b| a.1.bic.total_cmp(&b.1.bic))
            .cloned()
    });
    let best_tried = shown.as_ref().map(|(e, _)| e.clone()).unwrap_or_default();
    let after_rmse = shown
        .as_ref()
        .map_or(base_rmse.clone(), |(_, f)| rmse_of(f));
    let recordings = tests
        .iter()
        .enumerate()
        .map(|(i, t)| {
            let (full, finding) = &alone[i];
            let release = release_of(t).ok();
            PooledRecording {
                release_t_s: t.t_s[full.start],
                release_rule: release.map_or("?".into(), |r| r.rule.as_str().to_owned()),
                samples_fitted: full.n_fit,
                noise_sigma: sigma[i],
                rmse_alone: full.rmse,
                named_alone: finding
                    .effects
                    .iter()
                    .map(|e| e.name().to_owned())
                    .collect(),
                verdict_alone: finding.residual.verdict.clone(),
                rmse_pooled_before: base_rmse[i],
                rmse_pooled_after: after_rmse[i],
                explained_share: explained(base_rmse[i], after_rmse[i], sigma[i]),
            }
        })
        .collect();
    let (effects, reported) = match best {
        Some((e, f)) => (e, f),
        None => (Vec::new(), base.clone()),
    };
    Ok(PooledFinding {
        recordings,
        effects,
        verdict,
        candidates,
        best_tried,
        base,
        reported,
        alone,
    })
}

/// The contract's fit result for recording `i` of a pooled finding (issue 36, point 5): the
/// rig's shared parameters as its joint (judged against `baseline`), its own start, zero and
/// errors, the pooled loop's effects and verdict, and the `pooled_rig` block naming every
/// recording (`trace_ids`, in the order of `tests`).
#[allow(clippy::too_many_arguments)]
pub fn pooled_result(
    tests: &[&JointTest],
    finding: &PooledFinding,
    i: usize,
    trace_ids: &[String],
    rig_id: &str,
    baseline: &crate::contract::testspec::Baseline,
    thresholds: &crate::contract::drift::DriftThresholds,
) -> Result<crate::contract::report::FitResult, FitError> {
    use crate::contract::report::{
        self as report, FitResult, PooledRig, PooledRigModel, PooledRigRecording, Quantity,
        ResidualResult,
    };
    let (Some(test), Some(fit), Some(base)) = (
        tests.get(i),
        finding.reported.per_recording.get(i),
        finding.base.per_recording.get(i),
    ) else {
        return Err(FitError::Start(format!("no recording {i} in the pool")));
    };
    let units = match test.dof.mech {
        crate::joint::dynamics::Mechanism::Pendulum(_) => ("rad", "rad/s"),
        crate::joint::dynamics::Mechanism::Slider(_) => ("m", "m/s"),
    };
    let names = |e: &[Effect]| e.iter().map(|e| e.name().to_owned()).collect::<Vec<_>>();
    // This recording first, then the others in their order.
    let order: Vec<usize> = std::iter::once(i)
        .chain((0..tests.len()).filter(|&j| j != i))
        .collect();
    let recordings = order
        .iter()
        .filter_map(|&j| {
            let r = finding.recordings.get(j)?;
            Some(PooledRigRecording {
                trace_id: trace_ids.get(j).cloned().unwrap_or_default(),
                release_t_s: r.release_t_s,
                samples_fitted: r.samples_fitted,
                noise_sigma: r.noise_sigma,
                rmse_alone: r.rmse_alone,
                named_alone: r.named_alone.clone(),
                verdict_alone: r.verdict_alone.clone(),
                rmse_pooled_before: r.rmse_pooled_before,
                rmse_pooled_after: r.rmse_pooled_after,
                explained_share: r.explained_share,
            })
        })
        .collect();
    let tried = finding
        .candidates
        .iter()
        .map(|c| PooledRigModel {
            effects: names(&c.effects),
            delta_bic: c.delta_bic,
            accepted: c.accepted,
            reason: c.reason.clone(),
        })
        .collect();
    let effects = finding
        .effects
        .iter()
        .map(|e| super::effects::effect_result(*e, fit, test))
        .collect();
    let mut result = FitResult {
        trace_id: trace_ids.get(i).cloned().unwrap_or_default(),
        joints: vec![report::joint_result(fit, baseline, thresholds)],
        rmse: Quantity {
            value: fit.rmse,
            unit: test.unit.to_string(),
        },
        residual: ResidualResult {
            effects,
            rmse_before: base.rmse,
            rmse_after: fit.rmse,
            holdout_rmse_before: base.rmse,
            holdout_rmse_after: fit.rmse,
            verdict: finding.verdict.clone(),
            holdout_note: Some(
                "a pooled fit holds no part out: each recording is judged on its early and late \
                 halves instead (`pooled_rig`); the held-out pair repeats the fitted RMSE"
                    .into(),
            ),
            ..ResidualResult::default()
        },
        fit: report::details(
            fit,
            test.t_s[fit.start],
            &release_of(test)?,
            units,
            test.unit,
        ),
        pooled: None,
        combinations: Vec::new(),
        pooled_rig: Some(PooledRig {
            rig_id: rig_id.to_owned(),
            recordings,
            effects: names(&finding.effects),
            verdict: finding.verdict.clone(),
            best_tried: names(&finding.best_tried),
            tried,
        }),
    };
    let sigma = finding
        .recordings
        .get(i)
        .map_or(f64::NAN, |r| r.noise_sigma);
    crate::contract::withhold::if_unexplained(&mut result, sigma);
    Ok(result)
}

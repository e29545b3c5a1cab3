//! What a gauge fit leaves (issue 16/17 style): the residual against the gauge's noise, and the
//! effects tried when it shows a model error — `sensor_offset`, `spring_rate`, else `unexplained`.
//!
//! Protocol (each number stated here):
//! - Noise: σ̂_d from the residual's first differences *within* each branch (√(mean Δr²/2)):
//!   a misfit is slow over the heights, the gauge's noise is not. Floored at the fit's σ₀ =
//!   max(`gauge_noise_n`, resolution/√12), the noise its intervals assume.
//! - Excess: RMS(residual)/max(σ̂_d, σ₀). Whiteness: the pooled within-branch lag-1
//!   autocorrelation ρ₁ against its one-sided p = [`crate::numerics::stats::WHITENESS_P`] bound for white
//!   noise, z₀.₉₉₉/√m (m the pairs): a slow misfit makes neighbours alike.
//! - The base fit carries the gauge's zero b as a nuisance (`fit::GaugeFitOptions::fit_offset`:
//!   an unseen tare error of 0.5 N bent the friction by 15–20 % without it). Both effects are
//!   judged by the same margins — the fit with the effect's parameter at most [`MIN_IMPROVEMENT`]
//!   (half) the RMSE of the same fit without it, the parameter's interval excluding its null
//!   value (b = 0 N, k = 1), and the fit with it back within the lift's [`MODEL_ERROR_RATIO`] (3)
//!   of the noise; one extra parameter each, so the lowest BIC is the lowest RMSE:
//!   - `spring_rate`: tried (a refit with k) when the base residual exceeds the lift's
//!     [`EFFECT_TRY_RATIO`] (1.5) of the noise or is not white;
//!   - `sensor_offset`: b is always fitted; named when its interval excludes 0 and the same
//!     fit without b leaves at least twice the RMSE. A zero within the noise is not named, and
//!     still cannot bend the friction.
//! - A named effect's fit is the one the joints come from: an offset gauge or another spring is
//!   a finding on the gauge or the spring, never a joint alarm. `rmse_before` is the plain
//!   model's (no zero, no k), `rmse_after` the final fit's.
//! - The final residual over [`MODEL_ERROR_RATIO`] or not white: `unexplained`, the joints
//!   withheld (`report`); otherwise `none` or the named effects.

use super::super::dynamics::LiftModel;
use super::super::static_force::DriveLine;
use super::GaugeRecord;
use super::fit::{GaugeFit, GaugeFitOptions, fit_gauge_from};
use super::terms::GaugeEffect;
use crate::numerics::stats::{WHITENESS_P, normal_quantile};

pub use super::super::residual::{EFFECT_TRY_RATIO, MODEL_ERROR_RATIO};

/// A named effect's refit must bring the RMSE to at most this share of the plain fit's (the
/// lift's `effects::MIN_IMPROVEMENT`).
pub const MIN_IMPROVEMENT: f64 = super::super::effects::MIN_IMPROVEMENT;

/// The diagnosis of a gauge fit's residual (measured − fitted, N).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GaugeResidual {
    pub rms_n: f64,
    /// The noise from the within-branch first differences, N (unfloored).
    pub noise_n: f64,
    /// `rms_n / max(noise_n, floor)`.
    pub excess_ratio: f64,
    /// Pooled within-branch lag-1 autocorrelation.
    pub rho1: f64,
    /// ρ₁ within its bound for white noise.
    pub white: bool,
}

impl GaugeResidual {
    /// The plain model leaves more than noise: effects are tried.
    pub fn try_effects(&self) -> bool {
        self.excess_ratio > EFFECT_TRY_RATIO || !self.white
    }

    /// The fit's joint statuses may be used.
    pub fn trusted(&self) -> bool {
        self.excess_ratio <= MODEL_ERROR_RATIO && self.white
    }
}

/// Diagnose the residual of `fitted_n` on `record`; `floor_n` the least noise assumed.
pub fn diagnose(record: &GaugeRecord, fitted_n: &[f64], floor_n: f64) -> GaugeResidual {
    let r: Vec<f64> = record
        .forces_n
        .iter()
        .zip(fitted_n)
        .map(|(m, f)| m - f)
        .collect();
    let n = r.len().max(1) as f64;
    let rms_n = (r.iter().map(|v| v * v).sum::<f64>() / n).sqrt();
    let mean = r.iter().sum::<f64>() / n;
    let (mut d2, mut c1, mut pairs) = (0.0, 0.0, 0usize);
    for branch in [record.raising(), record.lowering()] {
        let b = &r[branch.start.min(r.len())..branch.end.min(r.len())];
        for w in b.windows(2) {
            d2 += (w[1] - w[0]).powi(2);
            c1 += (w[1] - mean) * (w[0] - mean);
            pairs += 1;
        }
    }
    let c0 = r.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n;
    let m = pairs.max(1) as f64;
    let noise_n = (d2 / m / 2.0).sqrt();
    let rho1 = if c0 > 0.0 { c1 / m / c0 } else { 0.0 };
    let bound = normal_quantile(1.0 - WHITENESS_P) / m.sqrt();
    GaugeResidual {
        rms_n,
        noise_n,
        excess_ratio: rms_n / noise_n.max(floor_n),
        rho1,
        white: rho1 <= bound,
    }
}

/// What the residual loop concluded.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum GaugeVerdict {
    /// The plain model explains the record.
    None,
    /// An effect explains it (`spring_rate` when both are named; [`GaugeLoop::named`] lists all).
    Named(GaugeEffect),
    /// Structure remains that no effect explains: the joints are withheld.
    Unexplained,
}

/// The residual loop's outcome: the verdict, the fit the joints come from, the plain one, and
/// each fit's diagnosis.
#[derive(Debug, Clone)]
pub struct GaugeLoop {
    pub verdict: GaugeVerdict,
    /// Every effect named, `spring_rate` first.
    pub named: Vec<GaugeEffect>,
    /// The fit the joints come from: the friction with the gauge's zero, and k if named.
    pub fit: GaugeFit,
    pub residual: GaugeResidual,
    /// With a named effect: the plain model's fit (no zero, no k) and its diagnosis, for
    /// `rmse_before` and plots.
    pub plain: Option<(GaugeFit, GaugeResidual)>,
    /// Every effect tried: (effect, RMSE with it N, RMSE without it N, named).
    pub tried: Vec<(GaugeEffect, f64, f64, bool)>,
}

/// The base fit of `record` (friction and the gauge's zero), then the vocabulary (module doc):
/// `spring_rate` by a refit when the base residual shows a model error; `sensor_offset` when the
/// fitted zero's interval excludes 0 and the fit without it leaves at least twice the RMSE.
/// `opts.effect` and `opts.fit_offset` are ignored (the loop sets them).
pub fn fit_with_effects(
    model: &LiftModel,
    alpha_range_rad: (f64, f64),
    drive: &DriveLine,
    record: &GaugeRecord,
    opts: &GaugeFitOptions,
) -> Result<GaugeLoop, super::GaugeError> {
    let with = |fit_offset: bool, effect: Option<GaugeEffect>| GaugeFitOptions {
        fit_offset,
        effect,
        ..opts.clone()
    };
    let base = fit_gauge_from(
        model,
        alpha_range_rad,
        drive,
        record,
        &with(true, None),
        None,
    )?;
    let base_res = diagnose(record, &base.fitted_n, base.noise_floor_n);
    let mut tried = Vec::new();
    let mut named = Vec::new();
    let (mut fit, mut res) = (base.clone(), base_res);
    if base_res.try_effects() {
        let start = base.friction_start();
        let o = with(true, Some(GaugeEffect::SpringRate));
        match fit_gauge_from(model, alpha_range_rad, drive, record, &o, Some(&start)) {
            Ok(k_fit) => {
                let r = diagnose(record, &k_fit.fitted_n, k_fit.noise_floor_n);
                let passes = k_fit.rmse_n <= MIN_IMPROVEMENT * base.rmse_n
                    && k_fit.spring_rate.is_some_and(|k| k.excludes_null())
                    && r.excess_ratio <= MODEL_ERROR_RATIO;
                tried.push((GaugeEffect::SpringRate, k_fit.rmse_n, base.rmse_n, passes));
                if passes {
                    named.push(GaugeEffect::SpringRate);
                    (fit, res) = (k_fit, r);
                }
            }
            Err(super::GaugeError::Failed(_)) => {}
            Err(e) => return Err(e),
        }
    }
    // The gauge's zero: named when its interval excludes 0 and the same fit without it leaves
    // at least 1/MIN_IMPROVEMENT times the RMSE (BIC: one parameter for that much less RSS).
    let mut plain = None;
    if fit.offset.is_some_and(|b| b.excludes_null()) {
        let start = fit.friction_start();
        let k = fit.spring_rate.map(|_| GaugeEffect::SpringRate);
        let o = with(false, k);
        let free = fit_gauge_from(model, alpha_range_rad, drive, record, &o, Some(&start))?;
        let passes =
            fit.rmse_n <= MIN_IMPROVEMENT * free.rmse_n && res.excess_ratio <= MODEL_ERROR_RATIO;
        tried.push((GaugeEffect::SensorOffset, fit.rmse_n, free.rmse_n, passes));
        if passes {
            named.push(GaugeEffect::SensorOffset);
        }
    }
    if !named.is_empty() {
        // The plain model (no zero, no k): the RMSE before and the curve for plots.
        let start = base.friction_start();
        let p = fit_gauge_from(
            model,
            alpha_range_rad,
            drive,
            record,
            &with(false, None),
            Some(&start),
        )?;
        let r = diagnose(record, &p.fitted_n, p.noise_floor_n);
        plain = Some((p, r));
    }
    let verdict = match named.first() {
        _ if !res.trusted() => GaugeVerdict::Unexplained,
        Some(e) => GaugeVerdict::Named(*e),
        None => GaugeVerdict::None,
    };
    if verdict == GaugeVerdict::Unexplained {
        // Structure remains: no effect is named beside it (the verdict says the model misses
        // something; a name would suggest it was found).
        named.clear();
        plain = None;
    }
    Ok(GaugeLoop {
        verdict,
        named,
        fit,
        residual: res,
        plain,
        tried,
    })
}

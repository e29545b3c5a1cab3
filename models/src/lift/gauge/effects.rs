//! What a gauge fit leaves (issue 16/17 style): the residual against the gauge's noise, and the
//! effects tried when it shows a model error — `sensor_offset`, `spring_rate`, else `unexplained`.
//!
//! Protocol (each number stated here):
//! - Noise: σ̂_d from the residual's first differences *within* each branch (√(mean Δr²/2)):
//!   a misfit is slow over the heights, the gauge's noise is not. Floored at the fit's σ₀ =
//!   max(`gauge_noise_n`, resolution/√12), the noise its intervals assume.
//! - Excess: RMS(residual)/max(σ̂_d, σ₀). Whiteness: the pooled within-branch lag-1
//!   autocorrelation ρ₁ against its one-sided p = [`crate::stats::WHITENESS_P`] bound for white
//!   noise, z₀.₉₉₉/√m (m the pairs): a slow misfit makes neighbours alike.
//! - Effects are tried when the excess exceeds the lift's [`EFFECT_TRY_RATIO`] (1.5) or the
//!   residual is not white: each a refit with one more parameter ([`GaugeEffect`]). One is named
//!   only when its refit's RMSE is at most [`MIN_IMPROVEMENT`] (half) of the plain fit's, its
//!   interval excludes the null value (b = 0 N, k = 1), and its refit is back within the lift's
//!   [`MODEL_ERROR_RATIO`] (3) of the noise; of those, the lowest BIC (n·ln(RSS/n) + k·ln n).
//! - A named effect's fit replaces the plain one: the friction comes from the augmented fit, so
//!   an offset gauge or another spring is a finding on the gauge or the spring, never a joint alarm.
//! - Nothing named and the plain residual over [`MODEL_ERROR_RATIO`] or not white: `unexplained`,
//!   the joints withheld (`report`); within it: `none`, the plain fit stands.

use super::super::dynamics::LiftModel;
use super::super::static_force::DriveLine;
use super::GaugeRecord;
use super::fit::{GaugeEffect, GaugeFit, GaugeFitOptions, fit_gauge_from};
use crate::stats::{WHITENESS_P, normal_quantile};

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
    /// An effect explains it (its fit replaced the plain one).
    Named(GaugeEffect),
    /// Structure remains that no effect explains: the joints are withheld.
    Unexplained,
}

/// The residual loop's outcome: the verdict, the fit the joints come from, the plain one, and
/// each fit's diagnosis.
#[derive(Debug, Clone)]
pub struct GaugeLoop {
    pub verdict: GaugeVerdict,
    pub fit: GaugeFit,
    pub residual: GaugeResidual,
    /// With a named effect: the plain fit and its diagnosis.
    pub plain: Option<(GaugeFit, GaugeResidual)>,
    /// Every effect tried: (effect, refit RMSE N, passed the margins).
    pub tried: Vec<(GaugeEffect, f64, bool)>,
}

/// The plain fit of `record`, then, if it leaves a model error, each [`GaugeEffect`] (module
/// doc). `opts.effect` is ignored (the loop sets it).
pub fn fit_with_effects(
    model: &LiftModel,
    alpha_range_rad: (f64, f64),
    drive: &DriveLine,
    record: &GaugeRecord,
    opts: &GaugeFitOptions,
) -> Result<GaugeLoop, super::GaugeError> {
    let plain_opts = GaugeFitOptions {
        effect: None,
        ..opts.clone()
    };
    let plain = fit_gauge_from(model, alpha_range_rad, drive, record, &plain_opts, None)?;
    let res = diagnose(record, &plain.fitted_n, plain.noise_floor_n);
    if !res.try_effects() {
        return Ok(GaugeLoop {
            verdict: GaugeVerdict::None,
            fit: plain,
            residual: res,
            plain: None,
            tried: Vec::new(),
        });
    }
    let n = record.len() as f64;
    let mut tried = Vec::new();
    let mut best: Option<(f64, GaugeEffect, GaugeFit, GaugeResidual)> = None;
    for e in GaugeEffect::ALL {
        let o = GaugeFitOptions {
            effect: Some(e),
            ..opts.clone()
        };
        // Warm at the plain fit's friction, the effect at its null value.
        let mut start = plain.start_point();
        start.push(e.null_value());
        let fit = match fit_gauge_from(model, alpha_range_rad, drive, record, &o, Some(&start)) {
            Ok(f) => f,
            Err(super::GaugeError::Failed(_)) => continue,
            Err(err) => return Err(err),
        };
        let r = diagnose(record, &fit.fitted_n, fit.noise_floor_n);
        let passes = fit.rmse_n <= MIN_IMPROVEMENT * plain.rmse_n
            && fit.effect.is_some_and(|x| x.excludes_null())
            && r.excess_ratio <= MODEL_ERROR_RATIO;
        tried.push((e, fit.rmse_n, passes));
        if passes {
            let bic = n * (fit.rmse_n * fit.rmse_n).max(f64::MIN_POSITIVE).ln() + n.ln();
            if best.as_ref().is_none_or(|(b, ..)| bic < *b) {
                best = Some((bic, e, fit, r));
            }
        }
    }
    Ok(match best {
        Some((_, e, fit, r)) => GaugeLoop {
            verdict: GaugeVerdict::Named(e),
            fit,
            residual: r,
            plain: Some((plain, res)),
            tried,
        },
        None => GaugeLoop {
            verdict: if res.trusted() {
                GaugeVerdict::None
            } else {
                GaugeVerdict::Unexplained
            },
            fit: plain,
            residual: res,
            plain: None,
            tried,
        },
    })
}

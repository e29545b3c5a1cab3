//! Effects a lift fit can name when its residual shows a model error (issue 16, point 2 in part):
//! so far `quadratic_drag` on the head and `sensor_delay` of H; anything else stays `unexplained`.
//!
//! `quadratic_drag` (contract vocabulary): the air's force c_a·v|v| against the strip's
//! vertical velocity ([`LiftModel::head_drag_n`]; parameter `c_a_ns2_per_m2`, N/(m/s)², prior
//! N(0, 5²) cut to [0, 50]: [`super::identify::effect_prior`]). Where it shows: a lift that
//! rises slower and lowers faster than the friction alone explains, the misfit growing with
//! the strip speed squared. Estimation: one fit with c_a among the parameters
//! (`LiftFitOptions::effect_params`); its interval is the posterior's (H noise scale κ², as the
//! friction's).
//!
//! `sensor_delay` (contract vocabulary): the logger's H is the strip's height τ seconds earlier,
//! H_meas(t) = H(t − τ) ([`LiftModel::h_sensor_delay_s`]). Where it shows: a residual that
//! follows the strip speed, r ≈ −τ·Ḣ. Estimation: one fit with τ among the parameters
//! (`LiftFitOptions::effect_params`): the model's H read τ late, linear between samples,
//! ∂H/∂τ = −Ḣ (`identify`); prior sd 0.1 s in [0, [`MAX_DELAY_S`]], nearly flat. Its interval
//! is the posterior's, widened by [`DELAY_INTERVAL_SCALE`] as the drag's.
//!
//! Acceptance, the same for every effect (stated choices): the refit's residual back under
//! `residual::MODEL_ERROR_RATIO`, its RMS at most half the base fit's ([`MIN_IMPROVEMENT`]),
//! the parameter's 95 % interval excluding 0, and the parameter within its range (a delay in
//! [`MIN_DELAY_S`] (one sample at 500 Hz: below it a delay is not detectable) to
//! [`MAX_DELAY_S`]; a drag below its prior's upper bound). Which is tried first and how a
//! second candidate is judged: `report::fit_lift_trace`.

use super::dynamics::LiftModel;
use super::identify::{LiftFit, LiftFitError, LiftFitOptions, LiftTrace, effect_prior, fit_map};
use super::sensitivity::LiftParam;

/// Longest delay tried, s: a logger's H lag is tens of ms; 0.2 s is a slow filter, not a lag.
pub const MAX_DELAY_S: f64 = 0.2;
/// Shortest delay named, s: one sample at the stand's 500 Hz.
pub const MIN_DELAY_S: f64 = 0.002;
/// The refit must bring the H residual RMS to at most this share of the base fit's.
pub const MIN_IMPROVEMENT: f64 = 0.5;

/// A named H delay and the fit with it.
#[derive(Debug, Clone)]
pub struct DelayFinding {
    pub delay_s: f64,
    pub delay_ci95_s: [f64; 2],
    pub fit: LiftFit,
}

/// The posterior sd of a fit with `quadratic_drag` is multiplied by this (every parameter's).
/// Measured (`examples/lift_effects_probe -- 12 drag:2 drag:4 drag:8`, realistic noise, seeds
/// 0–11, 27 lifts named): the plain posterior's c_a sd was 0.07 N/(m/s)² against errors of
/// up to 0.5 (RMS z 2.8): the drag's regressor v|v| comes from the motion the noisy drive
/// torque drives, so the inputs' noise, which the plain fit's κ² covers, enters c_a and the
/// friction correlated with it several times over. Checked on fresh seeds 12–19 (c_a 2, 4, 8,
/// 4 with J3 dry ×2, 6 with J3 ×0.4, 8 with J3 ×2): 33 of 33 intervals held the truth, RMS z
/// 0.9–1.1; at twice the noise 4 of 4 (RMS z 1.3).
pub const DRAG_INTERVAL_SCALE: f64 = 3.0;

/// `opts` with c_a fitted and the intervals scaled by [`DRAG_INTERVAL_SCALE`].
pub fn drag_options(opts: &LiftFitOptions) -> LiftFitOptions {
    LiftFitOptions {
        effect_params: vec![LiftParam::HeadDrag],
        interval_scale: DRAG_INTERVAL_SCALE,
        ..opts.clone()
    }
}

/// A named head drag and the fit with it.
#[derive(Debug, Clone)]
pub struct DragFinding {
    pub c_a_ns2_per_m2: f64,
    pub c_a_ci95: [f64; 2],
    pub fit: LiftFit,
}

/// Tries the `quadratic_drag` effect on a trace whose base fit `base` left a model error: one
/// fit with c_a added. `Ok(None)`: the drag does not explain it by the stated margins.
pub fn try_quadratic_drag(
    model: &LiftModel,
    trace: &LiftTrace,
    base: &LiftFit,
    opts: &LiftFitOptions,
) -> Result<Option<DragFinding>, LiftFitError> {
    let n = trace.strip_height_m.len();
    let base_rms = base.rmse_m.first().copied().unwrap_or(f64::NAN);
    let with_drag = drag_options(opts);
    let fit = match fit_map(model, std::slice::from_ref(trace), &with_drag) {
        Ok(f) => f,
        Err(LiftFitError::Failed(_)) => return Ok(None),
        Err(e) => return Err(e),
    };
    let Some(est) = fit.effects.first().cloned() else {
        return Ok(None);
    };
    let fitted = fit.fitted_height_m.first().cloned().unwrap_or_default();
    if fitted.len() != n {
        return Ok(None);
    }
    let r: Vec<f64> = trace
        .strip_height_m
        .iter()
        .zip(&fitted)
        .map(|(m, f)| m - f)
        .collect();
    let after = (r.iter().map(|v| v * v).sum::<f64>() / n as f64).sqrt();
    let diag = super::residual::diagnose(
        trace.inputs.t_s,
        &r,
        &fitted,
        trace.inputs.torque_nm,
        opts.h_noise_m,
    );
    let upper = effect_prior(LiftParam::HeadDrag).map_or(f64::INFINITY, |p| p.upper);
    let named = diag.trusted
        && after <= MIN_IMPROVEMENT * base_rms
        && est.value - 1.96 * est.posterior_sd > 0.0
        && est.ci95[1] < upper;
    Ok(named.then_some(DragFinding {
        c_a_ns2_per_m2: est.value,
        c_a_ci95: est.ci95,
        fit,
    }))
}

/// `h` read τ later: h(t + τ) by linear interpolation on `t_s`, the last sample held.
pub fn advance(t_s: &[f64], h: &[f64], tau_s: f64) -> Vec<f64> {
    let n = t_s.len().min(h.len());
    let mut out = Vec::with_capacity(n);
    let mut j = 0;
    for k in 0..n {
        let t = t_s[k] + tau_s;
        while j + 1 < n && t_s[j + 1] <= t {
            j += 1;
        }
        if j + 1 >= n {
            out.push(h[n - 1]);
        } else {
            let w = (t - t_s[j]) / (t_s[j + 1] - t_s[j]);
            out.push(h[j] + w.clamp(0.0, 1.0) * (h[j + 1] - h[j]));
        }
    }
    out
}

/// The posterior sd of a fit with `sensor_delay` is multiplied by this (every parameter's), as
/// [`DRAG_INTERVAL_SCALE`] for the drag: the delay's regressor Ḣ comes from the motion the
/// noisy inputs drive. Measured: see the README's lift-effects score.
pub const DELAY_INTERVAL_SCALE: f64 = 3.0;

/// `opts` with the H delay fitted and the intervals scaled by [`DELAY_INTERVAL_SCALE`].
pub fn delay_options(opts: &LiftFitOptions) -> LiftFitOptions {
    LiftFitOptions {
        effect_params: vec![LiftParam::SensorDelay],
        interval_scale: DELAY_INTERVAL_SCALE,
        ..opts.clone()
    }
}

/// Tries the `sensor_delay` effect on a trace whose base fit `base` left a model error: one fit
/// with τ among the parameters (the model's H read τ late, `identify`). `Ok(None)`: no delay
/// explains it by the stated margins (the verdict stays `unexplained`).
pub fn try_sensor_delay(
    model: &LiftModel,
    trace: &LiftTrace,
    base: &LiftFit,
    opts: &LiftFitOptions,
) -> Result<Option<DelayFinding>, LiftFitError> {
    let n = trace.strip_height_m.len();
    let base_rms = base.rmse_m.first().copied().unwrap_or(f64::NAN);
    let fit = match fit_map(model, std::slice::from_ref(trace), &delay_options(opts)) {
        Ok(f) => f,
        Err(LiftFitError::Failed(_)) => return Ok(None),
        Err(e) => return Err(e),
    };
    let Some(est) = fit.effects.first().cloned() else {
        return Ok(None);
    };
    // The delayed model's H: what the logger would have recorded.
    let fitted = fit.fitted_height_m.first().cloned().unwrap_or_default();
    if fitted.len() != n {
        return Ok(None);
    }
    let r: Vec<f64> = trace
        .strip_height_m
        .iter()
        .zip(&fitted)
        .map(|(m, f)| m - f)
        .collect();
    let after = (r.iter().map(|v| v * v).sum::<f64>() / n as f64).sqrt();
    let diag = super::residual::diagnose(
        trace.inputs.t_s,
        &r,
        &fitted,
        trace.inputs.torque_nm,
        opts.h_noise_m,
    );
    let tau = est.value;
    // The interval: the posterior's sd (× DELAY_INTERVAL_SCALE) and a quarter of the sampling
    // interval in quadrature, for the timing error the posterior does not see: the inputs'
    // noise shifts the model's timing by a realisation-dependent amount. Measured
    // (`examples/lift_effects_probe`, realistic noise, seeds 0–7): two delays, 20 and 40 ms,
    // on the same noise seed both read 1.5–1.6 ms short with posterior sds of 0.45 ms.
    let t = trace.inputs.t_s;
    let dt_s = (t[t.len() - 1] - t[0]) / (t.len() - 1).max(1) as f64;
    let sd = (est.posterior_sd.powi(2) + (dt_s / 4.0).powi(2)).sqrt();
    let ci = [tau - 1.96 * sd, tau + 1.96 * sd];
    let named = diag.trusted
        && after <= MIN_IMPROVEMENT * base_rms
        && (MIN_DELAY_S..MAX_DELAY_S).contains(&tau)
        && ci[0] > 0.0;
    Ok(named.then_some(DelayFinding {
        delay_s: tau,
        delay_ci95_s: ci,
        fit,
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn advance_reads_the_record_later_and_holds_its_end() {
        let t: Vec<f64> = (0..6).map(|k| k as f64 * 0.002).collect();
        let h: Vec<f64> = (0..6).map(|k| k as f64).collect();
        let a = advance(&t, &h, 0.003);
        assert!(
            (a[0] - 1.5).abs() < 1e-12 && (a[3] - 4.5).abs() < 1e-12,
            "{a:?}"
        );
        assert_eq!(a[5], 5.0);
        assert_eq!(advance(&t, &h, 0.0), h);
        let v = crate::lift::residual::speed(&t, &h);
        assert!(v.iter().all(|x| (x - 500.0).abs() < 1e-9), "{v:?}");
    }
}

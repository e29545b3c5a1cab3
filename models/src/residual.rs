//! What the fit leaves unexplained: the residual block of the fit result, judged on a part of
//! the trace held out of the fits.
//!
//! The trace's free motion is split: the first `1 − holdout` is fitted, the rest only predicted.
//! A sensor zero the base fit estimates is reported as the effect `sensor_offset` when its
//! 95 % interval excludes zero (the paper's model has none).

use crate::identify::{
    FitError, FitOptions, FitOutcome, FitSpec, InitialEstimate, JointTest, Param, fit_window,
    predict,
};
use crate::report::{EffectResult, ResidualResult};

/// Share of the free motion held out of the fits (the end of the trace).
pub const HOLDOUT_FRACTION: f64 = 0.25;

fn rmse(a: &[f64], b: &[f64]) -> f64 {
    if a.is_empty() {
        return f64::NAN;
    }
    (a.iter().zip(b).map(|(x, y)| (x - y).powi(2)).sum::<f64>() / a.len() as f64).sqrt()
}

/// The base model fitted on the first part, judged on the held-out part.
#[derive(Debug, Clone)]
pub struct Split {
    pub fit: FitOutcome,
    pub n_fit: usize,
    pub rmse_fit: f64,
    pub rmse_holdout: f64,
}

/// Refit `spec` on the first part of the free motion (warm-started from `full`), predict the rest.
pub fn split_fit(
    test: &JointTest,
    full: &FitOutcome,
    spec: &FitSpec,
    opts: &FitOptions,
) -> Result<Split, FitError> {
    let start = full.start;
    let n = test.t_s.len() - start;
    let n_fit = ((n as f64) * (1.0 - HOLDOUT_FRACTION)).round() as usize;
    let mut spec = spec.clone();
    spec.law = full.law;
    let init = InitialEstimate {
        viscous: full.law.viscous,
        dry: full.law.dry,
        offset: full.offset,
        q0: full.q0,
        v0: full.v0,
    };
    let fit = fit_window(test, start, n_fit, &spec, &init, opts)?;
    let pred = predict(test, &fit, test.t_s.len(), opts)?;
    let rmse_holdout = rmse(&pred[n_fit..], &test.y[start + n_fit..]);
    Ok(Split {
        rmse_fit: fit.rmse,
        fit,
        n_fit,
        rmse_holdout,
    })
}

/// The residual block for the base model alone (no candidate effects tried).
pub fn base_residual(
    test: &JointTest,
    full: &FitOutcome,
    opts: &FitOptions,
) -> Result<ResidualResult, FitError> {
    let spec = FitSpec {
        law: full.law,
        free: full
            .spec_params
            .iter()
            .filter_map(|p| {
                if let Param::Dyn(d) = p {
                    Some(*d)
                } else {
                    None
                }
            })
            .collect(),
        fit_offset: full.spec_params.contains(&Param::Offset),
    };
    let split = split_fit(test, full, &spec, opts)?;
    let mut effects = Vec::new();
    if let Some(e) = sensor_offset_effect(full, test.unit) {
        effects.push(e);
    }
    Ok(ResidualResult {
        effects,
        rmse_before: split.rmse_fit,
        rmse_after: split.rmse_fit,
        holdout_rmse_before: split.rmse_holdout,
        holdout_rmse_after: split.rmse_holdout,
        verdict: None,
    })
}

/// `sensor_offset` when the fitted zero's interval excludes 0.
pub fn sensor_offset_effect(full: &FitOutcome, unit: &str) -> Option<EffectResult> {
    let (v, _, ci) = full.get(Param::Offset)?;
    if ci[0] > 0.0 || ci[1] < 0.0 {
        let mut params = serde_json::Map::new();
        params.insert(format!("offset_{unit}"), serde_json::json!(v));
        params.insert("ci95".into(), serde_json::json!(ci));
        Some(EffectResult {
            name: "sensor_offset".into(),
            params,
        })
    } else {
        None
    }
}

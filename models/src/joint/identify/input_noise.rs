//! What a measured input's sensor noise adds to a single-joint fit's covariance (issue 17,
//! point 3; the lift's counterpart is `lift::input_noise`): errors in the inputs, not only in
//! the position channel.
//!
//! The model is driven by the recorded force or torque; its noise moves the simulated motion,
//! which the fit absorbs into the parameters — it barely shows in the residual, so the sandwich
//! of the residual misses it (measured: an input-driven slider's force-zero interval held the
//! truth in 1 of 4 traces without it). A linearised parametric bootstrap: for each of
//! [`DRAWS`] draws, white noise at the input's estimated sd is added to the recorded input, the
//! model at the estimate is run on it, and the change Δy is mapped to the parameters by the
//! fit's own linear response δx = (JᵀJ)⁻¹Jᵀ·Δy; the covariance of the δx is added.
//! Assumptions (stated): the input's sensor noise is white at its sampling rate, its sd read
//! off the second differences (1.4826·median|Δ²u|/√6, robust to steps; a smooth drive's own
//! second difference is far
//! below it at logger rates, and the logger's step is part of that noise); the response is
//! linear over the noise's effect; the draws are seeded (a deterministic result).

use nalgebra::{DMatrix, DVector};

use super::{BodyTerms, FitOptions, FitOutcome, JointTest, intervals, lower_bounds_of, readout};
use crate::joint::dynamics::Dof;
use crate::joint::simulate::SimOptions;

/// Noise draws per fit: one plain simulation each (a single-joint run: ~1 ms).
pub const DRAWS: usize = 16;

/// The input's white-noise sd from its second differences; 0 for fewer than 4 samples.
pub fn input_noise_sd(values: &[f64]) -> f64 {
    if values.len() < 4 {
        return 0.0;
    }
    // Robust: the median absolute second difference (×1.4826 for a normal's sd), so a step
    // in the drive (the head drop's release) is not read as noise.
    let mut d2: Vec<f64> = values
        .windows(3)
        .map(|w| (w[2] - 2.0 * w[1] + w[0]).abs())
        .collect();
    d2.sort_by(f64::total_cmp);
    let mad = d2[d2.len() / 2];
    1.4826 * mad / 6f64.sqrt()
}

/// The covariance the input's noise adds to the estimate. `run` simulates the model at the
/// estimate on a degree of freedom and returns its readings over the fitted samples (`None`:
/// the draw could not be run, and is left out); `y0` the readings at the estimate on the
/// recorded input; `jac` the fit's Jacobian there. `None` without an input or without noise.
pub fn covariance(
    dof: &Dof,
    jac: &DMatrix<f64>,
    y0: &[f64],
    run: impl Fn(&Dof) -> Option<Vec<f64>>,
) -> Option<DMatrix<f64>> {
    let input = dof.input.as_ref()?;
    let sd = input_noise_sd(&input.value);
    if sd == 0.0 || !sd.is_finite() {
        return None;
    }
    let p = jac.ncols();
    let jtj = jac.tr_mul(jac);
    let svd = jtj.svd(true, true);
    let smax = svd.singular_values.max();
    let ainv = svd.pseudo_inverse(smax * 1e-13).ok()?;
    let mut rng = crate::numerics::noise::Noise::new(0x5eed_1a7e);
    let mut sum = DMatrix::zeros(p, p);
    let mut used = 0usize;
    for _ in 0..DRAWS {
        let mut d = dof.clone();
        if let Some(i) = &mut d.input {
            for v in &mut i.value {
                *v += sd * rng.normal();
            }
        }
        let Some(y) = run(&d) else { continue };
        if y.len() != y0.len() {
            continue;
        }
        let dy = DVector::from_iterator(y.len(), y.iter().zip(y0).map(|(a, b)| a - b));
        let dx = &ainv * jac.tr_mul(&dy);
        sum += &dx * dx.transpose();
        used += 1;
    }
    (used > 0).then(|| sum / used as f64)
}

/// `fit` with its measured input's share of the covariance ([`covariance`]) added and its
/// standard errors and intervals derived again, when [`super::fit_window_deferred`] left it
/// pending; else `fit` as it is. The same draws, hence the same covariance, as a fit that added
/// it at once.
pub fn carry(test: &JointTest, mut fit: FitOutcome, opts: &FitOptions) -> FitOutcome {
    let Some(jac) = fit.pending_jacobian.take() else {
        return fit;
    };
    let adjusted = BodyTerms {
        inertia_log: fit.inertia_log,
        input_offset: fit.input_offset,
    }
    .apply(&test.dof);
    let times = &test.t_s[fit.start..fit.start + fit.n_fit];
    let sim = SimOptions {
        tol: opts.tol,
        sens: vec![],
    };
    let run = |d: &Dof| {
        readout::read(
            d,
            &fit.law,
            fit.q0,
            fit.v0,
            &fit.readout,
            times,
            &sim,
            test.scale,
            false,
            false,
        )
        .ok()
        .map(|r| r.y)
    };
    if let Some(extra) = covariance(&adjusted, &jac, &fit.model_y, run) {
        fit.covariance.cov += extra;
        let lb = lower_bounds_of(&fit.spec_params);
        (fit.std, fit.ci95) = intervals(&fit.values, &fit.covariance, &lb);
    }
    fit
}

#[cfg(test)]
mod tests {
    use super::input_noise_sd;

    #[test]
    fn the_input_noise_is_read_off_second_differences_not_the_drive() {
        let mut rng = crate::numerics::noise::Noise::new(3);
        let t: Vec<f64> = (0..3000).map(|k| k as f64 / 500.0).collect();
        let clean: Vec<f64> = t.iter().map(|x| 150.0 * (2.5 * x).sin()).collect();
        assert!(
            input_noise_sd(&clean) < 0.01,
            "a smooth drive reads as (almost) no noise"
        );
        let noisy: Vec<f64> = clean.iter().map(|v| v + 0.2 * rng.normal()).collect();
        let sd = input_noise_sd(&noisy);
        assert!((sd / 0.2 - 1.0).abs() < 0.05, "sd {sd}");
        // A step in the drive (a release) is no noise.
        let step: Vec<f64> = (0..3000)
            .map(|k| if k < 250 { -98.1 } else { 0.0 })
            .collect();
        assert_eq!(input_noise_sd(&step), 0.0);
    }
}

//! The design's final prediction (issue 15, point 3): a parametric bootstrap of the protocol —
//! simulated lifts at Table 4 with the stand's noise on every channel, each fitted exactly as
//! the service fits a lift, the spread of their estimates.
//!
//! Why not the linearised prediction (`Prediction::sd_sampling`): it maps the inputs' noise to
//! the parameters through the fit's linear response at Table 4, and that response is not what
//! the fit does. Measured over 16 realistic-noise lifts per protocol (`examples/lift_design`),
//! the linearised spread of J3 dry was 2× the realised on the designed protocol and 10× on the
//! raise and lower. More draws do not close it (48 instead of 12: J3 dry's linearised posterior
//! sd 0.064 designed, 0.142 raise and lower, against 0.056 and 0.138), and the H channel's share
//! is off too: with H noise alone, J3 dry realised 0.001 on the designed protocol against the
//! Fisher spread's 0.007 (`PW_APPLY=h`; inputs' noise alone: 0.023 against 0.047). The likely
//! reason: J3 trades off with the torque offset and weakly informed parameters nonlinearly, so
//! the local sensitivities at Table 4 do not describe the fit's response to either noise. A
//! re-weighting of the same linear response (a sandwich with the same Jacobian) cannot fix a
//! wrong H share, so it was not pursued; a simulated fit carries all of that by construction.
//! The linearised numbers stay as the design's *criterion* (they rank candidates cheaply, one
//! simulation per draw) and are printed as the Fisher numbers; the spread here is only computed
//! for the protocols a user is shown.

use super::{DesignError, LiftModel, LiftParam, LiftProtocol, LiftSensorNoise, SimOptions, record};
use crate::lift::batch::fit_many;
use crate::lift::identify::LiftFitOptions;

/// Simulated lifts per protocol in the final prediction. The sample sd of K fits has a relative
/// standard error of about 1/√(2(K − 1)) for normal estimates, 9 % at 64 against 18 % for the 16
/// lifts the design test realises, and J3 dry's estimates have heavier tails: its simulated sd
/// on the designed protocol was 0.031 over the first 32 seeds and 0.025 over 64, against 0.023
/// and 0.024 realised on seeds 7000–7015 and 8000–8015. 64 keeps the prediction's own sampling
/// error the small share of a 1.5× comparison. Cost: ~0.1 s per fit at the stand's noise
/// (release), ~3 s per protocol on 2 cores.
pub const SIMULATED_FITS: usize = 64;

/// First noise seed of the simulated lifts (seeds `SIMULATED_SEED0 ..`): disjoint from the
/// design test's realisation seeds (7000–7015) and the coverage sets' (1000–1023), so the test
/// compares the prediction with lifts it has not seen.
pub const SIMULATED_SEED0: u64 = 9000;

/// The spread of fitted estimates over simulated lifts of one protocol at Table 4.
#[derive(Debug, Clone)]
pub struct SimulatedSpread {
    /// The parameters, in the order of [`super::Prediction::params`] (friction, then the
    /// torque offset).
    pub params: Vec<LiftParam>,
    /// Sample sd of each estimate over the fits that ran (friction relative to Table 4,
    /// offset in N·m): the predicted sd of one test's estimate.
    pub sd: Vec<f64>,
    /// Mean of each estimate (same units; Table 4 is 1): a mean off 1 by more than sd/√K is
    /// the fit's bias on this protocol.
    pub mean: Vec<f64>,
    /// Share of the fits that *report* each parameter (issue 36, point 6): informed on its own
    /// or a member of an informed combination (`lift::absorbed::reported_params`, what a lift's
    /// result judges and alerts on); the torque offset, a nuisance, 0. The design's `informed`
    /// is the Fisher information's verdict; this is what the fit will say.
    pub reported: Vec<f64>,
    /// The combination a reported parameter was reported in, in most fits (`J1+J3 dry`), if
    /// any.
    pub reported_in: Vec<Option<String>>,
    /// Lifts simulated and fitted.
    pub fits: usize,
    /// Of those, fits that failed (left out of the spread).
    pub failed: usize,
}

impl SimulatedSpread {
    /// The predicted sd of parameter `p`, if it is one of the spread's.
    pub fn sd_of(&self, p: LiftParam) -> Option<f64> {
        self.params.iter().position(|q| *q == p).map(|i| self.sd[i])
    }
}

/// Simulate `fits` lifts of `protocol` at Table 4 (`model`) with `noise` on every channel
/// (`LiftSensorNoise::apply`, seeds `seed0 .. seed0 + fits`), fit each on its own as the
/// service does (`batch::fit_many`, `fit_map` of one trace with `opts`) on `threads` workers,
/// and return the spread of the estimates of `params`. `progress(done)` after each fit.
/// Assumptions: the truth is Table 4 (a worn pantograph's spread may differ, as the linearised
/// design also assumes); the stand's noise is `noise`, white plus logger steps, independent
/// between channels and lifts. Errors when fewer than 3 fits ran (no spread to estimate).
#[allow(clippy::too_many_arguments)]
pub fn simulated_spread(
    model: &LiftModel,
    protocol: &LiftProtocol,
    params: &[LiftParam],
    noise: &LiftSensorNoise,
    opts: &LiftFitOptions,
    fits: usize,
    seed0: u64,
    threads: Option<std::num::NonZeroUsize>,
    progress: &(dyn Fn(usize) + Sync),
) -> Result<SimulatedSpread, DesignError> {
    let clean =
        record(model, protocol, &SimOptions::default()).map_err(|e| DesignError::Fit(e.into()))?;
    let recs: Vec<_> = (0..fits as u64)
        .map(|k| noise.apply(&clean, seed0 + k))
        .collect();
    let traces: Vec<_> = recs.iter().map(|r| r.trace()).collect();
    let results = fit_many(model, &traces, opts, threads, progress);
    // Each fit's estimate of every parameter: friction over Table 4, the offset in N·m.
    let est: Vec<Vec<f64>> = results
        .iter()
        .filter_map(|r| r.as_ref().ok())
        .map(|f| {
            params
                .iter()
                .map(|p| {
                    if *p == LiftParam::TorqueOffset {
                        f.offsets.first().map_or(f64::NAN, |o| o.map_value)
                    } else {
                        f.params
                            .iter()
                            .find(|e| e.param == *p)
                            .map_or(f64::NAN, |e| e.map_value / e.baseline)
                    }
                })
                .collect()
        })
        .collect();
    let (reported, reported_in) = reported_share(params, &results);
    let n = est.len();
    if n < 3 {
        return Err(DesignError::Statics(format!(
            "only {n} of {fits} simulated lifts could be fitted: no spread to predict"
        )));
    }
    let mean: Vec<f64> = (0..params.len())
        .map(|i| est.iter().map(|e| e[i]).sum::<f64>() / n as f64)
        .collect();
    let sd = (0..params.len())
        .map(|i| {
            let ss: f64 = est.iter().map(|e| (e[i] - mean[i]).powi(2)).sum();
            (ss / (n - 1) as f64).sqrt()
        })
        .collect();
    Ok(SimulatedSpread {
        params: params.to_vec(),
        sd,
        mean,
        reported,
        reported_in,
        fits,
        failed: fits - n,
    })
}

/// Per parameter of `params`: the share of the fits in `results` that report it
/// ([`SimulatedSpread::reported`]) and the combination label it was reported in most often.
fn reported_share(
    params: &[LiftParam],
    results: &[Result<crate::lift::fit::LiftFit, crate::lift::fit::LiftFitError>],
) -> (Vec<f64>, Vec<Option<String>>) {
    let fits: Vec<_> = results.iter().filter_map(|r| r.as_ref().ok()).collect();
    let n = fits.len().max(1) as f64;
    let mut share = Vec::with_capacity(params.len());
    let mut label = Vec::with_capacity(params.len());
    for p in params {
        let mut labels: std::collections::BTreeMap<String, usize> = Default::default();
        let mut count = 0usize;
        for f in &fits {
            if crate::lift::absorbed::reported_params(f).contains(p) {
                count += 1;
                if let Some(c) = f
                    .params
                    .iter()
                    .find(|e| e.param == *p)
                    .and_then(|e| e.combination)
                    .and_then(|c| f.combinations.get(c))
                {
                    *labels.entry(c.label()).or_default() += 1;
                }
            }
        }
        share.push(count as f64 / n);
        label.push(
            labels
                .into_iter()
                .max_by_key(|(_, k)| *k)
                .filter(|(_, k)| 2 * k > count)
                .map(|(l, _)| l),
        );
    }
    (share, label)
}

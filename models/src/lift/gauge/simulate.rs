//! A simulated force-gauge record (for tests, the demo and the CLI's `simulate`): the statics'
//! readings, optionally with a gauge offset or another spring rate, white noise, then the gauge's steps.
//!
//! Assumed gauge (`models/data/160ec.toml`, `[static_force]`): noise `gauge_noise_n` (0.2 N,
//! one sd, white reading to reading), resolution `gauge_sim_resolution_n` (0.1 N); the noise is
//! added before the quantisation, as a gauge's display rounds what its cell reads. The random
//! source is the project's ([`crate::numerics::noise::Noise`]): a seed gives the same record everywhere.

use super::super::dynamics::LiftModel;
use super::super::static_force::DriveLine;
use super::solve::predicted_forces_n;
use super::{GaugeError, GaugeRecord, gauge_data};
use crate::numerics::noise::Noise;

/// How a gauge record is simulated.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GaugeSimOptions {
    /// White noise on every reading, one sd, N.
    pub noise_sd_n: f64,
    /// The gauge's resolution, N (readings rounded to it; also the record's stated one).
    pub resolution_n: f64,
    pub seed: u64,
    /// `sensor_offset`: the gauge's zero, N (F_meas = F + b); 0: none.
    pub offset_n: f64,
    /// `spring_rate`: the drive characteristic's slope × this factor about its first point
    /// ([`spring_rate_drive`]); 1: the type's.
    pub spring_rate_factor: f64,
}

impl Default for GaugeSimOptions {
    /// The assumed gauge (module doc), seed 0, no effect.
    fn default() -> Self {
        let d = gauge_data();
        Self {
            noise_sd_n: d.gauge_noise_n,
            resolution_n: d.gauge_sim_resolution_n,
            seed: 0,
            offset_n: 0.0,
            spring_rate_factor: 1.0,
        }
    }
}

/// `drive` with its slope × `factor` about its first point (h0, t0): the torque there kept, the
/// rate of change with height scaled — a spring whose rate differs from the type's
/// ([`DriveLine::with_rate_factor`], where the prediction takes it too).
pub fn spring_rate_drive(drive: &DriveLine, factor: f64) -> DriveLine {
    drive.with_rate_factor(factor)
}

/// Reading heights over the built-in type's working range: `per_branch` equally spaced heights
/// up from the lowest to the highest, then `per_branch` down from the highest to the lowest (the
/// first reading at the top is the turn; the second, equal, opens the lowering branch).
pub fn reading_heights(per_branch: usize) -> Vec<f64> {
    let [lo, hi] = gauge_data().working_height_m;
    let n = per_branch.max(2);
    let up: Vec<f64> = (0..n)
        .map(|k| lo + (hi - lo) * k as f64 / (n - 1) as f64)
        .collect();
    let mut all = up.clone();
    all.extend(up.iter().rev());
    all
}

/// A gauge record of `model` driven by `drive` at `heights_m` (reading order, split at the
/// turn as [`GaugeRecord::new`] splits it): each reading the statics' strip force on its
/// branch, plus `opts`' effects and noise, rounded to the resolution. Errors: the heights (or
/// the options' resolution) as the record's own checks refuse them, or the model fails.
pub fn simulate_gauge(
    model: &LiftModel,
    alpha_range_rad: (f64, f64),
    drive: &DriveLine,
    heights_m: &[f64],
    opts: &GaugeSimOptions,
) -> Result<GaugeRecord, GaugeError> {
    let shape = GaugeRecord::new(
        heights_m.to_vec(),
        vec![0.0; heights_m.len()],
        opts.resolution_n,
    )?;
    let drive = spring_rate_drive(drive, opts.spring_rate_factor);
    let clean = predicted_forces_n(model, alpha_range_rad, &drive, &shape)?;
    let mut rng = Noise::new(opts.seed);
    let q = opts.resolution_n;
    let forces_n: Vec<f64> = clean
        .iter()
        .map(|f| {
            let v = f + opts.offset_n + opts.noise_sd_n * rng.normal();
            (v / q).round() * q
        })
        .collect();
    GaugeRecord::new(heights_m.to_vec(), forces_n, opts.resolution_n)
}

/// A gauge record of the built-in 160EC with each `(joint, factor)` of `dry_factors` applied to
/// its Table 4 dry μ, `per_branch` readings up and down the working range
/// ([`reading_heights`]), driven by the type's drive line: for the CLI's `simulate` and the demo.
pub fn simulate_builtin_gauge(
    dry_factors: &[(super::super::topology::RevJoint, f64)],
    per_branch: usize,
    opts: &GaugeSimOptions,
) -> Result<GaugeRecord, GaugeError> {
    let g = super::super::geometry::builtin_160ec();
    let mut model = LiftModel::new(g);
    for (j, k) in dry_factors {
        if !(k.is_finite() && *k >= 0.0) {
            return Err(GaugeError::Model(format!(
                "dry friction factor {k} of {} must be finite and >= 0",
                j.name()
            )));
        }
        model.friction.dry_mu[j.index()] *= k;
    }
    simulate_gauge(
        &model,
        (g.alpha_min_rad, g.alpha_max_rad),
        &DriveLine::from_lift_test(g),
        &reading_heights(per_branch),
        opts,
    )
}

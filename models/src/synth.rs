//! Synthetic measurements: simulate a test with chosen parameters, add white Gaussian noise and
//! quantise like a real sensor. Deterministic for a given seed.

use crate::dynamics::Dof;
use crate::friction::FrictionLaw;
use crate::noise::Noise;
use crate::simulate::{SimError, SimOptions, Trajectory, simulate};

/// How the sensor reads the motion.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sensor {
    /// Channel units per model unit (180/π for degrees, 1000 for mm).
    pub scale: f64,
    /// White Gaussian noise, channel units (standard deviation).
    pub noise_sigma: f64,
    /// Quantisation step, channel units (0: none).
    pub quantum: f64,
    /// Sensor zero added to every reading, channel units.
    pub offset: f64,
    pub seed: u64,
}

/// Simulate and read through the sensor. Returns the readings and the exact trajectory.
pub fn measure(
    dof: &Dof,
    law: &FrictionLaw,
    q0: f64,
    v0: f64,
    t_s: &[f64],
    sensor: &Sensor,
) -> Result<(Vec<f64>, Trajectory), SimError> {
    let tr = simulate(dof, law, q0, v0, t_s, &SimOptions::default())?;
    let mut rng = Noise::new(sensor.seed);
    let y =
        tr.q.iter()
            .map(|q| {
                let y = sensor.scale * q + sensor.offset + sensor.noise_sigma * rng.normal();
                if sensor.quantum > 0.0 {
                    (y / sensor.quantum).round() * sensor.quantum
                } else {
                    y
                }
            })
            .collect();
    Ok((y, tr))
}

/// An even time grid from 0 to `duration_s` at `fs_hz`.
pub fn grid(duration_s: f64, fs_hz: f64) -> Vec<f64> {
    let n = (duration_s * fs_hz).round() as usize;
    (0..=n).map(|i| i as f64 / fs_hz).collect()
}

//! Synthetic measurements: simulate a test with chosen parameters, add white Gaussian noise and
//! quantise like a real sensor. Deterministic for a given seed.

use crate::joint::dynamics::Dof;
use crate::joint::friction::FrictionLaw;
use crate::joint::simulate::{SimError, SimOptions, Trajectory, simulate};
use crate::numerics::noise::Noise;

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

/// What a synthetic trace is made with: the friction law (with any effects), the sensor-side
/// effects, and friction that fades during the test (an effect outside the vocabulary).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Truth {
    pub law: FrictionLaw,
    pub readout: crate::joint::identify::Readout,
    /// Share of μ lost linearly over the trace (0: none).
    pub dry_fade: f64,
}

/// Simulate `truth` and read through the sensor (noise and quantisation from `sensor`; the
/// sensor zero from `truth.readout.offset` plus `sensor.offset`).
pub fn measure_truth(
    dof: &Dof,
    truth: &Truth,
    q0: f64,
    v0: f64,
    t_s: &[f64],
    sensor: &Sensor,
) -> Result<Vec<f64>, SimError> {
    let clean: Vec<f64> = if truth.dry_fade == 0.0 {
        crate::joint::identify::readout::read(
            dof,
            &truth.law,
            q0,
            v0,
            &truth.readout,
            t_s,
            &SimOptions::default(),
            sensor.scale,
            false,
            false,
        )?
        .y
    } else {
        // Piecewise-constant μ over 0.25 s chunks, each continuing from the last state.
        let (t0, t_end) = (t_s[0], t_s[t_s.len() - 1]);
        let mut out = vec![0.0; t_s.len()];
        let (mut q, mut v) = (q0, v0);
        let mut a = 0;
        out[0] = sensor.scale * q0 + truth.readout.offset;
        while a + 1 < t_s.len() {
            let b = t_s
                .partition_point(|&t| t <= t_s[a] + 0.25)
                .min(t_s.len() - 1)
                .max(a + 1);
            let mut law = truth.law;
            law.dry *= 1.0 - truth.dry_fade * ((t_s[a] + t_s[b]) / 2.0 - t0) / (t_end - t0);
            let tr = simulate(dof, &law, q, v, &t_s[a..=b], &SimOptions::default())?;
            for k in a + 1..=b {
                out[k] = sensor.scale * tr.q[k - a] + truth.readout.offset;
            }
            q = tr.q[b - a];
            v = tr.v[b - a];
            a = b;
        }
        out
    };
    let mut rng = Noise::new(sensor.seed);
    Ok(clean
        .iter()
        .map(|c| {
            let y = c + sensor.offset + sensor.noise_sigma * rng.normal();
            if sensor.quantum > 0.0 {
                (y / sensor.quantum).round() * sensor.quantum
            } else {
                y
            }
        })
        .collect())
}

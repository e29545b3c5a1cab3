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

/// A measured-like record of a positioning axis driven by a recorded force (issue 38): a slider
/// with no spring, pushed by a force that moves it back and forth with rests between the
/// moves (the positioning benchmark's kind of record), read by a position sensor and a force
/// sensor with the stand's noise and the logger's steps on both channels.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DrivenAxis {
    pub moving_mass_kg: f64,
    /// N·s/m.
    pub viscous: f64,
    /// Fn of the dry friction Fn·μ, N.
    pub normal_force_n: f64,
    pub dry: f64,
    /// The force sensor reads this much below the acting force, N.
    pub input_offset_n: f64,
    /// Peak of the drive force, N.
    pub force_n: f64,
    pub fs_hz: f64,
    pub duration_s: f64,
    /// White noise of the recorded force (one sd per sample), N.
    pub force_noise_n: f64,
    /// The force logger's step, N (0: none).
    pub force_step_n: f64,
    /// White noise of the position (one sd per sample), mm.
    pub position_noise_mm: f64,
    /// The position logger's step, mm (0: none).
    pub position_step_mm: f64,
    pub seed: u64,
}

impl DrivenAxis {
    /// The drive force acting at `t`, N: moves of a few seconds (two tones, a cosine-tapered
    /// envelope) with a rest of 1 s in every 5 s, when the force is 0 and static friction holds.
    pub fn force_at(&self, t: f64) -> f64 {
        let tau = std::f64::consts::TAU;
        let cycle = t.rem_euclid(5.0);
        let envelope = if cycle < 4.0 {
            0.5 * (1.0 - (tau * cycle / 4.0).cos())
        } else {
            0.0
        };
        self.force_n
            * envelope
            * (0.75 * (tau * 0.5 * t).sin() + 0.25 * (tau * 2.3 * t + 1.0).sin())
    }

    /// The record: the test as the fit sees it (recorded force driving the stated axis, mm),
    /// and the acting force's law (the truth).
    pub fn record(&self) -> Result<crate::joint::identify::JointTest, SimError> {
        use crate::joint::dynamics::{Input, Mechanism};
        use crate::joint::rig::SliderRig;
        let t = grid(self.duration_s, self.fs_hz);
        let acting: Vec<f64> = t.iter().map(|&x| self.force_at(x)).collect();
        let mech = Mechanism::Slider(SliderRig {
            moving_mass_kg: self.moving_mass_kg,
            stiffness_n_per_m: 0.0,
            normal_force_n: self.normal_force_n,
        });
        let truth_dof = Dof {
            mech,
            input: Some(Input {
                t_s: t.clone(),
                value: acting.clone(),
            }),
            torsion: 0.0,
        };
        let sensor = Sensor {
            scale: 1000.0,
            noise_sigma: self.position_noise_mm,
            quantum: self.position_step_mm,
            offset: 0.0,
            seed: self.seed,
        };
        let truth = Truth {
            law: FrictionLaw::base(self.viscous, self.dry),
            readout: crate::joint::identify::Readout::default(),
            dry_fade: 0.0,
        };
        let y = measure_truth(&truth_dof, &truth, 0.0, 0.0, &t, &sensor)?;
        let mut rng = Noise::new(self.seed ^ 0xF0_2CE5);
        let recorded: Vec<f64> = acting
            .iter()
            .map(|f| {
                let v = f - self.input_offset_n + self.force_noise_n * rng.normal();
                if self.force_step_n > 0.0 {
                    (v / self.force_step_n).round() * self.force_step_n
                } else {
                    v
                }
            })
            .collect();
        Ok(crate::joint::identify::JointTest {
            dof: Dof {
                mech,
                input: Some(Input {
                    t_s: t.clone(),
                    value: recorded,
                }),
                torsion: 0.0,
            },
            t_s: t,
            y,
            scale: 1000.0,
            unit: "mm",
            initial_rate: None,
            release_t_s: None,
            body_sd: Vec::new(),
        })
    }
}

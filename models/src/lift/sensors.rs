//! What a stand's sensors and logger add to a lift record (issue 15): white noise on every
//! channel, inputs included, then the logger's quantisation.
//!
//! Assumed stand (stated here, used by the tests, the bench suite and `simulate --kind lift`):
//! - noise, white at the sampling rate, one standard deviation: height 0.5 mm, drive torque
//!   1 N·m, spring force and weight 0.2 N each — the floor the developers' brief asks every
//!   claim to be checked at;
//! - a 16-bit logger over each channel's range: height 0–3.3 m → 0.05 mm steps, torque
//!   ±2000 N·m → 0.05 N·m (0.061 rounded down to a decimal step), forces ±500 N → 0.02 N.
//!   Quantisation is applied after the noise, as a logger does.

use super::protocol::LiftRecord;
use crate::numerics::noise::Noise;

/// Sensor noise (standard deviations) and logger steps of a lift record's four channels.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LiftSensorNoise {
    pub h_sd_m: f64,
    pub torque_sd_nm: f64,
    pub fs_sd_n: f64,
    pub fm_sd_n: f64,
    pub h_step_m: f64,
    pub torque_step_nm: f64,
    pub force_step_n: f64,
}

impl LiftSensorNoise {
    /// The assumed stand (module doc): 0.5 mm, 1 N·m, 0.2 N, 0.2 N; 16-bit logger steps.
    pub fn realistic() -> Self {
        Self {
            h_sd_m: 0.5e-3,
            torque_sd_nm: 1.0,
            fs_sd_n: 0.2,
            fm_sd_n: 0.2,
            h_step_m: 0.05e-3,
            torque_step_nm: 0.05,
            force_step_n: 0.02,
        }
    }

    /// No noise and no quantisation: the model's channels as they are.
    pub fn none() -> Self {
        Self {
            h_sd_m: 0.0,
            torque_sd_nm: 0.0,
            fs_sd_n: 0.0,
            fm_sd_n: 0.0,
            h_step_m: 0.0,
            torque_step_nm: 0.0,
            force_step_n: 0.0,
        }
    }

    /// The same logger with every noise level × `k` (k = 2: the "twice that noise").
    pub fn scaled(&self, k: f64) -> Self {
        Self {
            h_sd_m: self.h_sd_m * k,
            torque_sd_nm: self.torque_sd_nm * k,
            fs_sd_n: self.fs_sd_n * k,
            fm_sd_n: self.fm_sd_n * k,
            ..*self
        }
    }

    /// The record as the logger writes it: noise from `seed` on every channel, then steps.
    /// Time stamps are kept exact (the logger's clock is taken as the sampling reference).
    pub fn apply(&self, rec: &LiftRecord, seed: u64) -> LiftRecord {
        let mut rng = Noise::new(seed);
        let mut channel = |x: &[f64], sd: f64, step: f64| -> Vec<f64> {
            x.iter()
                .map(|v| quantise(v + sd * rng.normal(), step))
                .collect()
        };
        LiftRecord {
            t_s: rec.t_s.clone(),
            strip_height_m: channel(&rec.strip_height_m, self.h_sd_m, self.h_step_m),
            torque_nm: channel(&rec.torque_nm, self.torque_sd_nm, self.torque_step_nm),
            fs_n: channel(&rec.fs_n, self.fs_sd_n, self.force_step_n),
            fm_n: channel(&rec.fm_n, self.fm_sd_n, self.force_step_n),
        }
    }
}

/// `v` rounded to the logger's step (`step` ≤ 0: unchanged).
fn quantise(v: f64, step: f64) -> f64 {
    if step > 0.0 {
        (v / step).round() * step
    } else {
        v
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn flat(n: usize) -> LiftRecord {
        LiftRecord {
            t_s: (0..n).map(|k| k as f64 * 0.002).collect(),
            strip_height_m: vec![1.04; n],
            torque_nm: vec![1110.0; n],
            fs_n: vec![18.0; n],
            fm_n: vec![78.5; n],
        }
    }

    /// Each channel's noise has the stated sd (within sampling error over 20,000 samples),
    /// lands on the logger's grid, and the same seed gives the same record.
    #[test]
    fn noise_has_the_stated_size_and_lands_on_the_logger_grid() {
        let rec = flat(20_000);
        let s = LiftSensorNoise::realistic();
        let noisy = s.apply(&rec, 3);
        let sd = |a: &[f64], b: &[f64]| {
            let n = a.len() as f64;
            (a.iter().zip(b).map(|(x, y)| (x - y).powi(2)).sum::<f64>() / n).sqrt()
        };
        let cases = [
            (
                &noisy.strip_height_m,
                &rec.strip_height_m,
                s.h_sd_m,
                s.h_step_m,
            ),
            (
                &noisy.torque_nm,
                &rec.torque_nm,
                s.torque_sd_nm,
                s.torque_step_nm,
            ),
            (&noisy.fs_n, &rec.fs_n, s.fs_sd_n, s.force_step_n),
            (&noisy.fm_n, &rec.fm_n, s.fm_sd_n, s.force_step_n),
        ];
        for (x, x0, want, step) in cases {
            let got = sd(x, x0);
            // sd of a quantised normal: √(σ² + q²/12); sampling error of the sd ≈ 0.5 %.
            let expect = (want * want + step * step / 12.0).sqrt();
            assert!((got / expect - 1.0).abs() < 0.03, "sd {got} vs {expect}");
            for v in x.iter() {
                let k = v / step;
                assert!((k - k.round()).abs() < 1e-6, "{v} off the {step} grid");
            }
        }
        assert_eq!(noisy, s.apply(&rec, 3));
        assert_ne!(noisy, s.apply(&rec, 4));
        assert_eq!(LiftSensorNoise::none().apply(&rec, 3), rec);
        let twice = s.scaled(2.0).apply(&rec, 3);
        let ratio = sd(&twice.torque_nm, &rec.torque_nm) / sd(&noisy.torque_nm, &rec.torque_nm);
        assert!((ratio - 2.0).abs() < 0.05, "{ratio}");
    }
}

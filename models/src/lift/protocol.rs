//! A lift test as a test stand records it (paper, Section 5.3, Fig 15): the drive's set torque
//! with its equivalent damper, the external lowering spring, the weight cut at t = 0.
//!
//! Produces the contract's `lift` channels (H, T, Fs, Fm) from the model, e.g. with one joint's
//! friction drifted, for identification tests and the demo.

use super::dynamics::LiftModel;
use super::geometry::Geometry;
use super::simulate::{
    DriveModel, LiftInputs, SimError, SimOptions, StripSpring, initial_state, simulate,
};

/// The protocol of the paper's complete-assembly lift test.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LiftProtocol {
    pub t_start_s: f64,
    pub t_end_s: f64,
    pub sample_hz: f64,
    /// Set torque before the cut and its final value; it decays between them with `tau_s`.
    pub torque_initial_nm: f64,
    pub torque_final_nm: f64,
    pub tau_s: f64,
    /// The drive's equivalent damper on the lower arm (paper Fig 2a, c_b): the recorded torque
    /// is the set torque minus this times α̇.
    pub drive_damping_nms_per_rad: f64,
    pub spring: StripSpring,
    /// Suspended weight Fm, cut at t = 0.
    pub weight_n: f64,
}

impl LiftProtocol {
    /// The paper's test as the reference trace runs it: states and spring from the geometry
    /// file's `[lift_test]` (Section 5.3); τ = 0.8 s and c = 330 N·m·s/rad from
    /// `shared/reference/lift-example.meta.json` (tuned there so the head rests at 1.84 m).
    pub fn reference(g: &Geometry) -> Self {
        let lt = &g.lift_test;
        Self {
            t_start_s: -0.5,
            t_end_s: 7.5,
            sample_hz: 500.0,
            torque_initial_nm: lt.initial.t_nm,
            torque_final_nm: lt.final_.t_nm,
            tau_s: 0.8,
            drive_damping_nms_per_rad: 330.0,
            spring: StripSpring {
                force_at_ref_n: lt.initial.fs_n,
                stiffness_n_per_m: lt.external_spring_n_per_m,
                h_ref_m: lt.initial.h_m,
            },
            weight_n: lt.initial.fm_n,
        }
    }

    /// The set torque at time t.
    pub fn set_torque_nm(&self, t_s: f64) -> f64 {
        if t_s < 0.0 {
            self.torque_initial_nm
        } else {
            self.torque_final_nm
                + (self.torque_initial_nm - self.torque_final_nm) * (-t_s / self.tau_s).exp()
        }
    }
}

/// The recorded channels of a lift test (contract `lift` kind).
#[derive(Debug, Clone, PartialEq)]
pub struct LiftRecord {
    pub t_s: Vec<f64>,
    pub strip_height_m: Vec<f64>,
    pub torque_nm: Vec<f64>,
    pub fs_n: Vec<f64>,
    pub fm_n: Vec<f64>,
}

impl LiftRecord {
    /// The record's input channels.
    pub fn inputs(&self) -> LiftInputs<'_> {
        LiftInputs {
            t_s: &self.t_s,
            torque_nm: &self.torque_nm,
            fs_n: &self.fs_n,
            fm_n: &self.fm_n,
        }
    }
}

/// Run `protocol` on `model` and record it, noise-free.
pub fn record(
    model: &LiftModel,
    protocol: &LiftProtocol,
    opts: &SimOptions,
) -> Result<LiftRecord, SimError> {
    let p = protocol;
    if !(p.sample_hz > 0.0 && p.t_end_s > p.t_start_s) {
        return Err(SimError::Inputs("protocol: empty time span".into()));
    }
    let n = ((p.t_end_s - p.t_start_s) * p.sample_hz).round() as usize;
    let t_s: Vec<f64> = (0..n)
        .map(|k| p.t_start_s + k as f64 / p.sample_hz)
        .collect();
    let set: Vec<f64> = t_s.iter().map(|&t| p.set_torque_nm(t)).collect();
    let zero = vec![0.0; n];
    let fm_n: Vec<f64> = t_s
        .iter()
        .map(|&t| if t < 0.0 { p.weight_n } else { 0.0 })
        .collect();
    let inputs = LiftInputs {
        t_s: &t_s,
        torque_nm: &set,
        fs_n: &zero,
        fm_n: &fm_n,
    };
    let sim = SimOptions {
        drive: Some(DriveModel {
            stiffness_nm_per_rad: 0.0,
            damping_nms_per_rad: p.drive_damping_nms_per_rad,
            alpha_ref_rad: 0.0,
        }),
        strip_spring: Some(p.spring),
        torque_offset_nm: 0.0,
        ..*opts
    };
    let start = initial_state(model, &inputs, &sim)?;
    let run = simulate(model, &inputs, start, &sim)?;
    let torque_nm = (0..n)
        .map(|k| set[k] - p.drive_damping_nms_per_rad * run.alpha_dot_rad_s[k])
        .collect();
    let fs_n = run
        .strip_height_m
        .iter()
        .map(|&h| p.spring.force_n(h))
        .collect();
    Ok(LiftRecord {
        t_s,
        strip_height_m: run.strip_height_m,
        torque_nm,
        fs_n,
        fm_n,
    })
}

//! A lift test as a test stand records it (paper, Section 5.3, Fig 15): the drive's set torque
//! with its equivalent damper, the external lowering spring, the weight cut at t = 0.
//!
//! Produces the contract's `lift` channels (H, T, Fs, Fm) from the model, e.g. with one joint's
//! friction drifted, for identification tests and the demo. Two protocols (issue 5, point 5):
//! - *raise only* ([`LiftProtocol::reference`]): the paper's test, the head rises from 1.04 m to
//!   1.84 m and rests; friction shows only mixed with the drive's torque balance;
//! - *raise and lower* ([`LiftProtocol::raise_and_lower`]): the same raise, then the set torque
//!   falls back to the frictionless holding torque at the start height, and the head comes down:
//!   friction opposes the motion in both directions and shows as the hysteresis between them;
//! - *designed* (`lift::design`, issue 15 point 3): the same raise, then any sequence of
//!   [`Move`]s — the set torque relaxing to the holding torque of a target height at a chosen
//!   speed — within the stand's [`ProtocolLimits`].

use super::dynamics::LiftModel;
use super::geometry::Geometry;
use super::simulate::{
    DriveModel, LiftInputs, SimError, SimOptions, StripSpring, initial_state, simulate,
};
use super::statics::{StaticFriction, StaticsError, alpha_at_height, static_point};

/// The protocol of the paper's complete-assembly lift test (serialised as `pantowatch
/// design-test` writes it and `simulate --protocol` reads it).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
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
    /// What follows the raise, in time order (raise and lower: one move back down; raise
    /// only: none).
    #[serde(default)]
    pub moves: Vec<Move>,
}

/// One change of the drive's set point after the raise: from `t_s` the set torque relaxes
/// exponentially, with time constant `tau_s` (the pneumatic drive's pressure response), from
/// wherever it was to `torque_nm` — a pressure step at a chosen speed. `height_m` is the strip
/// height whose frictionless holding torque `torque_nm` is, when the move was made from one
/// (for the reader; the model reads `torque_nm`).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Move {
    pub t_s: f64,
    pub torque_nm: f64,
    pub tau_s: f64,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub height_m: Option<f64>,
}

impl LiftProtocol {
    /// The paper's test as the reference trace runs it: states and spring from the geometry
    /// file's `[lift_test]` (Section 5.3); the recording, τ and c from `[paper_tests]` of
    /// models/data/160ec.toml (from `shared/reference/lift-example.meta.json`).
    pub fn reference(g: &Geometry) -> Self {
        let lt = &g.lift_test;
        let pt = crate::data::builtin_160ec().paper_tests();
        Self {
            t_start_s: pt.lift_t_start_s,
            t_end_s: pt.lift_t_end_s,
            sample_hz: pt.lift_sample_hz,
            torque_initial_nm: lt.initial.t_nm,
            torque_final_nm: lt.final_.t_nm,
            tau_s: pt.lift_drive_tau_s,
            drive_damping_nms_per_rad: pt.lift_drive_damping_nms_per_rad,
            spring: StripSpring {
                force_at_ref_n: lt.initial.fs_n,
                stiffness_n_per_m: lt.external_spring_n_per_m,
                h_ref_m: lt.initial.h_m,
            },
            weight_n: lt.initial.fm_n,
            moves: Vec::new(),
        }
    }

    /// Raise and lower in the same 8 s record as [`LiftProtocol::reference`]: the paper's raise,
    /// then at t = 3.5 s (the raise has settled within ~2 s) the set torque falls to the
    /// frictionless static torque that holds the strip at the start height 1.04 m under the
    /// lowering spring alone (the weight stays cut), and the head comes down. Assumed protocol:
    /// the paper records only the raise.
    pub fn raise_and_lower(model: &LiftModel, g: &Geometry) -> Result<Self, StaticsError> {
        let lt = &g.lift_test;
        let range = (g.alpha_min_rad, g.alpha_max_rad);
        let load_n = lt.initial.fs_n;
        let alpha = alpha_at_height(model, lt.initial.h_m, load_n, range)?;
        let hold = static_point(model, alpha, load_n, StaticFriction::None)?;
        let raise = Self::reference(g);
        Ok(Self {
            moves: vec![Move {
                t_s: 3.5,
                torque_nm: hold.drive_torque_nm,
                tau_s: raise.tau_s,
                height_m: Some(lt.initial.h_m),
            }],
            ..raise
        })
    }

    /// The set torque at time t: held before the cut, the raise's relaxation from t = 0, then
    /// each move's relaxation from where the previous one had brought it (moves in time order).
    pub fn set_torque_nm(&self, t_s: f64) -> f64 {
        if t_s < 0.0 {
            return self.torque_initial_nm;
        }
        // The current segment: (start time, value at start, target, time constant).
        let (mut t0, mut from, mut to, mut tau) = (
            0.0,
            self.torque_initial_nm,
            self.torque_final_nm,
            self.tau_s,
        );
        for m in self.moves.iter().take_while(|m| m.t_s <= t_s) {
            from = to + (from - to) * (-(m.t_s - t0) / tau).exp();
            (t0, to, tau) = (m.t_s, m.torque_nm, m.tau_s);
        }
        to + (from - to) * (-(t_s - t0) / tau).exp()
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

    /// The record as a fit takes it: its inputs and its measured H.
    pub fn trace(&self) -> super::fit::LiftTrace<'_> {
        super::fit::LiftTrace {
            inputs: self.inputs(),
            strip_height_m: &self.strip_height_m,
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
    // The recorded torque is the drive side's: with a compliant drive its rate is α̇ + δ̇.
    let torque_nm = (0..n)
        .map(|k| {
            let rate = run.alpha_dot_rad_s[k] + run.deflection_rate_rad_s.get(k).unwrap_or(&0.0);
            set[k] - p.drive_damping_nms_per_rad * rate
        })
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lift::geometry::builtin_160ec;
    use crate::lift::identify::{LiftFitOptions, identifiability};

    /// Issue 5, point 5: what each protocol informs, from the model's own Fisher information
    /// (σ_H = 1 mm, 8 s at 500 Hz, Table 4 friction, prior sd 0.5 × baseline): a parameter is
    /// informed when its posterior sd is below half its prior sd. Printed for the README.
    #[test]
    fn raise_and_lower_informs_what_raise_only_does_and_more() {
        let g = builtin_160ec();
        let m = LiftModel::new(g);
        let opts = LiftFitOptions::default();
        let raise = LiftProtocol::reference(g);
        let both = LiftProtocol::raise_and_lower(&m, g).unwrap();
        let lower = both.moves[0];
        eprintln!(
            "lowering torque {:.1} N·m at t = {} s",
            lower.torque_nm, lower.t_s
        );
        let mut verdicts = Vec::new();
        for p in [raise, both.clone()] {
            let rec = record(&m, &p, &SimOptions::default()).unwrap();
            let at = |t: f64| rec.strip_height_m[((t - p.t_start_s) * p.sample_hz) as usize];
            eprintln!(
                "H at 0 / 3.4 / 7.4 s: {:.4} / {:.4} / {:.4} m",
                at(0.0),
                at(3.4),
                at(7.4)
            );
            let id = identifiability(&m, &rec.inputs(), &opts).unwrap();
            verdicts.push(id);
        }
        let (r, b) = (&verdicts[0], &verdicts[1]);
        eprintln!(
            "| parameter | raise: posterior sd / prior sd | informed | raise and lower: posterior sd / prior sd | informed |"
        );
        for (i, p) in r.params.iter().enumerate() {
            let prior = if *p == super::super::sensitivity::LiftParam::TorqueOffset {
                opts.offset_prior_sd_nm
            } else {
                opts.prior_relative_sd
            };
            eprintln!(
                "| {}.{} | {:.3} | {} | {:.3} | {} |",
                p.joint(),
                p.kind(),
                r.posterior_sd[i] / prior,
                if r.informed[i] { "yes" } else { "no" },
                b.posterior_sd[i] / prior,
                if b.informed[i] { "yes" } else { "no" }
            );
        }
        for i in 0..r.params.len() {
            assert!(!r.informed[i] || b.informed[i], "{:?}", r.params[i]);
        }
    }
}

//! Lift-test simulation: the model driven by sampled inputs (T, Fs, Fm) from its static start,
//! sampled off DOPRI5's dense output, with each joint's dissipated energy if asked.
//!
//! Inputs between samples: T and Fs linear; Fm (a weight on a cord: on or off) held from each
//! sample to the next, so a cut recorded at a sample acts from that instant (the integrator
//! lands and restarts there).

use super::dynamics::{DynamicsError, LiftModel, Loads, State};
use super::integrate::{IntegrateError, Segmented, integrate};
use super::statics::{StaticFriction, StaticsError, root_in_range, static_h_m, static_point};
use super::topology::{N_REV, RevJoint};
use crate::numerics::ode::{Dopri5, OdeError, OdeSystem, Tolerances};

/// The lift test's input channels, sampled at `t_s` (contract `lift` kind).
#[derive(Debug, Clone, Copy)]
pub struct LiftInputs<'a> {
    pub t_s: &'a [f64],
    /// Drive torque on the lower arm, N·m (positive raises).
    pub torque_nm: &'a [f64],
    /// External lowering spring on the head, N (positive down).
    pub fs_n: &'a [f64],
    /// Suspended weight on the head, N (positive down); empty when the channel is absent.
    pub fm_n: &'a [f64],
}

/// Something wrong with the inputs or the run.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SimError {
    #[error("lift inputs: {0}")]
    Inputs(String),
    #[error(transparent)]
    Statics(#[from] StaticsError),
    #[error(transparent)]
    Ode(#[from] OdeError),
    #[error("more than {0} integrator steps")]
    TooManySteps(usize),
    #[error(transparent)]
    Budget(#[from] crate::numerics::budget::Exhausted),
}

impl SimError {
    pub(super) fn from_integrate(e: IntegrateError<DynamicsError>) -> Self {
        match e {
            IntegrateError::Ode(e) => SimError::Ode(e),
            IntegrateError::TooManySteps(n) => SimError::TooManySteps(n),
            IntegrateError::Cancelled => {
                SimError::Budget(crate::numerics::budget::Exhausted::Cancelled)
            }
            IntegrateError::Sample(e) => SimError::Statics(StaticsError::Dynamics(e)),
        }
    }
}

impl<'a> LiftInputs<'a> {
    /// Check lengths, time order and finiteness.
    pub fn validate(&self) -> Result<(), SimError> {
        let n = self.t_s.len();
        if n < 2 {
            return Err(SimError::Inputs("`t_s` needs at least two samples".into()));
        }
        for (name, ch) in [("T_Nm", self.torque_nm), ("Fs_N", self.fs_n)] {
            if ch.len() != n {
                return Err(SimError::Inputs(format!(
                    "`{name}` has {} samples, `t_s` {n}",
                    ch.len()
                )));
            }
        }
        if !self.fm_n.is_empty() && self.fm_n.len() != n {
            return Err(SimError::Inputs(format!(
                "`Fm_N` has {} samples, `t_s` {n}",
                self.fm_n.len()
            )));
        }
        for (name, ch) in [
            ("t_s", self.t_s),
            ("T_Nm", self.torque_nm),
            ("Fs_N", self.fs_n),
            ("Fm_N", self.fm_n),
        ] {
            if let Some(k) = ch.iter().position(|v| !v.is_finite()) {
                return Err(SimError::Inputs(format!("`{name}`[{k}] is not finite")));
            }
        }
        if let Some(k) = self.t_s.windows(2).position(|w| w[1] <= w[0]) {
            return Err(SimError::Inputs(format!(
                "`t_s` not increasing at sample {}",
                k + 1
            )));
        }
        Ok(())
    }

    pub(super) fn fm(&self, k: usize) -> f64 {
        self.fm_n.get(k).copied().unwrap_or(0.0)
    }

    /// Samples where the held Fm steps (the integrator's breakpoints).
    pub(super) fn is_break(&self, k: usize) -> bool {
        k > 0 && self.fm(k) != self.fm(k - 1)
    }

    /// Loads at time t with the segment's held `fm_n` and `offset_nm` subtracted from the
    /// recorded torque (a torque-sensor offset: recorded = true + offset).
    #[inline]
    pub(super) fn loads(&self, t: f64, fm_n: f64, offset_nm: f64) -> Loads {
        let n = self.t_s.len();
        let k = self.t_s.partition_point(|&x| x <= t).clamp(1, n - 1) - 1;
        let (t0, t1) = (self.t_s[k], self.t_s[k + 1]);
        let x = (t - t0) / (t1 - t0);
        let lin = |c: &[f64]| c[k] + (c[k + 1] - c[k]) * x;
        Loads {
            drive_torque_nm: lin(self.torque_nm) - offset_nm,
            strip_load_n: lin(self.fs_n) + fm_n,
        }
    }
}

/// Energy dissipated by each joint over a run, J.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Dissipation {
    pub revolute_viscous_j: [f64; N_REV],
    pub revolute_dry_j: [f64; N_REV],
    pub j8_viscous_j: f64,
    pub j8_dry_j: f64,
    pub j9_damping_j: f64,
}

impl Dissipation {
    pub fn total_j(&self) -> f64 {
        self.revolute_viscous_j.iter().sum::<f64>()
            + self.revolute_dry_j.iter().sum::<f64>()
            + self.j8_viscous_j
            + self.j8_dry_j
            + self.j9_damping_j
    }

    /// Each joint's share of all friction work, % (J1 … J7, J8, J9).
    pub fn shares_pct(&self) -> Vec<(&'static str, f64)> {
        let total = self.total_j();
        let mut v: Vec<(&'static str, f64)> = RevJoint::ALL
            .iter()
            .map(|j| {
                let i = j.index();
                (
                    j.name(),
                    self.revolute_viscous_j[i] + self.revolute_dry_j[i],
                )
            })
            .collect();
        v.push(("J8", self.j8_viscous_j + self.j8_dry_j));
        v.push(("J9", self.j9_damping_j));
        for e in &mut v {
            e.1 *= 100.0 / total;
        }
        v
    }
}

/// A simulated lift: the state at every input sample.
#[derive(Debug, Clone, PartialEq)]
pub struct LiftRun {
    /// Contact-strip height H, m.
    pub strip_height_m: Vec<f64>,
    pub alpha_rad: Vec<f64>,
    pub h_m: Vec<f64>,
    pub alpha_dot_rad_s: Vec<f64>,
    pub h_dot_m_s: Vec<f64>,
    /// With a compliant drive ([`crate::lift::dynamics::DriveCompliance`]): the bellows'
    /// deflection δ = β − α, rad, and its rate, rad/s; empty otherwise.
    pub deflection_rad: Vec<f64>,
    pub deflection_rate_rad_s: Vec<f64>,
    pub dissipation: Option<Dissipation>,
    pub rhs_evaluations: usize,
    pub steps: usize,
}

/// An equivalent drive model on the lower arm (paper, Fig 2a: the bellows as a spring and a
/// damper): torque = input − k·(α − α_ref) − c·α̇. Without it the input is the whole torque.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct DriveModel {
    pub stiffness_nm_per_rad: f64,
    pub damping_nms_per_rad: f64,
    pub alpha_ref_rad: f64,
}

impl DriveModel {
    #[inline]
    fn torque_nm(&self, alpha_rad: f64, alpha_dot_rad_s: f64) -> f64 {
        -self.stiffness_nm_per_rad * (alpha_rad - self.alpha_ref_rad)
            - self.damping_nms_per_rad * alpha_dot_rad_s
    }
}

/// An external spring pulling the strip down, as on the lift-test stand (paper Fig 15a):
/// force = `force_at_ref_n` + `stiffness_n_per_m`·(H − `h_ref_m`), added to the strip load.
/// For simulating a test; a recorded test has the force as its `Fs_N` channel instead.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct StripSpring {
    pub force_at_ref_n: f64,
    pub stiffness_n_per_m: f64,
    pub h_ref_m: f64,
}

impl StripSpring {
    #[inline]
    pub fn force_n(&self, strip_height_m: f64) -> f64 {
        self.force_at_ref_n + self.stiffness_n_per_m * (strip_height_m - self.h_ref_m)
    }
}

/// Integrator settings.
#[derive(Debug, Clone, Copy)]
pub struct SimOptions {
    pub rtol: f64,
    pub atol: f64,
    /// Accumulate each joint's dissipated energy.
    pub energy: bool,
    /// Torque-sensor offset subtracted from the recorded torque, N·m.
    pub torque_offset_nm: f64,
    /// Drive dynamics added to the input torque (none: the input is the measured total).
    pub drive: Option<DriveModel>,
    /// External strip spring added to the Fs input (none: Fs is the measured force).
    pub strip_spring: Option<StripSpring>,
    /// Longest step, s: well under the head's bounce period (≈ 0.2 s on J9), so a quiet
    /// stretch cannot grow the step past the next transient.
    pub h_max_s: f64,
    pub max_steps: usize,
}

impl Default for SimOptions {
    fn default() -> Self {
        Self {
            rtol: 1e-8,
            atol: 1e-10,
            energy: false,
            torque_offset_nm: 0.0,
            drive: None,
            strip_spring: None,
            h_max_s: 0.02,
            max_steps: 1_000_000,
        }
    }
}

/// Components of the ODE state: α, h, α̇, ḣ, with a compliant drive δ and δ̇
/// ([`LiftModel::n_state`]), then (with energy) the dissipation integrals.
const N_STATE: usize = 4;
const N_ENERGY: usize = 2 * N_REV + 3;

/// The first-order system, with the held Fm of the current segment.
struct Sys<'a> {
    model: &'a LiftModel,
    inputs: &'a LiftInputs<'a>,
    offset_nm: f64,
    drive: Option<DriveModel>,
    strip_spring: Option<StripSpring>,
    fm_n: f64,
    energy: bool,
}

impl Segmented for Sys<'_> {
    fn enter_segment(&mut self, k: usize) {
        self.fm_n = self.inputs.fm(k);
    }
}

impl OdeSystem for Sys<'_> {
    fn dim(&self) -> usize {
        if self.energy {
            self.model.n_state() + N_ENERGY
        } else {
            self.model.n_state()
        }
    }

    fn rhs(&self, t: f64, y: &[f64], dy: &mut [f64]) -> Result<(), OdeError> {
        let s = State {
            alpha_rad: y[0],
            h_m: y[1],
            alpha_dot_rad_s: y[2],
            h_dot_m_s: y[3],
        };
        let mut loads = self.inputs.loads(t, self.fm_n, self.offset_nm);
        let ns = self.model.n_state();
        // With a compliant drive the drive model and the recorded torque act on the drive side
        // (angle α + δ); the lower arm gets what the bellows transmit.
        let (mut beta, mut beta_dot) = (s.alpha_rad, s.alpha_dot_rad_s);
        let compliance = self.model.drive_compliance;
        if compliance.is_some() {
            beta += y[4];
            beta_dot += y[5];
        }
        if let Some(d) = &self.drive {
            loads.drive_torque_nm += d.torque_nm(beta, beta_dot);
        }
        let drive_side_nm = loads.drive_torque_nm;
        if let Some(c) = &compliance {
            loads.drive_torque_nm = c.transmitted_nm(y[4], y[5]);
        }
        // A trial stage outside the assembly range rejects the step (non-finite derivative)
        // rather than ending the run; a trajectory that really leaves it ends in underflow.
        let Ok(e) = self
            .model
            .linkage
            .pose(s.alpha_rad)
            .map_err(DynamicsError::from)
            .and_then(|pose| {
                let head = self
                    .model
                    .linkage
                    .head(&pose, s.h_m, s.alpha_dot_rad_s, s.h_dot_m_s);
                if let Some(sp) = &self.strip_spring {
                    loads.strip_load_n += sp.force_n(head.strip.y);
                }
                loads.strip_load_n += self.model.head_drag_n(&head, &s);
                self.model.eval_with_head(&pose, &head, &s, &loads, None)
            })
        else {
            dy.fill(f64::NAN);
            return Ok(());
        };
        dy[0] = s.alpha_dot_rad_s;
        dy[1] = s.h_dot_m_s;
        dy[2] = e.alpha_ddot_rad_s2;
        dy[3] = e.h_ddot_m_s2;
        if let Some(c) = &compliance {
            dy[4] = y[5];
            dy[5] = (drive_side_nm - loads.drive_torque_nm) / c.inertia_kgm2 - e.alpha_ddot_rad_s2;
        }
        if self.energy {
            for j in RevJoint::ALL {
                let (v, d) = e.revolute_power_w(j);
                dy[ns + j.index()] = v;
                dy[ns + N_REV + j.index()] = d;
            }
            let hd = s.h_dot_m_s;
            dy[ns + 2 * N_REV] = e.j8_viscous_n * hd;
            dy[ns + 2 * N_REV + 1] = e.j8_dry_n * hd;
            dy[ns + 2 * N_REV + 2] = e.j9_damping_n * hd;
        }
        Ok(())
    }
}

/// The static state the lift starts from: at rest under the first sample's loads (and the
/// drive model's spring, if any). With the smoothed sign law friction vanishes at rest, so this
/// is the frictionless equilibrium.
pub fn initial_state(
    model: &LiftModel,
    inputs: &LiftInputs,
    opts: &SimOptions,
) -> Result<State, SimError> {
    inputs.validate()?;
    let loads = inputs.loads(inputs.t_s[0], inputs.fm(0), opts.torque_offset_nm);
    let drive = opts.drive.unwrap_or_default();
    let (lo, hi) = model.alpha_range_rad;
    // The strip load with the external spring at the strip height of (α, static h): a
    // fixed point in the load (the spring is soft against J9: 89 N/m vs 16 000 N/m).
    let strip_load = |a: f64| -> Result<(f64, f64), StaticsError> {
        let pose = model.linkage.pose(a).map_err(DynamicsError::from)?;
        let mut load = loads.strip_load_n;
        let mut h = static_h_m(model, &pose, load);
        if let Some(sp) = &opts.strip_spring {
            for _ in 0..50 {
                let hh = model.linkage.head(&pose, h, 0.0, 0.0).strip.y;
                let next = loads.strip_load_n + sp.force_n(hh);
                let done = (next - load).abs() <= 1e-13 * (1.0 + next.abs());
                load = next;
                h = static_h_m(model, &pose, load);
                if done {
                    break;
                }
            }
        }
        Ok((load, h))
    };
    let alpha = root_in_range(lo, hi, "the first sample's loads", |a| {
        let p = static_point(model, a, strip_load(a)?.0, StaticFriction::None)?;
        Ok(p.drive_torque_nm - loads.drive_torque_nm - drive.torque_nm(a, 0.0))
    })?;
    Ok(State {
        alpha_rad: alpha,
        h_m: strip_load(alpha)?.1,
        ..Default::default()
    })
}

/// The compliant drive's deflection at rest at the start `s`, rad: the spring carries the
/// first sample's drive torque, δ₀ = T₀/k (0 without a compliant drive).
pub fn initial_deflection_rad(
    model: &LiftModel,
    inputs: &LiftInputs,
    opts: &SimOptions,
    s: &State,
) -> f64 {
    let Some(c) = &model.drive_compliance else {
        return 0.0;
    };
    let loads = inputs.loads(inputs.t_s[0], inputs.fm(0), opts.torque_offset_nm);
    let drive = opts.drive.unwrap_or_default();
    (loads.drive_torque_nm + drive.torque_nm(s.alpha_rad, 0.0)) / c.stiffness_nm_per_rad
}

/// Simulate the lift from `start` at the first sample through the last.
pub fn simulate(
    model: &LiftModel,
    inputs: &LiftInputs,
    start: State,
    opts: &SimOptions,
) -> Result<LiftRun, SimError> {
    inputs.validate()?;
    let n = inputs.t_s.len();
    let mut sys = Sys {
        model,
        inputs,
        offset_nm: opts.torque_offset_nm,
        drive: opts.drive,
        strip_spring: opts.strip_spring,
        fm_n: inputs.fm(0),
        energy: opts.energy,
    };
    let dim = sys.dim();
    let ns = model.n_state();
    let mut y = vec![0.0; dim];
    y[..N_STATE].copy_from_slice(&[
        start.alpha_rad,
        start.h_m,
        start.alpha_dot_rad_s,
        start.h_dot_m_s,
    ]);
    if ns > N_STATE {
        y[4] = initial_deflection_rad(model, inputs, opts, &start);
    }
    let mut buf = vec![0.0; dim];
    let mut run = LiftRun {
        strip_height_m: Vec::with_capacity(n),
        alpha_rad: Vec::with_capacity(n),
        h_m: Vec::with_capacity(n),
        alpha_dot_rad_s: Vec::with_capacity(n),
        h_dot_m_s: Vec::with_capacity(n),
        deflection_rad: Vec::new(),
        deflection_rate_rad_s: Vec::new(),
        dissipation: None,
        rhs_evaluations: 0,
        steps: 0,
    };
    let tol = Tolerances {
        rtol: opts.rtol,
        atol: opts.atol,
        h_max: opts.h_max_s,
        ..Default::default()
    };
    let mut ode = Dopri5::new(dim, ns, tol);
    let work = integrate(
        &mut sys,
        &mut ode,
        inputs.t_s,
        |k| inputs.is_break(k),
        &mut y,
        opts.max_steps,
        &mut buf,
        |_, y| -> Result<(), DynamicsError> {
            run.strip_height_m
                .push(model.strip_height_partials(y[0], y[1])?.0);
            run.alpha_rad.push(y[0]);
            run.h_m.push(y[1]);
            run.alpha_dot_rad_s.push(y[2]);
            run.h_dot_m_s.push(y[3]);
            if ns > N_STATE {
                run.deflection_rad.push(y[4]);
                run.deflection_rate_rad_s.push(y[5]);
            }
            Ok(())
        },
    )
    .map_err(SimError::from_integrate)?;
    run.steps = work.steps;
    run.rhs_evaluations = work.rhs;
    if opts.energy {
        let e = &y[ns..];
        let mut d = Dissipation::default();
        d.revolute_viscous_j.copy_from_slice(&e[..N_REV]);
        d.revolute_dry_j.copy_from_slice(&e[N_REV..2 * N_REV]);
        d.j8_viscous_j = e[2 * N_REV];
        d.j8_dry_j = e[2 * N_REV + 1];
        d.j9_damping_j = e[2 * N_REV + 2];
        run.dissipation = Some(d);
    }
    Ok(run)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lift::dynamics::FrictionParams;
    use crate::lift::geometry::builtin_160ec;
    use crate::lift::statics::static_point;

    /// Largest |E(t) − E(0)| over a run, relative to the largest kinetic energy reached (a
    /// stricter scale than the total, which gravity's datum makes arbitrary).
    fn energy_drift(m: &LiftModel, run: &LiftRun, torque_nm: f64, drive: &DriveModel) -> f64 {
        let mut e0 = None;
        let (mut drift, mut kin_max): (f64, f64) = (0.0, 0.0);
        for i in 0..run.alpha_rad.len() {
            let s = State {
                alpha_rad: run.alpha_rad[i],
                h_m: run.h_m[i],
                alpha_dot_rad_s: run.alpha_dot_rad_s[i],
                h_dot_m_s: run.h_dot_m_s[i],
            };
            let pose = m.linkage.pose(s.alpha_rad).unwrap();
            let at_rest = State {
                alpha_dot_rad_s: 0.0,
                h_dot_m_s: 0.0,
                ..s
            };
            let (e, e_rest) = (m.energy_j(&pose, &s), m.energy_j(&pose, &at_rest));
            kin_max = kin_max.max(e - e_rest);
            let e = e - torque_nm * s.alpha_rad
                + 0.5 * drive.stiffness_nm_per_rad * (s.alpha_rad - drive.alpha_ref_rad).powi(2);
            let e0 = *e0.get_or_insert(e);
            drift = drift.max((e - e0).abs());
        }
        drift / kin_max
    }

    fn constant_inputs(n: usize, dt: f64, torque_nm: f64) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
        let t = (0..n).map(|k| k as f64 * dt).collect();
        (t, vec![torque_nm; n], vec![0.0; n])
    }

    /// Frictionless free motions conserve energy: (a) gravity only, the pantograph falling
    /// from the top of its range to near the bottom (0.6 s: the linkage would leave its range
    /// after that — the real one lands on its rest stops); (b) 5 s of oscillation of both
    /// coordinates, gravity against a constant torque and the drive's equivalent spring
    /// (conservative: paper Fig 2a's k_b, no damper), the head bouncing on J9.
    #[test]
    fn frictionless_free_motion_conserves_energy() {
        let g = builtin_160ec();
        let mut m = LiftModel::new(g);
        m.friction = FrictionParams::frictionless();
        let opts = SimOptions {
            rtol: 1e-10,
            atol: 1e-12,
            ..Default::default()
        };
        // (a) Gravity only.
        let (t, tq, z) = constant_inputs(301, 0.002, 0.0);
        let inputs = LiftInputs {
            t_s: &t,
            torque_nm: &tq,
            fs_n: &z,
            fm_n: &[],
        };
        let start = State {
            alpha_rad: g.alpha_max_rad,
            ..Default::default()
        };
        let run = simulate(&m, &inputs, start, &opts).unwrap();
        let none = DriveModel::default();
        let d_fall = energy_drift(&m, &run, 0.0, &none);
        assert!(*run.alpha_rad.last().unwrap() < 0.0, "it fell");
        // (b) 5 s oscillation.
        let t_hold = static_point(&m, 0.3, 0.0, crate::lift::statics::StaticFriction::None)
            .unwrap()
            .drive_torque_nm;
        let (t, tq, z) = constant_inputs(2501, 0.002, t_hold);
        let inputs = LiftInputs {
            t_s: &t,
            torque_nm: &tq,
            fs_n: &z,
            fm_n: &[],
        };
        let drive = DriveModel {
            stiffness_nm_per_rad: 3000.0,
            damping_nms_per_rad: 0.0,
            alpha_ref_rad: 0.3,
        };
        let start = State {
            alpha_rad: 0.35,
            h_m: 0.01,
            ..Default::default()
        };
        let run = simulate(
            &m,
            &inputs,
            start,
            &SimOptions {
                drive: Some(drive),
                ..opts
            },
        )
        .unwrap();
        let d_osc = energy_drift(&m, &run, t_hold, &drive);
        eprintln!(
            "energy drift / max kinetic energy: fall {d_fall:.2e}, 5 s oscillation {d_osc:.2e}"
        );
        assert!(d_fall <= 1e-7 && d_osc <= 1e-7, "{d_fall:e} {d_osc:e}");
    }

    #[test]
    fn inputs_are_validated() {
        let t = [0.0, 0.1, 0.1];
        let v = [0.0; 3];
        let inputs = LiftInputs {
            t_s: &t,
            torque_nm: &v,
            fs_n: &v,
            fm_n: &[],
        };
        assert!(
            inputs
                .validate()
                .unwrap_err()
                .to_string()
                .contains("not increasing")
        );
        let inputs = LiftInputs {
            t_s: &t[..2],
            torque_nm: &v,
            fs_n: &v[..2],
            fm_n: &[],
        };
        assert!(
            inputs
                .validate()
                .unwrap_err()
                .to_string()
                .contains("`T_Nm`")
        );
    }
}

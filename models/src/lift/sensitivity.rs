//! Forward sensitivities of a simulated lift: ∂H(t_k)/∂θ for the friction parameters of every
//! joint and the torque-sensor offset, integrated with the state on the same steps.
//!
//! S′ = f_y·S + f_θ: f_y (2×4, the accelerations' state Jacobian) by one-sided differences,
//! f_θ exactly from the model's linear response to the friction inputs (normal-force feedback
//! included); the initial state's dependence on the offset by a central difference.
//!
//! Integrated by the Rosenbrock-W method ([`crate::numerics::ode::Rosw`]) with W = I ⊗ f_y: the
//! smoothed friction at rest is stiff, which held the explicit DOPRI5 to ~3 ms steps through
//! every rest phase; f_y is computed for the sensitivities anyway, so W costs nothing.

use std::cell::{Cell, RefCell};

use super::dynamics::{DynamicsError, Eval, Kane, LiftModel, Loads, Q_DRIVE, Q_SLIDE, State};
use super::integrate::{Segmented, integrate};
use super::kinematics::{HeadKin, LinkagePose};
use super::simulate::{LiftInputs, SimError, SimOptions, initial_deflection_rad, initial_state};
use super::topology::N_REV;
use crate::numerics::ode::{OdeError, Rosw, Tolerances, WSystem};

mod param;
pub use param::{DRIVE_COMPLIANCE_START, LiftParam};

/// A simulated lift with its sensitivities.
#[derive(Debug, Clone, Default)]
pub struct SensitivityRun {
    /// H at every sample, m.
    pub strip_height_m: Vec<f64>,
    /// ∂H_k/∂θ_i, row-major n × p (row k, column i in the order of the parameter list).
    pub d_height: Vec<f64>,
    pub n_params: usize,
    pub rhs_evaluations: usize,
    pub steps: usize,
}

/// One-sided difference steps of the state Jacobian: α (rad), h (m), α̇ (rad/s), ḣ (m/s).
/// The rates' steps are far below the tanh smoothing scale (10⁻³), where the friction bends.
const FD_STEP: [f64; 4] = [1e-8, 1e-9, 1e-9, 1e-9];

/// The rates' (α̇, ḣ) absolute tolerance over the positions': at rest the rates creep at
/// 10⁻⁵–10⁻⁴ (rad/s, m/s), where `atol` 10⁻⁷ held the steps to resolving the creep itself.
/// A rate error of 10⁻⁶ held over a whole 8 s test moves α by 8·10⁻⁶ rad (H by ~16 µm).
/// Measured at the fit's tolerance on a raise and lower (docs/PROFILE.md): 893 → 572 steps,
/// H against a tight run 1.2·10⁻⁴ → 4·10⁻⁵ m, J3 dry on 14 traces within 0.1 sd of the ×1
/// factor's estimates; a factor of 100 breaks (H off by 3 mm).
const RATE_ATOL_FACTOR: f64 = 10.0;

struct SensSys<'a> {
    model: &'a LiftModel,
    inputs: &'a LiftInputs<'a>,
    params: &'a [LiftParam],
    offset_nm: f64,
    fm_n: f64,
    /// Friction torques of the last evaluation: the next fixed point's starting guess.
    last_torque: Cell<Option<[f64; N_REV]>>,
    /// The state parts of a step's stages 2–4 ([`WSystem::rhs_head`]), for their
    /// sensitivities' parts once the step stands ([`WSystem::rhs_rest`]).
    stages: RefCell<[Option<StatePart>; 3]>,
    /// Whether the stepper may split evaluations ([`WSystem::splits`]); off only in tests
    /// that compare the two ways bit for bit.
    split: bool,
}

impl Segmented for SensSys<'_> {
    fn enter_segment(&mut self, k: usize) {
        self.fm_n = self.inputs.fm(k);
    }
}

/// What the sensitivities' part of an evaluation ([`SensSys::eval_sens`]) takes from its
/// state part ([`SensSys::eval_state`]): the state part's values, kept so that the two parts
/// together perform the operations of one whole evaluation.
#[derive(Clone, Copy)]
struct StatePart {
    s: State,
    /// The loads of the evaluation (drag and a compliant drive's transmitted torque in).
    loads: Loads,
    /// The recorded drive torque (the drive side's, with a compliant drive).
    drive_side_nm: f64,
    pose: LinkagePose,
    head: HeadKin,
    drag: f64,
    e: Eval,
    kane: Kane,
    acc: [f64; 2],
    torque: [f64; N_REV],
    /// The linkage at α + `FD_STEP[0]` (the Jacobian's α column): assembled in the state
    /// part, so that a point where it fails fails there (where the stepper sees it).
    pose_up: LinkagePose,
}

impl SensSys<'_> {
    /// Accelerations and the exact ∂acc/∂θ at (t, state), plus ∂acc/∂y by differences; when
    /// `w` is given, the state's Jacobian into it (its leading [`LiftModel::n_state`] square).
    ///
    /// State order: α, h, α̇, ḣ, and with a compliant drive δ, δ̇; each parameter's
    /// sensitivity column follows in the same order.
    fn eval(
        &self,
        t: f64,
        y: &[f64],
        dy: &mut [f64],
        w: Option<&mut [[f64; 6]; 6]>,
    ) -> Result<(), DynamicsError> {
        let st = self.eval_state(t, y, dy)?;
        self.eval_sens(&st, y, dy, w)
    }

    /// The state's part of [`SensSys::eval`]: the state's derivatives into `dy[..n_state]`
    /// (reading `y[..n_state]` only) and what the sensitivities' part needs. Every failure of
    /// an evaluation that is not a measure-zero event is met here (the linkage's assembly at α
    /// and at α + `FD_STEP[0]`, the friction's fixed point); [`SensSys::eval_sens`] fails only
    /// on a singular response matrix or a non-positive mass-matrix determinant at a state
    /// 10⁻⁸ from one where it is positive (neither met in any run of the probes).
    fn eval_state(&self, t: f64, y: &[f64], dy: &mut [f64]) -> Result<StatePart, DynamicsError> {
        let m = self.model;
        let s = State {
            alpha_rad: y[0],
            h_m: y[1],
            alpha_dot_rad_s: y[2],
            h_dot_m_s: y[3],
        };
        let mut loads = self.inputs.loads(t, self.fm_n, self.offset_nm);
        // `drive_compliance`: the recorded torque acts on the drive side; the arm gets τ.
        let drive_side_nm = loads.drive_torque_nm;
        let compliance = m.drive_compliance;
        if let Some(c) = &compliance {
            loads.drive_torque_nm = c.transmitted_nm(y[4], y[5]);
        }
        let pose = m.linkage.pose(s.alpha_rad)?;
        let head = m.linkage.head(&pose, s.h_m, s.alpha_dot_rad_s, s.h_dot_m_s);
        // `quadratic_drag` is a load that depends on the state: each perturbed state below
        // carries its own.
        let drag = m.head_drag_n(&head, &s);
        loads.strip_load_n += drag;
        // The fixed point starts from the last evaluation's torques (a nearby state: the
        // previous stage); it converges to the same 10⁻¹⁴ tolerance from any start.
        let guess = self.last_torque.get();
        let (e, kane) = m.eval_with_kane(&pose, &head, &s, &loads, guess.as_ref())?;
        let acc = [e.alpha_ddot_rad_s2, e.h_ddot_m_s2];
        let mut torque = [0.0; N_REV];
        for i in 0..N_REV {
            torque[i] = e.viscous_torque_nm[i] + e.dry_torque_nm[i];
        }
        self.last_torque.set(Some(torque));
        // After the torques are kept: a failure here leaves them kept, as a failure of the
        // Jacobian's α column did when it was assembled there.
        let pose_up = m.linkage.pose(s.alpha_rad + FD_STEP[0])?;
        dy[0] = y[2];
        dy[1] = y[3];
        dy[2] = acc[0];
        dy[3] = acc[1];
        if let Some(c) = &compliance {
            // The transmitted torque τ = k·δ + c·δ̇ (the loads' drive torque, set above).
            let transmitted_nm = loads.drive_torque_nm;
            dy[4] = y[5];
            dy[5] = (drive_side_nm - transmitted_nm) / c.inertia_kgm2 - acc[0];
        }
        Ok(StatePart {
            s,
            loads,
            drive_side_nm,
            pose,
            head,
            drag,
            e,
            kane,
            acc,
            torque,
            pose_up,
        })
    }

    /// The sensitivities' part of [`SensSys::eval`] at the state part `st` (of the same `y`):
    /// `dy[n_state..]`, and W when `w` is given.
    fn eval_sens(
        &self,
        st: &StatePart,
        y: &[f64],
        dy: &mut [f64],
        w: Option<&mut [[f64; 6]; 6]>,
    ) -> Result<(), DynamicsError> {
        let m = self.model;
        let ns = m.n_state();
        let StatePart {
            s,
            loads,
            drive_side_nm,
            ref pose,
            ref head,
            drag,
            ref e,
            ref kane,
            acc,
            torque,
            ref pose_up,
        } = *st;
        let compliance = m.drive_compliance;
        let loads_at = |hp: &HeadKin, sp: &State| {
            let mut l = loads;
            if m.head_drag_ns2_per_m2 != 0.0 {
                l.strip_load_n += m.head_drag_n(hp, sp) - drag;
            }
            l
        };
        let phi = m.response(pose, head, &s, &loads, e, kane)?;
        // State Jacobian of the accelerations, one column per state component: one-sided
        // differences of the accelerations linearised in the friction torques about this
        // evaluation (`accelerations_near`: first-order exact, one reaction recovery each).
        let mut jy = [[0.0; 6]; 2];
        for c in 0..4 {
            let mut sp = s;
            let d = FD_STEP[c];
            match c {
                0 => sp.alpha_rad += d,
                1 => sp.h_m += d,
                2 => sp.alpha_dot_rad_s += d,
                _ => sp.h_dot_m_s += d,
            }
            let ap = if c == 0 {
                let pp = pose_up;
                let hp = m.linkage.head(pp, sp.h_m, sp.alpha_dot_rad_s, sp.h_dot_m_s);
                m.accelerations_near(pp, &hp, &sp, &loads_at(&hp, &sp), &torque, &phi, None)?
            } else {
                let hp = m
                    .linkage
                    .head(pose, sp.h_m, sp.alpha_dot_rad_s, sp.h_dot_m_s);
                // h and ḣ leave the revolute joints' rates, so their sign-law values, as they were.
                let sign = (c != 2).then_some(&e.sign);
                m.accelerations_near(pose, &hp, &sp, &loads_at(&hp, &sp), &torque, &phi, sign)?
            };
            jy[0][c] = (ap[0] - acc[0]) / d;
            jy[1][c] = (ap[1] - acc[1]) / d;
        }
        // With a compliant drive: τ = k·δ + c·δ̇ enters the accelerations as the drive torque
        // (Φ's drive column, exact), and δ̈ = (T − τ)/J_d − α̈.
        let mut jd = [0.0; 6];
        let mut transmitted_nm = 0.0;
        if let Some(c) = &compliance {
            transmitted_nm = loads.drive_torque_nm;
            for r in 0..2 {
                jy[r][4] = phi[r][Q_DRIVE] * c.stiffness_nm_per_rad;
                jy[r][5] = phi[r][Q_DRIVE] * c.damping_nms_per_rad;
            }
            for col in 0..6 {
                jd[col] = -jy[0][col];
            }
            jd[4] -= c.stiffness_nm_per_rad / c.inertia_kgm2;
            jd[5] -= c.damping_nms_per_rad / c.inertia_kgm2;
        }
        if let Some(w) = w {
            // d(α, h)/dt = (α̇, ḣ); d(α̇, ḣ)/dt = acc; dδ/dt = δ̇; dδ̇/dt = δ̈.
            *w = [[0.0; 6]; 6];
            w[0][2] = 1.0;
            w[1][3] = 1.0;
            w[2] = jy[0];
            w[3] = jy[1];
            if compliance.is_some() {
                w[4][5] = 1.0;
                w[5] = jd;
            }
        }
        let f = &m.friction;
        let hd = s.h_dot_m_s;
        // ∂acc/∂(strip load) at this state, for `quadratic_drag`: the difference of two
        // first-order-exact recoveries 1 N apart (the load enters the equations and the
        // reactions linearly; the normal-force feedback through Φ).
        let mut per_strip_n = None;
        for (i, p) in self.params.iter().enumerate() {
            // Direct change of the accelerations per unit parameter: through one generalised
            // friction input (Φ's column), or for the drag through the strip load; the third
            // entry is δ̈'s (with a compliant drive: −α̈'s, plus the drive side's own).
            let direct: [f64; 3] = if *p == LiftParam::HeadDrag {
                let d = match per_strip_n {
                    Some(d) => d,
                    None => {
                        let mut up = loads;
                        up.strip_load_n += 1.0;
                        let sign = Some(&e.sign);
                        let a1 = m.accelerations_near(pose, head, &s, &up, &torque, &phi, sign)?;
                        let a0 =
                            m.accelerations_near(pose, head, &s, &loads, &torque, &phi, sign)?;
                        let d = [a1[0] - a0[0], a1[1] - a0[1]];
                        per_strip_n = Some(d);
                        d
                    }
                };
                let v = head.strip_d_alpha.y * s.alpha_dot_rad_s + head.u.y * hd;
                let a = d[0] * v * v.abs();
                [a, d[1] * v * v.abs(), -a]
            } else if let (Some(c), true) = (
                &compliance,
                matches!(
                    p,
                    LiftParam::TorqueOffset
                        | LiftParam::DriveInertia
                        | LiftParam::DriveStiffness
                        | LiftParam::DriveDamping
                ),
            ) {
                let jd_kgm2 = c.inertia_kgm2;
                match p {
                    // The offset moves the drive side's torque only: δ̈ by −1/J_d.
                    LiftParam::TorqueOffset => [0.0, 0.0, -1.0 / jd_kgm2],
                    LiftParam::DriveInertia => [
                        0.0,
                        0.0,
                        -(drive_side_nm - transmitted_nm) / (jd_kgm2 * jd_kgm2),
                    ],
                    _ => {
                        // ∂τ/∂k = δ, ∂τ/∂c = δ̇.
                        let dtau = if *p == LiftParam::DriveStiffness {
                            y[4]
                        } else {
                            y[5]
                        };
                        let a = phi[0][Q_DRIVE] * dtau;
                        [a, phi[1][Q_DRIVE] * dtau, -dtau / jd_kgm2 - a]
                    }
                }
            } else {
                let (q, dq) = match *p {
                    LiftParam::Viscous(j) => (j.index(), e.rel_rate_rad_s[j.index()]),
                    LiftParam::Dry(j) => {
                        let k = j.index();
                        let mu = f.dry_mu[k];
                        // T_dry = μ·R·N·σ: per unit μ, R·N·σ (from the torque when μ ≠ 0).
                        let per_mu = if mu != 0.0 {
                            e.dry_torque_nm[k] / mu
                        } else {
                            m.pin_radius_m[k]
                                * e.normal_n[k]
                                * m.sign_law_revolute(k, e.rel_rate_rad_s[k])
                        };
                        (k, per_mu)
                    }
                    LiftParam::StribeckExcess(j) | LiftParam::StribeckSpeed(j) => {
                        // T_dry = μ·R·N·σ·s(w): per unit parameter, μ·R·N·σ·∂s/∂p.
                        let k = j.index();
                        let w = e.rel_rate_rad_s[k];
                        let (ds_de, ds_dvs) = m.stribeck_partials(k, w);
                        let ds = if matches!(p, LiftParam::StribeckExcess(_)) {
                            ds_de
                        } else {
                            ds_dvs
                        };
                        let per =
                            f.dry_mu[k] * m.pin_radius_m[k] * e.normal_n[k] * m.sign_law_plain(w);
                        (k, per * ds)
                    }
                    LiftParam::J8Viscous => (Q_SLIDE, -m.j8_count * hd),
                    LiftParam::J8Dry => (
                        Q_SLIDE,
                        -m.j8_count * m.j8_normal_n_each * m.sign_law_slide(hd),
                    ),
                    LiftParam::J9Damping => (Q_SLIDE, -m.j9_count * hd),
                    LiftParam::TorqueOffset => (Q_DRIVE, -1.0),
                    // Not reached (the strip-load and drive branches above; a delay is never
                    // a sensitivity run's parameter; the drive's parameters without a
                    // compliant drive move nothing): no generalised input.
                    LiftParam::HeadDrag
                    | LiftParam::SensorDelay
                    | LiftParam::SensorOffset
                    | LiftParam::DriveInertia
                    | LiftParam::DriveStiffness
                    | LiftParam::DriveDamping => (Q_DRIVE, 0.0),
                };
                let a = phi[0][q] * dq;
                [a, phi[1][q] * dq, -a]
            };
            let sv = &y[ns + ns * i..ns + ns * (i + 1)];
            let o = &mut dy[ns + ns * i..ns + ns * (i + 1)];
            o[0] = sv[2];
            o[1] = sv[3];
            for r in 0..2 {
                // The rigid drive's sum in its historical order (bit-for-bit the same runs).
                let mut v =
                    jy[r][0] * sv[0] + jy[r][1] * sv[1] + jy[r][2] * sv[2] + jy[r][3] * sv[3];
                if ns == 6 {
                    v += jy[r][4] * sv[4] + jy[r][5] * sv[5];
                }
                o[2 + r] = v + direct[r];
            }
            if ns == 6 {
                o[4] = sv[5];
                let mut v = direct[2];
                for col in 0..6 {
                    v += jd[col] * sv[col];
                }
                o[5] = v;
            }
        }
        Ok(())
    }

    /// [`SensSys::eval`] for the stepper's block of `B` (= [`LiftModel::n_state`]) components.
    fn rhs_block<const B: usize>(
        &self,
        t: f64,
        y: &[f64],
        dy: &mut [f64],
        w: Option<&mut [[f64; B]; B]>,
    ) -> Result<(), OdeError> {
        let mut full = [[0.0; 6]; 6];
        let want = w.is_some();
        if self.eval(t, y, dy, want.then_some(&mut full)).is_err() {
            // Outside the assembly range in a trial stage: reject the step.
            dy.fill(f64::NAN);
            return Ok(());
        }
        if let Some(w) = w {
            for r in 0..B {
                w[r].copy_from_slice(&full[r][..B]);
            }
        }
        Ok(())
    }
}

/// The block is the mechanical state: 4 components, 6 with a compliant drive (δ and δ̇ join it;
/// [`LiftModel::n_state`]).
impl<const B: usize> WSystem<B> for SensSys<'_> {
    fn dim(&self) -> usize {
        B + B * self.params.len()
    }
    fn rhs_w(
        &self,
        t: f64,
        y: &[f64],
        dy: &mut [f64],
        w: Option<&mut [[f64; B]; B]>,
    ) -> Result<(), OdeError> {
        self.rhs_block(t, y, dy, w)
    }

    /// Split: the state's equations read the state only, and every failure but the
    /// measure-zero ones [`SensSys::eval_state`] names is met in the state part.
    fn splits(&self) -> bool {
        self.split
    }

    fn rhs_head(&self, slot: usize, t: f64, y: &[f64], dy: &mut [f64]) -> Result<(), OdeError> {
        let mut stages = self.stages.borrow_mut();
        match self.eval_state(t, y, dy) {
            Ok(st) => stages[slot] = Some(st),
            Err(_) => {
                // As `rhs_block`: outside the assembly range in a trial stage.
                dy[..B].fill(f64::NAN);
                stages[slot] = None;
            }
        }
        Ok(())
    }

    fn rhs_rest(&self, slot: usize, _t: f64, y: &[f64], dy: &mut [f64]) -> Result<bool, OdeError> {
        let stages = self.stages.borrow();
        let Some(st) = &stages[slot] else {
            // Not reached: a failed state part makes the step's error NaN.
            return Ok(false);
        };
        if self.eval_sens(st, y, dy, None).is_err() {
            // The whole evaluation would have failed here, leaving this stage's torques as
            // the next guess (the later stages, at a NaN state, fail before they keep any).
            self.last_torque.set(Some(st.torque));
            return Ok(false);
        }
        Ok(true)
    }
}

/// The stepper kept in `slot`, restarted for a run of dimension `dim`, with the state's
/// absolute tolerances `atol` (its first `B`).
fn stepper<'s, const B: usize>(
    slot: &'s mut Option<Rosw<B>>,
    dim: usize,
    tol: Tolerances,
    atol: &[f64],
) -> &'s mut Rosw<B> {
    if slot.as_ref().is_some_and(|o| o.dim() != dim) {
        *slot = None;
    }
    let fresh = slot.is_none();
    let ode = slot.get_or_insert_with(|| Rosw::<B>::new(dim, B, tol));
    if !fresh {
        ode.restart(tol);
    }
    ode.set_atol(&atol[..B]);
    ode
}

/// The buffers of a sensitivity run, kept from one run to the next so that a fit's evaluations,
/// and the fits after it on the same thread, allocate nothing once the buffers have grown to
/// the trace's size (issue 8: reuse buffers across fits). Holds the Rosenbrock-W stepper (its
/// stage and dense-output vectors), the state, the dense-output buffer and the run's output
/// ([`SensitivityRun`]: n + n·p values, ~0.5 MB for an 8 s, 500 Hz trace and 16 parameters).
#[derive(Default)]
pub struct SensWorkspace {
    ode: Option<Rosw<4>>,
    /// The stepper of a model with a compliant drive (six state components).
    ode6: Option<Rosw<6>>,
    y: Vec<f64>,
    buf: Vec<f64>,
    run: SensitivityRun,
}

impl SensWorkspace {
    /// The output of the last run of [`simulate_sensitivities_in`] (complete when it returned
    /// `Ok`; a failed run leaves what it had read out).
    pub fn run(&self) -> &SensitivityRun {
        &self.run
    }

    /// Bytes held (capacity of every buffer), for callers that bound what a thread keeps.
    pub fn capacity_bytes(&self) -> usize {
        let ode = self.ode.as_ref().map_or(0, Rosw::capacity_bytes)
            + self.ode6.as_ref().map_or(0, Rosw::capacity_bytes);
        ode + std::mem::size_of::<f64>()
            * (self.y.capacity()
                + self.buf.capacity()
                + self.run.strip_height_m.capacity()
                + self.run.d_height.capacity())
    }
}

/// Simulate from the static start with sensitivities of H to `params` (the model's current
/// values and `offset_nm` are the point of linearisation). Allocates its buffers: for repeated
/// runs use [`simulate_sensitivities_in`] with one [`SensWorkspace`].
pub fn simulate_sensitivities(
    model: &LiftModel,
    inputs: &LiftInputs,
    params: &[LiftParam],
    offset_nm: f64,
    opts: &SimOptions,
) -> Result<SensitivityRun, SimError> {
    let mut ws = SensWorkspace::default();
    simulate_sensitivities_in(&mut ws, model, inputs, params, offset_nm, opts)?;
    Ok(ws.run)
}

/// [`simulate_sensitivities`] into `ws`: the result is `ws.run()`, the same bit for bit as a
/// run on a new workspace. Allocates only when a buffer must grow (a longer trace or more
/// parameters than any run on `ws` before).
pub fn simulate_sensitivities_in<'w>(
    ws: &'w mut SensWorkspace,
    model: &LiftModel,
    inputs: &LiftInputs,
    params: &[LiftParam],
    offset_nm: f64,
    opts: &SimOptions,
) -> Result<&'w SensitivityRun, SimError> {
    sensitivities_in(ws, model, inputs, params, offset_nm, opts, true)
}

/// [`simulate_sensitivities_in`], the stepper splitting its evaluations (a rejected step
/// skips its stages' sensitivities) or not: the same run bit for bit either way.
fn sensitivities_in<'w>(
    ws: &'w mut SensWorkspace,
    model: &LiftModel,
    inputs: &LiftInputs,
    params: &[LiftParam],
    offset_nm: f64,
    opts: &SimOptions,
    split: bool,
) -> Result<&'w SensitivityRun, SimError> {
    inputs.validate()?;
    let n = inputs.t_s.len();
    let p = params.len();
    let ns = model.n_state();
    let dim = ns + ns * p;
    let sim_opts = SimOptions {
        torque_offset_nm: offset_nm,
        drive: None,
        strip_spring: None,
        ..*opts
    };
    let start = initial_state(model, inputs, &sim_opts)?;
    let y = &mut ws.y;
    y.clear();
    y.resize(dim, 0.0);
    y[..4].copy_from_slice(&[start.alpha_rad, start.h_m, 0.0, 0.0]);
    // A compliant drive starts with its spring carrying the first torque: δ₀ = T₀/k.
    let deflection0 = initial_deflection_rad(model, inputs, &sim_opts, &start);
    if ns == 6 {
        y[4] = deflection0;
    }
    // Only the offset (and a compliant drive's stiffness, through δ₀) moves the static start
    // (friction vanishes at rest).
    if let Some(i) = params.iter().position(|q| *q == LiftParam::TorqueOffset) {
        let d = 1e-3;
        let at = |o: f64| {
            initial_state(
                model,
                inputs,
                &SimOptions {
                    torque_offset_nm: o,
                    ..sim_opts
                },
            )
        };
        let (a, b) = (at(offset_nm + d)?, at(offset_nm - d)?);
        y[ns + ns * i] = (a.alpha_rad - b.alpha_rad) / (2.0 * d);
        y[ns + ns * i + 1] = (a.h_m - b.h_m) / (2.0 * d);
        if let Some(c) = &model.drive_compliance {
            y[ns + ns * i + 4] = -1.0 / c.stiffness_nm_per_rad;
        }
    }
    if let (Some(c), Some(i)) = (
        &model.drive_compliance,
        params.iter().position(|q| *q == LiftParam::DriveStiffness),
    ) {
        y[ns + ns * i + 4] = -deflection0 / c.stiffness_nm_per_rad;
    }
    let mut sys = SensSys {
        model,
        inputs,
        params,
        offset_nm,
        fm_n: inputs.fm(0),
        last_torque: Cell::new(None),
        stages: RefCell::new([None; 3]),
        split,
    };
    let out = &mut ws.run;
    out.strip_height_m.clear();
    out.strip_height_m.reserve(n);
    out.d_height.clear();
    out.d_height.reserve(n * p);
    out.n_params = p;
    out.rhs_evaluations = 0;
    out.steps = 0;
    ws.buf.clear();
    ws.buf.resize(dim, 0.0);
    let tol = Tolerances {
        rtol: opts.rtol,
        atol: opts.atol,
        h_max: opts.h_max_s,
        ..Default::default()
    };
    // Only the state is error-controlled: an L-stable method keeps the sensitivities bounded,
    // and they come out within 0.2 % of tightly integrated ones at the fit's tolerance.
    // W: the state's Jacobian (4 × 4, 6 × 6 with a compliant drive), repeated over every
    // sensitivity column (their equations S′ = f_y·S + f_θ have the same Jacobian; the
    // coupling ∂(f_y·S)/∂y is left out of W).
    let rate_atol = RATE_ATOL_FACTOR * opts.atol;
    let atol = [
        opts.atol, opts.atol, rate_atol, rate_atol, opts.atol, rate_atol,
    ];
    let sample = |_: usize, y: &[f64]| -> Result<(), DynamicsError> {
        let (height, d_alpha, d_h) = model.strip_height_partials(y[0], y[1])?;
        out.strip_height_m.push(height);
        // H = y of strip: ∂H/∂θ = ∂H/∂α·∂α/∂θ + ∂H/∂h·∂h/∂θ.
        for i in 0..p {
            let sv = &y[ns + ns * i..ns + ns * i + 2];
            out.d_height.push(d_alpha * sv[0] + d_h * sv[1]);
        }
        Ok(())
    };
    let breaks = |k| inputs.is_break(k);
    let work = if ns == 6 {
        let ode = stepper(&mut ws.ode6, dim, tol, &atol);
        integrate(
            &mut sys,
            ode,
            inputs.t_s,
            breaks,
            y,
            opts.max_steps,
            &mut ws.buf,
            sample,
        )
    } else {
        let ode = stepper(&mut ws.ode, dim, tol, &atol);
        integrate(
            &mut sys,
            ode,
            inputs.t_s,
            breaks,
            y,
            opts.max_steps,
            &mut ws.buf,
            sample,
        )
    }
    .map_err(SimError::from_integrate)?;
    out.steps = work.steps;
    out.rhs_evaluations = work.rhs;
    Ok(&ws.run)
}

#[cfg(test)]
mod tests;

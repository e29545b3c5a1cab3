//! Equations of motion of the complete pantograph in the minimal coordinates (α, h), with every
//! joint's reaction force from the Newton–Euler equations of the bodies (the Lagrange
//! multipliers of the closed chain) and every joint's friction driven by its own reaction.
//!
//! Kane's form: M(α, h)·[α̈, ḧ] = b, with M and b summed over the bodies' partial velocities,
//! so the constraint forces drop out; they are then recovered body by body, loop by loop,
//! each loop a 2×2 solve (a Lagrange multiplier per constraint, in closed form).

use std::sync::Arc;

use super::geometry::Geometry;
use super::kinematics::{AssemblyError, HeadKin, Linkage, LinkagePose};
use super::readout::StripTable;
use super::topology::{BodyId, N_REV, RevJoint};
use super::vec2::V2;

mod parts;
mod reactions;
pub(super) use parts::sign0;
pub use parts::{
    DEFAULT_STRIBECK_SPEED_RAD_S, DynamicsError, Eval, FrictionBand, FrictionParams, Loads,
    Reactions, SignLaw, State,
};

/// The complete pantograph's dynamic model.
#[derive(Debug, Clone)]
pub struct LiftModel {
    pub linkage: Linkage,
    /// Masses and centroidal inertias, [`BodyId`] order.
    pub mass_kg: [f64; 7],
    pub inertia_kgm2: [f64; 7],
    pub gravity: V2,
    /// Pin radii R of the revolute joints.
    pub pin_radius_m: [f64; N_REV],
    /// J8: number of slides and the constant normal force of each (Section 4.2).
    pub j8_count: f64,
    pub j8_normal_n_each: f64,
    /// J9: number of springs, stiffness of each, preload (spring force at h = 0).
    pub j9_count: f64,
    pub j9_stiffness_n_per_m_each: f64,
    pub preload_n: f64,
    pub friction: FrictionParams,
    pub sign_law: SignLaw,
    /// `quadratic_drag` (issue 16, a lift effect; 0 in the paper's model): c_a = ½ρC_dA of the
    /// head and upper frame, N/(m/s)². The air's force on the strip is −c_a·v|v| with v the
    /// strip's vertical velocity, added to the strip load ([`LiftModel::head_drag_n`]).
    /// Assumptions: still air; the force acts vertically at the strip point (the strip's
    /// horizontal motion in a lift, a few cm over the whole stroke, is left out); the frame's
    /// own drag is lumped into the head's c_a.
    pub head_drag_ns2_per_m2: f64,
    /// `sensor_delay` (issue 16, a lift effect; 0 in the paper's model): the logger's H is the
    /// strip's height this long before, s, H_meas(t) = H(t − τ). An output effect: the
    /// dynamics never read it; a fit compares the model's H read τ late with the record
    /// (`identify`). The simulator never applies it (`simulate --effect sensor_delay` delays
    /// the recorded channel).
    pub h_sensor_delay_s: f64,
    /// `sensor_offset` (issue 16, a lift effect; 0 in the paper's model): the logger's H zero is
    /// off by this, m, H_meas = H + b. An output effect as the delay. Detectable only because
    /// a fit's start is pinned to the static equilibrium under the first sample's loads
    /// (`simulate::initial_state`), never to the measured H: an offset then shows as a
    /// constant gap from the first sample on.
    pub h_sensor_offset_m: f64,
    /// `stribeck` (issue 16, a lift effect; 0 in the paper's model): per revolute joint, the
    /// static friction's excess over the kinetic, e = μ_s/μ_k − 1 ([`LiftModel::stribeck_factor`]).
    pub stribeck_excess: [f64; N_REV],
    /// The Stribeck speed v_s of each revolute joint, rad/s: where the excess has fallen to
    /// 1/e of itself. Read only where the joint's excess is not 0.
    pub stribeck_speed_rad_s: [f64; N_REV],
    /// An effect **outside** the lift vocabulary, for tests that it is never named (issue 16):
    /// dry friction at one joint multiplied by a factor over a band of the lower arm's angle (a
    /// scored or dirty stretch of a pin). `None` in the paper's model; no fit estimates it.
    pub friction_band: Option<FrictionBand>,
    /// `drive_compliance` (issue 16, a lift effect; `None` in the paper's model, whose drive
    /// torque acts on the lower arm directly): the bellows as a spring and damper between the
    /// drive side, of its own inertia, and the lower arm ([`DriveCompliance`]).
    pub drive_compliance: Option<DriveCompliance>,
    /// Lower-arm range searched for static states (`[range]`), rad.
    pub alpha_range_rad: (f64, f64),
    /// H and its partials tabulated over α (geometry only; shared by the clones a fit makes).
    /// Made from `linkage` and `alpha_range_rad` by [`LiftModel::new`]: a model whose linkage
    /// is changed afterwards must be made anew.
    pub strip_table: Arc<StripTable>,
}

/// `drive_compliance` (issue 16, a lift effect; the paper's Fig 2a: the pneumatic bellows as an
/// equivalent spring and damper). The recorded drive torque T acts on the drive side (bellows
/// plate, cams, their lever: inertia J_d about the lower arm's axis, angle β); the drive side
/// turns the lower arm (angle α) through the bellows' spring k and damper c, which transmit
/// τ = k·δ + c·δ̇ with the deflection δ = β − α:
///
/// J_d·β̈ = T − τ,   the lower arm's Kane equation driven by τ instead of T.
///
/// The state gains δ and δ̇ (δ̈ = (T − τ)/J_d − α̈). A lift starts at rest with the spring
/// carrying the first sample's torque, δ₀ = T₀/k. Assumptions: linear spring and damper
/// (small deflections about the working pressure); the drive side a rigid body on the lower
/// arm's axis (the cams' radius R(α) lumped into k, c and J_d as equivalents at the arm); T
/// measured on the drive side (the bellows' pressure), so a rigid drive (k → ∞) is the paper's
/// model. Where a user sees it: a lift whose head rings or lags after the weight's cut and
/// every turn of the drive, at the two-mass mode √(k·(1/J_d + 1/M_α)), which no friction makes.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct DriveCompliance {
    /// k, N·m/rad.
    pub stiffness_nm_per_rad: f64,
    /// c, N·m·s/rad.
    pub damping_nms_per_rad: f64,
    /// J_d, kg·m².
    pub inertia_kgm2: f64,
}

impl DriveCompliance {
    /// The torque the bellows pass to the lower arm at deflection δ and rate δ̇, N·m.
    #[inline]
    pub fn transmitted_nm(&self, deflection_rad: f64, deflection_rate_rad_s: f64) -> f64 {
        self.stiffness_nm_per_rad * deflection_rad
            + self.damping_nms_per_rad * deflection_rate_rad_s
    }
}

/// Kane's equations of a state before the revolute joints' friction is added.
#[derive(Debug, Clone, Copy)]
pub(super) struct Kane {
    pub m_aa: f64,
    pub m_ah: f64,
    pub m_hh: f64,
    pub b_a: f64,
    pub b_h: f64,
    /// Force along the slide on the head (J9 spring and damper, J8 friction), N.
    pub f_axial: f64,
}

/// Number of generalised friction inputs: the revolute torques, the slide force, the drive.
pub const N_Q: usize = N_REV + 2;
/// Index of the slide's axial force on the head in q.
pub const Q_SLIDE: usize = N_REV;
/// Index of the drive torque in q.
pub const Q_DRIVE: usize = N_REV + 1;

/// Iteration limit and tolerance of the friction–reaction fixed point.
const MAX_ITER: u32 = 60;
const ITER_RTOL: f64 = 1e-14;

impl LiftModel {
    /// The model of a geometry with Table 4 friction and the reference tanh sign law.
    pub fn new(g: &Geometry) -> Self {
        let mut mass_kg = [0.0; 7];
        let mut inertia_kgm2 = [0.0; 7];
        for b in BodyId::ALL {
            mass_kg[b.index()] = g.body(b).mass_kg;
            inertia_kgm2[b.index()] = g.body(b).inertia_cm_kgm2;
        }
        let mut pin_radius_m = [0.0; N_REV];
        for j in RevJoint::ALL {
            pin_radius_m[j.index()] = g.revolute[j.index()].pin_radius_m;
        }
        let linkage = Linkage::new(g);
        let alpha_range_rad = (g.alpha_min_rad, g.alpha_max_rad);
        Self {
            strip_table: Arc::new(StripTable::new(&linkage, alpha_range_rad)),
            linkage,
            mass_kg,
            inertia_kgm2,
            gravity: V2::new(0.0, -g.gravity_m_s2),
            pin_radius_m,
            j8_count: g.slide.j8_count,
            j8_normal_n_each: g.slide.j8_normal_force_n_each,
            j9_count: g.slide.j9_count,
            j9_stiffness_n_per_m_each: g.slide.j9_stiffness_n_per_m_each,
            preload_n: g.slide.preload_n,
            friction: FrictionParams::baseline(g),
            sign_law: SignLaw::REFERENCE,
            head_drag_ns2_per_m2: 0.0,
            h_sensor_delay_s: 0.0,
            h_sensor_offset_m: 0.0,
            stribeck_excess: [0.0; N_REV],
            stribeck_speed_rad_s: [DEFAULT_STRIBECK_SPEED_RAD_S; N_REV],
            friction_band: None,
            drive_compliance: None,
            alpha_range_rad,
        }
    }

    /// Number of mechanical state components: α, h, α̇, ḣ, and with a compliant drive its
    /// deflection δ and δ̇ ([`DriveCompliance`]).
    pub fn n_state(&self) -> usize {
        if self.drive_compliance.is_some() {
            6
        } else {
            4
        }
    }

    /// The `quadratic_drag` load on the strip at a state, N: c_a·v|v| with v the strip's vertical
    /// velocity (∂y/∂α·α̇ + u_y·ḣ), positive pressing down (rising) like the strip load it is
    /// added to. 0 when the model has no drag.
    #[inline]
    pub fn head_drag_n(&self, head: &HeadKin, s: &State) -> f64 {
        if self.head_drag_ns2_per_m2 == 0.0 {
            return 0.0;
        }
        let v = head.strip_d_alpha.y * s.alpha_dot_rad_s + head.u.y * s.h_dot_m_s;
        self.head_drag_ns2_per_m2 * v * v.abs()
    }

    /// The contact-strip height H at (α, h) with its partials ∂H/∂α (m/rad) and ∂H/∂h (1):
    /// the read-out of a lift record and of its sensitivities. From the geometry's table where
    /// it has a checked interval (within 10⁻⁹ m of the closed form: [`StripTable`]), else from
    /// the closed-form pose.
    #[inline]
    pub fn strip_height_partials(
        &self,
        alpha_rad: f64,
        h_m: f64,
    ) -> Result<(f64, f64, f64), AssemblyError> {
        if let Some(v) = self.strip_table.lookup(alpha_rad, h_m) {
            return Ok(v);
        }
        let pose = self.linkage.pose(alpha_rad)?;
        let head = self.linkage.head(&pose, h_m, 0.0, 0.0);
        Ok((head.strip.y, head.strip_d_alpha.y, head.u.y))
    }

    /// The sign law's value for revolute joint `i` at relative rate `w` (0 for exact statics),
    /// times its Stribeck factor.
    pub(super) fn sign_law_revolute(&self, i: usize, w: f64) -> f64 {
        self.sign_law_plain(w) * self.stribeck_factor(i, w)
    }

    /// The sign law's value for a revolute joint at relative rate `w`, without a Stribeck factor.
    pub(super) fn sign_law_plain(&self, w: f64) -> f64 {
        match self.sign_law {
            SignLaw::Exact { .. } => sign0(w),
            law => law.revolute(w, 0.0),
        }
    }

    /// ∂s/∂e and ∂s/∂v_s of joint `i`'s Stribeck factor at relative rate `w`
    /// ([`LiftModel::stribeck_factor`]).
    pub fn stribeck_partials(&self, i: usize, w: f64) -> (f64, f64) {
        let (e, vs) = (self.stribeck_excess[i], self.stribeck_speed_rad_s[i]);
        let u = w / vs;
        let g = (-u * u).exp();
        (g, e * g * 2.0 * u * u / vs)
    }

    /// The out-of-vocabulary friction band's factor on joint `i` at lower-arm angle `alpha_rad`
    /// ([`LiftModel::friction_band`]); 1 outside it or without one.
    pub fn band_factor(&self, i: usize, alpha_rad: f64) -> f64 {
        match &self.friction_band {
            Some(b)
                if b.joint_index == i && (b.alpha_lo_rad..=b.alpha_hi_rad).contains(&alpha_rad) =>
            {
                b.factor
            }
            _ => 1.0,
        }
    }

    /// `stribeck` at revolute joint `i` (issue 16, a lift effect): the dry friction's factor
    /// s(w) = 1 + e·exp(−(w/v_s)²) at relative rate `w`, e = μ_s/μ_k − 1
    /// ([`LiftModel::stribeck_excess`]), v_s = [`LiftModel::stribeck_speed_rad_s`]; 1 where
    /// e = 0 (the paper's model). Assumptions: the Gaussian Stribeck curve (exponent 2), the
    /// same static-to-kinetic ratio in both directions, the kinetic μ the joint's `dry_mu`.
    /// Quasi-static statics (`statics`) keep the kinetic μ.
    pub fn stribeck_factor(&self, i: usize, w: f64) -> f64 {
        let e = self.stribeck_excess[i];
        if e == 0.0 {
            return 1.0;
        }
        let vs = self.stribeck_speed_rad_s[i];
        1.0 + e * (-(w / vs) * (w / vs)).exp()
    }

    /// The sign law's value for the slide at rate `v`.
    pub(super) fn sign_law_slide(&self, v: f64) -> f64 {
        self.sign_law.slide(v)
    }

    /// Total J9 stiffness, N/m.
    pub fn j9_stiffness_n_per_m(&self) -> f64 {
        self.j9_count * self.j9_stiffness_n_per_m_each
    }

    /// Accelerations, reactions and friction at a state.
    ///
    /// Friction and reactions are implicit in each other (N = |reaction| sets the dry torque,
    /// which changes the accelerations and so the reactions). Solved by fixed-point iteration
    /// from the friction-free reactions: μ·R ≤ 0.009 m against link levers ≥ 0.15 m makes the
    /// map a contraction by about 0.05 per step, so a few iterations reach 10⁻¹⁴ relative.
    pub fn eval(
        &self,
        pose: &LinkagePose,
        s: &State,
        loads: &Loads,
    ) -> Result<Eval, DynamicsError> {
        let head = self
            .linkage
            .head(pose, s.h_m, s.alpha_dot_rad_s, s.h_dot_m_s);
        self.eval_with_head(pose, &head, s, loads, None)
    }

    /// [`LiftModel::eval`] with the head's kinematics given and the fixed point started from
    /// `guess` (friction torques of a nearby evaluation) instead of the viscous torques.
    pub(super) fn eval_with_head(
        &self,
        pose: &LinkagePose,
        head: &HeadKin,
        s: &State,
        loads: &Loads,
        guess: Option<&[f64; N_REV]>,
    ) -> Result<Eval, DynamicsError> {
        self.eval_with_kane(pose, head, s, loads, guess)
            .map(|(e, _)| e)
    }

    /// [`LiftModel::eval_with_head`] and the [`LiftModel::kane`] it solved, for a caller that
    /// needs both at the same state ([`LiftModel::response`]'s, the same value to the bit).
    pub(super) fn eval_with_kane(
        &self,
        pose: &LinkagePose,
        head: &HeadKin,
        s: &State,
        loads: &Loads,
        guess: Option<&[f64; N_REV]>,
    ) -> Result<(Eval, Kane), DynamicsError> {
        let ad = s.alpha_dot_rad_s;
        let f = &self.friction;
        let k = self.kane(pose, head, s, loads);
        let Kane {
            m_aa,
            m_ah,
            m_hh,
            b_a,
            b_h,
            f_axial,
        } = k;
        let det = m_aa * m_hh - m_ah * m_ah;
        if det.is_nan() || det <= 0.0 {
            return Err(DynamicsError::Singular {
                alpha_rad: s.alpha_rad,
            });
        }
        let (j9_spring_n, j9_damping_n, j8_viscous_n, j8_dry_n) = self.slide_forces(s);
        let ad2 = ad * ad;

        let mut e = Eval {
            j8_viscous_n,
            j8_dry_n,
            j9_spring_n,
            j9_damping_n,
            ..Default::default()
        };
        let mut rate = [0.0; N_REV];
        for j in RevJoint::ALL {
            rate[j.index()] = pose.rel_rate(j);
            e.rel_rate_rad_s[j.index()] = rate[j.index()] * ad;
        }
        let j6 = RevJoint::J6.index();
        // Viscous torques do not depend on the reactions; J6 is locked (rate 0): its friction
        // does no work and its static part is inside the J6 couple.
        let mut sgn = [0.0; N_REV];
        for i in 0..N_REV {
            if i == j6 {
                continue;
            }
            e.viscous_torque_nm[i] = f.viscous_nms_per_rad[i] * e.rel_rate_rad_s[i];
            sgn[i] = self.sign_law.revolute(e.rel_rate_rad_s[i], rate[i])
                * self.stribeck_factor(i, e.rel_rate_rad_s[i])
                * self.band_factor(i, s.alpha_rad);
        }
        let mut torque = match guess {
            Some(g) => *g,
            None => e.viscous_torque_nm,
        };
        torque[j6] = 0.0;
        for it in 1..=MAX_ITER {
            let mut b = b_a;
            for i in 0..N_REV {
                b -= torque[i] * rate[i];
            }
            let add = (b * m_hh - m_ah * b_h) / det;
            let hdd = (m_aa * b_h - m_ah * b) / det;
            let r = self.reactions(pose, head, ad2, add, hdd, &torque, loads, f_axial);
            let mut change: f64 = 0.0;
            let mut scale: f64 = 0.0;
            for i in 0..N_REV {
                if i == j6 {
                    continue;
                }
                let n = r.force_n[i].norm();
                let dry = f.dry_mu[i] * self.pin_radius_m[i] * n * sgn[i];
                let t = e.viscous_torque_nm[i] + dry;
                change = change.max((t - torque[i]).abs());
                scale = scale.max(t.abs());
                torque[i] = t;
                e.dry_torque_nm[i] = dry;
                e.normal_n[i] = n;
            }
            e.normal_n[j6] = r.force_n[j6].norm();
            e.alpha_ddot_rad_s2 = add;
            e.h_ddot_m_s2 = hdd;
            e.reactions = r;
            e.iterations = it;
            if change <= ITER_RTOL * (1.0 + scale) {
                e.sign = sgn;
                // One more pass is not needed: the accelerations above used torques within
                // the tolerance of the ones stored.
                return Ok((e, k));
            }
        }
        Err(DynamicsError::FrictionNotConverged {
            alpha_rad: s.alpha_rad,
        })
    }

    /// J9 spring force (preload − k·h), J9 damping, J8 viscous and J8 dry force, N; the
    /// spring pushes the head up the slide, the other three oppose ḣ. J8's normal force is the
    /// constant of Section 4.2, not a reaction.
    #[inline]
    pub(super) fn slide_forces(&self, s: &State) -> (f64, f64, f64, f64) {
        let f = &self.friction;
        let hd = s.h_dot_m_s;
        (
            self.preload_n - self.j9_stiffness_n_per_m() * s.h_m,
            self.j9_count * f.j9_damping_ns_per_m_each * hd,
            self.j8_count * f.j8_viscous_ns_per_m_each * hd,
            self.j8_count * self.j8_normal_n_each * f.j8_dry_mu * self.sign_law.slide(hd),
        )
    }

    /// Kane's equations without the revolute joints' friction: the mass matrix and the
    /// generalised forces of gravity, inertia's velocity terms, the drive, the strip load and the
    /// head suspension (J8, J9).
    pub(super) fn kane(
        &self,
        pose: &LinkagePose,
        head: &HeadKin,
        s: &State,
        loads: &Loads,
    ) -> Kane {
        let ad2 = s.alpha_dot_rad_s * s.alpha_dot_rad_s;
        let g = self.gravity;
        let strip_force = V2::new(0.0, -loads.strip_load_n);
        let (mut m_aa, mut b_a) = (0.0, loads.drive_torque_nm);
        for i in 0..6 {
            let bk = &pose.bodies[i];
            let (m, inertia) = (self.mass_kg[i], self.inertia_kgm2[i]);
            let v = bk.com.d1;
            m_aa += m * v.norm2() + inertia * bk.w1 * bk.w1;
            b_a += v.dot(m * g - (m * ad2) * bk.com.d2) - inertia * bk.w1 * bk.w2 * ad2;
        }
        let hi = BodyId::Head.index();
        let (mh, ih) = (self.mass_kg[hi], self.inertia_kgm2[hi]);
        let sus = pose.body(BodyId::Suspension);
        let vh = head.com_d_alpha;
        m_aa += mh * vh.norm2() + ih * sus.w1 * sus.w1;
        let head_free = mh * g - mh * head.com_acc0;
        b_a += vh.dot(head_free) - ih * sus.w1 * sus.w2 * ad2 + head.strip_d_alpha.dot(strip_force);
        // Head suspension forces along the slide (on the head): J9 spring and damper, J8.
        let (spring, damping, j8_viscous, j8_dry) = self.slide_forces(s);
        let f_axial = spring - damping - j8_viscous - j8_dry;
        Kane {
            m_aa,
            m_ah: mh * vh.dot(head.u),
            m_hh: mh,
            b_a,
            b_h: head.u.dot(head_free + strip_force) + f_axial,
            f_axial,
        }
    }

    /// Linear response of the accelerations to the generalised friction inputs
    /// q = (revolute torques T_j, slide force on the head, drive torque), at a converged
    /// [`Eval`], with the normal-force feedback included: a change δq of the inputs moves the
    /// reactions, so the normal forces, so the dry torques, so the inputs again:
    /// δq_total = (I − C)⁻¹ δq, C_jl = μ_j R_j σ_j n̂_j·∂f_j/∂q_l. Returns
    /// ∂(α̈, ḧ)/∂q = A (I − C)⁻¹ (2 × [`N_Q`]). Everything is affine in q at a fixed state,
    /// so the columns of ∂f/∂q are exact differences of reaction recoveries.
    ///
    /// `k`: [`LiftModel::kane`] at (pose, head, s, loads), as [`LiftModel::eval_with_kane`]
    /// returned it with `e`.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn response(
        &self,
        pose: &LinkagePose,
        head: &HeadKin,
        s: &State,
        loads: &Loads,
        e: &Eval,
        k: &Kane,
    ) -> Result<[[f64; N_Q]; 2], DynamicsError> {
        let det = k.m_aa * k.m_hh - k.m_ah * k.m_ah;
        // M⁻¹ applied to a generalised-force change (δb_α, δb_h).
        let minv = |ba: f64, bh: f64| {
            (
                (ba * k.m_hh - k.m_ah * bh) / det,
                (k.m_aa * bh - k.m_ah * ba) / det,
            )
        };
        let ad2 = s.alpha_dot_rad_s * s.alpha_dot_rad_s;
        let mut torque = [0.0; N_REV];
        for i in 0..N_REV {
            torque[i] = e.viscous_torque_nm[i] + e.dry_torque_nm[i];
        }
        let base = self.reactions(
            pose,
            head,
            ad2,
            e.alpha_ddot_rad_s2,
            e.h_ddot_m_s2,
            &torque,
            loads,
            k.f_axial,
        );
        let j6 = RevJoint::J6.index();
        let mut a = [[0.0; N_Q]; 2];
        // I − C, built as the identity minus the feedback.
        let mut c = [[0.0; N_Q]; N_Q];
        for (i, row) in c.iter_mut().enumerate() {
            row[i] = 1.0;
        }
        for l in 0..N_Q {
            if l == j6 {
                continue;
            }
            let (ba, bh) = match l {
                l if l < N_REV => (-pose.rel_rate(RevJoint::ALL[l]), 0.0),
                Q_SLIDE => (0.0, 1.0),
                _ => (1.0, 0.0),
            };
            let (da, dh) = minv(ba, bh);
            a[0][l] = da;
            a[1][l] = dh;
            let mut t = torque;
            let mut fax = k.f_axial;
            if l < N_REV {
                t[l] += 1.0;
            } else if l == Q_SLIDE {
                fax += 1.0;
            }
            let r = self.reactions(
                pose,
                head,
                ad2,
                e.alpha_ddot_rad_s2 + da,
                e.h_ddot_m_s2 + dh,
                &t,
                loads,
                fax,
            );
            for j in 0..N_REV {
                let n = e.normal_n[j];
                if j == j6 || n == 0.0 || e.dry_torque_nm[j] == 0.0 {
                    continue;
                }
                // μRσ = dry torque / N.
                let dn = base.force_n[j].dot(r.force_n[j] - base.force_n[j]) / n;
                c[j][l] -= e.dry_torque_nm[j] / n * dn;
            }
        }
        // Φ = A·(I − C)⁻¹ ⇔ Φ·(I − C) = A: two row systems, solved in place on the stack.
        solve_rows(c, a).ok_or(DynamicsError::FrictionNotConverged {
            alpha_rad: s.alpha_rad,
        })
    }

    /// Accelerations at a state `s` near a converged evaluation whose friction torques are
    /// `t0` and whose response is `phi` ([`LiftModel::response`]): one reaction recovery at the
    /// torques `t0`, one fixed-point update δT, and the fixed point's remaining change through
    /// Φ: acc(t0) + Φ·δT. Exact to first order in the state change (the neglected terms are
    /// O(|Δy|·|δT|) = O(|Δy|²)), so a one-sided difference quotient built from it has the same
    /// O(Δy) truncation as one built from a fully iterated [`LiftModel::eval_with_head`], at the
    /// cost of one recovery instead of several. `sign`: the revolute joints' sign-law values
    /// when the caller knows them unchanged (α and α̇ as at the evaluation), else computed.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn accelerations_near(
        &self,
        pose: &LinkagePose,
        head: &HeadKin,
        s: &State,
        loads: &Loads,
        t0: &[f64; N_REV],
        phi: &[[f64; N_Q]; 2],
        sign: Option<&[f64; N_REV]>,
    ) -> Result<[f64; 2], DynamicsError> {
        let ad = s.alpha_dot_rad_s;
        let f = &self.friction;
        let k = self.kane(pose, head, s, loads);
        let det = k.m_aa * k.m_hh - k.m_ah * k.m_ah;
        if det.is_nan() || det <= 0.0 {
            return Err(DynamicsError::Singular {
                alpha_rad: s.alpha_rad,
            });
        }
        let mut rate = [0.0; N_REV];
        let mut b = k.b_a;
        for j in RevJoint::ALL {
            let i = j.index();
            rate[i] = pose.rel_rate(j);
            b -= t0[i] * rate[i];
        }
        let add = (b * k.m_hh - k.m_ah * k.b_h) / det;
        let hdd = (k.m_aa * k.b_h - k.m_ah * b) / det;
        let r = self.reactions(pose, head, ad * ad, add, hdd, t0, loads, k.f_axial);
        let j6 = RevJoint::J6.index();
        let mut acc = [add, hdd];
        for i in 0..N_REV {
            if i == j6 {
                continue;
            }
            let w = rate[i] * ad;
            let sg = match sign {
                Some(sg) => sg[i],
                None => {
                    self.sign_law.revolute(w, rate[i])
                        * self.stribeck_factor(i, w)
                        * self.band_factor(i, s.alpha_rad)
                }
            };
            let t = f.viscous_nms_per_rad[i] * w
                + f.dry_mu[i] * self.pin_radius_m[i] * r.force_n[i].norm() * sg;
            let dt = t - t0[i];
            acc[0] += phi[0][i] * dt;
            acc[1] += phi[1][i] * dt;
        }
        Ok(acc)
    }

    /// Residual of the two equations the reaction recovery leaves unused (lower-arm moment
    /// about J1, head force along the slide), for checking: both ≈ 0 at a consistent [`Eval`].
    pub fn unused_equations(
        &self,
        pose: &LinkagePose,
        s: &State,
        loads: &Loads,
        e: &Eval,
    ) -> (f64, f64) {
        use RevJoint as J;
        let head = self
            .linkage
            .head(pose, s.h_m, s.alpha_dot_rad_s, s.h_dot_m_s);
        let li = BodyId::LowerArm.index();
        let lower = &pose.bodies[li];
        let (add, ad2) = (e.alpha_ddot_rad_s2, s.alpha_dot_rad_s * s.alpha_dot_rad_s);
        let need = self.mass_kg[li] * (lower.com.d1 * add + lower.com.d2 * ad2 - self.gravity);
        let j1 = pose.joints[J::J1.index()].p;
        let t = |j: J| e.viscous_torque_nm[j.index()] + e.dry_torque_nm[j.index()];
        let f = |j: J| e.reactions.force_n[j.index()];
        let lhs = loads.drive_torque_nm - t(J::J1) + t(J::J3) + t(J::J4)
            - (pose.joints[J::J3.index()].p - j1).cross(f(J::J3))
            - (pose.joints[J::J4.index()].p - j1).cross(f(J::J4));
        let rhs = self.inertia_kgm2[li] * add + (lower.com.p - j1).cross(need);
        (lhs - rhs, e.reactions.j8_force_n.dot(head.u))
    }

    /// Mechanical energy: kinetic + gravity + J9 spring, J (the drive's and the strip loads'
    /// work is the caller's to add).
    pub fn energy_j(&self, pose: &LinkagePose, s: &State) -> f64 {
        let head = self
            .linkage
            .head(pose, s.h_m, s.alpha_dot_rad_s, s.h_dot_m_s);
        let ad = s.alpha_dot_rad_s;
        let mut e = 0.0;
        for i in 0..6 {
            let bk = &pose.bodies[i];
            let v = bk.com.d1 * ad;
            e += 0.5 * self.mass_kg[i] * v.norm2()
                + 0.5 * self.inertia_kgm2[i] * (bk.w1 * ad).powi(2);
            e -= self.mass_kg[i] * self.gravity.dot(bk.com.p);
        }
        let hi = BodyId::Head.index();
        let vh = head.com_d_alpha * ad + head.u * s.h_dot_m_s;
        let wh = pose.body(BodyId::Suspension).w1 * ad;
        e += 0.5 * self.mass_kg[hi] * vh.norm2() + 0.5 * self.inertia_kgm2[hi] * wh * wh;
        e -= self.mass_kg[hi] * self.gravity.dot(head.com);
        // Spring force on the head preload − k·h ⇒ potential −preload·h + k·h²/2.
        e += -self.preload_n * s.h_m + 0.5 * self.j9_stiffness_n_per_m() * s.h_m * s.h_m;
        e
    }
}

/// X with X·M = B for the 2 × [`N_Q`] right-hand side B: Gaussian elimination with partial
/// pivoting on Mᵀ (fixed size, on the stack). `None` if M is singular.
fn solve_rows(m: [[f64; N_Q]; N_Q], b: [[f64; N_Q]; 2]) -> Option<[[f64; N_Q]; 2]> {
    // Mᵀ·xᵀ = bᵀ: work on t = Mᵀ with the two right-hand sides as extra columns.
    let mut t = [[0.0; N_Q + 2]; N_Q];
    for i in 0..N_Q {
        for j in 0..N_Q {
            t[i][j] = m[j][i];
        }
        t[i][N_Q] = b[0][i];
        t[i][N_Q + 1] = b[1][i];
    }
    for col in 0..N_Q {
        let piv = (col..N_Q).max_by(|&x, &y| t[x][col].abs().total_cmp(&t[y][col].abs()))?;
        if t[piv][col] == 0.0 || !t[piv][col].is_finite() {
            return None;
        }
        t.swap(col, piv);
        let inv = 1.0 / t[col][col];
        for row in col + 1..N_Q {
            let f = t[row][col] * inv;
            if f != 0.0 {
                for k in col..N_Q + 2 {
                    t[row][k] -= f * t[col][k];
                }
            }
        }
    }
    let mut out = [[0.0; N_Q]; 2];
    for r in 0..2 {
        for i in (0..N_Q).rev() {
            let mut v = t[i][N_Q + r];
            for k in i + 1..N_Q {
                v -= t[i][k] * out[r][k];
            }
            out[r][i] = v / t[i][i];
        }
    }
    Some(out)
}

#[cfg(test)]
mod tests;

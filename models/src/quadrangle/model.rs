//! The lower quadrangle as a planar four-bar on an inclined frame: loop closure in closed form,
//! derivatives in α, Kane's equation of motion, reactions and reaction-driven joint friction.
//!
//! Assumptions (stated where they are made, collected here):
//! - Bodies, joint positions, masses and Table 4 friction are the lift model's
//!   (`models/data/160ec-geometry.toml`): the same lower loop, detached from the upper loop, the
//!   head and the drive. The whole upper arm (Table 2 no. 3) swings with the loop.
//! - The incline γ is the frame plane's angle to the horizontal. The frame is turned about the
//!   transverse axis (parallel to the joint axes), so gravity stays in the plane of motion, with
//!   the lower arm's free end (J3, +x of the geometry file) downhill and the arms' side of the
//!   frame facing down — the quadrangle hangs under the frame like a pendulum: gravity is
//!   g·(sin γ, cos γ) in frame coordinates. At γ = 70° the lower arm alone would hang plumb at
//!   α = +20°; the loop rests at α ≈ 25.5° (frictionless). The other sense (arms above the
//!   frame, gravity g·(sin γ, −cos γ)) has no rest position inside this geometry's assembly
//!   range (α ≈ −18° … 53°: the loop toggles at both ends), so it cannot swing there.
//!   The paper's geometry is not published: its α₀ = −10.1° is not reproducible on the assumed
//!   one, whose swing is therefore released 10.1° below its own rest angle by default.
//! - α is the lower arm's angle to the frame plane (the lift's α: 0 = parallel to the frame,
//!   positive raising). β is the upper arm's angle to the frame plane: the J3 → J5 line against
//!   the frame's −x direction, positive when J5 rises (raising sense). β follows from α through
//!   the loop; it is a second reading of the one degree of freedom.
//! - Friction of each joint: T = D·ω_rel + N·R·μ·sign(ω_rel) (paper, rotational law), N = |joint
//!   reaction|, recovered from the bodies' Newton–Euler equations at each state.

use crate::lift::dynamics::DynamicsError;
use crate::lift::geometry::{Geometry, Points};
use crate::lift::kinematics::{AssemblyError, BodyKin, PointKin};
use crate::lift::topology::{BodyId, RevJoint};
use crate::lift::vec2::{Rot, V2};

/// The quadrangle's moving bodies.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum QBody {
    LowerArm,
    CouplingRod,
    UpperArm,
}

impl QBody {
    pub const ALL: [QBody; 3] = [QBody::LowerArm, QBody::CouplingRod, QBody::UpperArm];

    /// The body's key in the geometry file and in `test.rig.attachments[].body`.
    pub fn key(self) -> &'static str {
        self.lift().key()
    }
    pub fn named(key: &str) -> Option<QBody> {
        Self::ALL.into_iter().find(|b| b.key() == key)
    }
    pub fn lift(self) -> BodyId {
        match self {
            QBody::LowerArm => BodyId::LowerArm,
            QBody::CouplingRod => BodyId::CouplingRod,
            QBody::UpperArm => BodyId::UpperArm,
        }
    }
    pub fn index(self) -> usize {
        self as usize
    }
}

/// The quadrangle's joints. The paper's Section 5.1 lists "J1, J2, J3 and J4"; by its own
/// Table 4 and Fig 3 the loop's four joints are J1, J2, J2′ (coupling rod – upper arm) and J3
/// (J4 belongs to the upper quadrangle), which is what this model uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum QJoint {
    J1,
    J2,
    J2p,
    J3,
}

/// Number of joints of the quadrangle.
pub const N_JOINT: usize = 4;

impl QJoint {
    pub const ALL: [QJoint; N_JOINT] = [QJoint::J1, QJoint::J2, QJoint::J2p, QJoint::J3];

    /// The paper's name (`J2'` for J2′).
    pub fn name(self) -> &'static str {
        self.lift().name()
    }
    pub fn lift(self) -> RevJoint {
        match self {
            QJoint::J1 => RevJoint::J1,
            QJoint::J2 => RevJoint::J2,
            QJoint::J2p => RevJoint::J2p,
            QJoint::J3 => RevJoint::J3,
        }
    }
    pub fn index(self) -> usize {
        self as usize
    }
}

/// Friction parameters of the four joints, [`QJoint`] order.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct QuadFriction {
    pub viscous_nms_per_rad: [f64; N_JOINT],
    pub dry_mu: [f64; N_JOINT],
}

impl QuadFriction {
    /// Table 4 (through the geometry file).
    pub fn baseline(g: &Geometry) -> Self {
        let mut f = Self::frictionless();
        for j in QJoint::ALL {
            let r = &g.revolute[j.lift().index()];
            f.viscous_nms_per_rad[j.index()] = r.viscous_nms_per_rad;
            f.dry_mu[j.index()] = r.dry_mu;
        }
        f
    }
    pub fn frictionless() -> Self {
        Self {
            viscous_nms_per_rad: [0.0; N_JOINT],
            dry_mu: [0.0; N_JOINT],
        }
    }
}

/// A point mass fixed to a body (a test weight), at body-frame coordinates of the geometry file.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PointMass {
    pub body: QBody,
    pub mass_kg: f64,
    pub position_m: V2,
}

/// Why a quadrangle cannot be built from the given rig.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("`{field}`: {message}")]
pub struct RigError {
    pub field: String,
    pub message: String,
}

/// The quadrangle at one α.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct QPose {
    pub alpha_rad: f64,
    /// [`QBody`] order.
    pub bodies: [BodyKin; 3],
    /// Joint centres, [`QJoint`] order.
    pub joints: [PointKin; N_JOINT],
}

impl QPose {
    pub fn body(&self, b: QBody) -> &BodyKin {
        &self.bodies[b.index()]
    }
    /// Rate coefficient of a joint: ω_rel = r·α̇, ω_rel = θ̇(second) − θ̇(first) as in the lift.
    pub fn rel_rate(&self, j: QJoint) -> f64 {
        let w = |b: QBody| self.bodies[b.index()].w1;
        match j {
            QJoint::J1 => w(QBody::LowerArm),
            QJoint::J2 => w(QBody::CouplingRod),
            QJoint::J2p => w(QBody::UpperArm) - w(QBody::CouplingRod),
            QJoint::J3 => w(QBody::UpperArm) - w(QBody::LowerArm),
        }
    }
    /// β, rad: the upper arm's angle to the frame plane (module doc), in (−π, π].
    pub fn beta_rad(&self) -> f64 {
        let r = self.body(QBody::UpperArm).rot;
        // J3 → J5 is the upper arm's ξ axis (cos θ, sin θ); against −x, positive up: (−c, s).
        r.s.atan2(-r.c)
    }
    /// dβ/dα.
    pub fn beta_d_alpha(&self) -> f64 {
        -self.body(QBody::UpperArm).w1
    }
}

/// State in the one coordinate.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct QState {
    pub alpha_rad: f64,
    pub alpha_dot_rad_s: f64,
}

/// One evaluation of the equation of motion.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct QEval {
    pub alpha_ddot_rad_s2: f64,
    /// Force the first body of each joint exerts on the second (J1, J2: the frame on the arm), N.
    pub force_n: [V2; N_JOINT],
    pub rel_rate_rad_s: [f64; N_JOINT],
    pub viscous_torque_nm: [f64; N_JOINT],
    pub dry_torque_nm: [f64; N_JOINT],
    pub normal_n: [f64; N_JOINT],
    pub iterations: u32,
}

/// Fixed-point limits of the friction–reaction coupling (as in the lift model).
const MAX_ITER: u32 = 60;
const ITER_RTOL: f64 = 1e-14;

/// The lower-quadrangle swing model.
#[derive(Debug, Clone)]
pub struct Quadrangle {
    pub ground_j1: V2,
    pub ground_j2: V2,
    pts: Points,
    pub com_local: [V2; 3],
    pub mass_kg: [f64; 3],
    /// About the centre of mass, kg·m².
    pub inertia_kgm2: [f64; 3],
    pub pin_radius_m: [f64; N_JOINT],
    /// Gravity in frame coordinates, m/s².
    pub gravity: V2,
    pub incline_rad: f64,
    pub friction: QuadFriction,
    sign: f64,
    d_u: V2,
    d_c: V2,
    r_u: f64,
    r_c: f64,
}

/// Circle (a, r1) ∩ circle (b, r2) on the side `sign` (+1: left of a → b), as the lift's loop.
fn circle_intersection(a: V2, r1: f64, b: V2, r2: f64, sign: f64) -> Option<V2> {
    let d = b - a;
    let dd = d.norm();
    if dd == 0.0 {
        return None;
    }
    let e = d * (1.0 / dd);
    let x = (r1 * r1 - r2 * r2 + dd * dd) / (2.0 * dd);
    let y2 = r1 * r1 - x * x;
    if y2.is_nan() || y2 < 0.0 {
        return None;
    }
    Some(a + e * x + e.perp() * (sign * y2.sqrt()))
}

/// x·a + y·b = rhs.
fn solve2(a: V2, b: V2, rhs: V2) -> (f64, f64) {
    let det = a.cross(b);
    (rhs.cross(b) / det, a.cross(rhs) / det)
}

/// The force f with r1 × f = m1 and r2 × f = m2.
fn solve_moments(r1: V2, m1: f64, r2: V2, m2: f64) -> V2 {
    (m1 * r2 - m2 * r1) * (1.0 / r1.cross(r2))
}

/// sign(x) with sign(0) = 0.
fn sign0(x: f64) -> f64 {
    if x > 0.0 {
        1.0
    } else if x < 0.0 {
        -1.0
    } else {
        0.0
    }
}

impl Quadrangle {
    /// The 160EC's lower quadrangle on a frame inclined at `incline_rad`, Table 4 friction.
    pub fn new(g: &Geometry, incline_rad: f64) -> Self {
        let pts = g.points;
        let d_u = pts.upper_arm_j2p - pts.upper_arm_j3;
        let d_c = pts.coupling_rod_j2p - pts.coupling_rod_j2;
        let mut m = Self {
            ground_j1: g.ground_j1_m,
            ground_j2: g.ground_j2_m,
            pts,
            com_local: [V2::ZERO; 3],
            mass_kg: [0.0; 3],
            inertia_kgm2: [0.0; 3],
            pin_radius_m: [0.0; N_JOINT],
            gravity: V2::ZERO,
            incline_rad,
            friction: QuadFriction::baseline(g),
            sign: g.lower_loop_sign,
            d_u,
            d_c,
            r_u: d_u.norm(),
            r_c: d_c.norm(),
        };
        for b in QBody::ALL {
            let d = g.body(b.lift());
            m.com_local[b.index()] = d.com_m;
            m.mass_kg[b.index()] = d.mass_kg;
            m.inertia_kgm2[b.index()] = d.inertia_cm_kgm2;
        }
        for j in QJoint::ALL {
            m.pin_radius_m[j.index()] = g.revolute[j.lift().index()].pin_radius_m;
        }
        m.set_gravity(g.gravity_m_s2, incline_rad);
        m
    }

    /// Gravity of magnitude `g_m_s2` on the frame inclined at `incline_rad` (module doc).
    pub fn set_gravity(&mut self, g_m_s2: f64, incline_rad: f64) {
        self.incline_rad = incline_rad;
        self.gravity = V2::new(g_m_s2 * incline_rad.sin(), g_m_s2 * incline_rad.cos());
    }

    /// Add a point mass to a body: mass, centre of mass and centroidal inertia lumped.
    pub fn add_point_mass(&mut self, pm: &PointMass, field: &str) -> Result<(), RigError> {
        if !(pm.mass_kg.is_finite() && pm.mass_kg > 0.0) {
            return Err(RigError {
                field: format!("{field}.mass_kg"),
                message: format!("must be a finite number > 0, got {}", pm.mass_kg),
            });
        }
        // How far from the body is plausible is the stand's question (`QuadRig::model`, from
        // the type's `[rig_limits]`); the model needs only finite coordinates.
        if !(pm.position_m.x.is_finite() && pm.position_m.y.is_finite()) {
            return Err(RigError {
                field: format!("{field}.position_m"),
                message: "must be two finite numbers".into(),
            });
        }
        let i = pm.body.index();
        let (m0, c0, i0) = (self.mass_kg[i], self.com_local[i], self.inertia_kgm2[i]);
        let m1 = m0 + pm.mass_kg;
        let c1 = (m0 * c0 + pm.mass_kg * pm.position_m) * (1.0 / m1);
        self.inertia_kgm2[i] =
            i0 + m0 * (c0 - c1).norm2() + pm.mass_kg * (pm.position_m - c1).norm2();
        self.mass_kg[i] = m1;
        self.com_local[i] = c1;
        Ok(())
    }

    /// Assemble the loop at α and differentiate it twice in α.
    pub fn pose(&self, alpha_rad: f64) -> Result<QPose, AssemblyError> {
        let p = &self.pts;
        let fixed = |x: V2| PointKin {
            p: x,
            ..Default::default()
        };
        let lower = BodyKin::new(
            Rot::from_angle(alpha_rad),
            1.0,
            0.0,
            fixed(self.ground_j1),
            p.lower_arm_j1,
            self.com_local[0],
        );
        let j3 = lower.at(p.lower_arm_j3);
        let x = circle_intersection(j3.p, self.r_u, self.ground_j2, self.r_c, self.sign).ok_or(
            AssemblyError {
                alpha_rad,
                loop_name: "lower",
            },
        )?;
        let rot_u = Rot::between(self.d_u, x - j3.p);
        let rot_c = Rot::between(self.d_c, x - self.ground_j2);
        let (w_u, w_c) = (rot_u.apply(self.d_u), rot_c.apply(self.d_c));
        // J3′ + θu′ k×w_u = θc′ k×w_c, and the same matrix for the second derivatives.
        let (a, b) = (w_u.perp(), -w_c.perp());
        let (u1, c1) = solve2(a, b, -j3.d1);
        let (u2, c2) = solve2(a, b, -j3.d2 + (u1 * u1) * w_u - (c1 * c1) * w_c);
        let upper = BodyKin::new(rot_u, u1, u2, j3, p.upper_arm_j3, self.com_local[2]);
        let coupling = BodyKin::new(
            rot_c,
            c1,
            c2,
            fixed(self.ground_j2),
            p.coupling_rod_j2,
            self.com_local[1],
        );
        let j2p = upper.at(p.upper_arm_j2p);
        Ok(QPose {
            alpha_rad,
            bodies: [lower, coupling, upper],
            joints: [fixed(self.ground_j1), fixed(self.ground_j2), j2p, j3],
        })
    }

    /// Loop-closure error: the largest distance between a joint placed from its two bodies, m.
    pub fn closure_error_m(&self, pose: &QPose) -> f64 {
        let p = &self.pts;
        let b = |id: QBody| pose.body(id);
        [
            (
                b(QBody::UpperArm).at(p.upper_arm_j2p).p,
                b(QBody::CouplingRod).at(p.coupling_rod_j2p).p,
            ),
            (
                b(QBody::LowerArm).at(p.lower_arm_j3).p,
                b(QBody::UpperArm).at(p.upper_arm_j3).p,
            ),
            (
                b(QBody::CouplingRod).at(p.coupling_rod_j2).p,
                self.ground_j2,
            ),
            (b(QBody::LowerArm).at(p.lower_arm_j1).p, self.ground_j1),
        ]
        .iter()
        .map(|(a, c)| (*a - *c).norm())
        .fold(0.0, f64::max)
    }

    /// Generalised mass M(α) and the generalised force without joint friction (gravity and the
    /// velocity-product inertia terms): M·α̈ = b − Σ T_j r_j.
    fn kane(&self, pose: &QPose, ad: f64) -> (f64, f64) {
        let ad2 = ad * ad;
        let (mut m_aa, mut b) = (0.0, 0.0);
        for i in 0..3 {
            let bk = &pose.bodies[i];
            let (m, inertia) = (self.mass_kg[i], self.inertia_kgm2[i]);
            let v = bk.com.d1;
            m_aa += m * v.norm2() + inertia * bk.w1 * bk.w1;
            b += v.dot(m * self.gravity - (m * ad2) * bk.com.d2) - inertia * bk.w1 * bk.w2 * ad2;
        }
        (m_aa, b)
    }

    /// Generalised gravity force at rest, N·m (positive drives α up).
    pub fn gravity_torque_nm(&self, pose: &QPose) -> f64 {
        self.kane(pose, 0.0).1
    }

    /// Joint reactions from the bodies' Newton–Euler equations at (α̇², α̈) and joint friction
    /// torques `torque` (each acts −T on its second body, +T on its first): upper arm (moment
    /// about J3) and coupling rod (moment about J2) → J2′, then J3, J2, J1 by force balance.
    /// The lower arm's moment about J1 is the equation of motion itself.
    fn reactions(&self, pose: &QPose, ad2: f64, add: f64, torque: &[f64; N_JOINT]) -> [V2; 4] {
        let g = self.gravity;
        let mut need = [V2::ZERO; 3];
        let mut iacc = [0.0; 3];
        for i in 0..3 {
            let bk = &pose.bodies[i];
            need[i] = self.mass_kg[i] * (bk.com.d1 * add + bk.com.d2 * ad2 - g);
            iacc[i] = self.inertia_kgm2[i] * (bk.w1 * add + bk.w2 * ad2);
        }
        let [j1, j2, j2p, j3] = pose.joints.map(|k| k.p);
        let _ = j1;
        let t = |j: QJoint| torque[j.index()];
        let (la, cr, ua) = (0, 1, 2);
        let com = |i: usize| pose.bodies[i].com.p;
        let b1 = iacc[ua] + (com(ua) - j3).cross(need[ua]) + t(QJoint::J3) + t(QJoint::J2p);
        let b2 = -(iacc[cr] + (com(cr) - j2).cross(need[cr]) + t(QJoint::J2) - t(QJoint::J2p));
        let f2p = solve_moments(j2p - j3, b1, j2p - j2, b2);
        let f3 = need[ua] - f2p;
        let f2 = need[cr] + f2p;
        let f1 = need[la] + f3;
        [f1, f2, f2p, f3]
    }

    /// α̈, reactions and friction at a state, dry friction's sign given per joint (`sign`, the
    /// direction of relative motion, ±1 or 0). Friction and reactions are implicit in each
    /// other; solved by fixed-point iteration from the viscous torques (μ·R ≤ 0.0044 m against
    /// levers ≥ 0.15 m: a contraction by ~0.03 per step).
    pub fn eval(
        &self,
        pose: &QPose,
        s: &QState,
        sign: &[f64; N_JOINT],
    ) -> Result<QEval, DynamicsError> {
        self.eval_at(pose, s, sign, None)
    }

    /// [`Quadrangle::eval`], or with α̈ held at `fixed_add` (statics: α̈ = 0 at impending motion).
    fn eval_at(
        &self,
        pose: &QPose,
        s: &QState,
        sign: &[f64; N_JOINT],
        fixed_add: Option<f64>,
    ) -> Result<QEval, DynamicsError> {
        let ad = s.alpha_dot_rad_s;
        let (m_aa, b_a) = self.kane(pose, ad);
        if m_aa.is_nan() || m_aa <= 0.0 {
            return Err(DynamicsError::Singular {
                alpha_rad: s.alpha_rad,
            });
        }
        let f = &self.friction;
        let mut e = QEval::default();
        let mut rate = [0.0; N_JOINT];
        for j in QJoint::ALL {
            let i = j.index();
            rate[i] = pose.rel_rate(j);
            e.rel_rate_rad_s[i] = rate[i] * ad;
            e.viscous_torque_nm[i] = f.viscous_nms_per_rad[i] * e.rel_rate_rad_s[i];
        }
        let mut torque = e.viscous_torque_nm;
        for it in 1..=MAX_ITER {
            let add = fixed_add.unwrap_or_else(|| {
                let mut b = b_a;
                for i in 0..N_JOINT {
                    b -= torque[i] * rate[i];
                }
                b / m_aa
            });
            let r = self.reactions(pose, ad * ad, add, &torque);
            let (mut change, mut scale) = (0.0f64, 0.0f64);
            for i in 0..N_JOINT {
                let n = r[i].norm();
                let dry = f.dry_mu[i] * self.pin_radius_m[i] * n * sign[i];
                let t = e.viscous_torque_nm[i] + dry;
                change = change.max((t - torque[i]).abs());
                scale = scale.max(t.abs());
                torque[i] = t;
                e.dry_torque_nm[i] = dry;
                e.normal_n[i] = n;
            }
            e.alpha_ddot_rad_s2 = add;
            e.force_n = r;
            e.iterations = it;
            if change <= ITER_RTOL * (1.0 + scale) {
                return Ok(e);
            }
        }
        Err(DynamicsError::FrictionNotConverged {
            alpha_rad: s.alpha_rad,
        })
    }

    /// Dry friction's sign in each joint when the loop moves (or is about to) with sign(α̇) =
    /// `direction`.
    pub fn signs(&self, pose: &QPose, direction: f64) -> [f64; N_JOINT] {
        QJoint::ALL.map(|j| sign0(pose.rel_rate(j) * direction))
    }

    /// At rest at this pose: `None` if dry friction holds the loop (|gravity's generalised
    /// force| ≤ the friction's at impending motion, α̈ = 0, all joints slipping together), else
    /// the direction it starts to move in (±1).
    pub fn breakaway(&self, pose: &QPose) -> Result<Option<f64>, DynamicsError> {
        let q = self.gravity_torque_nm(pose);
        if q == 0.0 {
            return Ok(None);
        }
        let dir = sign0(q);
        let s = QState {
            alpha_rad: pose.alpha_rad,
            alpha_dot_rad_s: 0.0,
        };
        let e = self.eval_at(pose, &s, &self.signs(pose, dir), Some(0.0))?;
        let capacity: f64 = QJoint::ALL
            .iter()
            .map(|j| e.dry_torque_nm[j.index()] * pose.rel_rate(*j) * dir)
            .sum();
        Ok(if q.abs() <= capacity { None } else { Some(dir) })
    }

    /// Kinetic + gravitational energy, J (zero of potential at the frame origin).
    pub fn energy_j(&self, pose: &QPose, s: &QState) -> f64 {
        let ad = s.alpha_dot_rad_s;
        let mut e = 0.0;
        for i in 0..3 {
            let bk = &pose.bodies[i];
            e += 0.5 * self.mass_kg[i] * (bk.com.d1 * ad).norm2()
                + 0.5 * self.inertia_kgm2[i] * (bk.w1 * ad).powi(2)
                - self.mass_kg[i] * self.gravity.dot(bk.com.p);
        }
        e
    }

    /// Residual of the equation the reaction recovery leaves unused (lower arm's moment about
    /// J1), N·m: ≈ 0 at a consistent [`QEval`].
    pub fn unused_equation_nm(&self, pose: &QPose, s: &QState, e: &QEval) -> f64 {
        let lower = pose.body(QBody::LowerArm);
        let (add, ad2) = (e.alpha_ddot_rad_s2, s.alpha_dot_rad_s.powi(2));
        let need = self.mass_kg[0] * (lower.com.d1 * add + lower.com.d2 * ad2 - self.gravity);
        let t = |j: QJoint| e.viscous_torque_nm[j.index()] + e.dry_torque_nm[j.index()];
        let j1 = pose.joints[0].p;
        let lhs = -t(QJoint::J1) + t(QJoint::J3)
            - (pose.joints[QJoint::J3.index()].p - j1).cross(e.force_n[QJoint::J3.index()]);
        let rhs = self.inertia_kgm2[0] * add + (lower.com.p - j1).cross(need);
        lhs - rhs
    }

    /// The stable rest angle without friction near `guess_rad` (Newton on the generalised
    /// gravity force), rad; `None` when the loop has none there (at this incline it falls
    /// into a toggle of its assembly range instead).
    pub fn rest_alpha_rad(&self, guess_rad: f64) -> Option<f64> {
        let q_at = |a: f64| self.pose(a).ok().map(|p| self.gravity_torque_nm(&p));
        let mut a = guess_rad;
        for _ in 0..50 {
            let h = 1e-6;
            let q = q_at(a)?;
            let dq = (q_at(a + h)? - q_at(a - h)?) / (2.0 * h);
            // Stable: gravity's generalised force falls through zero (dQ/dα < 0).
            if !(dq < 0.0 && dq.is_finite()) {
                return None;
            }
            let step = (q / dq).clamp(-0.1, 0.1);
            a -= step;
            if step.abs() < 1e-13 {
                return Some(a);
            }
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lift::geometry::builtin_160ec;
    use crate::lift::kinematics::Linkage;

    fn quad() -> Quadrangle {
        Quadrangle::new(builtin_160ec(), 70f64.to_radians())
    }

    fn wrap(a: f64) -> f64 {
        (a + std::f64::consts::PI).rem_euclid(2.0 * std::f64::consts::PI) - std::f64::consts::PI
    }

    /// The loop closes to machine precision over the swing's range and past it.
    #[test]
    fn closure_error_is_machine_precision_over_the_swing_range() {
        let q = quad();
        let mut worst: f64 = 0.0;
        for k in 0..=1000 {
            let a = (-15.0 + 65.0 * f64::from(k) / 1000.0f64).to_radians();
            worst = worst.max(q.closure_error_m(&q.pose(a).unwrap()));
        }
        assert!(worst < 1e-12, "closure error {worst:e} m");
    }

    /// The sub-linkage is the lift's lower loop: same bodies' angles and joint positions as the
    /// complete pantograph's kinematics over the lift's range.
    #[test]
    fn lower_loop_agrees_with_the_lift_linkage() {
        let g = builtin_160ec();
        let (q, lk) = (quad(), Linkage::new(g));
        for k in 0..=20 {
            let a = g.alpha_min_rad + (g.alpha_max_rad - g.alpha_min_rad) * f64::from(k) / 20.0;
            let (p, l) = (q.pose(a).unwrap(), lk.pose(a).unwrap());
            for b in QBody::ALL {
                let (mine, theirs) = (p.body(b), l.body(b.lift()));
                assert!(wrap(mine.theta_rad() - theirs.theta_rad()).abs() < 1e-12);
                assert!((mine.w1 - theirs.w1).abs() < 1e-9 && (mine.w2 - theirs.w2).abs() < 1e-9);
                assert!((mine.com.p - theirs.com.p).norm() < 1e-12);
            }
            for j in QJoint::ALL {
                assert!((p.joints[j.index()].p - l.joint(j.lift()).p).norm() < 1e-12);
                assert!((p.rel_rate(j) - l.rel_rate(j.lift())).abs() < 1e-9);
            }
        }
    }

    /// β is consistent with α through the closure: dβ/dα matches finite differences of β(α),
    /// and β of a pose equals the angle of the J3 → J5 line built from the joint points.
    #[test]
    fn beta_follows_alpha_through_the_closure() {
        let q = quad();
        let g = builtin_160ec();
        for a_deg in [-10.0, 0.0, 15.4, 25.5, 45.0] {
            let a = f64::to_radians(a_deg);
            let e = 1e-6;
            let p = q.pose(a).unwrap();
            let fd = wrap(q.pose(a + e).unwrap().beta_rad() - q.pose(a - e).unwrap().beta_rad())
                / (2.0 * e);
            assert!(
                (fd - p.beta_d_alpha()).abs() < 1e-7,
                "{fd} vs {}",
                p.beta_d_alpha()
            );
            let j5 = p.body(QBody::UpperArm).at(g.points.upper_arm_j5).p;
            let j3 = p.joints[QJoint::J3.index()].p;
            let d = j5 - j3;
            assert!((wrap(d.y.atan2(-d.x) - p.beta_rad())).abs() < 1e-12);
        }
    }

    #[test]
    fn reactions_satisfy_the_unused_equation_with_friction() {
        let q = quad();
        for (a, ad) in [(0.2, 0.8), (0.45, -1.1), (0.6, 0.0)] {
            let p = q.pose(a).unwrap();
            let s = QState {
                alpha_rad: a,
                alpha_dot_rad_s: ad,
            };
            let e = q.eval(&p, &s, &q.signs(&p, ad.signum())).unwrap();
            let r = q.unused_equation_nm(&p, &s, &e);
            assert!(r.abs() < 1e-9, "residual {r}");
            assert!(e.iterations < 15);
            assert!(e.normal_n.iter().all(|n| *n > 1.0), "{:?}", e.normal_n);
        }
    }

    /// dE/dt = −Σ friction power: checks M, b and the friction's generalised force.
    #[test]
    fn power_balance_holds() {
        let q = quad();
        let s = QState {
            alpha_rad: 0.4,
            alpha_dot_rad_s: 0.6,
        };
        let p = q.pose(s.alpha_rad).unwrap();
        let sg = q.signs(&p, 1.0);
        let e = q.eval(&p, &s, &sg).unwrap();
        let dt = 1e-6;
        let en = |k: f64| {
            let st = QState {
                alpha_rad: s.alpha_rad
                    + k * dt * s.alpha_dot_rad_s
                    + 0.5 * (k * dt).powi(2) * e.alpha_ddot_rad_s2,
                alpha_dot_rad_s: s.alpha_dot_rad_s + k * dt * e.alpha_ddot_rad_s2,
            };
            q.energy_j(&q.pose(st.alpha_rad).unwrap(), &st)
        };
        let de_dt = (en(1.0) - en(-1.0)) / (2.0 * dt);
        let loss: f64 = (0..N_JOINT)
            .map(|i| (e.viscous_torque_nm[i] + e.dry_torque_nm[i]) * e.rel_rate_rad_s[i])
            .sum();
        assert!(loss > 0.0);
        assert!(
            (de_dt + loss).abs() < 1e-6 * loss.max(1.0),
            "{de_dt} vs −{loss}"
        );
    }

    /// At 70° the loop rests near the plumb lower arm (+20°); released 10.1° below its rest
    /// (the paper's deflection) Table 4 friction cannot hold it, so it swings up (α increasing);
    /// with the frame level (γ = 0, hanging straight down) nothing pulls it back into the range.
    #[test]
    fn rest_angle_and_breakaway_at_the_papers_release() {
        let q = quad();
        let rest = q.rest_alpha_rad(0.4).unwrap();
        let beta = |a: f64| q.pose(a).unwrap().beta_rad().to_degrees();
        let a0 = rest - f64::to_radians(10.1);
        eprintln!(
            "rest alpha {:.3} deg beta {:.3} deg; release alpha {:.3} deg beta {:.3} deg",
            rest.to_degrees(),
            beta(rest),
            a0.to_degrees(),
            beta(a0)
        );
        assert!(
            (20.0..30.0).contains(&rest.to_degrees()),
            "{}",
            rest.to_degrees()
        );
        let p = q.pose(rest - f64::to_radians(10.1)).unwrap();
        assert_eq!(q.breakaway(&p).unwrap(), Some(1.0));
        // At the rest angle itself nothing moves.
        assert_eq!(q.breakaway(&q.pose(rest).unwrap()).unwrap(), None);
        // Level frame, arms hanging straight down: no rest inside the assembly range.
        let level = Quadrangle::new(builtin_160ec(), 0.0);
        assert_eq!(level.rest_alpha_rad(0.4), None);
    }

    #[test]
    fn point_mass_moves_the_centre_of_mass_and_adds_inertia() {
        let mut q = quad();
        let before = (q.mass_kg[0], q.com_local[0], q.inertia_kgm2[0]);
        q.add_point_mass(
            &PointMass {
                body: QBody::LowerArm,
                mass_kg: 10.0,
                position_m: V2::new(1.5, 0.0),
            },
            "test.rig.attachments[0]",
        )
        .unwrap();
        assert_eq!(q.mass_kg[0], before.0 + 10.0);
        // Moment of inertia about J1 = old + 10·1.5².
        let about_j1 = |m: f64, c: V2, i: f64| i + m * c.norm2();
        let want = about_j1(before.0, before.1, before.2) + 10.0 * 2.25;
        let got = about_j1(q.mass_kg[0], q.com_local[0], q.inertia_kgm2[0]);
        assert!((got - want).abs() < 1e-9, "{got} vs {want}");
        let e = q
            .add_point_mass(
                &PointMass {
                    body: QBody::UpperArm,
                    mass_kg: -1.0,
                    position_m: V2::ZERO,
                },
                "test.rig.attachments[1]",
            )
            .unwrap_err();
        assert_eq!(e.field, "test.rig.attachments[1].mass_kg");
    }
}

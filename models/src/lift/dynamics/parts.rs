//! The dynamic model's parts besides the model itself: the sign law and friction parameters,
//! the loads, the state, the reactions and what one evaluation yields, and its error.

use super::super::geometry::Geometry;
use super::super::kinematics::AssemblyError;
use super::super::topology::{N_REV, RevJoint};
use super::super::vec2::V2;

/// The Stribeck speed a model starts with, rad/s (only read where a joint has a Stribeck excess):
/// a lift's lower-arm joints turn at ~0.05–0.3 rad/s, so 0.05 rad/s puts the Stribeck band in
/// the starts and reversals, where joints pass through rest.
pub const DEFAULT_STRIBECK_SPEED_RAD_S: f64 = 0.05;

/// A band of the lower arm's angle over which one joint's dry friction is `factor` × its own
/// ([`super::LiftModel::friction_band`]); a step at the band's edges (the smoothed sign law carries
/// the simulator through them at small steps).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrictionBand {
    pub joint_index: usize,
    pub alpha_lo_rad: f64,
    pub alpha_hi_rad: f64,
    pub factor: f64,
}

/// How dry friction's sign(v) is evaluated.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SignLaw {
    /// tanh(ω/ω₀) for the revolute joints and tanh(v/v₀) for J8, as the reference lift
    /// simulation does (`lift-example.meta.json`: ω₀ = 10⁻³ rad/s, v₀ = 10⁻³ m/s). Smooth, so
    /// an explicit integrator can step through reversals; near rest the mechanism creeps at
    /// up to ~ω₀ instead of sticking.
    Tanh { omega0_rad_s: f64, v0_m_s: f64 },
    /// The exact sign, with the direction of (impending) motion given: +1 raising, −1
    /// lowering. For statics, where the rate is zero and the direction is the question asked.
    Exact { direction: f64 },
}

impl SignLaw {
    /// The reference simulator's smoothing.
    pub const REFERENCE: SignLaw = SignLaw::Tanh {
        omega0_rad_s: 1e-3,
        v0_m_s: 1e-3,
    };

    /// sign of a revolute joint's relative rate `w` = `r`·α̇ (`r` its rate coefficient).
    #[inline]
    pub(in crate::lift) fn revolute(self, w: f64, r: f64) -> f64 {
        match self {
            SignLaw::Tanh { omega0_rad_s, .. } => (w / omega0_rad_s).tanh(),
            SignLaw::Exact { direction } => sign0(r * direction),
        }
    }
    #[inline]
    pub(in crate::lift) fn slide(self, v: f64) -> f64 {
        match self {
            SignLaw::Tanh { v0_m_s, .. } => (v / v0_m_s).tanh(),
            // Statics: the head slide's state is taken at its frictionless equilibrium.
            SignLaw::Exact { .. } => 0.0,
        }
    }
}

/// sign(x) with sign(0) = 0.
#[inline]
pub(in crate::lift) fn sign0(x: f64) -> f64 {
    if x > 0.0 {
        1.0
    } else if x < 0.0 {
        -1.0
    } else {
        0.0
    }
}

/// The friction parameters identification estimates (Table 4 baseline by default).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrictionParams {
    /// Revolute joints, [`RevJoint`] order: D (N·m·s/rad) and μ.
    pub viscous_nms_per_rad: [f64; N_REV],
    pub dry_mu: [f64; N_REV],
    /// J8, per slide (Table 4): viscous N·s/m and μ.
    pub j8_viscous_ns_per_m_each: f64,
    pub j8_dry_mu: f64,
    /// J9, per spring (Table 4): damping N·s/m.
    pub j9_damping_ns_per_m_each: f64,
}

impl FrictionParams {
    pub fn baseline(g: &Geometry) -> Self {
        let mut viscous = [0.0; N_REV];
        let mut dry = [0.0; N_REV];
        for j in RevJoint::ALL {
            viscous[j.index()] = g.revolute[j.index()].viscous_nms_per_rad;
            dry[j.index()] = g.revolute[j.index()].dry_mu;
        }
        Self {
            viscous_nms_per_rad: viscous,
            dry_mu: dry,
            j8_viscous_ns_per_m_each: g.slide.j8_viscous_ns_per_m_each,
            j8_dry_mu: g.slide.j8_dry_mu,
            j9_damping_ns_per_m_each: g.slide.j9_damping_ns_per_m_each,
        }
    }

    /// No friction anywhere (energy-conservation checks, frictionless statics).
    pub fn frictionless() -> Self {
        Self {
            viscous_nms_per_rad: [0.0; N_REV],
            dry_mu: [0.0; N_REV],
            j8_viscous_ns_per_m_each: 0.0,
            j8_dry_mu: 0.0,
            j9_damping_ns_per_m_each: 0.0,
        }
    }
}

/// Loads on the mechanism besides gravity.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Loads {
    /// Drive torque on the lower arm about J1, reacted by the frame; positive raises.
    pub drive_torque_nm: f64,
    /// Vertical force pressing the strip down (external lowering spring Fs + suspended weight
    /// Fm), applied at the strip point.
    pub strip_load_n: f64,
}

/// State in the minimal coordinates.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct State {
    pub alpha_rad: f64,
    pub h_m: f64,
    pub alpha_dot_rad_s: f64,
    pub h_dot_m_s: f64,
}

/// Joint reaction forces (the Lagrange multipliers in physical form).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Reactions {
    /// Revolute joints, [`RevJoint`] order: force the first body exerts on the second, N.
    pub force_n: [V2; N_REV],
    /// J6 (locked in the plane): the couple the shaft exerts on the suspension, N·m.
    pub j6_couple_nm: f64,
    /// J8: the constraint force the suspension exerts on the head, N (perpendicular to the slide).
    pub j8_force_n: V2,
}

/// Everything one evaluation of the equations of motion yields.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Eval {
    pub alpha_ddot_rad_s2: f64,
    pub h_ddot_m_s2: f64,
    pub reactions: Reactions,
    /// Revolute joints: relative rate ω_rel = θ̇(second) − θ̇(first), rad/s.
    pub rel_rate_rad_s: [f64; N_REV],
    /// Revolute joints: viscous and dry parts of the friction torque, N·m (opposing ω_rel).
    pub viscous_torque_nm: [f64; N_REV],
    pub dry_torque_nm: [f64; N_REV],
    /// Normal force N = |reaction| used in each revolute joint's dry friction, N.
    pub normal_n: [f64; N_REV],
    /// J8 friction force on the head (opposing ḣ): viscous and dry, N.
    pub j8_viscous_n: f64,
    pub j8_dry_n: f64,
    /// J9 spring force on the head along the slide (preload − k·h) and its damping, N.
    pub j9_spring_n: f64,
    pub j9_damping_n: f64,
    /// Revolute joints: the sign law's value σ at the relative rate times the joint's Stribeck
    /// factor ([`super::LiftModel::stribeck_factor`], 1 without one); 0 for J6, locked.
    pub sign: [f64; N_REV],
    /// Fixed-point iterations taken to make friction and reactions consistent.
    pub iterations: u32,
}

impl Eval {
    /// Power dissipated by each revolute joint's viscous and dry friction, W.
    pub fn revolute_power_w(&self, j: RevJoint) -> (f64, f64) {
        let i = j.index();
        let w = self.rel_rate_rad_s[i];
        (self.viscous_torque_nm[i] * w, self.dry_torque_nm[i] * w)
    }
}

/// The friction–reaction coupling did not settle (it is a strong contraction for Table 4
/// friction; this means friction coefficients far beyond any physical value).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DynamicsError {
    #[error(transparent)]
    Assembly(#[from] AssemblyError),
    #[error("friction and reaction forces do not converge at alpha = {alpha_rad} rad")]
    FrictionNotConverged { alpha_rad: f64 },
    #[error("singular mass matrix at alpha = {alpha_rad} rad")]
    Singular { alpha_rad: f64 },
}

//! The parameters a lift fit can free (each joint's friction, the sensor terms, a compliant
//! drive's), their names in the contract, and how each is read from and set on a model.

use crate::lift::dynamics::LiftModel;
use crate::lift::topology::RevJoint;

/// A parameter of a lift fit.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum LiftParam {
    /// Revolute joint viscous coefficient D, N·m·s/rad.
    Viscous(RevJoint),
    /// Revolute joint dry coefficient μ.
    Dry(RevJoint),
    /// J8 viscous coefficient per slide, N·s/m.
    J8Viscous,
    /// J8 dry coefficient μ.
    J8Dry,
    /// J9 damping per spring, N·s/m.
    J9Damping,
    /// Torque-sensor offset, N·m (recorded = true + offset).
    TorqueOffset,
    /// `quadratic_drag` on the head, c_a in N/(m/s)² ([`LiftModel::head_drag_n`]): a lift
    /// effect, not a friction parameter (not in [`LiftParam::all`]; fitted only when a fit's
    /// `effect_params` name it).
    HeadDrag,
    /// `sensor_delay` of the H channel, τ in s ([`LiftModel::h_sensor_delay_s`]): a lift effect
    /// on the output, not in the dynamics (no sensitivity run carries it: a fit differentiates
    /// the delayed read-out, −Ḣ(t − τ), itself).
    SensorDelay,
    /// `sensor_offset` of the H channel, b in m ([`LiftModel::h_sensor_offset_m`]): an output
    /// effect as the delay, H_meas = H + b.
    SensorOffset,
    /// `stribeck` at a revolute joint: the static friction's excess over the kinetic,
    /// e = μ_s/μ_k − 1 ([`LiftModel::stribeck_factor`]). A lift effect, as `HeadDrag`.
    StribeckExcess(RevJoint),
    /// `stribeck` at a revolute joint: its Stribeck speed v_s, rad/s.
    StribeckSpeed(RevJoint),
    /// `drive_compliance`: the drive side's inertia J_d, kg·m² ([`crate::lift::dynamics::DriveCompliance`]).
    DriveInertia,
    /// `drive_compliance`: the bellows' stiffness k, N·m/rad.
    DriveStiffness,
    /// `drive_compliance`: the bellows' damping c, N·m·s/rad.
    DriveDamping,
}

/// The compliant drive a fit starts from when it sets one of its parameters on a model without
/// one: the middle of [`crate::lift::fit::effect_prior`]'s ranges.
pub const DRIVE_COMPLIANCE_START: crate::lift::dynamics::DriveCompliance =
    crate::lift::dynamics::DriveCompliance {
        stiffness_nm_per_rad: 5000.0,
        damping_nms_per_rad: 20.0,
        inertia_kgm2: 0.5,
    };

impl LiftParam {
    /// An effect on the H read-out rather than on the dynamics (`sensor_delay`).
    pub fn is_output(self) -> bool {
        matches!(self, LiftParam::SensorDelay | LiftParam::SensorOffset)
    }

    /// Every friction parameter a lift can touch (J6 is locked: it cannot) and the offset.
    pub fn all() -> Vec<LiftParam> {
        let mut v = Vec::new();
        for j in RevJoint::ALL {
            if j != RevJoint::J6 {
                v.push(LiftParam::Viscous(j));
                v.push(LiftParam::Dry(j));
            }
        }
        v.extend([
            LiftParam::J8Viscous,
            LiftParam::J8Dry,
            LiftParam::J9Damping,
            LiftParam::TorqueOffset,
        ]);
        v
    }

    /// The friction parameter named by joint (`J1` … `J9`) and kind (`viscous` or `dry`);
    /// `None` for J6 (locked in a lift), J9's dry friction (it has none) or an unknown name.
    pub fn named(joint: &str, kind: &str) -> Option<LiftParam> {
        Self::all()
            .into_iter()
            .filter(|p| *p != LiftParam::TorqueOffset)
            .find(|p| p.joint() == joint && p.kind() == kind)
    }

    /// The joint's name (`J3`, `J8`, …), or `T` for the offset.
    pub fn joint(self) -> &'static str {
        match self {
            LiftParam::Viscous(j) | LiftParam::Dry(j) => j.name(),
            LiftParam::J8Viscous | LiftParam::J8Dry => "J8",
            LiftParam::J9Damping => "J9",
            LiftParam::TorqueOffset => "T",
            LiftParam::HeadDrag => "head",
            LiftParam::SensorDelay | LiftParam::SensorOffset => "H",
            LiftParam::StribeckExcess(j) | LiftParam::StribeckSpeed(j) => j.name(),
            LiftParam::DriveInertia | LiftParam::DriveStiffness | LiftParam::DriveDamping => {
                "drive"
            }
        }
    }

    /// `viscous`, `dry`, `offset`, `drag`, `delay`, `zero`, `stribeck_excess` or
    /// `stribeck_speed`.
    pub fn kind(self) -> &'static str {
        match self {
            LiftParam::Viscous(_) | LiftParam::J8Viscous | LiftParam::J9Damping => "viscous",
            LiftParam::Dry(_) | LiftParam::J8Dry => "dry",
            LiftParam::TorqueOffset => "offset",
            LiftParam::HeadDrag => "drag",
            LiftParam::SensorDelay => "delay",
            LiftParam::SensorOffset => "zero",
            LiftParam::StribeckExcess(_) => "stribeck_excess",
            LiftParam::StribeckSpeed(_) => "stribeck_speed",
            LiftParam::DriveInertia => "inertia",
            LiftParam::DriveStiffness => "stiffness",
            LiftParam::DriveDamping => "damping",
        }
    }

    pub fn get(self, model: &LiftModel, offset_nm: f64) -> f64 {
        let f = &model.friction;
        match self {
            LiftParam::Viscous(j) => f.viscous_nms_per_rad[j.index()],
            LiftParam::Dry(j) => f.dry_mu[j.index()],
            LiftParam::J8Viscous => f.j8_viscous_ns_per_m_each,
            LiftParam::J8Dry => f.j8_dry_mu,
            LiftParam::J9Damping => f.j9_damping_ns_per_m_each,
            LiftParam::TorqueOffset => offset_nm,
            LiftParam::HeadDrag => model.head_drag_ns2_per_m2,
            LiftParam::SensorDelay => model.h_sensor_delay_s,
            LiftParam::SensorOffset => model.h_sensor_offset_m,
            LiftParam::StribeckExcess(j) => model.stribeck_excess[j.index()],
            LiftParam::StribeckSpeed(j) => model.stribeck_speed_rad_s[j.index()],
            LiftParam::DriveInertia => model.drive_compliance.map_or(0.0, |c| c.inertia_kgm2),
            LiftParam::DriveStiffness => {
                model
                    .drive_compliance
                    .unwrap_or(DRIVE_COMPLIANCE_START)
                    .stiffness_nm_per_rad
            }
            LiftParam::DriveDamping => {
                model
                    .drive_compliance
                    .unwrap_or(DRIVE_COMPLIANCE_START)
                    .damping_nms_per_rad
            }
        }
    }

    pub fn set(self, model: &mut LiftModel, offset_nm: &mut f64, v: f64) {
        let f = &mut model.friction;
        match self {
            LiftParam::Viscous(j) => f.viscous_nms_per_rad[j.index()] = v,
            LiftParam::Dry(j) => f.dry_mu[j.index()] = v,
            LiftParam::J8Viscous => f.j8_viscous_ns_per_m_each = v,
            LiftParam::J8Dry => f.j8_dry_mu = v,
            LiftParam::J9Damping => f.j9_damping_ns_per_m_each = v,
            LiftParam::TorqueOffset => *offset_nm = v,
            LiftParam::HeadDrag => model.head_drag_ns2_per_m2 = v,
            LiftParam::SensorDelay => model.h_sensor_delay_s = v,
            LiftParam::SensorOffset => model.h_sensor_offset_m = v,
            LiftParam::StribeckExcess(j) => model.stribeck_excess[j.index()] = v,
            LiftParam::StribeckSpeed(j) => model.stribeck_speed_rad_s[j.index()] = v,
            LiftParam::DriveInertia | LiftParam::DriveStiffness | LiftParam::DriveDamping => {
                let c = model.drive_compliance.get_or_insert(DRIVE_COMPLIANCE_START);
                match self {
                    LiftParam::DriveInertia => c.inertia_kgm2 = v,
                    LiftParam::DriveStiffness => c.stiffness_nm_per_rad = v,
                    _ => c.damping_nms_per_rad = v,
                }
            }
        }
    }
}

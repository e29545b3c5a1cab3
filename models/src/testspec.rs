//! A single-joint test described as data — joint, rig overrides, channels — turned into the
//! equation of motion with the pantograph type's defaults (Table 2 body, Table 4 R, Fig rigs).
//!
//! The service parses documents into these structs; the mechanics of filling defaults lives here.

use crate::data::{Attachment, JointKind, PantographType};
use crate::dynamics::{Dof, Input, Mechanism};
use crate::identify::JointTest;
use crate::rig::{BodySpec, PendulumRig, RigError, SliderRig};

/// Pendulum test overrides (trace format `test.rig`); `None` takes the paper's value.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct PendulumSpec {
    /// `J1` … `J7`, `J2'`, or `custom`.
    pub joint: String,
    pub body: Option<BodySpec>,
    /// Replaces the paper rig's attachments when given.
    pub attachments: Option<Vec<Attachment>>,
    pub pin_radius_m: Option<f64>,
    pub gravity_m_s2: Option<f64>,
    pub initial_rate_deg_s: Option<f64>,
}

/// Slider test overrides.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SliderSpec {
    pub moving_mass_kg: Option<f64>,
    pub springs: Option<u32>,
    pub spring_stiffness_n_per_mm: Option<f64>,
    pub normal_force_n: Option<f64>,
}

/// The Table 4 baseline a joint's fit is judged against.
#[derive(Debug, Clone, PartialEq)]
pub struct Baseline {
    pub joint: String,
    pub viscous: Option<f64>,
    pub dry: Option<f64>,
    pub viscous_unit: &'static str,
}

fn err(field: &str, message: impl Into<String>) -> RigError {
    RigError {
        field: field.to_string(),
        message: message.into(),
    }
}

impl PendulumSpec {
    /// The rig: defaults from `data` (None for a `custom` joint or a non-160EC model, where
    /// `body` and `pin_radius_m` are required).
    pub fn rig(&self, data: Option<&PantographType>) -> Result<(PendulumRig, Baseline), RigError> {
        let known = data.and_then(|d| d.rigs.get(&self.joint).map(|r| (d, r)));
        if self.joint != "custom" && known.is_none() && data.is_some() {
            return Err(err(
                "test.joint",
                format!(
                    "`{}` is not a pendulum joint of this pantograph (J1 J2 J2' J3 J4 J5 J6 J7 or custom)",
                    self.joint
                ),
            ));
        }
        let body = match (self.body, known) {
            (Some(b), _) => b,
            (None, Some((d, r))) => {
                let b = &d.bodies[&r.body];
                BodySpec {
                    mass_kg: b.mass_kg,
                    inertia_kgm2: b.inertia_axis_kgm2.unwrap_or(f64::NAN),
                    com_distance_m: b.com_distance_m.unwrap_or(0.0),
                }
            }
            (None, None) => {
                return Err(err(
                    "test.rig.body",
                    "required for a custom joint or a pantograph model without data",
                ));
            }
        };
        let attachments = match (&self.attachments, known) {
            (Some(a), _) => a.clone(),
            (None, Some((_, r))) if self.body.is_none() => r.attachments.clone(),
            _ => Vec::new(),
        };
        let joint_data = known.map(|(d, _)| &d.joints[&self.joint]);
        let r = match (self.pin_radius_m, joint_data) {
            (Some(r), _) => r,
            (None, Some(j)) => j.pin_radius_m.unwrap_or(f64::NAN),
            (None, None) => {
                return Err(err(
                    "test.rig.pin_radius_m",
                    "required for a custom joint or a pantograph model without data",
                ));
            }
        };
        let g = self
            .gravity_m_s2
            .or(data.map(|d| d.gravity_m_s2))
            .unwrap_or(9.81);
        let rig = PendulumRig::compose(body, &attachments, r, g)
            .map_err(|e| err(&format!("test.rig.{}", e.field), e.message))?;
        if rig.com_distance_m <= 0.0 {
            return Err(err(
                "test.rig",
                "the centre of mass is on the axis: no restoring torque, not a pendulum",
            ));
        }
        let baseline = Baseline {
            joint: self.joint.clone(),
            viscous: joint_data.map(|j| j.viscous_baseline()),
            dry: joint_data.map(|j| j.dry_mu),
            viscous_unit: "N·m·s/rad",
        };
        Ok((rig, baseline))
    }

    /// The joint test over measured angles `alpha_deg` at `t_s`.
    pub fn joint_test(
        &self,
        data: Option<&PantographType>,
        t_s: Vec<f64>,
        alpha_deg: Vec<f64>,
    ) -> Result<(JointTest, Baseline), RigError> {
        let (rig, baseline) = self.rig(data)?;
        let test = JointTest {
            dof: Dof {
                mech: Mechanism::Pendulum(rig),
                input: None,
                torsion: 0.0,
            },
            t_s,
            y: alpha_deg,
            scale: 180.0 / std::f64::consts::PI,
            unit: "deg",
            initial_rate: self.initial_rate_deg_s.map(f64::to_radians),
        };
        Ok((test, baseline))
    }
}

impl SliderSpec {
    pub fn rig(&self, data: Option<&PantographType>) -> Result<(SliderRig, Baseline), RigError> {
        let sd = data.map(|d| &d.slider);
        let jd = data
            .and_then(|d| d.joints.get(&d.slider.joint))
            .filter(|j| j.kind == JointKind::Prismatic);
        let m = self
            .moving_mass_kg
            .or(sd.map(|s| s.moving_mass_kg))
            .ok_or_else(|| {
                err(
                    "test.rig.moving_mass_kg",
                    "required for a pantograph model without data",
                )
            })?;
        let springs = self.springs.or(sd.map(|s| s.springs)).unwrap_or(1);
        let k = self
            .spring_stiffness_n_per_mm
            .or(sd.map(|s| s.spring_stiffness_n_per_mm))
            .unwrap_or(4.0);
        let fnn = self
            .normal_force_n
            .or(jd.and_then(|j| j.normal_force_n))
            .unwrap_or(4.05);
        let rig = SliderRig::new(m, springs, k, fnn)
            .map_err(|e| err(&format!("test.rig.{}", e.field), e.message))?;
        let baseline = Baseline {
            joint: sd.map_or("J8".into(), |s| s.joint.clone()),
            viscous: jd.map(|j| j.viscous_baseline()),
            dry: jd.map(|j| j.dry_mu),
            viscous_unit: "N·s/m",
        };
        Ok((rig, baseline))
    }

    /// The joint test over measured `h_mm` with the optional input force `F_N`.
    pub fn joint_test(
        &self,
        data: Option<&PantographType>,
        t_s: Vec<f64>,
        h_mm: Vec<f64>,
        force_n: Option<Vec<f64>>,
    ) -> Result<(JointTest, Baseline), RigError> {
        let (rig, baseline) = self.rig(data)?;
        let input = force_n.map(|f| Input {
            t_s: t_s.clone(),
            value: f,
        });
        let test = JointTest {
            dof: Dof {
                mech: Mechanism::Slider(rig),
                input,
                torsion: 0.0,
            },
            t_s,
            y: h_mm,
            scale: 1000.0,
            unit: "mm",
            initial_rate: None,
        };
        Ok((test, baseline))
    }
}

//! A single-joint test described as data — joint, rig overrides, channels — turned into the
//! equation of motion with the pantograph type's defaults (Table 2 body, Table 4 R, Fig rigs).
//!
//! The service parses documents into these structs; the mechanics of filling defaults lives here.

use crate::data::{Attachment, JointKind, PantographType, RigLimits, builtin_160ec};
use crate::joint::dynamics::{Dof, Input, Mechanism};
use crate::joint::identify::JointTest;
use crate::joint::identify::body_uncertainty::BodySd;
use crate::joint::rig::{
    BodySpec, BodyUncertainty, PendulumRig, RigError, SliderRig, check_uncertainty,
};

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
    /// `test.rig.body_uncertainty` (issue 17, point 1): the stated 1 σ errors of `body`, or of
    /// the paper's default body for the joint when `body` is absent.
    pub body_uncertainty: Option<BodyUncertainty>,
}

/// Slider test overrides.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SliderSpec {
    /// `test.joint` `custom` (pantowatch extension, issue 17 point 3): a slider that is not the
    /// pantograph's head — every rig value stated, no pantograph defaults, no Table 4 baseline,
    /// reported as `custom`.
    pub custom: bool,
    pub moving_mass_kg: Option<f64>,
    pub springs: Option<u32>,
    pub spring_stiffness_n_per_mm: Option<f64>,
    pub normal_force_n: Option<f64>,
    /// `test.rig.moving_mass_uncertainty_kg` (issue 17, point 1): the stated 1 σ error of the
    /// moving mass (stated or the type's default).
    pub moving_mass_sd_kg: Option<f64>,
}

/// The Table 4 baseline a joint's fit is judged against.
#[derive(Debug, Clone, PartialEq)]
pub struct Baseline {
    pub joint: String,
    pub viscous: Option<f64>,
    pub dry: Option<f64>,
    pub viscous_unit: &'static str,
}

/// A pendulum spec resolved: the lumped rig, its baseline, the stated body errors at ±1 sd.
struct Resolved {
    rig: PendulumRig,
    baseline: Baseline,
    body_sd: Vec<BodySd>,
}

fn err(field: &str, message: impl Into<String>) -> RigError {
    RigError {
        field: field.to_string(),
        message: message.into(),
    }
}

/// The rig limits of `data`'s type, or the built-in 160EC's for a model without data.
fn limits(data: Option<&PantographType>) -> &RigLimits {
    data.unwrap_or_else(|| builtin_160ec()).rig_limits()
}

/// A [`RigLimits`] refusal as the trace field it names.
fn out_of_range((field, message): (String, String)) -> RigError {
    RigError { field, message }
}

impl PendulumSpec {
    /// Every value the trace states lies in the type's plausible rig span (issue 18): checked
    /// before the rig is composed, so the refusal names the field as the trace spells it.
    fn check_limits(&self, l: &RigLimits) -> Result<(), RigError> {
        let c = |f: &str, v: f64, span| RigLimits::check(f, v, span).map_err(out_of_range);
        if let Some(b) = &self.body {
            c("test.rig.body.mass_kg", b.mass_kg, l.mass_kg)?;
            c("test.rig.body.inertia_kgm2", b.inertia_kgm2, l.inertia_kgm2)?;
            c(
                "test.rig.body.com_distance_m",
                b.com_distance_m,
                l.com_distance_m,
            )?;
        }
        for (i, a) in self.attachments.iter().flatten().enumerate() {
            let f = format!("test.rig.attachments[{i}]");
            let (mass_kg, (key, length)) = match *a {
                Attachment::Point {
                    mass_kg,
                    distance_m,
                } => (mass_kg, ("distance_m", distance_m)),
                Attachment::Rod { mass_kg, length_m } => (mass_kg, ("length_m", length_m)),
            };
            c(&format!("{f}.mass_kg"), mass_kg, l.mass_kg)?;
            c(&format!("{f}.{key}"), length, l.attachment_m)?;
        }
        if let Some(r) = self.pin_radius_m {
            c("test.rig.pin_radius_m", r, l.pin_radius_m)?;
        }
        if let Some(g) = self.gravity_m_s2 {
            c("test.rig.gravity_m_s2", g, l.gravity_m_s2)?;
        }
        if let Some(w) = self.initial_rate_deg_s {
            c("test.rig.initial_rate_deg_s", w, l.initial_rate_deg_s)?;
        }
        Ok(())
    }

    /// The rig: defaults from `data` (None for a `custom` joint or a non-160EC model, where
    /// `body` and `pin_radius_m` are required).
    pub fn rig(&self, data: Option<&PantographType>) -> Result<(PendulumRig, Baseline), RigError> {
        self.resolve(data).map(|r| (r.rig, r.baseline))
    }

    /// [`PendulumSpec::rig`] with its parts and the stated body uncertainty, checked.
    fn resolve(&self, data: Option<&PantographType>) -> Result<Resolved, RigError> {
        self.check_limits(limits(data))?;
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
            .unwrap_or(builtin_160ec().gravity_m_s2);
        let rig = PendulumRig::compose(body, &attachments, r, g)
            .map_err(|e| err(&format!("test.rig.{}", e.field), e.message))?;
        let uncertainty = self.body_uncertainty.unwrap_or_default();
        uncertainty
            .check(&body)
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
        // The stated errors as mechanisms at ±1 sd (`identify::body_uncertainty`): the body's
        // quantity moved, the rig lumped again with the same attachments; 0 carries nothing.
        let body_sd = uncertainty
            .entries(&body)
            .into_iter()
            .filter(|(_, sd, _)| *sd > 0.0)
            .map(|(quantity, sd, _)| {
                let moved = |k: f64| {
                    let mut b = body;
                    match quantity {
                        "mass_kg" => b.mass_kg += k * sd,
                        "inertia_kgm2" => b.inertia_kgm2 += k * sd,
                        _ => b.com_distance_m += k * sd,
                    }
                    Mechanism::Pendulum(PendulumRig::lump(b, &attachments, r, g))
                };
                BodySd {
                    quantity,
                    sd,
                    inertia: quantity == "inertia_kgm2",
                    plus: moved(1.0),
                    minus: moved(-1.0),
                }
            })
            .collect();
        Ok(Resolved {
            rig,
            baseline,
            body_sd,
        })
    }

    /// The joint test over measured angles `alpha_deg` at `t_s`.
    pub fn joint_test(
        &self,
        data: Option<&PantographType>,
        t_s: Vec<f64>,
        alpha_deg: Vec<f64>,
    ) -> Result<(JointTest, Baseline), RigError> {
        let Resolved {
            rig,
            baseline,
            body_sd,
        } = self.resolve(data)?;
        RigLimits::check_channel("alpha_deg", &alpha_deg, limits(data).alpha_deg_abs)
            .map_err(out_of_range)?;
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
            release_t_s: None,
            body_sd,
        };
        Ok((test, baseline))
    }
}

impl SliderSpec {
    /// Every value the trace states lies in the type's plausible rig span (issue 18).
    fn check_limits(&self, l: &RigLimits) -> Result<(), RigError> {
        let c = |f: &str, v: Option<f64>, span| match v {
            Some(v) => RigLimits::check(f, v, span).map_err(out_of_range),
            None => Ok(()),
        };
        c(
            "test.rig.moving_mass_kg",
            self.moving_mass_kg,
            l.moving_mass_kg,
        )?;
        c("test.rig.springs", self.springs.map(f64::from), l.springs)?;
        c(
            "test.rig.spring_stiffness_n_per_mm",
            self.spring_stiffness_n_per_mm,
            l.spring_stiffness_n_per_mm,
        )?;
        c(
            "test.rig.normal_force_n",
            self.normal_force_n,
            l.normal_force_n,
        )
    }

    /// The rig with the type's defaults where not stated, and the stated moving-mass
    /// uncertainty checked against the moving mass it qualifies.
    pub fn rig(&self, data: Option<&PantographType>) -> Result<(SliderRig, Baseline), RigError> {
        let (rig, baseline) = self.rig_unchecked_sd(data)?;
        if let Some(sd) = self.moving_mass_sd_kg {
            check_uncertainty(
                "test.rig.moving_mass_uncertainty_kg",
                sd,
                rig.moving_mass_kg,
            )?;
        }
        Ok((rig, baseline))
    }

    /// [`SliderSpec::rig`] before its moving-mass uncertainty is checked.
    fn rig_unchecked_sd(
        &self,
        data: Option<&PantographType>,
    ) -> Result<(SliderRig, Baseline), RigError> {
        self.check_limits(limits(data))?;
        if self.custom {
            return self.custom_rig();
        }
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
            .unwrap_or(builtin_160ec().slider.spring_stiffness_n_per_mm);
        let fnn = self
            .normal_force_n
            .or(jd.and_then(|j| j.normal_force_n))
            .or_else(|| builtin_160ec().joint("J8").and_then(|j| j.normal_force_n))
            .unwrap_or_default();
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

    /// A custom slider's rig from the values the trace states: the moving mass, the spring
    /// count, the stiffness (when there are springs) and the normal force on the guide are all
    /// required (the 160EC head's are no default for another axis).
    fn custom_rig(&self) -> Result<(SliderRig, Baseline), RigError> {
        let need = |field: &str, v: Option<f64>| {
            v.ok_or_else(|| err(field, "required for a custom slider (`test.joint`: custom)"))
        };
        let m = need("test.rig.moving_mass_kg", self.moving_mass_kg)?;
        let springs = self.springs.ok_or_else(|| {
            err(
                "test.rig.springs",
                "required for a custom slider (`test.joint`: custom); 0 for none",
            )
        })?;
        let k = if springs == 0 {
            self.spring_stiffness_n_per_mm.unwrap_or(0.0)
        } else {
            need(
                "test.rig.spring_stiffness_n_per_mm",
                self.spring_stiffness_n_per_mm,
            )?
        };
        let fnn = need("test.rig.normal_force_n", self.normal_force_n)?;
        let rig = SliderRig::new(m, springs, k, fnn)
            .map_err(|e| err(&format!("test.rig.{}", e.field), e.message))?;
        Ok((
            rig,
            Baseline {
                joint: "custom".into(),
                viscous: None,
                dry: None,
                viscous_unit: "N·s/m",
            },
        ))
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
        let l = limits(data);
        RigLimits::check_channel("h_mm", &h_mm, l.h_mm_abs).map_err(out_of_range)?;
        if let Some(f) = &force_n {
            RigLimits::check_channel("F_N", f, l.force_n_abs).map_err(out_of_range)?;
        }
        // The stated moving-mass error at ±1 sd (`identify::body_uncertainty`); 0 carries
        // nothing.
        let body_sd = self
            .moving_mass_sd_kg
            .filter(|sd| *sd > 0.0)
            .map(|sd| {
                let moved = |k: f64| {
                    Mechanism::Slider(SliderRig {
                        moving_mass_kg: rig.moving_mass_kg + k * sd,
                        ..rig
                    })
                };
                BodySd {
                    quantity: "moving_mass_kg",
                    sd,
                    inertia: true,
                    plus: moved(1.0),
                    minus: moved(-1.0),
                }
            })
            .into_iter()
            .collect();
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
            release_t_s: None,
            body_sd,
        };
        Ok((test, baseline))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pendulum(joint: &str) -> PendulumSpec {
        PendulumSpec {
            joint: joint.into(),
            ..Default::default()
        }
    }

    /// Issue 18: every paper rig lies inside the plausible span, and a stated value or a channel
    /// sample outside it is refused naming the field as the trace spells it.
    #[test]
    fn absurd_rigs_and_channels_are_refused_naming_the_field() {
        let data = Some(builtin_160ec());
        for j in ["J1", "J2", "J2'", "J3", "J4", "J5", "J6", "J7"] {
            pendulum(j).rig(data).unwrap_or_else(|e| panic!("{j}: {e}"));
        }
        SliderSpec::default()
            .rig(data)
            .expect("the paper's slider rig");
        let refuse = |spec: PendulumSpec, field: &str| {
            let e = spec.rig(data).expect_err(field);
            assert_eq!(e.field, field, "{e}");
        };
        refuse(
            PendulumSpec {
                pin_radius_m: Some(1e308),
                ..pendulum("J1")
            },
            "test.rig.pin_radius_m",
        );
        refuse(
            PendulumSpec {
                pin_radius_m: Some(f64::NAN),
                ..pendulum("J1")
            },
            "test.rig.pin_radius_m",
        );
        refuse(
            PendulumSpec {
                attachments: Some(vec![Attachment::Rod {
                    mass_kg: 1.0,
                    length_m: 1e6,
                }]),
                ..pendulum("J5")
            },
            "test.rig.attachments[0].length_m",
        );
        refuse(
            PendulumSpec {
                initial_rate_deg_s: Some(-1e9),
                ..pendulum("J3")
            },
            "test.rig.initial_rate_deg_s",
        );
        let e = SliderSpec {
            springs: Some(1000),
            ..Default::default()
        }
        .rig(data)
        .unwrap_err();
        assert_eq!(e.field, "test.rig.springs");
        let t = vec![0.0, 0.002, 0.004];
        let e = pendulum("J1")
            .joint_test(data, t.clone(), vec![70.0, 1e308, 69.0])
            .unwrap_err();
        assert_eq!(e.field, "channels.alpha_deg[1]");
        let e = SliderSpec::default()
            .joint_test(
                data,
                t.clone(),
                vec![1.0, 1.0, 1.0],
                Some(vec![0.0, -1e7, 0.0]),
            )
            .unwrap_err();
        assert_eq!(e.field, "channels.F_N[1]");
        // At the limits: accepted.
        let l = builtin_160ec().rig_limits();
        pendulum("J1")
            .joint_test(data, t, vec![l.alpha_deg_abs, 0.0, -l.alpha_deg_abs])
            .expect("±alpha_deg_abs is inside");
    }

    /// Issue 18: one rule for a slider's spring count, `[rig_limits] springs` — a custom
    /// slider's "0 for none" is accepted (the range check refused it), the span's ends are
    /// accepted, one past them refused naming `test.rig.springs`.
    #[test]
    fn the_spring_count_has_one_rule_and_zero_means_none() {
        let data = Some(builtin_160ec());
        let [lo, hi] = builtin_160ec().rig_limits().springs;
        assert_eq!(lo, 0.0, "0 springs is the documented `none`");
        let custom = |springs: u32| SliderSpec {
            custom: true,
            moving_mass_kg: Some(2.0),
            springs: Some(springs),
            spring_stiffness_n_per_mm: None,
            normal_force_n: Some(10.0),
            moving_mass_sd_kg: None,
        };
        let (rig, baseline) = custom(0)
            .rig(data)
            .expect("a custom slider without springs");
        assert_eq!(rig.stiffness_n_per_m, 0.0);
        assert_eq!(baseline.joint, "custom");
        let top = hi as u32;
        let e = custom(top)
            .rig(data)
            .expect_err("springs need their stiffness");
        assert_eq!(e.field, "test.rig.spring_stiffness_n_per_mm");
        SliderSpec {
            spring_stiffness_n_per_mm: Some(4.0),
            ..custom(top)
        }
        .rig(data)
        .expect("the span's upper end");
        for springs in [top + 1, u32::MAX] {
            let e = SliderSpec {
                springs: Some(springs),
                ..Default::default()
            }
            .rig(data)
            .unwrap_err();
            assert_eq!(e.field, "test.rig.springs", "{springs}");
        }
        SliderSpec {
            springs: Some(0),
            ..Default::default()
        }
        .rig(data)
        .expect("the head's slider without springs");
    }
}

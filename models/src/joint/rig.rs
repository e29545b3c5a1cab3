//! The single-joint test rigs as mechanics: a body swinging on one revolute joint (pendulum,
//! Figs 5–10) or a mass on a cylindrical joint with springs (slider, Figs 11–12).
//!
//! Composes a rig's body and attachments into the totals the equation of motion uses.

use crate::data::{Attachment, PantographType};

/// A compound pendulum on one revolute joint, all masses lumped.
///
/// Assumptions: planar motion about a fixed horizontal axis; every attachment's centre of mass
/// lies on the body's centre-of-mass line (so moments add as scalars); rods are uniform and thin
/// (I = m L²/3 about the axis).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PendulumRig {
    /// Total swinging mass.
    pub mass_kg: f64,
    /// Total moment of inertia about the joint axis.
    pub inertia_kgm2: f64,
    /// Axis to the total centre of mass.
    pub com_distance_m: f64,
    /// R in the dry-friction torque N·R·μ (Table 4).
    pub pin_radius_m: f64,
    pub gravity_m_s2: f64,
}

/// The head-suspension slider: a mass on a cylindrical joint held by springs.
///
/// Assumptions: displacement measured from the static rest position under the rig load, so
/// gravity and the spring preload cancel; springs linear; the normal force Fn in the dry force
/// Fn·μ is constant (paper, Section 4.2), not a reaction.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SliderRig {
    pub moving_mass_kg: f64,
    /// All springs together, N/m.
    pub stiffness_n_per_m: f64,
    /// Fn in the dry friction force Fn·μ.
    pub normal_force_n: f64,
}

/// The swinging body of a pendulum rig before attachments.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BodySpec {
    pub mass_kg: f64,
    pub inertia_kgm2: f64,
    pub com_distance_m: f64,
}

/// The stated standard uncertainties (1 σ, the value's units) of a pendulum's body
/// (`test.rig.body_uncertainty`, issue 17 point 1); `None`: not stated (no uncertainty carried).
///
/// Assumption (stated): independent Gaussian errors of the stated body's mass, inertia about the
/// axis and centre-of-mass distance; the attachments, pin radius and gravity are exact.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct BodyUncertainty {
    pub mass_sd_kg: Option<f64>,
    pub inertia_sd_kgm2: Option<f64>,
    pub com_distance_sd_m: Option<f64>,
}

/// A stated uncertainty `sd` of the value `value`: finite, ≥ 0, and below the value (an
/// uncertainty as large as the value says the value is not known); 0 is always accepted (no
/// uncertainty). A refusal names `field`.
pub fn check_uncertainty(field: &str, sd: f64, value: f64) -> Result<(), RigError> {
    if !sd.is_finite() || sd < 0.0 {
        return Err(rig_err(
            field,
            format!("must be a finite number >= 0, got {sd}"),
        ));
    }
    if sd > 0.0 && sd >= value {
        return Err(rig_err(
            field,
            format!("{sd} is not below the value it qualifies ({value})"),
        ));
    }
    Ok(())
}

impl BodyUncertainty {
    /// Each stated uncertainty against the body's value it qualifies ([`check_uncertainty`]);
    /// a refusal names `body_uncertainty.<field>`.
    pub fn check(&self, body: &BodySpec) -> Result<(), RigError> {
        for (k, sd, v) in self.entries(body) {
            check_uncertainty(&format!("body_uncertainty.{k}"), sd, v)?;
        }
        Ok(())
    }

    /// (field, sd, the body's value) of each stated uncertainty, in the contract's order.
    pub fn entries(&self, body: &BodySpec) -> Vec<(&'static str, f64, f64)> {
        [
            ("mass_kg", self.mass_sd_kg, body.mass_kg),
            ("inertia_kgm2", self.inertia_sd_kgm2, body.inertia_kgm2),
            (
                "com_distance_m",
                self.com_distance_sd_m,
                body.com_distance_m,
            ),
        ]
        .into_iter()
        .filter_map(|(k, sd, v)| sd.map(|sd| (k, sd, v)))
        .collect()
    }
}

/// Why a rig cannot be built.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("rig `{field}`: {message}")]
pub struct RigError {
    pub field: String,
    pub message: String,
}

/// A body's mass properties about the axis: m > 0, J > 0, d ≥ 0 and J ≥ m·d² (parallel-axis
/// theorem); a refusal names `prefix` + the field.
fn mass_properties(prefix: &str, m: f64, j: f64, d: f64) -> Result<(), RigError> {
    for (f, v) in [("mass_kg", m), ("inertia_kgm2", j)] {
        if !(v.is_finite() && v > 0.0) {
            return Err(rig_err(
                &format!("{prefix}{f}"),
                format!("must be > 0, got {v}"),
            ));
        }
    }
    if !(d.is_finite() && d >= 0.0) {
        return Err(rig_err(
            &format!("{prefix}com_distance_m"),
            format!("must be >= 0, got {d}"),
        ));
    }
    let md2 = m * d.powi(2);
    if j < md2 * (1.0 - 1e-9) {
        return Err(rig_err(
            &format!("{prefix}inertia_kgm2"),
            format!("{j} kg·m² is below m·d² = {md2} (parallel-axis theorem)"),
        ));
    }
    Ok(())
}

fn rig_err(field: &str, message: impl Into<String>) -> RigError {
    RigError {
        field: field.to_string(),
        message: message.into(),
    }
}

impl PendulumRig {
    /// Lump a body and its attachments: m = Σm, J = ΣJ (all about the axis), d = Σ(m·d)/m.
    pub fn compose(
        body: BodySpec,
        attachments: &[Attachment],
        pin_radius_m: f64,
        gravity_m_s2: f64,
    ) -> Result<Self, RigError> {
        // Each part checked where it was stated, so a refusal names its exact contract path
        // (`body.inertia_kgm2`, `attachments[1].mass_kg`), not the lumped rig's field.
        mass_properties(
            "body.",
            body.mass_kg,
            body.inertia_kgm2,
            body.com_distance_m,
        )?;
        let positive = |f: String, v: f64| {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(rig_err(&f, format!("must be > 0, got {v}")))
            }
        };
        for (i, a) in attachments.iter().enumerate() {
            let (mass_kg, (k, v)) = match *a {
                Attachment::Point {
                    mass_kg,
                    distance_m,
                } => (mass_kg, ("distance_m", distance_m)),
                Attachment::Rod { mass_kg, length_m } => (mass_kg, ("length_m", length_m)),
            };
            positive(format!("attachments[{i}].mass_kg"), mass_kg)?;
            if !(v.is_finite() && v >= 0.0) {
                return Err(rig_err(
                    &format!("attachments[{i}].{k}"),
                    format!("must be >= 0, got {v}"),
                ));
            }
        }
        let rig = Self::lump(body, attachments, pin_radius_m, gravity_m_s2);
        rig.validate()?;
        Ok(rig)
    }

    /// The lumped rig without the checks of [`PendulumRig::compose`]: a body perturbed by its
    /// stated uncertainty (`identify::body_uncertainty`) may lie a hair past the parallel-axis
    /// bound, which the simulation does not need.
    pub fn lump(
        body: BodySpec,
        attachments: &[Attachment],
        pin_radius_m: f64,
        gravity_m_s2: f64,
    ) -> Self {
        let (mut m, mut j, mut md) = (
            body.mass_kg,
            body.inertia_kgm2,
            body.mass_kg * body.com_distance_m,
        );
        for a in attachments {
            match *a {
                Attachment::Point {
                    mass_kg,
                    distance_m,
                } => {
                    m += mass_kg;
                    j += mass_kg * distance_m * distance_m;
                    md += mass_kg * distance_m;
                }
                Attachment::Rod { mass_kg, length_m } => {
                    m += mass_kg;
                    j += mass_kg * length_m * length_m / 3.0;
                    md += mass_kg * length_m / 2.0;
                }
            }
        }
        Self {
            mass_kg: m,
            inertia_kgm2: j,
            com_distance_m: md / m,
            pin_radius_m,
            gravity_m_s2,
        }
    }

    /// Physical consistency: positive mass and inertia, J ≥ m·d² (parallel-axis theorem).
    pub fn validate(&self) -> Result<(), RigError> {
        mass_properties("", self.mass_kg, self.inertia_kgm2, self.com_distance_m)?;
        for (f, v) in [
            ("pin_radius_m", self.pin_radius_m),
            ("gravity_m_s2", self.gravity_m_s2),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(rig_err(f, format!("must be > 0, got {v}")));
            }
        }
        Ok(())
    }

    /// Small-angle period, s: 2π √(J / (m g d)).
    pub fn small_angle_period_s(&self) -> f64 {
        2.0 * std::f64::consts::PI
            * (self.inertia_kgm2 / (self.mass_kg * self.gravity_m_s2 * self.com_distance_m)).sqrt()
    }

    /// The paper's rig for a 160EC joint (Table 2 body, Fig 5–10 attachments, Table 4 R).
    pub fn paper_default(data: &PantographType, joint: &str) -> Result<Self, RigError> {
        let rig = data
            .rigs
            .get(joint)
            .ok_or_else(|| rig_err("joint", format!("no pendulum rig for `{joint}`")))?;
        let b = &data.bodies[&rig.body];
        let body = BodySpec {
            mass_kg: b.mass_kg,
            inertia_kgm2: b.inertia_axis_kgm2.unwrap_or(f64::NAN),
            com_distance_m: b.com_distance_m.unwrap_or(0.0),
        };
        let r = data.joints[joint].pin_radius_m.unwrap_or(f64::NAN);
        Self::compose(body, &rig.attachments, r, data.gravity_m_s2)
    }
}

impl SliderRig {
    /// Build from the rig fields of the trace format (`springs` × `spring_stiffness_n_per_mm`).
    pub fn new(
        moving_mass_kg: f64,
        springs: u32,
        spring_stiffness_n_per_mm: f64,
        normal_force_n: f64,
    ) -> Result<Self, RigError> {
        let rig = Self {
            moving_mass_kg,
            stiffness_n_per_m: springs as f64 * spring_stiffness_n_per_mm * 1000.0,
            normal_force_n,
        };
        if !(moving_mass_kg.is_finite() && moving_mass_kg > 0.0) {
            return Err(rig_err(
                "moving_mass_kg",
                format!("must be > 0, got {moving_mass_kg}"),
            ));
        }
        if !(spring_stiffness_n_per_mm.is_finite() && spring_stiffness_n_per_mm >= 0.0) {
            return Err(rig_err(
                "spring_stiffness_n_per_mm",
                format!("must be >= 0, got {spring_stiffness_n_per_mm}"),
            ));
        }
        if !(normal_force_n.is_finite() && normal_force_n >= 0.0) {
            return Err(rig_err(
                "normal_force_n",
                format!("must be >= 0, got {normal_force_n}"),
            ));
        }
        Ok(rig)
    }

    /// Undamped period, s (infinite without springs).
    pub fn period_s(&self) -> f64 {
        2.0 * std::f64::consts::PI * (self.moving_mass_kg / self.stiffness_n_per_m).sqrt()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::data::builtin_160ec;

    /// A refusal names the part where the bad value was stated (issue 17, point 5): the body's
    /// field under `body.`, an attachment's under `attachments[i].`.
    #[test]
    fn a_bad_part_is_named_by_its_own_path() {
        let body = BodySpec {
            mass_kg: 2.0,
            inertia_kgm2: 0.1,
            com_distance_m: 0.5,
        };
        let e = PendulumRig::compose(body, &[], 0.01, 9.81).unwrap_err();
        assert_eq!(e.field, "body.inertia_kgm2", "{e:?}");
        assert!(e.message.contains("parallel-axis"), "{e:?}");
        let ok = BodySpec {
            inertia_kgm2: 0.6,
            ..body
        };
        let rod = Attachment::Rod {
            mass_kg: -1.0,
            length_m: 0.3,
        };
        let point = Attachment::Point {
            mass_kg: 0.5,
            distance_m: 0.2,
        };
        let e = PendulumRig::compose(ok, &[point.clone(), rod], 0.01, 9.81).unwrap_err();
        assert_eq!(e.field, "attachments[1].mass_kg", "{e:?}");
        let e = PendulumRig::compose(ok, &[], -0.01, 9.81).unwrap_err();
        assert_eq!(e.field, "pin_radius_m", "{e:?}");
        assert!(PendulumRig::compose(ok, &[point], 0.01, 9.81).is_ok());
    }

    /// Issue 17, point 7: a stated uncertainty is finite, ≥ 0 and below its value; 0 always
    /// passes (no uncertainty), even of a value 0; a refusal names the uncertainty's field.
    #[test]
    fn a_stated_uncertainty_lies_in_0_up_to_its_value() {
        let body = BodySpec {
            mass_kg: 2.0,
            inertia_kgm2: 0.6,
            com_distance_m: 0.0,
        };
        let u = |m, j, d| BodyUncertainty {
            mass_sd_kg: m,
            inertia_sd_kgm2: j,
            com_distance_sd_m: d,
        };
        assert!(u(Some(1.99), Some(0.0), Some(0.0)).check(&body).is_ok());
        for (bad, field) in [
            (u(Some(2.0), None, None), "body_uncertainty.mass_kg"),
            (u(None, Some(-1e-9), None), "body_uncertainty.inertia_kgm2"),
            (
                u(None, Some(f64::NAN), None),
                "body_uncertainty.inertia_kgm2",
            ),
            (u(None, None, Some(1e-3)), "body_uncertainty.com_distance_m"),
        ] {
            assert_eq!(bad.check(&body).unwrap_err().field, field, "{bad:?}");
        }
        assert!(check_uncertainty("x", f64::INFINITY, 1.0).is_err());
    }

    #[test]
    fn j5_rig_lumps_rod_and_weight_as_the_examples_state() {
        // ../shared/data/examples/README.md: J5 m_tot 7.415, J_tot 4.645, d_tot 0.6685.
        let r = PendulumRig::paper_default(builtin_160ec(), "J5").unwrap();
        assert!((r.mass_kg - 7.415).abs() < 1e-9);
        assert!((r.inertia_kgm2 - 4.645).abs() < 5e-4, "{}", r.inertia_kgm2);
        assert!(
            (r.com_distance_m - 0.6685).abs() < 5e-4,
            "{}",
            r.com_distance_m
        );
        let r6 = PendulumRig::paper_default(builtin_160ec(), "J6").unwrap();
        assert!(
            (r6.mass_kg - 10.64).abs() < 1e-9
                && (r6.inertia_kgm2 - 0.1448).abs() < 1e-3
                && (r6.com_distance_m - 0.1146).abs() < 1e-3
        );
    }

    #[test]
    fn inconsistent_inertia_is_rejected() {
        let e = PendulumRig::compose(
            BodySpec {
                mass_kg: 1.0,
                inertia_kgm2: 0.1,
                com_distance_m: 1.0,
            },
            &[],
            0.01,
            9.81,
        )
        .unwrap_err();
        assert_eq!(e.field, "body.inertia_kgm2");
    }
}

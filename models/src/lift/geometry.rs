//! The complete pantograph as data: `models/data/160ec-geometry.toml` (link geometry assumed,
//! masses from Table 2, friction from Table 4), parsed from a string and validated.
//!
//! Parsing resolves the file into [`Geometry`]: the topology's points, bodies and joints by
//! name, every error naming its key. The file's `[checks]` and `[[reference_pose]]` come along
//! for tests. A pantograph with real drawings replaces the file, not this code.

use std::sync::OnceLock;

use super::topology::{BodyId, N_REV, RevJoint};
use super::vec2::V2;

/// The 160EC geometry file (copy of `shared/reference/160ec.toml`).
pub const GEOMETRY_160EC_TOML: &str = include_str!("../../data/160ec-geometry.toml");

/// The format tag the parser accepts (`[meta] format`).
pub const GEOMETRY_FORMAT: &str = "160ec-geometry/1";

/// Error in a geometry file, naming the offending key.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum GeometryError {
    #[error("geometry: cannot parse TOML: {0}")]
    Parse(String),
    #[error("geometry: `{key}`: {message}")]
    Invalid { key: String, message: String },
}

fn invalid(key: impl Into<String>, message: impl Into<String>) -> GeometryError {
    GeometryError::Invalid {
        key: key.into(),
        message: message.into(),
    }
}

mod file;
pub use file::{Checks, LiftState, ReferencePose, StandData};
use file::{GeometryFile, JointFile};

// ------------------------------------------------------------------ the resolved geometry

/// Mass properties of one body (Table 2 through the file's `source`).
#[derive(Debug, Clone, PartialEq)]
pub struct BodyData {
    pub mass_kg: f64,
    /// About the transverse axis through the centre of mass.
    pub inertia_cm_kgm2: f64,
    /// Centre of mass in the body frame (ξ, η).
    pub com_m: V2,
    pub source: String,
}

/// The named points of the topology, each in its body's frame (ξ, η), m.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Points {
    pub lower_arm_j1: V2,
    pub lower_arm_j3: V2,
    pub lower_arm_j4: V2,
    pub coupling_rod_j2: V2,
    pub coupling_rod_j2p: V2,
    pub upper_arm_j3: V2,
    pub upper_arm_j5: V2,
    pub upper_arm_j2p: V2,
    pub balance_rod_j4: V2,
    pub balance_rod_j7: V2,
    pub shaft_j5: V2,
    pub shaft_j6: V2,
    pub shaft_j7: V2,
    pub suspension_j6: V2,
    pub suspension_j8: V2,
    pub head_strip: V2,
}

/// A revolute joint's friction (Table 4): T = D·ω_rel + N·R·μ·sign(ω_rel).
#[derive(Debug, Clone, PartialEq)]
pub struct RevoluteData {
    pub viscous_nms_per_rad: f64,
    pub dry_mu: f64,
    pub pin_radius_m: f64,
    /// J6: locked in the plane of motion (relative rate 0).
    pub locked: bool,
    pub source: String,
}

/// The head suspension: J8 slides (lumped), J9 springs (lumped), the slide line.
#[derive(Debug, Clone, PartialEq)]
pub struct SlideData {
    /// Unit slide direction in the suspension frame (positive h).
    pub axis: V2,
    /// Strip distance from the slide base point (suspension's J8) along the axis at h = 0.
    pub strip_offset_m: f64,
    /// Number of cylindrical slides (J8) and springs (J9), Table 4 values are per unit.
    pub j8_count: f64,
    pub j8_viscous_ns_per_m_each: f64,
    pub j8_dry_mu: f64,
    /// Constant normal force of one slide (paper, Section 4.2), not a reaction.
    pub j8_normal_force_n_each: f64,
    pub j9_count: f64,
    pub j9_stiffness_n_per_m_each: f64,
    pub j9_damping_ns_per_m_each: f64,
    /// Spring force on the head at h = 0 (= head weight: h = 0 at rest without strip load).
    pub preload_n: f64,
    pub j8_source: String,
    pub j9_source: String,
}

/// The lift test of Section 5.3 as the file states it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LiftTestData {
    pub external_spring_n_per_m: f64,
    pub initial: LiftState,
    pub final_: LiftState,
}

/// The validated geometry of a complete pantograph.
#[derive(Debug, Clone)]
pub struct Geometry {
    pub model: String,
    pub gravity_m_s2: f64,
    /// Ground pivots, world (x along the vehicle, y up), m.
    pub ground_j1_m: V2,
    pub ground_j2_m: V2,
    /// Mass properties in [`BodyId`] order.
    pub bodies: [BodyData; 7],
    pub points: Points,
    /// Revolute joints in [`RevJoint`] order.
    pub revolute: [RevoluteData; N_REV],
    pub slide: SlideData,
    /// Loop-closure branches (+1: left of the directed line, see `[assembly]`).
    pub lower_loop_sign: f64,
    pub upper_loop_sign: f64,
    pub alpha_min_rad: f64,
    pub alpha_max_rad: f64,
    pub operating_h_m: Option<[f64; 2]>,
    /// The drive torque the pantograph's drive can make, N·m (`[drive] torque_range_Nm`);
    /// `None`: the file states no range.
    pub drive_torque_range_nm: Option<[f64; 2]>,
    /// The test stand's protocol limits (`[stand]`); `None`: the file states none (the
    /// built-in file's apply, `ProtocolLimits::stand`).
    pub stand: Option<StandData>,
    pub lift_test: LiftTestData,
    pub checks: Checks,
    pub reference_poses: Vec<ReferencePose>,
}

fn positive(key: &str, v: f64) -> Result<f64, GeometryError> {
    if v.is_finite() && v > 0.0 {
        Ok(v)
    } else {
        Err(invalid(
            key,
            format!("must be a finite number > 0, got {v}"),
        ))
    }
}
fn non_negative(key: &str, v: f64) -> Result<f64, GeometryError> {
    if v.is_finite() && v >= 0.0 {
        Ok(v)
    } else {
        Err(invalid(
            key,
            format!("must be a finite number >= 0, got {v}"),
        ))
    }
}
fn finite2(key: &str, v: [f64; 2]) -> Result<V2, GeometryError> {
    if v.iter().all(|x| x.is_finite()) {
        Ok(V2::from_array(v))
    } else {
        Err(invalid(
            key,
            format!("must be two finite numbers, got {v:?}"),
        ))
    }
}
fn required<T: Copy>(key: &str, v: Option<T>) -> Result<T, GeometryError> {
    v.ok_or_else(|| invalid(key, "required"))
}
/// Two figures the file states twice (a per-unit table value and a total) must agree.
fn consistent(key: &str, stated: f64, derived: f64) -> Result<(), GeometryError> {
    if (stated - derived).abs() <= 1e-9 * derived.abs().max(1.0) {
        Ok(())
    } else {
        Err(invalid(
            key,
            format!("{stated} disagrees with {derived} derived from the joints table"),
        ))
    }
}

impl Geometry {
    /// Parse and validate a geometry file.
    pub fn from_toml(text: &str) -> Result<Self, GeometryError> {
        let f: GeometryFile =
            toml::from_str(text).map_err(|e| GeometryError::Parse(e.to_string()))?;
        Self::resolve(f)
    }

    fn resolve(f: GeometryFile) -> Result<Self, GeometryError> {
        if f.meta.format != GEOMETRY_FORMAT {
            return Err(invalid(
                "meta.format",
                format!("expected `{GEOMETRY_FORMAT}`, got `{}`", f.meta.format),
            ));
        }
        let gravity_m_s2 = positive("meta.gravity_m_s2", f.meta.gravity_m_s2)?;
        if f.ground.source.trim().is_empty() {
            return Err(invalid(
                "ground.source",
                "must say where the numbers come from",
            ));
        }
        let ground_j1_m = finite2("ground.J1_m", f.ground.j1_m)?;
        let ground_j2_m = finite2("ground.J2_m", f.ground.j2_m)?;

        // Bodies: exactly the topology's, each with mass, inertia, centre of mass, points.
        for name in f.bodies.keys() {
            if !BodyId::ALL.iter().any(|b| b.key() == name) {
                return Err(invalid(
                    format!("bodies.{name}"),
                    "not a body of the topology",
                ));
            }
        }
        let mut bodies = Vec::with_capacity(7);
        for b in BodyId::ALL {
            let key = b.key();
            let bf = f
                .bodies
                .get(key)
                .ok_or_else(|| invalid(format!("bodies.{key}"), "missing"))?;
            let mass_kg = positive(&format!("bodies.{key}.mass_kg"), bf.mass_kg)?;
            let inertia_cm_kgm2 =
                positive(&format!("bodies.{key}.inertia_cm_kgm2"), bf.inertia_cm_kgm2)?;
            let com_m = finite2(&format!("bodies.{key}.com_m"), bf.com_m)?;
            if bf.paper_no == 0 {
                return Err(invalid(
                    format!("bodies.{key}.paper_no"),
                    "must be Table 2's number (>= 1)",
                ));
            }
            if bf.source.trim().is_empty() {
                return Err(invalid(
                    format!("bodies.{key}.source"),
                    "must say where the numbers come from",
                ));
            }
            if let Some(c) = bf.count
                && c == 0
            {
                return Err(invalid(format!("bodies.{key}.count"), "must be >= 1"));
            }
            if let Some(e) = bf.inertia_axis_kgm2_each {
                positive(&format!("bodies.{key}.inertia_axis_kgm2_each"), e)?;
            }
            // Parallel-axis theorem about the pendulum-test axis (the frame origin, the body's
            // first joint): I_axis = I_cm + m·|com|².
            if let Some(i_axis) = bf.inertia_axis_kgm2 {
                let k = format!("bodies.{key}.inertia_axis_kgm2");
                positive(&k, i_axis)?;
                let implied = inertia_cm_kgm2 + mass_kg * com_m.norm2();
                if (i_axis - implied).abs() > 1e-4 * i_axis {
                    return Err(invalid(
                        k,
                        format!(
                            "{i_axis} kg·m² disagrees with I_cm + m·|com|² = {implied} (parallel-axis theorem)"
                        ),
                    ));
                }
            }
            for (p, v) in &bf.points_m {
                finite2(&format!("bodies.{key}.points_m.{p}"), *v)?;
            }
            bodies.push(BodyData {
                mass_kg,
                inertia_cm_kgm2,
                com_m,
                source: bf.source.clone(),
            });
        }
        let bodies: [BodyData; 7] = bodies
            .try_into()
            .map_err(|_| invalid("bodies", "seven bodies expected"))?;

        let point = |b: BodyId, p: &str| -> Result<V2, GeometryError> {
            let key = b.key();
            f.bodies
                .get(key)
                .and_then(|bf| bf.points_m.get(p))
                .map(|v| V2::from_array(*v))
                .ok_or_else(|| {
                    invalid(
                        format!("bodies.{key}.points_m.{p}"),
                        "required point missing",
                    )
                })
        };
        use BodyId::*;
        let points = Points {
            lower_arm_j1: point(LowerArm, "J1")?,
            lower_arm_j3: point(LowerArm, "J3")?,
            lower_arm_j4: point(LowerArm, "J4")?,
            coupling_rod_j2: point(CouplingRod, "J2")?,
            coupling_rod_j2p: point(CouplingRod, "J2'")?,
            upper_arm_j3: point(UpperArm, "J3")?,
            upper_arm_j5: point(UpperArm, "J5")?,
            upper_arm_j2p: point(UpperArm, "J2'")?,
            balance_rod_j4: point(BalanceRod, "J4")?,
            balance_rod_j7: point(BalanceRod, "J7")?,
            shaft_j5: point(Shaft, "J5")?,
            shaft_j6: point(Shaft, "J6")?,
            shaft_j7: point(Shaft, "J7")?,
            suspension_j6: point(Suspension, "J6")?,
            suspension_j8: point(Suspension, "J8")?,
            head_strip: point(Head, "strip")?,
        };
        // Links of the two loops must have length.
        for (k, a, b) in [
            (
                "bodies.lower_arm.points_m.J3",
                points.lower_arm_j1,
                points.lower_arm_j3,
            ),
            (
                "bodies.coupling_rod.points_m.J2'",
                points.coupling_rod_j2,
                points.coupling_rod_j2p,
            ),
            (
                "bodies.upper_arm.points_m.J2'",
                points.upper_arm_j3,
                points.upper_arm_j2p,
            ),
            (
                "bodies.balance_rod.points_m.J7",
                points.balance_rod_j4,
                points.balance_rod_j7,
            ),
            ("bodies.shaft.points_m.J7", points.shaft_j5, points.shaft_j7),
        ] {
            if (b - a).norm() < 1e-6 {
                return Err(invalid(k, "coincides with the link's other joint"));
            }
        }

        // Joints: exactly J1…J9 with the topology's body pairs.
        let expected: Vec<&str> = RevJoint::ALL
            .iter()
            .map(|j| j.name())
            .chain(["J8", "J9"])
            .collect();
        for name in f.joints.keys() {
            if !expected.contains(&name.as_str()) {
                return Err(invalid(
                    format!("joints.{name}"),
                    "not a joint of the topology",
                ));
            }
        }
        let joint = |name: &str| {
            f.joints
                .get(name)
                .ok_or_else(|| invalid(format!("joints.{name}"), "missing"))
        };
        let check_bodies = |name: &str, jf: &JointFile, first: &str, second: &str| {
            if jf.bodies[0] != first || jf.bodies[1] != second {
                Err(invalid(
                    format!("joints.{name}.bodies"),
                    format!("expected [\"{first}\", \"{second}\"], got {:?}", jf.bodies),
                ))
            } else {
                Ok(())
            }
        };
        let mut revolute = Vec::with_capacity(N_REV);
        for j in RevJoint::ALL {
            let name = j.name();
            let jf = joint(name)?;
            let k = |s: &str| format!("joints.{name}.{s}");
            if jf.kind != "revolute" {
                return Err(invalid(
                    k("type"),
                    format!("expected `revolute`, got `{}`", jf.kind),
                ));
            }
            let (a, b) = j.bodies();
            check_bodies(name, jf, a.map_or("ground", |a| a.key()), b.key())?;
            let locked = match jf.planar_rotation.as_deref() {
                None | Some("free") => false,
                Some("locked") => true,
                Some(o) => {
                    return Err(invalid(
                        k("planar_rotation"),
                        format!("`locked` or `free`, got `{o}`"),
                    ));
                }
            };
            // The model locks J6 in the plane (the head forces it, paper Section 2); a free J6
            // would add an inverted-pendulum degree of freedom this model does not have.
            if (j == RevJoint::J6) != locked {
                return Err(invalid(
                    k("planar_rotation"),
                    if locked {
                        "only J6 can be locked in this topology"
                    } else {
                        "J6 must be `locked`: the model has no free suspension rotation"
                    },
                ));
            }
            if jf.source.trim().is_empty() {
                return Err(invalid(k("source"), "must say where the numbers come from"));
            }
            revolute.push(RevoluteData {
                viscous_nms_per_rad: non_negative(
                    &k("viscous_Nms_per_rad"),
                    required(&k("viscous_Nms_per_rad"), jf.viscous_nms_per_rad)?,
                )?,
                dry_mu: non_negative(&k("dry_mu"), required(&k("dry_mu"), jf.dry_mu)?)?,
                pin_radius_m: positive(
                    &k("pin_radius_m"),
                    required(&k("pin_radius_m"), jf.pin_radius_m)?,
                )?,
                locked,
                source: jf.source.clone(),
            });
        }
        let revolute: [RevoluteData; N_REV] = revolute
            .try_into()
            .map_err(|_| invalid("joints", "eight revolute joints expected"))?;

        let j8 = joint("J8")?;
        if j8.kind != "prismatic" {
            return Err(invalid(
                "joints.J8.type",
                format!("expected `prismatic`, got `{}`", j8.kind),
            ));
        }
        check_bodies("J8", j8, Suspension.key(), Head.key())?;
        let j9 = joint("J9")?;
        if j9.kind != "spring" {
            return Err(invalid(
                "joints.J9.type",
                format!("expected `spring`, got `{}`", j9.kind),
            ));
        }
        check_bodies("J9", j9, Suspension.key(), Head.key())?;
        let hs = &f.head_suspension;
        let axis = finite2(
            "head_suspension.slide_axis_in_suspension_frame",
            hs.slide_axis_in_suspension_frame,
        )?;
        if (axis.norm() - 1.0).abs() > 1e-9 {
            return Err(invalid(
                "head_suspension.slide_axis_in_suspension_frame",
                "must be a unit vector",
            ));
        }
        let j8_count = j8.count.unwrap_or(1);
        let j9_count = j9.count.unwrap_or(1);
        if j8_count == 0 {
            return Err(invalid("joints.J8.count", "must be >= 1"));
        }
        if j9_count == 0 {
            return Err(invalid("joints.J9.count", "must be >= 1"));
        }
        let slide = SlideData {
            axis,
            strip_offset_m: {
                let v = hs.strip_above_slide_base_at_h0_m;
                if !v.is_finite() {
                    return Err(invalid(
                        "head_suspension.strip_above_slide_base_at_h0_m",
                        "must be finite",
                    ));
                }
                v
            },
            j8_count: j8_count as f64,
            j8_viscous_ns_per_m_each: non_negative(
                "joints.J8.viscous_Ns_per_m_each",
                required("joints.J8.viscous_Ns_per_m_each", j8.viscous_ns_per_m_each)?,
            )?,
            j8_dry_mu: non_negative("joints.J8.dry_mu", required("joints.J8.dry_mu", j8.dry_mu)?)?,
            j8_normal_force_n_each: positive(
                "joints.J8.normal_force_N_each",
                required("joints.J8.normal_force_N_each", j8.normal_force_n_each)?,
            )?,
            j9_count: j9_count as f64,
            j9_stiffness_n_per_m_each: positive(
                "joints.J9.stiffness_N_per_m_each",
                required(
                    "joints.J9.stiffness_N_per_m_each",
                    j9.stiffness_n_per_m_each,
                )?,
            )?,
            j9_damping_ns_per_m_each: non_negative(
                "joints.J9.damping_Ns_per_m_each",
                required("joints.J9.damping_Ns_per_m_each", j9.damping_ns_per_m_each)?,
            )?,
            preload_n: non_negative("head_suspension.preload_N", hs.preload_n)?,
            j8_source: j8.source.clone(),
            j9_source: j9.source.clone(),
        };
        // The head-suspension totals repeat the joints table: they must agree with it.
        consistent(
            "head_suspension.stiffness_total_N_per_m",
            hs.stiffness_total_n_per_m,
            slide.j9_count * slide.j9_stiffness_n_per_m_each,
        )?;
        consistent(
            "head_suspension.damping_total_Ns_per_m",
            hs.damping_total_ns_per_m,
            slide.j9_count * slide.j9_damping_ns_per_m_each,
        )?;
        consistent(
            "head_suspension.j8_viscous_total_Ns_per_m",
            hs.j8_viscous_total_ns_per_m,
            slide.j8_count * slide.j8_viscous_ns_per_m_each,
        )?;
        consistent(
            "head_suspension.j8_dry_force_total_N",
            hs.j8_dry_force_total_n,
            slide.j8_count * slide.j8_normal_force_n_each * slide.j8_dry_mu,
        )?;

        let sign = |key: &str, s: i32| -> Result<f64, GeometryError> {
            match s {
                1 => Ok(1.0),
                -1 => Ok(-1.0),
                o => Err(invalid(key, format!("must be +1 or -1, got {o}"))),
            }
        };
        let lower_loop_sign = sign("assembly.lower_loop_sign", f.assembly.lower_loop_sign)?;
        let upper_loop_sign = sign("assembly.upper_loop_sign", f.assembly.upper_loop_sign)?;
        let (a0, a1) = (f.range.alpha_min_rad, f.range.alpha_max_rad);
        if !(a0.is_finite() && a1.is_finite() && a0 < a1) {
            return Err(invalid(
                "range.alpha_max_rad",
                format!("must be finite and above alpha_min_rad ({a0}), got {a1}"),
            ));
        }
        if f.drive.torque_on != LowerArm.key() {
            return Err(invalid(
                "drive.torque_on",
                format!(
                    "the model drives the lower arm, got `{}`",
                    f.drive.torque_on
                ),
            ));
        }
        let lt = &f.lift_test;
        for (k, s) in [
            ("lift_test.initial", lt.initial),
            ("lift_test.final", lt.final_),
        ] {
            for (field, v) in [
                ("H_m", s.h_m),
                ("T_Nm", s.t_nm),
                ("Fs_N", s.fs_n),
                ("Fm_N", s.fm_n),
            ] {
                if !v.is_finite() {
                    return Err(invalid(format!("{k}.{field}"), "must be finite"));
                }
            }
        }
        non_negative(
            "lift_test.external_spring_N_per_m",
            lt.external_spring_n_per_m,
        )?;
        Ok(Geometry {
            model: f.meta.model,
            gravity_m_s2,
            ground_j1_m,
            ground_j2_m,
            bodies,
            points,
            revolute,
            slide,
            lower_loop_sign,
            upper_loop_sign,
            alpha_min_rad: a0,
            alpha_max_rad: a1,
            operating_h_m: f.range.operating_h_m,
            drive_torque_range_nm: match f.drive.torque_range_nm {
                Some([lo, hi]) if lo.is_finite() && hi.is_finite() && lo < hi => Some([lo, hi]),
                Some(r) => {
                    return Err(invalid(
                        "drive.torque_range_Nm",
                        format!("must be [low, high] with low < high, got {r:?}"),
                    ));
                }
                None => None,
            },
            stand: match f.stand {
                Some(s) => {
                    let range = |key: &str, r: [f64; 2]| {
                        if r[0].is_finite() && r[1].is_finite() && 0.0 < r[0] && r[0] < r[1] {
                            Ok(r)
                        } else {
                            Err(invalid(
                                key,
                                format!("must be [low, high] with 0 < low < high, got {r:?}"),
                            ))
                        }
                    };
                    Some(StandData {
                        height_range_m: range("stand.height_range_m", s.height_range_m)?,
                        tau_range_s: range("stand.tau_range_s", s.tau_range_s)?,
                        dwell_min_s: positive("stand.dwell_min_s", s.dwell_min_s)?,
                        duration_max_s: positive("stand.duration_max_s", s.duration_max_s)?,
                    })
                }
                None => None,
            },
            lift_test: LiftTestData {
                external_spring_n_per_m: lt.external_spring_n_per_m,
                initial: lt.initial,
                final_: lt.final_,
            },
            checks: f.checks,
            reference_poses: f.reference_pose,
        })
    }

    /// Mass data of a body.
    pub fn body(&self, b: BodyId) -> &BodyData {
        &self.bodies[b.index()]
    }
}

/// The 160EC geometry, parsed and validated once.
///
/// # Panics
/// Never on a released build: the compiled-in file is checked by `builtin_geometry_is_valid`.
pub fn builtin_160ec() -> &'static Geometry {
    static G: OnceLock<Geometry> = OnceLock::new();
    G.get_or_init(|| {
        Geometry::from_toml(GEOMETRY_160EC_TOML).expect("models/data/160ec-geometry.toml is valid")
    })
}

#[cfg(test)]
mod tests;

//! The geometry file as written (`models/data/160ec-geometry.toml`): its sections as serde
//! structs, resolved into [`super::Geometry`] by `Geometry::parse`.

use std::collections::BTreeMap;

use serde::Deserialize;

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct MetaFile {
    pub(super) format: String,
    pub(super) model: String,
    pub(super) gravity_m_s2: f64,
    #[serde(default)]
    #[allow(dead_code)]
    pub(super) units: Option<String>,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct GroundFile {
    #[serde(rename = "J1_m")]
    pub(super) j1_m: [f64; 2],
    #[serde(rename = "J2_m")]
    pub(super) j2_m: [f64; 2],
    pub(super) source: String,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct BodyFile {
    pub(super) paper_no: u32,
    pub(super) mass_kg: f64,
    #[serde(default)]
    pub(super) count: Option<u32>,
    #[serde(default)]
    pub(super) inertia_axis_kgm2: Option<f64>,
    #[serde(default)]
    pub(super) inertia_axis_kgm2_each: Option<f64>,
    pub(super) inertia_cm_kgm2: f64,
    pub(super) com_m: [f64; 2],
    pub(super) source: String,
    pub(super) points_m: BTreeMap<String, [f64; 2]>,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct JointFile {
    #[serde(rename = "type")]
    pub(super) kind: String,
    pub(super) bodies: [String; 2],
    #[serde(default)]
    pub(super) planar_rotation: Option<String>,
    #[serde(default)]
    pub(super) count: Option<u32>,
    #[serde(default, rename = "viscous_Nms_per_rad")]
    pub(super) viscous_nms_per_rad: Option<f64>,
    #[serde(default, rename = "viscous_Ns_per_m_each")]
    pub(super) viscous_ns_per_m_each: Option<f64>,
    #[serde(default)]
    pub(super) dry_mu: Option<f64>,
    #[serde(default)]
    pub(super) pin_radius_m: Option<f64>,
    #[serde(default, rename = "normal_force_N_each")]
    pub(super) normal_force_n_each: Option<f64>,
    #[serde(default, rename = "stiffness_N_per_m_each")]
    pub(super) stiffness_n_per_m_each: Option<f64>,
    #[serde(default, rename = "damping_Ns_per_m_each")]
    pub(super) damping_ns_per_m_each: Option<f64>,
    pub(super) source: String,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct HeadSuspensionFile {
    pub(super) slide_axis_in_suspension_frame: [f64; 2],
    pub(super) strip_above_slide_base_at_h0_m: f64,
    #[serde(rename = "stiffness_total_N_per_m")]
    pub(super) stiffness_total_n_per_m: f64,
    #[serde(rename = "damping_total_Ns_per_m")]
    pub(super) damping_total_ns_per_m: f64,
    #[serde(rename = "j8_viscous_total_Ns_per_m")]
    pub(super) j8_viscous_total_ns_per_m: f64,
    #[serde(rename = "j8_dry_force_total_N")]
    pub(super) j8_dry_force_total_n: f64,
    #[serde(rename = "preload_N")]
    pub(super) preload_n: f64,
    #[serde(default)]
    #[allow(dead_code)]
    pub(super) static_deflection_lift_initial_mm: Option<f64>,
    #[serde(default)]
    #[allow(dead_code)]
    pub(super) travel_stops: Option<String>,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct AssemblyFile {
    pub(super) lower_loop_sign: i32,
    pub(super) upper_loop_sign: i32,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RangeFile {
    pub(super) alpha_min_rad: f64,
    pub(super) alpha_max_rad: f64,
    #[serde(default, rename = "operating_H_m")]
    pub(super) operating_h_m: Option<[f64; 2]>,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct DriveFile {
    pub(super) torque_on: String,
    #[serde(default, rename = "torque_range_Nm")]
    pub(super) torque_range_nm: Option<[f64; 2]>,
}

/// A steady state of the lift test (paper, Section 5.3).
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LiftState {
    #[serde(rename = "H_m")]
    pub h_m: f64,
    #[serde(rename = "T_Nm")]
    pub t_nm: f64,
    #[serde(rename = "Fs_N")]
    pub fs_n: f64,
    #[serde(rename = "Fm_N")]
    pub fm_n: f64,
}

impl LiftState {
    /// Everything pressing the strip down: the external spring plus the suspended weight.
    pub fn strip_load_n(&self) -> f64 {
        self.fs_n + self.fm_n
    }
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct StandFile {
    pub(super) height_range_m: [f64; 2],
    pub(super) tau_range_s: [f64; 2],
    pub(super) dwell_min_s: f64,
    pub(super) duration_max_s: f64,
}

/// The test stand's limits for a designed lift protocol (`[stand]`, assumed; read by
/// `lift::design::ProtocolLimits::stand`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StandData {
    pub height_range_m: [f64; 2],
    pub tau_range_s: [f64; 2],
    pub dwell_min_s: f64,
    pub duration_max_s: f64,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct LiftTestFile {
    #[serde(rename = "external_spring_N_per_m")]
    pub(super) external_spring_n_per_m: f64,
    #[serde(default)]
    #[allow(dead_code)]
    pub(super) transient_duration_s: Option<toml::Value>,
    pub(super) initial: LiftState,
    #[serde(rename = "final")]
    pub(super) final_: LiftState,
}

/// `[checks]`: figures derived from the file by its design script, for an implementation to
/// reproduce (frictionless statics, h static).
#[derive(Debug, Clone, Default, Deserialize)]
pub struct Checks {
    #[serde(rename = "T_eq_initial_Nm")]
    pub t_eq_initial_nm: Option<f64>,
    #[serde(rename = "T_eq_final_Nm")]
    pub t_eq_final_nm: Option<f64>,
    pub alpha_initial_rad: Option<f64>,
    pub alpha_final_rad: Option<f64>,
    pub h_initial_m: Option<f64>,
    pub h_final_m: Option<f64>,
    pub dh_dalpha_range_m_per_rad: Option<[f64; 2]>,
    pub head_pitch_operating_deg: Option<[f64; 2]>,
    pub min_transmission_angle_lower_loop_deg: Option<f64>,
    pub min_transmission_angle_upper_loop_deg: Option<f64>,
}

/// `[[reference_pose]]`: the assembly at one (α, h), to check an implementation against.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ReferencePose {
    #[serde(rename = "H_m")]
    pub h_strip_m: f64,
    pub alpha_rad: f64,
    /// Head travel h on the J8 slide.
    pub h_m: f64,
    /// Body angles by body key.
    pub theta_rad: BTreeMap<String, f64>,
    /// World positions of joints (and `strip`) by name.
    pub points_m: BTreeMap<String, [f64; 2]>,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct GeometryFile {
    pub(super) meta: MetaFile,
    pub(super) ground: GroundFile,
    pub(super) bodies: BTreeMap<String, BodyFile>,
    pub(super) joints: BTreeMap<String, JointFile>,
    pub(super) head_suspension: HeadSuspensionFile,
    pub(super) assembly: AssemblyFile,
    pub(super) range: RangeFile,
    pub(super) drive: DriveFile,
    #[serde(default)]
    pub(super) stand: Option<StandFile>,
    pub(super) lift_test: LiftTestFile,
    #[serde(default)]
    #[allow(dead_code)]
    pub(super) design: Option<toml::Table>,
    #[serde(default)]
    pub(super) checks: Checks,
    #[serde(default)]
    pub(super) reference_pose: Vec<ReferencePose>,
}

//! The pantograph type as data: Table 2 inertia, Table 4 friction and pin radii, and the
//! single-joint test rigs of Figs 5–12, parsed from a TOML file and validated.
//!
//! The 160EC file is compiled in ([`builtin_160ec`]); another type is another file of the
//! same shape, loaded with [`PantographType::from_toml`]. Parsing takes a string: no I/O here.

use std::collections::BTreeMap;
use std::sync::OnceLock;

use serde::Deserialize;

/// The 160EC data file, `models/data/160ec.toml`.
pub const PANTOGRAPH_160EC_TOML: &str = include_str!("../data/160ec.toml");

/// Error in a pantograph data file, naming the offending key.
#[derive(Debug, thiserror::Error)]
pub enum DataError {
    #[error("pantograph data: cannot parse TOML: {0}")]
    Parse(String),
    #[error("pantograph data: `{field}`: {message}")]
    Invalid { field: String, message: String },
}

fn invalid(field: impl Into<String>, message: impl Into<String>) -> DataError {
    DataError::Invalid {
        field: field.into(),
        message: message.into(),
    }
}

/// A rigid body of the pantograph (Table 2), as it swings in its pendulum test.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BodyData {
    pub paper_no: u32,
    pub mass_kg: f64,
    /// Moment of inertia about the pendulum-test axis (Table 2, "Ji axis").
    #[serde(default)]
    pub inertia_axis_kgm2: Option<f64>,
    /// Distance from that axis to the centre of mass.
    #[serde(default)]
    pub com_distance_m: Option<f64>,
    pub source: String,
}

/// Kind of a joint of the pantograph.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum JointKind {
    Revolute,
    Prismatic,
}

/// A joint's friction baseline (Table 4).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct JointData {
    pub kind: JointKind,
    pub description: String,
    /// Revolute joints: viscous damping, N·m·s/rad.
    #[serde(default)]
    pub viscous_nms_per_rad: Option<f64>,
    /// Prismatic joints: viscous damping, N·s/m.
    #[serde(default)]
    pub viscous_ns_per_m: Option<f64>,
    /// Dry friction coefficient μ (dimensionless).
    pub dry_mu: f64,
    /// Revolute joints: radius R of the contact surface in the dry torque N·R·μ.
    #[serde(default)]
    pub pin_radius_m: Option<f64>,
    /// Prismatic joints: the constant normal force Fn in the dry force Fn·μ.
    #[serde(default)]
    pub normal_force_n: Option<f64>,
    pub source: String,
}

impl JointData {
    /// Baseline viscous coefficient in the joint's own unit (N·m·s/rad or N·s/m).
    pub fn viscous_baseline(&self) -> f64 {
        match self.kind {
            JointKind::Revolute => self.viscous_nms_per_rad.unwrap_or(f64::NAN),
            JointKind::Prismatic => self.viscous_ns_per_m.unwrap_or(f64::NAN),
        }
    }
    /// Unit of the viscous coefficient.
    pub fn viscous_unit(&self) -> &'static str {
        match self.kind {
            JointKind::Revolute => "N·m·s/rad",
            JointKind::Prismatic => "N·s/m",
        }
    }
}

/// A mass added to a pendulum rig (Figs 9, 10): a point mass on the centre-of-mass line,
/// or a uniform rod hanging from the axis along that line.
#[derive(Debug, Clone, PartialEq, Deserialize, serde::Serialize)]
#[serde(tag = "kind", rename_all = "lowercase", deny_unknown_fields)]
pub enum Attachment {
    Point { mass_kg: f64, distance_m: f64 },
    Rod { mass_kg: f64, length_m: f64 },
}

/// The pendulum test rig of one joint.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RigData {
    pub figure: String,
    /// Key into `bodies`.
    pub body: String,
    pub release_deg: f64,
    #[serde(default)]
    pub attachments: Vec<Attachment>,
    pub source: String,
}

/// The slider (head suspension) test rig.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SliderRigData {
    pub figure: String,
    pub joint: String,
    pub moving_mass_kg: f64,
    pub springs: u32,
    pub spring_stiffness_n_per_mm: f64,
    pub release_mm: f64,
    pub source: String,
}

/// One pantograph type: bodies, joints and test rigs.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PantographType {
    pub format: String,
    pub model: String,
    pub gravity_m_s2: f64,
    pub bodies: BTreeMap<String, BodyData>,
    pub joints: BTreeMap<String, JointData>,
    pub rigs: BTreeMap<String, RigData>,
    pub slider: SliderRigData,
    /// The plausible span of a test rig's stated values (`[rig_limits]`); a file without the
    /// table borrows the built-in 160EC's ([`PantographType::rig_limits`]).
    #[serde(default, rename = "rig_limits")]
    pub rig_limits_data: Option<RigLimits>,
    /// The static contact force's working range and limits (`[static_force]`, issue 20); a
    /// type without the table has no static-force prediction.
    #[serde(default)]
    pub static_force: Option<StaticForceData>,
    /// The paper's whole-pantograph test protocols (`[paper_tests]`); a file without the table
    /// borrows the built-in 160EC's ([`PantographType::paper_tests`]).
    #[serde(default, rename = "paper_tests")]
    pub paper_tests_data: Option<PaperTests>,
    /// How the fleet's prior is learned from workshop fits (`[fleet_prior]`, issue 37); a file
    /// without the table borrows the built-in 160EC's ([`PantographType::fleet_prior`]).
    #[serde(default, rename = "fleet_prior")]
    pub fleet_prior_data: Option<FleetPriorData>,
    /// What a joint's evidence may age to and how fast it ages (`[test_plan]`, issue 37); a type
    /// without the table has no test plan.
    #[serde(default)]
    pub test_plan: Option<TestPlanData>,
}

/// `[fleet_prior]`: how a fleet prior is learned from workshop fits (`lift::fleet_prior`).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FleetPriorData {
    pub source: String,
    /// Fewest workshop fits of one joint and parameter before the fleet's spread is used.
    pub min_fits: usize,
    /// The spread (Table 4 units) of a joint with fewer fits.
    pub floor_relative_sd: f64,
    /// The narrowest learned spread, Table 4 units.
    pub min_relative_sd: f64,
    /// A new prior version when a mean or sd moves by more than this, Table 4 units.
    pub version_tolerance_relative: f64,
    /// Every learned sd × this where a fit uses the prior (`FleetPrior::for_fit`).
    pub fit_sd_scale: f64,
}

/// `[test_plan]`: the wear-rate spread that widens old evidence (`contract::evidence`), the
/// prior of a parameter never measured, and how old each joint's evidence may get before a
/// workshop test is due (a joint not named is never due).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TestPlanData {
    pub source: String,
    /// sd of a joint parameter's wear rate across the fleet, × baseline per year.
    pub fleet_wear_sd_per_year: f64,
    /// sd of a parameter no test has informed, × baseline.
    pub unmeasured_relative_sd: f64,
    /// Per joint, days.
    pub max_evidence_age_days: BTreeMap<String, f64>,
}

/// `[static_force]`: where the characteristic is computed and what it must stay within. Limits
/// are the operator's; the built-in values are placeholders derived from the paper's lift states.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StaticForceData {
    pub source: String,
    /// Strip heights [lowest, highest], m.
    pub working_height_m: [f64; 2],
    pub height_step_m: f64,
    /// The nominal force at two heights, `[[H m, F N], [H m, F N]]`, linear in between.
    pub nominal_force_points: [[f64; 2]; 2],
    /// Allowed deviation either side of the nominal force, N.
    pub tolerance_n: f64,
    /// Largest lowering − raising force difference, N.
    pub max_raise_lower_difference_n: f64,
    /// Fewest readings per branch of a force-gauge record (`lift::gauge`).
    pub min_points_per_branch: usize,
    /// The plausible span of a gauge's stated resolution, N.
    pub gauge_resolution_range_n: [f64; 2],
    /// The gauge's noise (one sd), N: a gauge fit's noise floor, a simulation's default.
    pub gauge_noise_n: f64,
    /// A simulated gauge's resolution, N.
    pub gauge_sim_resolution_n: f64,
    /// Time between two gauge readings [shortest, longest], s (readings by hand: replaces
    /// `rig_limits.sample_interval_s` for a `static_force` record).
    pub gauge_reading_interval_s: [f64; 2],
}

/// The paper's whole-pantograph tests as the reference traces run them: the lower-quadrangle
/// swing (Fig 12) and the reference lift (Section 5.3). The file gives each value's source.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PaperTests {
    pub source: String,
    /// The frame plane's incline in the quadrangle swing test, deg.
    pub quadrangle_incline_deg: f64,
    /// The quadrangle's release as a deflection from its rest angle, deg.
    pub quadrangle_deflection_deg: f64,
    /// The reference lift's recording: start, end (s) and sampling rate (Hz).
    pub lift_t_start_s: f64,
    pub lift_t_end_s: f64,
    pub lift_sample_hz: f64,
    /// The lift drive's torque-step time constant, s.
    pub lift_drive_tau_s: f64,
    /// The lift drive's damping, N·m·s/rad.
    pub lift_drive_damping_nms_per_rad: f64,
}

/// The span a test rig's stated values and recorded channels can physically have (issue 18):
/// each `[lo, hi]` inclusive, channel bounds on the absolute value. Outside it, a trace is
/// refused at upload naming the field, before any fit could spend its budget on it. The file
/// states each value's reason; docs/API.md "Input limits" lists them.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RigLimits {
    pub source: String,
    pub pin_radius_m: [f64; 2],
    /// Any stated mass: a pendulum's body, an attachment, a quadrangle's point mass, kg.
    pub mass_kg: [f64; 2],
    pub inertia_kgm2: [f64; 2],
    pub com_distance_m: [f64; 2],
    /// A point attachment's distance or a rod's length, m; a quadrangle point mass's distance
    /// from its body's origin.
    pub attachment_m: [f64; 2],
    pub gravity_m_s2: [f64; 2],
    pub initial_rate_deg_s: [f64; 2],
    pub moving_mass_kg: [f64; 2],
    /// Springs of a slider, a whole number; 0 is a slider without one.
    pub springs: [f64; 2],
    pub spring_stiffness_n_per_mm: [f64; 2],
    pub normal_force_n: [f64; 2],
    /// |joint angle| of a pendulum's `alpha_deg`, a quadrangle's `alpha_deg` and `beta_deg`.
    pub alpha_deg_abs: f64,
    pub h_mm_abs: f64,
    /// |force| of a slider's `F_N`.
    pub force_n_abs: f64,
    /// The quadrangle stand's frame-plane incline from horizontal, deg.
    pub incline_deg: [f64; 2],
    /// A lift's `H_m`, the contact strip's height above the base frame, m.
    pub lift_strip_height_m: [f64; 2],
    /// A lift's `Fs_N` and `Fm_N`, loads on the strip positive down, N.
    pub lift_strip_force_n: [f64; 2],
    /// Each interval between consecutive `t_s` samples, s (every kind).
    pub sample_interval_s: [f64; 2],
    /// Every `t_s` sample, s on the test's own clock.
    pub time_s: [f64; 2],
    /// `t_s`'s last sample less its first, s.
    pub record_duration_max_s: f64,
}

impl RigLimits {
    /// `Err((field, message))` when `v` lies outside `span` (NaN included).
    pub fn check(field: &str, v: f64, span: [f64; 2]) -> Result<(), (String, String)> {
        if v >= span[0] && v <= span[1] {
            Ok(())
        } else {
            Err((
                field.to_string(),
                format!(
                    "{v} is outside the plausible range [{}, {}] of a test rig (models/data, `rig_limits`)",
                    span[0], span[1]
                ),
            ))
        }
    }

    /// The first sample of a channel outside `span` (NaN included), as `channels.NAME[i]`.
    pub fn check_channel_span(
        name: &str,
        values: &[f64],
        span: [f64; 2],
        unit: &str,
    ) -> Result<(), (String, String)> {
        match values
            .iter()
            .position(|v| !(*v >= span[0] && *v <= span[1]))
        {
            None => Ok(()),
            Some(i) => Err((
                format!("channels.{name}[{i}]"),
                format!(
                    "{} {unit} is outside [{}, {}] {unit}, the plausible range of this channel (models/data, `rig_limits`)",
                    values[i], span[0], span[1]
                ),
            )),
        }
    }

    /// A record's clock (`channels.t_s`, already strictly increasing): every sample within
    /// `time_s`, every interval within `sample_interval_s` (named by the sample after it), and
    /// the whole record no longer than `record_duration_max_s` (named `channels.t_s`).
    pub fn check_sampling(&self, t_s: &[f64]) -> Result<(), (String, String)> {
        self.check_sampling_within(t_s, self.sample_interval_s, "rig_limits.sample_interval_s")
    }

    /// [`RigLimits::check_sampling`] with another interval rule (`interval_s`, named by `key`
    /// in the message): a force gauge read by hand (`static_force.gauge_reading_interval_s`).
    pub fn check_sampling_within(
        &self,
        t_s: &[f64],
        interval_s: [f64; 2],
        key: &str,
    ) -> Result<(), (String, String)> {
        Self::check_channel_span("t_s", t_s, self.time_s, "s")?;
        let [lo, hi] = interval_s;
        if let Some(i) = t_s
            .windows(2)
            .position(|w| !(w[1] - w[0] >= lo && w[1] - w[0] <= hi))
        {
            return Err((
                format!("channels.t_s[{}]", i + 1),
                format!(
                    "{} s after the sample before it: a sampling interval outside [{lo}, {hi}] s \
                     (models/data, `{key}`)",
                    t_s[i + 1] - t_s[i]
                ),
            ));
        }
        if let (Some(first), Some(last)) = (t_s.first(), t_s.last())
            && last - first > self.record_duration_max_s
        {
            return Err((
                "channels.t_s".into(),
                format!(
                    "the record lasts {} s, longer than {} s (models/data, \
                     `rig_limits.record_duration_max_s`)",
                    last - first,
                    self.record_duration_max_s
                ),
            ));
        }
        Ok(())
    }

    /// Every span names a range: finite, `lo <= hi`; every bound on a magnitude finite and > 0.
    fn validate(&self) -> Result<(), DataError> {
        let spans = [
            ("pin_radius_m", self.pin_radius_m),
            ("mass_kg", self.mass_kg),
            ("inertia_kgm2", self.inertia_kgm2),
            ("com_distance_m", self.com_distance_m),
            ("attachment_m", self.attachment_m),
            ("gravity_m_s2", self.gravity_m_s2),
            ("initial_rate_deg_s", self.initial_rate_deg_s),
            ("moving_mass_kg", self.moving_mass_kg),
            ("springs", self.springs),
            ("spring_stiffness_n_per_mm", self.spring_stiffness_n_per_mm),
            ("normal_force_n", self.normal_force_n),
            ("incline_deg", self.incline_deg),
            ("lift_strip_height_m", self.lift_strip_height_m),
            ("lift_strip_force_n", self.lift_strip_force_n),
            ("sample_interval_s", self.sample_interval_s),
            ("time_s", self.time_s),
        ];
        for (name, [lo, hi]) in spans {
            if !(lo.is_finite() && hi.is_finite() && lo <= hi) {
                return Err(invalid(
                    format!("rig_limits.{name}"),
                    format!("[{lo}, {hi}] is not a range"),
                ));
            }
        }
        for (name, v) in [
            ("alpha_deg_abs", self.alpha_deg_abs),
            ("h_mm_abs", self.h_mm_abs),
            ("force_n_abs", self.force_n_abs),
            ("record_duration_max_s", self.record_duration_max_s),
        ] {
            positive(&format!("rig_limits.{name}"), v)?;
        }
        positive("rig_limits.sample_interval_s[0]", self.sample_interval_s[0])
    }

    /// The first sample of a channel whose magnitude exceeds `abs_max`, as `channels.NAME[i]`.
    pub fn check_channel(name: &str, values: &[f64], abs_max: f64) -> Result<(), (String, String)> {
        match values.iter().position(|v| v.is_nan() || v.abs() > abs_max) {
            None => Ok(()),
            Some(i) => Err((
                format!("channels.{name}[{i}]"),
                format!(
                    "{} is outside ±{abs_max}, the plausible range of this channel (models/data, `rig_limits`)",
                    values[i]
                ),
            )),
        }
    }
}

fn positive(field: &str, v: f64) -> Result<(), DataError> {
    if v.is_finite() && v > 0.0 {
        Ok(())
    } else {
        Err(invalid(
            field,
            format!("must be a finite number > 0, got {v}"),
        ))
    }
}
fn non_negative(field: &str, v: f64) -> Result<(), DataError> {
    if v.is_finite() && v >= 0.0 {
        Ok(())
    } else {
        Err(invalid(
            field,
            format!("must be a finite number >= 0, got {v}"),
        ))
    }
}

impl PantographType {
    /// This type's rig limits, or the built-in 160EC's when its file has none.
    pub fn rig_limits(&self) -> &RigLimits {
        match &self.rig_limits_data {
            Some(l) => l,
            None => builtin_160ec()
                .rig_limits_data
                .as_ref()
                .expect("models/data/160ec.toml has [rig_limits]"),
        }
    }

    /// This type's fleet-prior settings, or the built-in 160EC's when its file has none.
    pub fn fleet_prior(&self) -> &FleetPriorData {
        match &self.fleet_prior_data {
            Some(p) => p,
            None => builtin_160ec()
                .fleet_prior_data
                .as_ref()
                .expect("models/data/160ec.toml has [fleet_prior]"),
        }
    }

    /// This type's paper test protocols, or the built-in 160EC's when its file has none.
    pub fn paper_tests(&self) -> &PaperTests {
        match &self.paper_tests_data {
            Some(p) => p,
            None => builtin_160ec()
                .paper_tests_data
                .as_ref()
                .expect("models/data/160ec.toml has [paper_tests]"),
        }
    }

    /// Parse and validate a pantograph data file.
    pub fn from_toml(text: &str) -> Result<Self, DataError> {
        let t: PantographType =
            toml::from_str(text).map_err(|e| DataError::Parse(e.to_string()))?;
        t.validate()?;
        Ok(t)
    }

    /// Check every number: physical signs, units present for each joint kind, rigs naming
    /// existing bodies and joints.
    pub fn validate(&self) -> Result<(), DataError> {
        if self.format != "pantowatch-pantograph/1" {
            return Err(invalid(
                "format",
                format!("expected `pantowatch-pantograph/1`, got `{}`", self.format),
            ));
        }
        positive("gravity_m_s2", self.gravity_m_s2)?;
        if let Some(fp) = &self.fleet_prior_data {
            positive("fleet_prior.floor_relative_sd", fp.floor_relative_sd)?;
            positive("fleet_prior.min_relative_sd", fp.min_relative_sd)?;
            positive(
                "fleet_prior.version_tolerance_relative",
                fp.version_tolerance_relative,
            )?;
            positive("fleet_prior.fit_sd_scale", fp.fit_sd_scale)?;
        }
        if let Some(sf) = &self.static_force {
            let [a, b] = sf.working_height_m;
            positive("static_force.working_height_m", a)?;
            if !(b.is_finite() && b > a) {
                return Err(invalid(
                    "static_force.working_height_m",
                    "must be [lowest, highest] with highest > lowest",
                ));
            }
            positive("static_force.height_step_m", sf.height_step_m)?;
            if (b - a) / sf.height_step_m > 1000.0 {
                return Err(invalid(
                    "static_force.height_step_m",
                    "more than 1000 heights",
                ));
            }
            let [[h0, f0], [h1, f1]] = sf.nominal_force_points;
            for v in [h0, f0, h1, f1] {
                positive("static_force.nominal_force_points", v)?;
            }
            if h0 == h1 {
                return Err(invalid(
                    "static_force.nominal_force_points",
                    "the two heights must differ",
                ));
            }
            positive("static_force.tolerance_n", sf.tolerance_n)?;
            if sf.min_points_per_branch < 2 {
                return Err(invalid(
                    "static_force.min_points_per_branch",
                    "must be at least 2",
                ));
            }
            let [r0, r1] = sf.gauge_resolution_range_n;
            positive("static_force.gauge_resolution_range_n", r0)?;
            if !(r1.is_finite() && r1 > r0) {
                return Err(invalid(
                    "static_force.gauge_resolution_range_n",
                    "must be [smallest, largest] with largest > smallest",
                ));
            }
            positive("static_force.gauge_noise_n", sf.gauge_noise_n)?;
            let [g0, g1] = sf.gauge_reading_interval_s;
            positive("static_force.gauge_reading_interval_s", g0)?;
            if !(g1.is_finite() && g1 > g0) {
                return Err(invalid(
                    "static_force.gauge_reading_interval_s",
                    "must be [shortest, longest] with longest > shortest",
                ));
            }
            positive(
                "static_force.gauge_sim_resolution_n",
                sf.gauge_sim_resolution_n,
            )?;
            positive(
                "static_force.max_raise_lower_difference_n",
                sf.max_raise_lower_difference_n,
            )?;
        }
        if let Some(l) = &self.rig_limits_data {
            l.validate()?;
        }
        for (name, b) in &self.bodies {
            positive(&format!("bodies.{name}.mass_kg"), b.mass_kg)?;
            if let Some(i) = b.inertia_axis_kgm2 {
                positive(&format!("bodies.{name}.inertia_axis_kgm2"), i)?;
                let d = b.com_distance_m.unwrap_or(0.0);
                non_negative(&format!("bodies.{name}.com_distance_m"), d)?;
                // Parallel-axis theorem: I_axis = I_cm + m d^2 >= m d^2.
                if i < b.mass_kg * d * d {
                    return Err(invalid(
                        format!("bodies.{name}.inertia_axis_kgm2"),
                        format!(
                            "{i} kg·m² is below m·d² = {} (parallel-axis theorem)",
                            b.mass_kg * d * d
                        ),
                    ));
                }
            }
        }
        for (name, j) in &self.joints {
            non_negative(&format!("joints.{name}.dry_mu"), j.dry_mu)?;
            match j.kind {
                JointKind::Revolute => {
                    let v = j.viscous_nms_per_rad.ok_or_else(|| {
                        invalid(
                            format!("joints.{name}.viscous_nms_per_rad"),
                            "required for a revolute joint",
                        )
                    })?;
                    non_negative(&format!("joints.{name}.viscous_nms_per_rad"), v)?;
                    let r = j.pin_radius_m.ok_or_else(|| {
                        invalid(
                            format!("joints.{name}.pin_radius_m"),
                            "required for a revolute joint",
                        )
                    })?;
                    positive(&format!("joints.{name}.pin_radius_m"), r)?;
                }
                JointKind::Prismatic => {
                    let v = j.viscous_ns_per_m.ok_or_else(|| {
                        invalid(
                            format!("joints.{name}.viscous_ns_per_m"),
                            "required for a prismatic joint",
                        )
                    })?;
                    non_negative(&format!("joints.{name}.viscous_ns_per_m"), v)?;
                    let f = j.normal_force_n.ok_or_else(|| {
                        invalid(
                            format!("joints.{name}.normal_force_n"),
                            "required for a prismatic joint",
                        )
                    })?;
                    positive(&format!("joints.{name}.normal_force_n"), f)?;
                }
            }
        }
        for (name, r) in &self.rigs {
            let j = self
                .joints
                .get(name)
                .ok_or_else(|| invalid(format!("rigs.{name}"), "no joint of that name"))?;
            if j.kind != JointKind::Revolute {
                return Err(invalid(
                    format!("rigs.{name}"),
                    "pendulum rigs are for revolute joints",
                ));
            }
            let b = self.bodies.get(&r.body).ok_or_else(|| {
                invalid(format!("rigs.{name}.body"), format!("no body `{}`", r.body))
            })?;
            if b.inertia_axis_kgm2.is_none() {
                return Err(invalid(
                    format!("bodies.{}.inertia_axis_kgm2", r.body),
                    "required for a pendulum rig body",
                ));
            }
            if !r.release_deg.is_finite() {
                return Err(invalid(
                    format!("rigs.{name}.release_deg"),
                    "must be finite",
                ));
            }
            for (k, a) in r.attachments.iter().enumerate() {
                let f = format!("rigs.{name}.attachments[{k}]");
                match a {
                    Attachment::Point {
                        mass_kg,
                        distance_m,
                    } => {
                        positive(&format!("{f}.mass_kg"), *mass_kg)?;
                        non_negative(&format!("{f}.distance_m"), *distance_m)?;
                    }
                    Attachment::Rod { mass_kg, length_m } => {
                        positive(&format!("{f}.mass_kg"), *mass_kg)?;
                        positive(&format!("{f}.length_m"), *length_m)?;
                    }
                }
            }
        }
        if let Some(tp) = &self.test_plan {
            positive(
                "test_plan.fleet_wear_sd_per_year",
                tp.fleet_wear_sd_per_year,
            )?;
            positive(
                "test_plan.unmeasured_relative_sd",
                tp.unmeasured_relative_sd,
            )?;
            for (j, d) in &tp.max_evidence_age_days {
                if !self.joints.contains_key(j) {
                    return Err(invalid(
                        "test_plan.max_evidence_age_days",
                        format!("no joint `{j}`"),
                    ));
                }
                positive("test_plan.max_evidence_age_days", *d)?;
            }
        }
        let s = &self.slider;
        let j = self
            .joints
            .get(&s.joint)
            .ok_or_else(|| invalid("slider.joint", format!("no joint `{}`", s.joint)))?;
        if j.kind != JointKind::Prismatic {
            return Err(invalid("slider.joint", "must be a prismatic joint"));
        }
        positive("slider.moving_mass_kg", s.moving_mass_kg)?;
        non_negative(
            "slider.spring_stiffness_n_per_mm",
            s.spring_stiffness_n_per_mm,
        )?;
        Ok(())
    }

    /// Table 4 data of a joint, by the paper's name (`J1` … `J8`, `J2'`).
    pub fn joint(&self, name: &str) -> Option<&JointData> {
        self.joints.get(name)
    }
}

/// The 160EC data, parsed and validated once.
///
/// # Panics
/// Never on a released build: the compiled-in file is checked by the `builtin_data_is_valid` test.
pub fn builtin_160ec() -> &'static PantographType {
    static DATA: OnceLock<PantographType> = OnceLock::new();
    DATA.get_or_init(|| {
        PantographType::from_toml(PANTOGRAPH_160EC_TOML).expect("models/data/160ec.toml is valid")
    })
}

/// Look up a compiled-in pantograph type by model name (`160EC`).
pub fn builtin(model: &str) -> Option<&'static PantographType> {
    match model {
        "160EC" => Some(builtin_160ec()),
        _ => None,
    }
}

#[cfg(test)]
mod tests;

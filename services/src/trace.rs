//! The trace document (`pantograph-trace/1`, `../shared/contract/TRACE_FORMAT.md`): parsed,
//! checked against every rule of the contract, and turned into the models' test description.
//!
//! Every rejection names the offending field (`channels.alpha_deg[17]`, `test.joint`, …).

use std::collections::BTreeMap;

use pantowatch_models::data::{self, Attachment, PantographType};
use pantowatch_models::identify::JointTest;
use pantowatch_models::lift::gauge::GaugeRecord;
use pantowatch_models::lift::report::LiftChannels;
use pantowatch_models::lift::vec2::V2;
use pantowatch_models::quadrangle::model::{PointMass, QBody};
use pantowatch_models::quadrangle::report::{QuadChannels, QuadRig};
use pantowatch_models::rig::BodySpec;
use pantowatch_models::testspec::{Baseline, PendulumSpec, SliderSpec};
use serde_json::{Map, Value};

use crate::ids::MAX_STRING;

/// The format tag every document carries.
pub const FORMAT: &str = "pantograph-trace/1";
/// Longest accepted channel, samples (a 30 min recording at 500 Hz is 900 000).
pub const MAX_SAMPLES: usize = 2_000_000;
/// The lower-quadrangle swing kind (docs/TRACE_FORMAT.md, paper Fig 12).
pub const QUADRANGLE_SWING: &str = "quadrangle_swing";
/// The force-gauge measurement of the static contact force (issue 20, docs/TRACE_FORMAT.md).
pub const STATIC_FORCE: &str = "static_force";
/// Most channels in one document.
pub const MAX_CHANNELS: usize = 32;

/// A rule of the contract that the document breaks.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("`{field}`: {message}")]
pub struct TraceError {
    pub field: String,
    pub message: String,
}

fn bad(field: impl Into<String>, message: impl Into<String>) -> TraceError {
    TraceError {
        field: field.into(),
        message: message.into(),
    }
}

/// The test kinds of the contract.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    Pendulum,
    Slider,
    Lift,
    /// The lower articulated quadrangle swinging on an inclined frame (paper, Fig 12).
    QuadrangleSwing,
    /// A force gauge's readings of the static contact force, raising then lowering (issue 20).
    StaticForce,
}

impl Kind {
    pub fn as_str(self) -> &'static str {
        match self {
            Kind::Pendulum => "pendulum",
            Kind::Slider => "slider",
            Kind::Lift => "lift",
            Kind::QuadrangleSwing => QUADRANGLE_SWING,
            Kind::StaticForce => STATIC_FORCE,
        }
    }
    /// Every kind of the contract, in the order the documentation lists them.
    pub const ALL: [Kind; 5] = [
        Kind::Pendulum,
        Kind::Slider,
        Kind::Lift,
        Kind::QuadrangleSwing,
        Kind::StaticForce,
    ];
    /// The kind named `name` (`test.kind`, the stored `kind` column).
    pub fn parse(name: &str) -> Option<Kind> {
        Kind::ALL.into_iter().find(|k| k.as_str() == name)
    }
    /// Channels the kind needs, and optional ones.
    pub fn channels(self) -> (&'static [&'static str], &'static [&'static str]) {
        match self {
            Kind::Pendulum => (&["alpha_deg"], &[]),
            Kind::Slider => (&["h_mm"], &["F_N"]),
            Kind::Lift => (&["H_m", "T_Nm", "Fs_N"], &["Fm_N"]),
            Kind::QuadrangleSwing => (&["alpha_deg", "beta_deg"], &[]),
            Kind::StaticForce => (&["H_m", "F_N"], &[]),
        }
    }
}

/// The readings of a `static_force` test ([`TraceDoc::static_force_channels`]): the first
/// `raise_len` readings raise the strip (the last of them the highest), the rest lower it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GaugeChannels<'a> {
    pub t_s: &'a [f64],
    /// Strip height above the base frame, m.
    pub strip_height_m: &'a [f64],
    /// The gauge's force on the strip, N, positive down.
    pub force_n: &'a [f64],
    /// The gauge's stated resolution, N.
    pub gauge_resolution_n: f64,
    /// Readings of the raising branch (the highest reading is its last).
    pub raise_len: usize,
}

impl GaugeChannels<'_> {
    /// (H m, F N) of the raising branch, then of the lowering branch.
    pub fn branches(&self) -> [Vec<(f64, f64)>; 2] {
        let pairs = |r: std::ops::Range<usize>| -> Vec<(f64, f64)> {
            r.filter_map(|i| Some((*self.strip_height_m.get(i)?, *self.force_n.get(i)?)))
                .collect()
        };
        let n = self.strip_height_m.len().min(self.force_n.len());
        let k = self.raise_len.min(n);
        [pairs(0..k), pairs(k..n)]
    }
}

/// A validated trace document.
#[derive(Debug, Clone, PartialEq)]
pub struct TraceDoc {
    pub trace_id: Option<String>,
    pub vehicle_id: String,
    pub pantograph_model: String,
    pub pantograph_serial: Option<String>,
    pub recorded_at: String,
    pub kind: Kind,
    pub joint: Option<String>,
    /// The document's `test` object, verbatim.
    pub test: Value,
    /// `t_s` first, then the others in name order.
    pub channels: Vec<(String, Vec<f64>)>,
}

fn obj<'a>(v: &'a Value, field: &str) -> Result<&'a Map<String, Value>, TraceError> {
    v.as_object().ok_or_else(|| bad(field, "must be an object"))
}

fn string(
    m: &Map<String, Value>,
    key: &str,
    field: &str,
    required: bool,
) -> Result<Option<String>, TraceError> {
    match m.get(key) {
        None | Some(Value::Null) if !required => Ok(None),
        None | Some(Value::Null) => Err(bad(field, "is required")),
        Some(Value::String(s)) if s.trim().is_empty() => Err(bad(field, "must not be empty")),
        Some(Value::String(s)) if s.chars().count() > MAX_STRING => {
            Err(bad(field, format!("longer than {MAX_STRING} characters")))
        }
        Some(Value::String(s)) if s.chars().any(char::is_control) => {
            Err(bad(field, "contains control characters"))
        }
        Some(Value::String(s)) => Ok(Some(s.clone())),
        Some(_) => Err(bad(field, "must be a string")),
    }
}

fn number(m: &Map<String, Value>, key: &str, field: &str) -> Result<Option<f64>, TraceError> {
    match m.get(key) {
        None | Some(Value::Null) => Ok(None),
        Some(Value::Number(n)) => match n.as_f64() {
            Some(x) if x.is_finite() => Ok(Some(x)),
            _ => Err(bad(field, "must be a finite number")),
        },
        Some(_) => Err(bad(field, "must be a number")),
    }
}

fn only_keys(m: &Map<String, Value>, allowed: &[&str], field: &str) -> Result<(), TraceError> {
    for k in m.keys() {
        if !allowed.contains(&k.as_str()) {
            let at = if field.is_empty() {
                k.clone()
            } else {
                format!("{field}.{k}")
            };
            return Err(bad(
                at,
                format!("unknown key (allowed: {})", allowed.join(", ")),
            ));
        }
    }
    Ok(())
}

/// Why a `recorded_at` is refused: not RFC 3339, or outside the years every backend stores.
///
/// RFC 3339 (`YYYY-MM-DDTHH:MM:SS[.frac](Z|±HH:MM)`, calendar-valid fields) as chrono parses
/// it, and then — after the offset is applied, in UTC — a year in 1…9999: SQLite keeps dates as
/// RFC 3339 text, whose four-digit year a `9999-12-31T23:59:59-23:59` would push to 10000, and
/// such a row made every later read of its vehicle fail (issue 18). Year 0 is refused too.
pub fn rfc3339_problem(s: &str) -> Option<String> {
    // chrono accepts a space or `t` for `T` and a lowercase `z`, as RFC 3339 § 5.6 allows.
    let parsed = chrono::DateTime::parse_from_rfc3339(s).ok();
    match parsed.map(|d| d.with_timezone(&chrono::Utc)) {
        None => Some(format!(
            "`{s}` is not an RFC 3339 date-time (e.g. 2026-03-02T07:15:00Z)"
        )),
        Some(utc) if !(1..=9999).contains(&chrono::Datelike::year(&utc)) => Some(format!(
            "`{s}` is year {} in UTC: dates must lie in the years 1 to 9999",
            chrono::Datelike::year(&utc)
        )),
        Some(_) => None,
    }
}

/// RFC 3339 date-time within the stored years ([`rfc3339_problem`] finds nothing).
pub fn check_rfc3339(s: &str) -> bool {
    rfc3339_problem(s).is_none()
}

/// The longest gap a lift record may have, in median sampling intervals: a logger that drops
/// samples leaves the model's inputs undefined across the gap (they would be interpolated
/// through it), so a lift with a gap over 5 intervals is refused naming the first sample after
/// it. 5 intervals: 10 ms at 500 Hz, a fraction of the head's ≈ 0.2 s bounce period.
pub const LIFT_MAX_GAP_INTERVALS: f64 = 5.0;

/// A lift's `t_s` has no gap longer than [`LIFT_MAX_GAP_INTERVALS`] median intervals.
fn lift_gaps(t_s: &[f64]) -> Result<(), TraceError> {
    if t_s.len() < 3 {
        return Ok(());
    }
    let mut dt: Vec<f64> = t_s.windows(2).map(|w| w[1] - w[0]).collect();
    let (_, median, _) = dt.select_nth_unstable_by(t_s.len() / 2 - 1, f64::total_cmp);
    let median = *median;
    match t_s
        .windows(2)
        .position(|w| w[1] - w[0] > LIFT_MAX_GAP_INTERVALS * median)
    {
        None => Ok(()),
        Some(i) => Err(bad(
            format!("channels.t_s[{}]", i + 1),
            format!(
                "a gap of {:.6} s before this sample, more than {LIFT_MAX_GAP_INTERVALS} × the median interval {median:.6} s: samples are missing",
                t_s[i + 1] - t_s[i]
            ),
        )),
    }
}

fn channel(v: &Value, field: &str) -> Result<Vec<f64>, TraceError> {
    let a = v
        .as_array()
        .ok_or_else(|| bad(field, "must be an array of numbers"))?;
    if a.len() > MAX_SAMPLES {
        return Err(bad(
            field,
            format!("{} samples, more than the limit of {MAX_SAMPLES}", a.len()),
        ));
    }
    a.iter()
        .enumerate()
        .map(|(i, x)| match x.as_f64() {
            Some(f) if f.is_finite() => Ok(f),
            Some(_) => Err(bad(format!("{field}[{i}]"), "must be finite")),
            None => Err(bad(format!("{field}[{i}]"), "must be a number")),
        })
        .collect()
}

impl TraceDoc {
    /// Parse and validate a document from JSON bytes.
    pub fn from_json(bytes: &[u8]) -> Result<Self, TraceError> {
        let v: Value = serde_json::from_slice(bytes)
            .map_err(|e| bad("body", format!("not valid JSON: {e}")))?;
        if let Ok(Some(key)) = crate::json_keys::first_duplicate_key(bytes) {
            return Err(bad(
                key.clone(),
                format!("`{key}` appears twice in its object"),
            ));
        }
        Self::from_value(&v)
    }

    /// Validate a parsed JSON document against the contract.
    pub fn from_value(v: &Value) -> Result<Self, TraceError> {
        let root = obj(v, "body")?;
        only_keys(
            root,
            &[
                "format",
                "trace_id",
                "vehicle_id",
                "pantograph",
                "recorded_at",
                "test",
                "channels",
            ],
            "",
        )?;
        match string(root, "format", "format", true)?.as_deref() {
            Some(FORMAT) => {}
            Some(other) => {
                return Err(bad("format", format!("expected `{FORMAT}`, got `{other}`")));
            }
            None => unreachable!("required"),
        }
        // Ids by the rules of `ids` (issue 18): stored in NFC, no invisible characters.
        let id_rule = |e: crate::ids::IdError| bad(e.field, e.message);
        let trace_id = string(root, "trace_id", "trace_id", false)?
            .map(|id| crate::ids::check_trace_id("trace_id", &id).map_err(id_rule))
            .transpose()?;
        let vehicle_id = string(root, "vehicle_id", "vehicle_id", true)?.unwrap_or_default();
        let vehicle_id = crate::ids::normalise_text("vehicle_id", &vehicle_id).map_err(id_rule)?;
        let panto = obj(
            root.get("pantograph")
                .ok_or_else(|| bad("pantograph", "is required"))?,
            "pantograph",
        )?;
        only_keys(panto, &["model", "serial"], "pantograph")?;
        let pantograph_model =
            string(panto, "model", "pantograph.model", true)?.unwrap_or_default();
        let pantograph_serial = string(panto, "serial", "pantograph.serial", false)?
            .map(|v| crate::ids::normalise_text("pantograph.serial", &v).map_err(id_rule))
            .transpose()?;
        let recorded_at = string(root, "recorded_at", "recorded_at", true)?.unwrap_or_default();
        if let Some(why) = rfc3339_problem(&recorded_at) {
            return Err(bad("recorded_at", why));
        }
        let test_v = root.get("test").ok_or_else(|| bad("test", "is required"))?;
        let test = obj(test_v, "test")?;
        only_keys(
            test,
            &[
                "kind",
                "joint",
                "rig",
                "protocol",
                "release_t_s",
                "gauge_resolution_n",
            ],
            "test",
        )?;
        let kind = match string(test, "kind", "test.kind", true)?.as_deref() {
            Some(k) => Kind::parse(k).ok_or_else(|| {
                let all: Vec<&str> = Kind::ALL.iter().map(|k| k.as_str()).collect();
                bad(
                    "test.kind",
                    format!("unknown kind `{k}` ({})", all.join(", ")),
                )
            })?,
            None => unreachable!("required"),
        };
        if kind != Kind::Pendulum && test.get("release_t_s").is_some_and(|v| !v.is_null()) {
            return Err(bad(
                "test.release_t_s",
                "only a pendulum test states its release",
            ));
        }
        if kind != Kind::StaticForce && test.contains_key("gauge_resolution_n") {
            return Err(bad(
                "test.gauge_resolution_n",
                "only a static_force test states a gauge resolution",
            ));
        }
        let joint = string(test, "joint", "test.joint", false)?;
        if let Some(r) = test.get("rig")
            && !r.is_object()
        {
            return Err(bad("test.rig", "must be an object"));
        }
        let chans = obj(
            root.get("channels")
                .ok_or_else(|| bad("channels", "is required"))?,
            "channels",
        )?;
        if chans.len() > MAX_CHANNELS {
            return Err(bad(
                "channels",
                format!("{} channels, more than {MAX_CHANNELS}", chans.len()),
            ));
        }
        let t = channel(
            chans
                .get("t_s")
                .ok_or_else(|| bad("channels.t_s", "is required"))?,
            "channels.t_s",
        )?;
        if t.len() < 2 {
            return Err(bad("channels.t_s", "needs at least 2 samples"));
        }
        if let Some(i) = t.windows(2).position(|w| w[1] <= w[0]) {
            return Err(bad(
                format!("channels.t_s[{}]", i + 1),
                format!(
                    "time must be strictly increasing ({} after {})",
                    t[i + 1],
                    t[i]
                ),
            ));
        }
        // The clock within the type's plausible sampling (issue 18: `t_s = [0, 1e300]` was
        // accepted): times, intervals and the record's length, `[rig_limits]` in models/data.
        // A force gauge is read by hand: its readings' spacing has its own rule
        // (`[static_force] gauge_reading_interval_s`).
        let type_data = data::builtin(&pantograph_model).unwrap_or_else(data::builtin_160ec);
        let limits = type_data.rig_limits();
        match (&kind, type_data.static_force.as_ref()) {
            (Kind::StaticForce, Some(sf)) => limits.check_sampling_within(
                &t,
                sf.gauge_reading_interval_s,
                "static_force.gauge_reading_interval_s",
            ),
            _ => limits.check_sampling(&t),
        }
        .map_err(|(field, message)| bad(field, message))?;
        let (needed, optional) = kind.channels();
        for name in needed {
            if !chans.contains_key(*name) {
                return Err(bad(
                    format!("channels.{name}"),
                    format!("is required for a {} test", kind.as_str()),
                ));
            }
        }
        let mut channels = vec![("t_s".to_string(), t)];
        for (name, v) in chans {
            if name == "t_s" {
                continue;
            }
            if name.is_empty()
                || name.len() > 64
                || !name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
            {
                return Err(bad(
                    "channels",
                    format!(
                        "channel name `{}` must be 1-64 letters, digits or _",
                        name.chars().take(64).collect::<String>()
                    ),
                ));
            }
            let field = format!("channels.{name}");
            let x = channel(v, &field)?;
            if x.len() != channels[0].1.len() {
                return Err(bad(
                    field,
                    format!(
                        "has {} samples but t_s has {}",
                        x.len(),
                        channels[0].1.len()
                    ),
                ));
            }
            let _ = optional;
            channels.push((name.clone(), x));
        }
        let doc = TraceDoc {
            trace_id,
            vehicle_id,
            pantograph_model,
            pantograph_serial,
            recorded_at,
            kind,
            joint,
            test: test_v.clone(),
            channels,
        };
        // Check the rig now, so a document the model cannot use is rejected at the door.
        match doc.kind {
            Kind::Lift => {
                doc.lift_channels()?;
            }
            Kind::QuadrangleSwing => {
                doc.quadrangle_channels()?;
            }
            Kind::StaticForce => {
                doc.static_force_channels()?;
            }
            Kind::Pendulum | Kind::Slider => {
                doc.joint_test()?;
            }
        }
        Ok(doc)
    }

    pub fn channel(&self, name: &str) -> Option<&[f64]> {
        self.channels
            .iter()
            .find(|(n, _)| n == name)
            .map(|(_, v)| v.as_slice())
    }

    /// The channels of a `lift` test for the complete-pantograph model (built-in 160EC
    /// geometry, `../shared/reference/160ec.toml`).
    ///
    /// The contract allows `test.rig` overrides of that geometry; none is supported yet, so a
    /// non-empty `test.rig` is refused rather than silently ignored.
    pub fn lift_channels(&self) -> Result<LiftChannels<'_>, TraceError> {
        if self.kind != Kind::Lift {
            return Err(bad("test.kind", "not a lift test"));
        }
        if self.pantograph_model != "160EC" {
            return Err(bad(
                "pantograph.model",
                format!(
                    "lift tests are fitted with the 160EC geometry only, got `{}`",
                    self.pantograph_model
                ),
            ));
        }
        if let Some(j) = &self.joint {
            return Err(bad(
                "test.joint",
                format!("a lift test is of the whole pantograph, got joint `{j}`"),
            ));
        }
        if let Some((k, _)) = self
            .test
            .get("rig")
            .and_then(Value::as_object)
            .and_then(|r| r.iter().next())
        {
            return Err(bad(
                format!("test.rig.{k}"),
                "overrides of the 160EC lift geometry are not supported yet (send an empty rig)",
            ));
        }
        let get = |name: &str| self.channel(name).unwrap_or_default();
        lift_gaps(get("t_s"))?;
        self.lift_protocol(get("t_s"))?;
        let channels = LiftChannels {
            t_s: get("t_s"),
            strip_height_m: get("H_m"),
            torque_nm: get("T_Nm"),
            fs_n: get("Fs_N"),
            fm_n: get("Fm_N"),
        };
        // T within the drive's range, H within the working heights, Fs and Fm within the
        // strip loads the drive can hold (models' data files).
        channels
            .check_limits()
            .map_err(|(field, message)| bad(field, message))?;
        Ok(channels)
    }

    /// The drive protocol a lift states it ran (`test.protocol`, optional: as `pantowatch
    /// design-test` writes it), checked against the stand's limits
    /// (`lift::design::ProtocolLimits::stand`, issue 15 point 7): a field outside them, or a
    /// record longer than the limit's duration, is refused naming it. `None`: not stated.
    pub fn lift_protocol(
        &self,
        t_s: &[f64],
    ) -> Result<Option<pantowatch_models::lift::protocol::LiftProtocol>, TraceError> {
        use pantowatch_models::lift::design::ProtocolLimits;
        let Some(v) = self.test.get("protocol") else {
            return Ok(None);
        };
        let p: pantowatch_models::lift::protocol::LiftProtocol =
            serde_json::from_value(v.clone()).map_err(|e| bad("test.protocol", e.to_string()))?;
        let lim = ProtocolLimits::stand(pantowatch_models::lift::geometry::builtin_160ec());
        lim.check(&p)
            .map_err(|e| bad(format!("test.protocol.{}", e.field), e.message))?;
        if let (Some(first), Some(last)) = (t_s.first(), t_s.last())
            && last - first > lim.duration_max_s
        {
            return Err(bad(
                "channels.t_s",
                format!(
                    "the record lasts {:.1} s, over the stated protocol limit of {} s",
                    last - first,
                    lim.duration_max_s
                ),
            ));
        }
        Ok(Some(p))
    }

    /// The channels and stand of a `quadrangle_swing` test for the lower-quadrangle model
    /// (built-in 160EC geometry). `test.rig`: `incline_deg` (default 70), `gravity_m_s2`
    /// (default 9.81), `attachments` (point masses fixed to a body, at body coordinates).
    pub fn quadrangle_channels(&self) -> Result<(QuadChannels<'_>, QuadRig), TraceError> {
        if self.kind != Kind::QuadrangleSwing {
            return Err(bad("test.kind", "not a quadrangle_swing test"));
        }
        if self.pantograph_model != "160EC" {
            return Err(bad(
                "pantograph.model",
                format!(
                    "quadrangle swings are fitted with the 160EC geometry only, got `{}`",
                    self.pantograph_model
                ),
            ));
        }
        if let Some(j) = &self.joint {
            return Err(bad(
                "test.joint",
                format!(
                    "a quadrangle swing is of joints J1, J2, J2', J3 together, got joint `{j}`"
                ),
            ));
        }
        let rig = self
            .test
            .get("rig")
            .and_then(Value::as_object)
            .cloned()
            .unwrap_or_default();
        only_keys(
            &rig,
            &["incline_deg", "gravity_m_s2", "attachments"],
            "test.rig",
        )?;
        let mut q = QuadRig::default();
        if let Some(v) = number(&rig, "incline_deg", "test.rig.incline_deg")? {
            q.incline_deg = v;
        }
        if let Some(v) = number(&rig, "gravity_m_s2", "test.rig.gravity_m_s2")? {
            q.gravity_m_s2 = v;
        }
        match rig.get("attachments") {
            None | Some(Value::Null) => {}
            Some(a) => {
                let arr = a
                    .as_array()
                    .ok_or_else(|| bad("test.rig.attachments", "must be an array"))?;
                if arr.len() > 16 {
                    return Err(bad("test.rig.attachments", "more than 16 attachments"));
                }
                for (i, x) in arr.iter().enumerate() {
                    let f = format!("test.rig.attachments[{i}]");
                    let m = obj(x, &f)?;
                    only_keys(m, &["kind", "mass_kg", "body", "position_m"], &f)?;
                    if m.get("kind").and_then(Value::as_str) != Some("point") {
                        return Err(bad(format!("{f}.kind"), "must be `point`"));
                    }
                    let mass_kg = number(m, "mass_kg", &format!("{f}.mass_kg"))?
                        .ok_or_else(|| bad(format!("{f}.mass_kg"), "is required"))?;
                    let body = match m.get("body").and_then(Value::as_str) {
                        Some(k) => QBody::named(k),
                        None => None,
                    }
                    .ok_or_else(|| {
                        bad(
                            format!("{f}.body"),
                            "must be `lower_arm`, `coupling_rod` or `upper_arm`",
                        )
                    })?;
                    let pos = m
                        .get("position_m")
                        .and_then(Value::as_array)
                        .filter(|a| a.len() == 2)
                        .and_then(|a| Some([a[0].as_f64()?, a[1].as_f64()?]))
                        .ok_or_else(|| {
                            bad(format!("{f}.position_m"), "must be two numbers [x, y], m")
                        })?;
                    q.attachments.push(PointMass {
                        body,
                        mass_kg,
                        position_m: V2::from_array(pos),
                    });
                }
            }
        }
        q.model().map_err(|e| bad(e.field, e.message))?;
        let get = |name: &str| self.channel(name).unwrap_or_default();
        let channels = QuadChannels {
            t_s: get("t_s"),
            alpha_deg: get("alpha_deg"),
            beta_deg: get("beta_deg"),
        };
        channels
            .check_limits()
            .map_err(|e| bad(e.field, e.message))?;
        Ok((channels, q))
    }

    /// The readings of a `static_force` test (a force gauge on the strip, issue 20), checked
    /// by the models' record (`lift::gauge::GaugeRecord`) against the type's `[static_force]`
    /// data: `test.gauge_resolution_n` stated and within `gauge_resolution_range_n`, every `H_m`
    /// within `working_height_m`, every `F_N` within `[rig_limits] lift_strip_force_n`, a raising
    /// branch (H never decreasing up to the first highest reading) then a lowering branch (H
    /// never increasing after it), each of at least `min_points_per_branch` readings.
    pub fn static_force_channels(&self) -> Result<GaugeChannels<'_>, TraceError> {
        if self.kind != Kind::StaticForce {
            return Err(bad("test.kind", "not a static_force test"));
        }
        let sf = self
            .pantograph_data()
            .and_then(|d| d.static_force.as_ref())
            .filter(|_| self.pantograph_model == "160EC")
            .ok_or_else(|| {
                bad(
                    "pantograph.model",
                    format!(
                        "static_force tests are fitted with the 160EC geometry and its \
                         [static_force] data only, got `{}`",
                        self.pantograph_model
                    ),
                )
            })?;
        if let Some(j) = &self.joint {
            return Err(bad(
                "test.joint",
                format!("a static_force test is of the whole pantograph, got joint `{j}`"),
            ));
        }
        if let Some((k, _)) = self
            .test
            .get("rig")
            .and_then(Value::as_object)
            .and_then(|r| r.iter().next())
        {
            return Err(bad(
                format!("test.rig.{k}"),
                "a static_force test has no rig to state (send an empty rig or none)",
            ));
        }
        if self.test.get("protocol").is_some_and(|v| !v.is_null()) {
            return Err(bad(
                "test.protocol",
                "only a lift test states a drive protocol",
            ));
        }
        const RES: &str = "test.gauge_resolution_n";
        let test = self.test.as_object().cloned().unwrap_or_default();
        let gauge_resolution_n = match number(&test, "gauge_resolution_n", RES)? {
            None => {
                return Err(bad(
                    RES,
                    "is required for a static_force test: the gauge's stated resolution, N",
                ));
            }
            Some(r) if r <= 0.0 => return Err(bad(RES, format!("{r} N: must be > 0"))),
            Some(r) => r,
        };
        let get = |name: &str| self.channel(name).unwrap_or_default();
        let (t_s, h, f) = (get("t_s"), get("H_m"), get("F_N"));
        // The record's rules are the models' (`lift::gauge::GaugeRecord`, the type's
        // `[static_force]`): the resolution's span, every height within the working range, both
        // branches, each never turning back and of `min_points_per_branch` readings, every
        // force within the strip loads a drive can hold. One rule set for upload and fit.
        let record = GaugeRecord::with_limits(h.to_vec(), f.to_vec(), gauge_resolution_n, sf)
            .map_err(|e| {
                let field = e.field_path().unwrap_or_else(|| "channels".to_owned());
                let text = e.to_string();
                let message = text
                    .strip_prefix(&format!("{field}: "))
                    .unwrap_or(&text)
                    .to_owned();
                bad(field, message)
            })?;
        Ok(GaugeChannels {
            t_s,
            strip_height_m: h,
            force_n: f,
            gauge_resolution_n,
            raise_len: record.turn + 1,
        })
    }

    /// The pantograph type's data when compiled in (`160EC`); `None` for other models.
    pub fn pantograph_data(&self) -> Option<&'static PantographType> {
        data::builtin(&self.pantograph_model)
    }

    /// `test.release_t_s` (issue 17, point 2): when the body was let go, s, on the trace's
    /// clock; only a pendulum states it. It must lie within `t` and leave at least 20 samples of
    /// free motion (what a fit needs).
    fn release_t_s(&self, t: &[f64]) -> Result<Option<f64>, TraceError> {
        const FIELD: &str = "test.release_t_s";
        let Some(test) = self.test.as_object() else {
            return Ok(None);
        };
        let Some(r) = number(test, "release_t_s", FIELD)? else {
            return Ok(None);
        };
        match pantowatch_models::identify::release::stated_release(t, r, 20) {
            Some(_) => Ok(Some(r)),
            None => Err(bad(
                FIELD,
                format!(
                    "{r} s lies outside the trace ({} to {} s) or leaves fewer than 20 samples \
                     after it",
                    t.first().copied().unwrap_or(f64::NAN),
                    t.last().copied().unwrap_or(f64::NAN)
                ),
            )),
        }
    }

    /// The models' single-joint test (pendulum or slider) with its Table 4 baseline.
    pub fn joint_test(&self) -> Result<(JointTest, Baseline), TraceError> {
        let rig = self
            .test
            .get("rig")
            .and_then(Value::as_object)
            .cloned()
            .unwrap_or_default();
        let t = self.channel("t_s").unwrap_or_default().to_vec();
        let data = self.pantograph_data();
        let rig_err = |e: pantowatch_models::rig::RigError| bad(e.field, e.message);
        match self.kind {
            Kind::Pendulum => {
                let joint = self
                    .joint
                    .clone()
                    .ok_or_else(|| bad("test.joint", "is required for a pendulum test"))?;
                const JOINTS: [&str; 9] =
                    ["J1", "J2", "J2'", "J3", "J4", "J5", "J6", "J7", "custom"];
                if !JOINTS.contains(&joint.as_str()) {
                    return Err(bad(
                        "test.joint",
                        format!("unknown joint `{joint}` (J1 J2 J2' J3 J4 J5 J6 J7 custom)"),
                    ));
                }
                only_keys(
                    &rig,
                    &[
                        "body",
                        "attachments",
                        "pin_radius_m",
                        "gravity_m_s2",
                        "initial_rate_deg_s",
                    ],
                    "test.rig",
                )?;
                let body = match rig.get("body") {
                    None | Some(Value::Null) => None,
                    Some(b) => {
                        let b = obj(b, "test.rig.body")?;
                        only_keys(
                            b,
                            &["mass_kg", "inertia_kgm2", "com_distance_m"],
                            "test.rig.body",
                        )?;
                        let get = |k: &str| {
                            number(b, k, &format!("test.rig.body.{k}"))?
                                .ok_or_else(|| bad(format!("test.rig.body.{k}"), "is required"))
                        };
                        Some(BodySpec {
                            mass_kg: get("mass_kg")?,
                            inertia_kgm2: get("inertia_kgm2")?,
                            com_distance_m: get("com_distance_m")?,
                        })
                    }
                };
                let attachments = match rig.get("attachments") {
                    None | Some(Value::Null) => None,
                    Some(a) => {
                        let arr = a
                            .as_array()
                            .ok_or_else(|| bad("test.rig.attachments", "must be an array"))?;
                        let mut out = Vec::new();
                        for (i, x) in arr.iter().enumerate() {
                            let f = format!("test.rig.attachments[{i}]");
                            let m = obj(x, &f)?;
                            let req = |k: &str| {
                                number(m, k, &format!("{f}.{k}"))?
                                    .ok_or_else(|| bad(format!("{f}.{k}"), "is required"))
                            };
                            out.push(match m.get("kind").and_then(Value::as_str) {
                                Some("point") => {
                                    only_keys(m, &["kind", "mass_kg", "distance_m"], &f)?;
                                    Attachment::Point {
                                        mass_kg: req("mass_kg")?,
                                        distance_m: req("distance_m")?,
                                    }
                                }
                                Some("rod") => {
                                    only_keys(m, &["kind", "mass_kg", "length_m"], &f)?;
                                    Attachment::Rod {
                                        mass_kg: req("mass_kg")?,
                                        length_m: req("length_m")?,
                                    }
                                }
                                _ => {
                                    return Err(bad(
                                        format!("{f}.kind"),
                                        "must be `point` or `rod`",
                                    ));
                                }
                            });
                        }
                        Some(out)
                    }
                };
                let spec = PendulumSpec {
                    joint,
                    body,
                    attachments,
                    pin_radius_m: number(&rig, "pin_radius_m", "test.rig.pin_radius_m")?,
                    gravity_m_s2: number(&rig, "gravity_m_s2", "test.rig.gravity_m_s2")?,
                    initial_rate_deg_s: number(
                        &rig,
                        "initial_rate_deg_s",
                        "test.rig.initial_rate_deg_s",
                    )?,
                };
                let y = self.channel("alpha_deg").unwrap_or_default().to_vec();
                let release_t_s = self.release_t_s(&t)?;
                spec.joint_test(data, t, y)
                    .map(|(test, baseline)| {
                        (
                            JointTest {
                                release_t_s,
                                ..test
                            },
                            baseline,
                        )
                    })
                    .map_err(rig_err)
            }
            Kind::Slider => {
                if let Some(j) = &self.joint
                    && j != "J8"
                    && j != "custom"
                {
                    return Err(bad(
                        "test.joint",
                        format!("a slider test is of joint J8 (or `custom`), got `{j}`"),
                    ));
                }
                only_keys(
                    &rig,
                    &[
                        "moving_mass_kg",
                        "springs",
                        "spring_stiffness_n_per_mm",
                        "normal_force_n",
                    ],
                    "test.rig",
                )?;
                // A whole number here; its span (`[rig_limits] springs`, 0 = none) is the
                // models' one rule, checked with the rest of the rig.
                let springs = match rig.get("springs") {
                    None | Some(Value::Null) => None,
                    Some(v) => Some(
                        v.as_u64()
                            .map(|n| u32::try_from(n).unwrap_or(u32::MAX))
                            .ok_or_else(|| {
                                bad(
                                    "test.rig.springs",
                                    "must be a whole number of springs (0 for none)",
                                )
                            })?,
                    ),
                };
                let spec = SliderSpec {
                    custom: self.joint.as_deref() == Some("custom"),
                    moving_mass_kg: number(&rig, "moving_mass_kg", "test.rig.moving_mass_kg")?,
                    springs,
                    spring_stiffness_n_per_mm: number(
                        &rig,
                        "spring_stiffness_n_per_mm",
                        "test.rig.spring_stiffness_n_per_mm",
                    )?,
                    normal_force_n: number(&rig, "normal_force_n", "test.rig.normal_force_n")?,
                };
                let y = self.channel("h_mm").unwrap_or_default().to_vec();
                let f = self.channel("F_N").map(<[f64]>::to_vec);
                spec.joint_test(data, t, y, f).map_err(rig_err)
            }
            Kind::Lift => Err(bad(
                "test.kind",
                "a lift test is of the whole pantograph: see `lift_channels`",
            )),
            Kind::QuadrangleSwing => Err(bad(
                "test.kind",
                "a quadrangle swing is of four joints together: see `quadrangle_channels`",
            )),
            Kind::StaticForce => Err(bad(
                "test.kind",
                "a static_force test is of the whole pantograph: see `static_force_channels`",
            )),
        }
    }

    /// The document as JSON (the contract's shape), channels in stored order.
    pub fn to_value(&self) -> Value {
        let mut root = Map::new();
        root.insert("format".into(), FORMAT.into());
        if let Some(id) = &self.trace_id {
            root.insert("trace_id".into(), id.clone().into());
        }
        root.insert("vehicle_id".into(), self.vehicle_id.clone().into());
        let mut p = Map::new();
        p.insert("model".into(), self.pantograph_model.clone().into());
        if let Some(s) = &self.pantograph_serial {
            p.insert("serial".into(), s.clone().into());
        }
        root.insert("pantograph".into(), p.into());
        root.insert("recorded_at".into(), self.recorded_at.clone().into());
        root.insert("test".into(), self.test.clone());
        let ch: BTreeMap<&str, &Vec<f64>> =
            self.channels.iter().map(|(n, v)| (n.as_str(), v)).collect();
        root.insert(
            "channels".into(),
            serde_json::to_value(ch).unwrap_or(Value::Null),
        );
        root.into()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    fn doc() -> Value {
        json!({"format": FORMAT, "vehicle_id": "EN57-1021", "pantograph": {"model": "160EC", "serial": "160EC-0042"},
               "recorded_at": "2026-03-02T07:15:00Z", "test": {"kind": "pendulum", "joint": "J1", "rig": {}},
               "channels": {"t_s": [0.0, 0.002, 0.004], "alpha_deg": [74.2, 74.19, 74.17]}})
    }

    fn field_of(v: Value) -> String {
        TraceDoc::from_value(&v).unwrap_err().field
    }

    /// Issue 17, point 3: a slider that is not the pantograph's head says so (`test.joint`:
    /// `custom`): it is reported under that label, with no Table 4 baseline to judge it by, the
    /// same physics fitted; its rig is stated in full, a missing value named.
    #[test]
    fn a_custom_slider_is_reported_as_custom_with_its_own_rig() {
        let path = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../../shared/data/examples/slider_baseline.json"
        );
        let head: Value = serde_json::from_slice(&std::fs::read(path).unwrap()).unwrap();
        let mut custom = head.clone();
        custom["test"]["joint"] = json!("custom");
        let thresholds = pantowatch_models::drift::DriftThresholds::default();
        let fit = |v: &Value| {
            crate::fitting::fit_document(&TraceDoc::from_value(v).unwrap(), &thresholds).unwrap()
        };
        let (j8, mine) = (fit(&head), fit(&custom));
        assert_eq!(j8.joints[0].joint, "J8");
        let c = &mine.joints[0];
        assert_eq!(c.joint, "custom");
        assert_eq!(c.status, pantowatch_models::drift::Status::Unknown);
        assert!(c.dry.baseline.is_none() && c.viscous.baseline.is_none());
        assert!((c.dry.value - j8.joints[0].dry.value).abs() <= 1e-9 * j8.joints[0].dry.value);
        for key in [
            "moving_mass_kg",
            "springs",
            "spring_stiffness_n_per_mm",
            "normal_force_n",
        ] {
            let mut d = custom.clone();
            d["test"]["rig"].as_object_mut().unwrap().remove(key);
            assert_eq!(field_of(d), format!("test.rig.{key}"));
        }
        let mut d = custom.clone();
        d["test"]["joint"] = json!("J3");
        assert_eq!(field_of(d), "test.joint");
    }

    /// Issue 18: one rule for a slider's springs (`[rig_limits] springs` in models/data): a
    /// custom slider's "0 for none" is accepted — the range check refused it while the parser
    /// said "0 to 64" — and a count outside the span or not whole is refused naming the field.
    #[test]
    fn a_custom_slider_without_springs_is_accepted() {
        let mut d = doc();
        d["test"] = json!({"kind": "slider", "joint": "custom",
            "rig": {"moving_mass_kg": 2.0, "springs": 0, "normal_force_n": 10.0}});
        d["channels"] = json!({"t_s": [0.0, 0.002, 0.004], "h_mm": [1.0, 0.9, 0.8]});
        TraceDoc::from_value(&d).expect("a custom slider with no spring");
        for bad in [
            json!(17),
            json!(64),
            json!(4_294_967_296_u64),
            json!(1.5),
            json!(-1),
        ] {
            let mut d = d.clone();
            d["test"]["rig"]["springs"] = bad.clone();
            d["test"]["rig"]["spring_stiffness_n_per_mm"] = json!(4.0);
            assert_eq!(field_of(d), "test.rig.springs", "{bad}");
        }
    }

    #[test]
    fn accepts_the_contract_example() {
        let d = TraceDoc::from_value(&doc()).unwrap();
        assert_eq!(d.kind, Kind::Pendulum);
        assert_eq!(d.channels[0].0, "t_s");
        assert_eq!(TraceDoc::from_value(&d.to_value()).unwrap(), d);
    }

    #[test]
    fn every_rule_names_its_field() {
        let mut cases: Vec<(Value, &str)> = Vec::new();
        let mut d = doc();
        d["format"] = json!("pantograph-trace/2");
        cases.push((d, "format"));
        let mut d = doc();
        d.as_object_mut().unwrap().remove("vehicle_id");
        cases.push((d, "vehicle_id"));
        let mut d = doc();
        d["pantograph"].as_object_mut().unwrap().remove("model");
        cases.push((d, "pantograph.model"));
        let mut d = doc();
        d["recorded_at"] = json!("2026-02-30T07:15:00Z");
        cases.push((d, "recorded_at"));
        let mut d = doc();
        d["test"]["kind"] = json!("swing");
        cases.push((d, "test.kind"));
        let mut d = doc();
        d["test"]["joint"] = json!("J9");
        cases.push((d, "test.joint"));
        let mut d = doc();
        d["test"] = json!({"kind": "quadrangle_swing", "rig": {"incline_deg": 70.0}});
        cases.push((d, "channels.beta_deg"));
        let quad = |rig: Value| {
            let mut d = doc();
            d["test"] = json!({"kind": "quadrangle_swing", "rig": rig});
            d["channels"]["beta_deg"] = json!([1.0, 2.0, 3.0]);
            d
        };
        cases.push((quad(json!({"incline_deg": 95.0})), "test.rig.incline_deg"));
        cases.push((quad(json!({"incline": 70.0})), "test.rig.incline"));
        cases.push((
            quad(json!({"attachments": [{"kind": "point", "mass_kg": 10.0, "body": "head", "position_m": [1.0, 0.0]}]})),
            "test.rig.attachments[0].body",
        ));
        cases.push((
            quad(json!({"attachments": [{"kind": "point", "mass_kg": 0.0, "body": "lower_arm", "position_m": [1.0, 0.0]}]})),
            "test.rig.attachments[0].mass_kg",
        ));
        cases.push((
            quad(json!({"attachments": [{"kind": "point", "mass_kg": 1.0, "body": "lower_arm", "position_m": [1.0]}]})),
            "test.rig.attachments[0].position_m",
        ));
        let mut d = quad(json!({}));
        d["test"]["joint"] = json!("J3");
        cases.push((d, "test.joint"));
        let mut d = doc();
        d["test"] = json!({"kind": "lift", "rig": {"L1_m": 1.6}});
        d["channels"] =
            json!({"t_s": [0.0, 0.1], "H_m": [1.0, 1.0], "T_Nm": [0.0, 0.0], "Fs_N": [0.0, 0.0]});
        cases.push((d, "test.rig.L1_m"));
        let mut d = doc();
        d["channels"]["t_s"] = json!([0.0, 0.002, 0.002]);
        cases.push((d, "channels.t_s[2]"));
        let mut d = doc();
        d["channels"]["alpha_deg"] = json!([1.0, 2.0]);
        cases.push((d, "channels.alpha_deg"));
        let mut d = doc();
        d["channels"]["alpha_deg"] = json!([1.0, "x", 2.0]);
        cases.push((d, "channels.alpha_deg[1]"));
        let mut d = doc();
        d["channels"].as_object_mut().unwrap().remove("alpha_deg");
        cases.push((d, "channels.alpha_deg"));
        let mut d = doc();
        d["test"]["rig"] =
            json!({"body": {"mass_kg": -1.0, "inertia_kgm2": 1.0, "com_distance_m": 0.1}});
        cases.push((d, "test.rig.body.mass_kg"));
        let mut d = doc();
        d["test"]["rig"] = json!({"pin_radius": 0.01});
        cases.push((d, "test.rig.pin_radius"));
        let mut d = doc();
        d["test"]["joint"] = json!("custom");
        cases.push((d, "test.rig.body"));
        let mut d = doc();
        d["trace_id"] = json!("a b; DROP TABLE traces");
        cases.push((d, "trace_id"));
        for (v, field) in cases {
            assert_eq!(field_of(v.clone()), field, "{v}");
        }
        assert_eq!(
            TraceDoc::from_json(b"{\"format\": ").unwrap_err().field,
            "body"
        );
        assert_eq!(
            TraceDoc::from_json(b"{\"a\": NaN}").unwrap_err().field,
            "body"
        );
    }

    /// A quadrangle swing with its rig is accepted as written in docs/TRACE_FORMAT.md and
    /// round-trips; its channels and stand reach the model.
    #[test]
    fn accepts_a_quadrangle_swing() {
        let mut d = doc();
        d["test"] = json!({"kind": "quadrangle_swing", "rig": {"incline_deg": 65.0,
            "attachments": [{"kind": "point", "mass_kg": 5.0, "body": "upper_arm", "position_m": [0.5, 0.0]}]}});
        d["channels"]["beta_deg"] = json!([-3.6, -3.6, -3.59]);
        let doc = TraceDoc::from_value(&d).unwrap();
        assert_eq!(doc.kind, Kind::QuadrangleSwing);
        let (ch, rig) = doc.quadrangle_channels().unwrap();
        assert_eq!(ch.beta_deg, [-3.6, -3.6, -3.59]);
        assert_eq!(rig.incline_deg, 65.0);
        assert_eq!(rig.attachments.len(), 1);
        assert_eq!(TraceDoc::from_value(&doc.to_value()).unwrap(), doc);
    }

    /// A force-gauge test (issue 20): 6 readings raising to 1.8 m, 5 lowering.
    fn gauge() -> Value {
        let h = [0.85, 1.0, 1.2, 1.4, 1.6, 1.8, 1.6, 1.4, 1.2, 1.0, 0.85];
        let f = [
            80.1, 79.5, 78.9, 78.0, 77.2, 76.4, 104.3, 105.2, 106.0, 106.9, 107.5,
        ];
        let t: Vec<f64> = (0..h.len()).map(|i| i as f64).collect();
        let mut d = doc();
        d["test"] = json!({"kind": "static_force", "gauge_resolution_n": 0.1});
        d["channels"] = json!({"t_s": t, "H_m": h, "F_N": f});
        d
    }

    #[test]
    fn every_kind_parses_by_its_name() {
        for k in Kind::ALL {
            assert_eq!(Kind::parse(k.as_str()), Some(k));
        }
        assert_eq!(Kind::parse("gauge"), None);
        assert_eq!(Kind::StaticForce.as_str(), STATIC_FORCE);
    }

    /// Issue 20: a force gauge's readings, raising then lowering, are accepted as written in
    /// docs/TRACE_FORMAT.md, round-trip, and split at the highest reading; every bad one is
    /// refused naming its field.
    #[test]
    fn a_static_force_test_is_accepted_and_each_bad_reading_named() {
        let d = TraceDoc::from_value(&gauge()).expect("a gauge test");
        assert_eq!(d.kind, Kind::StaticForce);
        assert_eq!(TraceDoc::from_value(&d.to_value()).unwrap(), d);
        let g = d.static_force_channels().unwrap();
        assert_eq!(g.raise_len, 6);
        assert_eq!(g.gauge_resolution_n, 0.1);
        let [up, down] = g.branches();
        assert_eq!((up.len(), down.len()), (6, 5));
        assert_eq!(up[5], (1.8, 76.4));
        assert_eq!(down[0], (1.6, 104.3));
        // A height read twice in a branch is no turn (the gauge's scale is coarse).
        let mut twice = gauge();
        twice["channels"]["H_m"][2] = json!(1.0);
        twice["channels"]["H_m"][8] = json!(1.4);
        TraceDoc::from_value(&twice).expect("a height read twice in a branch");
        let min = data::builtin_160ec()
            .static_force
            .as_ref()
            .expect("[static_force]")
            .min_points_per_branch;
        assert_eq!(min, 5);
        // `path` as `/a/b/c`: objects keyed by name, arrays by index; a missing key is added.
        let set = |path: &str, v: Value| {
            let mut d = gauge();
            let mut at = &mut d;
            for k in path.trim_start_matches('/').split('/') {
                at = match k.parse::<usize>() {
                    Ok(i) => &mut at[i],
                    Err(_) => &mut at[k],
                };
            }
            *at = v;
            d
        };
        let keep = |n: std::ops::Range<usize>| {
            let mut d = gauge();
            for c in ["t_s", "H_m", "F_N"] {
                let a = d["channels"][c].as_array().unwrap()[n.clone()].to_vec();
                d["channels"][c] = Value::Array(a);
            }
            d
        };
        let mut no_res = gauge();
        no_res["test"]
            .as_object_mut()
            .unwrap()
            .remove("gauge_resolution_n");
        let mut no_force = gauge();
        no_force["channels"].as_object_mut().unwrap().remove("F_N");
        let cases = [
            (set("/channels/H_m/2", json!(1.85)), "channels.H_m[2]"),
            (set("/channels/H_m/10", json!(0.79)), "channels.H_m[10]"),
            (keep(0..6), "channels.H_m"),
            (keep(5..11), "channels.H_m"),
            (keep(2..11), "channels.H_m"),
            (keep(0..10), "channels.H_m"),
            (set("/channels/H_m/3", json!(1.1)), "channels.H_m[3]"),
            (set("/channels/H_m/8", json!(1.5)), "channels.H_m[8]"),
            (no_res, "test.gauge_resolution_n"),
            (
                set("/test/gauge_resolution_n", json!(0)),
                "test.gauge_resolution_n",
            ),
            (
                set("/test/gauge_resolution_n", json!("0.1")),
                "test.gauge_resolution_n",
            ),
            (
                set("/test/gauge_resolution_n", json!(10.0)),
                "test.gauge_resolution_n",
            ),
            (no_force, "channels.F_N"),
            (set("/channels/F_N/1", json!(-2000.0)), "channels.F_N[1]"),
            (set("/test/joint", json!("J3")), "test.joint"),
            (set("/test/rig", json!({"L1_m": 1.6})), "test.rig.L1_m"),
            (set("/pantograph/model", json!("200EC")), "pantograph.model"),
            (set("/test/kind", json!("lift")), "test.gauge_resolution_n"),
        ];
        for (v, field) in cases {
            assert_eq!(field_of(v.clone()), field, "{v}");
        }
        // Read by hand: readings a minute apart are a gauge test (a logger's channel may not
        // pause over 1 s); a pause over `gauge_reading_interval_s` is refused at its reading.
        let spaced = |dt: f64| {
            let t: Vec<f64> = (0..11).map(|i| i as f64 * 60.0).collect();
            let mut d = set("/channels/t_s", json!(t));
            d["channels"]["t_s"][7] = json!(6.0 * 60.0 + dt);
            for i in 8..11 {
                d["channels"]["t_s"][i] = json!(6.0 * 60.0 + dt + (i - 7) as f64 * 60.0);
            }
            d
        };
        TraceDoc::from_value(&spaced(60.0)).expect("readings a minute apart");
        assert_eq!(field_of(spaced(601.0)), "channels.t_s[7]");
        let mut logger = doc();
        logger["channels"]["t_s"][1] = json!(60.0);
        assert!(
            field_of(logger).starts_with("channels.t_s["),
            "a logger's channel keeps its 1 s rule"
        );
        // A pendulum states no gauge.
        let mut d = doc();
        d["test"]["gauge_resolution_n"] = json!(0.1);
        assert_eq!(field_of(d), "test.gauge_resolution_n");
    }

    /// README "Input limits" lists the `[static_force]` limits an upload is checked against.
    #[test]
    fn readme_lists_the_static_force_limits() {
        let readme = include_str!("../../README.md");
        let sf = data::builtin_160ec()
            .static_force
            .as_ref()
            .expect("[static_force]");
        let [lo, hi] = sf.working_height_m;
        for row in [
            format!("| `[static_force] working_height_m` | [{lo}, {hi}] |"),
            format!(
                "| `[static_force] min_points_per_branch` | {} |",
                sf.min_points_per_branch
            ),
            format!(
                "| `[static_force] gauge_resolution_range_n` | [{}, {}] |",
                sf.gauge_resolution_range_n[0], sf.gauge_resolution_range_n[1]
            ),
            format!(
                "| `[static_force] gauge_reading_interval_s` | [{}, {}] |",
                sf.gauge_reading_interval_s[0], sf.gauge_reading_interval_s[1]
            ),
        ] {
            assert!(readme.contains(&row), "README \"Input limits\" lacks {row}");
        }
    }

    #[test]
    fn rfc3339() {
        for ok in [
            "2026-03-02T07:15:00Z",
            "2024-02-29T23:59:60.123+01:00",
            "2026-03-02t07:15:00z",
        ] {
            assert!(check_rfc3339(ok), "{ok}");
        }
        for no in [
            "2026-03-02",
            "2026-03-02T07:15:00",
            "2025-02-29T00:00:00Z",
            "2026-13-01T00:00:00Z",
            "2026-03-02T07:15:00+0100",
            "2026-03-02T07:15:00.Z",
            // Issue 18: outside the years 1…9999 once the offset is applied.
            "9999-12-31T23:59:59-23:59",
            "0000-06-01T00:00:00Z",
            "0001-01-01T00:30:00+01:00",
        ] {
            assert!(!check_rfc3339(no), "{no}");
        }
        for edge in [
            "9999-12-31T23:59:59Z",
            "0001-01-01T00:00:00Z",
            "0001-01-01T00:30:00-01:00",
        ] {
            assert!(check_rfc3339(edge), "{edge}");
        }
        let why = rfc3339_problem("9999-12-31T23:59:59-23:59").unwrap();
        assert!(why.contains("year 10000"), "{why}");
    }
}

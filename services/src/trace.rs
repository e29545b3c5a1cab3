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
use pantowatch_models::rig::{BodySpec, BodyUncertainty};
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

/// A document's test as the models crate takes it, per kind (issue 19, point 1): built once
/// where the document is parsed ([`TraceDoc::from_value`], and for a stored trace
/// `ingest::stored_doc`), with every check of the test and its channels; fitting, reports and
/// the CLI read it and check nothing again.
#[derive(Debug, Clone, PartialEq)]
pub enum TestSpec {
    /// A pendulum or slider: the models' single-joint test and its Table 4 baseline.
    Joint(
        Box<(
            pantowatch_models::identify::JointTest,
            pantowatch_models::testspec::Baseline,
        )>,
    ),
    /// A lift: the drive protocol it states it ran, checked against the stand's limits.
    Lift {
        protocol: Option<pantowatch_models::lift::protocol::LiftProtocol>,
    },
    /// A quadrangle swing: its stand.
    Quadrangle(Box<QuadRig>),
    /// A force-gauge record: the gauge's resolution (N) and how many readings raise the strip.
    StaticForce {
        gauge_resolution_n: f64,
        raise_len: usize,
    },
    /// Not typed yet: a stored trace read back as sent (`ingest::stored_doc_as_sent`, for
    /// downloads). No view accepts it; [`TraceDoc::typed`] types it.
    Unchecked,
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
    /// The document's `test` object, verbatim: what is stored and served (the contract is
    /// lossless). Code reads [`TraceDoc::spec`].
    pub test: Value,
    /// The test, typed: built and checked once, where the document is parsed.
    pub spec: TestSpec,
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

/// A lift record lasts at most the stated test duration (`[stand] duration_max_s` of the
/// 160EC geometry, `lift::design::ProtocolLimits::stand`), protocol stated or not: it is the
/// longest lift whose fit was validated, not the stand's own limit (README, "Long protocols
/// fit": on 19.5 s lifts a viscous combination read in a wrong basin and raised a false alarm).
fn lift_duration(t_s: &[f64]) -> Result<(), TraceError> {
    let g = pantowatch_models::lift::geometry::builtin_160ec();
    let max_s = pantowatch_models::lift::design::ProtocolLimits::stand(g).duration_max_s;
    match (t_s.first(), t_s.last()) {
        (Some(first), Some(last)) if last - first > max_s => Err(bad(
            "channels.t_s",
            format!(
                "the lift lasts {:.1} s, over the {max_s} s its fit is validated for \
                 (models/data/160ec-geometry.toml, `[stand] duration_max_s`)",
                last - first
            ),
        )),
        _ => Ok(()),
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
            spec: TestSpec::Unchecked,
            channels,
        };
        // Type the test now, so a document the model cannot use is rejected at the door.
        doc.typed()
    }

    /// The document with its test typed ([`TestSpec`]): the one place the test is checked.
    pub fn typed(mut self) -> Result<Self, TraceError> {
        self.spec = self.typed_spec()?;
        Ok(self)
    }

    pub fn channel(&self, name: &str) -> Option<&[f64]> {
        self.channels
            .iter()
            .find(|(n, _)| n == name)
            .map(|(_, v)| v.as_slice())
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
mod tests;

mod kinds;

//! The trace document (`pantograph-trace/1`, `../shared/contract/TRACE_FORMAT.md`): read by
//! serde into typed structs ([`wire`]: JSON, and a CSV's rows through `trace_csv`), checked
//! against every rule of the contract ([`TraceDoc::from_wire`]), and its test turned into the
//! models' test description ([`TraceDoc::typed`] → [`TestSpec`]).
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

/// Why a JSON body was refused: not JSON (`Malformed`, naming `body`) or a contract rule
/// (`Invalid`).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum JsonError {
    #[error("{0}")]
    Malformed(TraceError),
    #[error("{0}")]
    Invalid(TraceError),
}

fn bad(field: impl Into<String>, message: impl Into<String>) -> TraceError {
    TraceError {
        field: field.into(),
        message: message.into(),
    }
}

/// The test kinds of the contract (`test.kind`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
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

/// A string of the document by the rules of every text field: `field` names it; `required`
/// turns a missing (or `null`) one into "is required". Not empty, at most [`MAX_STRING`]
/// characters, no control characters.
fn text(v: Option<String>, field: &str, required: bool) -> Result<Option<String>, TraceError> {
    match v {
        None if !required => Ok(None),
        None => Err(bad(field, "is required")),
        Some(s) if s.trim().is_empty() => Err(bad(field, "must not be empty")),
        Some(s) if s.chars().count() > MAX_STRING => {
            Err(bad(field, format!("longer than {MAX_STRING} characters")))
        }
        Some(s) if s.chars().any(char::is_control) => {
            Err(bad(field, "contains control characters"))
        }
        Some(s) => Ok(Some(s)),
    }
}

/// A required value of the document: `field` "is required" when it is missing.
fn required<T>(v: Option<T>, field: &str) -> Result<T, TraceError> {
    v.ok_or_else(|| bad(field, "is required"))
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
/// longest lift whose fit was validated, not the stand's own limit (docs/VALIDATION.md, "Long protocols
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

impl TraceDoc {
    /// Parse and validate a document from JSON bytes ([`TraceDoc::parse_json`]).
    pub fn from_json(bytes: &[u8]) -> Result<Self, TraceError> {
        Self::parse_json(bytes).map_err(|e| match e {
            JsonError::Malformed(e) | JsonError::Invalid(e) => e,
        })
    }

    /// Parse and validate a document from JSON bytes: well-formed JSON (else `Malformed`,
    /// naming `body`), no key repeated in an object (else that key's path), then the typed
    /// document ([`wire::WireDoc`]: a value of the wrong shape or an unknown key named by its
    /// path) and the contract's rules ([`TraceDoc::from_wire`]).
    pub fn parse_json(bytes: &[u8]) -> Result<Self, JsonError> {
        match crate::json_keys::first_duplicate_key(bytes) {
            Err(e) => {
                return Err(JsonError::Malformed(bad(
                    "body",
                    format!("not valid JSON: {e}"),
                )));
            }
            // Valid JSON whose objects repeat a key: refused naming it, not last-wins.
            Ok(Some(key)) => {
                return Err(JsonError::Invalid(bad(
                    key.clone(),
                    format!("`{key}` appears twice in its object"),
                )));
            }
            Ok(None) => {}
        }
        wire::WireDoc::from_json(bytes)
            .and_then(Self::from_wire)
            .map_err(JsonError::Invalid)
    }

    /// Validate a parsed JSON document against the contract.
    pub fn from_value(v: &Value) -> Result<Self, TraceError> {
        Self::from_wire(wire::WireDoc::from_value(v)?)
    }

    /// The typed document (from JSON or CSV) checked against every rule of the contract, its
    /// test typed ([`TraceDoc::typed`]).
    pub fn from_wire(w: wire::WireDoc) -> Result<Self, TraceError> {
        match text(w.format, "format", true)?.as_deref() {
            Some(FORMAT) => {}
            other => {
                return Err(bad(
                    "format",
                    format!("expected `{FORMAT}`, got `{}`", other.unwrap_or_default()),
                ));
            }
        }
        // Ids by the rules of `ids` (issue 18): stored in NFC, no invisible characters.
        let id_rule = |e: crate::ids::IdError| bad(e.field, e.message);
        let trace_id = text(w.trace_id, "trace_id", false)?
            .map(|id| crate::ids::check_trace_id("trace_id", &id).map_err(id_rule))
            .transpose()?;
        let vehicle_id = text(w.vehicle_id, "vehicle_id", true)?.unwrap_or_default();
        let vehicle_id = crate::ids::normalise_text("vehicle_id", &vehicle_id).map_err(id_rule)?;
        let panto = required(w.pantograph, "pantograph")?;
        let pantograph_model = text(panto.model, "pantograph.model", true)?.unwrap_or_default();
        let pantograph_serial = text(panto.serial, "pantograph.serial", false)?
            .map(|v| crate::ids::normalise_text("pantograph.serial", &v).map_err(id_rule))
            .transpose()?;
        let recorded_at = text(w.recorded_at, "recorded_at", true)?.unwrap_or_default();
        if let Some(why) = rfc3339_problem(&recorded_at) {
            return Err(bad("recorded_at", why));
        }
        let test = Value::Object(required(w.test, "test")?);
        let wt: wire::WireTest = wire::read(&test, "test")?;
        let kind = required(wt.kind, "test.kind")?;
        if kind != Kind::Pendulum && wt.release_t_s.is_some() {
            return Err(bad(
                "test.release_t_s",
                "only a pendulum test states its release",
            ));
        }
        if kind != Kind::StaticForce && wt.gauge_resolution_n.is_some() {
            return Err(bad(
                "test.gauge_resolution_n",
                "only a static_force test states a gauge resolution",
            ));
        }
        let joint = text(wt.joint, "test.joint", false)?;
        // Recordings of one rig (issue 36, point 5): a name within the pantograph's records.
        if let Some(rig) = text(wt.rig_id, "test.rig_id", false)? {
            crate::ids::normalise_text("test.rig_id", &rig).map_err(id_rule)?;
            if !matches!(kind, Kind::Pendulum | Kind::Slider) {
                return Err(bad(
                    "test.rig_id",
                    "only a single-joint test (pendulum, slider) is pooled by its rig",
                ));
            }
            if pantograph_serial.is_none() {
                return Err(bad(
                    "test.rig_id",
                    "needs pantograph.serial: a rig id names a rig within one pantograph's records",
                ));
            }
        }
        let wire::Channels(mut chans) = required(w.channels, "channels")?;
        if chans.len() > MAX_CHANNELS {
            return Err(bad(
                "channels",
                format!("{} channels, more than {MAX_CHANNELS}", chans.len()),
            ));
        }
        let t = required(chans.remove("t_s"), "channels.t_s")?;
        if t.len() > MAX_SAMPLES {
            return Err(bad(
                "channels.t_s",
                format!("{} samples, more than the limit of {MAX_SAMPLES}", t.len()),
            ));
        }
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
        let (needed, _optional) = kind.channels();
        for name in needed {
            if !chans.contains_key(*name) {
                return Err(bad(
                    format!("channels.{name}"),
                    format!("is required for a {} test", kind.as_str()),
                ));
            }
        }
        let n = t.len();
        let mut channels = vec![("t_s".to_string(), t)];
        for (name, x) in chans {
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
            if x.len() > MAX_SAMPLES {
                return Err(bad(
                    format!("channels.{name}"),
                    format!("{} samples, more than the limit of {MAX_SAMPLES}", x.len()),
                ));
            }
            if x.len() != n {
                return Err(bad(
                    format!("channels.{name}"),
                    format!("has {} samples but t_s has {n}", x.len()),
                ));
            }
            channels.push((name, x));
        }
        let doc = TraceDoc {
            trace_id,
            vehicle_id,
            pantograph_model,
            pantograph_serial,
            recorded_at,
            kind,
            joint,
            test,
            spec: TestSpec::Unchecked,
            channels,
        };
        // Type the test now, so a document the model cannot use is rejected at the door.
        doc.typed()
    }

    /// The stated `test.rig_id` (recordings of one rig, issue 36 point 5), if any.
    pub fn rig_id(&self) -> Option<&str> {
        self.test.get("rig_id").and_then(Value::as_str)
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
pub mod wire;

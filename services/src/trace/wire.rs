//! The trace document as serde reads it: one struct per object of the contract
//! (`../shared/contract/TRACE_FORMAT.md`), `deny_unknown_fields` wherever the contract lists the
//! keys (the root, `pantograph`, `test`, each kind's `rig`, `rig.body`, `rig.body_uncertainty`,
//! an attachment), read through `serde_path_to_error` so that a refusal names the field by its
//! path (`test.rig.body.mass_kg`, `channels.alpha_deg[3]`, `test.rig.colour`).
//!
//! Two objects are tagged by their `kind` (the test, an attachment): their tag is read first
//! ([`Kind`], [`PendulumAttachmentKind`]), then the object as that kind's struct — serde's own
//! internally tagged enums buffer the object and lose the path inside it.
//!
//! What a struct cannot say — a key the contract requires (named with "is required", not serde's
//! "missing field"), the string rules, every range — is checked by the rules after it
//! (`TraceDoc::from_wire`, `TraceDoc::typed`), as the contract orders them.

use std::collections::BTreeMap;
use std::fmt;

use serde::de::{self, DeserializeOwned, Deserializer, IgnoredAny, MapAccess, SeqAccess, Visitor};
use serde::{Deserialize, Serialize};
use serde_json::{Map, Value};

use super::{Kind, MAX_CHANNELS, MAX_SAMPLES, TraceError, bad};

/// A finite number (any JSON number; a non-finite value is refused naming its field).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
#[serde(transparent)]
pub struct Finite(pub f64);

impl<'de> Deserialize<'de> for Finite {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V;
        impl Visitor<'_> for V {
            type Value = Finite;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str("a number")
            }
            fn visit_f64<E: de::Error>(self, x: f64) -> Result<Finite, E> {
                if x.is_finite() {
                    Ok(Finite(x))
                } else {
                    Err(E::custom("must be a finite number"))
                }
            }
            fn visit_i64<E: de::Error>(self, x: i64) -> Result<Finite, E> {
                Ok(Finite(x as f64))
            }
            fn visit_u64<E: de::Error>(self, x: u64) -> Result<Finite, E> {
                Ok(Finite(x as f64))
            }
        }
        d.deserialize_f64(V)
    }
}

/// A key that may be stated as `null`, told apart from one left out: `#[serde(default,
/// deserialize_with = "present")]` on an `Option<T>` field reads a stated value (`null`
/// included, when `T` takes it) as `Some`.
pub fn present<'de, D: Deserializer<'de>, T: Deserialize<'de>>(
    d: D,
) -> Result<Option<T>, D::Error> {
    T::deserialize(d).map(Some)
}

/// An object of the document: `T` read from a JSON object only. (A struct that serde derives
/// also reads an array, its fields by position: `"pantograph": []` would read as a pantograph
/// with no model, `"body_uncertainty": [0.1]` as a mass's.)
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Obj<T>(pub T);

impl<'de, T: Deserialize<'de>> Deserialize<'de> for Obj<T> {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct Gate<T>(std::marker::PhantomData<T>);
        impl<'de, T: Deserialize<'de>> Visitor<'de> for Gate<T> {
            type Value = Obj<T>;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str("an object")
            }
            fn visit_map<A: MapAccess<'de>>(self, map: A) -> Result<Obj<T>, A::Error> {
                T::deserialize(de::value::MapAccessDeserializer::new(map)).map(Obj)
            }
        }
        d.deserialize_map(Gate(std::marker::PhantomData))
    }
}

/// An optional object of the document (`null` as absent): `#[serde(default, deserialize_with =
/// "object")]`.
pub fn object<'de, D: Deserializer<'de>, T: Deserialize<'de>>(d: D) -> Result<Option<T>, D::Error> {
    Option::<Obj<T>>::deserialize(d).map(|o| o.map(|Obj(t)| t))
}

/// The root object.
#[derive(Debug, Clone, Default, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WireDoc {
    #[serde(default)]
    pub format: Option<String>,
    #[serde(default)]
    pub trace_id: Option<String>,
    #[serde(default)]
    pub vehicle_id: Option<String>,
    #[serde(default, deserialize_with = "object")]
    pub pantograph: Option<WirePantograph>,
    #[serde(default)]
    pub recorded_at: Option<String>,
    /// The test object as sent: stored verbatim (the contract is lossless) and read as
    /// [`WireTest`] by the rules.
    #[serde(default)]
    pub test: Option<Map<String, Value>>,
    #[serde(default)]
    pub channels: Option<Channels>,
}

/// `pantograph`.
#[derive(Debug, Clone, Default, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WirePantograph {
    #[serde(default)]
    pub model: Option<String>,
    #[serde(default)]
    pub serial: Option<String>,
}

/// `test`: the keys of every kind; which kind may state which is the rules' (a
/// `release_t_s` only a pendulum's, a `gauge_resolution_n` only a static_force test's).
#[derive(Debug, Clone, Default, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WireTest {
    #[serde(default)]
    pub kind: Option<Kind>,
    #[serde(default)]
    pub joint: Option<String>,
    /// Read per kind ([`PendulumRig`], [`SliderRig`], [`QuadrangleRig`]; a lift's and a gauge
    /// test's must be empty).
    #[serde(default, deserialize_with = "present")]
    pub rig: Option<Map<String, Value>>,
    /// A lift's stated drive protocol, read as `lift::protocol::LiftProtocol`; `Some(Null)`:
    /// stated as `null`.
    #[serde(default, deserialize_with = "present")]
    pub protocol: Option<Value>,
    #[serde(default)]
    pub release_t_s: Option<Finite>,
    /// Recordings of one rig (issue 36, point 5): a single-joint test's name for its rig
    /// within the pantograph's records; the same `pantograph.serial`, `test.kind`, `test.joint`
    /// and `test.rig_id` are fitted pooled.
    #[serde(default)]
    pub rig_id: Option<String>,
    /// `Some(None)`: stated as `null`.
    #[serde(default, deserialize_with = "present")]
    pub gauge_resolution_n: Option<Option<Finite>>,
}

/// A pendulum's `test.rig`.
#[derive(Debug, Clone, Default, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PendulumRig {
    #[serde(default, deserialize_with = "object")]
    pub body: Option<WireBody>,
    /// Each one tagged by its `kind` ([`PendulumAttachment::read`]).
    #[serde(default)]
    pub attachments: Option<Vec<Map<String, Value>>>,
    #[serde(default)]
    pub pin_radius_m: Option<Finite>,
    #[serde(default)]
    pub gravity_m_s2: Option<Finite>,
    #[serde(default)]
    pub initial_rate_deg_s: Option<Finite>,
    #[serde(default, deserialize_with = "object")]
    pub body_uncertainty: Option<WireBody>,
}

/// `rig.body` (each value required by the rules) and `rig.body_uncertainty` (each optional).
#[derive(Debug, Clone, Default, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WireBody {
    #[serde(default)]
    pub mass_kg: Option<Finite>,
    #[serde(default)]
    pub inertia_kgm2: Option<Finite>,
    #[serde(default)]
    pub com_distance_m: Option<Finite>,
}

/// The kinds of a pendulum's attachment.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum PendulumAttachmentKind {
    Point,
    Rod,
}

/// An attachment's tag: its `kind`, the other keys left to the kind's struct.
#[derive(Debug, Deserialize)]
struct Tag<K> {
    #[serde(default = "none")]
    kind: Option<K>,
}

fn none<K>() -> Option<K> {
    None
}

/// A point mass on the pendulum's centre-of-mass line.
#[derive(Debug, Clone, Default, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PointOnLine {
    #[serde(default)]
    kind: IgnoredAny,
    #[serde(default)]
    pub mass_kg: Option<Finite>,
    #[serde(default)]
    pub distance_m: Option<Finite>,
}

/// A uniform rod hanging from the pendulum's axis.
#[derive(Debug, Clone, Default, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Rod {
    #[serde(default)]
    kind: IgnoredAny,
    #[serde(default)]
    pub mass_kg: Option<Finite>,
    #[serde(default)]
    pub length_m: Option<Finite>,
}

/// A pendulum's attachment, by its kind.
#[derive(Debug, Clone, PartialEq)]
pub enum PendulumAttachment {
    Point(PointOnLine),
    Rod(Rod),
}

impl PendulumAttachment {
    /// `rig.attachments[i]`, at `field`: its `kind` first, then the keys of that kind.
    pub fn read(m: &Map<String, Value>, field: &str) -> Result<Self, TraceError> {
        let tag: Tag<PendulumAttachmentKind> = read_map(m, field)?;
        match tag.kind {
            Some(PendulumAttachmentKind::Point) => read_map(m, field).map(Self::Point),
            Some(PendulumAttachmentKind::Rod) => read_map(m, field).map(Self::Rod),
            None => Err(bad(format!("{field}.kind"), "must be `point` or `rod`")),
        }
    }
}

/// A slider's `test.rig`.
#[derive(Debug, Clone, Default, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SliderRig {
    #[serde(default)]
    pub moving_mass_kg: Option<Finite>,
    /// A whole number of springs (0 for none).
    #[serde(default)]
    pub springs: Option<u64>,
    #[serde(default)]
    pub spring_stiffness_n_per_mm: Option<Finite>,
    #[serde(default)]
    pub normal_force_n: Option<Finite>,
    #[serde(default)]
    pub moving_mass_uncertainty_kg: Option<Finite>,
}

/// A quadrangle swing's `test.rig`.
#[derive(Debug, Clone, Default, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct QuadrangleRig {
    #[serde(default)]
    pub incline_deg: Option<Finite>,
    #[serde(default)]
    pub gravity_m_s2: Option<Finite>,
    #[serde(default)]
    pub attachments: Option<Vec<Obj<QuadrangleAttachment>>>,
}

/// The one kind of a quadrangle's attachment.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum PointKind {
    Point,
}

/// A point mass fixed to one of the quadrangle's bodies, at body coordinates.
#[derive(Debug, Clone, Default, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct QuadrangleAttachment {
    #[serde(default)]
    pub kind: Option<PointKind>,
    #[serde(default)]
    pub mass_kg: Option<Finite>,
    #[serde(default)]
    pub body: Option<String>,
    #[serde(default)]
    pub position_m: Option<Pair>,
}

/// Two finite numbers `[x, y]`; anything else is refused naming the pair, not an element.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pair(pub [f64; 2]);

impl<'de> Deserialize<'de> for Pair {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        const WHAT: &str = "must be two numbers [x, y], m";
        struct V;
        impl<'de> Visitor<'de> for V {
            type Value = Pair;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str("two numbers [x, y]")
            }
            fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Pair, A::Error> {
                let mut xy = Vec::with_capacity(2);
                while let Some(v) = seq.next_element::<Value>()? {
                    xy.push(v.as_f64().filter(|x| x.is_finite()));
                }
                match xy[..] {
                    [Some(x), Some(y)] => Ok(Pair([x, y])),
                    _ => Err(de::Error::custom(WHAT)),
                }
            }
        }
        d.deserialize_seq(V)
            .map_err(|_: D::Error| de::Error::custom(WHAT))
    }
}

/// `channels`: every channel by name (at most [`MAX_CHANNELS`], each at most [`MAX_SAMPLES`]
/// finite numbers), straight into `f64`s.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Channels(pub BTreeMap<String, Vec<f64>>);

impl<'de> Deserialize<'de> for Channels {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V;
        impl<'de> Visitor<'de> for V {
            type Value = Channels;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str("an object of channels")
            }
            fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<Channels, A::Error> {
                let mut out = BTreeMap::new();
                let mut n = 0usize;
                while let Some(name) = map.next_key::<String>()? {
                    n += 1;
                    // Over the limit: the rest are counted, not read.
                    if n > MAX_CHANNELS {
                        map.next_value::<IgnoredAny>()?;
                    } else {
                        let Samples(x) = map.next_value()?;
                        out.insert(name, x);
                    }
                }
                if n > MAX_CHANNELS {
                    return Err(de::Error::custom(format!(
                        "{n} channels, more than {MAX_CHANNELS}"
                    )));
                }
                Ok(Channels(out))
            }
        }
        d.deserialize_map(V)
    }
}

/// One channel's samples.
struct Samples(Vec<f64>);

impl<'de> Deserialize<'de> for Samples {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V;
        impl<'de> Visitor<'de> for V {
            type Value = Samples;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str("an array of numbers")
            }
            fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Samples, A::Error> {
                let mut x = Vec::with_capacity(seq.size_hint().unwrap_or(0).min(MAX_SAMPLES));
                while x.len() < MAX_SAMPLES {
                    match seq.next_element::<Finite>()? {
                        Some(Finite(v)) => x.push(v),
                        None => return Ok(Samples(x)),
                    }
                }
                // At the limit: the rest are counted, not kept.
                let mut n = x.len();
                while seq.next_element::<IgnoredAny>()?.is_some() {
                    n += 1;
                }
                if n > MAX_SAMPLES {
                    return Err(de::Error::custom(format!(
                        "{n} samples, more than the limit of {MAX_SAMPLES}"
                    )));
                }
                Ok(Samples(x))
            }
        }
        d.deserialize_seq(V)
    }
}

/// A serde error at `path` (under `prefix`, the field the value was read from) as the
/// document's error: the field is the path (`channels.alpha_deg[3]`; an unknown key's path
/// ends at that key), the message serde's.
fn at_path<E: fmt::Display>(e: serde_path_to_error::Error<E>, prefix: &str) -> TraceError {
    let path = e.path().to_string();
    let field = match (prefix, path.as_str()) {
        ("", ".") => "body".to_owned(),
        (p, ".") => p.to_owned(),
        ("", p) => p.to_owned(),
        (pre, p) if p.starts_with('[') => format!("{pre}{p}"),
        (pre, p) => format!("{pre}.{p}"),
    };
    bad(field, e.into_inner().to_string())
}

/// `T` read from a value of the document at `field`.
pub fn read<T: DeserializeOwned>(v: &Value, field: &str) -> Result<T, TraceError> {
    serde_path_to_error::deserialize(v).map_err(|e| at_path(e, field))
}

/// `T` read from an object of the document at `field`.
pub fn read_map<T: DeserializeOwned>(m: &Map<String, Value>, field: &str) -> Result<T, TraceError> {
    serde_path_to_error::deserialize(m).map_err(|e| at_path(e, field))
}

impl WireDoc {
    /// The document from JSON text already checked to be well-formed JSON with no repeated
    /// key (`json_keys::first_duplicate_key`).
    pub fn from_json(bytes: &[u8]) -> Result<Self, TraceError> {
        let de = &mut serde_json::Deserializer::from_slice(bytes);
        serde_path_to_error::deserialize(de)
            .map(|Obj(doc)| doc)
            .map_err(|e| at_path(e, ""))
    }

    /// The document from a parsed JSON value.
    pub fn from_value(v: &Value) -> Result<Self, TraceError> {
        read(v, "").map(|Obj(doc)| doc)
    }
}

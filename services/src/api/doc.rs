//! What the OpenAPI document states beyond each handler's own annotation: the ids' rules as
//! schemas (from `crate::ids`, the code that enforces them), and the answers every operation
//! shares — 401, 403 by the role its security requirement names, 400/404 by what it takes from
//! the address, 413/415/422 by its body, 429 unless exempt from the rate limit, 414, 5xx — each
//! a problem+json response of `components.responses`.

use std::borrow::Cow;

use utoipa::openapi::header::HeaderBuilder;
use utoipa::openapi::path::{Operation, ParameterIn};
use utoipa::openapi::schema::{
    AllOfBuilder, ArrayBuilder, KnownFormat, ObjectBuilder, OneOfBuilder, Schema, SchemaFormat,
    Type,
};
use utoipa::openapi::{ContentBuilder, OpenApi, Ref, RefOr, ResponseBuilder};
use utoipa::{PartialSchema, ToSchema};

use super::error::PROBLEM_JSON;
use super::ratelimit::EXEMPT_PATHS;
use crate::ids::{ID_PUNCTUATION, JOINTS, JointName, MAX_STRING, Serial, TraceId, VehicleId};

/// The name of the bearer security scheme; an operation's requirement lists the least role it
/// needs (`reader`, `writer`, `admin`), as OpenAPI 3.1 allows for non-OAuth schemes.
pub const BEARER: &str = "bearer";

/// `c` inside a pattern's character class, written the same for ECMA-262, Python's `re` (what
/// `openapi-spec-validator` compiles) and Rust's `regex`: ASCII as itself (escaped where the
/// class needs it), anything else as `\uXXXX`.
fn class_char(c: char) -> String {
    if c.is_ascii_alphanumeric() || " _:/#()+',.".contains(c) {
        c.to_string()
    } else if c.is_ascii() && !c.is_ascii_control() {
        format!("\\{c}")
    } else {
        format!("\\u{:04X}", c as u32)
    }
}

/// The character class of the characters `keep` admits, as ranges, over U+0000–U+FFFF (the
/// range one `\uXXXX` escape spans in all three engines; surrogates excluded).
fn class_of(keep: impl Fn(char) -> bool) -> String {
    let mut out = String::from("[");
    let mut run: Option<(char, char)> = None;
    let close = |out: &mut String, (a, b): (char, char)| {
        out.push_str(&class_char(a));
        if b != a {
            if b as u32 > a as u32 + 1 {
                out.push('-');
            }
            out.push_str(&class_char(b));
        }
    };
    for c in (0..=0xFFFF_u32).filter_map(char::from_u32) {
        match (keep(c), run) {
            (true, Some((a, b))) if b as u32 + 1 == c as u32 => run = Some((a, c)),
            (true, Some(r)) => {
                close(&mut out, r);
                run = Some((c, c));
            }
            (true, None) => run = Some((c, c)),
            (false, Some(r)) => {
                close(&mut out, r);
                run = None;
            }
            (false, None) => {}
        }
    }
    if let Some(r) = run {
        close(&mut out, r);
    }
    out.push(']');
    out
}

/// The trace id rule of `ids::check_trace_id`: ASCII letters, digits and `- _ . :`.
pub fn trace_id_pattern() -> String {
    format!(
        "^{}+$",
        class_of(|c| c.is_ascii_alphanumeric() || "-_.:".contains(c))
    )
}

/// The characters of the free-text id rule of `ids::normalise_text`: letters and digits
/// (Rust's `char::is_alphanumeric`, the rule's own test), the punctuation
/// `ids::ID_PUNCTUATION` and spaces.
pub fn text_id_pattern() -> String {
    format!(
        "^{}+$",
        class_of(|c| c.is_alphanumeric() || c == ' ' || ID_PUNCTUATION.contains(c))
    )
}

/// The shape every id has, whatever its characters: not `.` or `..` alone, no space first or
/// last.
pub const ID_SHAPE: &str = "^(?:[^ .]|[^ .][^ ]|\\.[^ .]|[^ ][\\s\\S]+[^ ])$";

fn id_schema(pattern: String, description: &str, example: &str) -> RefOr<Schema> {
    let characters = ObjectBuilder::new()
        .schema_type(Type::String)
        .min_length(Some(1))
        .max_length(Some(MAX_STRING))
        .pattern(Some(pattern));
    let shape = ObjectBuilder::new()
        .schema_type(Type::String)
        .pattern(Some(ID_SHAPE));
    AllOfBuilder::new()
        .item(characters)
        .item(shape)
        .description(Some(description))
        .examples([example])
        .into()
}

impl PartialSchema for TraceId {
    fn schema() -> RefOr<Schema> {
        id_schema(
            trace_id_pattern(),
            "A trace id: 1–256 ASCII letters, digits and `- _ . :`, not `.` or `..` alone.",
            "en57-1021-2026-03-02",
        )
    }
}

impl ToSchema for TraceId {
    fn name() -> Cow<'static, str> {
        "TraceId".into()
    }
}

const TEXT_ID: &str = "1–256 characters: letters and digits of any script, spaces (not first or \
    last) and `- _ . : / # ( ) + ' ,`; not `.` or `..` alone. Stored and compared in Unicode \
    NFC, so two spellings of one text are one id.";

impl PartialSchema for VehicleId {
    fn schema() -> RefOr<Schema> {
        id_schema(
            text_id_pattern(),
            &format!("A vehicle id. {TEXT_ID}"),
            "EN57 1021",
        )
    }
}

impl ToSchema for VehicleId {
    fn name() -> Cow<'static, str> {
        "VehicleId".into()
    }
}

impl PartialSchema for Serial {
    fn schema() -> RefOr<Schema> {
        id_schema(
            text_id_pattern(),
            &format!("A pantograph serial. {TEXT_ID}"),
            "160EC-0042",
        )
    }
}

impl ToSchema for Serial {
    fn name() -> Cow<'static, str> {
        "Serial".into()
    }
}

impl PartialSchema for JointName {
    fn schema() -> RefOr<Schema> {
        ObjectBuilder::new()
            .schema_type(Type::String)
            .enum_values(Some(JOINTS))
            .description(Some(
                "A joint of the 160EC (`J1` … `J9`, `J2'`) or `custom`.",
            ))
            .into()
    }
}

impl ToSchema for JointName {
    fn name() -> Cow<'static, str> {
        "JointName".into()
    }
}

/// A shared answer: name in `components.responses`, status, description, and the header it
/// carries (name, description).
type Shared = (
    &'static str,
    &'static str,
    &'static str,
    Option<(&'static str, &'static str)>,
);

/// The shared answers.
const SHARED: [Shared; 13] = [
    (
        "BadRequest",
        "400",
        "A path segment, query value or body field that does not parse or breaks its rule \
         (`parameter` or `field` names it)",
        None,
    ),
    (
        "Unauthorized",
        "401",
        "No key, or an unknown or revoked key (`field`: `Authorization`)",
        Some(("WWW-Authenticate", "`Bearer realm=\"pantowatch\"`")),
    ),
    (
        "Forbidden",
        "403",
        "The key's role is lower than the route needs (the security requirement names it)",
        None,
    ),
    (
        "NotFound",
        "404",
        "Nothing at this address (`parameter`: `path`)",
        None,
    ),
    (
        "PayloadTooLarge",
        "413",
        "The body (inflated, when sent with `Content-Encoding: gzip`) is larger than \
         `http.body_limit_mib`",
        None,
    ),
    (
        "UriTooLong",
        "414",
        "Path and query longer than 8 KiB",
        None,
    ),
    (
        "UnsupportedMediaType",
        "415",
        "A `Content-Type` the route does not take (`field`: `Content-Type`)",
        None,
    ),
    (
        "Unprocessable",
        "422",
        "The body parses but breaks a rule (a key given twice in one object; `field` names it)",
        None,
    ),
    (
        "TooManyRequests",
        "429",
        "Over the rate limit of this key, or of this address without a known key \
         (`http.rate_limit_per_s`, `http.rate_limit_burst`)",
        Some((
            "Retry-After",
            "Whole seconds until a request is admitted again",
        )),
    ),
    (
        "InternalError",
        "500",
        "The server failed; the error is in its log, not in the answer",
        None,
    ),
    (
        "Unavailable",
        "503",
        "The database does not answer or refuses writes (read-only), or the request took \
         longer than `http.request_timeout_secs`",
        Some(("Retry-After", "Seconds before a retry is worth it")),
    ),
    (
        "StorageFull",
        "507",
        "The database has no space left for the write",
        Some(("Retry-After", "Seconds before a retry is worth it")),
    ),
    (
        "Conflict",
        "409",
        "The request contradicts what is stored (`field` names the part that does)",
        None,
    ),
];

/// The statuses `op` (at `path`, written with method `write`) can answer besides its own.
fn shared_statuses(path: &str, write: bool, op: &Operation) -> Vec<&'static str> {
    let mut out = vec!["414", "500", "503"];
    let roles: Vec<String> = op
        .security
        .iter()
        .flatten()
        .filter_map(|r| serde_json::to_value(r).ok())
        .filter_map(|v| v.get(BEARER).cloned())
        .filter_map(|v| serde_json::from_value::<Vec<String>>(v).ok())
        .flatten()
        .collect();
    let secured = op.security.iter().flatten().next().is_some();
    if secured {
        out.push("401");
        if roles.iter().any(|r| r != "reader") {
            out.push("403");
        }
        if write {
            out.push("507");
        }
    }
    if !EXEMPT_PATHS.contains(&path) {
        out.push("429");
    }
    let params = op.parameters.iter().flatten().filter_map(|p| match p {
        RefOr::T(p) => Some(&p.parameter_in),
        RefOr::Ref(_) => None,
    });
    let (mut any, mut in_path) = (false, false);
    for p in params {
        any = true;
        in_path |= matches!(p, ParameterIn::Path);
    }
    let body = op.request_body.is_some();
    if any || body {
        out.push("400");
    }
    if in_path {
        out.push("404");
    }
    if body {
        out.extend(["413", "415", "422"]);
    }
    out
}

/// Adds the shared answers to `components.responses` and to every operation that can give
/// them (an operation's own, more specific answer for a status is kept).
pub fn add_shared_answers(doc: &mut OpenApi) {
    let components = doc.components.get_or_insert_with(Default::default);
    for (name, _, description, header) in SHARED {
        let mut r = ResponseBuilder::new().description(description).content(
            PROBLEM_JSON,
            ContentBuilder::new()
                .schema(Some(Ref::from_schema_name("Problem")))
                .build(),
        );
        if let Some((h, text)) = header {
            let schema = ObjectBuilder::new().schema_type(if h == "Retry-After" {
                Type::Integer
            } else {
                Type::String
            });
            r = r.header(
                h,
                HeaderBuilder::new()
                    .schema(Some(schema))
                    .description(Some(text))
                    .build(),
            );
        }
        components
            .responses
            .insert(name.into(), RefOr::T(r.build()));
    }
    for (path, item) in doc.paths.paths.iter_mut() {
        let ops = [
            (&mut item.get, false),
            (&mut item.post, true),
            (&mut item.put, true),
            (&mut item.delete, true),
            (&mut item.patch, true),
        ];
        for (op, write) in ops {
            let Some(op) = op.as_mut() else { continue };
            for status in shared_statuses(path, write, op) {
                let Some((name, ..)) = SHARED.iter().find(|s| s.1 == status) else {
                    continue;
                };
                op.responses
                    .responses
                    .entry(status.into())
                    .or_insert_with(|| RefOr::Ref(Ref::from_response_name(*name)));
            }
        }
    }
}

/// The evidence an alert carries, by what raised it (`crate::alerts`): a joint's status or
/// forecast; the static-force prediction against the type's limits; a finding a fit names on
/// the measuring chain or the spring (`H sensor`, `force gauge`, `spring rate`); a joint's test
/// due (`J5 test due`). Every part is
/// a schema of its own type (the fit result's, fleet health's, the static force's); this lists
/// which parts each kind holds, as `crate::alerts` writes them.
fn alert_evidence() -> Schema {
    let r = |name: &str| RefOr::Ref(Ref::from_schema_name(name));
    let string = || ObjectBuilder::new().schema_type(Type::String);
    let integer = || ObjectBuilder::new().schema_type(Type::Integer);
    let number = || ObjectBuilder::new().schema_type(Type::Number);
    let list = |name: &str| ArrayBuilder::new().items(r(name));
    let date_time = || string().format(Some(SchemaFormat::KnownFormat(KnownFormat::DateTime)));
    let common = |o: ObjectBuilder| {
        o.property("fit_id", integer())
            .property("trace_id", r("TraceId"))
            .property("recorded_at", date_time())
            .required("fit_id")
            .required("trace_id")
            .required("recorded_at")
    };
    let joint = common(ObjectBuilder::new())
        .title(Some("Joint"))
        .description(Some(
            "A joint's status (`watch`, `alarm`) or its forecast crossing",
        ))
        .property("model_version", string())
        .property("status", r("Status"))
        .property("viscous", r("ParamResult"))
        .property("dry", r("ParamResult"))
        .property("residual", r("ResidualResult"))
        .property("rmse", r("Quantity"))
        .property("trends", list("ParamTrend"))
        .property("horizon_days", number())
        .property("tests", integer().minimum(Some(0)))
        .required("model_version")
        .required("status")
        .required("viscous")
        .required("dry")
        .required("residual")
        .required("rmse")
        .required("trends")
        .required("horizon_days")
        .required("tests");
    let static_force = common(ObjectBuilder::new())
        .title(Some("StaticForce"))
        .description(Some(
            "The predicted static contact force leaves the type's limits (`static force`)",
        ))
        .property("findings", list("FindingView"))
        .property("parameters", list("MuSource"))
        .property("limits", r("LimitsView"))
        .required("findings")
        .required("parameters")
        .required("limits");
    let finding = common(ObjectBuilder::new())
        .title(Some("Finding"))
        .description(Some(
            "An effect a fit names on the measuring chain or the spring (`H sensor`, \
             `force gauge`, `spring rate`)",
        ))
        .property("model_version", string())
        .property("effect", r("EffectResult"))
        .property("residual", r("ResidualResult"))
        .required("model_version")
        .required("effect")
        .required("residual");
    let test_due = ObjectBuilder::new()
        .title(Some("TestDue"))
        .description(Some(
            "A joint's evidence older than its type allows (`J5 test due`, issue 37): the \
             pantograph's newest test, its time, and the joint's evidence then",
        ))
        .property("trace_id", r("TraceId"))
        .property("at", date_time())
        .property("due", r("EvidenceJoint"))
        .required("trace_id")
        .required("at")
        .required("due");
    OneOfBuilder::new()
        .item(joint)
        .item(static_force)
        .item(finding)
        .item(test_due)
        .description(Some(
            "Why the alert stands: model version, fit, parameters with intervals and baseline, \
             residual, trends and forecast — by the kind of alert",
        ))
        .into()
}

/// Types `Alert.evidence` (stored as JSON, `store::alerts`) by [`alert_evidence`].
pub fn add_alert_evidence(doc: &mut OpenApi) {
    let components = doc.components.get_or_insert_with(Default::default);
    components
        .schemas
        .insert("AlertEvidence".into(), RefOr::T(alert_evidence()));
    if let Some(RefOr::T(Schema::Object(alert))) = components.schemas.get_mut("Alert") {
        alert.properties.insert(
            "evidence".into(),
            RefOr::Ref(Ref::from_schema_name("AlertEvidence")),
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `s` matches the id schema of `pattern`: the characters and the shape.
    fn matches(pattern: &str, s: &str) -> bool {
        use std::collections::HashMap;
        use std::sync::{Mutex, OnceLock};
        static COMPILED: OnceLock<Mutex<HashMap<String, regex::Regex>>> = OnceLock::new();
        let mut cache = COMPILED
            .get_or_init(Default::default)
            .lock()
            .expect("cache");
        let mut compiled = |p: &str| {
            cache
                .entry(p.to_owned())
                .or_insert_with(|| regex::Regex::new(p).expect("pattern"))
                .is_match(s)
        };
        compiled(pattern) && compiled(ID_SHAPE)
    }

    /// The document's id patterns say what `crate::ids` enforces, on the ids the project's
    /// tests name and on the edges of each rule (length is the schema's `maxLength`).
    #[test]
    fn id_patterns_agree_with_the_id_rules() {
        let trace = trace_id_pattern();
        let text = text_id_pattern();
        let mut samples: Vec<String> = [
            "",
            ".",
            "..",
            "...",
            "a",
            "a.",
            ".a",
            "a..",
            "abc-1.2:3_x",
            "a b",
            "a/b",
            "é",
            "EN57 1021",
            "160EC-0042",
            "ET22 (2)",
            "Łódź #4",
            "A+B/C,D'E",
            " EN57",
            "EN57 ",
            "EN57<script>",
            "EN57\u{1F682}",
            "EN57\u{200B}1021",
            "EN57\u{7}",
            "a\tb",
            "a  b",
            "J2'",
            "x;y",
            "x?y",
            "x%y",
            "x\\y",
            "x]y",
            "x^y",
            "x[y",
            "-",
            ":",
            "_",
            "é.é",
            "日本語",
            "٣٤",
            "a\nb",
            "Ⓐb",
            "a\u{345}",
            "a\u{2028}b",
            "a\u{A0}b",
            "x\u{FEFF}",
            "Ω-Ж",
            "a\u{7F}",
            "a\u{85}",
            "½",
        ]
        .iter()
        .map(|s| s.to_string())
        .collect();
        samples.extend(ID_PUNCTUATION.chars().map(|c| format!("a{c}b")));
        samples.extend(ID_PUNCTUATION.chars().map(|c| c.to_string()));
        for s in &samples {
            assert_eq!(
                matches(&trace, s),
                TraceId::parse("t", s).is_ok(),
                "trace id {s:?} against {trace}"
            );
            assert_eq!(
                matches(&text, s),
                VehicleId::parse("v", s).is_ok(),
                "text id {s:?} against {text}"
            );
        }
    }

    /// Every character of U+0000–U+FFFF between two letters: the pattern admits it exactly when
    /// the rule does (characters that Unicode NFC changes are left out: the rule reads their
    /// normal form).
    #[test]
    fn the_text_id_class_is_the_rules_character_by_character() {
        use unicode_normalization::UnicodeNormalization;
        let text = text_id_pattern();
        let trace = trace_id_pattern();
        let mut checked = 0;
        for c in (0..=0xFFFF_u32).filter_map(char::from_u32) {
            let s = format!("a{c}b");
            if s.nfc().collect::<String>() != s {
                continue;
            }
            checked += 1;
            assert_eq!(
                matches(&text, &s),
                VehicleId::parse("v", &s).is_ok(),
                "U+{:04X}",
                c as u32
            );
            assert_eq!(
                matches(&trace, &s),
                TraceId::parse("t", &s).is_ok(),
                "U+{:04X}",
                c as u32
            );
        }
        assert!(checked > 60_000, "{checked}");
    }

    #[test]
    fn every_joint_is_in_the_enum_and_nothing_else() {
        let v = serde_json::to_value(JointName::schema()).expect("schema");
        let listed: Vec<String> = serde_json::from_value(v["enum"].clone()).expect("enum");
        assert_eq!(listed, JOINTS);
        for j in &listed {
            assert!(JointName::parse("joint", j).is_ok(), "{j}");
        }
    }
}

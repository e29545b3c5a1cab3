//! Traces as CSV, the shape a data logger writes: `# key: value` metadata lines, a header row
//! of channel names (`t_s` first), then one row per sample. Read into the same [`TraceDoc`].
//!
//! ```text
//! # format: pantograph-trace/1
//! # trace_id: EN57-1021-J1-2026-03-02
//! # vehicle_id: EN57-1021
//! # pantograph.model: 160EC
//! # pantograph.serial: 160EC-0042
//! # recorded_at: 2026-03-02T07:15:00Z
//! # test.kind: pendulum
//! # test.joint: J1
//! # test.rig: {"pin_radius_m": 0.01}
//! t_s,alpha_deg
//! 0,74.2
//! 0.002,74.19
//! ```
//!
//! Metadata keys are the contract's field paths; `test.rig` and `test.protocol` are JSON objects,
//! `test.gauge_resolution_n` (a `static_force` test's) a JSON number. Rows are read by
//! the `csv` crate: separated by `,` (decimal point `.`) or, when the header row holds a `;`,
//! by `;` with a decimal comma or point (`0,002;74,19` — what European spreadsheet tools write);
//! fields may be quoted; `nan`/`inf` are rejected like any non-finite value. Blank lines are
//! ignored; `\r\n` line ends are accepted. A refusal names the channel and sample
//! (`channels.alpha_deg[2]`) or the line, and says the row, the column and why. The rows go
//! straight into the typed document a JSON upload is read into ([`WireDoc`]: the samples as
//! `f64`s, the metadata as its fields) and it is validated by [`TraceDoc::from_wire`], exactly
//! like a JSON upload.

use std::fmt::Write as _;

use serde_json::{Map, Value};

use crate::trace::wire::{Channels, WireDoc, WirePantograph};
use crate::trace::{MAX_CHANNELS, MAX_SAMPLES, TraceDoc, TraceError};

/// Metadata keys accepted in the `# key: value` header.
pub const META_KEYS: [&str; 11] = [
    "format",
    "trace_id",
    "vehicle_id",
    "pantograph.model",
    "pantograph.serial",
    "recorded_at",
    "test.kind",
    "test.joint",
    "test.rig",
    "test.protocol",
    "test.gauge_resolution_n",
];

/// Why a CSV body was refused: its structure (`Malformed`) or a contract rule (`Invalid`).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum CsvError {
    #[error("{0}")]
    Malformed(TraceError),
    #[error("{0}")]
    Invalid(TraceError),
}

fn malformed(field: impl Into<String>, message: impl Into<String>) -> CsvError {
    CsvError::Malformed(TraceError {
        field: field.into(),
        message: message.into(),
    })
}

/// Parses a CSV trace into a validated document.
pub fn parse(bytes: &[u8]) -> Result<TraceDoc, CsvError> {
    TraceDoc::from_wire(to_wire(bytes)?).map_err(CsvError::Invalid)
}

/// The separator of the data rows, read from the header row: `;` when the header holds one
/// (European tools, which then write decimal commas: `0,002;74,19`), else `,`.
fn separator(header_line: &str) -> u8 {
    if header_line.contains(';') {
        b';'
    } else {
        b','
    }
}

/// A value as a number: `.` as the decimal point, or — with `;` separators — a decimal comma
/// (`74,19`). Thousands separators are not read (`1.234,5` is refused).
fn number(field: &str, sep: u8) -> Option<f64> {
    let owned;
    let text = if sep == b';' && field.contains(',') && !field.contains('.') {
        owned = field.replacen(',', ".", 1);
        owned.as_str()
    } else {
        field
    };
    text.parse::<f64>().ok().filter(|x| x.is_finite())
}

/// The CSV as the typed document (not yet validated).
pub fn to_wire(bytes: &[u8]) -> Result<WireDoc, CsvError> {
    let text = std::str::from_utf8(bytes)
        .map_err(|e| malformed("body", format!("not UTF-8 text: {e}")))?;
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let mut doc = WireDoc::default();
    let mut panto: Option<WirePantograph> = None;
    // The test object as a JSON upload sends it (stored verbatim): `test.rig`,
    // `test.protocol` and `test.gauge_resolution_n` are JSON values, the rest strings.
    let mut test = Map::new();
    // The `# key: value` head, up to the header row; the rest is the csv crate's.
    let mut offset = 0;
    let mut header_line_no = 0;
    for (i, raw) in text.split_inclusive('\n').enumerate() {
        let line_no = i + 1;
        let line = raw.trim_end_matches(['\n', '\r']);
        if line.trim().is_empty() {
            offset += raw.len();
            continue;
        }
        let Some(meta) = line.strip_prefix('#') else {
            header_line_no = line_no;
            break;
        };
        offset += raw.len();
        let (key, value) = meta.split_once(':').ok_or_else(|| {
            malformed(
                format!("csv.line[{line_no}]"),
                "a metadata line is `# key: value`",
            )
        })?;
        let (key, value) = (key.trim(), value.trim());
        if !META_KEYS.contains(&key) {
            return Err(malformed(
                key.chars().take(64).collect::<String>(),
                format!("unknown metadata key (allowed: {})", META_KEYS.join(", ")),
            ));
        }
        let set = |slot: &mut Option<String>| slot.replace(value.to_owned()).is_some();
        let twice = match key {
            "format" => set(&mut doc.format),
            "trace_id" => set(&mut doc.trace_id),
            "vehicle_id" => set(&mut doc.vehicle_id),
            "recorded_at" => set(&mut doc.recorded_at),
            "pantograph.model" => set(&mut panto.get_or_insert_default().model),
            "pantograph.serial" => set(&mut panto.get_or_insert_default().serial),
            _ => {
                let name = key.strip_prefix("test.").unwrap_or(key);
                let value = if matches!(name, "rig" | "protocol" | "gauge_resolution_n") {
                    serde_json::from_str::<Value>(value)
                        .map_err(|e| malformed(key, format!("not valid JSON: {e}")))?
                } else {
                    Value::String(value.to_owned())
                };
                test.insert(name.to_owned(), value).is_some()
            }
        };
        // A key given twice is the same rule as a key repeated in a JSON object: 422 naming it.
        if twice {
            return Err(CsvError::Invalid(TraceError {
                field: key.to_owned(),
                message: format!("`{key}` is given twice in the metadata"),
            }));
        }
    }
    if header_line_no == 0 {
        return Err(malformed(
            "channels",
            "no header row (channel names, `t_s` first) after the metadata",
        ));
    }
    let data = &text[offset..];
    let sep = separator(data.lines().next().unwrap_or(""));
    // The file's line of a record: the header's line plus the line ends before its first byte.
    let line_of = |p: Option<&csv::Position>| {
        p.map_or(header_line_no, |p| {
            // A `\r\n` ends a record at its `\r`: the next one's position is on the `\n`.
            let mut at = (p.byte() as usize).min(data.len());
            while data
                .as_bytes()
                .get(at)
                .is_some_and(|b| matches!(b, b'\r' | b'\n'))
            {
                at += 1;
            }
            header_line_no
                + data.as_bytes()[..at]
                    .iter()
                    .filter(|b| **b == b'\n')
                    .count()
        })
    };
    let mut reader = csv::ReaderBuilder::new()
        .delimiter(sep)
        .trim(csv::Trim::All)
        .comment(Some(b'#'))
        .from_reader(data.as_bytes());
    let names: Vec<String> = reader
        .headers()
        .map_err(|e| {
            malformed(
                format!("csv.line[{header_line_no}]"),
                format!("header row: {e}"),
            )
        })?
        .iter()
        .map(str::to_owned)
        .collect();
    if names.len() > MAX_CHANNELS {
        return Err(malformed(
            "channels",
            format!("{} channels, more than {MAX_CHANNELS}", names.len()),
        ));
    }
    if names.first().map(String::as_str) != Some("t_s") {
        let hint = if sep == b',' && names.len() == 1 && names[0].contains('\t') {
            " (tab-separated? use `,` or `;`)"
        } else {
            ""
        };
        return Err(malformed(
            format!("csv.line[{header_line_no}]"),
            format!("the header row must start with the channel `t_s`{hint}"),
        ));
    }
    let mut seen = std::collections::HashSet::new();
    for f in &names {
        if !seen.insert(f.as_str()) {
            return Err(CsvError::Invalid(TraceError {
                field: format!("channels.{f}"),
                message: "channel named twice in the header row".into(),
            }));
        }
    }
    let sep_name = if sep == b';' { "`;`" } else { "`,`" };
    let mut columns: Vec<Vec<f64>> = vec![Vec::new(); names.len()];
    for (row, record) in reader.records().enumerate() {
        let record = record.map_err(|e| {
            let line = line_of(e.position());
            let why = match e.kind() {
                csv::ErrorKind::UnequalLengths { len, expected_len, .. } => format!(
                    "row {} has {len} values, but the header has {expected_len} channels ({sep_name}-separated)",
                    row + 1
                ),
                _ => format!("row {}: {e}", row + 1),
            };
            malformed(format!("csv.line[{line}]"), why)
        })?;
        if row >= MAX_SAMPLES {
            return Err(malformed(
                "channels.t_s",
                format!("more than the limit of {MAX_SAMPLES} samples"),
            ));
        }
        for ((col, name), f) in columns.iter_mut().zip(&names).zip(record.iter()) {
            let x = number(f, sep).ok_or_else(|| {
                let why = if sep == b',' && f.contains(';') {
                    " — the header row is `,`-separated but this row uses `;`"
                } else if sep == b',' && f.is_empty() {
                    " — empty (a decimal comma in a `,`-separated file splits a value in two: use `;` as the separator)"
                } else {
                    ""
                };
                // Only a refusal needs its line (counting them for every row is quadratic).
                let line = line_of(record.position());
                CsvError::Invalid(TraceError {
                    field: format!("channels.{name}[{row}]"),
                    message: format!(
                        "`{}` is not a finite number (line {line}, row {}, column `{name}`){why}",
                        f.chars().take(32).collect::<String>(),
                        row + 1
                    ),
                })
            })?;
            col.push(x);
        }
    }
    doc.pantograph = panto;
    if !test.is_empty() {
        doc.test = Some(test);
    }
    doc.channels = Some(Channels(names.into_iter().zip(columns).collect()));
    Ok(doc)
}

/// Writes a document in the CSV shape that [`parse`] reads (numbers in Rust's shortest
/// round-trip form, so the values read back bit-identical).
pub fn write(doc: &TraceDoc) -> String {
    let mut s = String::new();
    let mut meta = |k: &str, v: &str| {
        let _ = writeln!(s, "# {k}: {v}");
    };
    meta("format", crate::trace::FORMAT);
    if let Some(id) = &doc.trace_id {
        meta("trace_id", id);
    }
    meta("vehicle_id", &doc.vehicle_id);
    meta("pantograph.model", &doc.pantograph_model);
    if let Some(serial) = &doc.pantograph_serial {
        meta("pantograph.serial", serial);
    }
    meta("recorded_at", &doc.recorded_at);
    meta("test.kind", doc.kind.as_str());
    if let Some(j) = &doc.joint {
        meta("test.joint", j);
    }
    if let Some(rig) = doc.test.get("rig") {
        meta("test.rig", &rig.to_string());
    }
    if let Some(p) = doc.test.get("protocol") {
        meta("test.protocol", &p.to_string());
    }
    if let Some(r) = doc.test.get("gauge_resolution_n") {
        meta("test.gauge_resolution_n", &r.to_string());
    }
    let names: Vec<&str> = doc.channels.iter().map(|(n, _)| n.as_str()).collect();
    let _ = writeln!(s, "{}", names.join(","));
    let n = doc.channels.first().map_or(0, |(_, v)| v.len());
    for i in 0..n {
        for (k, (_, v)) in doc.channels.iter().enumerate() {
            if k > 0 {
                s.push(',');
            }
            let _ = write!(s, "{:?}", v.get(i).copied().unwrap_or(f64::NAN));
        }
        s.push('\n');
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    const CSV: &str = "# format: pantograph-trace/1\r\n# trace_id: t-1\n# vehicle_id: EN57-1021\n\
        # pantograph.model: 160EC\n# pantograph.serial: 160EC-0042\n# recorded_at: 2026-03-02T07:15:00Z\n\
        # test.kind: pendulum\n# test.joint: J1\n# test.rig: {}\n\nt_s,alpha_deg\n0,74.2\n0.002,74.19\r\n0.004, 74.17\n";

    #[test]
    fn reads_the_documented_shape_and_round_trips() {
        let d = parse(CSV.as_bytes()).expect("valid CSV");
        assert_eq!(d.trace_id.as_deref(), Some("t-1"));
        assert_eq!(d.channel("alpha_deg"), Some(&[74.2, 74.19, 74.17][..]));
        let again = parse(write(&d).as_bytes()).expect("round trip");
        assert_eq!(again, d);
        // Same document as JSON.
        assert_eq!(TraceDoc::from_value(&d.to_value()).expect("json"), d);
    }

    #[test]
    fn errors_name_the_field() {
        let field = |s: &str| match parse(s.as_bytes()) {
            Err(CsvError::Malformed(e) | CsvError::Invalid(e)) => e.field,
            Ok(_) => panic!("accepted: {s}"),
        };
        assert_eq!(
            field(&CSV.replace("0.002,74.19", "0.002,NaN")),
            "channels.alpha_deg[1]"
        );
        assert_eq!(
            field(&CSV.replace("0.002,74.19", "0.002,x")),
            "channels.alpha_deg[1]"
        );
        assert_eq!(field(&CSV.replace("0.004, 74.17", "0.004")), "csv.line[14]");
        assert_eq!(
            field(&CSV.replace("# test.joint: J1", "# test.joint: J12")),
            "test.joint"
        );
        assert_eq!(
            field(&CSV.replace("# vehicle_id: EN57-1021\n", "")),
            "vehicle_id"
        );
        assert_eq!(
            field(&CSV.replace("# test.rig: {}", "# test.rig: {")),
            "test.rig"
        );
        assert_eq!(
            field(&CSV.replace("# test.rig: {}", "# colour: red")),
            "colour"
        );
        assert_eq!(
            field(&CSV.replace("0.004, 74.17", "0.001, 74.17")),
            "channels.t_s[2]"
        );
        assert_eq!(
            field(&CSV.replace("t_s,alpha_deg", "alpha_deg,t_s")),
            "csv.line[11]"
        );
        assert_eq!(field("# format: pantograph-trace/1\n"), "channels");
    }

    /// Issue 18: a metadata key given twice or a channel named twice breaks the same rule as a
    /// key repeated in a JSON object — `Invalid` (422) naming it, not `Malformed` (400).
    #[test]
    fn a_repeated_key_or_channel_is_invalid_naming_it() {
        for (csv, field) in [
            (
                CSV.replace(
                    "# test.joint: J1",
                    "# test.joint: J1\n# vehicle_id: EN57-9999",
                ),
                "vehicle_id",
            ),
            (
                CSV.replace("# test.rig: {}", "# test.rig: {}\n# pantograph.serial: S-2"),
                "pantograph.serial",
            ),
            (
                CSV.replace("t_s,alpha_deg", "t_s,alpha_deg,alpha_deg")
                    .replace("0,74.2", "0,74.2,1")
                    .replace("0.002,74.19", "0.002,74.19,1")
                    .replace("0.004, 74.17", "0.004, 74.17,1"),
                "channels.alpha_deg",
            ),
        ] {
            match parse(csv.as_bytes()) {
                Err(CsvError::Invalid(e)) => assert_eq!(e.field, field, "{}", e.message),
                other => panic!("{field}: {other:?}"),
            }
        }
    }

    /// Issue 18: what European tools write — `;` separators and decimal commas — reads as the
    /// same document; a mixed file is refused saying where and why.
    #[test]
    fn semicolons_and_decimal_commas_read_as_the_same_document() {
        let eu = CSV
            .replace("t_s,alpha_deg", "t_s;alpha_deg")
            .replace("0,74.2", "0;74,2")
            .replace("0.002,74.19", "0,002;74,19")
            .replace("0.004, 74.17", "0,004; 74.17");
        assert_eq!(
            parse(eu.as_bytes()).expect("`;` CSV"),
            parse(CSV.as_bytes()).unwrap()
        );
        let quoted = CSV.replace("0.002,74.19", "\"0.002\",\"74.19\"");
        assert_eq!(
            parse(quoted.as_bytes()).unwrap(),
            parse(CSV.as_bytes()).unwrap()
        );
        // A decimal comma in a `,`-separated file: a row with one value too many.
        match parse(CSV.replace("0.002,74.19", "0,002,74,19").as_bytes()) {
            Err(CsvError::Malformed(e)) => {
                assert_eq!(e.field, "csv.line[13]");
                assert!(e.message.contains("row 2 has 4 values"), "{}", e.message);
            }
            other => panic!("{other:?}"),
        }
        // Thousands separators are not guessed at.
        match parse(eu.replace("0,002;74,19", "0,002;1.074,19").as_bytes()) {
            Err(CsvError::Invalid(e)) => {
                assert_eq!(e.field, "channels.alpha_deg[1]");
                assert!(
                    e.message.contains("row 2, column `alpha_deg`"),
                    "{}",
                    e.message
                );
            }
            other => panic!("{other:?}"),
        }
    }
}

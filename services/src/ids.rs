//! Domain identifiers, parsed once at the edge (`TraceId`, `VehicleId`, `Serial`, `JointName`):
//! handlers and the store only ever see well-formed ids, and a bad one names its field.

use std::fmt;

/// Longest accepted identifier or free-text string, characters.
pub const MAX_STRING: usize = 256;

/// An identifier that failed to parse: which field, and why.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("`{field}`: {message}")]
pub struct IdError {
    pub field: String,
    pub message: String,
}

fn err(field: &str, message: impl Into<String>) -> IdError {
    IdError {
        field: field.to_owned(),
        message: message.into(),
    }
}

/// Characters that change how text prints without printing themselves: zero-width (U+200B–D,
/// U+2060, U+FEFF) and bidirectional controls (U+061C, U+200E–F, U+202A–E, U+2066–9). Two ids
/// differing only by these would be two vehicles that print the same (issue 18).
fn invisible(c: char) -> bool {
    matches!(c,
        '\u{061C}' | '\u{200B}'..='\u{200F}' | '\u{202A}'..='\u{202E}'
        | '\u{2060}'..='\u{2064}' | '\u{2066}'..='\u{2069}' | '\u{FEFF}')
}

/// Punctuation an id may hold besides letters, digits and spaces.
pub const ID_PUNCTUATION: &str = "-_.:/#()+',";

/// The rule for free-text identifiers (`vehicle_id`, `pantograph.serial`, `pantograph.model`),
/// returning the id in Unicode NFC — the form that is stored and compared, so two spellings of
/// one text are one id:
/// - non-empty, at most `MAX_STRING` characters, no leading or trailing space;
/// - letters and digits of any script, spaces, and `- _ . : / # ( ) + ' ,` only: no control,
///   zero-width, bidirectional or other symbol characters;
/// - not `.` or `..` alone (a path segment, not a name).
pub fn normalise_text(field: &str, s: &str) -> Result<String, IdError> {
    use unicode_normalization::UnicodeNormalization;
    let n: String = s.nfc().collect();
    if n.trim().is_empty() {
        return Err(err(field, "must not be empty"));
    }
    if n.chars().count() > MAX_STRING {
        return Err(err(field, format!("longer than {MAX_STRING} characters")));
    }
    if n.trim() != n {
        return Err(err(field, "must not start or end with a space"));
    }
    if let Some(c) = n.chars().find(|c| c.is_control() || invisible(*c)) {
        return Err(err(
            field,
            format!(
                "contains U+{:04X}, a control, zero-width or bidirectional character",
                c as u32
            ),
        ));
    }
    if let Some(c) = n
        .chars()
        .find(|c| !(c.is_alphanumeric() || *c == ' ' || ID_PUNCTUATION.contains(*c)))
    {
        return Err(err(
            field,
            format!(
                "contains `{c}` (U+{:04X}): ids hold letters, digits, spaces and {ID_PUNCTUATION}",
                c as u32
            ),
        ));
    }
    if n == "." || n == ".." {
        return Err(err(field, "must not be `.` or `..` alone"));
    }
    Ok(n)
}

/// The trace id rule: 1–256 ASCII letters, digits and `- _ . :`, not `.` or `..` alone.
pub fn check_trace_id(field: &str, s: &str) -> Result<String, IdError> {
    let s = normalise_text(field, s)?;
    if !s
        .chars()
        .all(|c| c.is_ascii_alphanumeric() || "-_.:".contains(c))
    {
        return Err(err(field, "may contain only letters, digits and - _ . :"));
    }
    Ok(s)
}

macro_rules! id_type {
    ($(#[$m:meta])* $name:ident, $check:expr) => {
        $(#[$m])*
        #[derive(Debug, Clone, PartialEq, Eq, Hash, PartialOrd, Ord)]
        pub struct $name(String);

        impl $name {
            /// Parses `s` as this identifier; `field` names it in the error.
            pub fn parse(field: &str, s: &str) -> Result<Self, IdError> {
                let check: fn(&str, &str) -> Result<String, IdError> = $check;
                Ok($name(check(field, s)?))
            }
            pub fn as_str(&self) -> &str {
                &self.0
            }
        }

        impl fmt::Display for $name {
            fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                f.write_str(&self.0)
            }
        }

        impl AsRef<str> for $name {
            fn as_ref(&self) -> &str {
                &self.0
            }
        }
    };
}

id_type!(
    /// A trace id: 1–256 letters, digits and `- _ . :` (the contract's `trace_id` rule).
    TraceId,
    check_trace_id
);
id_type!(
    /// A vehicle id (`vehicle_id`): free text by [`normalise_text`], stored in NFC.
    VehicleId,
    normalise_text
);
id_type!(
    /// A pantograph serial (`pantograph.serial`): free text by [`normalise_text`], in NFC.
    Serial,
    normalise_text
);

/// Joint names that a fit can report.
pub const JOINTS: [&str; 11] = [
    "J1", "J2", "J2'", "J3", "J4", "J5", "J6", "J7", "J8", "J9", "custom",
];

id_type!(
    /// A joint of the 160EC (`J1`…`J9`, `J2'`) or `custom`.
    JointName,
    |field, s| {
        if JOINTS.contains(&s) {
            Ok(s.to_owned())
        } else {
            Err(err(field, format!("unknown joint `{}` ({})", s.chars().take(16).collect::<String>(), JOINTS.join(" "))))
        }
    }
);

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ids_parse_or_name_their_field() {
        assert_eq!(
            TraceId::parse("id", "abc-1.2:3_x").unwrap().as_str(),
            "abc-1.2:3_x"
        );
        assert_eq!(TraceId::parse("id", "a b").unwrap_err().field, "id");
        assert!(TraceId::parse("id", "").is_err());
        assert!(VehicleId::parse("vehicle", "EN57 1021").is_ok());
        assert!(VehicleId::parse("vehicle", "a\u{0}b").is_err());
        assert!(Serial::parse("serial", &"x".repeat(257)).is_err());
        assert!(JointName::parse("joint", "J2'").is_ok());
        assert_eq!(JointName::parse("joint", "J10").unwrap_err().field, "joint");
    }

    /// Issue 18: ids that print alike are one id (NFC), or refused; `.`/`..` alone refused.
    #[test]
    fn ids_are_nfc_and_hold_no_invisible_characters() {
        let composed = VehicleId::parse("v", "Z\u{00FC}rich-7").unwrap();
        let decomposed = VehicleId::parse("v", "Zu\u{0308}rich-7").unwrap();
        assert_eq!(composed, decomposed);
        assert_eq!(decomposed.as_str(), "Z\u{00FC}rich-7");
        for bad in [
            "EN57\u{200B}1021",
            "EN57\u{202E}1021",
            "EN57\u{2066}1021",
            "\u{FEFF}EN57",
            "EN57\u{7}",
            ".",
            "..",
            " EN57",
            "EN57 ",
            "EN57<script>",
            "EN57\u{1F682}",
        ] {
            let e = VehicleId::parse("vehicle_id", bad).unwrap_err();
            assert_eq!(e.field, "vehicle_id", "{bad:?}");
        }
        for bad in [".", "..", "a/b", "\u{00E9}t\u{00E9}"] {
            assert!(TraceId::parse("trace_id", bad).is_err(), "{bad:?}");
        }
        for ok in [
            "EN57 1021",
            "160EC-0042",
            "ET22 (2)",
            "Łódź #4",
            "A+B/C,D'E",
        ] {
            assert!(Serial::parse("serial", ok).is_ok(), "{ok:?}");
        }
    }
}

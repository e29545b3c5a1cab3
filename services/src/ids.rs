//! Domain identifiers, parsed once at the edge (`TraceId`, `VehicleId`, `Serial`, `JointName`):
//! handlers and the store only ever see well-formed ids, and a bad one names its field.

use std::fmt;

use crate::trace::MAX_STRING;

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

/// The contract's rule for free-text identifiers: non-empty, at most `MAX_STRING` characters,
/// no control characters.
fn check_text(field: &str, s: &str) -> Result<(), IdError> {
    if s.trim().is_empty() {
        return Err(err(field, "must not be empty"));
    }
    if s.chars().count() > MAX_STRING {
        return Err(err(field, format!("longer than {MAX_STRING} characters")));
    }
    if s.chars().any(char::is_control) {
        return Err(err(field, "contains control characters"));
    }
    Ok(())
}

macro_rules! id_type {
    ($(#[$m:meta])* $name:ident, $check:expr) => {
        $(#[$m])*
        #[derive(Debug, Clone, PartialEq, Eq, Hash, PartialOrd, Ord)]
        pub struct $name(String);

        impl $name {
            /// Parses `s` as this identifier; `field` names it in the error.
            pub fn parse(field: &str, s: &str) -> Result<Self, IdError> {
                let check: fn(&str, &str) -> Result<(), IdError> = $check;
                check(field, s)?;
                Ok($name(s.to_owned()))
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
    |field, s| {
        check_text(field, s)?;
        if !s
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || "-_.:".contains(c))
        {
            return Err(err(field, "may contain only letters, digits and - _ . :"));
        }
        Ok(())
    }
);
id_type!(
    /// A vehicle id (`vehicle_id`): free text, non-empty, no control characters.
    VehicleId,
    check_text
);
id_type!(
    /// A pantograph serial (`pantograph.serial`): free text, non-empty, no control characters.
    Serial,
    check_text
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
            Ok(())
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
}

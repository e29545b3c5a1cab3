//! Duplicate object keys in a JSON body: found before the body is read as a document, so
//! `{"vehicle_id": "A", "vehicle_id": "B"}` is refused naming the key instead of last-wins.
//!
//! A streaming walk (`serde::de::DeserializeSeed`): numbers and strings are skipped without
//! being kept, each object's keys are held only while it is open.

use std::collections::HashSet;
use std::fmt;

use serde::de::{DeserializeSeed, Deserializer, IgnoredAny, MapAccess, SeqAccess, Visitor};

/// The first key that appears twice in one object, as a field path (`test.rig.body`,
/// `channels.t_s`, `attachments[1].mass_kg`); `Ok(None)` when every object's keys are unique.
/// Malformed JSON (trailing characters included) is `Err`: the walk is also the upload's check
/// that the body is JSON at all, before it is read as a document.
pub fn first_duplicate_key(bytes: &[u8]) -> Result<Option<String>, serde_json::Error> {
    let mut found = None;
    let mut de = serde_json::Deserializer::from_slice(bytes);
    Walk {
        path: String::new(),
        found: &mut found,
    }
    .deserialize(&mut de)?;
    de.end()?;
    Ok(found)
}

struct Walk<'a> {
    path: String,
    found: &'a mut Option<String>,
}

impl<'de> DeserializeSeed<'de> for Walk<'_> {
    type Value = ();
    fn deserialize<D: Deserializer<'de>>(self, d: D) -> Result<(), D::Error> {
        d.deserialize_any(self)
    }
}

impl<'de> Visitor<'de> for Walk<'_> {
    type Value = ();

    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str("any JSON value")
    }
    fn visit_bool<E>(self, _: bool) -> Result<(), E> {
        Ok(())
    }
    fn visit_i64<E>(self, _: i64) -> Result<(), E> {
        Ok(())
    }
    fn visit_u64<E>(self, _: u64) -> Result<(), E> {
        Ok(())
    }
    fn visit_f64<E>(self, _: f64) -> Result<(), E> {
        Ok(())
    }
    fn visit_str<E>(self, _: &str) -> Result<(), E> {
        Ok(())
    }
    fn visit_unit<E>(self) -> Result<(), E> {
        Ok(())
    }
    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<(), A::Error> {
        let mut i = 0usize;
        loop {
            if self.found.is_some() {
                while seq.next_element::<IgnoredAny>()?.is_some() {}
                return Ok(());
            }
            let path = format!("{}[{i}]", self.path);
            let seed = Walk {
                path,
                found: &mut *self.found,
            };
            if seq.next_element_seed(seed)?.is_none() {
                return Ok(());
            }
            i += 1;
        }
    }
    fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<(), A::Error> {
        let mut keys = HashSet::new();
        while let Some(key) = map.next_key::<String>()? {
            let path = if self.path.is_empty() {
                key.clone()
            } else {
                format!("{}.{key}", self.path)
            };
            if self.found.is_some() {
                map.next_value::<IgnoredAny>()?;
                continue;
            }
            if !keys.insert(key) {
                *self.found = Some(path);
                map.next_value::<IgnoredAny>()?;
                continue;
            }
            map.next_value_seed(Walk {
                path,
                found: &mut *self.found,
            })?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_first_repeated_key_is_named_by_its_path() {
        let dup = |s: &str| first_duplicate_key(s.as_bytes()).unwrap();
        assert_eq!(dup(r#"{"a": 1, "b": [1, 2], "c": {"d": "x"}}"#), None);
        assert_eq!(dup(r#"{"a": 1, "a": 2}"#).as_deref(), Some("a"));
        assert_eq!(
            dup(r#"{"test": {"rig": {"body": {}, "body": {}}}}"#).as_deref(),
            Some("test.rig.body")
        );
        assert_eq!(
            dup(r#"{"x": [{"k": 1}, {"k": 1, "m": 2, "k": 3}]}"#).as_deref(),
            Some("x[1].k")
        );
        // The same key in two different objects is no duplicate.
        assert_eq!(dup(r#"{"p": {"k": 1}, "q": {"k": 1}}"#), None);
        assert!(first_duplicate_key(b"{\"a\": ").is_err());
        // Trailing characters, a NaN and an overflowing number are not JSON.
        for bad in [&b"{\"a\": 1} x"[..], b"{\"a\": NaN}", b"{\"a\": 1e400}"] {
            assert!(first_duplicate_key(bad).is_err(), "{bad:?}");
        }
    }
}

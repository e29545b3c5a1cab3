//! API key material: generation from the OS RNG, SHA-256 hashing and constant-time comparison.
//! Only the hash and an 8-character lookup prefix are ever stored; the key is shown once.

use sha2::{Digest, Sha256};
use subtle::ConstantTimeEq;

/// Every key starts with this tag, so leaked keys are easy to grep for.
pub const KEY_TAG: &str = "pw_";
/// Length of the stored lookup prefix (`pw_` plus 5 hex digits).
pub const PREFIX_LEN: usize = 8;

/// A fresh key: `pw_` + 64 lowercase hex digits (32 random bytes from the OS).
pub fn generate() -> Result<String, getrandom::Error> {
    let mut bytes = [0u8; 32];
    getrandom::fill(&mut bytes)?;
    Ok(format!("{KEY_TAG}{}", hex::encode(bytes)))
}

/// The lookup prefix of a presented key, if it is long enough to be one of ours.
pub fn prefix(key: &str) -> Option<&str> {
    key.get(..PREFIX_LEN).filter(|_| key.is_ascii())
}

/// Lowercase hex SHA-256 of the key text.
pub fn hash(key: &str) -> String {
    hex::encode(Sha256::digest(key.as_bytes()))
}

/// Constant-time equality of two hashes (time independent of where they differ).
pub fn hashes_equal(a: &str, b: &str) -> bool {
    a.len() == b.len() && bool::from(a.as_bytes().ct_eq(b.as_bytes()))
}

/// A random UUID (version 4) as text, for trace ids the client did not choose.
pub fn new_uuid() -> Result<String, getrandom::Error> {
    let mut b = [0u8; 16];
    getrandom::fill(&mut b)?;
    b[6] = (b[6] & 0x0f) | 0x40;
    b[8] = (b[8] & 0x3f) | 0x80;
    let h = hex::encode(b);
    Ok(format!(
        "{}-{}-{}-{}-{}",
        &h[..8],
        &h[8..12],
        &h[12..16],
        &h[16..20],
        &h[20..]
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keys_are_random_tagged_and_hash_stably() {
        let a = generate().expect("rng");
        let b = generate().expect("rng");
        assert_ne!(a, b);
        assert!(a.starts_with(KEY_TAG) && a.len() == 3 + 64);
        assert_eq!(prefix(&a).map(str::len), Some(PREFIX_LEN));
        assert_eq!(prefix("pw_12"), None);
        assert_eq!(hash("abc").len(), 64);
        assert!(hashes_equal(&hash(&a), &hash(&a)));
        assert!(!hashes_equal(&hash(&a), &hash(&b)));
        assert!(!hashes_equal("ab", "abc"));
        let u = new_uuid().expect("rng");
        assert_eq!(u.len(), 36);
        assert_eq!(&u[14..15], "4");
    }
}

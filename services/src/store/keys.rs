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

/// Constant-time equality of two hashes: `subtle` compares every byte whatever the first
/// difference, so the time tells nothing about how much of a guess was right. Only the length
/// may short-cut, and it is public (every stored hash is 64 hex digits).
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

    /// The compare path: equal hashes match; one differing digit anywhere (first, middle,
    /// last), a case change, a prefix or an extension of the hash never does.
    #[test]
    fn compare_path_matches_only_the_exact_hash() {
        let key = generate().expect("rng");
        let h = hash(&key);
        assert!(hashes_equal(&h, &hash(&key.clone())));
        for i in [0, 1, 31, 32, 62, 63] {
            let mut b = h.clone().into_bytes();
            b[i] = if b[i] == b'0' { b'f' } else { b'0' };
            let other = String::from_utf8(b).expect("hex");
            assert!(!hashes_equal(&h, &other), "differs at {i}");
            assert!(!hashes_equal(&other, &h), "differs at {i} (swapped)");
        }
        assert!(!hashes_equal(&h, &h.to_uppercase()) || h.bytes().all(|c| c.is_ascii_digit()));
        assert!(!hashes_equal(&h, &h[..63]));
        assert!(!hashes_equal(&h, &format!("{h}0")));
        assert!(!hashes_equal(&h, ""));
        // The stored form is the SHA-256 of the key, never the key (FIPS 180-2 test vector).
        assert_eq!(
            hash("abc"),
            "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"
        );
        assert_ne!(hash(&key), key);
    }
}

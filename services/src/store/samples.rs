//! Samples codec: a trace's channels packed into one lossless, compact, checksummed blob.
//! Pure functions; decoding returns an error (never panics) on truncated or corrupted input.
//!
//! # Format (version 1, all integers little-endian)
//!
//! ```text
//! header:  "PWSM" | version u8 = 1 | n_channels u16
//!          per channel: name_len u16 | name (UTF-8) | n_values u32
//!          crc32 u32   (CRC-32 of the header bytes above + every value's `to_bits` LE)
//!          body_len u32
//! body:    raw DEFLATE of the concatenated channel encodings:
//!          mode u8 = 0 (decimal) | scale k u8 | order u8 (1|2)
//!                       | n_exceptions varint | per exception: index step varint, bits u64
//!                       | zigzag varints of the order-th differences of n_i,
//!                         where value_i == (n_i as f64) / 10^k bit for bit (or an exception)
//!          mode u8 = 1 (xor)     | 8 byte planes of bits_i XOR bits_{i-1} (byte-shuffled)
//! ```
//!
//! Measured data are decimal numbers printed by a logger (`74.19`, `0.002`): their binary
//! mantissas look random, so XOR/Gorilla coding alone stays near 6–7 bytes per value. The
//! decimal mode finds the smallest `k` for which every value is exactly `n / 10^k` (checked on
//! `to_bits`; `-0.0`, NaN and non-decimal values are stored raw as exceptions, and a channel with
//! more than 1/8 exceptions uses the XOR mode); because `n` and
//! `10^k` are exact doubles and IEEE division is correctly rounded, `n as f64 / 10^k` *is* the
//! double a correct parser produced from the decimal text. Uniform time steps become zeros at
//! order 2; noisy signals become small first differences.
//!
//! DEFLATE via `flate2` (pure-Rust backend, no C toolchain): after the modelling above the
//! residual stream is small and repetitive, and zstd would save a few percent at the price of a
//! C build. Measured on `J1_baseline.json` (2 channels × 15001 values, `t_s` and `alpha_deg`):
//! **12 511 bytes for 30 002 values → 0.417 bytes per stored sample value** (8 raw, 240 016
//! bytes), see the test `j1_baseline_bytes_per_sample`.

use std::io::{Read, Write};

use flate2::Compression;
use flate2::read::DeflateDecoder;
use flate2::write::DeflateEncoder;

/// Channel name → values, in document order (`t_s` first).
pub type Channels = Vec<(String, Vec<f64>)>;

const MAGIC: &[u8; 4] = b"PWSM";
const VERSION: u8 = 1;
const MODE_DECIMAL: u8 = 0;
const MODE_XOR: u8 = 1;
/// Largest decimal scale tried: 10^15 keeps `n` well inside the exact-integer range of f64.
const MAX_SCALE: u8 = 15;
const EXACT_INT: f64 = 9_007_199_254_740_992.0; // 2^53

/// Why a blob could not be encoded or decoded.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum CodecError {
    /// Input cannot be represented (too many channels, a name or channel too long).
    #[error("samples cannot be encoded: {0}")]
    Unencodable(String),
    /// The blob is truncated, malformed or fails its checksum.
    #[error("samples blob is corrupt: {0}")]
    Corrupt(String),
}

fn corrupt(msg: impl Into<String>) -> CodecError {
    CodecError::Corrupt(msg.into())
}

/// Encodes channels into the versioned, compressed, checksummed format described above.
pub fn encode(channels: &[(String, Vec<f64>)]) -> Result<Vec<u8>, CodecError> {
    let n_channels = u16::try_from(channels.len())
        .map_err(|_| CodecError::Unencodable(format!("{} channels", channels.len())))?;
    let mut header = Vec::with_capacity(16 + channels.len() * 16);
    header.extend_from_slice(MAGIC);
    header.push(VERSION);
    header.extend_from_slice(&n_channels.to_le_bytes());
    for (name, values) in channels {
        let len = u16::try_from(name.len()).map_err(|_| {
            CodecError::Unencodable(format!("channel name of {} bytes", name.len()))
        })?;
        let n = u32::try_from(values.len()).map_err(|_| {
            CodecError::Unencodable(format!("channel {name} has {} values", values.len()))
        })?;
        header.extend_from_slice(&len.to_le_bytes());
        header.extend_from_slice(name.as_bytes());
        header.extend_from_slice(&n.to_le_bytes());
    }
    let crc = checksum(&header, channels.iter().map(|(_, v)| v.as_slice()));

    let mut body = Vec::new();
    for (_, values) in channels {
        encode_channel(values, &mut body);
    }
    let mut enc = DeflateEncoder::new(Vec::new(), Compression::best());
    enc.write_all(&body)
        .map_err(|e| CodecError::Unencodable(e.to_string()))?;
    let compressed = enc
        .finish()
        .map_err(|e| CodecError::Unencodable(e.to_string()))?;
    let body_len = u32::try_from(compressed.len())
        .map_err(|_| CodecError::Unencodable("compressed body over 4 GiB".into()))?;

    let mut out = header;
    out.extend_from_slice(&crc.to_le_bytes());
    out.extend_from_slice(&body_len.to_le_bytes());
    out.extend_from_slice(&compressed);
    Ok(out)
}

/// Decodes a blob made by [`encode`], verifying structure and checksum.
pub fn decode(bytes: &[u8]) -> Result<Channels, CodecError> {
    let mut r = Reader::new(bytes);
    if r.take(4)? != MAGIC {
        return Err(corrupt("bad magic"));
    }
    let version = r.u8()?;
    if version != VERSION {
        return Err(corrupt(format!("unsupported version {version}")));
    }
    let n_channels = r.u16()? as usize;
    let mut names = Vec::with_capacity(n_channels.min(1024));
    let mut total_values: usize = 0;
    for _ in 0..n_channels {
        let len = r.u16()? as usize;
        let name = std::str::from_utf8(r.take(len)?)
            .map_err(|_| corrupt("channel name is not UTF-8"))?
            .to_owned();
        let n = r.u32()? as usize;
        total_values = total_values.saturating_add(n);
        names.push((name, n));
    }
    let header_end = r.pos;
    let crc = r.u32()?;
    let body_len = r.u32()? as usize;
    let compressed = r.take(body_len)?;
    if r.pos != bytes.len() {
        return Err(corrupt("trailing bytes after body"));
    }
    // Worst case per value: a 10-byte varint plus a 10 + 8-byte exception; bounds a corrupt
    // stream's decompressed size by what the header allows.
    let limit = total_values
        .saturating_mul(28)
        .saturating_add(16 * n_channels + 64);
    let mut body = Vec::new();
    DeflateDecoder::new(compressed)
        .take(limit as u64 + 1)
        .read_to_end(&mut body)
        .map_err(|e| corrupt(format!("deflate: {e}")))?;
    if body.len() > limit {
        return Err(corrupt("body longer than its header allows"));
    }
    let mut br = Reader::new(&body);
    let mut out = Vec::with_capacity(names.len());
    for (name, n) in names {
        let values = decode_channel(&mut br, n)?;
        out.push((name, values));
    }
    if br.pos != body.len() {
        return Err(corrupt("trailing bytes in body"));
    }
    let actual = checksum(&bytes[..header_end], out.iter().map(|(_, v)| v.as_slice()));
    if actual != crc {
        return Err(corrupt(format!(
            "checksum mismatch: stored {crc:08x}, computed {actual:08x}"
        )));
    }
    Ok(out)
}

fn checksum<'a>(header: &[u8], channels: impl Iterator<Item = &'a [f64]>) -> u32 {
    let mut h = crc32fast::Hasher::new();
    h.update(header);
    for values in channels {
        for v in values {
            h.update(&v.to_bits().to_le_bytes());
        }
    }
    h.finalize()
}

fn pow10(k: u8) -> f64 {
    10f64.powi(i32::from(k))
}

/// Integer mantissa of `v` at scale `k`, if `(n as f64) / 10^k` reproduces `v` bit for bit.
fn scaled(v: f64, k: u8) -> Option<i64> {
    let p = pow10(k);
    let n = (v * p).round();
    if !n.is_finite() || n.abs() >= EXACT_INT {
        return None;
    }
    let n = n as i64;
    ((n as f64 / p).to_bits() == v.to_bits()).then_some(n)
}

fn min_scale(v: f64) -> Option<u8> {
    if !v.is_finite() {
        return None;
    }
    (0..=MAX_SCALE).find(|&k| scaled(v, k).is_some())
}

/// (scale `k`, mantissas, exceptions as (index, bits)).
type DecimalForm = (u8, Vec<i64>, Vec<(usize, u64)>);

/// Decimal form of a channel: the common scale `k`, every value's mantissa, and the values that
/// have none (`-0.0`, NaN, non-decimal) as (index, bits) exceptions, their mantissa repeating the
/// previous one so that differences stay small. `None` when exceptions would dominate.
fn decimal_form(values: &[f64]) -> Option<DecimalForm> {
    let k = values
        .iter()
        .filter_map(|&v| min_scale(v))
        .max()
        .unwrap_or(0);
    let mut ints = Vec::with_capacity(values.len());
    let mut exceptions = Vec::new();
    let mut prev = 0i64;
    for (i, &v) in values.iter().enumerate() {
        match scaled(v, k) {
            Some(n) => prev = n,
            None => exceptions.push((i, v.to_bits())),
        }
        ints.push(prev);
    }
    (exceptions.len() * 8 <= values.len()).then_some((k, ints, exceptions))
}

fn diff(xs: &[i64]) -> Vec<i64> {
    let mut prev = 0i64;
    xs.iter()
        .map(|&x| {
            let d = x.wrapping_sub(prev);
            prev = x;
            d
        })
        .collect()
}

fn undiff(xs: &mut [i64]) {
    let mut acc = 0i64;
    for x in xs.iter_mut() {
        acc = acc.wrapping_add(*x);
        *x = acc;
    }
}

fn zigzag(x: i64) -> u64 {
    ((x << 1) ^ (x >> 63)) as u64
}

fn unzigzag(u: u64) -> i64 {
    ((u >> 1) as i64) ^ -((u & 1) as i64)
}

fn varint_len(mut u: u64) -> usize {
    let mut n = 1;
    while u >= 0x80 {
        u >>= 7;
        n += 1;
    }
    n
}

fn put_varint(mut u: u64, out: &mut Vec<u8>) {
    while u >= 0x80 {
        out.push((u as u8) | 0x80);
        u >>= 7;
    }
    out.push(u as u8);
}

fn encode_channel(values: &[f64], out: &mut Vec<u8>) {
    if let Some((k, ints, exceptions)) = decimal_form(values) {
        let d1 = diff(&ints);
        let d2 = diff(&d1);
        let cost = |d: &[i64]| d.iter().map(|&x| varint_len(zigzag(x))).sum::<usize>();
        let (order, resid) = if cost(&d2) < cost(&d1) {
            (2u8, d2)
        } else {
            (1u8, d1)
        };
        out.extend_from_slice(&[MODE_DECIMAL, k, order]);
        put_varint(exceptions.len() as u64, out);
        let mut last = 0usize;
        for (i, bits) in exceptions {
            put_varint((i - last) as u64, out);
            out.extend_from_slice(&bits.to_le_bytes());
            last = i;
        }
        for x in resid {
            put_varint(zigzag(x), out);
        }
    } else {
        out.push(MODE_XOR);
        let mut prev = 0u64;
        let xors: Vec<u64> = values
            .iter()
            .map(|v| {
                let b = v.to_bits();
                let x = b ^ prev;
                prev = b;
                x
            })
            .collect();
        for plane in 0..8 {
            out.extend(xors.iter().map(|x| (x >> (8 * plane)) as u8));
        }
    }
}

fn decode_channel(r: &mut Reader<'_>, n: usize) -> Result<Vec<f64>, CodecError> {
    match r.u8()? {
        MODE_DECIMAL => {
            let k = r.u8()?;
            if k > MAX_SCALE {
                return Err(corrupt(format!("decimal scale {k}")));
            }
            let order = r.u8()?;
            if !(1..=2).contains(&order) {
                return Err(corrupt(format!("difference order {order}")));
            }
            let n_exc = usize::try_from(r.varint()?).map_err(|_| corrupt("exception count"))?;
            if n_exc > n {
                return Err(corrupt("more exceptions than values"));
            }
            let mut exceptions = Vec::with_capacity(n_exc.min(r.remaining() / 9));
            let mut last = 0usize;
            for _ in 0..n_exc {
                let step = usize::try_from(r.varint()?).map_err(|_| corrupt("exception index"))?;
                last = last
                    .checked_add(step)
                    .filter(|&i| i < n)
                    .ok_or_else(|| corrupt("exception index out of range"))?;
                let b = r.take(8)?;
                let bits = u64::from_le_bytes([b[0], b[1], b[2], b[3], b[4], b[5], b[6], b[7]]);
                exceptions.push((last, bits));
            }
            let mut ints = Vec::with_capacity(n.min(r.remaining()));
            for _ in 0..n {
                ints.push(unzigzag(r.varint()?));
            }
            for _ in 0..order {
                undiff(&mut ints);
            }
            let p = pow10(k);
            let mut values: Vec<f64> = ints.into_iter().map(|i| i as f64 / p).collect();
            for (i, bits) in exceptions {
                values[i] = f64::from_bits(bits);
            }
            Ok(values)
        }
        MODE_XOR => {
            let planes = r.take(n.checked_mul(8).ok_or_else(|| corrupt("length"))?)?;
            let mut prev = 0u64;
            Ok((0..n)
                .map(|i| {
                    let x = (0..8).fold(0u64, |acc, p| {
                        acc | (u64::from(planes[p * n + i]) << (8 * p))
                    });
                    prev ^= x;
                    f64::from_bits(prev)
                })
                .collect())
        }
        m => Err(corrupt(format!("unknown channel mode {m}"))),
    }
}

struct Reader<'a> {
    buf: &'a [u8],
    pos: usize,
}

impl<'a> Reader<'a> {
    fn new(buf: &'a [u8]) -> Self {
        Self { buf, pos: 0 }
    }
    fn remaining(&self) -> usize {
        self.buf.len() - self.pos
    }
    fn take(&mut self, n: usize) -> Result<&'a [u8], CodecError> {
        let end = self
            .pos
            .checked_add(n)
            .filter(|&e| e <= self.buf.len())
            .ok_or_else(|| corrupt("truncated"))?;
        let s = &self.buf[self.pos..end];
        self.pos = end;
        Ok(s)
    }
    fn u8(&mut self) -> Result<u8, CodecError> {
        Ok(self.take(1)?[0])
    }
    fn u16(&mut self) -> Result<u16, CodecError> {
        let b = self.take(2)?;
        Ok(u16::from_le_bytes([b[0], b[1]]))
    }
    fn u32(&mut self) -> Result<u32, CodecError> {
        let b = self.take(4)?;
        Ok(u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    }
    fn varint(&mut self) -> Result<u64, CodecError> {
        let mut u = 0u64;
        for shift in (0..64).step_by(7) {
            let b = self.u8()?;
            u |= u64::from(b & 0x7f) << shift;
            if b & 0x80 == 0 {
                return Ok(u);
            }
        }
        Err(corrupt("varint too long"))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn assert_bit_identical(a: &[(String, Vec<f64>)], b: &[(String, Vec<f64>)]) {
        assert_eq!(a.len(), b.len());
        for ((na, va), (nb, vb)) in a.iter().zip(b) {
            assert_eq!(na, nb);
            assert_eq!(va.len(), vb.len(), "channel {na}");
            for (i, (x, y)) in va.iter().zip(vb).enumerate() {
                assert_eq!(
                    x.to_bits(),
                    y.to_bits(),
                    "channel {na} value {i}: {x} vs {y}"
                );
            }
        }
    }

    fn roundtrip(ch: &[(String, Vec<f64>)]) -> Vec<u8> {
        let bytes = encode(ch).expect("encode");
        let back = decode(&bytes).expect("decode");
        assert_bit_identical(ch, &back);
        bytes
    }

    /// Deterministic pseudo-random numbers (SplitMix64) so the test needs no RNG crate.
    fn splitmix(state: &mut u64) -> u64 {
        *state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = *state;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    fn logger_like(n: usize) -> Channels {
        let mut s = 7u64;
        let t: Vec<f64> = (0..n)
            .map(|i| format!("{:.3}", i as f64 * 0.002).parse().unwrap())
            .collect();
        let a: Vec<f64> = t
            .iter()
            .map(|&t| {
                let noise = (splitmix(&mut s) % 21) as f64 / 100.0 - 0.1;
                let v = 74.2 * (-t / 9.0).exp() * (3.0 * t).cos() + noise;
                format!("{v:.2}").parse().unwrap()
            })
            .collect();
        vec![("t_s".into(), t), ("alpha_deg".into(), a)]
    }

    #[test]
    fn decimal_channels_roundtrip_compactly() {
        let ch = logger_like(15001);
        let bytes = roundtrip(&ch);
        let per_value = bytes.len() as f64 / 30002.0;
        assert!(per_value <= 4.0, "{per_value} bytes per value");
    }

    #[test]
    fn arbitrary_bits_roundtrip() {
        let mut s = 42u64;
        let mut weird = vec![
            0.0,
            -0.0,
            f64::NAN,
            -f64::NAN,
            f64::from_bits(0x7ff8_0000_dead_beef),
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::MIN_POSITIVE,
            f64::from_bits(1),
            f64::MAX,
            f64::MIN,
            1e300,
            0.1 + 0.2,
        ];
        weird.extend((0..1000).map(|_| f64::from_bits(splitmix(&mut s))));
        let smooth: Vec<f64> = (0..1000).map(|i| (i as f64 * 0.01).sin()).collect();
        let ints: Vec<f64> = (0..1000).map(|i| (i * i) as f64 - 5e5).collect();
        let big: Vec<f64> = vec![9.007_199_254_740_993e15, 1e22, -1e-300, 123_456.789_012_345];
        roundtrip(&[
            ("t_s".into(), (0..13).map(f64::from).collect()),
            ("weird".into(), weird),
        ]);
        roundtrip(&[("s".into(), smooth), ("i".into(), ints), ("b".into(), big)]);
        roundtrip(&[]);
        roundtrip(&[("empty".into(), vec![]), ("één ∆".into(), vec![1.5])]);
    }

    #[test]
    fn every_corruption_is_an_error_not_a_panic() {
        let ch = logger_like(500);
        let bytes = encode(&ch).expect("encode");
        // Every truncation.
        for n in 0..bytes.len() {
            assert!(decode(&bytes[..n]).is_err(), "truncated to {n} decoded");
        }
        // Every single-bit flip: never a panic; an error unless the flip is in the body
        // and yields the same values (impossible with CRC over values + deflate framing, but
        // we only require that whatever decodes is bit-identical).
        let mut undetected = 0;
        for i in 0..bytes.len() {
            for bit in 0..8 {
                let mut b = bytes.clone();
                b[i] ^= 1 << bit;
                if let Ok(back) = decode(&b) {
                    assert_bit_identical(&ch, &back);
                    undetected += 1;
                }
            }
        }
        assert!(undetected < 8, "{undetected} flips decoded");
        // Checksum is over values: a re-encoded body with one value changed is caught.
        let mut other = ch.clone();
        other[1].1[10] += 0.01;
        let forged = encode(&other).expect("encode");
        let hdr = 4 + 1 + 2 + ch.iter().map(|(n, _)| 2 + n.len() + 4).sum::<usize>();
        let mut spliced = forged.clone();
        spliced[hdr..hdr + 4].copy_from_slice(&bytes[hdr..hdr + 4]); // original CRC
        assert!(matches!(decode(&spliced), Err(CodecError::Corrupt(m)) if m.contains("checksum")));
        assert!(decode(b"").is_err());
        assert!(decode(b"XXXX\x01\x00\x00").is_err());
    }

    #[test]
    fn j1_baseline_bytes_per_sample() {
        let path = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../../shared/data/examples/J1_baseline.json"
        );
        let Ok(text) = std::fs::read_to_string(path) else {
            eprintln!("{path} not present; measured on the synthetic trace only");
            return;
        };
        let doc: serde_json::Value = serde_json::from_str(&text).expect("json");
        let chans = doc["channels"].as_object().expect("channels");
        let mut ch: Channels = Vec::new();
        for name in ["t_s", "alpha_deg"] {
            let v = chans[name]
                .as_array()
                .expect("array")
                .iter()
                .map(|x| x.as_f64().expect("number"))
                .collect();
            ch.push((name.to_owned(), v));
        }
        let start = std::time::Instant::now();
        let bytes = roundtrip(&ch);
        eprintln!("J1_baseline: encode + decode {:?}", start.elapsed());
        let values: usize = ch.iter().map(|(_, v)| v.len()).sum();
        let per_value = bytes.len() as f64 / values as f64;
        eprintln!(
            "J1_baseline: {} values, {} bytes, {per_value:.3} bytes per value",
            values,
            bytes.len()
        );
        assert!(per_value <= 4.0);
    }
}

// SPDX-License-Identifier: MIT
//! RVL: lossless compression of 16-bit depth images (A. D. Wilson, "Fast Lossless Depth Image
//! Compression", ISS 2017).
//!
//! The image is scanned in row-major order as alternating runs: a run of zeros (no reading),
//! then a run of non-zero values. Each run starts with its length; each non-zero value is
//! stored as the zig-zag-mapped difference to the previous non-zero value (carried across
//! runs, starting at 0), so small changes along a surface cost few bits. Every number (run
//! length or mapped difference) is a variable-length code of 4-bit nibbles: 3 payload bits,
//! least significant group first, and the high bit set when another nibble follows.
//!
//! Byte layout: nibbles fill 32-bit words from the most significant nibble down; words are
//! stored little-endian; the last word is padded with zero nibbles. An image of `n` pixels
//! always encodes as (zero-run length, non-zero-run length, values...) pairs until `n` pixels
//! are covered, so the stream length is a multiple of 4 and is empty only for `n = 0`.
//!
//! RVL is fast but leaves redundancy in noisy depth (TUM's 5000 units/m Kinect frames code to
//! about 3.6:1). [`rvl_deflate_encode`] adds a DEFLATE stage for storage: the RVL stream with
//! each word's bytes reversed (nibbles in stream order, which DEFLATE models better than the
//! little-endian word bytes), compressed as raw DEFLATE (RFC 1951).

use crate::{Error, Result};

/// Codec name used in errors.
const CODEC: &str = "rvl";
/// Codec name of RVL + DEFLATE used in errors.
const DEFLATE_CODEC: &str = "rvl-deflate";
/// DEFLATE level of [`rvl_deflate_encode`] (miniz scale 0..=10; 6 is zlib's default).
const DEFLATE_LEVEL: u8 = 6;
/// Payload bits per nibble.
const NIBBLE_PAYLOAD_BITS: u32 = 3;
/// Continuation flag of a nibble.
const NIBBLE_CONTINUE: u32 = 0x8;
/// Nibbles per 32-bit word.
const NIBBLES_PER_WORD: u32 = 8;
/// Longest code a conforming encoder writes: 11 nibbles hold 33 payload bits, enough for any
/// `u32` run length.
const MAX_CODE_NIBBLES: u32 = 11;

/// Compresses raw depth values (0 = no reading). Lossless; see the module doc for the format.
pub fn rvl_encode(units: &[u16]) -> Vec<u8> {
    let mut writer = NibbleWriter { bytes: Vec::with_capacity(units.len() / 2 + 8), word: 0, nibbles_in_word: 0 };
    let mut previous = 0_i32;
    let mut rest = units;
    while !rest.is_empty() {
        let zeros = rest.iter().take_while(|&&u| u == 0).count();
        rest = &rest[zeros..];
        let non_zeros = rest.iter().take_while(|&&u| u != 0).count();
        writer.write_code(zeros as u64);
        writer.write_code(non_zeros as u64);
        for &value in &rest[..non_zeros] {
            let current = i32::from(value);
            writer.write_code(u64::from(zigzag_encode(current - previous)));
            previous = current;
        }
        rest = &rest[non_zeros..];
    }
    writer.finish()
}

/// Decompresses an RVL stream holding exactly `pixel_count` values.
///
/// Safe on hostile input: it allocates only the `pixel_count` output values (the caller bounds
/// that) and returns [`Error::Codec`] if the stream is truncated, has trailing data, encodes
/// more pixels than `pixel_count`, a zero inside a non-zero run, or a value outside `u16`.
pub fn rvl_decode(bytes: &[u8], pixel_count: usize) -> Result<Vec<u16>> {
    if !bytes.len().is_multiple_of(4) {
        return Err(codec_error(format!("stream length {} is not a multiple of 4 bytes", bytes.len())));
    }
    let mut reader = NibbleReader { words: bytes.chunks_exact(4), word: 0, nibbles_left: 0 };
    let mut units = Vec::new();
    units.try_reserve_exact(pixel_count).map_err(|_| codec_error(format!("cannot allocate {pixel_count} pixels")))?;
    let mut previous = 0_i64;
    while units.len() < pixel_count {
        let remaining = pixel_count - units.len();
        let zeros = reader.read_code()?;
        if zeros > remaining as u64 {
            return Err(codec_error(format!("zero run of {zeros} pixels overruns the image ({remaining} pixels left)")));
        }
        units.resize(units.len() + zeros as usize, 0);
        let remaining = pixel_count - units.len();
        let non_zeros = reader.read_code()?;
        if non_zeros > remaining as u64 {
            return Err(codec_error(format!("value run of {non_zeros} pixels overruns the image ({remaining} pixels left)")));
        }
        for _ in 0..non_zeros {
            let current = previous + zigzag_decode(reader.read_code()?);
            if !(1..=i64::from(u16::MAX)).contains(&current) {
                return Err(codec_error(format!("decoded value {current} at pixel {} is not a non-zero u16", units.len())));
            }
            units.push(current as u16);
            previous = current;
        }
    }
    reader.expect_end()?;
    Ok(units)
}

/// Compresses raw depth values with RVL followed by DEFLATE (see the module doc). Lossless.
pub fn rvl_deflate_encode(units: &[u16]) -> Vec<u8> {
    let mut rvl = rvl_encode(units);
    reverse_word_bytes(&mut rvl);
    miniz_oxide::deflate::compress_to_vec(&rvl, DEFLATE_LEVEL)
}

/// Decompresses a [`rvl_deflate_encode`] stream holding exactly `pixel_count` values.
///
/// Safe on hostile input like [`rvl_decode`]: the inflated RVL stream is capped at the
/// largest one `pixel_count` values can produce (`4 * pixel_count + 8` bytes).
pub fn rvl_deflate_decode(bytes: &[u8], pixel_count: usize) -> Result<Vec<u16>> {
    let deflate_error = |message: String| Error::Codec { codec: DEFLATE_CODEC, message };
    let max_rvl_len = pixel_count
        .checked_mul(4)
        .and_then(|n| n.checked_add(8))
        .ok_or_else(|| deflate_error(format!("{pixel_count} pixels is too many for this platform")))?;
    let mut rvl = miniz_oxide::inflate::decompress_to_vec_with_limit(bytes, max_rvl_len).map_err(|e| {
        let reason = match e.status {
            miniz_oxide::inflate::TINFLStatus::HasMoreOutput => format!("inflates past the largest RVL stream of {pixel_count} pixels"),
            status => format!("invalid DEFLATE data ({status:?})"),
        };
        deflate_error(reason)
    })?;
    if !rvl.len().is_multiple_of(4) {
        return Err(deflate_error(format!("inflated RVL stream of {} bytes is not a multiple of 4", rvl.len())));
    }
    reverse_word_bytes(&mut rvl);
    rvl_decode(&rvl, pixel_count).map_err(|e| match e {
        Error::Codec { message, .. } => deflate_error(message),
        other => other,
    })
}

/// Reverses the byte order of each 4-byte word (little-endian words ↔ nibbles in stream order).
fn reverse_word_bytes(bytes: &mut [u8]) {
    for word in bytes.chunks_exact_mut(4) {
        word.reverse();
    }
}

/// Maps a signed difference to an unsigned code: 0, -1, 1, -2, 2, ... → 0, 1, 2, 3, 4, ...
fn zigzag_encode(delta: i32) -> u32 {
    ((delta << 1) ^ (delta >> 31)) as u32
}

/// Inverse of [`zigzag_encode`], widened so that any decoded code is representable.
fn zigzag_decode(code: u64) -> i64 {
    ((code >> 1) as i64) ^ -((code & 1) as i64)
}

fn codec_error(message: String) -> Error {
    Error::Codec { codec: CODEC, message }
}

/// Packs nibbles into little-endian 32-bit words, most significant nibble first.
struct NibbleWriter {
    bytes: Vec<u8>,
    word: u32,
    nibbles_in_word: u32,
}

impl NibbleWriter {
    fn write_nibble(&mut self, nibble: u32) {
        self.word = (self.word << 4) | nibble;
        self.nibbles_in_word += 1;
        if self.nibbles_in_word == NIBBLES_PER_WORD {
            self.bytes.extend_from_slice(&self.word.to_le_bytes());
            self.word = 0;
            self.nibbles_in_word = 0;
        }
    }

    fn write_code(&mut self, mut value: u64) {
        loop {
            let payload = (value & 0x7) as u32;
            value >>= NIBBLE_PAYLOAD_BITS;
            if value == 0 {
                self.write_nibble(payload);
                return;
            }
            self.write_nibble(payload | NIBBLE_CONTINUE);
        }
    }

    fn finish(mut self) -> Vec<u8> {
        if self.nibbles_in_word > 0 {
            let word = self.word << (4 * (NIBBLES_PER_WORD - self.nibbles_in_word));
            self.bytes.extend_from_slice(&word.to_le_bytes());
        }
        self.bytes
    }
}

/// Reads nibbles back in the order [`NibbleWriter`] wrote them.
struct NibbleReader<'a> {
    words: std::slice::ChunksExact<'a, u8>,
    word: u32,
    nibbles_left: u32,
}

impl NibbleReader<'_> {
    fn read_nibble(&mut self) -> Result<u32> {
        if self.nibbles_left == 0 {
            let chunk = self.words.next().ok_or_else(|| codec_error("stream ends before the image is complete".to_owned()))?;
            self.word = u32::from_le_bytes([chunk[0], chunk[1], chunk[2], chunk[3]]);
            self.nibbles_left = NIBBLES_PER_WORD;
        }
        self.nibbles_left -= 1;
        Ok((self.word >> (4 * self.nibbles_left)) & 0xF)
    }

    fn read_code(&mut self) -> Result<u64> {
        let mut value = 0_u64;
        for nibble_ix in 0..MAX_CODE_NIBBLES {
            let nibble = self.read_nibble()?;
            value |= u64::from(nibble & 0x7) << (NIBBLE_PAYLOAD_BITS * nibble_ix);
            if nibble & NIBBLE_CONTINUE == 0 {
                return Ok(value);
            }
        }
        Err(codec_error(format!("variable-length code longer than {MAX_CODE_NIBBLES} nibbles")))
    }

    /// Checks that only zero padding nibbles remain.
    fn expect_end(&mut self) -> Result<()> {
        let padding_mask = if self.nibbles_left == 0 { 0 } else { u32::MAX >> (32 - 4 * self.nibbles_left) };
        if self.word & padding_mask != 0 {
            return Err(codec_error("non-zero padding after the last pixel".to_owned()));
        }
        let trailing_words = self.words.len();
        if trailing_words != 0 {
            return Err(codec_error(format!("{} bytes of trailing data after the last pixel", trailing_words * 4)));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Deterministic xorshift generator for property tests.
    struct Rng(u64);

    impl Rng {
        fn next(&mut self) -> u64 {
            self.0 ^= self.0 << 13;
            self.0 ^= self.0 >> 7;
            self.0 ^= self.0 << 17;
            self.0
        }

        fn below(&mut self, n: u64) -> u64 {
            self.next() % n
        }
    }

    /// A depth-like image: smooth ramps with noise, zero holes of random length, random jumps.
    fn random_depth(rng: &mut Rng, len: usize) -> Vec<u16> {
        let mut units = Vec::with_capacity(len);
        let mut level = 5000_i64;
        while units.len() < len {
            let run = (1 + rng.below(200)) as usize;
            let kind = rng.below(10);
            for _ in 0..run.min(len - units.len()) {
                units.push(match kind {
                    0..=2 => 0,
                    3 => 1 + rng.below(u64::from(u16::MAX)) as u16,
                    4 => u16::MAX - rng.below(3) as u16,
                    _ => {
                        level = (level + rng.below(41) as i64 - 20).clamp(1, i64::from(u16::MAX));
                        level as u16
                    }
                });
            }
        }
        units
    }

    #[test]
    fn zigzag_maps_small_magnitudes_to_small_codes() {
        let pairs = [(0, 0), (-1, 1), (1, 2), (-2, 3), (2, 4), (65535, 131_070), (-65535, 131_069)];
        for (delta, code) in pairs {
            assert_eq!(zigzag_encode(delta), code, "encode {delta}");
            assert_eq!(zigzag_decode(u64::from(code)), i64::from(delta), "decode {code}");
        }
    }

    #[test]
    fn encodes_the_documented_layout() {
        // 2 zeros, then 1 value 5: codes 2, 1, zigzag(5) = 10 = 0b1_010 -> nibbles 0x2, 0x1, 0xA, 0x1.
        let bytes = rvl_encode(&[0, 0, 5]);
        assert_eq!(bytes, 0x21A1_0000_u32.to_le_bytes().to_vec(), "bytes {bytes:02x?}");
        assert_eq!(rvl_decode(&bytes, 3).expect("decoding"), vec![0, 0, 5], "round trip");
    }

    #[test]
    fn round_trips_edge_cases() {
        let cases: Vec<Vec<u16>> = vec![
            vec![],
            vec![0],
            vec![1],
            vec![u16::MAX],
            vec![0; 640 * 480],
            vec![u16::MAX; 640 * 480],
            vec![1; 1000],
            (0..=u16::MAX).collect(),
            (0..=u16::MAX).rev().collect(),
            (0..5000).map(|i| if i % 2 == 0 { u16::MAX } else { 1 }).collect(),
            (0..5000).map(|i| if i % 3 == 0 { 0 } else { u16::MAX }).collect(),
        ];
        for units in cases {
            let bytes = rvl_encode(&units);
            assert!(bytes.len().is_multiple_of(4), "whole words for {} px", units.len());
            assert_eq!(rvl_decode(&bytes, units.len()).expect("decoding"), units, "round trip of {} px", units.len());
        }
    }

    #[test]
    fn compresses_constant_images_to_a_few_words() {
        // 307200 zeros: a 7-nibble run length (19 bits) and an empty value run fill one word.
        assert_eq!(rvl_encode(&vec![0; 640 * 480]), 0x8888_B910_u32.to_le_bytes().to_vec(), "all zeros");
        assert!(rvl_encode(&vec![u16::MAX; 640 * 480]).len() < 640 * 480 / 2 + 64, "constant max value: one nibble per pixel");
    }

    #[test]
    fn round_trips_random_images() {
        let mut rng = Rng(0x1234_5678_9ABC_DEF1);
        for _ in 0..200 {
            let len = rng.below(5000) as usize;
            let units = random_depth(&mut rng, len);
            let bytes = rvl_encode(&units);
            assert_eq!(rvl_decode(&bytes, len).expect("decoding"), units, "round trip of {len} px");
        }
    }

    #[test]
    fn deflate_variant_shrinks_real_tum_depth() {
        let depth = crate::io::test_util::sample_frame(0).depth;
        let (rvl, deflated) = (rvl_encode(&depth.units), rvl_deflate_encode(&depth.units));
        assert!(deflated.len() < rvl.len() * 3 / 4, "RVL {} B, RVL+DEFLATE {} B", rvl.len(), deflated.len());
        assert_eq!(rvl_deflate_decode(&deflated, depth.units.len()).expect("decoding"), depth.units, "bit-exact");
    }

    #[test]
    fn round_trips_real_tum_depth() {
        let depth = crate::io::test_util::sample_frame(0).depth;
        let bytes = rvl_encode(&depth.units);
        assert_eq!(rvl_decode(&bytes, depth.units.len()).expect("decoding"), depth.units, "bit-exact round trip");
        assert!(bytes.len() < depth.units.len() * 2, "RVL ({} B) should be smaller than raw", bytes.len());
    }

    #[test]
    fn every_truncation_is_an_error() {
        let mut rng = Rng(7);
        let units = random_depth(&mut rng, 300);
        let bytes = rvl_encode(&units);
        for len in 0..bytes.len() {
            let result = rvl_decode(&bytes[..len], units.len());
            assert!(matches!(result, Err(Error::Codec { codec: "rvl", .. })), "truncation to {len} of {} bytes: {result:?}", bytes.len());
        }
    }

    #[test]
    fn rejects_trailing_data_overlong_streams_and_bad_padding() {
        let units = vec![0, 0, 5];
        let bytes = rvl_encode(&units);
        let mut extra_word = bytes.clone();
        extra_word.extend_from_slice(&[0; 4]);
        assert!(rvl_decode(&extra_word, 3).is_err(), "trailing word");
        assert!(rvl_decode(&bytes, 2).is_err(), "stream encodes more pixels than asked for");
        assert!(rvl_decode(&bytes, 4).is_err(), "stream encodes fewer pixels than asked for");
        let bad_padding = 0x21A1_0001_u32.to_le_bytes();
        assert!(rvl_decode(&bad_padding, 3).is_err(), "non-zero padding");
        let endless_code = [0xFF_u8; 16];
        assert!(rvl_decode(&endless_code, 10).is_err(), "code without an end");
        // One value run of a zero difference from 0: decodes to 0, which a value run cannot hold.
        let zero_in_value_run = 0x0100_0000_u32.to_le_bytes();
        assert!(rvl_decode(&zero_in_value_run, 1).is_err(), "zero inside a value run");
        // A difference of +65536 from 0 leaves u16.
        let mut too_big = NibbleWriter { bytes: Vec::new(), word: 0, nibbles_in_word: 0 };
        too_big.write_code(0);
        too_big.write_code(1);
        too_big.write_code(u64::from(zigzag_encode(65_536)));
        assert!(rvl_decode(&too_big.finish(), 1).is_err(), "value above u16::MAX");
    }

    #[test]
    fn deflate_variant_round_trips() {
        let mut rng = Rng(0xDEF1_A7E0);
        let mut cases: Vec<Vec<u16>> = vec![vec![], vec![0; 640 * 480], vec![u16::MAX; 1000], (0..=u16::MAX).collect()];
        cases.extend((0..50).map(|_| {
            let len = rng.below(5000) as usize;
            random_depth(&mut rng, len)
        }));
        for units in cases {
            let bytes = rvl_deflate_encode(&units);
            assert_eq!(rvl_deflate_decode(&bytes, units.len()).expect("decoding"), units, "round trip of {} px", units.len());
        }
    }

    #[test]
    fn deflate_variant_rejects_bad_input() {
        let mut rng = Rng(11);
        let units = random_depth(&mut rng, 400);
        let bytes = rvl_deflate_encode(&units);
        for len in 0..bytes.len() {
            assert!(rvl_deflate_decode(&bytes[..len], units.len()).is_err(), "truncation to {len} of {} bytes", bytes.len());
        }
        assert!(rvl_deflate_decode(&bytes, units.len() - 1).is_err(), "fewer pixels than encoded");
        // A valid DEFLATE stream of far more data than 10 pixels can need: stopped at the cap.
        let bomb = miniz_oxide::deflate::compress_to_vec(&vec![0; 1 << 20], 6);
        let err = rvl_deflate_decode(&bomb, 10).expect_err("decompression bomb");
        assert!(err.to_string().contains("inflates past"), "{err}");
        let not_words = miniz_oxide::deflate::compress_to_vec(&[1, 2, 3], 6);
        assert!(rvl_deflate_decode(&not_words, 1).is_err(), "inflated length not a multiple of 4");
        for _ in 0..2000 {
            let garbage: Vec<u8> = (0..rng.below(64)).map(|_| rng.next() as u8).collect();
            rvl_deflate_decode(&garbage, rng.below(64) as usize).ok();
        }
    }

    #[test]
    fn worst_case_rvl_fits_the_inflate_cap() {
        // Alternating extremes: the largest per-pixel codes RVL produces.
        for units in [
            (0..9999).map(|i| if i % 2 == 0 { 1 } else { u16::MAX }).collect::<Vec<u16>>(),
            (0..9999)
                .map(|i| match i % 3 {
                    0 => 0,
                    1 => 1,
                    _ => u16::MAX,
                })
                .collect(),
        ] {
            assert!(rvl_encode(&units).len() <= 4 * units.len() + 8, "RVL stream within the cap");
            let bytes = rvl_deflate_encode(&units);
            assert_eq!(rvl_deflate_decode(&bytes, units.len()).expect("decoding"), units, "round trip");
        }
    }

    #[test]
    fn absurd_pixel_counts_are_errors() {
        assert!(rvl_decode(&[], usize::MAX).is_err(), "capacity overflow is an error, not a panic");
        assert!(rvl_deflate_decode(&[], usize::MAX).is_err(), "deflate variant");
    }

    #[test]
    fn garbage_never_panics() {
        let mut rng = Rng(99);
        for _ in 0..20_000 {
            let len = 4 * rng.below(16) as usize + if rng.below(8) == 0 { rng.below(4) as usize } else { 0 };
            let bytes: Vec<u8> = (0..len).map(|_| rng.next() as u8).collect();
            let pixel_count = rng.below(64) as usize;
            if let Ok(units) = rvl_decode(&bytes, pixel_count) {
                assert_eq!(units.len(), pixel_count, "a successful decode has exactly pixel_count values");
            }
        }
    }

    #[test]
    fn flipped_bits_never_panic() {
        let mut rng = Rng(5);
        let units = random_depth(&mut rng, 500);
        let bytes = rvl_encode(&units);
        for bit in 0..bytes.len() * 8 {
            let mut corrupt = bytes.clone();
            corrupt[bit / 8] ^= 1 << (bit % 8);
            if let Ok(decoded) = rvl_decode(&corrupt, units.len()) {
                assert_eq!(decoded.len(), units.len(), "a successful decode has exactly pixel_count values");
            }
        }
    }
}

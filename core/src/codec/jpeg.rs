// SPDX-License-Identifier: MIT
//! JPEG colour images (lossy), encoded with `jpeg-encoder` and decoded with `zune-jpeg`, both
//! pure Rust so they also run in the browser.

use zune_jpeg::JpegDecoder;
use zune_jpeg::zune_core::bytestream::ZCursor;
use zune_jpeg::zune_core::colorspace::ColorSpace;
use zune_jpeg::zune_core::options::DecoderOptions;

use crate::{ColorImage, Error, Result};

/// Codec name used in errors.
const CODEC: &str = "jpeg";

/// Default JPEG quality (1..=100) of recordings. At 90 and above the encoder keeps full
/// chroma resolution (4:4:4); below it subsamples chroma 2x2 (4:2:0).
pub const DEFAULT_JPEG_QUALITY: u8 = 90;

fn codec_error(message: String) -> Error {
    Error::Codec { codec: CODEC, message }
}

/// Encodes an RGB8 image as baseline JPEG at `quality` (1..=100).
pub fn encode_rgb8(image: &ColorImage, quality: u8) -> Result<Vec<u8>> {
    if !(1..=100).contains(&quality) {
        return Err(Error::InvalidConfig(format!("JPEG quality must be 1..=100, got {quality}")));
    }
    let (Ok(width), Ok(height)) = (u16::try_from(image.width_px), u16::try_from(image.height_px)) else {
        return Err(codec_error(format!("{}x{} px exceeds JPEG's 65535 px limit", image.width_px, image.height_px)));
    };
    let mut bytes = Vec::new();
    let encoder = jpeg_encoder::Encoder::new(&mut bytes, quality);
    encoder.encode(&image.rgb8, width, height, jpeg_encoder::ColorType::Rgb).map_err(|e| codec_error(format!("encoding: {e}")))?;
    Ok(bytes)
}

/// Decodes a JPEG of `width_px x height_px` into RGB8 (grayscale JPEGs are replicated).
///
/// The size is checked from the header before the image is decoded, and the decoder is told
/// not to accept anything larger, so hostile input cannot make it allocate more.
pub fn decode_rgb8(bytes: &[u8], width_px: u32, height_px: u32) -> Result<ColorImage> {
    let options = DecoderOptions::default()
        .set_max_width(width_px as usize)
        .set_max_height(height_px as usize)
        .jpeg_set_out_colorspace(ColorSpace::RGB);
    let mut decoder = JpegDecoder::new_with_options(ZCursor::new(bytes), options);
    decoder.decode_headers().map_err(|e| codec_error(e.to_string()))?;
    let info = decoder.info().ok_or_else(|| codec_error("no image header".to_owned()))?;
    if (u32::from(info.width), u32::from(info.height)) != (width_px, height_px) {
        return Err(codec_error(format!("image is {}x{} px but {width_px}x{height_px} px were expected", info.width, info.height)));
    }
    let size = decoder.output_buffer_size().ok_or_else(|| codec_error("no image header".to_owned()))?;
    let expected = 3 * width_px as usize * height_px as usize;
    if size != expected {
        return Err(codec_error(format!("decoder would output {size} bytes, expected {expected} for RGB8")));
    }
    let mut rgb8 = vec![0; size];
    decoder.decode_into(&mut rgb8).map_err(|e| codec_error(e.to_string()))?;
    ColorImage::new(width_px, height_px, rgb8)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Smooth test image (JPEG's friendly case) with some edges.
    fn test_image(width_px: u32, height_px: u32) -> ColorImage {
        let mut rgb8 = Vec::with_capacity(3 * (width_px * height_px) as usize);
        for y in 0..height_px {
            for x in 0..width_px {
                let edge = if (x / 16 + y / 16) % 2 == 0 { 40 } else { 0 };
                rgb8.extend_from_slice(&[(x * 255 / width_px) as u8, (y * 255 / height_px) as u8, 100 + edge]);
            }
        }
        ColorImage::new(width_px, height_px, rgb8).expect("valid size")
    }

    fn mean_abs_error(a: &ColorImage, b: &ColorImage) -> f64 {
        let sum: u64 = a.rgb8.iter().zip(&b.rgb8).map(|(&x, &y)| u64::from(x.abs_diff(y))).sum();
        sum as f64 / a.rgb8.len() as f64
    }

    #[test]
    fn round_trips_within_tolerance() {
        let image = test_image(64, 48);
        for (quality, max_mean_error) in [(95, 1.5), (90, 2.0), (50, 4.0)] {
            let bytes = encode_rgb8(&image, quality).expect("encoding");
            let decoded = decode_rgb8(&bytes, 64, 48).expect("decoding");
            let error = mean_abs_error(&image, &decoded);
            assert!(error <= max_mean_error, "quality {quality}: mean abs error {error}");
        }
    }

    #[test]
    fn rejects_bad_quality_and_wrong_size() {
        let image = test_image(16, 8);
        assert!(matches!(encode_rgb8(&image, 0), Err(Error::InvalidConfig(_))), "quality 0");
        assert!(matches!(encode_rgb8(&image, 101), Err(Error::InvalidConfig(_))), "quality 101");
        let bytes = encode_rgb8(&image, 90).expect("encoding");
        assert!(decode_rgb8(&bytes, 16, 9).is_err(), "wrong height");
        assert!(decode_rgb8(&bytes, 8, 8).is_err(), "larger than allowed");
    }

    #[test]
    fn garbage_and_truncation_never_panic() {
        let bytes = encode_rgb8(&test_image(32, 32), 90).expect("encoding");
        for len in 0..bytes.len() {
            // The decoder is lenient with truncated scans (it may fill the rest); it must not panic.
            if let Ok(image) = decode_rgb8(&bytes[..len], 32, 32) {
                assert_eq!(image.rgb8.len(), 32 * 32 * 3, "decoded size");
            }
        }
        let mut state = 1_u32;
        for _ in 0..200 {
            let mut corrupt = bytes.clone();
            for _ in 0..8 {
                state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
                let ix = state as usize % corrupt.len();
                corrupt[ix] = (state >> 24) as u8;
            }
            if let Ok(image) = decode_rgb8(&corrupt, 32, 32) {
                assert_eq!(image.rgb8.len(), 32 * 32 * 3, "decoded size");
            }
        }
        assert!(decode_rgb8(b"\xFF\xD8garbage", 32, 32).is_err(), "garbage after SOI");
    }
}

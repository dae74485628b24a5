// SPDX-License-Identifier: MIT
//! PNG images: 16-bit grayscale depth (the TUM format) and lossless colour.
//!
//! Decoders check the image size from the header before decoding anything, so a file can
//! never make them allocate more than the expected image.

use std::io::Cursor;

use crate::{ColorImage, DepthImage, Error, Result};

/// Codec name used in errors.
const CODEC: &str = "png";

fn codec_error(message: String) -> Error {
    Error::Codec { codec: CODEC, message }
}

/// Memory the PNG decoder may use per pixel of the expected image: RGBA16 output plus a row.
const DECODER_BYTES_PER_PX: usize = 16;
/// Memory the PNG decoder may always use (its default limit).
const DECODER_MIN_BYTES: usize = 64 << 20;

/// Reads the PNG header and checks the size; `transformations` choose the output format.
fn read_header(bytes: &[u8], transformations: png::Transformations, width_px: u32, height_px: u32) -> Result<png::Reader<Cursor<&[u8]>>> {
    let limit = (width_px as usize).saturating_mul(height_px as usize).saturating_mul(DECODER_BYTES_PER_PX).max(DECODER_MIN_BYTES);
    let mut decoder = png::Decoder::new_with_limits(Cursor::new(bytes), png::Limits { bytes: limit });
    decoder.set_transformations(transformations);
    let reader = decoder.read_info().map_err(|e| codec_error(e.to_string()))?;
    let info = reader.info();
    if (info.width, info.height) != (width_px, height_px) {
        return Err(codec_error(format!("image is {}x{} px but {width_px}x{height_px} px were expected", info.width, info.height)));
    }
    Ok(reader)
}

/// Decodes the first frame into a buffer of exactly the reader's output size.
fn decode_frame(reader: &mut png::Reader<Cursor<&[u8]>>) -> Result<Vec<u8>> {
    let size = reader.output_buffer_size().ok_or_else(|| codec_error("image too large for this platform".to_owned()))?;
    let mut buffer = vec![0; size];
    let frame = reader.next_frame(&mut buffer).map_err(|e| codec_error(e.to_string()))?;
    buffer.truncate(frame.buffer_size());
    Ok(buffer)
}

/// Decodes a 16-bit grayscale PNG of `width_px x height_px` into raw depth units.
///
/// Any other pixel format (8-bit, colour, alpha) is an error: scaling it would silently
/// change the depth units.
pub fn decode_depth16(bytes: &[u8], width_px: u32, height_px: u32) -> Result<DepthImage> {
    let mut reader = read_header(bytes, png::Transformations::IDENTITY, width_px, height_px)?;
    let (color_type, bit_depth) = reader.output_color_type();
    if (color_type, bit_depth) != (png::ColorType::Grayscale, png::BitDepth::Sixteen) {
        return Err(codec_error(format!("depth must be 16-bit grayscale, found {bit_depth:?}-bit {color_type:?}")));
    }
    let buffer = decode_frame(&mut reader)?;
    // PNG stores 16-bit samples big-endian.
    let units = buffer.chunks_exact(2).map(|b| u16::from_be_bytes([b[0], b[1]])).collect();
    DepthImage::new(width_px, height_px, units)
}

/// Decodes a PNG of `width_px x height_px` into RGB8.
///
/// Accepts RGB, RGBA (alpha dropped), grayscale (replicated) and grayscale+alpha, at any bit
/// depth (palette expanded, 16-bit reduced to 8-bit).
pub fn decode_rgb8(bytes: &[u8], width_px: u32, height_px: u32) -> Result<ColorImage> {
    let transformations = png::Transformations::EXPAND | png::Transformations::STRIP_16;
    let mut reader = read_header(bytes, transformations, width_px, height_px)?;
    let (color_type, bit_depth) = reader.output_color_type();
    if bit_depth != png::BitDepth::Eight {
        return Err(codec_error(format!("unsupported colour bit depth {bit_depth:?} after expansion")));
    }
    let buffer = decode_frame(&mut reader)?;
    let rgb8 = match color_type {
        png::ColorType::Rgb => buffer,
        png::ColorType::Rgba => buffer.chunks_exact(4).flat_map(|p| [p[0], p[1], p[2]]).collect(),
        png::ColorType::Grayscale => buffer.iter().flat_map(|&g| [g, g, g]).collect(),
        png::ColorType::GrayscaleAlpha => buffer.chunks_exact(2).flat_map(|p| [p[0], p[0], p[0]]).collect(),
        png::ColorType::Indexed => return Err(codec_error("palette image was not expanded".to_owned())),
    };
    ColorImage::new(width_px, height_px, rgb8)
}

fn encode(width_px: u32, height_px: u32, color_type: png::ColorType, bit_depth: png::BitDepth, data: &[u8]) -> Result<Vec<u8>> {
    let mut bytes = Vec::new();
    let mut encoder = png::Encoder::new(&mut bytes, width_px, height_px);
    encoder.set_color(color_type);
    encoder.set_depth(bit_depth);
    encoder.set_compression(png::Compression::Fast);
    let mut writer = encoder.write_header().map_err(|e| codec_error(format!("encoding: {e}")))?;
    writer.write_image_data(data).map_err(|e| codec_error(format!("encoding: {e}")))?;
    writer.finish().map_err(|e| codec_error(format!("encoding: {e}")))?;
    Ok(bytes)
}

/// Encodes a colour image as an RGB8 PNG (lossless).
pub fn encode_rgb8(image: &ColorImage) -> Result<Vec<u8>> {
    encode(image.width_px, image.height_px, png::ColorType::Rgb, png::BitDepth::Eight, &image.rgb8)
}

/// Encodes one byte per pixel as an 8-bit grayscale PNG (masks).
pub fn encode_gray8(width_px: u32, height_px: u32, values: &[u8]) -> Result<Vec<u8>> {
    if values.len() != width_px as usize * height_px as usize {
        return Err(codec_error(format!("{} values for a {width_px}x{height_px} image", values.len())));
    }
    encode(width_px, height_px, png::ColorType::Grayscale, png::BitDepth::Eight, values)
}

/// Encodes a depth image as a 16-bit grayscale PNG, the TUM depth format (lossless).
pub fn encode_depth16(image: &DepthImage) -> Result<Vec<u8>> {
    let big_endian: Vec<u8> = image.units.iter().flat_map(|u| u.to_be_bytes()).collect();
    encode(image.width_px, image.height_px, png::ColorType::Grayscale, png::BitDepth::Sixteen, &big_endian)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn gradient_color(width_px: u32, height_px: u32) -> ColorImage {
        let rgb8 = (0..width_px * height_px).flat_map(|i| [(i % 251) as u8, (i / 7 % 256) as u8, (i * 3 % 256) as u8]).collect();
        ColorImage::new(width_px, height_px, rgb8).expect("valid size")
    }

    #[test]
    fn colour_round_trips_exactly() {
        let image = gradient_color(37, 11);
        let bytes = encode_rgb8(&image).expect("encoding");
        assert_eq!(decode_rgb8(&bytes, 37, 11).expect("decoding"), image, "lossless round trip");
    }

    #[test]
    fn depth_round_trips_exactly() {
        let units = (0..40 * 30).map(|i| if i % 5 == 0 { 0 } else { (i * 97 % 65536) as u16 }).collect();
        let image = DepthImage::new(40, 30, units).expect("valid size");
        let bytes = encode_depth16(&image).expect("encoding");
        assert_eq!(decode_depth16(&bytes, 40, 30).expect("decoding"), image, "lossless round trip");
    }

    #[test]
    fn converts_gray_and_rgba_to_rgb() {
        let gray = encode(2, 1, png::ColorType::Grayscale, png::BitDepth::Eight, &[10, 200]).expect("encoding gray");
        assert_eq!(decode_rgb8(&gray, 2, 1).expect("decoding gray").rgb8, vec![10, 10, 10, 200, 200, 200], "gray");
        let rgba = encode(2, 1, png::ColorType::Rgba, png::BitDepth::Eight, &[1, 2, 3, 4, 5, 6, 7, 8]).expect("encoding rgba");
        assert_eq!(decode_rgb8(&rgba, 2, 1).expect("decoding rgba").rgb8, vec![1, 2, 3, 5, 6, 7], "rgba");
    }

    #[test]
    fn rejects_wrong_size_and_format() {
        let image = gradient_color(8, 4);
        let bytes = encode_rgb8(&image).expect("encoding");
        let err = decode_rgb8(&bytes, 8, 5).expect_err("wrong height");
        assert!(err.to_string().contains("8x4 px but 8x5 px"), "{err}");
        let err = decode_depth16(&bytes, 8, 4).expect_err("colour as depth");
        assert!(err.to_string().contains("16-bit grayscale"), "{err}");
        let gray8 = encode(2, 1, png::ColorType::Grayscale, png::BitDepth::Eight, &[10, 200]).expect("encoding gray");
        assert!(decode_depth16(&gray8, 2, 1).is_err(), "8-bit gray is not depth");
    }

    #[test]
    fn truncated_and_garbage_input_is_an_error() {
        let bytes = encode_rgb8(&gradient_color(16, 16)).expect("encoding");
        for len in (0..bytes.len()).step_by(7) {
            assert!(decode_rgb8(&bytes[..len], 16, 16).is_err(), "truncation to {len}");
        }
        assert!(decode_rgb8(b"not a png at all", 16, 16).is_err(), "garbage");
    }
}

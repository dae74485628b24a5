// SPDX-License-Identifier: MIT
//! RGB-D frames as sources deliver them.

use crate::{Error, Result};

/// A raw depth image: row-major sensor units (see [`crate::RgbdCalibration`]), 0 = no reading.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct DepthImage {
    /// Width in pixels.
    pub width_px: u32,
    /// Height in pixels.
    pub height_px: u32,
    /// `width_px * height_px` raw depth values, row-major.
    pub units: Vec<u16>,
}

/// A colour image: row-major RGB8, registered to the depth image.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ColorImage {
    /// Width in pixels.
    pub width_px: u32,
    /// Height in pixels.
    pub height_px: u32,
    /// `3 * width_px * height_px` bytes, R G B per pixel, row-major.
    pub rgb8: Vec<u8>,
}

impl DepthImage {
    /// Checks that the buffer holds exactly `width x height` values.
    pub fn new(width_px: u32, height_px: u32, units: Vec<u16>) -> Result<Self> {
        let want = (width_px as usize).checked_mul(height_px as usize);
        if want != Some(units.len()) {
            return Err(Error::InvalidConfig(format!("depth image {width_px}x{height_px} needs {want:?} values, got {}", units.len())));
        }
        Ok(Self { width_px, height_px, units })
    }
}

impl ColorImage {
    /// Checks that the buffer holds exactly `3 x width x height` bytes.
    pub fn new(width_px: u32, height_px: u32, rgb8: Vec<u8>) -> Result<Self> {
        let want = (width_px as usize).checked_mul(height_px as usize).and_then(|n| n.checked_mul(3));
        if want != Some(rgb8.len()) {
            return Err(Error::InvalidConfig(format!("colour image {width_px}x{height_px} needs {want:?} bytes, got {}", rgb8.len())));
        }
        Ok(Self { width_px, height_px, rgb8 })
    }
}

/// One synchronised RGB-D frame.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct RgbdFrame {
    /// Position of the frame in its source, from 0.
    pub index: u64,
    /// Capture time of the depth image, nanoseconds (Unix epoch for TUM; device clock live).
    pub depth_timestamp_ns: i64,
    /// Capture time of the colour image, nanoseconds, same clock.
    pub color_timestamp_ns: i64,
    /// Depth image.
    pub depth: DepthImage,
    /// Colour image, same size as depth.
    pub color: ColorImage,
}

// SPDX-License-Identifier: MIT
//! Image codecs of recordings: RVL (optionally followed by DEFLATE) for depth, lossless;
//! JPEG or PNG for colour.
//!
//! All are pure Rust and run natively and in the browser. Decoders take the expected image
//! size and treat their input as untrusted: malformed data is an [`crate::Error::Codec`],
//! never a panic or an allocation beyond the expected image.

pub mod jpeg;
pub mod png;
pub mod rvl;

pub use jpeg::DEFAULT_JPEG_QUALITY;
pub use rvl::{rvl_decode, rvl_deflate_decode, rvl_deflate_encode, rvl_encode};

use crate::{ColorImage, DepthImage, Result};

/// How depth images are compressed.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum DepthCodec {
    /// RVL run-length + delta coding ([`rvl`]), lossless and fastest.
    Rvl,
    /// RVL followed by DEFLATE ([`rvl::rvl_deflate_encode`]), lossless and about 2x smaller
    /// than RVL on Kinect-class depth; for files.
    RvlDeflate,
}

/// How colour images are compressed.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum ColorCodec {
    /// Baseline JPEG ([`jpeg`]), lossy.
    Jpeg,
    /// RGB8 PNG ([`png`]), lossless.
    Png,
}

impl DepthCodec {
    /// Id stored in recordings.
    pub fn id(self) -> u8 {
        match self {
            Self::Rvl => 1,
            Self::RvlDeflate => 2,
        }
    }

    /// The codec with id `id`, if this build knows it.
    pub fn from_id(id: u8) -> Option<Self> {
        match id {
            1 => Some(Self::Rvl),
            2 => Some(Self::RvlDeflate),
            _ => None,
        }
    }

    /// Lower-case name (`rvl`, `rvl-deflate`).
    pub fn name(self) -> &'static str {
        match self {
            Self::Rvl => "rvl",
            Self::RvlDeflate => "rvl-deflate",
        }
    }

    /// Compresses a depth image.
    pub fn encode(self, image: &DepthImage) -> Vec<u8> {
        match self {
            Self::Rvl => rvl_encode(&image.units),
            Self::RvlDeflate => rvl_deflate_encode(&image.units),
        }
    }

    /// Decompresses a depth image of `width_px x height_px`.
    pub fn decode(self, bytes: &[u8], width_px: u32, height_px: u32) -> Result<DepthImage> {
        let pixel_count = (width_px as usize).checked_mul(height_px as usize).ok_or_else(|| crate::Error::Codec {
            codec: self.name(),
            message: format!("{width_px}x{height_px} px is too large for this platform"),
        })?;
        let units = match self {
            Self::Rvl => rvl_decode(bytes, pixel_count)?,
            Self::RvlDeflate => rvl_deflate_decode(bytes, pixel_count)?,
        };
        DepthImage::new(width_px, height_px, units)
    }
}

impl ColorCodec {
    /// Id stored in recordings.
    pub fn id(self) -> u8 {
        match self {
            Self::Jpeg => 1,
            Self::Png => 2,
        }
    }

    /// The codec with id `id`, if this build knows it.
    pub fn from_id(id: u8) -> Option<Self> {
        match id {
            1 => Some(Self::Jpeg),
            2 => Some(Self::Png),
            _ => None,
        }
    }

    /// Lower-case name (`jpeg`, `png`).
    pub fn name(self) -> &'static str {
        match self {
            Self::Jpeg => "jpeg",
            Self::Png => "png",
        }
    }

    /// Compresses a colour image; `jpeg_quality` (1..=100) applies to [`ColorCodec::Jpeg`] only.
    pub fn encode(self, image: &ColorImage, jpeg_quality: u8) -> Result<Vec<u8>> {
        match self {
            Self::Jpeg => jpeg::encode_rgb8(image, jpeg_quality),
            Self::Png => png::encode_rgb8(image),
        }
    }

    /// Decompresses a colour image of `width_px x height_px`.
    pub fn decode(self, bytes: &[u8], width_px: u32, height_px: u32) -> Result<ColorImage> {
        match self {
            Self::Jpeg => jpeg::decode_rgb8(bytes, width_px, height_px),
            Self::Png => png::decode_rgb8(bytes, width_px, height_px),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ids_round_trip_and_unknown_ids_are_none() {
        for codec in [ColorCodec::Jpeg, ColorCodec::Png] {
            assert_eq!(ColorCodec::from_id(codec.id()), Some(codec), "{}", codec.name());
        }
        for codec in [DepthCodec::Rvl, DepthCodec::RvlDeflate] {
            assert_eq!(DepthCodec::from_id(codec.id()), Some(codec), "{}", codec.name());
        }
        assert_eq!(ColorCodec::from_id(0), None, "colour id 0");
        assert_eq!(DepthCodec::from_id(0), None, "depth id 0");
    }
}

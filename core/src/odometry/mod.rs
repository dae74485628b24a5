// SPDX-License-Identifier: MIT
//! Seed 002's feature-based RGB-D odometry, rebuilt for the GPU (`shaders/wgsl/odometry/`).
//!
//! Per frame: FAST-9 corner scores on each level of the intensity pyramid (`fast_score`), the
//! local maxima that pass 002's depth border filter (`corner_candidates`), the best few of them
//! per cell of an image grid with their 3D points (`keypoint_select`), the intensity centroid's orientation and a 256-bit
//! rotated binary descriptor on the smoothed level image (`feature_smooth`, `orb_describe`),
//! then brute-force Hamming matching against the reference frame in both directions
//! (`hamming_match`). The host filters the matches (Lowe's ratio, the mutual check, 002's
//! margin and keep-best percentage as options; [`matching`]) and estimates the rigid motion
//! from the 3D-3D pairs with RANSAC on 3-point Kabsch samples, then Gauss-Newton refits of the
//! Mahalanobis cost under the Kinect noise model ([`rigid`]).
//!
//! Beside a dense tracker, [`assist::FeatureAssist`] gives ICP its initial guess and
//! relocalises against stored keyframes after a loss.
//!
//! [`reference::extract`] is the CPU chain of the kernels' twins; [`gpu::FeatureExtractor`]
//! records the same chain on the GPU.

pub mod assist;
pub mod gpu;
pub mod keyframe;
pub mod matching;
pub mod reference;
pub mod rigid;
pub mod tracker;

use crate::cpu::shared::{DESCRIPTOR_BITS, DESCRIPTOR_WORDS, pcg_hash, random_uniform};
use crate::cpu::odometry::keypoint_select::MAX_PER_CELL;
use crate::kernels::{corner_candidates::CornerCandidatesParams, fast_score::FastScoreParams, keypoint_select::KeypointSelectParams, orb_describe::OrbDescribeParams};
use crate::{Error, PinholeIntrinsics, Result};

/// Radius within which the descriptor's test points lie, pixels: rotated by any angle they
/// stay inside the orientation disc ([`FeatureConfig::patch_radius_px`] = 15) with a pixel to
/// spare for the bilinear sample.
pub const PATTERN_RADIUS_PX: f32 = 13.0;

/// How keypoints are detected and described.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FeatureConfig {
    /// Keypoints wanted per frame (at most; the grid cells share them).
    pub target_keypoints: u32,
    /// Pyramid levels searched (each halves the resolution; at most the preprocessor's).
    pub levels: u32,
    /// Grid cell side, pixels of each level.
    pub cell_px: u32,
    /// The smallest FAST score (intensity in [0, 1]) kept: 7/255, ORB-SLAM's fallback
    /// threshold for low-contrast cells; the grid ranks the corners by score anyway.
    pub fast_threshold: f32,
    /// Radius of the orientation disc, pixels (ORB's 15: a 31-pixel patch).
    pub patch_radius_px: u32,
}

impl Default for FeatureConfig {
    fn default() -> Self {
        Self { target_keypoints: 1000, levels: 3, cell_px: 32, fast_threshold: 7.0 / 255.0, patch_radius_px: 15 }
    }
}

impl FeatureConfig {
    /// Checks the values.
    pub fn validate(&self) -> Result<()> {
        let bad = |what: String| Err(Error::InvalidConfig(format!("features: {what}")));
        if self.target_keypoints == 0 || self.target_keypoints > 1 << 16 {
            return bad(format!("target_keypoints must be in 1..=65536, got {}", self.target_keypoints));
        }
        if !(1..=4).contains(&self.levels) {
            return bad(format!("levels must be 1..=4, got {}", self.levels));
        }
        if !(8..=256).contains(&self.cell_px) {
            return bad(format!("cell_px must be in 8..=256, got {}", self.cell_px));
        }
        if !(self.fast_threshold.is_finite() && self.fast_threshold >= 0.0 && self.fast_threshold < 1.0) {
            return bad(format!("fast_threshold must be in [0, 1), got {}", self.fast_threshold));
        }
        if (self.patch_radius_px as f32) < PATTERN_RADIUS_PX + 2.0 || self.patch_radius_px > 32 {
            return bad(format!("patch_radius_px must be in {}..=32, got {}", PATTERN_RADIUS_PX as u32 + 2, self.patch_radius_px));
        }
        Ok(())
    }

    /// Pixels near an edge without keypoints: the orientation disc and one more.
    pub fn border_px(&self) -> u32 {
        self.patch_radius_px + 1
    }

    /// The layout of every level's keypoint slots for a full-resolution image `k0`. Levels
    /// too small for one cell clear of the border are left out.
    pub fn layout(&self, k0: &PinholeIntrinsics) -> Vec<LevelLayout> {
        let sizes: Vec<(u32, u32)> = (0..self.levels).map(|l| (k0.width_px >> l, k0.height_px >> l)).filter(|&(w, h)| w > 2 * self.border_px() + 1 && h > 2 * self.border_px() + 1).collect();
        let cells: u32 = sizes.iter().map(|&(w, h)| w.div_ceil(self.cell_px) * h.div_ceil(self.cell_px)).sum();
        let per_cell = self.target_keypoints.div_ceil(cells.max(1)).clamp(1, MAX_PER_CELL);
        let mut offset = 0;
        sizes
            .iter()
            .enumerate()
            .map(|(l, &(w, h))| {
                let (cells_x, cells_y) = (w.div_ceil(self.cell_px), h.div_ceil(self.cell_px));
                let layout = LevelLayout { level: l as u32, width_px: w, height_px: h, cells_x, cells_y, per_cell, slot_offset: offset };
                offset += layout.slot_count();
                layout
            })
            .collect()
    }
}

/// Where one pyramid level's keypoints go.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LevelLayout {
    /// Pyramid level.
    pub level: u32,
    /// The level's width, pixels.
    pub width_px: u32,
    /// The level's height, pixels.
    pub height_px: u32,
    /// Grid cells across.
    pub cells_x: u32,
    /// Grid cells down.
    pub cells_y: u32,
    /// Keypoints per cell.
    pub per_cell: u32,
    /// The level's first slot.
    pub slot_offset: u32,
}

impl LevelLayout {
    /// Slots of the level.
    pub fn slot_count(&self) -> u32 {
        self.cells_x * self.cells_y * self.per_cell
    }

    /// `fast_score`'s parameters.
    pub fn fast_params(&self, config: &FeatureConfig) -> FastScoreParams {
        FastScoreParams { width_px: self.width_px, height_px: self.height_px, border_px: config.border_px(), threshold: config.fast_threshold }
    }

    /// `corner_candidates`' parameters, with the full-resolution intrinsics `k0`.
    pub fn candidates_params(&self, k0: &PinholeIntrinsics) -> CornerCandidatesParams {
        CornerCandidatesParams {
            width_px: self.width_px,
            height_px: self.height_px,
            level: self.level,
            depth_width_px: k0.width_px,
            depth_height_px: k0.height_px,
            fx_px: k0.fx_px,
            ..Default::default()
        }
    }

    /// `keypoint_select`'s parameters, with the full-resolution intrinsics `k0`.
    pub fn select_params(&self, config: &FeatureConfig, k0: &PinholeIntrinsics) -> KeypointSelectParams {
        KeypointSelectParams {
            width_px: self.width_px,
            height_px: self.height_px,
            level: self.level,
            cell_px: config.cell_px,
            cells_x: self.cells_x,
            cells_y: self.cells_y,
            per_cell: self.per_cell,
            slot_offset: self.slot_offset,
            depth_width_px: k0.width_px,
            depth_height_px: k0.height_px,
            fx_px: k0.fx_px,
            fy_px: k0.fy_px,
            cx_px: k0.cx_px,
            cy_px: k0.cy_px,
        }
    }

    /// `orb_describe`'s parameters.
    pub fn describe_params(&self, config: &FeatureConfig) -> OrbDescribeParams {
        OrbDescribeParams { width_px: self.width_px, height_px: self.height_px, slot_offset: self.slot_offset, slot_count: self.slot_count(), patch_radius_px: config.patch_radius_px }
    }
}

/// Total slots of a layout.
pub fn slot_count(layout: &[LevelLayout]) -> usize {
    layout.iter().map(|l| l.slot_count() as usize).sum()
}

/// The descriptor's 256 test pairs (ax, ay, bx, by), pixels, generated (not copied from ORB's
/// learned table): each point drawn from an isotropic Gaussian of σ = 31/5 px (BRIEF's
/// best-performing sampling, "G II", for a 31-pixel patch; Calonder et al. 2010) and redrawn
/// until it lies within [`PATTERN_RADIUS_PX`]; a pair is redrawn when its two points are
/// under 2 px apart (a test between nearly the same pixels carries noise, not structure).
/// Coordinates are rounded to whole pixels. The stream is PCG from a fixed seed, so the
/// pattern is the same everywhere and forever: changing it invalidates stored descriptors.
pub fn descriptor_pattern() -> Vec<[f32; 4]> {
    const SIGMA_PX: f32 = 31.0 / 5.0;
    let mut state = pcg_hash(0x0002_0b1e);
    let point = |state: &mut u32| loop {
        // Box-Muller on the shared stream, rounded to pixels.
        let (u1, u2) = (random_uniform(state), random_uniform(state));
        let r = (-2.0 * u1.ln()).sqrt() * SIGMA_PX;
        let phi = std::f32::consts::TAU * u2;
        let (x, y) = ((r * phi.cos()).round(), (r * phi.sin()).round());
        if x * x + y * y <= PATTERN_RADIUS_PX * PATTERN_RADIUS_PX {
            return [x, y];
        }
    };
    (0..DESCRIPTOR_BITS)
        .map(|_| loop {
            let (a, b) = (point(&mut state), point(&mut state));
            if (a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) >= 4.0 {
                return [a[0], a[1], b[0], b[1]];
            }
        })
        .collect()
}

/// One frame's keypoints, as the kernels leave them (one entry per slot; empty slots have
/// score 0, an invalid feature and point and a zero descriptor).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Features {
    /// Per slot: (x, y in level pixels, level, FAST score).
    pub keypoints: Vec<[f32; 4]>,
    /// Per slot: (x, y in full-resolution pixels, orientation radians, level).
    pub features: Vec<[f32; 4]>,
    /// Per slot: the point in the camera frame (x, y, z, 1), metres.
    pub points: Vec<[f32; 4]>,
    /// [`DESCRIPTOR_WORDS`] words per slot.
    pub descriptors: Vec<u32>,
}

impl Features {
    /// Empty features for `slots` slots.
    pub fn with_slots(slots: usize) -> Self {
        Self { keypoints: vec![[0.0; 4]; slots], features: vec![[0.0; 4]; slots], points: vec![[0.0; 4]; slots], descriptors: vec![0; slots * DESCRIPTOR_WORDS] }
    }

    /// Slots.
    pub fn slots(&self) -> usize {
        self.keypoints.len()
    }

    /// Whether slot `i` holds a keypoint.
    pub fn is_keypoint(&self, i: usize) -> bool {
        self.keypoints[i][3] > 0.0
    }

    /// Keypoints held.
    pub fn keypoint_count(&self) -> usize {
        (0..self.slots()).filter(|&i| self.is_keypoint(i)).count()
    }
}

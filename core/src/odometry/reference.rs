// SPDX-License-Identifier: MIT
//! The feature chain on the CPU: the kernels' twins in the GPU's order.

use super::{FeatureConfig, Features, descriptor_pattern, slot_count};
use crate::PinholeIntrinsics;
use crate::cpu;
use crate::kernels::hamming_match::HammingMatchParams;

/// Keypoints, points and descriptors of one frame: `intensity[l]` is pyramid level l's
/// intensity (level 0 at `k0`'s size) and `depth_m` the full-resolution metric depth before the
/// bilateral filter (what [`super::gpu::FeatureExtractor`] lifts keypoints with).
///
/// # Panics
/// If fewer intensity levels are given than the layout uses (a caller's bug).
pub fn extract(config: &FeatureConfig, k0: &PinholeIntrinsics, intensity: &[&[f32]], depth_m: &[f32]) -> Features {
    let layout = config.layout(k0);
    let pattern = descriptor_pattern();
    let mut out = Features::with_slots(slot_count(&layout));
    for level in &layout {
        let n = (level.width_px * level.height_px) as usize;
        let image = intensity[level.level as usize];
        let mut score = vec![0.0; n];
        cpu::fast_score(&level.fast_params(config), image, &mut score);
        let mut candidate = vec![0.0; n];
        cpu::corner_candidates(&level.candidates_params(k0), &score, depth_m, &mut candidate);
        cpu::keypoint_select(&level.select_params(config, k0), &candidate, depth_m, &mut out.keypoints, &mut out.points);
        let smoothed = cpu::odometry::feature_smooth::smooth_image(level.width_px, level.height_px, image);
        cpu::orb_describe(&level.describe_params(config), &smoothed, &out.keypoints, &pattern, &mut out.descriptors, &mut out.features);
    }
    out
}

/// The matching stage on the CPU: per slot of `query`, its nearest slot of `train` (the twin of
/// `hamming_match`).
pub fn matches(query: &Features, train: &Features) -> Vec<[u32; 4]> {
    let p = HammingMatchParams { query_count: query.slots() as u32, train_count: train.slots() as u32 };
    let mut out = vec![[0; 4]; query.slots()];
    cpu::hamming_match(&p, &query.keypoints, &query.descriptors, &train.keypoints, &train.descriptors, &mut out);
    out
}

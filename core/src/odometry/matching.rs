// SPDX-License-Identifier: MIT
//! Filters on the brute-force matches (`hamming_match`'s nearest and second-nearest), applied
//! on the GPU by `match_select` (and its twin on the CPU).

use crate::kernels::match_select::MatchSelectParams;
use crate::{Error, Result};

/// Which matches are kept.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MatchConfig {
    /// Lowe's ratio: keep when nearest < ratio · second-nearest (002 §4.2.2: 0.8).
    pub ratio: f32,
    /// Keep only pairs that are each other's nearest.
    pub mutual: bool,
    /// Reject matches farther than this, bits of 256: ORB-SLAM's loose bound (100) rounded to
    /// 3/8 of the bits; unrelated descriptors sit near 128.
    pub max_distance_bits: u32,
    /// 002's "outstanding" filter: keep when second − nearest ≥ this many bits. 002's 100 was
    /// an L2 distance between SIFT descriptors, whose unrelated pairs sit near 450; the same
    /// fraction of a 256-bit descriptor's unrelated distance (128) is 28 bits. Off by default
    /// (the ratio test does the same job scale-free).
    pub margin_bits: Option<u32>,
    /// 002's keep-best percentage: only the best fraction of the surviving matches by distance
    /// (002: 0.2). Off by default: RANSAC needs the inliers more than it fears outliers.
    pub keep_best_fraction: Option<f32>,
}

impl Default for MatchConfig {
    fn default() -> Self {
        Self { ratio: 0.8, mutual: true, max_distance_bits: 96, margin_bits: None, keep_best_fraction: None }
    }
}

impl MatchConfig {
    /// Checks the values (a NaN from a form is an error, not a filter that keeps nothing).
    pub fn validate(&self) -> Result<()> {
        if !(self.ratio > 0.0 && self.ratio <= 1.0) {
            return Err(Error::InvalidConfig(format!("matching: ratio must be in (0, 1], got {}", self.ratio)));
        }
        if let Some(f) = self.keep_best_fraction
            && !(f > 0.0 && f <= 1.0)
        {
            return Err(Error::InvalidConfig(format!("matching: keep_best_fraction must be in (0, 1], got {f}")));
        }
        Ok(())
    }

    /// `match_select`'s parameters for frames of `slots` keypoint slots (an absent margin is
    /// 0 bits, an absent keep-best fraction keeps all).
    pub fn select_params(&self, slots: u32) -> MatchSelectParams {
        MatchSelectParams {
            slots,
            mutual: u32::from(self.mutual),
            max_distance_bits: self.max_distance_bits,
            margin_bits: self.margin_bits.unwrap_or(0),
            ratio: self.ratio,
            keep_best_fraction: self.keep_best_fraction.unwrap_or(1.0),
            ..Default::default()
        }
    }
}

/// A kept match: slot `query` of the current frame and slot `train` of the reference.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Match {
    /// Slot in the current frame.
    pub query: u32,
    /// Slot in the reference frame.
    pub train: u32,
    /// Hamming distance, bits.
    pub distance_bits: u32,
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cpu;
    use crate::cpu::shared::NO_MATCH;
    use crate::kernels::gpu_data::{FeaturePair, RigidEstimate};

    /// The current slots `match_select`'s twin keeps under `config` (every point valid).
    fn kept(config: &MatchConfig, forward: &[[u32; 4]], backward: &[[u32; 4]]) -> Vec<u32> {
        let points = vec![[0.1f32, 0.2, 1.5, 1.0]; forward.len().max(backward.len())];
        let keypoints = vec![[0.0f32, 0.0, 0.0, 1.0]; points.len()];
        let mut pairs = vec![FeaturePair::default(); forward.len()];
        let mut estimate = RigidEstimate::default();
        cpu::match_select(&config.select_params(forward.len() as u32), forward, backward, &keypoints, &points, &keypoints, &points, &mut pairs, &mut estimate);
        pairs[..estimate.pairs as usize].iter().map(|p| p.slots[0]).collect()
    }

    #[test]
    fn each_filter_drops_what_it_should() {
        // Query 0: clear and mutual; 1: ambiguous (ratio); 2: not mutual; 3: too far; 4: none.
        let forward = [[5, 10, 60, 0], [6, 50, 55, 0], [7, 20, 80, 0], [8, 120, 200, 0], [NO_MATCH, 257, 257, 0], [NO_MATCH, 257, 257, 0], [NO_MATCH, 257, 257, 0], [NO_MATCH, 257, 257, 0], [NO_MATCH, 257, 257, 0], [NO_MATCH, 257, 257, 0]];
        let mut backward = vec![[NO_MATCH, 257, 257, 0]; 10];
        backward[5][0] = 0;
        backward[6][0] = 1;
        backward[7][0] = 9;
        backward[8][0] = 3;
        assert_eq!(kept(&MatchConfig::default(), &forward, &backward), vec![0]);
        let loose = MatchConfig { mutual: false, ..MatchConfig::default() };
        assert_eq!(kept(&loose, &forward, &backward), vec![0, 2]);
        let margin = MatchConfig { mutual: false, margin_bits: Some(55), ..MatchConfig::default() };
        assert_eq!(kept(&margin, &forward, &backward), vec![2]);
        let best = MatchConfig { mutual: false, keep_best_fraction: Some(0.5), ..MatchConfig::default() };
        assert_eq!(kept(&best, &forward, &backward), vec![0]);
        assert!(MatchConfig { ratio: f32::NAN, ..MatchConfig::default() }.validate().is_err());
        assert!(MatchConfig { keep_best_fraction: Some(0.0), ..MatchConfig::default() }.validate().is_err());
    }
}

// SPDX-License-Identifier: MIT
//! Filters on the brute-force matches (`hamming_match`'s nearest and second-nearest).

use crate::cpu::shared::NO_MATCH;
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

/// The matches `forward` (per query: nearest train slot, its distance, the second distance)
/// keeps under `config`; `backward` is the same from the train side, for the mutual check.
/// Sorted by query slot (by distance when keep-best applies).
pub fn filter_matches(config: &MatchConfig, forward: &[[u32; 4]], backward: &[[u32; 4]]) -> Vec<Match> {
    let mut kept: Vec<Match> = forward
        .iter()
        .enumerate()
        .filter_map(|(q, &[train, d1, d2, _])| {
            if train == NO_MATCH || d1 > config.max_distance_bits || (d1 as f32) >= config.ratio * d2 as f32 {
                return None;
            }
            if config.margin_bits.is_some_and(|m| d2 - d1 < m) {
                return None;
            }
            if config.mutual && backward.get(train as usize).is_none_or(|b| b[0] != q as u32) {
                return None;
            }
            Some(Match { query: q as u32, train, distance_bits: d1 })
        })
        .collect();
    if let Some(f) = config.keep_best_fraction {
        kept.sort_by_key(|m| (m.distance_bits, m.query));
        kept.truncate(((kept.len() as f32 * f).ceil() as usize).min(kept.len()));
    }
    kept
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_filter_drops_what_it_should() {
        // Query 0: clear and mutual; 1: ambiguous (ratio); 2: not mutual; 3: too far; 4: none.
        let forward = [[5, 10, 60, 0], [6, 50, 55, 0], [7, 20, 80, 0], [8, 120, 200, 0], [NO_MATCH, 257, 257, 0]];
        let mut backward = vec![[NO_MATCH, 257, 257, 0]; 9];
        backward[5][0] = 0;
        backward[6][0] = 1;
        backward[7][0] = 9;
        backward[8][0] = 3;
        let kept = filter_matches(&MatchConfig::default(), &forward, &backward);
        assert_eq!(kept, vec![Match { query: 0, train: 5, distance_bits: 10 }]);
        let loose = MatchConfig { mutual: false, ..MatchConfig::default() };
        assert_eq!(filter_matches(&loose, &forward, &backward).iter().map(|m| m.query).collect::<Vec<_>>(), vec![0, 2]);
        let margin = MatchConfig { mutual: false, margin_bits: Some(55), ..MatchConfig::default() };
        assert_eq!(filter_matches(&margin, &forward, &backward).iter().map(|m| m.query).collect::<Vec<_>>(), vec![2]);
        let best = MatchConfig { mutual: false, keep_best_fraction: Some(0.5), ..MatchConfig::default() };
        assert_eq!(filter_matches(&best, &forward, &backward).iter().map(|m| m.query).collect::<Vec<_>>(), vec![0]);
        assert!(MatchConfig { ratio: f32::NAN, ..MatchConfig::default() }.validate().is_err());
        assert!(MatchConfig { keep_best_fraction: Some(0.0), ..MatchConfig::default() }.validate().is_err());
    }
}

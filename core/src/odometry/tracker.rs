// SPDX-License-Identifier: MIT
//! Frame-to-frame feature odometry: each frame's motion against the reference frame (the last
//! one tracked), from the matched keypoints' 3D points.

use glam::DVec3;

use super::matching::{Match, MatchConfig, filter_matches};
use super::rigid::{Correspondence, RansacConfig, RigidEstimate, ransac};
use super::{FeatureConfig, Features};
use crate::{PinholeIntrinsics, Result, Se3};

/// Feature odometry's settings.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct OdometryConfig {
    /// Detection and description.
    pub features: FeatureConfig,
    /// Match filters.
    pub matching: MatchConfig,
    /// Robust motion estimation.
    pub ransac: RansacConfig,
}

impl OdometryConfig {
    /// Checks every part.
    pub fn validate(&self) -> Result<()> {
        self.features.validate()?;
        self.matching.validate()
    }
}

/// One frame's outcome.
#[derive(Clone, Debug, PartialEq)]
pub struct MotionEstimate {
    /// Keypoints of the current frame.
    pub keypoints: usize,
    /// Matches kept by the filters.
    pub matches: usize,
    /// The kept matches (current slot → reference slot).
    pub matched: Vec<Match>,
    /// RANSAC's result (`None`: rejected, too few inliers).
    pub rigid: Option<RigidEstimate>,
}

impl MotionEstimate {
    /// The reference camera from the current one, when accepted.
    pub fn reference_from_current(&self) -> Option<Se3> {
        self.rigid.as_ref().map(|r| r.dst_from_src)
    }

    /// Inliers (0 when rejected).
    pub fn inliers(&self) -> usize {
        self.rigid.as_ref().map_or(0, |r| r.inliers.len())
    }
}

/// The 3D pairs of `matched` (current → reference), with their noise.
pub fn correspondences(k0: &PinholeIntrinsics, current: &Features, reference: &Features, matched: &[Match]) -> Vec<Correspondence> {
    let f = f64::from(k0.fx_px.max(k0.fy_px));
    let v = |p: [f32; 4]| DVec3::new(f64::from(p[0]), f64::from(p[1]), f64::from(p[2]));
    matched
        .iter()
        .map(|m| {
            let (q, t) = (m.query as usize, m.train as usize);
            Correspondence::new(v(current.points[q]), current.keypoints[q][2] as u32, v(reference.points[t]), reference.keypoints[t][2] as u32, f)
        })
        .collect()
}

/// The motion of `current` against `reference` from the matcher's nearest neighbours both
/// ways (`forward`: per current slot; `backward`: per reference slot); `seed` seeds RANSAC.
pub fn estimate_motion(config: &OdometryConfig, k0: &PinholeIntrinsics, current: &Features, reference: &Features, forward: &[[u32; 4]], backward: &[[u32; 4]], seed: u32) -> MotionEstimate {
    let matched = filter_matches(&config.matching, forward, backward);
    let corr = correspondences(k0, current, reference, &matched);
    let rigid = ransac(&corr, &config.ransac, seed);
    MotionEstimate { keypoints: current.keypoint_count(), matches: matched.len(), matched, rigid }
}

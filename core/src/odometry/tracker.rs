// SPDX-License-Identifier: MIT
//! Frame-to-frame feature odometry: each frame's motion against the reference frame (the last
//! one tracked), from the matched keypoints' 3D points.

use super::matching::{Match, MatchConfig};
use super::rigid::{RansacConfig, RigidEstimate, correspondences, motion_covariance};
use super::{FeatureConfig, Features};
use crate::cpu;
use crate::cpu::odometry::estimate::RANSAC_MAX_HYPOTHESES;
use crate::kernels::gpu_data::{FeaturePair, RigidEstimate as GpuEstimate};
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
        self.matching.validate()?;
        self.ransac.validate()
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

/// The focal length the estimate's lateral noise uses, pixels.
pub fn focal_px(k0: &PinholeIntrinsics) -> f32 {
    k0.fx_px.max(k0.fy_px)
}

/// A frame's outcome from what the GPU estimate (or its twins) wrote: the estimate, the first
/// `estimate.pairs` pairs and their inlier flags; `keypoints` of the current frame; the
/// motion's covariance from the inliers in f64 (`motion_covariance`) for focal length `f_px`.
pub fn motion_from_estimate(keypoints: usize, estimate: &GpuEstimate, pairs: &[FeaturePair], inlier_flags: &[u32], f_px: f32) -> MotionEstimate {
    let n = (estimate.pairs as usize).min(pairs.len()).min(inlier_flags.len());
    let matched: Vec<Match> = pairs[..n].iter().map(|p| Match { query: p.slots[0], train: p.slots[1], distance_bits: p.slots[2] }).collect();
    let rigid = (estimate.accepted == 1).then(|| {
        let dst_from_src = Se3::from_cols_f32(&estimate.dst_from_src);
        let inliers: Vec<usize> = (0..n).filter(|&i| inlier_flags[i] == 1).collect();
        let noise_scale = f64::from(estimate.noise_scale);
        let covariance = motion_covariance(&correspondences(&pairs[..n], f64::from(f_px)), &inliers, &dst_from_src, noise_scale);
        RigidEstimate { dst_from_src, inliers, rmse_m: f64::from(estimate.rmse_m), noise_scale, covariance }
    });
    MotionEstimate { keypoints, matches: n, matched, rigid }
}

/// The motion of `current` against `reference` on the CPU, by the twins of the GPU's
/// estimate (`match_select`, `ransac_hypotheses`, `ransac_refine`) from the matcher's nearest
/// neighbours both ways (`forward`: per current slot; `backward`: per reference slot); `seed`
/// seeds RANSAC.
pub fn estimate_motion(config: &OdometryConfig, k0: &PinholeIntrinsics, current: &Features, reference: &Features, forward: &[[u32; 4]], backward: &[[u32; 4]], seed: u32) -> MotionEstimate {
    let slots = current.slots();
    let mut pairs = vec![FeaturePair::default(); slots];
    let mut estimate = GpuEstimate::default();
    cpu::match_select(&config.matching.select_params(slots as u32), forward, backward, &current.keypoints, &current.points, &reference.keypoints, &reference.points, &mut pairs, &mut estimate);
    let params = config.ransac.params(focal_px(k0), seed);
    let mut hypotheses = vec![[[0.0f32; 4]; 4]; RANSAC_MAX_HYPOTHESES as usize];
    let mut costs = vec![0.0f32; RANSAC_MAX_HYPOTHESES as usize];
    cpu::ransac_hypotheses(&params, &pairs, &estimate, &mut hypotheses, &mut costs);
    let (mut residuals, mut flags) = (vec![0.0f32; slots], vec![0u32; slots]);
    cpu::ransac_refine(&params, &hypotheses, &costs, &pairs, &mut estimate, &mut residuals, &mut flags);
    motion_from_estimate(current.keypoint_count(), &estimate, &pairs, &flags, focal_px(k0))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cpu::preprocess::chain::preprocess;
    use crate::odometry::reference::{extract, matches};
    use crate::preprocess::PreprocessConfig;
    use crate::sim::room::SyntheticRoom;
    use crate::{PinholeIntrinsics, RgbdCalibration};

    /// The synthetic room (exact depth and a view-independent texture) at consecutive poses of
    /// its loop: the whole CPU chain (twins of every kernel, the GPU's estimate included)
    /// recovers each motion within issue 14's 2 mm and 0.2°. Measured: 1.93, 1.38, 1.43 mm and
    /// 0.04-0.05° (the f64 host estimate it replaced: 1.4-2.3 mm). Keypoints sit on whole level
    /// pixels: a parabola fit on the FAST score reached 0.8-1.9 mm here but made the real
    /// sequences worse (FAST's score is too rough to interpolate), so it is not used.
    #[test]
    fn exact_synthetic_motions_are_recovered_within_2_mm_and_0_2_degrees() {
        let k = PinholeIntrinsics { fx_px: 525.0, fy_px: 525.0, cx_px: 319.5, cy_px: 239.5, width_px: 640, height_px: 480 };
        let calibration = RgbdCalibration { intrinsics: k, depth_units_per_metre: 5000.0 };
        let room = SyntheticRoom::new(6.0, 3.0, 6.0);
        let path = room.path(90);
        let config = OdometryConfig::default();
        let features = |i: usize| {
            let pre = preprocess(&calibration, &PreprocessConfig::default(), &room.frame(&k, &path, i));
            let levels: Vec<&[f32]> = pre.levels.iter().map(|l| l.intensity.as_slice()).collect();
            extract(&config.features, &k, &levels, &pre.depth_unfiltered_m)
        };
        let mut previous = features(0);
        for i in 1..4 {
            let current = features(i);
            let (forward, backward) = (matches(&current, &previous), matches(&previous, &current));
            let e = estimate_motion(&config, &k, &current, &previous, &forward, &backward, i as u32);
            let got = e.reference_from_current().unwrap_or_else(|| panic!("frame {i}: rejected ({} matches)", e.matches));
            let truth = path[i - 1].inverse().compose(&path[i]);
            let error = truth.inverse().compose(&got);
            let (t_mm, r_deg) = (error.translation_m.length() * 1e3, error.rotation_angle_rad().to_degrees());
            eprintln!("frame {i}: {} keypoints, {} matches, {} inliers, error {t_mm:.3} mm {r_deg:.4}°", e.keypoints, e.matches, e.inliers());
            assert!(t_mm < 2.0 && r_deg < 0.2, "frame {i}: error {t_mm} mm, {r_deg}°");
            previous = current;
        }
    }
}

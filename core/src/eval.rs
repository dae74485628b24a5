// SPDX-License-Identifier: MIT
//! Trajectory evaluation with the conventions of the TUM RGB-D benchmark and of `evo`:
//! timestamp association, Horn/Umeyama alignment, absolute trajectory error (ATE) and relative
//! pose error (RPE).
//!
//! - [`associate`] follows the benchmark's `associate.py`: every pair of stamps closer than the
//!   maximum difference is a candidate, candidates are taken greedily by smallest |Δt| and each
//!   stamp is used at most once. (`evo` instead gives every pose of the shorter trajectory its
//!   nearest stamp in the longer one; on trajectories sampled as the benchmark's are, e.g. ground
//!   truth at 100 Hz and estimates at 30 Hz, the two give the same pairs.)
//! - [`ate`] is `evo_ape tum GT EST -a` (or without `-a`, or with `-as`): pose relation
//!   "translation part", i.e. the distance between the aligned estimated position and the
//!   ground-truth position of every associated pair.
//! - [`rpe`] is `evo_rpe tum GT EST --delta 1 --delta_unit f`: for pose pairs `(i, j)` `delta`
//!   frames apart, `E = (gt_i⁻¹ gt_j)⁻¹ (est_i⁻¹ est_j)`; the translation error is `|t(E)|` and
//!   the rotation error is the angle of `R(E)` in degrees.
//!
//! Statistics are those `evo` prints: RMSE, mean, median (mean of the two middle values for an
//! even count), standard deviation (population, as `numpy.std`), minimum and maximum.

use glam::{DMat3, DQuat, DVec3};
use nalgebra::{Matrix3, Vector3};

use crate::io::TimedPose;
use crate::{Error, Result, Se3};

/// Default largest |t_gt − t_est| for two poses to be associated, in nanoseconds (20 ms, the
/// default `--max_difference` of the benchmark's `associate.py` and `evaluate_ate.py`; `evo`'s
/// default `--t_max_diff` is 10 ms).
pub const DEFAULT_MAX_DIFFERENCE_NS: u64 = 20_000_000;

/// Default RPE pose distance, in frames (associated poses), as `evo_rpe --delta 1 --delta_unit f`.
pub const DEFAULT_DELTA_FRAMES: usize = 1;

/// Umeyama alignment needs the cross-covariance of the two point sets to have rank ≥ 2; a
/// singular value at most this fraction of the largest one counts as zero (points on a line,
/// or all at one place).
const ALIGNMENT_RANK_TOLERANCE: f64 = 1e-12;

/// Iteration cap of the 3×3 SVD (it converges in a handful; the cap only guards against a hang).
const SVD_MAX_ITERATIONS: usize = 1000;

/// ATE with alignment needs three non-collinear positions.
const MIN_PAIRS_FOR_ALIGNMENT: usize = 3;

/// One associated pair: indices into the ground-truth and estimated slices.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Association {
    /// Index into the ground-truth poses.
    pub gt_ix: usize,
    /// Index into the estimated poses.
    pub est_ix: usize,
}

/// Associates ground-truth and estimated poses by timestamp, with the semantics of the TUM
/// benchmark's `associate.py` (no time offset).
///
/// Every pair with `|t_gt − t_est| < max_difference_ns` (strictly, as `associate.py`) is a
/// candidate; candidates are taken in order of increasing |Δt| (ties: earlier ground-truth stamp,
/// then earlier estimated stamp), each pose at most once. The result is sorted by estimated
/// timestamp (then estimated index). Poses need not be sorted; `max_difference_ns == 0` gives no
/// pairs. Memory grows with the number of candidates, so a huge maximum difference on long
/// trajectories is slow.
pub fn associate(gt: &[TimedPose], est: &[TimedPose], max_difference_ns: u64) -> Vec<Association> {
    let mut gt_order: Vec<usize> = (0..gt.len()).collect();
    gt_order.sort_by_key(|&ix| (gt[ix].timestamp_ns, ix));

    // (|Δt|, t_gt, t_est, gt_ix, est_ix): the sort key of associate.py's `(diff, a, b)`, plus
    // indices to break ties between equal stamps deterministically.
    let mut candidates: Vec<(u64, i64, i64, usize, usize)> = Vec::new();
    for (est_ix, est_pose) in est.iter().enumerate() {
        let t_est = est_pose.timestamp_ns;
        let too_early = |t_gt: i64| t_gt < t_est && t_gt.abs_diff(t_est) >= max_difference_ns;
        let first = gt_order.partition_point(|&ix| too_early(gt[ix].timestamp_ns));
        for &gt_ix in &gt_order[first..] {
            let t_gt = gt[gt_ix].timestamp_ns;
            let dt_ns = t_gt.abs_diff(t_est);
            if dt_ns < max_difference_ns {
                candidates.push((dt_ns, t_gt, t_est, gt_ix, est_ix));
            } else if t_gt > t_est {
                break;
            }
        }
    }
    candidates.sort_unstable();

    let mut gt_used = vec![false; gt.len()];
    let mut est_used = vec![false; est.len()];
    let mut pairs = Vec::new();
    for &(_, _, _, gt_ix, est_ix) in &candidates {
        if !gt_used[gt_ix] && !est_used[est_ix] {
            gt_used[gt_ix] = true;
            est_used[est_ix] = true;
            pairs.push(Association { gt_ix, est_ix });
        }
    }
    pairs.sort_unstable_by_key(|pair| (est[pair.est_ix].timestamp_ns, pair.est_ix));
    pairs
}

/// A similarity transform found by [`umeyama_se3`]: `point_in_gt ≈ gt_from_est * (scale * point_in_est)`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Alignment {
    /// Rotation and translation (metres) taking scaled estimated positions into the ground-truth frame.
    pub gt_from_est: Se3,
    /// Scale applied to estimated positions first; exactly 1 without scale correction.
    pub scale: f64,
}

impl Alignment {
    /// No alignment at all.
    pub const IDENTITY: Self = Self { gt_from_est: Se3::IDENTITY, scale: 1.0 };

    /// Maps a position of the estimated trajectory into the ground-truth frame.
    pub fn transform_point(&self, point_in_est: DVec3) -> DVec3 {
        self.gt_from_est.transform_point(self.scale * point_in_est)
    }

    /// Maps a pose of the estimated trajectory (`est_world_from_camera`) into the ground-truth
    /// frame: the camera position is transformed as a point, the orientation is rotated.
    pub fn transform_pose(&self, est_world_from_camera: &Se3) -> Se3 {
        Se3 {
            rotation: (self.gt_from_est.rotation * est_world_from_camera.rotation).normalize(),
            translation_m: self.transform_point(est_world_from_camera.translation_m),
        }
    }
}

/// Least-squares rigid (or, with `with_scale`, similarity) transform taking `points_in_est` onto
/// `points_in_gt` (Horn 1987 / Umeyama 1991, as `evo`'s `umeyama_alignment`): minimises
/// `Σ |point_in_gt − (R (c · point_in_est) + t)|²`, with `c = 1` unless `with_scale`.
///
/// Reflection-safe: the rotation is proper (det +1) even when the best orthogonal fit is a
/// reflection. Errors: [`Error::InvalidConfig`] for slices of different lengths,
/// [`Error::TooFewAssociations`] for fewer than three points, [`Error::DegenerateAlignment`]
/// for non-finite coordinates or points that do not span a plane (all on one line).
pub fn umeyama_se3(points_in_est: &[DVec3], points_in_gt: &[DVec3], with_scale: bool) -> Result<Alignment> {
    if points_in_est.len() != points_in_gt.len() {
        return Err(Error::InvalidConfig(format!(
            "umeyama_se3: {} estimated points but {} ground-truth points",
            points_in_est.len(),
            points_in_gt.len()
        )));
    }
    let n_points = points_in_est.len();
    if n_points < MIN_PAIRS_FOR_ALIGNMENT {
        return Err(Error::TooFewAssociations { what: "Umeyama alignment", pairs: n_points, required: MIN_PAIRS_FOR_ALIGNMENT });
    }
    if !points_in_est.iter().chain(points_in_gt).all(|p| p.is_finite()) {
        return Err(Error::DegenerateAlignment { message: "a position is NaN or infinite".to_owned() });
    }

    let inv_n = 1.0 / n_points as f64;
    let mean_est = points_in_est.iter().sum::<DVec3>() * inv_n;
    let mean_gt = points_in_gt.iter().sum::<DVec3>() * inv_n;
    let mut variance_est_m2 = 0.0;
    let mut covariance = Matrix3::<f64>::zeros();
    for (p_est, p_gt) in points_in_est.iter().zip(points_in_gt) {
        let x = *p_est - mean_est;
        let y = *p_gt - mean_gt;
        variance_est_m2 += x.length_squared();
        covariance += Vector3::new(y.x, y.y, y.z) * Vector3::new(x.x, x.y, x.z).transpose();
    }
    let moments = Moments { n_points, mean_est, mean_gt, variance_est_m2: variance_est_m2 * inv_n, covariance: covariance * inv_n };
    Ok(umeyama_from_moments(&moments, with_scale)?.0)
}

/// First and second moments of paired positions: what the Umeyama alignment needs.
struct Moments {
    n_points: usize,
    mean_est: DVec3,
    mean_gt: DVec3,
    /// Mean squared distance of the estimated positions from their mean, m².
    variance_est_m2: f64,
    /// Cross-covariance `(1/n) Σ (p_gt − mean_gt)(p_est − mean_est)ᵀ`, m².
    covariance: Matrix3<f64>,
}

/// The alignment the moments give, and `tr(D S)` (the sum of the signed singular values of
/// the cross-covariance, which the residual needs).
fn umeyama_from_moments(m: &Moments, with_scale: bool) -> Result<(Alignment, f64)> {
    let svd = nalgebra::linalg::SVD::try_new(m.covariance, true, true, f64::EPSILON, SVD_MAX_ITERATIONS)
        .ok_or_else(|| Error::DegenerateAlignment { message: "the SVD of the cross-covariance did not converge".to_owned() })?;
    let (Some(u), Some(v_t)) = (svd.u, svd.v_t) else {
        return Err(Error::DegenerateAlignment { message: "the SVD returned no singular vectors".to_owned() });
    };
    let d = svd.singular_values;
    if !(d[0] > 0.0) || !(d[1] > d[0] * ALIGNMENT_RANK_TOLERANCE) {
        return Err(Error::DegenerateAlignment {
            message: format!(
                "the {} positions are collinear or coincident (cross-covariance singular values {:.3e}, {:.3e}, {:.3e} m²)",
                m.n_points, d[0], d[1], d[2]
            ),
        });
    }
    let mut s = Vector3::new(1.0, 1.0, 1.0);
    if u.determinant() * v_t.determinant() < 0.0 {
        s[2] = -1.0;
    }
    let rotation_matrix = u * Matrix3::from_diagonal(&s) * v_t;
    let trace_ds = d.dot(&s);
    let scale = if with_scale { trace_ds / m.variance_est_m2 } else { 1.0 };

    let rotation = DQuat::from_mat3(&DMat3::from_cols_slice(rotation_matrix.as_slice())).normalize();
    let translation_m = m.mean_gt - scale * (rotation * m.mean_est);
    Ok((Alignment { gt_from_est: Se3 { rotation, translation_m }, scale }, trace_ds))
}

/// ATE (SE(3)-aligned position RMSE, as [`ate`] with its default alignment and no scale) of a
/// trajectory that grows one pair at a time, in O(1) per pair and per query: it keeps the
/// positions' moments instead of the positions, so a live view can show the error of every
/// frame so far without redoing the alignment over all of them.
///
/// The residual of the best rigid fit follows from the moments (Umeyama 1991):
/// `RMSE² = σ²_gt + σ²_est − 2 tr(D S)`. Sums are taken relative to the first pair, so
/// trajectories far from the origin lose no precision.
#[derive(Clone, Debug, Default)]
pub struct RunningAte {
    origin_est: DVec3,
    origin_gt: DVec3,
    n_points: usize,
    sum_est: DVec3,
    sum_gt: DVec3,
    sum_sq_est: f64,
    sum_sq_gt: f64,
    sum_gt_est: Matrix3<f64>,
}

impl RunningAte {
    /// Adds the estimated and ground-truth positions of one frame.
    pub fn push(&mut self, position_in_est: DVec3, position_in_gt: DVec3) {
        if self.n_points == 0 {
            self.origin_est = position_in_est;
            self.origin_gt = position_in_gt;
        }
        let x = position_in_est - self.origin_est;
        let y = position_in_gt - self.origin_gt;
        self.n_points += 1;
        self.sum_est += x;
        self.sum_gt += y;
        self.sum_sq_est += x.length_squared();
        self.sum_sq_gt += y.length_squared();
        self.sum_gt_est += Vector3::new(y.x, y.y, y.z) * Vector3::new(x.x, x.y, x.z).transpose();
    }

    /// Pairs so far.
    pub fn len(&self) -> usize {
        self.n_points
    }

    /// Whether no pair was added.
    pub fn is_empty(&self) -> bool {
        self.n_points == 0
    }

    /// The best rigid alignment of the pairs so far and the RMSE of the positions after it,
    /// metres. Errors as [`umeyama_se3`]'s (fewer than three pairs, collinear or non-finite
    /// positions).
    pub fn alignment_and_rmse_m(&self) -> Result<(Alignment, f64)> {
        if self.n_points < MIN_PAIRS_FOR_ALIGNMENT {
            return Err(Error::TooFewAssociations { what: "Umeyama alignment", pairs: self.n_points, required: MIN_PAIRS_FOR_ALIGNMENT });
        }
        let inv_n = 1.0 / self.n_points as f64;
        let (mean_x, mean_y) = (self.sum_est * inv_n, self.sum_gt * inv_n);
        if !(mean_x.is_finite() && mean_y.is_finite() && self.sum_sq_est.is_finite() && self.sum_sq_gt.is_finite()) {
            return Err(Error::DegenerateAlignment { message: "a position is NaN or infinite".to_owned() });
        }
        let covariance = self.sum_gt_est * inv_n - Vector3::new(mean_y.x, mean_y.y, mean_y.z) * Vector3::new(mean_x.x, mean_x.y, mean_x.z).transpose();
        let variance_est_m2 = (self.sum_sq_est * inv_n - mean_x.length_squared()).max(0.0);
        let variance_gt_m2 = (self.sum_sq_gt * inv_n - mean_y.length_squared()).max(0.0);
        let moments = Moments { n_points: self.n_points, mean_est: mean_x, mean_gt: mean_y, variance_est_m2, covariance };
        let (relative, trace_ds) = umeyama_from_moments(&moments, false)?;
        let rmse_m = (variance_gt_m2 + variance_est_m2 - 2.0 * trace_ds).max(0.0).sqrt();
        // Undo the origins: p_gt = origin_gt + R (p_est − origin_est) + t.
        let rotation = relative.gt_from_est.rotation;
        let translation_m = self.origin_gt + relative.gt_from_est.translation_m - rotation * self.origin_est;
        Ok((Alignment { gt_from_est: Se3 { rotation, translation_m }, scale: 1.0 }, rmse_m))
    }
}

/// Summary statistics of a set of errors, as `evo` reports them. Units are those of the field
/// holding the statistics (`error_m`, `rotation_deg`, ...).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ErrorStats {
    /// Number of errors.
    pub count: usize,
    /// Root mean square.
    pub rmse: f64,
    /// Arithmetic mean.
    pub mean: f64,
    /// Median (mean of the two middle values for an even count, as `numpy.median`).
    pub median: f64,
    /// Population standard deviation (`numpy.std`, ddof = 0).
    pub std: f64,
    /// Smallest error.
    pub min: f64,
    /// Largest error.
    pub max: f64,
}

impl ErrorStats {
    /// Statistics of `errors`; `None` when empty.
    pub fn from_errors(errors: &[f64]) -> Option<Self> {
        if errors.is_empty() {
            return None;
        }
        let n = errors.len() as f64;
        let mean = errors.iter().sum::<f64>() / n;
        let mean_square = errors.iter().map(|e| e * e).sum::<f64>() / n;
        let variance = errors.iter().map(|e| (e - mean) * (e - mean)).sum::<f64>() / n;
        let mut sorted = errors.to_vec();
        sorted.sort_unstable_by(f64::total_cmp);
        let mid = sorted.len() / 2;
        let median = if sorted.len() % 2 == 1 { sorted[mid] } else { 0.5 * (sorted[mid - 1] + sorted[mid]) };
        Some(Self {
            count: errors.len(),
            rmse: mean_square.sqrt(),
            mean,
            median,
            std: variance.sqrt(),
            min: sorted[0],
            max: sorted[sorted.len() - 1],
        })
    }
}

/// Options of [`ate`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct AteOptions {
    /// Largest |t_gt − t_est| for association, nanoseconds (see [`associate`]).
    pub max_difference_ns: u64,
    /// Align the estimate to the ground truth with [`umeyama_se3`] first (`evo_ape -a`).
    pub align: bool,
    /// Also correct the scale (`evo_ape -s`): with `align`, a Sim(3) alignment (`-as`); without,
    /// only the scale of the Sim(3) fit is applied, as `evo` does.
    pub correct_scale: bool,
}

impl Default for AteOptions {
    fn default() -> Self {
        Self { max_difference_ns: DEFAULT_MAX_DIFFERENCE_NS, align: true, correct_scale: false }
    }
}

/// Result of [`ate`].
#[derive(Clone, Debug, PartialEq)]
pub struct AteReport {
    /// Associated poses, sorted by estimated timestamp.
    pub pairs: Vec<Association>,
    /// Transform applied to the estimate before measuring ([`Alignment::IDENTITY`] without
    /// alignment or scale correction).
    pub alignment: Alignment,
    /// Distance between aligned estimated and ground-truth position of each pair, metres (same
    /// order as `pairs`).
    pub per_pair_error_m: Vec<f64>,
    /// Statistics of `per_pair_error_m`, metres.
    pub error_m: ErrorStats,
}

/// Absolute trajectory error, translation part (`evo_ape tum GT EST [-a] [-s]`).
///
/// Errors: [`Error::TooFewAssociations`] when fewer than 1 pair (3 with alignment or scale
/// correction) associate, [`Error::DegenerateAlignment`] when the associated estimated
/// positions are collinear and alignment was asked for.
pub fn ate(gt: &[TimedPose], est: &[TimedPose], options: &AteOptions) -> Result<AteReport> {
    let pairs = associate(gt, est, options.max_difference_ns);
    let fit = options.align || options.correct_scale;
    let required = if fit { MIN_PAIRS_FOR_ALIGNMENT } else { 1 };
    if pairs.len() < required {
        let what = if fit { "ATE with alignment" } else { "ATE" };
        return Err(Error::TooFewAssociations { what, pairs: pairs.len(), required });
    }
    let points_in_gt: Vec<DVec3> = pairs.iter().map(|p| gt[p.gt_ix].world_from_camera.translation_m).collect();
    let points_in_est: Vec<DVec3> = pairs.iter().map(|p| est[p.est_ix].world_from_camera.translation_m).collect();
    let alignment = if fit {
        let sim3 = umeyama_se3(&points_in_est, &points_in_gt, options.correct_scale)?;
        if options.align { sim3 } else { Alignment { scale: sim3.scale, ..Alignment::IDENTITY } }
    } else {
        Alignment::IDENTITY
    };
    let per_pair_error_m: Vec<f64> =
        points_in_est.iter().zip(&points_in_gt).map(|(p_est, p_gt)| (alignment.transform_point(*p_est) - *p_gt).length()).collect();
    let error_m = ErrorStats::from_errors(&per_pair_error_m).ok_or(Error::TooFewAssociations { what: "ATE", pairs: 0, required })?;
    Ok(AteReport { pairs, alignment, per_pair_error_m, error_m })
}

/// Options of [`rpe`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RpeOptions {
    /// Largest |t_gt − t_est| for association, nanoseconds (see [`associate`]).
    pub max_difference_ns: u64,
    /// Distance between the two poses of each relative pose, in associated poses (frames); ≥ 1.
    pub delta_frames: usize,
    /// `false` (evo's default): pairs `(0, δ), (δ, 2δ), …`; `true` (`--all_pairs`): every
    /// `(i, i + δ)`. The same for δ = 1.
    pub all_pairs: bool,
    /// Scale the estimate by the scale of a Sim(3) fit to the ground truth first (`evo_rpe -as`);
    /// a rigid alignment does not change the RPE, so there is no `align` option.
    pub correct_scale: bool,
}

impl Default for RpeOptions {
    fn default() -> Self {
        Self { max_difference_ns: DEFAULT_MAX_DIFFERENCE_NS, delta_frames: DEFAULT_DELTA_FRAMES, all_pairs: false, correct_scale: false }
    }
}

/// Result of [`rpe`].
#[derive(Clone, Debug, PartialEq)]
pub struct RpeReport {
    /// Associated poses, sorted by estimated timestamp.
    pub pairs: Vec<Association>,
    /// The relative poses measured, as `(i, j)` indices into `pairs`.
    pub relative_pairs: Vec<(usize, usize)>,
    /// Scale applied to the estimated translations (1 without scale correction).
    pub scale: f64,
    /// `|t(E)|` of each relative pair, metres (same order as `relative_pairs`).
    pub per_pair_translation_m: Vec<f64>,
    /// Rotation angle of `R(E)` of each relative pair, degrees.
    pub per_pair_rotation_deg: Vec<f64>,
    /// Statistics of `per_pair_translation_m`, metres.
    pub translation_m: ErrorStats,
    /// Statistics of `per_pair_rotation_deg`, degrees.
    pub rotation_deg: ErrorStats,
}

/// Relative pose error (`evo_rpe tum GT EST --delta δ --delta_unit f`, pose relations
/// `trans_part` and `angle_deg`), over the associated poses in estimated-time order.
///
/// Errors: [`Error::InvalidConfig`] for `delta_frames == 0`, [`Error::TooFewAssociations`]
/// when fewer than `delta_frames + 1` poses associate (3 with scale correction), and the
/// errors of [`umeyama_se3`] with scale correction.
pub fn rpe(gt: &[TimedPose], est: &[TimedPose], options: &RpeOptions) -> Result<RpeReport> {
    let delta = options.delta_frames;
    if delta == 0 {
        return Err(Error::InvalidConfig("RPE delta must be at least 1 frame".to_owned()));
    }
    let pairs = associate(gt, est, options.max_difference_ns);
    let required = delta.saturating_add(1).max(if options.correct_scale { MIN_PAIRS_FOR_ALIGNMENT } else { 0 });
    if pairs.len() < required {
        return Err(Error::TooFewAssociations { what: "RPE", pairs: pairs.len(), required });
    }
    let scale = if options.correct_scale {
        let points_in_gt: Vec<DVec3> = pairs.iter().map(|p| gt[p.gt_ix].world_from_camera.translation_m).collect();
        let points_in_est: Vec<DVec3> = pairs.iter().map(|p| est[p.est_ix].world_from_camera.translation_m).collect();
        umeyama_se3(&points_in_est, &points_in_gt, true)?.scale
    } else {
        1.0
    };

    let relative_pairs: Vec<(usize, usize)> = if options.all_pairs {
        (0..pairs.len() - delta).map(|i| (i, i + delta)).collect()
    } else {
        (0..pairs.len()).step_by(delta).zip((delta..pairs.len()).step_by(delta)).collect()
    };
    let mut per_pair_translation_m = Vec::with_capacity(relative_pairs.len());
    let mut per_pair_rotation_deg = Vec::with_capacity(relative_pairs.len());
    for &(i, j) in &relative_pairs {
        let gt_i = gt[pairs[i].gt_ix].world_from_camera;
        let gt_j = gt[pairs[j].gt_ix].world_from_camera;
        let est_i = est[pairs[i].est_ix].world_from_camera;
        let est_j = est[pairs[j].est_ix].world_from_camera;
        let gt_i_from_gt_j = gt_i.inverse() * gt_j;
        let mut est_i_from_est_j = est_i.inverse() * est_j;
        est_i_from_est_j.translation_m *= scale;
        let error = gt_i_from_gt_j.inverse() * est_i_from_est_j;
        per_pair_translation_m.push(error.translation_m.length());
        per_pair_rotation_deg.push(rotation_angle_rad(error.rotation).to_degrees());
    }
    let (Some(translation_m), Some(rotation_deg)) =
        (ErrorStats::from_errors(&per_pair_translation_m), ErrorStats::from_errors(&per_pair_rotation_deg))
    else {
        return Err(Error::TooFewAssociations { what: "RPE", pairs: pairs.len(), required });
    };
    Ok(RpeReport { pairs, relative_pairs, scale, per_pair_translation_m, per_pair_rotation_deg, translation_m, rotation_deg })
}

/// Rotation angle of a unit quaternion in [0, π], radians; `atan2` keeps small angles exact
/// where `acos(w)` loses half the digits.
fn rotation_angle_rad(rotation: DQuat) -> f64 {
    2.0 * rotation.xyz().length().atan2(rotation.w.abs())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::test_util::SAMPLE_RECORDING;
    use crate::source::FrameSource as _;

    const MS: i64 = 1_000_000;

    fn pose(timestamp_ns: i64, rotation: DQuat, translation_m: DVec3) -> TimedPose {
        TimedPose { timestamp_ns, world_from_camera: Se3::new(rotation, translation_m) }
    }

    /// A 3-D trajectory: 40 poses at 10 ms along a twisted curve with varying orientation.
    fn curvy_trajectory() -> Vec<TimedPose> {
        (0..40_i32)
            .map(|i| {
                let s = f64::from(i) * 0.1;
                pose(
                    1_000_000_000 + i64::from(i) * 10 * MS,
                    DQuat::from_euler(glam::EulerRot::ZYX, 0.3 * s, -0.2 * s.sin(), 0.1 * s * s),
                    DVec3::new(s.cos(), s.sin() * 0.5, 0.2 * s + 0.1 * (2.0 * s).sin()),
                )
            })
            .collect()
    }

    fn known_transform() -> Se3 {
        Se3::new(DQuat::from_axis_angle(DVec3::new(0.3, -0.5, 0.8).normalize(), 0.7), DVec3::new(0.5, -1.2, 0.3))
    }

    fn assert_close(got: f64, want: f64, tolerance: f64, what: &str) {
        assert!((got - want).abs() <= tolerance, "{what}: got {got}, want {want} (tolerance {tolerance})");
    }

    fn assert_se3_close(got: &Se3, want: &Se3, tolerance: f64, what: &str) {
        assert!(got.translation_m.abs_diff_eq(want.translation_m, tolerance), "{what}: translation {got:?} vs {want:?}");
        let angle = rotation_angle_rad(got.rotation.conjugate() * want.rotation);
        assert!(angle <= tolerance, "{what}: rotations differ by {angle} rad ({got:?} vs {want:?})");
    }

    fn assert_stats(got: &ErrorStats, want: &ErrorStats, tolerance: f64, what: &str) {
        assert_eq!(got.count, want.count, "{what}: count");
        for (name, g, w) in [
            ("rmse", got.rmse, want.rmse),
            ("mean", got.mean, want.mean),
            ("median", got.median, want.median),
            ("std", got.std, want.std),
            ("min", got.min, want.min),
            ("max", got.max, want.max),
        ] {
            assert_close(g, w, tolerance, &format!("{what} {name}"));
        }
    }

    /// The benchmark's `associate.py`, literally: all candidate pairs, sorted, taken greedily.
    fn associate_reference(gt: &[TimedPose], est: &[TimedPose], max_difference_ns: u64) -> Vec<Association> {
        let mut candidates = Vec::new();
        for (gt_ix, g) in gt.iter().enumerate() {
            for (est_ix, e) in est.iter().enumerate() {
                let dt = g.timestamp_ns.abs_diff(e.timestamp_ns);
                if dt < max_difference_ns {
                    candidates.push((dt, g.timestamp_ns, e.timestamp_ns, gt_ix, est_ix));
                }
            }
        }
        candidates.sort_unstable();
        let (mut gt_used, mut est_used, mut pairs) = (vec![false; gt.len()], vec![false; est.len()], Vec::new());
        for (_, _, _, gt_ix, est_ix) in candidates {
            if !gt_used[gt_ix] && !est_used[est_ix] {
                (gt_used[gt_ix], est_used[est_ix]) = (true, true);
                pairs.push(Association { gt_ix, est_ix });
            }
        }
        pairs.sort_unstable_by_key(|p| (est[p.est_ix].timestamp_ns, p.est_ix));
        pairs
    }

    fn stamps(timestamps_ns: &[i64]) -> Vec<TimedPose> {
        timestamps_ns.iter().map(|&t| TimedPose { timestamp_ns: t, world_from_camera: Se3::IDENTITY }).collect()
    }

    #[test]
    fn associates_jittered_stamps_to_the_nearest_and_drops_a_gap() {
        // Ground truth at 100 Hz from 0 to 300 ms; estimates at ~30 Hz with ±4 ms jitter, one in
        // a gap 25 ms past the last ground-truth stamp, and one exactly 20 ms away (not < 20 ms).
        let gt = stamps(&(0..=30).map(|i| i * 10 * MS).collect::<Vec<_>>());
        let est = stamps(&[13 * MS, 37 * MS, 66 * MS, 99 * MS + 500_000, 134 * MS, 325 * MS, -20 * MS]);
        let pairs = associate(&gt, &est, DEFAULT_MAX_DIFFERENCE_NS);
        let got: Vec<(usize, usize)> = pairs.iter().map(|p| (p.gt_ix, p.est_ix)).collect();
        assert_eq!(got, vec![(1, 0), (4, 1), (7, 2), (10, 3), (13, 4)], "pairs (gt_ix, est_ix)");
        assert_eq!(associate(&gt, &est, 21 * MS as u64).len(), 6, "-20 ms associates with 0 ms once 20 ms < max difference");
        assert_eq!(associate(&gt, &est, 0), vec![], "max difference 0 associates nothing, as associate.py");
    }

    #[test]
    fn associates_each_stamp_once_greedily_by_smallest_difference() {
        // est 1 ms and 2 ms both want gt 0 ms: the closer (1 ms) gets it; 2 ms takes gt 15 ms
        // (13 ms away) rather than nothing.
        let gt = stamps(&[0, 15 * MS, 100 * MS]);
        let est = stamps(&[2 * MS, MS]);
        let pairs = associate(&gt, &est, DEFAULT_MAX_DIFFERENCE_NS);
        assert_eq!(pairs, vec![Association { gt_ix: 0, est_ix: 1 }, Association { gt_ix: 1, est_ix: 0 }], "sorted by estimated time");
    }

    #[test]
    fn association_matches_the_associate_py_reference_on_random_stamps() {
        // Deterministic LCG; stamps in 0..1 s, unsorted, some duplicated.
        let mut state = 0x2545_f491_4f6c_dd1d_u64;
        let mut next_ms = || {
            state = state.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1_442_695_040_888_963_407);
            i64::try_from((state >> 33) % 1000).expect("small") * MS / 7
        };
        for round in 0..20 {
            let gt = stamps(&(0..60).map(|_| next_ms()).collect::<Vec<_>>());
            let est = stamps(&(0..25).map(|_| next_ms()).collect::<Vec<_>>());
            for max_difference_ns in [0, MS as u64, 5 * MS as u64, DEFAULT_MAX_DIFFERENCE_NS, 1_000 * MS as u64] {
                let got = associate(&gt, &est, max_difference_ns);
                let want = associate_reference(&gt, &est, max_difference_ns);
                assert_eq!(got, want, "round {round}, max difference {max_difference_ns} ns");
            }
        }
        // Negative control: the reference is sensitive to the tie order it claims to follow.
        let gt = stamps(&[0, 20 * MS]);
        let est = stamps(&[10 * MS]);
        assert_eq!(
            associate_reference(&gt, &est, DEFAULT_MAX_DIFFERENCE_NS),
            vec![Association { gt_ix: 0, est_ix: 0 }],
            "tie → earlier gt"
        );
        assert_ne!(
            associate(&gt, &est, DEFAULT_MAX_DIFFERENCE_NS),
            vec![Association { gt_ix: 1, est_ix: 0 }],
            "tie must not go to later gt"
        );
    }

    #[test]
    fn ate_recovers_a_known_rigid_transform_exactly() {
        let gt = curvy_trajectory();
        let est_from_gt = known_transform();
        let est: Vec<TimedPose> = gt.iter().map(|p| TimedPose { world_from_camera: est_from_gt * p.world_from_camera, ..*p }).collect();
        let report = ate(&gt, &est, &AteOptions::default()).expect("ATE");
        assert_eq!(report.pairs.len(), gt.len(), "all poses associate");
        assert!(report.error_m.max < 1e-12, "aligned ATE should vanish: {:?}", report.error_m);
        assert_eq!(report.alignment.scale, 1.0, "no scale correction asked");
        assert_se3_close(&report.alignment.gt_from_est, &est_from_gt.inverse(), 1e-12, "gt_from_est");
        // The aligned poses, orientation included, coincide with ground truth.
        for pair in &report.pairs {
            let aligned = report.alignment.transform_pose(&est[pair.est_ix].world_from_camera);
            assert_se3_close(&aligned, &gt[pair.gt_ix].world_from_camera, 1e-12, "aligned pose");
        }

        // Without alignment the error is the displacement of every position.
        let raw = ate(&gt, &est, &AteOptions { align: false, ..AteOptions::default() }).expect("unaligned ATE");
        let want: Vec<f64> = gt
            .iter()
            .map(|p| (est_from_gt.transform_point(p.world_from_camera.translation_m) - p.world_from_camera.translation_m).length())
            .collect();
        assert_eq!(raw.per_pair_error_m, want, "unaligned per-pair errors");
        assert_eq!(raw.alignment, Alignment::IDENTITY, "no alignment applied");
    }

    #[test]
    fn ate_with_scale_recovers_a_known_similarity() {
        let gt = curvy_trajectory();
        let est_from_gt = known_transform();
        let scale_est_per_gt = 1.7;
        let est: Vec<TimedPose> = gt
            .iter()
            .map(|p| {
                let t = est_from_gt.transform_point(p.world_from_camera.translation_m) * scale_est_per_gt;
                TimedPose { world_from_camera: Se3::new(est_from_gt.rotation * p.world_from_camera.rotation, t), ..*p }
            })
            .collect();
        let sim3 = ate(&gt, &est, &AteOptions { correct_scale: true, ..AteOptions::default() }).expect("Sim(3) ATE");
        assert!(sim3.error_m.max < 1e-12, "Sim(3)-aligned ATE should vanish: {:?}", sim3.error_m);
        assert_close(sim3.alignment.scale, 1.0 / scale_est_per_gt, 1e-12, "scale");
        assert_se3_close(&sim3.alignment.gt_from_est, &est_from_gt.inverse(), 1e-12, "gt_from_est");
        let se3 = ate(&gt, &est, &AteOptions::default()).expect("SE(3) ATE");
        assert!(se3.error_m.rmse > 0.1, "a rigid fit cannot absorb a 1.7x scale: {:?}", se3.error_m);
    }

    #[test]
    fn ate_of_a_constant_offset_without_alignment() {
        let gt = curvy_trajectory();
        let offset_m = DVec3::new(0.03, -0.04, 0.0);
        let est: Vec<TimedPose> =
            gt.iter().map(|p| pose(p.timestamp_ns, p.world_from_camera.rotation, p.world_from_camera.translation_m + offset_m)).collect();
        let report = ate(&gt, &est, &AteOptions { align: false, ..AteOptions::default() }).expect("ATE");
        let want = ErrorStats { count: 40, rmse: 0.05, mean: 0.05, median: 0.05, std: 0.0, min: 0.05, max: 0.05 };
        assert_stats(&report.error_m, &want, 1e-12, "constant 5 cm offset");
        let aligned = ate(&gt, &est, &AteOptions::default()).expect("aligned ATE");
        assert!(aligned.error_m.max < 1e-12, "alignment removes a constant offset: {:?}", aligned.error_m);
    }

    #[test]
    fn ate_statistics_of_hand_computed_noise() {
        // Errors 1, 2, 2, 4 cm along different axes, no alignment.
        let offsets_m = [DVec3::new(0.01, 0.0, 0.0), DVec3::new(0.0, -0.02, 0.0), DVec3::new(0.0, 0.0, 0.02), DVec3::new(0.0, 0.04, 0.0)];
        let gt = curvy_trajectory()[..4].to_vec();
        let est: Vec<TimedPose> = gt
            .iter()
            .zip(offsets_m)
            .map(|(p, o)| pose(p.timestamp_ns, p.world_from_camera.rotation, p.world_from_camera.translation_m + o))
            .collect();
        let report = ate(&gt, &est, &AteOptions { align: false, ..AteOptions::default() }).expect("ATE");
        // rmse = sqrt((1 + 4 + 4 + 16) / 4) cm = 2.5 cm; mean 2.25 cm; median 2 cm;
        // std = sqrt(6.25 - 2.25²) cm = sqrt(1.1875) cm.
        let want = ErrorStats { count: 4, rmse: 0.025, mean: 0.0225, median: 0.02, std: 0.011_875_f64.sqrt() * 0.1, min: 0.01, max: 0.04 };
        assert_stats(&report.error_m, &want, 1e-15, "1, 2, 2, 4 cm");
        // Negative control: one more centimetre on one pose changes the RMSE.
        let mut worse = est.clone();
        worse[0].world_from_camera.translation_m.x += 0.01;
        let worse = ate(&gt, &worse, &AteOptions { align: false, ..AteOptions::default() }).expect("ATE");
        assert!((worse.error_m.rmse - want.rmse).abs() > 1e-3, "perturbation must show: {:?}", worse.error_m);
    }

    #[test]
    fn ate_of_radial_noise_under_alignment() {
        // Six points on the unit axes, each pushed 1 cm outwards: the best rigid fit is the
        // identity (symmetric cross-covariance, centroid 0), so each aligned error is 1 cm; with
        // scale the fit absorbs it entirely (scale 1/1.01). A known rigid transform on top changes
        // neither.
        let axes = [DVec3::X, DVec3::NEG_X, DVec3::Y, DVec3::NEG_Y, DVec3::Z, DVec3::NEG_Z];
        let gt: Vec<TimedPose> = axes.iter().zip(0..).map(|(a, i)| pose(i * 33 * MS, DQuat::IDENTITY, *a)).collect();
        let est_from_gt = known_transform();
        let est: Vec<TimedPose> = gt
            .iter()
            .map(|p| pose(p.timestamp_ns + 2 * MS, DQuat::IDENTITY, est_from_gt.transform_point(p.world_from_camera.translation_m * 1.01)))
            .collect();
        let rigid = ate(&gt, &est, &AteOptions::default()).expect("ATE");
        let want = ErrorStats { count: 6, rmse: 0.01, mean: 0.01, median: 0.01, std: 0.0, min: 0.01, max: 0.01 };
        assert_stats(&rigid.error_m, &want, 1e-12, "1 cm radial noise");
        assert_se3_close(&rigid.alignment.gt_from_est, &est_from_gt.inverse(), 1e-12, "gt_from_est");
        let sim3 = ate(&gt, &est, &AteOptions { correct_scale: true, ..AteOptions::default() }).expect("Sim(3) ATE");
        assert!(sim3.error_m.max < 1e-12, "scale absorbs radial noise: {:?}", sim3.error_m);
        assert_close(sim3.alignment.scale, 1.0 / 1.01, 1e-12, "scale");
    }

    #[test]
    fn umeyama_never_returns_a_reflection() {
        // Points in the plane z = 0 mirrored through x = 0: the SVD's best orthogonal map may be
        // the reflection diag(-1, 1, 1); on the plane it acts as the rotation by π about y,
        // diag(-1, 1, -1), which must come out, with zero residual.
        let points_in_est = [DVec3::new(0.0, 0.0, 0.0), DVec3::new(1.0, 0.0, 0.0), DVec3::new(0.0, 2.0, 0.0), DVec3::new(1.0, 1.0, 0.0)];
        let points_in_gt: Vec<DVec3> = points_in_est.iter().map(|p| DVec3::new(-p.x, p.y, p.z)).collect();
        let alignment = umeyama_se3(&points_in_est, &points_in_gt, false).expect("planar alignment");
        assert_close(DMat3::from_quat(alignment.gt_from_est.rotation).determinant(), 1.0, 1e-12, "determinant");
        let half_turn_about_y = Se3::new(DQuat::from_rotation_y(std::f64::consts::PI), DVec3::ZERO);
        assert_se3_close(&alignment.gt_from_est, &half_turn_about_y, 1e-12, "planar mirror");
        for (p_est, p_gt) in points_in_est.iter().zip(&points_in_gt) {
            assert!(alignment.transform_point(*p_est).abs_diff_eq(*p_gt, 1e-12), "residual at {p_est}");
        }

        // Non-planar points mirrored: the fit is a proper rotation, with a residual.
        let points_in_est: Vec<DVec3> = curvy_trajectory().iter().map(|p| p.world_from_camera.translation_m).collect();
        let points_in_gt: Vec<DVec3> = points_in_est.iter().map(|p| DVec3::new(p.x, p.y, -p.z)).collect();
        let alignment = umeyama_se3(&points_in_est, &points_in_gt, false).expect("alignment");
        assert_close(DMat3::from_quat(alignment.gt_from_est.rotation).determinant(), 1.0, 1e-12, "determinant");
    }

    #[test]
    fn degenerate_input_is_a_typed_error() {
        let gt = curvy_trajectory();
        assert!(matches!(ate(&[], &[], &AteOptions::default()), Err(Error::TooFewAssociations { pairs: 0, required: 3, .. })), "empty");
        assert!(
            matches!(
                ate(&gt, &[], &AteOptions { align: false, ..AteOptions::default() }),
                Err(Error::TooFewAssociations { pairs: 0, required: 1, .. })
            ),
            "no estimate"
        );
        let far: Vec<TimedPose> = gt.iter().map(|p| TimedPose { timestamp_ns: p.timestamp_ns + 10_000 * MS, ..*p }).collect();
        let err = ate(&gt, &far, &AteOptions::default()).expect_err("no overlap in time");
        assert!(err.to_string().contains("found 0"), "message: {err}");
        assert!(matches!(ate(&gt, &gt[..2], &AteOptions::default()), Err(Error::TooFewAssociations { pairs: 2, .. })), "two pairs");

        let line: Vec<TimedPose> = (0..10).map(|i| pose(i * 10 * MS, DQuat::IDENTITY, DVec3::new(0.1, 0.2, 0.3) * (i as f64))).collect();
        assert!(matches!(ate(&line, &line, &AteOptions::default()), Err(Error::DegenerateAlignment { .. })), "collinear");
        let still: Vec<TimedPose> = (0..10).map(|i| pose(i * 10 * MS, DQuat::IDENTITY, DVec3::ONE)).collect();
        assert!(
            matches!(
                ate(&still, &still, &AteOptions { correct_scale: true, ..AteOptions::default() }),
                Err(Error::DegenerateAlignment { .. })
            ),
            "one place"
        );
        assert!(ate(&line, &line, &AteOptions { align: false, ..AteOptions::default() }).is_ok(), "collinear is fine without alignment");

        let nan = [DVec3::ZERO, DVec3::X, DVec3::new(f64::NAN, 0.0, 1.0)];
        assert!(matches!(umeyama_se3(&nan, &nan, false), Err(Error::DegenerateAlignment { .. })), "NaN");
        assert!(matches!(umeyama_se3(&nan, &nan[..2], false), Err(Error::InvalidConfig(_))), "length mismatch");

        assert!(matches!(rpe(&gt, &gt, &RpeOptions { delta_frames: 0, ..RpeOptions::default() }), Err(Error::InvalidConfig(_))), "delta 0");
        assert!(
            matches!(rpe(&gt[..1], &gt[..1], &RpeOptions::default()), Err(Error::TooFewAssociations { pairs: 1, required: 2, .. })),
            "one pose"
        );
        assert!(
            matches!(
                rpe(&gt, &gt, &RpeOptions { delta_frames: usize::MAX, ..RpeOptions::default() }),
                Err(Error::TooFewAssociations { .. })
            ),
            "huge delta"
        );
        assert!(ErrorStats::from_errors(&[]).is_none(), "no stats of nothing");
    }

    /// `n` poses, each `step` after the previous in the previous pose's frame, 33 ms apart.
    fn odometry(n: usize, step: Se3, world_from_first: Se3) -> Vec<TimedPose> {
        let mut current = world_from_first;
        let mut poses = Vec::new();
        for i in 0..n {
            poses.push(TimedPose { timestamp_ns: i64::try_from(i).expect("small") * 33 * MS, world_from_camera: current });
            current = current * step;
        }
        poses
    }

    #[test]
    fn rpe_of_known_per_frame_drift() {
        // gt: 10 cm and 1° about z per frame; est: 11 cm and 1.5° per frame, in another world
        // frame. Per pair E = step_gt⁻¹ step_est: |t| = 1 cm, angle 0.5°.
        let gt = odometry(12, Se3::new(DQuat::from_rotation_z(1.0_f64.to_radians()), DVec3::new(0.1, 0.0, 0.0)), Se3::IDENTITY);
        let est = odometry(12, Se3::new(DQuat::from_rotation_z(1.5_f64.to_radians()), DVec3::new(0.11, 0.0, 0.0)), known_transform());
        let report = rpe(&gt, &est, &RpeOptions::default()).expect("RPE");
        assert_eq!(report.relative_pairs.len(), 11, "consecutive pairs");
        let want_t = ErrorStats { count: 11, rmse: 0.01, mean: 0.01, median: 0.01, std: 0.0, min: 0.01, max: 0.01 };
        let want_r = ErrorStats { count: 11, rmse: 0.5, mean: 0.5, median: 0.5, std: 0.0, min: 0.5, max: 0.5 };
        assert_stats(&report.translation_m, &want_t, 1e-12, "RPE translation");
        assert_stats(&report.rotation_deg, &want_r, 1e-9, "RPE rotation");

        // Identical trajectories (up to a world change) have zero RPE.
        let same: Vec<TimedPose> =
            gt.iter().map(|p| TimedPose { world_from_camera: known_transform() * p.world_from_camera, ..*p }).collect();
        let zero = rpe(&gt, &same, &RpeOptions::default()).expect("RPE");
        assert!(zero.translation_m.max < 1e-12 && zero.rotation_deg.max < 1e-9, "{:?} {:?}", zero.translation_m, zero.rotation_deg);
    }

    #[test]
    fn rpe_delta_and_pair_selection() {
        // Both turn 10° about z per frame; gt advances 10 cm, est 11 cm (so est = 1.1 × gt).
        // Over δ = 2 frames the translation error is |(I + Rz(10°)) (1 cm, 0, 0)| = 2 cm · cos 5°.
        let turn = DQuat::from_rotation_z(10.0_f64.to_radians());
        let gt = odometry(11, Se3::new(turn, DVec3::new(0.1, 0.0, 0.0)), Se3::IDENTITY);
        let est = odometry(11, Se3::new(turn, DVec3::new(0.11, 0.0, 0.0)), Se3::IDENTITY);
        let want_m = 0.02 * 5.0_f64.to_radians().cos();
        let strided = rpe(&gt, &est, &RpeOptions { delta_frames: 2, ..RpeOptions::default() }).expect("RPE δ=2");
        assert_eq!(strided.relative_pairs, vec![(0, 2), (2, 4), (4, 6), (6, 8), (8, 10)], "evo's default pairs");
        assert_close(strided.translation_m.rmse, want_m, 1e-12, "δ=2 translation");
        assert!(strided.rotation_deg.max < 1e-9, "same rotations: {:?}", strided.rotation_deg);
        let all = rpe(&gt, &est, &RpeOptions { delta_frames: 2, all_pairs: true, ..RpeOptions::default() }).expect("RPE all pairs");
        assert_eq!(all.relative_pairs.len(), 9, "every (i, i+2)");
        assert_close(all.translation_m.max, want_m, 1e-12, "all pairs translation");

        // Scale correction removes the uniform 10% scale error.
        let scaled = rpe(&gt, &est, &RpeOptions { correct_scale: true, ..RpeOptions::default() }).expect("RPE with scale");
        assert_close(scaled.scale, 1.0 / 1.1, 1e-12, "scale");
        assert!(scaled.translation_m.max < 1e-12, "{:?}", scaled.translation_m);
    }

    #[test]
    fn the_running_ate_equals_the_batch_ate_at_every_length() {
        let sample = crate::recording::RecordingReader::open(SAMPLE_RECORDING).expect("opening the sample");
        let gt: Vec<TimedPose> = sample.ground_truth().expect("ground truth").iter().step_by(4).copied().collect();
        // The ground truth in another world frame, 10 km away, with millimetre wobble.
        let est_from_gt = Se3 { translation_m: DVec3::new(1e4, -2e4, 5e3), ..known_transform() };
        let est: Vec<TimedPose> = gt
            .iter()
            .enumerate()
            .map(|(i, p)| {
                let wobble_m = 0.003 * DVec3::new((i as f64 * 0.7).sin(), (i as f64 * 1.3).cos(), (i as f64 * 0.4).sin());
                TimedPose { timestamp_ns: p.timestamp_ns, world_from_camera: Se3 { translation_m: est_from_gt.transform_point(p.world_from_camera.translation_m) + wobble_m, ..p.world_from_camera } }
            })
            .collect();
        let mut running = RunningAte::default();
        assert!(matches!(running.alignment_and_rmse_m(), Err(Error::TooFewAssociations { .. })), "no pairs");
        for (n, (e, g)) in est.iter().zip(&gt).enumerate() {
            running.push(e.world_from_camera.translation_m, g.world_from_camera.translation_m);
            if n + 1 < 3 || (n + 1) % 10 != 0 {
                continue;
            }
            let batch = ate(&gt, &est[..=n], &AteOptions::default()).expect("batch ATE");
            let (alignment, rmse_m) = running.alignment_and_rmse_m().expect("running ATE");
            assert!((rmse_m - batch.error_m.rmse).abs() < 1e-7, "{} pairs: running {rmse_m} m vs batch {} m", n + 1, batch.error_m.rmse);
            assert_se3_close(&alignment.gt_from_est, &batch.alignment.gt_from_est, 1e-6, "alignment");
        }
        assert!(running.alignment_and_rmse_m().expect("ATE").1 > 1e-3, "the wobble shows");
        let mut bad = running.clone();
        bad.push(DVec3::new(f64::NAN, 0.0, 0.0), DVec3::ZERO);
        assert!(matches!(bad.alignment_and_rmse_m(), Err(Error::DegenerateAlignment { .. })), "a NaN position is an error");
        let mut line = RunningAte::default();
        for i in 0..5 {
            line.push(DVec3::X * f64::from(i), DVec3::Y * f64::from(i));
        }
        assert!(matches!(line.alignment_and_rmse_m(), Err(Error::DegenerateAlignment { .. })), "collinear positions");
    }

    #[test]
    fn evaluates_rigidly_moved_tum_ground_truth() {
        let sample = crate::recording::RecordingReader::open(SAMPLE_RECORDING).expect("opening the sample");
        let gt = sample.ground_truth().expect("the sample carries TUM's motion capture").to_vec();
        // Every third pose, 3 ms later, in another world frame.
        let est_from_gt = known_transform();
        let est: Vec<TimedPose> = gt
            .iter()
            .step_by(3)
            .map(|p| TimedPose { timestamp_ns: p.timestamp_ns + 3 * MS, world_from_camera: est_from_gt * p.world_from_camera })
            .collect();
        let report = ate(&gt, &est, &AteOptions::default()).expect("ATE");
        assert_eq!(report.pairs.len(), est.len(), "every estimate associates");
        assert!(report.pairs.iter().all(|p| p.gt_ix == 3 * p.est_ix), "each with the pose it came from");
        assert!(report.error_m.max < 1e-9, "{:?}", report.error_m);
        assert_se3_close(&report.alignment.gt_from_est, &est_from_gt.inverse(), 1e-9, "gt_from_est");
        let relative = rpe(&gt, &est, &RpeOptions::default()).expect("RPE");
        assert!(
            relative.translation_m.max < 1e-9 && relative.rotation_deg.max < 1e-6,
            "{:?} {:?}",
            relative.translation_m,
            relative.rotation_deg
        );
    }
}

// SPDX-License-Identifier: MIT
//! The f64 reference of the GPU's robust motion estimate (`match_select`, `ransac_hypotheses`,
//! `ransac_refine`, which hold the same method in f32; the kernel tests hold them to it), and
//! its settings.
//!
//! Rigid motion from 3D-3D correspondences: Kabsch (the rotation from the SVD of the
//! cross-covariance, with the reflection fixed; Kabsch 1976, Umeyama 1991) on 3-point samples
//! inside RANSAC scored by MSAC (Torr and Zisserman 2000), then Gauss-Newton refits of the
//! Mahalanobis cost on the inliers until they settle. Residuals are measured
//! against the Kinect noise model: each point's covariance is its axial σ_z(z)² (Nguyen et
//! al. 2012) along its ray and its lateral (z · 2^level / f)² across it (one pixel of its
//! pyramid level); a pair's residual dst − T src has covariance R Σ_src Rᵀ + Σ_dst, and the pair
//! is an inlier when its squared Mahalanobis norm is within χ²(3 dof, 95 %) times the frame's
//! noise scale². The model is a floor, not the truth: in fast motion the colour image and the
//! depth are taken at different instants (TUM's fr1 streams are not synchronised) and blur
//! moves the keypoints, so every point of the frame is off by more than the sensor's noise. The
//! scale is estimated from the data (MSAC on a bound of `max_noise_scale`² χ², then the median
//! normalised residual of the best hypothesis against χ²₃'s median), never below 1. 002 instead fitted an
//! unconstrained 4×4 matrix by least squares on 80 % random subsets (§4.5.3), which is neither
//! a rotation nor robust.

use glam::{DMat3, DQuat, DVec3};
use nalgebra::{Matrix3, Matrix6, SVD, Vector6};

use crate::Se3;
use crate::cpu::odometry::estimate::RANSAC_MAX_HYPOTHESES;
use crate::cpu::shared::{kinect_sigma_m, pcg_hash};
use crate::kernels::gpu_data::{FeaturePair, RansacParams};

/// χ²(3 degrees of freedom) at 95 %.
pub const CHI2_3DOF_95: f64 = 7.815;
/// The median of χ²(3 degrees of freedom).
pub const CHI2_3DOF_MEDIAN: f64 = 2.366;

/// One pair of points: `src` in the current camera, `dst` in the reference camera.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Correspondence {
    /// The point in the current camera, metres.
    pub src: DVec3,
    /// The matched point in the reference camera, metres.
    pub dst: DVec3,
    /// `src`'s covariance in the current camera, m².
    pub src_cov: DMat3,
    /// `dst`'s covariance in the reference camera, m².
    pub dst_cov: DMat3,
}

impl Correspondence {
    /// A pair with the Kinect noise of each point (`point_covariance`).
    pub fn new(src: DVec3, src_level: u32, dst: DVec3, dst_level: u32, f_px: f64) -> Self {
        Self { src, dst, src_cov: point_covariance(src, src_level, f_px), dst_cov: point_covariance(dst, dst_level, f_px) }
    }
}

/// The f64 reference's pairs for the GPU estimate's pairs (`match_select`'s output: points
/// and pyramid levels), each with its points' Kinect noise, for a camera of focal length `f_px`.
pub fn correspondences(pairs: &[FeaturePair], f_px: f64) -> Vec<Correspondence> {
    let v = |p: [f32; 4]| DVec3::new(f64::from(p[0]), f64::from(p[1]), f64::from(p[2]));
    pairs.iter().map(|p| Correspondence::new(v(p.src), p.src[3] as u32, v(p.dst), p.dst[3] as u32, f_px)).collect()
}

/// The covariance of a point `p` (camera frame, metres) measured at pyramid `level` with focal
/// length `f_px`: the Kinect's axial variance σ_z(z)² along the ray through it, and one level
/// pixel's lateral variance (z · 2^level / f)² across, m².
pub fn point_covariance(p: DVec3, level: u32, f_px: f64) -> DMat3 {
    let axial = f64::from(kinect_sigma_m(p.z as f32));
    let lateral = p.z * f64::from(1u32 << level) / f_px;
    let ray = p.normalize_or_zero();
    DMat3::from_diagonal(DVec3::splat(lateral * lateral)) + (axial * axial - lateral * lateral) * outer(ray, ray)
}

/// `m` as nalgebra's matrix (for the factorisations glam lacks).
pub(crate) fn na_mat3(m: &DMat3) -> Matrix3<f64> {
    let c = m.to_cols_array_2d();
    Matrix3::from_fn(|row, col| c[col][row])
}

/// The cross-product matrix [v]×: [v]× u = v × u.
pub(crate) fn skew(v: DVec3) -> Matrix3<f64> {
    Matrix3::new(0.0, -v.z, v.y, v.z, 0.0, -v.x, -v.y, v.x, 0.0)
}

fn outer(a: DVec3, b: DVec3) -> DMat3 {
    DMat3::from_cols(a * b.x, a * b.y, a * b.z)
}

/// RANSAC's settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RansacConfig {
    /// Hypotheses drawn (3-point samples). 256 find an all-inlier sample with 99 % probability
    /// down to an inlier fraction of 0.26.
    pub hypotheses: u32,
    /// Fewest inliers for an accepted motion.
    pub min_inliers: usize,
    /// Refits on the inliers after the best hypothesis.
    pub refits: u32,
    /// The largest noise scale (times the sensor model's σ) a frame may show: the inlier bound
    /// stops growing there, and a frame whose pairs are noisier still is rejected.
    pub max_noise_scale: f64,
}

impl Default for RansacConfig {
    fn default() -> Self {
        Self { hypotheses: 256, min_inliers: 20, refits: 3, max_noise_scale: 4.0 }
    }
}

/// Gauss-Newton steps per refit.
pub const REFIT_ITERATIONS: u32 = 5;

impl RansacConfig {
    /// Checks the values: 3 ..= [`RANSAC_MAX_HYPOTHESES`] hypotheses (one GPU workgroup each,
    /// chosen among by one workgroup), at least 3 inliers, a finite noise bound of at least 1.
    pub fn validate(&self) -> crate::Result<()> {
        let bad = |what: String| Err(crate::Error::InvalidConfig(format!("ransac: {what}")));
        if !(1..=RANSAC_MAX_HYPOTHESES).contains(&self.hypotheses) {
            return bad(format!("hypotheses must be in 1..={RANSAC_MAX_HYPOTHESES}, got {}", self.hypotheses));
        }
        if self.min_inliers < 3 {
            return bad(format!("min_inliers must be at least 3, got {}", self.min_inliers));
        }
        if !(self.max_noise_scale >= 1.0 && self.max_noise_scale.is_finite()) {
            return bad(format!("max_noise_scale must be finite and at least 1, got {}", self.max_noise_scale));
        }
        Ok(())
    }

    /// The GPU estimate's parameters (`ransac_hypotheses`, `ransac_refine`) for a camera of
    /// focal length `f_px` and the sample stream `seed`.
    pub fn params(&self, f_px: f32, seed: u32) -> RansacParams {
        RansacParams {
            hypotheses: self.hypotheses.min(RANSAC_MAX_HYPOTHESES),
            seed,
            min_inliers: self.min_inliers as u32,
            refits: self.refits,
            f_px,
            max_noise_scale: self.max_noise_scale as f32,
            iterations: REFIT_ITERATIONS,
            ..Default::default()
        }
    }
}

/// A robust estimate.
#[derive(Clone, Debug, PartialEq)]
pub struct RigidEstimate {
    /// The motion taking `src` points onto `dst` points: reference_from_current.
    pub dst_from_src: Se3,
    /// Indices of the inlier correspondences.
    pub inliers: Vec<usize>,
    /// Root mean square residual of the inliers, metres.
    pub rmse_m: f64,
    /// The frame's noise relative to the sensor model (1 ..= the configured maximum).
    pub noise_scale: f64,
    /// The motion's covariance ([`motion_covariance`]: ξ = (ω, v) on the left, in the reference
    /// camera); `None` when the inliers do not fix it.
    pub covariance: Option<Matrix6<f64>>,
}

/// The rigid motion minimising Σ |dstᵢ − (R srcᵢ + t)|² over `pairs` (indices into `corr`),
/// or `None` when the points are degenerate (collinear or fewer than 3).
pub fn kabsch(corr: &[Correspondence], pairs: &[usize]) -> Option<Se3> {
    if pairs.len() < 3 {
        return None;
    }
    let n = pairs.len() as f64;
    let cs = pairs.iter().map(|&i| corr[i].src).sum::<DVec3>() / n;
    let cd = pairs.iter().map(|&i| corr[i].dst).sum::<DVec3>() / n;
    let mut h = Matrix3::<f64>::zeros();
    for &i in pairs {
        let (a, b) = (corr[i].src - cs, corr[i].dst - cd);
        h += Matrix3::new(a.x * b.x, a.x * b.y, a.x * b.z, a.y * b.x, a.y * b.y, a.y * b.z, a.z * b.x, a.z * b.y, a.z * b.z);
    }
    let svd = SVD::new(h, true, true);
    let (u, v_t) = (svd.u?, svd.v_t?);
    // Rank below 2: the points are collinear and the rotation about their line is unknown.
    let mut s = svd.singular_values.as_slice().to_vec();
    s.sort_by(|a, b| b.total_cmp(a));
    if !(s[1] > 1e-9 * s[0].max(1e-30)) {
        return None;
    }
    let v = v_t.transpose();
    let d = (v * u.transpose()).determinant().signum();
    let r = v * Matrix3::from_diagonal(&nalgebra::Vector3::new(1.0, 1.0, d)) * u.transpose();
    let rotation = DMat3::from_cols_array(&[r[(0, 0)], r[(1, 0)], r[(2, 0)], r[(0, 1)], r[(1, 1)], r[(2, 1)], r[(0, 2)], r[(1, 2)], r[(2, 2)]]);
    let q = DQuat::from_mat3(&rotation).normalize();
    Some(Se3::new(q, cd - q * cs))
}

/// The information (inverse covariance) of pair `c`'s residual under `t`.
fn information(t: &Se3, c: &Correspondence) -> DMat3 {
    let r = DMat3::from_quat(t.rotation);
    (r * c.src_cov * r.transpose() + c.dst_cov).inverse()
}

/// Squared Mahalanobis norm of pair `c`'s residual under `t`.
fn normalised_residual(t: &Se3, c: &Correspondence) -> f64 {
    let r = c.dst - t.transform_point(c.src);
    r.dot(information(t, c) * r)
}

/// Gauss-Newton on Σ ρ(rᵢᵀ Ωᵢ rᵢ) over the pairs `inliers` from `t` (Ω recomputed at each
/// step; ρ Huber at the χ² bound's square root times the noise `scale`, as a few inliers are
/// still wrong). `None` when
/// the system is singular.
pub fn refine_mahalanobis(corr: &[Correspondence], inliers: &[usize], t: &Se3, iterations: u32, scale: f64) -> Option<Se3> {
    let mut t = *t;
    let huber = CHI2_3DOF_95.sqrt() * scale;
    for _ in 0..iterations {
        let mut h = Matrix6::<f64>::zeros();
        let mut g = Vector6::<f64>::zeros();
        for &i in inliers {
            let (jtj, jtr, e) = pair_normal_equations(&t, &corr[i]);
            let w = if e <= huber { 1.0 } else { huber / e };
            h += w * jtj;
            g += w * jtr;
        }
        let step = h.cholesky()?.solve(&(-g));
        let update = crate::pose::twist_exp(DVec3::new(step[0], step[1], step[2]), DVec3::new(step[3], step[4], step[5]));
        t = update.compose(&t);
        if step.norm() < 1e-9 {
            break;
        }
    }
    Some(t)
}

/// Pair `c`'s contribution to the Gauss-Newton system at `t`: JᵀΩJ, JᵀΩr and the residual's
/// Mahalanobis norm, for r(ξ) = dst − exp(ξ) T src with ξ = (ω, v) on the left (in the
/// reference camera): ∂r/∂ω = [T src]×, ∂r/∂v = −I.
fn pair_normal_equations(t: &Se3, c: &Correspondence) -> (Matrix6<f64>, Vector6<f64>, f64) {
    let q = t.transform_point(c.src);
    let r = c.dst - q;
    let omega = information(t, c);
    let mut j = nalgebra::Matrix3x6::<f64>::zeros();
    j.fixed_view_mut::<3, 3>(0, 0).copy_from(&skew(q));
    j.fixed_view_mut::<3, 3>(0, 3).copy_from(&(-Matrix3::<f64>::identity()));
    let om = na_mat3(&omega);
    let rv = nalgebra::Vector3::new(r.x, r.y, r.z);
    (j.transpose() * om * j, j.transpose() * om * rv, r.dot(omega * r).sqrt())
}

/// The covariance of the motion `t` estimated from the pairs `inliers`: s² (Σ JᵢᵀΩᵢJᵢ)⁻¹ with
/// `noise_scale` s (the frame's noise over the sensor model's, which Ω holds), for the left
/// perturbation ξ = (ω rad, v m) in the reference camera (T = exp(ξ) T̂, as the refinement
/// steps). The Cramér-Rao bound of the model, not the truth: it holds the sensor's noise and the
/// pairs' geometry (few or clustered points, leverage of far ones), not wrong matches that
/// passed as inliers. `None` when the pairs do not fix all six degrees of freedom.
pub fn motion_covariance(corr: &[Correspondence], inliers: &[usize], t: &Se3, noise_scale: f64) -> Option<Matrix6<f64>> {
    let h: Matrix6<f64> = inliers.iter().map(|&i| pair_normal_equations(t, &corr[i]).0).sum();
    let inverse = h.cholesky()?.inverse();
    Some(noise_scale * noise_scale * inverse)
}

/// The inliers of `t` within `bound` (squared Mahalanobis), and its MSAC cost
/// (Σ min(r²/σ², bound)).
fn classify(t: &Se3, corr: &[Correspondence], bound: f64) -> (Vec<usize>, f64) {
    let mut inliers = Vec::new();
    let mut cost = 0.0;
    for (i, c) in corr.iter().enumerate() {
        let e = normalised_residual(t, c);
        if e <= bound {
            inliers.push(i);
            cost += e;
        } else {
            cost += bound;
        }
    }
    (inliers, cost)
}

/// RANSAC over `corr` with the sample stream seeded by `seed`; `None` when no hypothesis
/// gathers `min_inliers` inliers.
pub fn ransac(corr: &[Correspondence], config: &RansacConfig, seed: u32) -> Option<RigidEstimate> {
    let n = corr.len();
    if n < config.min_inliers.max(3) {
        return None;
    }
    let loose = CHI2_3DOF_95 * config.max_noise_scale * config.max_noise_scale;
    let mut best: Option<(f64, Se3)> = None;
    let mut state = pcg_hash(seed);
    let next = |state: &mut u32| {
        *state = pcg_hash(*state);
        (*state as usize) % n
    };
    for _ in 0..config.hypotheses {
        let i = next(&mut state);
        let (mut j, mut k) = (next(&mut state), next(&mut state));
        if j == i || k == i || k == j {
            (j, k) = ((i + 1 + j % (n - 1)) % n, (i + 2 + k % (n - 2).max(1)) % n);
            if j == i || k == i || k == j {
                continue;
            }
        }
        // A sample whose triangle is under 5 cm on a side fixes the rotation poorly.
        let (a, b, c) = (corr[i].src, corr[j].src, corr[k].src);
        if (b - a).cross(c - a).length() < 0.0025 {
            continue;
        }
        let Some(t) = kabsch(corr, &[i, j, k]) else { continue };
        let (_, cost) = classify(&t, corr, loose);
        if best.as_ref().is_none_or(|(c, _)| cost < *c) {
            best = Some((cost, t));
        }
    }
    let (_, mut t) = best?;
    // The noise scale: the median normalised residual of the pairs within the loose bound,
    // against χ²₃'s median.
    let scale_of = |t: &Se3| {
        let mut e: Vec<f64> = corr.iter().map(|c| normalised_residual(t, c)).filter(|&e| e <= loose).collect();
        if e.is_empty() {
            return 1.0;
        }
        let mid = e.len() / 2;
        let (_, median, _) = e.select_nth_unstable_by(mid, f64::total_cmp);
        (*median / CHI2_3DOF_MEDIAN).sqrt().max(1.0)
    };
    let bound = |scale: f64| scale.min(config.max_noise_scale);
    let mut scale = scale_of(&t);
    let (mut inliers, _) = classify(&t, corr, CHI2_3DOF_95 * bound(scale).powi(2));
    for _ in 0..config.refits {
        if inliers.len() < config.min_inliers {
            return None;
        }
        let refit = refine_mahalanobis(corr, &inliers, &t, 5, bound(scale))?;
        scale = scale_of(&refit);
        let (next_inliers, _) = classify(&refit, corr, CHI2_3DOF_95 * bound(scale).powi(2));
        let unchanged = next_inliers == inliers;
        t = refit;
        inliers = next_inliers;
        if unchanged {
            break;
        }
    }
    // 002's rejection of poor residuals: pairs noisier than the bound are no motion the sensor
    // model vouches for.
    if inliers.len() < config.min_inliers || scale > config.max_noise_scale {
        return None;
    }
    let rmse_m = (inliers.iter().map(|&i| (corr[i].dst - t.transform_point(corr[i].src)).length_squared()).sum::<f64>() / inliers.len() as f64).sqrt();
    let covariance = motion_covariance(corr, &inliers, &t, scale);
    Some(RigidEstimate { dst_from_src: t, inliers, rmse_m, noise_scale: scale, covariance })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scene(n: usize, truth: &Se3, outliers: usize) -> Vec<Correspondence> {
        let mut state = 7u32;
        let mut u = || {
            state = pcg_hash(state);
            f64::from(state) / f64::from(u32::MAX)
        };
        (0..n)
            .map(|i| {
                let src = DVec3::new(u() * 2.0 - 1.0, u() * 1.5 - 0.75, 1.0 + 2.0 * u());
                let dst = if i < outliers { DVec3::new(u(), u(), 1.0 + u()) } else { truth.transform_point(src) };
                Correspondence::new(src, 0, dst, 0, 525.0)
            })
            .collect()
    }

    /// The covariance is the spread the estimate really has under the noise it models: 400
    /// scenes of 80 pairs, each point displaced by a draw from its Kinect covariance, refined
    /// from the true motion; the squared Mahalanobis norm of the error under
    /// `motion_covariance` averages χ²₆'s mean, 6 (its standard error here is 0.17), and the
    /// noise scale multiplies it as it should. Negative control: the same errors under a
    /// covariance a quarter the size average 24.
    #[test]
    fn the_motion_covariance_is_the_spread_of_the_estimate() {
        let truth = Se3::new(DQuat::from_euler(glam::EulerRot::XYZ, 0.05, -0.1, 0.02), DVec3::new(0.03, -0.01, 0.05));
        let mut state = 11u32;
        let mut uniform = || {
            state = pcg_hash(state);
            (f64::from(state) + 0.5) / (f64::from(u32::MAX) + 1.0)
        };
        let mut gaussian = || (-2.0 * uniform().ln()).sqrt() * (std::f64::consts::TAU * uniform()).cos();
        let clean = scene(80, &truth, 0);
        let all: Vec<usize> = (0..clean.len()).collect();
        let (mut sum, mut sum_quarter, mut sum_scaled) = (0.0, 0.0, 0.0);
        let trials = 400;
        for _ in 0..trials {
            let mut draw = |cov: &DMat3| {
                let l = na_mat3(cov).cholesky().expect("a covariance").l();
                let v = l * nalgebra::Vector3::new(gaussian(), gaussian(), gaussian());
                DVec3::new(v.x, v.y, v.z)
            };
            let noisy: Vec<Correspondence> = clean.iter().map(|c| Correspondence { src: c.src + draw(&c.src_cov), dst: c.dst + draw(&c.dst_cov), ..*c }).collect();
            let t = refine_mahalanobis(&noisy, &all, &truth, 10, 100.0).expect("a motion");
            let cov = motion_covariance(&noisy, &all, &t, 1.0).expect("a covariance");
            let e = crate::odometry::keyframe::twist_log(&t.compose(&truth.inverse()));
            let m = e.dot(&(cov.try_inverse().expect("invertible") * e));
            sum += m;
            sum_quarter += 4.0 * m;
            // Twice the modelled noise, said by the scale: the same norm.
            let cov2 = motion_covariance(&noisy, &all, &t, 2.0).expect("a covariance");
            sum_scaled += (2.0 * e).dot(&(cov2.try_inverse().expect("invertible") * (2.0 * e)));
        }
        let (mean, quarter, scaled) = (sum / trials as f64, sum_quarter / trials as f64, sum_scaled / trials as f64);
        eprintln!("mean squared Mahalanobis error {mean:.2} (χ²₆ mean 6), under a quarter of the covariance {quarter:.2}, scaled noise {scaled:.2}");
        assert!((5.3..6.7).contains(&mean), "{mean}");
        assert!((mean - scaled).abs() < 1e-6 * mean, "{scaled}");
        assert!(!(5.3..6.7).contains(&quarter), "the negative control passed: {quarter}");
    }

    #[test]
    fn kabsch_recovers_an_exact_motion_and_rejects_collinear_points() {
        let truth = Se3::new(DQuat::from_euler(glam::EulerRot::XYZ, 0.1, -0.2, 0.05), DVec3::new(0.1, -0.05, 0.2));
        let corr = scene(50, &truth, 0);
        let all: Vec<usize> = (0..corr.len()).collect();
        let t = kabsch(&corr, &all).unwrap();
        assert!((t.translation_m - truth.translation_m).length() < 1e-9);
        assert!(t.compose(&truth.inverse()).rotation_angle_rad() < 1e-9);
        let line: Vec<Correspondence> = (0..5).map(|i| Correspondence::new(DVec3::new(i as f64, 0.0, 1.0), 0, DVec3::new(i as f64, 0.0, 1.0), 0, 525.0)).collect();
        assert!(kabsch(&line, &[0, 1, 2, 3, 4]).is_none());
    }

    #[test]
    fn ransac_finds_the_motion_among_70_percent_outliers() {
        let truth = Se3::new(DQuat::from_rotation_y(0.15), DVec3::new(-0.08, 0.02, 0.1));
        let corr = scene(200, &truth, 140);
        let e = ransac(&corr, &RansacConfig::default(), 1).expect("an estimate");
        assert_eq!(e.inliers, (140..200).collect::<Vec<_>>());
        assert!((e.dst_from_src.translation_m - truth.translation_m).length() < 1e-9);
        // All outliers: no estimate rather than a wrong one.
        let noise = scene(200, &truth, 200);
        assert!(ransac(&noise, &RansacConfig::default(), 1).is_none());
    }
}

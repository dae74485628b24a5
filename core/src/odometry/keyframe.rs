// SPDX-License-Identifier: MIT
//! Keyframe odometry with two paths to each frame, weighed by what each one knows.
//!
//! Frame-to-frame odometry chains one estimate per frame, so its error grows with every frame
//! even while the camera hovers over the same view; matching each frame against a keyframe
//! instead adds one estimate's error, but a keyframe seen across a wider baseline (blur, fewer
//! and less central matches, colour and depth taken at different instants) may give a worse
//! estimate than the frame just before. Neither is right everywhere, so both are kept: the
//! current camera relative to the keyframe is measured directly (keyframe → current) and
//! through the previous frame (keyframe → previous, as estimated so far, then previous →
//! current), each with its covariance (the estimate's Cramér-Rao bound,
//! [`super::rigid::motion_covariance`]; the chained one adds the previous frame's), and the
//! two are fused by their information. When they disagree by more than their covariances allow
//! (χ² of 6 degrees of freedom at 99 %), one of them is wrong — a match set that passed
//! RANSAC with a wrong motion, typically across the wider baseline — and the chain, the shorter
//! baseline, is kept while the current frame becomes the next keyframe.
//!
//! Poses are perturbed on the left, ξ = (ω rad, v m), T = exp(ξ) T̂ with exp as the estimate
//! applies it ([`crate::pose::twist_exp`]), in the keyframe's camera frame.

use glam::{DMat3, DVec3};
use nalgebra::{Matrix6, Vector6};

use crate::Se3;
use super::rigid::{na_mat3, skew};
use crate::pose::twist_exp;

/// χ²(6 degrees of freedom) at 99 %: two estimates of one pose further apart than this in
/// their joint Mahalanobis norm disagree.
pub const CHI2_6DOF_99: f64 = 16.812;

/// A relative pose with its covariance (left perturbation ξ = (ω, v) in the frame it maps to).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct UncertainPose {
    /// The transform, `a_from_b`.
    pub pose: Se3,
    /// Its covariance, rad² / m².
    pub covariance: Matrix6<f64>,
}

impl UncertainPose {
    /// `pose` known exactly (a keyframe relative to itself).
    pub fn exact(pose: Se3) -> Self {
        Self { pose, covariance: Matrix6::zeros() }
    }

    /// `a_from_c = self ∘ b_from_c`, the two independent: Σ = Σ_ab + Ad(a_from_b) Σ_bc Ad(a_from_b)ᵀ.
    pub fn then(&self, b_from_c: &UncertainPose) -> UncertainPose {
        let ad = adjoint(&self.pose);
        UncertainPose { pose: self.pose.compose(&b_from_c.pose), covariance: self.covariance + ad * b_from_c.covariance * ad.transpose() }
    }
}

/// The adjoint of `t` for left perturbations ξ = (ω, v): exp(Ad ξ) t = t exp(ξ), to first
/// order; Ad = [[R, 0], [[t]× R, R]].
pub fn adjoint(t: &Se3) -> Matrix6<f64> {
    let r = na_mat3(&DMat3::from_quat(t.rotation));
    let px = skew(t.translation_m);
    let mut ad = Matrix6::zeros();
    ad.fixed_view_mut::<3, 3>(0, 0).copy_from(&r);
    ad.fixed_view_mut::<3, 3>(3, 3).copy_from(&r);
    ad.fixed_view_mut::<3, 3>(3, 0).copy_from(&(px * r));
    ad
}

/// The twist ξ with `twist_exp(ξ) = delta`: the rotation's axis times its angle, and the
/// translation.
pub fn twist_log(delta: &Se3) -> Vector6<f64> {
    let w = delta.rotation.to_scaled_axis();
    let t = delta.translation_m;
    Vector6::new(w.x, w.y, w.z, t.x, t.y, t.z)
}

/// Two estimates of one pose that [`fuse`] refused: their squared Mahalanobis distance exceeds
/// [`CHI2_6DOF_99`] (or their covariances are singular).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Disagreement {
    /// δᵀ (Σ_a + Σ_b)⁻¹ δ, δ the twist from `a` to `b`.
    pub chi2: f64,
}

/// Two estimates of one pose that [`fuse`] accepted, fused, and how far apart they were.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Fused {
    /// The fused pose and its covariance.
    pub pose: UncertainPose,
    /// δᵀ (Σ_a + Σ_b)⁻¹ δ of the two: χ²(6) distributed when both covariances are right, so its
    /// mean over many fused frames measures how right they are (6 expected).
    pub chi2: f64,
}

/// Two independent estimates of the same pose fused: ξ = (Λ_a + Λ_b)⁻¹ Λ_b δ on the left of
/// `a`, δ = log(b a⁻¹) (one Gauss-Newton step of the two-measurement cost from `a`, exact for
/// the linearised problem), Σ = (Λ_a + Λ_b)⁻¹; refused when δ is not within χ²(6, 99 %) of
/// Σ_a + Σ_b.
pub fn fuse(a: &UncertainPose, b: &UncertainPose) -> Result<Fused, Disagreement> {
    let delta = twist_log(&b.pose.compose(&a.pose.inverse()));
    let Some(joint) = (a.covariance + b.covariance).cholesky() else { return Err(Disagreement { chi2: f64::INFINITY }) };
    let chi2 = delta.dot(&joint.solve(&delta));
    if !(chi2 <= CHI2_6DOF_99) {
        return Err(Disagreement { chi2 });
    }
    // Σ_a (Σ_a + Σ_b)⁻¹ δ = (Λ_a + Λ_b)⁻¹ Λ_b δ, and Σ = Σ_a − Σ_a (Σ_a + Σ_b)⁻¹ Σ_a: no
    // information matrix is formed, so an exactly known `a` (Σ_a = 0) stays exact.
    let xi = a.covariance * joint.solve(&delta);
    let covariance = a.covariance - a.covariance * joint.solve(&a.covariance);
    let step = twist_exp(DVec3::new(xi[0], xi[1], xi[2]), DVec3::new(xi[3], xi[4], xi[5]));
    Ok(Fused { pose: UncertainPose { pose: step.compose(&a.pose), covariance: (covariance + covariance.transpose()) * 0.5 }, chi2 })
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DQuat;

    fn diag(rot_sigma_rad: f64, trans_sigma_m: f64) -> Matrix6<f64> {
        let (r, t) = (rot_sigma_rad * rot_sigma_rad, trans_sigma_m * trans_sigma_m);
        Matrix6::from_diagonal(&Vector6::new(r, r, r, t, t, t))
    }

    #[test]
    fn the_log_inverts_the_exp_and_the_adjoint_moves_a_perturbation_across() {
        let t = Se3::new(DQuat::from_euler(glam::EulerRot::XYZ, 0.3, -0.2, 0.5), DVec3::new(0.4, -1.0, 2.0));
        let xi = Vector6::new(0.01, -0.02, 0.015, 0.003, 0.002, -0.004);
        let e = |x: &Vector6<f64>| twist_exp(DVec3::new(x[0], x[1], x[2]), DVec3::new(x[3], x[4], x[5]));
        assert!((twist_log(&e(&xi)) - xi).norm() < 1e-12);
        // t exp(ξ) = exp(Ad ξ) t to first order: the mismatch is second order in |ξ| (a tenth of
        // the perturbation leaves about a hundredth of it), while the transpose, no adjoint,
        // leaves a first-order one (about a tenth).
        let mismatch = |ad: &Matrix6<f64>, x: &Vector6<f64>| twist_log(&e(&(ad * x)).compose(&t).compose(&t.compose(&e(x)).inverse())).norm();
        let small = xi * 0.1;
        let (near, near_small) = (mismatch(&adjoint(&t), &xi), mismatch(&adjoint(&t), &small));
        assert!(near_small < near / 50.0 && near < 0.05 * xi.norm(), "{near} -> {near_small}");
        let (wrong, wrong_small) = (mismatch(&adjoint(&t).transpose(), &xi), mismatch(&adjoint(&t).transpose(), &small));
        assert!(wrong_small > wrong / 20.0 && wrong > 10.0 * near, "{wrong} -> {wrong_small}");
    }

    #[test]
    fn two_estimates_fuse_by_their_information_and_a_disagreement_is_refused() {
        let truth = Se3::new(DQuat::from_rotation_y(0.1), DVec3::new(0.05, 0.0, 0.02));
        let off = |dx: f64| Se3::new(DQuat::IDENTITY, DVec3::new(dx, 0.0, 0.0)).compose(&truth);
        // Translation σ 1 mm and 3 mm, 4 mm apart along x: the fused x sits at 1/(1+9) of the
        // way from the sharper one, with σ² = 1·9/(1+9) mm².
        let a = UncertainPose { pose: off(0.0), covariance: diag(1e-3, 1e-3) };
        let b = UncertainPose { pose: off(0.004), covariance: diag(1e-3, 3e-3) };
        let fused = fuse(&a, &b).expect("4 mm is within 3.2 mm·√16.8");
        let f = fused.pose;
        assert!((f.pose.translation_m.x - truth.translation_m.x - 0.0004).abs() < 1e-9, "{:?}", f.pose);
        assert!((f.covariance[(3, 3)] - 0.9e-6).abs() < 1e-12);
        // The same order-independent result with the roles swapped.
        let swapped = fuse(&b, &a).expect("symmetric");
        // Their χ²: (4 mm)² / (1 + 9) mm², whichever comes first.
        assert!((fused.chi2 - 1.6).abs() < 1e-3 && (swapped.chi2 - 1.6).abs() < 1e-3, "{} {}", fused.chi2, swapped.chi2);
        let g = swapped.pose;
        assert!((g.pose.translation_m - f.pose.translation_m).length() < 1e-9);
        // An exact estimate is kept as it is.
        let exact = UncertainPose { pose: truth, covariance: Matrix6::zeros() };
        let h = fuse(&exact, &b).expect("within").pose;
        assert_eq!(h.pose, truth);
        // 20 mm apart is 6.3σ of the joint spread: refused.
        let far = UncertainPose { pose: off(0.02), covariance: diag(1e-3, 3e-3) };
        match fuse(&a, &far) {
            Err(Disagreement { chi2 }) => assert!((chi2 - 40.0).abs() < 0.1, "chi2 {chi2}"),
            Ok(f) => panic!("fused a 20 mm disagreement: {f:?}"),
        }
    }

    #[test]
    fn a_chain_adds_the_second_covariance_seen_from_the_first_frame() {
        // b is 2 m along x from a, turned 90° about z: b's own x uncertainty shows up along a's
        // y, and b's rotation uncertainty about z moves c (at b) nowhere but turns it.
        let a_from_b = UncertainPose { pose: Se3::new(DQuat::from_rotation_z(std::f64::consts::FRAC_PI_2), DVec3::new(2.0, 0.0, 0.0)), covariance: Matrix6::zeros() };
        let mut cov = Matrix6::zeros();
        cov[(3, 3)] = 1e-6;
        let c = a_from_b.then(&UncertainPose { pose: Se3::IDENTITY, covariance: cov });
        assert!((c.covariance[(4, 4)] - 1e-6).abs() < 1e-15 && c.covariance[(3, 3)].abs() < 1e-15, "{}", c.covariance);
        // A rotation about b's z is one about a's z that swings the lever [t]× ω: at a, the
        // translation gains along y (2 m × σ_ω).
        let mut rot = Matrix6::zeros();
        rot[(2, 2)] = 1e-6;
        let d = a_from_b.then(&UncertainPose { pose: Se3::IDENTITY, covariance: rot });
        assert!((d.covariance[(2, 2)] - 1e-6).abs() < 1e-15);
        assert!((d.covariance[(4, 4)] - 4e-6).abs() < 1e-15, "{}", d.covariance);
    }
}

// SPDX-License-Identifier: MIT
//! Rigid transforms. Name them `a_from_b`: `world_from_camera * point_in_camera = point_in_world`.

use glam::{DMat4, DQuat, DVec3, Mat4};

/// A rigid transform (SE(3)) in double precision, for poses and trajectories.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Se3 {
    /// Rotation part.
    pub rotation: DQuat,
    /// Translation part, in metres.
    pub translation_m: DVec3,
}

impl Default for Se3 {
    fn default() -> Self {
        Self::IDENTITY
    }
}

impl Se3 {
    /// The identity transform.
    pub const IDENTITY: Self = Self { rotation: DQuat::IDENTITY, translation_m: DVec3::ZERO };

    /// Builds a transform from rotation and translation.
    pub fn new(rotation: DQuat, translation_m: DVec3) -> Self {
        Self { rotation: rotation.normalize(), translation_m }
    }

    /// `self * other`: applies `other` first. `a_from_b * b_from_c = a_from_c`.
    pub fn compose(&self, other: &Se3) -> Se3 {
        Se3 { rotation: (self.rotation * other.rotation).normalize(), translation_m: self.rotation * other.translation_m + self.translation_m }
    }

    /// The inverse: `a_from_b.inverse() = b_from_a`.
    pub fn inverse(&self) -> Se3 {
        let r = self.rotation.conjugate();
        Se3 { rotation: r, translation_m: -(r * self.translation_m) }
    }

    /// Transforms a point.
    pub fn transform_point(&self, p: DVec3) -> DVec3 {
        self.rotation * p + self.translation_m
    }

    /// 4x4 matrix (column vectors) in single precision, for the GPU.
    pub fn to_mat4(&self) -> Mat4 {
        DMat4::from_rotation_translation(self.rotation, self.translation_m).as_mat4()
    }

    /// The rigid transform of a column-major matrix from the GPU (`[[f32; 4]; 4]`, rotation in
    /// the upper 3x3): its rotation as a unit quaternion, its translation as given.
    pub fn from_cols_f32(m: &[[f32; 4]; 4]) -> Se3 {
        let cols = m.map(|c| DVec3::new(f64::from(c[0]), f64::from(c[1]), f64::from(c[2])));
        let rotation = DQuat::from_mat3(&glam::DMat3::from_cols(cols[0], cols[1], cols[2]));
        Se3::new(rotation, cols[3])
    }

    /// The matrix the GPU reads, column-major `[[f32; 4]; 4]`.
    pub fn to_cols_f32(&self) -> [[f32; 4]; 4] {
        self.to_mat4().to_cols_array_2d()
    }

    /// Rotation angle of this transform, in radians.
    pub fn rotation_angle_rad(&self) -> f64 {
        let w = self.rotation.w.abs().min(1.0);
        2.0 * w.acos()
    }
}

impl std::ops::Mul for Se3 {
    type Output = Se3;
    fn mul(self, rhs: Se3) -> Se3 {
        self.compose(&rhs)
    }
}

/// exp of a twist (ω, t) as the tracker applies it: rotation by the axis-angle ω (Rodrigues)
/// followed by the translation t, `[R(ω) | t]`, on the left of the estimate (world frame).
/// The f64 twin of WGSL `twist_exp_mat()`.
pub fn twist_exp(omega: DVec3, t: DVec3) -> Se3 {
    let angle = omega.length();
    let rotation = if angle > 0.0 { DQuat::from_axis_angle(omega / angle, angle) } else { DQuat::IDENTITY };
    Se3::new(rotation, t)
}

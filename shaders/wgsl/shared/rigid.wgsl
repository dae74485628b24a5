// SPDX-License-Identifier: MIT
#import camera_pose
// Rigid transforms as column-major mat4x4<f32> (rotation R in the upper 3x3, translation t in
// column 3). Mirrors core/src/cpu/shared.rs::{rigid_inverse, twist_exp_mat, orthonormalised,
// rotation_angle_rad}.

// [Rᵀ | -Rᵀ t], the inverse of a rigid transform.
fn rigid_inverse(m: mat4x4<f32>) -> mat4x4<f32> {
    let r = transpose(mat3x3<f32>(m[0].xyz, m[1].xyz, m[2].xyz));
    let t = -(r * m[3].xyz);
    return mat4x4<f32>(vec4<f32>(r[0], 0.0), vec4<f32>(r[1], 0.0), vec4<f32>(r[2], 0.0), vec4<f32>(t, 1.0));
}

// The tracker's update for a twist (ω, t): rotation by the axis-angle ω (Rodrigues) followed
// by the translation t, as [R(ω) | t]; applied on the left of the estimate (world frame).
fn twist_exp_mat(omega: vec3<f32>, t: vec3<f32>) -> mat4x4<f32> {
    let angle = length(omega);
    var r = mat3x3<f32>(vec3<f32>(1.0, 0.0, 0.0), vec3<f32>(0.0, 1.0, 0.0), vec3<f32>(0.0, 0.0, 1.0));
    if angle > 0.0 {
        let k = omega / angle;
        let c = cos(angle);
        let s = sin(angle);
        let v = 1.0 - c;
        // Column-major: column j holds R[.][j].
        r = mat3x3<f32>(
            vec3<f32>(c + k.x * k.x * v, k.y * k.x * v + k.z * s, k.z * k.x * v - k.y * s),
            vec3<f32>(k.x * k.y * v - k.z * s, c + k.y * k.y * v, k.z * k.y * v + k.x * s),
            vec3<f32>(k.x * k.z * v + k.y * s, k.y * k.z * v - k.x * s, c + k.z * k.z * v),
        );
    }
    return mat4x4<f32>(vec4<f32>(r[0], 0.0), vec4<f32>(r[1], 0.0), vec4<f32>(r[2], 0.0), vec4<f32>(t, 1.0));
}

// `m` with its rotation re-orthonormalised (Gram-Schmidt on the columns x, y; z = x × y), so
// composing many f32 updates cannot drift away from a rotation.
fn orthonormalised(m: mat4x4<f32>) -> mat4x4<f32> {
    let x = normalize(m[0].xyz);
    let y = normalize(m[1].xyz - dot(x, m[1].xyz) * x);
    let z = cross(x, y);
    return mat4x4<f32>(vec4<f32>(x, 0.0), vec4<f32>(y, 0.0), vec4<f32>(z, 0.0), vec4<f32>(m[3].xyz, 1.0));
}

// Rotation angle of a rigid transform, radians in [0, π].
fn rotation_angle_rad(m: mat4x4<f32>) -> f32 {
    let c = clamp(0.5 * (m[0].x + m[1].y + m[2].z - 1.0), -1.0, 1.0);
    return acos(c);
}

// The CameraPose of a camera-to-world transform.
fn camera_pose(world_from_camera: mat4x4<f32>, enabled: u32) -> CameraPose {
    return CameraPose(world_from_camera, rigid_inverse(world_from_camera), enabled, 0u, 0u, 0u);
}

// SPDX-License-Identifier: MIT
//! Each invocation labels one full-resolution pixel with its plane (seed 003 §4.3.5, with the
//! point-to-plane distance its errata call for): among the planes whose normal is within the
//! labelling angle of the pixel's normal and whose distance |n·p + d| from the pixel's point is
//! below max(`min_distance_m`, 3 σ(z)) (the sensor's axial noise at the pixel's depth), the
//! nearest (the first among equals); NO_LABEL where none is. Mirrors
//! core/src/cpu/planes/plane_label.rs.
#import invalid
#import kinect
#import planes

struct PlaneLabelParams {
    // Pixels of the maps.
    pixel_count: u32,
    // cos of the labelling angle.
    cos_label: f32,
    // The smallest distance tolerance, metres.
    min_distance_m: f32,
    _pad0: u32,
}

@group(0) @binding(0) var<uniform> params: PlaneLabelParams;
@group(0) @binding(1) var<storage, read> vertex_in_camera: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read> normal_in_camera: array<vec4<f32>>;
// The planes: unit normal (xyz, facing the camera) and offset d (w) of n·p + d = 0.
@group(0) @binding(3) var<storage, read> planes: array<vec4<f32>>;
// [0] = the number of planes.
@group(0) @binding(4) var<storage, read> plane_count: array<u32>;
// Out: per pixel its plane, or NO_LABEL.
@group(0) @binding(5) var<storage, read_write> labels: array<u32>;

@compute @workgroup_size(256, 1, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let ix = gid.x;
    if ix >= params.pixel_count {
        return;
    }
    labels[ix] = NO_LABEL;
    let count = plane_count[0];
    if count == 0u {
        return;
    }
    let p = vertex_in_camera[ix];
    let n = normal_in_camera[ix];
    if !is_valid_f32(p.z) || !(p.z > 0.0) || !is_valid_f32(n.x) {
        return;
    }
    let tolerance = max(params.min_distance_m, 3.0 * kinect_sigma_m(p.z));
    var best = NO_LABEL;
    var best_r = tolerance;
    for (var k = 0u; k < count; k++) {
        let plane = planes[k];
        let r = abs(dot(plane.xyz, p.xyz) + plane.w);
        if abs(dot(n.xyz, plane.xyz)) >= params.cos_label && r < best_r {
            best = k;
            best_r = r;
        }
    }
    labels[ix] = best;
}

// SPDX-License-Identifier: MIT
//! Each invocation bins one pixel's normal into the 32 x 32 normal histogram of plane
//! segmentation (seed 003 §4.3.1): bin (⌊acos(n_x) / π · 32⌋, ⌊acos(n_y) / π · 32⌋) of the
//! normal on the hemisphere n_z ≥ 0 (one with n_z < 0 is negated first), counted by an atomic
//! increment (integer atomics only). Invalid normals, and with `use_labels` the pixels an
//! earlier round labelled (`labels` not NO_LABEL), are not counted. Mirrors
//! core/src/cpu/planes/normal_histogram.rs.
#import invalid
#import planes

struct NormalHistogramParams {
    // Pixels of the normal map.
    pixel_count: u32,
    // 1: skip labelled pixels; 0: count every valid normal (`labels` is then not read).
    use_labels: u32,
    _pad0: u32,
    _pad1: u32,
}

@group(0) @binding(0) var<uniform> params: NormalHistogramParams;
// Unit normals (camera frame; NaN: none).
@group(0) @binding(1) var<storage, read> normal_in_camera: array<vec4<f32>>;
// Per pixel its plane from an earlier round, or NO_LABEL.
@group(0) @binding(2) var<storage, read> labels: array<u32>;
// In/out: NORMAL_BINS² counts, row-major (y, x), cleared by the caller.
@group(0) @binding(3) var<storage, read_write> histogram: array<atomic<u32>>;

@compute @workgroup_size(256, 1, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let ix = gid.x;
    if ix >= params.pixel_count {
        return;
    }
    let n = normal_in_camera[ix];
    if !is_valid_f32(n.x) || !is_valid_f32(n.y) || !is_valid_f32(n.z) {
        return;
    }
    if params.use_labels != 0u && labels[ix] != NO_LABEL {
        return;
    }
    let b = normal_bin(n.xyz);
    atomicAdd(&histogram[b.y * NORMAL_BINS + b.x], 1u);
}

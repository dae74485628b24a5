// SPDX-License-Identifier: MIT
//! Each invocation takes one pixel of the inner loop's pyramid level (seed 003 §4.3.2-4.3.3):
//! unless the full-resolution pixel at its corner is labelled already, it picks the normal peak
//! nearest its normal (the largest |n·n_peak|, the first among equals) and, when that is within
//! the segmentation angle, counts the pixel's distance |n_peak·p| in the peak's distance
//! histogram and adds its normal, turned to the peak's side, to the peak's normal sum (fixed
//! point, NORMAL_SUM_SCALE per unit, i32 atomics: WebGPU has no float atomics) for the
//! realignment to the pixels' mean normal. It records (peak, bin) for the plane sums, or
//! NO_ASSIGNMENT. Mirrors core/src/cpu/planes/distance_histogram.rs.
#import invalid
#import planes

const NO_ASSIGNMENT: u32 = 0xffffffffu;
// Fixed-point scale of the normal sums: 2^14 per unit keeps 2^17 pixels' sum within i32.
const NORMAL_SUM_SCALE: f32 = 16384.0;

struct DistanceHistogramParams {
    // Width and height of this level, pixels.
    width_px: u32,
    height_px: u32,
    // Width of the full-resolution label image, and log2 of this level's scale.
    full_width_px: u32,
    level_shift: u32,
    // cos of the segmentation angle.
    cos_segment: f32,
    // Width of a distance bin, metres.
    bin_m: f32,
    // 1: skip pixels whose full-resolution corner is labelled.
    use_labels: u32,
    _pad0: u32,
}

@group(0) @binding(0) var<uniform> params: DistanceHistogramParams;
@group(0) @binding(1) var<storage, read> vertex_in_camera: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read> normal_in_camera: array<vec4<f32>>;
// Full-resolution labels of earlier rounds (NO_LABEL: free).
@group(0) @binding(3) var<storage, read> labels: array<u32>;
// The normal peaks (normal_peaks' output) and their number.
@group(0) @binding(4) var<storage, read> peaks: array<vec4<f32>>;
@group(0) @binding(5) var<storage, read> peak_count: array<u32>;
// Out: per pixel (peak << 16) | bin, or NO_ASSIGNMENT.
@group(0) @binding(6) var<storage, read_write> assignment: array<u32>;
// In/out (cleared by the caller): per peak DISTANCE_BINS counts.
@group(0) @binding(7) var<storage, read_write> histogram: array<atomic<u32>>;
// In/out (cleared by the caller): per peak the fixed-point sum of normals (x, y, z, unused).
@group(0) @binding(8) var<storage, read_write> normal_sums: array<atomic<i32>>;

@compute @workgroup_size(16, 16, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    if gid.x >= params.width_px || gid.y >= params.height_px {
        return;
    }
    let ix = gid.y * params.width_px + gid.x;
    assignment[ix] = NO_ASSIGNMENT;
    let p = vertex_in_camera[ix];
    let n = normal_in_camera[ix];
    if !is_valid_f32(p.z) || !(p.z > 0.0) || !is_valid_f32(n.x) {
        return;
    }
    if params.use_labels != 0u && labels[(gid.y << params.level_shift) * params.full_width_px + (gid.x << params.level_shift)] != NO_LABEL {
        return;
    }
    var best = 0u;
    var best_cos = -1.0;
    for (var k = 0u; k < peak_count[0]; k++) {
        let c = abs(dot(n.xyz, peaks[k].xyz));
        if c > best_cos {
            best_cos = c;
            best = k;
        }
    }
    if best_cos < params.cos_segment {
        return;
    }
    let pk = peaks[best].xyz;
    let bin = u32(abs(dot(pk, p.xyz)) / params.bin_m);
    if bin >= DISTANCE_BINS {
        return;
    }
    atomicAdd(&histogram[best * DISTANCE_BINS + bin], 1u);
    let side = select(1.0, -1.0, dot(n.xyz, pk) < 0.0);
    let q = vec3<i32>(round(side * n.xyz * NORMAL_SUM_SCALE));
    atomicAdd(&normal_sums[4u * best], q.x);
    atomicAdd(&normal_sums[4u * best + 1u], q.y);
    atomicAdd(&normal_sums[4u * best + 2u], q.z);
    assignment[ix] = (best << 16u) | bin;
}

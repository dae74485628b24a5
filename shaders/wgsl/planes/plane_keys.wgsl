// SPDX-License-Identifier: MIT
//! Each invocation decides which plane's statistics one pixel goes into (seed 003 §4.3.3's
//! per-plane sums), or none (NO_LABEL):
//! - mode 0, the inner loop: from distance_histogram's assignment (normal peak k, distance bin)
//!   and distance_peaks' intervals, the plane k · MAX_DISTANCE_PEAKS + j of the interval j of
//!   peak k that holds the bin;
//! - mode 1, after labelling: the pixel's label, if every pixel within `margin_px` carries the
//!   same label (the filters blend depth and normals across a border, which would pull a narrow
//!   plane's fit), and, with `use_raw`, if its raw depth is valid and the raw point lies within
//!   the labelling distance max(`min_distance_m`, 3 σ(z)) of the plane.
//! Each keyed pixel also sets its plane's bit in its chunk's mask (PLANE_SUMS_CHUNK_PX pixels
//! in index order; atomicOr, the caller clears), so plane_sums skips the (chunk, plane) pairs
//! with no pixel. Mirrors core/src/cpu/planes/plane_keys.rs.
#import invalid
#import kinect
#import planes

const NO_ASSIGNMENT: u32 = 0xffffffffu;

struct PlaneKeysParams {
    // Width and height of the maps, pixels.
    width_px: u32,
    height_px: u32,
    // 0: keys from an assignment and intervals; 1: from labels.
    mode: u32,
    // Mode 1: the neighbourhood radius that must carry the pixel's label, pixels.
    margin_px: u32,
    // Mode 1: 1 to test the raw point against the plane.
    use_raw: u32,
    // Mode 1: the smallest labelling distance, metres.
    min_distance_m: f32,
    // Intrinsics of the maps (mode 1 with use_raw: the raw point's back-projection).
    fx_px: f32,
    fy_px: f32,
    cx_px: f32,
    cy_px: f32,
    _pad0: u32,
    _pad1: u32,
}

@group(0) @binding(0) var<uniform> params: PlaneKeysParams;
// Mode 0: per pixel (peak << 16) | bin or NO_ASSIGNMENT; mode 1: per pixel its label.
@group(0) @binding(1) var<storage, read> source: array<u32>;
// Mode 0: per normal peak MAX_DISTANCE_PEAKS intervals (first bin, last bin, pixels, 0).
@group(0) @binding(2) var<storage, read> intervals: array<vec4<u32>>;
// Mode 0: per normal peak its number of intervals.
@group(0) @binding(3) var<storage, read> interval_count: array<u32>;
// Mode 1: the depth before filtering, metres (NaN: none).
@group(0) @binding(4) var<storage, read> raw_depth_m: array<f32>;
// Mode 1: the planes, unit normal (xyz) and offset (w) of n·p + d = 0.
@group(0) @binding(5) var<storage, read> planes: array<vec4<f32>>;
// Out: per pixel its plane, or NO_LABEL.
@group(0) @binding(6) var<storage, read_write> keys: array<u32>;
// In/out (cleared by the caller): per chunk CHUNK_MASK_WORDS words, bit k set when a pixel of
// the chunk has key k.
@group(0) @binding(7) var<storage, read_write> chunk_masks: array<atomic<u32>>;

fn key_from_assignment(ix: u32) -> u32 {
    let a = source[ix];
    if a == NO_ASSIGNMENT {
        return NO_LABEL;
    }
    let k = a >> 16u;
    let bin = a & 0xffffu;
    for (var j = 0u; j < interval_count[k]; j++) {
        let iv = intervals[k * MAX_DISTANCE_PEAKS + j];
        if iv.x <= bin && bin <= iv.y {
            return k * MAX_DISTANCE_PEAKS + j;
        }
    }
    return NO_LABEL;
}

fn key_from_label(x: u32, y: u32) -> u32 {
    let w = i32(params.width_px);
    let h = i32(params.height_px);
    let ix = y * params.width_px + x;
    let l = source[ix];
    if l == NO_LABEL {
        return NO_LABEL;
    }
    let m = i32(params.margin_px);
    for (var dy = -m; dy <= m; dy++) {
        for (var dx = -m; dx <= m; dx++) {
            let u = i32(x) + dx;
            let v = i32(y) + dy;
            if u < 0 || v < 0 || u >= w || v >= h || source[u32(v * w + u)] != l {
                return NO_LABEL;
            }
        }
    }
    if params.use_raw != 0u {
        let z = raw_depth_m[ix];
        if !is_valid_f32(z) || !(z > 0.0) {
            return NO_LABEL;
        }
        let q = vec3<f32>((f32(x) - params.cx_px) / params.fx_px * z, (f32(y) - params.cy_px) / params.fy_px * z, z);
        let plane = planes[l];
        if abs(dot(plane.xyz, q) + plane.w) >= max(params.min_distance_m, 3.0 * kinect_sigma_m(z)) {
            return NO_LABEL;
        }
    }
    return l;
}

@compute @workgroup_size(16, 16, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    if gid.x >= params.width_px || gid.y >= params.height_px {
        return;
    }
    let ix = gid.y * params.width_px + gid.x;
    var key = NO_LABEL;
    if params.mode == 0u {
        key = key_from_assignment(ix);
    } else {
        key = key_from_label(gid.x, gid.y);
    }
    keys[ix] = key;
    if key != NO_LABEL {
        // Most pixels of a chunk find their plane's bit set already: a load, not a
        // read-modify-write every pixel of the chunk contends for.
        let word = (ix / PLANE_SUMS_CHUNK_PX) * CHUNK_MASK_WORDS + key / 32u;
        let bit = 1u << (key % 32u);
        if (atomicLoad(&chunk_masks[word]) & bit) == 0u {
            atomicOr(&chunk_masks[word], bit);
        }
    }
}

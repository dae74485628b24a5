// SPDX-License-Identifier: MIT
//! Each workgroup sums one plane's pixels in one chunk of PLANE_SUMS_CHUNK_PX pixels (seed 003
//! §4.3.3's plane statistics, reduced on the GPU without float atomics): workgroup (c, k)
//! takes the pixels of chunk c whose key (plane_keys' output) is k; each of its 64 invocations
//! walks pixels c · PLANE_SUMS_CHUNK_PX + lid, + 64, ... and adds each to its moments
//! (shared/plane_moments.wgsl: centred, Welford's update), then the workgroup tree-combines
//! its 64 moments and writes them as partial (k, c). A pixel's point is its vertex, or with
//! `use_raw` its raw depth back-projected (whose model noise σ(z)² r rᵀ, r = p / z, it also
//! adds); its footprint on the plane, z³ / (f_x f_y |n·p|), uses the normal
//! `normals[k >> normal_shift]` (the plane's, or in the inner loop its normal peak's).
//! Mirrors core/src/cpu/planes/plane_sums.rs.
#import invalid
#import kinect
#import plane_moments

const PLANE_SUMS_CHUNK_PX: u32 = 4096u;
const PLANE_SUMS_WORKGROUP: u32 = 64u;

struct PlaneSumsParams {
    // Width and height of the maps, pixels.
    width_px: u32,
    height_px: u32,
    // 1: points from `raw_depth_m`, with their model noise.
    use_raw: u32,
    // log2 of the keys per entry of `normals`.
    normal_shift: u32,
    fx_px: f32,
    fy_px: f32,
    cx_px: f32,
    cy_px: f32,
}

@group(0) @binding(0) var<uniform> params: PlaneSumsParams;
// Per pixel its plane (plane_keys' output), or NO_LABEL.
@group(0) @binding(1) var<storage, read> keys: array<u32>;
@group(0) @binding(2) var<storage, read> vertex_in_camera: array<vec4<f32>>;
@group(0) @binding(3) var<storage, read> normal_in_camera: array<vec4<f32>>;
// The depth before filtering, metres (read with `use_raw`).
@group(0) @binding(4) var<storage, read> raw_depth_m: array<f32>;
// The normals (xyz) the footprints are measured on.
@group(0) @binding(5) var<storage, read> normals: array<vec4<f32>>;
// Out: per plane k and chunk c, PLANE_MOMENT_VEC4S vec4 at (k · chunks + c).
@group(0) @binding(6) var<storage, read_write> partials: array<vec4<f32>>;

var<workgroup> scratch: array<array<vec4<f32>, 10>, 64>;

@compute @workgroup_size(64, 1, 1)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let pixel_count = params.width_px * params.height_px;
    let chunks = (pixel_count + PLANE_SUMS_CHUNK_PX - 1u) / PLANE_SUMS_CHUNK_PX;
    let c = wid.x;
    let k = wid.y;
    let footprint_normal = normals[k >> params.normal_shift].xyz;
    var acc = plane_moments_zero();
    for (var i = 0u; i < PLANE_SUMS_CHUNK_PX / PLANE_SUMS_WORKGROUP; i++) {
        let ix = c * PLANE_SUMS_CHUNK_PX + i * PLANE_SUMS_WORKGROUP + lid;
        if ix >= pixel_count || keys[ix] != k {
            continue;
        }
        var p = vertex_in_camera[ix].xyz;
        var noise_scale = 0.0;
        if params.use_raw != 0u {
            let z = raw_depth_m[ix];
            let x = f32(ix % params.width_px);
            let y = f32(ix / params.width_px);
            p = vec3<f32>((x - params.cx_px) / params.fx_px * z, (y - params.cy_px) / params.fy_px * z, z);
            let s = kinect_sigma_m(z) / z;
            noise_scale = s * s;
        }
        let np = max(abs(dot(footprint_normal, p)), 1e-6);
        let area = p.z * p.z * p.z / (params.fx_px * params.fy_px * np);
        plane_moments_add_point(&acc, p, normal_in_camera[ix].xyz, area, noise_scale);
    }
    scratch[lid] = acc;
    for (var stride = PLANE_SUMS_WORKGROUP / 2u; stride > 0u; stride >>= 1u) {
        workgroupBarrier();
        if lid < stride {
            scratch[lid] = plane_moments_combine(scratch[lid], scratch[lid + stride]);
        }
    }
    workgroupBarrier();
    if lid == 0u && c < chunks {
        let base = (k * chunks + c) * PLANE_MOMENT_VEC4S;
        for (var j = 0u; j < PLANE_MOMENT_VEC4S; j++) {
            partials[base + j] = scratch[0][j];
        }
    }
}

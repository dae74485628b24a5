// SPDX-License-Identifier: MIT
//! Each workgroup sums one plane's pixels in one chunk of PLANE_SUMS_CHUNK_PX pixels (seed 003
//! §4.3.3's plane statistics, reduced on the GPU without float atomics): workgroup (c, k)
//! takes the pixels of chunk c whose key (plane_keys' output) is k; where plane_keys' chunk
//! mask says the chunk has none, it writes empty moments at once. Each of its 64 invocations
//! walks PLANE_SUMS_CHUNK_PX / 64 consecutive pixels (a few centimetres of surface) and sums
//! them relative to its first point (plain sums of d = p - p₀: a handful of multiply-adds per
//! pixel, and no cancellation worth the name over so short a run), turns its sums into centred
//! moments (shared/plane_moments.wgsl), then the workgroup tree-combines its 64 moments
//! pairwise and writes them as partial (k, c). A pixel's point is its vertex, or with `use_raw`
//! its raw depth back-projected (whose model noise σ(z)² r rᵀ, r = p / z, it also adds); its
//! footprint on the plane, z³ / (f_x f_y |n·p|), uses the normal `normals[k >> normal_shift]`
//! (the plane's, or in the inner loop its normal peak's). Mirrors
//! core/src/cpu/planes/plane_sums.rs.
#import invalid
#import kinect
#import planes
#import plane_moments

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
// Per chunk CHUNK_MASK_WORDS words: bit k set when the chunk has a pixel of key k (plane_keys').
@group(0) @binding(7) var<storage, read> chunk_masks: array<u32>;

var<workgroup> scratch: array<array<vec4<f32>, 10>, 64>;

@compute @workgroup_size(64, 1, 1)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let pixel_count = params.width_px * params.height_px;
    let chunks = (pixel_count + PLANE_SUMS_CHUNK_PX - 1u) / PLANE_SUMS_CHUNK_PX;
    let c = wid.x;
    let k = wid.y;
    if c >= chunks {
        return;
    }
    if (chunk_masks[c * CHUNK_MASK_WORDS + k / 32u] & (1u << (k % 32u))) == 0u {
        if lid == 0u {
            for (var j = 0u; j < PLANE_MOMENT_VEC4S; j++) {
                partials[(k * chunks + c) * PLANE_MOMENT_VEC4S + j] = vec4<f32>(0.0);
            }
        }
        return;
    }
    let footprint_normal = normals[k >> params.normal_shift].xyz;
    // Sums over this invocation's pixels of d = p - p0 (p0 its first point), d dᵀ (diagonal,
    // then xy xz yz), n, n_i d, and of the area and noise.
    var count = 0.0;
    var area = 0.0;
    var p0 = vec3<f32>(0.0);
    var sd = vec3<f32>(0.0);
    var sdd = vec3<f32>(0.0);
    var sdd_off = vec3<f32>(0.0);
    var sn = vec3<f32>(0.0);
    var snd_x = vec3<f32>(0.0);
    var snd_y = vec3<f32>(0.0);
    var snd_z = vec3<f32>(0.0);
    var noise = vec3<f32>(0.0);
    var noise_off = vec3<f32>(0.0);
    let run = PLANE_SUMS_CHUNK_PX / PLANE_SUMS_WORKGROUP;
    for (var i = 0u; i < run; i++) {
        let ix = c * PLANE_SUMS_CHUNK_PX + lid * run + i;
        if ix >= pixel_count || keys[ix] != k {
            continue;
        }
        var p: vec3<f32>;
        var noise_scale = 0.0;
        if params.use_raw == 0u {
            p = vertex_in_camera[ix].xyz;
        } else {
            let z = raw_depth_m[ix];
            let x = f32(ix % params.width_px);
            let y = f32(ix / params.width_px);
            p = vec3<f32>((x - params.cx_px) / params.fx_px * z, (y - params.cy_px) / params.fy_px * z, z);
            let s = kinect_sigma_m(z) / z;
            noise_scale = s * s;
        }
        let np = max(abs(dot(footprint_normal, p)), 1e-6);
        let n = normal_in_camera[ix].xyz;
        if count == 0.0 {
            p0 = p;
        }
        let d = p - p0;
        count += 1.0;
        area += p.z * p.z * p.z / (params.fx_px * params.fy_px * np);
        sd += d;
        sdd += d * d;
        sdd_off += vec3<f32>(d.x * d.y, d.x * d.z, d.y * d.z);
        sn += n;
        snd_x += n.x * d;
        snd_y += n.y * d;
        snd_z += n.z * d;
        noise += noise_scale * p * p;
        noise_off += noise_scale * vec3<f32>(p.x * p.y, p.x * p.z, p.y * p.z);
    }
    // The centred moments of those sums.
    var acc = plane_moments_zero();
    if count > 0.0 {
        let mean_d = sd / count;
        acc[0] = vec4<f32>(count, area, 0.0, 0.0);
        acc[1] = vec4<f32>(p0 + mean_d, 0.0);
        acc[2] = vec4<f32>(sn / count, 0.0);
        acc[3] = vec4<f32>(sdd - sd * mean_d, 0.0);
        acc[4] = vec4<f32>(sdd_off - vec3<f32>(sd.x * mean_d.y, sd.x * mean_d.z, sd.y * mean_d.z), 0.0);
        acc[5] = vec4<f32>(snd_x - sn.x * mean_d, 0.0);
        acc[6] = vec4<f32>(snd_y - sn.y * mean_d, 0.0);
        acc[7] = vec4<f32>(snd_z - sn.z * mean_d, 0.0);
        acc[8] = vec4<f32>(noise, 0.0);
        acc[9] = vec4<f32>(noise_off, 0.0);
    }
    scratch[lid] = acc;
    for (var stride = PLANE_SUMS_WORKGROUP / 2u; stride > 0u; stride >>= 1u) {
        workgroupBarrier();
        if lid < stride {
            scratch[lid] = plane_moments_combine(scratch[lid], scratch[lid + stride]);
        }
    }
    workgroupBarrier();
    if lid == 0u {
        let base = (k * chunks + c) * PLANE_MOMENT_VEC4S;
        for (var j = 0u; j < PLANE_MOMENT_VEC4S; j++) {
            partials[base + j] = scratch[0][j];
        }
    }
}

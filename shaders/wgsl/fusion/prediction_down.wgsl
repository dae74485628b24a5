// SPDX-License-Identifier: MIT
//! Each invocation makes one pixel of the next-coarser predicted surface from the finer one
//! (raycasting only the finest level, as KinectFusion does): the mean of the 2x2 block's world
//! vertices and the normalised sum of its normals, or invalid (NaN) unless all four are valid,
//! so a coarse pixel never averages across a silhouette. Pixel centres follow the pyramid's
//! cx' = (cx - 0.5) / 2, whose pixel sees the block's centre.
#import invalid

struct PredictionDownParams {
    // Finer level width, pixels.
    src_width_px: u32,
    // Finer level height, pixels.
    src_height_px: u32,
    // Coarser level width, pixels.
    dst_width_px: u32,
    // Coarser level height, pixels.
    dst_height_px: u32,
}

@group(0) @binding(0) var<uniform> params: PredictionDownParams;
// Finer predicted vertices (x, y, z, 1), world frame.
@group(0) @binding(1) var<storage, read> vertex_fine: array<vec4<f32>>;
// Finer predicted unit normals, world frame.
@group(0) @binding(2) var<storage, read> normal_fine: array<vec4<f32>>;
// Out: coarser predicted vertices.
@group(0) @binding(3) var<storage, read_write> vertex_coarse: array<vec4<f32>>;
// Out: coarser predicted normals.
@group(0) @binding(4) var<storage, read_write> normal_coarse: array<vec4<f32>>;

@compute @workgroup_size(16, 16, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    if gid.x >= params.dst_width_px || gid.y >= params.dst_height_px {
        return;
    }
    let out_ix = gid.y * params.dst_width_px + gid.x;
    let x = min(2u * gid.x, params.src_width_px - 2u);
    let y = min(2u * gid.y, params.src_height_px - 2u);
    let w = params.src_width_px;
    var v = vec3<f32>(0.0);
    var n = vec3<f32>(0.0);
    for (var i = 0u; i < 4u; i++) {
        let ix = (y + (i >> 1u)) * w + x + (i & 1u);
        let vi = vertex_fine[ix];
        let ni = normal_fine[ix];
        if !is_valid_f32(vi.x) || !is_valid_f32(ni.x) {
            vertex_coarse[out_ix] = invalid_vec4();
            normal_coarse[out_ix] = invalid_vec4();
            return;
        }
        v += vi.xyz;
        n += ni.xyz;
    }
    let len = length(n);
    if !(len > 1e-6) {
        vertex_coarse[out_ix] = invalid_vec4();
        normal_coarse[out_ix] = invalid_vec4();
        return;
    }
    vertex_coarse[out_ix] = vec4<f32>(0.25 * v, 1.0);
    normal_coarse[out_ix] = vec4<f32>(n / len, 0.0);
}

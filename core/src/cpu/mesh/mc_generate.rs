// SPDX-License-Identifier: MIT
//! CPU reference of `shaders/wgsl/mc_generate.wgsl`.

use crate::cpu::mesh::marching_cubes::{
    SCAN_WG_SIZE, add3, mc_block_origin, mc_case_edge, mc_case_triangle_count, mc_cell_case, mc_cell_in_volume, mc_edge_start_offset, mc_local_cell, unit_u32,
    wg_exclusive_scan,
};
use crate::cpu::shared::{MapRef, map_word, pack_rgb8, unpack_rgb8, voxel_centre_in_world, voxel_slot, voxel_tsdf, voxel_weight};
use crate::kernels::mc_generate::{MC_MIN_GRADIENT_SQ, MC_WHITE_RGB8, McGenerateParams, McVertex};
use crate::kernels::mc_scan::MC_NO_BLOCK;
use crate::tsdf::VolumeDesc;

/// Twin of `unit_f32()`.
fn unit_f32(axis: u32) -> [f32; 3] {
    unit_u32(axis).map(|v| v as f32)
}

/// Twin of `mc_voxel_gradient()`.
pub fn mc_voxel_gradient(map: MapRef<'_>, d: &VolumeDesc, v: [u32; 3], c: f32) -> [f32; 3] {
    let dims = [d.dim_x, d.dim_y, d.dim_z];
    let mut g = [0.0f32; 3];
    for i in 0..3usize {
        let u = unit_u32(i as u32);
        let mut plus_ok = v[i] + 1 < dims[i];
        let mut minus_ok = v[i] > 0;
        let mut t_plus = 0.0;
        let mut t_minus = 0.0;
        if plus_ok {
            let w = map_word(map, d, v[0] + u[0], v[1] + u[1], v[2] + u[2]);
            plus_ok = voxel_weight(w) != 0;
            t_plus = voxel_tsdf(w);
        }
        if minus_ok {
            let w = map_word(map, d, v[0] - u[0], v[1] - u[1], v[2] - u[2]);
            minus_ok = voxel_weight(w) != 0;
            t_minus = voxel_tsdf(w);
        }
        if plus_ok && minus_ok {
            g[i] = (t_plus - t_minus) * 0.5;
        } else if plus_ok {
            g[i] = t_plus - c;
        } else if minus_ok {
            g[i] = c - t_minus;
        }
    }
    g
}

/// Twin of `mc_vertex_normal()`; `mix(a, b, t)` is `a * (1 - t) + b * t` as WGSL defines it.
#[expect(clippy::too_many_arguments, reason = "same arguments as the WGSL function (plus the volume it reads)")]
pub fn mc_vertex_normal(map: MapRef<'_>, d: &VolumeDesc, base: [u32; 3], end: [u32; 3], axis: u32, v0: f32, v1: f32, t: f32) -> [f32; 3] {
    let (g0, g1) = (mc_voxel_gradient(map, d, base, v0), mc_voxel_gradient(map, d, end, v1));
    let g: [f32; 3] = std::array::from_fn(|i| g0[i] * (1.0 - t) + g1[i] * t);
    let len_sq = g[0] * g[0] + g[1] * g[1] + g[2] * g[2];
    if len_sq > MC_MIN_GRADIENT_SQ {
        let len = len_sq.sqrt();
        return g.map(|v| v / len);
    }
    let s = if v1 > v0 { 1.0 } else { -1.0 };
    unit_f32(axis).map(|v| v * s)
}

/// Twin of `mc_edge_vertex()`.
pub fn mc_edge_vertex(params: &McGenerateParams, map: MapRef<'_>, colors: &[u32], base: [u32; 3], axis: u32) -> McVertex {
    let d = &params.volume;
    let ix0 = voxel_slot(map, d, base[0], base[1], base[2]);
    let u = unit_u32(axis);
    let end = [base[0] + u[0], base[1] + u[1], base[2] + u[2]];
    let ix1 = voxel_slot(map, d, end[0], end[1], end[2]);
    let v0 = voxel_tsdf(map.tsdf_volume[ix0 as usize]);
    let v1 = voxel_tsdf(map.tsdf_volume[ix1 as usize]);
    let t = v0 / (v0 - v1);
    let mut p = voxel_centre_in_world(d, base[0], base[1], base[2]);
    p[axis as usize] += t * d.voxel_size_m;
    let n = mc_vertex_normal(map, d, base, end, axis, v0, v1, t);
    let color_rgb8 = if params.has_color != 0 {
        let (c0, c1) = (unpack_rgb8(colors[ix0 as usize]), unpack_rgb8(colors[ix1 as usize]));
        pack_rgb8(std::array::from_fn(|k| c0[k] * (1.0 - t) + c1[k] * t))
    } else {
        MC_WHITE_RGB8
    };
    McVertex { x_m: p[0], y_m: p[1], z_m: p[2], edge_id: ix0 * 3 + axis, normal_x: n[0], normal_y: n[1], normal_z: n[2], color_rgb8 }
}

/// Writes the triangles in `[first_triangle, first_triangle + capacity_triangles)` as the
/// `n_workgroups` workgroups do (`McCounters::generate_workgroups` of `mc_scan`, x times y);
/// `vertices` holds `3 * capacity_triangles` entries.
#[expect(clippy::too_many_arguments, reason = "the kernel's bindings in WGSL order, plus its dispatch size")]
pub fn mc_generate(
    params: &McGenerateParams,
    tsdf_volume: &[u32],
    colors: &[u32],
    mc_table: &[u32],
    active_blocks: &[u32],
    block_offsets: &[u32],
    vertices: &mut [McVertex],
    block_table: &[u32],
    block_coords: &[u32],
    n_workgroups: u32,
) {
    let d = &params.volume;
    let map = MapRef { tsdf_volume, block_table };
    for wg_ix in 0..n_workgroups {
        let block_ix = active_blocks[wg_ix as usize];
        if block_ix == MC_NO_BLOCK {
            continue;
        }
        let origin = mc_block_origin(d, block_coords, block_ix, params.n_blocks_x, params.n_blocks_y);
        let mut sh_cell_case = [0u32; SCAN_WG_SIZE];
        let mut n_triangles = [0u32; SCAN_WG_SIZE];
        for local_ix in 0..SCAN_WG_SIZE {
            let cell = add3(origin, mc_local_cell(local_ix as u32));
            if mc_cell_in_volume(d, cell) {
                sh_cell_case[local_ix] = mc_cell_case(map, d, cell);
            }
            n_triangles[local_ix] = mc_case_triangle_count(mc_table, sh_cell_case[local_ix]);
        }
        let scan = wg_exclusive_scan(&n_triangles);
        let sh_cell_first: [u32; SCAN_WG_SIZE] = std::array::from_fn(|i| scan[i].exclusive);
        let block_first = block_offsets[block_ix as usize];
        // Vertex slots in order; on the GPU invocation i takes slots i, i + 256, ...
        for slot in 0..3 * scan[0].total {
            let local_tri = slot / 3;
            let tri_ix = block_first + local_tri;
            if tri_ix < params.first_triangle || tri_ix - params.first_triangle >= params.capacity_triangles {
                continue;
            }
            let (mut lo, mut hi) = (0usize, SCAN_WG_SIZE);
            while hi - lo > 1 {
                let mid = (lo + hi) / 2;
                if sh_cell_first[mid] <= local_tri {
                    lo = mid;
                } else {
                    hi = mid;
                }
            }
            let k = local_tri - sh_cell_first[lo];
            let edge = mc_case_edge(mc_table, sh_cell_case[lo], 3 * k + slot % 3);
            let owner = add3(origin, mc_local_cell(lo as u32));
            vertices[((tri_ix - params.first_triangle) * 3 + slot % 3) as usize] = mc_edge_vertex(params, map, colors, add3(owner, mc_edge_start_offset(edge)), edge / 4);
        }
    }
}

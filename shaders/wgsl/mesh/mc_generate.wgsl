// SPDX-License-Identifier: MIT
//! Marching cubes, pass 3 of 3, dispatched indirectly with mc_scan's size: workgroup w
//! (= workgroup_id.x + workgroup_id.y * num_workgroups.x) takes the 8 x 8 x 4 block
//! active_blocks[w], so only blocks with triangles run (MC_NO_BLOCK padding returns at once).
//! Each invocation re-classifies one cell of the block and the workgroup scans the triangle
//! counts, so triangle k of cell c is the block's local triangle sh_cell_first[c] + k, with
//! global index block_offsets[block] + that. The work is then expanded by output vertex, not
//! by cell, to keep invocations in step: invocation i handles the block's vertex slots
//! s = i, i + 256, ... below 3 * (block total), finding the cell of local triangle s / 3 by
//! binary search in sh_cell_first. Triangles with a global index in
//! [first_triangle, first_triangle + capacity_triangles) are written as 3 McVertex at
//! 3 * (index - first_triangle); the rest are skipped (the host learned the total from mc_scan
//! and grows the buffer or generates in several ranges).
//! Each vertex lies on the voxel edge from voxel `base` along `axis`, at the linear zero
//! crossing of the TSDF. Its normal is the normalised TSDF gradient there: central differences
//! at the two edge voxels (one-sided next to an unobserved voxel or the volume's border),
//! interpolated along the edge (what trilinear interpolation reduces to on an edge). Its colour
//! interpolates the edge voxels' colours (white without colour). Its `edge_id` =
//! voxel_slot(base) * 3 + axis is the same in every cell sharing the edge, for welding.
#import marching_cubes
#import mc_counters
#import workgroup_scan

struct McGenerateParams {
    // The TSDF volume.
    volume: VolumeDesc,
    // As in McCountParams.
    n_blocks_x: u32,
    // Blocks along y.
    n_blocks_y: u32,
    // First global triangle index this pass writes.
    first_triangle: u32,
    // Triangles `vertices` holds (3 vertices each).
    capacity_triangles: u32,
    // 1 when `colors` holds one RGB8 word per voxel.
    has_color: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

struct McVertex {
    // World x, metres.
    x_m: f32,
    // World y, metres.
    y_m: f32,
    // World z, metres.
    z_m: f32,
    // Voxel edge the vertex lies on: `voxel_slot(lower voxel) * 3 + axis` (the voxel's index in the
    // dense box or the sparse pool); equal for every cell sharing the edge, so it welds triangles
    // into an indexed mesh.
    edge_id: u32,
    // Unit normal x (toward free space).
    normal_x: f32,
    // Unit normal y.
    normal_y: f32,
    // Unit normal z.
    normal_z: f32,
    // r | g << 8 | b << 16.
    color_rgb8: u32,
}

const MC_WHITE_RGB8: u32 = 0xffffffu;
// Squared gradient norms (truncation units per voxel, squared) at or below this give no normal.
const MC_MIN_GRADIENT_SQ: f32 = 1e-12;

// Per cell of the block: its first local triangle (exclusive scan of the counts) and its case.
var<workgroup> sh_cell_first: array<u32, MC_CELLS_PER_BLOCK>;
var<workgroup> sh_cell_case: array<u32, MC_CELLS_PER_BLOCK>;

// Uniform [`McGenerateParams`].
@group(0) @binding(0) var<uniform> params: McGenerateParams;
// Voxel words (TSDF + weight).
@group(0) @binding(1) var<storage, read> tsdf_volume: array<u32>;
// Colour words (RGB8), or a placeholder when `has_color` is 0.
@group(0) @binding(2) var<storage, read> colors: array<u32>;
// [`crate::mesh::mc_table::McTable::packed`].
@group(0) @binding(3) var<storage, read> mc_table: array<u32>;
// Blocks with triangles, padded (from `mc_scan`).
@group(0) @binding(4) var<storage, read> active_blocks: array<u32>;
// First triangle of each block (from `mc_scan`).
@group(0) @binding(5) var<storage, read> block_offsets: array<u32>;
// Out: `3 * capacity_triangles` [`McVertex`].
@group(0) @binding(6) var<storage, read_write> vertices: array<McVertex>;
// A sparse map's hash table (map.wgsl); one placeholder word for a dense map.
@group(0) @binding(7) var<storage, read> block_table: array<u32>;
// A sparse map's key per pool block; one placeholder word for a dense map.
@group(0) @binding(8) var<storage, read> block_coords: array<u32>;

fn unit_f32(axis: u32) -> vec3<f32> {
    return vec3<f32>(unit_u32(axis));
}

// TSDF gradient (truncation units per voxel) at observed voxel `v` with TSDF `c`: central
// differences, one-sided where a neighbour is unobserved or outside the volume, 0 along an axis
// with neither.
fn mc_voxel_gradient(d: VolumeDesc, v: vec3<u32>, c: f32) -> vec3<f32> {
    let dims = vec3<u32>(d.dim_x, d.dim_y, d.dim_z);
    var g = vec3<f32>(0.0);
    for (var i = 0u; i < 3u; i++) {
        let u = unit_u32(i);
        var plus_ok = v[i] + 1u < dims[i];
        var minus_ok = v[i] > 0u;
        var t_plus = 0.0;
        var t_minus = 0.0;
        if plus_ok {
            let w = map_word(d, v.x + u.x, v.y + u.y, v.z + u.z);
            plus_ok = voxel_weight(w) != 0u;
            t_plus = voxel_tsdf(w);
        }
        if minus_ok {
            let w = map_word(d, v.x - u.x, v.y - u.y, v.z - u.z);
            minus_ok = voxel_weight(w) != 0u;
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
    return g;
}

// Unit normal at parameter `t` along the edge from voxel `base` (TSDF v0) to `end` (v1): the
// interpolated voxel gradients, normalised; the edge direction toward the positive end when
// the gradient vanishes.
fn mc_vertex_normal(d: VolumeDesc, base: vec3<u32>, end: vec3<u32>, axis: u32, v0: f32, v1: f32, t: f32) -> vec3<f32> {
    let g = mix(mc_voxel_gradient(d, base, v0), mc_voxel_gradient(d, end, v1), vec3<f32>(t));
    let len_sq = dot(g, g);
    if len_sq > MC_MIN_GRADIENT_SQ {
        return g / sqrt(len_sq);
    }
    return unit_f32(axis) * select(-1.0, 1.0, v1 > v0);
}

fn mc_edge_vertex(d: VolumeDesc, base: vec3<u32>, axis: u32) -> McVertex {
    // Both ends lie in allocated blocks: the cell's case came from their words.
    let ix0 = voxel_slot(d, base.x, base.y, base.z);
    let end = base + unit_u32(axis);
    let ix1 = voxel_slot(d, end.x, end.y, end.z);
    let v0 = voxel_tsdf(tsdf_volume[ix0]);
    let v1 = voxel_tsdf(tsdf_volume[ix1]);
    let t = v0 / (v0 - v1);
    var p = voxel_centre_in_world(d, base.x, base.y, base.z);
    p[axis] = p[axis] + t * d.voxel_size_m;
    let n = mc_vertex_normal(d, base, end, axis, v0, v1, t);
    var out: McVertex;
    out.x_m = p.x;
    out.y_m = p.y;
    out.z_m = p.z;
    out.edge_id = ix0 * 3u + axis;
    out.normal_x = n.x;
    out.normal_y = n.y;
    out.normal_z = n.z;
    out.color_rgb8 = MC_WHITE_RGB8;
    if params.has_color != 0u {
        out.color_rgb8 = pack_rgb8(mix(unpack_rgb8(colors[ix0]), unpack_rgb8(colors[ix1]), vec3<f32>(t)));
    }
    return out;
}

@compute @workgroup_size(256, 1, 1)
fn main(@builtin(workgroup_id) wg_id: vec3<u32>, @builtin(num_workgroups) n_wg: vec3<u32>, @builtin(local_invocation_index) local_ix: u32) {
    let block_ix = active_blocks[wg_id.x + wg_id.y * n_wg.x];
    if block_ix == MC_NO_BLOCK {
        return;
    }
    let d = params.volume;
    let origin = mc_block_origin(d, block_ix, params.n_blocks_x, params.n_blocks_y);
    let cell = origin + mc_local_cell(local_ix);
    var case_ix = 0u;
    if mc_cell_in_volume(d, cell) {
        case_ix = mc_cell_case(d, cell);
    }
    let scan = wg_exclusive_scan(local_ix, mc_case_triangle_count(case_ix));
    sh_cell_first[local_ix] = scan.exclusive;
    sh_cell_case[local_ix] = case_ix;
    workgroupBarrier();
    let block_first = block_offsets[block_ix];
    for (var slot = local_ix; slot < 3u * scan.total; slot += MC_CELLS_PER_BLOCK) {
        let local_tri = slot / 3u;
        let tri_ix = block_first + local_tri;
        if tri_ix < params.first_triangle || tri_ix - params.first_triangle >= params.capacity_triangles {
            continue;
        }
        // The last cell whose first triangle is <= local_tri (cells without triangles share
        // their first index with the next cell, so the last one is the owner).
        var lo = 0u;
        var hi = MC_CELLS_PER_BLOCK;
        while hi - lo > 1u {
            let mid = (lo + hi) / 2u;
            if sh_cell_first[mid] <= local_tri {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        let k = local_tri - sh_cell_first[lo];
        let edge = mc_case_edge(sh_cell_case[lo], 3u * k + slot % 3u);
        let owner = origin + mc_local_cell(lo);
        vertices[(tri_ix - params.first_triangle) * 3u + slot % 3u] = mc_edge_vertex(d, owner + mc_edge_start_offset(edge), edge / 4u);
    }
}

// SPDX-License-Identifier: MIT
//! Marching cubes, pass 1 of 3. Each invocation takes one 8 x 8 x 4 block of cells (block =
//! global_invocation_id.x + global_invocation_id.y * num_workgroups.x * 64, so more than 65535
//! workgroups use a 2D dispatch), classifies its cells row by row along x (each step loads the
//! 4 voxels of the next x face and reuses the previous face: 36 loads per row of 8 cells, not
//! 64), and writes the sum of their triangle counts to `block_counts[block]`. No barriers and
//! no atomics: one invocation owns each output, so the result is deterministic.
#import marching_cubes

struct McCountParams {
    // The map.
    volume: VolumeDesc,
    // Blocks along x: ceil((dim_x - 1) / MC_BLOCK_CELLS_X) (dense maps).
    n_blocks_x: u32,
    // Blocks along y: ceil((dim_y - 1) / MC_BLOCK_CELLS_Y).
    n_blocks_y: u32,
    // All blocks: n_blocks_x * n_blocks_y * ceil((dim_z - 1) / MC_BLOCK_CELLS_Z), or twice the
    // pool of a sparse map.
    n_blocks: u32,
    _pad0: u32,
}

// Uniform [`McCountParams`].
@group(0) @binding(0) var<uniform> params: McCountParams;
// Voxel words (TSDF + weight).
@group(0) @binding(1) var<storage, read> tsdf_volume: array<u32>;
// [`crate::mesh::mc_table::McTable::packed`].
@group(0) @binding(2) var<storage, read> mc_table: array<u32>;
// Out: triangles per block, `n_blocks` u32.
@group(0) @binding(3) var<storage, read_write> block_counts: array<u32>;
// A sparse map's hash table (map.wgsl); one placeholder word for a dense map.
@group(0) @binding(4) var<storage, read> block_table: array<u32>;
// A sparse map's key per pool block; one placeholder word for a dense map.
@group(0) @binding(5) var<storage, read> block_coords: array<u32>;

@compute @workgroup_size(64, 1, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) n_wg: vec3<u32>) {
    let block_ix = gid.x + gid.y * n_wg.x * 64u;
    if block_ix >= params.n_blocks {
        return;
    }
    let d = params.volume;
    let origin = mc_block_origin(d, block_ix, params.n_blocks_x, params.n_blocks_y);
    let end = min(origin + vec3<u32>(MC_BLOCK_CELLS_X, MC_BLOCK_CELLS_Y, MC_BLOCK_CELLS_Z), vec3<u32>(d.dim_x, d.dim_y, d.dim_z) - vec3<u32>(1u));
    var n_triangles = 0u;
    for (var z = origin.z; z < end.z; z++) {
        for (var y = origin.y; y < end.y; y++) {
            // Flags of the 4 voxels of the current x face, corner (dy, dz) in bits 4 * (dy + 2 dz).
            var face = 0u;
            for (var k = 0u; k < 4u; k++) {
                face |= mc_voxel_flags(map_word(d, origin.x, y + (k & 1u), z + (k >> 1u))) << (4u * k);
            }
            for (var x = origin.x; x < end.x; x++) {
                var next = 0u;
                for (var k = 0u; k < 4u; k++) {
                    next |= mc_voxel_flags(map_word(d, x + 1u, y + (k & 1u), z + (k >> 1u))) << (4u * k);
                }
                // Corner c = dx + 2 dy + 4 dz: dx = 0 from `face`, dx = 1 from `next`.
                var corner_flags = 0u;
                for (var k = 0u; k < 4u; k++) {
                    corner_flags |= ((face >> (4u * k)) & 15u) << (8u * k);
                    corner_flags |= ((next >> (4u * k)) & 15u) << (8u * k + 4u);
                }
                n_triangles += mc_case_triangle_count(mc_case_from_flags(corner_flags));
                face = next;
            }
        }
    }
    block_counts[block_ix] = n_triangles;
}

// SPDX-License-Identifier: MIT
// Counters of marching-cubes extraction (STYLE lesson 7), written by mc_scan: read back by the
// host, and words 4..7 are the indirect dispatch size of mc_generate. Mirrors McCounters in
// core/src/kernels/mc_scan.rs.

struct McCounters {
    // Triangles the whole volume produces (counted past the output capacity).
    n_triangles: u32,
    // Output capacity, triangles, that mc_scan compared against.
    capacity_triangles: u32,
    // Bitmask of MC_FAILED_* flags.
    failed: u32,
    // Blocks with at least one triangle (listed in `active_blocks`).
    n_active_blocks: u32,
    // Workgroups of mc_generate (one per active block; 2D past the per-dimension limit;
    // 0 x 1 x 1 without triangles). Byte offset 16: the indirect dispatch arguments.
    generate_workgroups_x: u32,
    // Workgroups of `mc_generate` along y.
    generate_workgroups_y: u32,
    // Workgroups of `mc_generate` along z (1).
    generate_workgroups_z: u32,
    _pad0: u32,
}

// n_triangles > capacity_triangles: the output holds only part of the mesh.
const MC_FAILED_OUTPUT: u32 = 1u;
// Entry of `active_blocks` past the active ones, up to the padded 2D dispatch size.
const MC_NO_BLOCK: u32 = 0xffffffffu;

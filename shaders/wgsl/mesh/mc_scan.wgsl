// SPDX-License-Identifier: MIT
//! Marching cubes, pass 2 of 3. One workgroup of 256 invocations turns the per-block triangle
//! counts into exclusive offsets and lists the blocks that have triangles: invocation i takes
//! the contiguous segment [i * seg, (i + 1) * seg) of `block_counts` (seg = ceil(n_blocks /
//! 256)), sums its triangles and non-empty blocks, the workgroup scans both sums, and each
//! invocation writes its segment's running triangle offsets to `block_offsets` and its
//! non-empty blocks, in block order, to `active_blocks`. The list is padded with MC_NO_BLOCK to
//! the 2D dispatch size of mc_generate, which invocation 0 writes with the grand total, the
//! active count and the overflow flag to `counters`. Integer sums only: deterministic.
#import mc_counters
#import workgroup_scan

struct McScanParams {
    // Blocks of cells.
    n_blocks: u32,
    // Triangles the output buffer holds; more sets MC_FAILED_OUTPUT.
    capacity_triangles: u32,
    // The device's limit on workgroups per dispatch dimension (for mc_generate's dispatch).
    max_workgroups_per_dimension: u32,
    _pad0: u32,
}

// Uniform [`McScanParams`].
@group(0) @binding(0) var<uniform> params: McScanParams;
// Triangles per block (from `mc_count`).
@group(0) @binding(1) var<storage, read> block_counts: array<u32>;
// Out: first triangle of each block.
@group(0) @binding(2) var<storage, read_write> block_offsets: array<u32>;
// Out: the blocks with triangles, in order, padded with [`MC_NO_BLOCK`] ([`crate::kernels::mc_count::McGrid::active_blocks_len`] entries).
@group(0) @binding(3) var<storage, read_write> active_blocks: array<u32>;
// Out: [`McCounters`]; needs `INDIRECT` usage to drive `mc_generate`.
@group(0) @binding(4) var<storage, read_write> counters: McCounters;

@compute @workgroup_size(256, 1, 1)
fn main(@builtin(local_invocation_index) local_ix: u32) {
    let n = params.n_blocks;
    let seg = (n + SCAN_WG_SIZE - 1u) / SCAN_WG_SIZE;
    let begin = min(local_ix * seg, n);
    let end = min(begin + seg, n);
    var n_triangles = 0u;
    var n_active = 0u;
    for (var i = begin; i < end; i++) {
        let c = block_counts[i];
        n_triangles += c;
        n_active += u32(c != 0u);
    }
    let triangle_scan = wg_exclusive_scan(local_ix, n_triangles);
    let active_scan = wg_exclusive_scan(local_ix, n_active);
    var running = triangle_scan.exclusive;
    var slot = active_scan.exclusive;
    for (var i = begin; i < end; i++) {
        let c = block_counts[i];
        block_offsets[i] = running;
        running += c;
        if c != 0u {
            active_blocks[slot] = i;
            slot += 1u;
        }
    }
    // One mc_generate workgroup per active block: y rows of at most the limit, x * y - total < y.
    let wg_y = max(1u, (active_scan.total + params.max_workgroups_per_dimension - 1u) / params.max_workgroups_per_dimension);
    let wg_x = (active_scan.total + wg_y - 1u) / wg_y;
    for (var i = active_scan.total + local_ix; i < wg_x * wg_y; i += SCAN_WG_SIZE) {
        active_blocks[i] = MC_NO_BLOCK;
    }
    if local_ix == 0u {
        counters.n_triangles = triangle_scan.total;
        counters.capacity_triangles = params.capacity_triangles;
        counters.failed = select(0u, MC_FAILED_OUTPUT, triangle_scan.total > params.capacity_triangles);
        counters.n_active_blocks = active_scan.total;
        counters.generate_workgroups_x = wg_x;
        counters.generate_workgroups_y = wg_y;
        counters.generate_workgroups_z = 1u;
        counters._pad0 = 0u;
    }
}

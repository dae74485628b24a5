// SPDX-License-Identifier: MIT
//! Seed 003's parallel quadtree decimation (its Algorithm 4, §4.4 step 5), in its two phases
//! of 16 x 16 tiles in workgroup memory. A grid of cells (covered or not) becomes quads: a
//! cell's degree is the side, in cells, of the quad whose first (lowest x, lowest y) cell it
//! is, or -1 for none (not covered, or inside a larger quad). Each step merges four quads of
//! side `step` filling an aligned 2·step block into one; every invocation reads its block's
//! four corners, the workgroup syncs, then writes (003's printed version races).
//!
//! - Phase 0: one invocation per cell, a workgroup per 16 x 16 tile: covered cells are unit
//!   quads, merged up to 16 x 16; writes every cell's degree.
//! - Phase 1: one invocation per 16 x 16 block (the 16x-subsampled grid), a workgroup per 16
//!   x 16 blocks: a block whose first cell has degree 16 is a unit quad of this grid; merged
//!   up to 16 x 16 blocks (256 cells, 003's largest quad); rewrites the first cell of every
//!   full block (its new degree, or -1 when a larger quad took it).
//!
//! Tiles start at multiples of 16 (of 256 in phase 1), so the blocks are aligned as if the
//! whole grid were merged at once. Mirrors core/src/cpu/planes/quadtree_decimate.rs.

struct QuadtreeDecimateParams {
    // Cells along x and y.
    width: u32,
    height: u32,
    // 0 or 1, see above.
    phase: u32,
    _pad0: u32,
}

@group(0) @binding(0) var<uniform> params: QuadtreeDecimateParams;
// Per cell, non-zero when covered (phase 0 only).
@group(0) @binding(1) var<storage, read> covered: array<u32>;
// Per cell its degree: written in phase 0, updated in phase 1.
@group(0) @binding(2) var<storage, read_write> degrees: array<i32>;

const TILE: u32 = 16u;

var<workgroup> tile: array<i32, 256>;
var<workgroup> merge: array<u32, 256>;

@compute @workgroup_size(16, 16, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(local_invocation_id) lid: vec3<u32>) {
    // The cell this invocation stands for: itself (phase 0) or its block's first (phase 1).
    let scale = select(1u, TILE, params.phase == 1u);
    let cx = gid.x * scale;
    let cy = gid.y * scale;
    let inside = cx < params.width && cy < params.height;
    let cell = cy * params.width + cx;
    let l = lid.y * TILE + lid.x;
    var start = -1;
    if inside {
        if params.phase == 0u {
            start = select(-1, 1, covered[cell] != 0u);
        } else {
            start = select(-1, 1, degrees[cell] == i32(TILE));
        }
    }
    tile[l] = start;
    for (var step = 1u; step < TILE; step *= 2u) {
        workgroupBarrier();
        // Read: is this the first of four quads of side `step` filling a 2·step block?
        var m = 0u;
        if lid.x % (2u * step) == 0u && lid.y % (2u * step) == 0u {
            let s = i32(step);
            let right = tile[l + step];
            let below = tile[l + step * TILE];
            let diagonal = tile[l + step * TILE + step];
            m = u32(tile[l] == s && right == s && below == s && diagonal == s);
        }
        merge[l] = m;
        workgroupBarrier();
        // Write.
        if merge[l] != 0u {
            tile[l] = i32(2u * step);
            tile[l + step] = -1;
            tile[l + step * TILE] = -1;
            tile[l + step * TILE + step] = -1;
        }
    }
    workgroupBarrier();
    if !inside {
        return;
    }
    if params.phase == 0u {
        degrees[cell] = tile[l];
    } else if start == 1 {
        // A full block: its merged degree in cells, or -1 inside a larger quad.
        degrees[cell] = select(-1, tile[l] * i32(TILE), tile[l] > 0);
    }
}

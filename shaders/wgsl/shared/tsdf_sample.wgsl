// SPDX-License-Identifier: MIT
// Trilinear sampling of a map of either kind, bound as the module-scope `tsdf_volume` and
// `block_table` (declared by the importing kernel, see map_lookup.wgsl). Mirrors
// core/src/cpu/shared.rs::sample_tsdf.
#import map_lookup

struct TsdfSample {
    // Interpolated TSDF, truncation units.
    tsdf: f32,
    // False if any of the 8 voxels around the point was never observed or lies outside.
    valid: bool,
}

// TSDF at a world point, trilinearly interpolated between the 8 surrounding voxel centres:
// the 8 words are read (at fixed offsets in a dense box; in a sparse map with one lookup per
// block they lie in) and blended by x, then y, then z.
fn sample_tsdf(d: VolumeDesc, p_world: vec3<f32>) -> TsdfSample {
    // Voxel coordinates relative to the anchor (small near the first camera, so the fractions
    // keep f32's precision), then the anchor added as an integer.
    let g = (p_world - vec3<f32>(d.origin_x_m, d.origin_y_m, d.origin_z_m)) / d.voxel_size_m - vec3<f32>(0.5);
    let base_rel = floor(g);
    let anchor = vec3<f32>(voxel_anchor(d));
    let base_f = base_rel + anchor;
    var out: TsdfSample;
    out.tsdf = 0.0;
    out.valid = false;
    if base_f.x < 0.0 || base_f.y < 0.0 || base_f.z < 0.0 || base_f.x >= f32(d.dim_x - 1u) || base_f.y >= f32(d.dim_y - 1u) || base_f.z >= f32(d.dim_z - 1u) {
        return out;
    }
    let b = vec3<u32>(base_f);
    let f = g - base_rel;
    // Corner c of the cell is voxel b + (c & 1, (c >> 1) & 1, c >> 2); a corner's word stays 0
    // (never observed) where a sparse map has no block.
    var w000 = 0u;
    var w100 = 0u;
    var w010 = 0u;
    var w110 = 0u;
    var w001 = 0u;
    var w101 = 0u;
    var w011 = 0u;
    var w111 = 0u;
    if !map_is_sparse(d) {
        // The 8 words at fixed offsets from the first, along rows and slices of the box.
        let s = voxel_index(d, b.x, b.y, b.z);
        let row = d.dim_x;
        let slice = d.dim_x * d.dim_y;
        w000 = tsdf_volume[s];
        w100 = tsdf_volume[s + 1u];
        w010 = tsdf_volume[s + row];
        w110 = tsdf_volume[s + row + 1u];
        w001 = tsdf_volume[s + slice];
        w101 = tsdf_volume[s + slice + 1u];
        w011 = tsdf_volume[s + slice + row];
        w111 = tsdf_volume[s + slice + row + 1u];
    } else {
        // A sparse map: the 8 voxels lie in one block (343 of 512 positions), or in 2, 4 or 8
        // when the base voxel is its block's last along 1, 2 or 3 axes (the bits of
        // `crossing`). One pass per block they lie in, each with one lookup: `sub` runs over
        // the subsets of `crossing` (the pass's block is the base block plus those axes), and
        // the corners c with c & crossing == sub read their words in it. One code path for
        // every case keeps the loop body small: a CPU adapter runs 8 invocations in lockstep,
        // so a path any of them takes costs all of them.
        let last = (b & vec3<u32>(7u)) == vec3<u32>(7u);
        let crossing = select(0u, 1u, last.x) | select(0u, 2u, last.y) | select(0u, 4u, last.z);
        let base_block = b >> vec3<u32>(BRICK_SHIFT);
        var sub = 0u;
        loop {
            let block = find_block(d, base_block + vec3<u32>(sub & 1u, (sub >> 1u) & 1u, sub >> 2u));
            if block != NO_BLOCK {
                // voxel_in_block wraps a corner past the block's last voxel to the next block's 0.
                let first = block * BLOCK_VOXELS;
                w000 = select(w000, tsdf_volume[first + voxel_in_block(b.x, b.y, b.z)], (0u & crossing) == sub);
                w100 = select(w100, tsdf_volume[first + voxel_in_block(b.x + 1u, b.y, b.z)], (1u & crossing) == sub);
                w010 = select(w010, tsdf_volume[first + voxel_in_block(b.x, b.y + 1u, b.z)], (2u & crossing) == sub);
                w110 = select(w110, tsdf_volume[first + voxel_in_block(b.x + 1u, b.y + 1u, b.z)], (3u & crossing) == sub);
                w001 = select(w001, tsdf_volume[first + voxel_in_block(b.x, b.y, b.z + 1u)], (4u & crossing) == sub);
                w101 = select(w101, tsdf_volume[first + voxel_in_block(b.x + 1u, b.y, b.z + 1u)], (5u & crossing) == sub);
                w011 = select(w011, tsdf_volume[first + voxel_in_block(b.x, b.y + 1u, b.z + 1u)], (6u & crossing) == sub);
                w111 = select(w111, tsdf_volume[first + voxel_in_block(b.x + 1u, b.y + 1u, b.z + 1u)], (7u & crossing) == sub);
            }
            // The next subset of `crossing` in increasing order; back at 0 after the last.
            sub = (sub - crossing) & crossing;
            if sub == 0u {
                break;
            }
        }
    }
    // A weight of 0 (never observed) has all high bits 0.
    let observed = min(min(min(w000, w100), min(w010, w110)), min(min(w001, w101), min(w011, w111))) >= 0x10000u;
    let x00 = mix(voxel_tsdf(w000), voxel_tsdf(w100), f.x);
    let x10 = mix(voxel_tsdf(w010), voxel_tsdf(w110), f.x);
    let x01 = mix(voxel_tsdf(w001), voxel_tsdf(w101), f.x);
    let x11 = mix(voxel_tsdf(w011), voxel_tsdf(w111), f.x);
    out.tsdf = mix(mix(x00, x10, f.y), mix(x01, x11, f.y), f.z);
    out.valid = observed;
    return out;
}

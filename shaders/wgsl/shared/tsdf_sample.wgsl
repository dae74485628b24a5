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
// the 8 words are read (at fixed offsets in a dense box or within one sparse block, else one
// lookup each) and blended by x, then y, then z.
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
    var w000: u32;
    var w100: u32;
    var w010: u32;
    var w110: u32;
    var w001: u32;
    var w101: u32;
    var w011: u32;
    var w111: u32;
    let one_block = d.kind == MAP_SPARSE && all((b & vec3<u32>(7u)) < vec3<u32>(7u));
    if d.kind == MAP_DENSE || one_block {
        // The 8 words at fixed offsets from the first: rows of the dense box, or (the 8 voxels
        // in one block, 343 of 512 positions) rows of that block, found with one lookup.
        var s = 0u;
        var row = 0u;
        var slice = 0u;
        if d.kind == MAP_DENSE {
            s = voxel_index(d, b.x, b.y, b.z);
            row = d.dim_x;
            slice = d.dim_x * d.dim_y;
        } else {
            let block = find_block(d, b >> vec3<u32>(BRICK_SHIFT));
            if block == NO_BLOCK {
                return out;
            }
            s = block * BLOCK_VOXELS + voxel_in_block(b.x, b.y, b.z);
            row = 8u;
            slice = 64u;
        }
        w000 = tsdf_volume[s];
        w100 = tsdf_volume[s + 1u];
        w010 = tsdf_volume[s + row];
        w110 = tsdf_volume[s + row + 1u];
        w001 = tsdf_volume[s + slice];
        w101 = tsdf_volume[s + slice + 1u];
        w011 = tsdf_volume[s + slice + row];
        w111 = tsdf_volume[s + slice + row + 1u];
    } else {
        // A sparse sample across blocks: each corner looked up (one loop, so the lookup's
        // probe loop is compiled once).
        var w: array<u32, 8>;
        for (var c = 0u; c < 8u; c++) {
            w[c] = map_word(d, b.x + (c & 1u), b.y + ((c >> 1u) & 1u), b.z + (c >> 2u));
        }
        w000 = w[0];
        w100 = w[1];
        w010 = w[2];
        w110 = w[3];
        w001 = w[4];
        w101 = w[5];
        w011 = w[6];
        w111 = w[7];
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

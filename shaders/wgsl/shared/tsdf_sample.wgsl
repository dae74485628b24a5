// SPDX-License-Identifier: MIT
// Trilinear sampling of the TSDF volume bound as the module-scope `tsdf_volume` (declared by
// the importing kernel, with `params.volume` its description). Mirrors
// core/src/cpu/shared.rs::{sample_tsdf, tsdf_gradient}.
#import tsdf

struct TsdfSample {
    // Interpolated TSDF, truncation units.
    tsdf: f32,
    // False if any of the 8 voxels around the point was never observed or lies outside.
    valid: bool,
}

// TSDF at a world point, trilinearly interpolated between the 8 surrounding voxel centres.
fn sample_tsdf(d: VolumeDesc, p_world: vec3<f32>) -> TsdfSample {
    let g = (p_world - vec3<f32>(d.origin_x_m, d.origin_y_m, d.origin_z_m)) / d.voxel_size_m - vec3<f32>(0.5);
    let base_f = floor(g);
    var out: TsdfSample;
    out.tsdf = 0.0;
    out.valid = false;
    if base_f.x < 0.0 || base_f.y < 0.0 || base_f.z < 0.0 || base_f.x >= f32(d.dim_x - 1u) || base_f.y >= f32(d.dim_y - 1u) || base_f.z >= f32(d.dim_z - 1u) {
        return out;
    }
    let b = vec3<u32>(base_f);
    let f = g - base_f;
    var acc = 0.0;
    for (var corner = 0u; corner < 8u; corner++) {
        let o = vec3<u32>(corner & 1u, (corner >> 1u) & 1u, (corner >> 2u) & 1u);
        let word = tsdf_volume[voxel_index(d, b.x + o.x, b.y + o.y, b.z + o.z)];
        if voxel_weight(word) == 0u {
            return out;
        }
        let wx = select(1.0 - f.x, f.x, o.x == 1u);
        let wy = select(1.0 - f.y, f.y, o.y == 1u);
        let wz = select(1.0 - f.z, f.z, o.z == 1u);
        acc += wx * wy * wz * voxel_tsdf(word);
    }
    out.tsdf = acc;
    out.valid = true;
    return out;
}

// SPDX-License-Identifier: MIT
//! Each workgroup fuses visible blocks of a sparse map: workgroup w takes the blocks at
//! w, w + n_workgroups, ... of `visible_blocks`, and within a block invocation (x, y) walks its
//! voxel column along z, updating each of the 8 voxels with `integrate_voxel`
//! (shared/tsdf_update.wgsl: the same projective TSDF average, colour and brick mark as the
//! dense map's `tsdf_integrate`; the brick of a sparse voxel is its pool block). Voxels of
//! blocks not in the list are untouched. Nothing is fused when the pose is disabled.
#import tsdf_update
#import map

struct BlockIntegrateParams {
    // The sparse map.
    volume: VolumeDesc,
    // Intrinsics of the depth image.
    intrinsics: Intrinsics,
    // 1 to fuse colour as well.
    color_enabled: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

@group(0) @binding(0) var<uniform> params: BlockIntegrateParams;
// The pose to fuse at (the tracker's, or one the host gives).
@group(0) @binding(1) var<uniform> pose: CameraPose;
// Depth to fuse, metres (NaN: none).
@group(0) @binding(2) var<storage, read> depth_m: array<f32>;
// Colour (r, g, b, 1) in [0, 1].
@group(0) @binding(3) var<storage, read> color: array<vec4<f32>>;
// The voxel pool (TSDF + weight), updated in place.
@group(0) @binding(4) var<storage, read_write> tsdf_volume: array<u32>;
// Colour words of the pool (RGB8), updated in place (one placeholder word when colour is off).
@group(0) @binding(5) var<storage, read_write> color_volume: array<u32>;
// One word per pool block, set to 1 when a voxel in it takes a TSDF below FAR_TSDF.
@group(0) @binding(6) var<storage, read_write> surface_bricks: array<atomic<u32>>;
// The key of each pool block in use.
@group(0) @binding(7) var<storage, read> block_coords: array<u32>;
// The pool indices of this frame's visible blocks.
@group(0) @binding(8) var<storage, read> visible_blocks: array<u32>;
// The map's counters (map.wgsl): MAP_COUNTER_VISIBLE is the list's length.
@group(0) @binding(9) var<storage, read> map_counters: array<u32>;

@compute @workgroup_size(8, 8, 1)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) n_wg: vec3<u32>, @builtin(local_invocation_id) lid: vec3<u32>) {
    if pose.enabled == 0u {
        return;
    }
    let d = params.volume;
    let n = map_counters[MAP_COUNTER_VISIBLE];
    for (var i = wg.x; i < n; i += n_wg.x) {
        let block = visible_blocks[i];
        let b = block_of_key(block_coords[block]) << vec3<u32>(BRICK_SHIFT);
        let x = b.x + lid.x;
        let y = b.y + lid.y;
        for (var dz = 0u; dz < 8u; dz++) {
            let z = b.z + dz;
            integrate_voxel(d, voxel_centre_in_world(d, x, y, z), block * BLOCK_VOXELS + voxel_in_block(x, y, z), block);
        }
    }
}

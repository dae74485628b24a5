// SPDX-License-Identifier: MIT
//! Each invocation takes one tile of `tile_px` x `tile_px` pixels of the depth a sparse map
//! fuses (metres, NaN: none; the tiles of the last column and row are cut at the image's edge)
//! and writes the largest valid depth in it to `tile_max_m`, or NO_DEPTH_TILE when it has none.
//! `block_visible` bounds what the pixels a block projects onto can measure with these: a block
//! wholly farther than that depth and its truncation band takes no update.
#import invalid
#import map

struct DepthTileMaxParams {
    // The depth image, pixels.
    width_px: u32,
    height_px: u32,
    // Tile edge, pixels.
    tile_px: u32,
    // Tiles along x and y: ceil(width / tile) and ceil(height / tile).
    tiles_x: u32,
    tiles_y: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

@group(0) @binding(0) var<uniform> params: DepthTileMaxParams;
// Depth, metres, row-major (NaN: no measurement).
@group(0) @binding(1) var<storage, read> depth_m: array<f32>;
// Out: per tile (x fastest), the largest valid depth, metres, or NO_DEPTH_TILE.
@group(0) @binding(2) var<storage, read_write> tile_max_m: array<f32>;

@compute @workgroup_size(64, 1, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let p = params;
    let tile = gid.x;
    if tile >= p.tiles_x * p.tiles_y {
        return;
    }
    let x0 = (tile % p.tiles_x) * p.tile_px;
    let y0 = (tile / p.tiles_x) * p.tile_px;
    let x1 = min(x0 + p.tile_px, p.width_px);
    let y1 = min(y0 + p.tile_px, p.height_px);
    var deepest = NO_DEPTH_TILE;
    for (var y = y0; y < y1; y++) {
        for (var x = x0; x < x1; x++) {
            let d = depth_m[y * p.width_px + x];
            if is_valid_f32(d) {
                deepest = max(deepest, d);
            }
        }
    }
    tile_max_m[tile] = deepest;
}

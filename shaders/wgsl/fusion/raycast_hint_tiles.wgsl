// SPDX-License-Identifier: MIT
//! Each invocation looks at one tile of the depth-range image of a prediction that has a depth
//! hint (`raycast`'s `use_depth_hint`), after the tiles were cleared and before `raycast_range`
//! widens them. A ray with a hint searches only around it and never reads its tile's interval,
//! so when every pixel of the tile has a hint (its own measured depth or one 2 or 4 pixels away,
//! as `depth_hint_range` finds) the tile's far word is set to TILE_UNUSED and `raycast_range`
//! spends no atomics on it. A tile with a pixel without a hint is left cleared and widened as
//! usual. On Kinect frames most tiles are hinted throughout, and the atomics for surface
//! bricks that cover many tiles were most of `raycast_range`'s time.
#import depth_hint

struct RaycastHintTilesParams {
    // Intrinsics of the rendered images.
    intrinsics: Intrinsics,
    // Pixels along each edge of a tile.
    tile_px: u32,
    // Tiles along x.
    tiles_x: u32,
    // Tiles along y.
    tiles_y: u32,
    // Metres per raw unit of `depth_hint_raw`.
    hint_metres_per_unit: f32,
}

// A tile's far word when no ray of the tile reads it (no depth is stored with all bits set).
const TILE_UNUSED: u32 = 0xffffffffu;

@group(0) @binding(0) var<uniform> params: RaycastHintTilesParams;
// The raw sensor depth at each pixel (u16 units, two per word, low half first; 0: no return).
@group(0) @binding(1) var<storage, read> depth_hint_raw: array<u32>;
// The depth-range tiles (cleared before): !bits(nearest z), bits(farthest z) per tile.
@group(0) @binding(2) var<storage, read_write> depth_range_tiles: array<u32>;

@compute @workgroup_size(8, 8, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    if gid.x >= params.tiles_x || gid.y >= params.tiles_y {
        return;
    }
    let k = params.intrinsics;
    let x0 = gid.x * params.tile_px;
    let y0 = gid.y * params.tile_px;
    let x1 = min(x0 + params.tile_px, k.width_px);
    let y1 = min(y0 + params.tile_px, k.height_px);
    for (var y = y0; y < y1; y++) {
        for (var x = x0; x < x1; x++) {
            if !is_valid_f32(depth_hint_range(vec2<u32>(x, y)).x) {
                return;
            }
        }
    }
    depth_range_tiles[2u * (gid.y * params.tiles_x + gid.x) + 1u] = TILE_UNUSED;
}

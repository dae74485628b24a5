// SPDX-License-Identifier: MIT
// The sparse map's addressing (voxel-block hashing, Nießner et al. 2013; InfiniTAM): the box of
// a sparse `VolumeDesc` is tiled into blocks of 8³ voxels (BRICK_SHIFT), and only blocks near a
// measured surface are stored, each as 512 consecutive voxel words of a bounded pool (x fastest,
// then y, then z within the block). A hash table maps a block's key to its pool index: slot s
// holds two words, the key at 2s and the pool index at 2s + 1, found by linear probing from
// block_hash(key) over at most MAP_MAX_PROBES slots. Keys pack the block coordinates in 11, 11
// and 10 bits, so a sparse box spans at most 2048 x 2048 x 1023 blocks (1023: the all-ones key is
// EMPTY_KEY). Mirrors core/src/cpu/shared.rs and core/src/map/.
#import tsdf

// Voxels per block.
const BLOCK_VOXELS: u32 = 512u;
// The key of a free hash slot.
const EMPTY_KEY: u32 = 0xffffffffu;
// The pool index of a key that has no block (yet: the pool was full when it was inserted).
const NO_BLOCK: u32 = 0xffffffffu;
// The pool index of a key whose block was swapped out to host memory (InfiniTAM's swapping,
// `block_swap_out`): the key stays in the table, so allocation gives it no fresh block, and it
// reads as unobserved until `block_swap_in` brings its voxels back.
const SWAPPED_BLOCK: u32 = 0xfffffffeu;
// The voxel slot of a voxel whose block is not allocated.
const NO_SLOT: u32 = 0xffffffffu;
// Most slots a lookup or an insertion visits: with the table at most half full, linear probing
// visits 2.5 slots on average for a miss; a key not found within this many is treated as absent
// (a lookup) or counted as a failed insertion (MAP_COUNTER_HASH_FULL).
const MAP_MAX_PROBES: u32 = 64u;

// A tile of `depth_tile_max` without a valid depth (valid depths are positive).
const NO_DEPTH_TILE: f32 = -1.0;

// Words of the map's counters buffer (`map_counters`), read back by the host each frame.
// Pool blocks ever handed out by bump allocation (never more than `pool_blocks`): blocks
// 0..this are in use or on the free list (MAP_COUNTER_FREE of them).
const MAP_COUNTER_BLOCKS_USED: u32 = 0u;
// Blocks in this frame's visible list (cleared before each frame's `block_visible`).
const MAP_COUNTER_VISIBLE: u32 = 1u;
// Block insertions that found no free slot within MAP_MAX_PROBES (cumulative).
const MAP_COUNTER_HASH_FULL: u32 = 2u;
// Inserted keys left without a block because the pool was full (cumulative, once per key and
// frame).
const MAP_COUNTER_POOL_FULL: u32 = 3u;
// Surface samples outside the sparse box, not allocated (cumulative).
const MAP_COUNTER_OUT_OF_RANGE: u32 = 4u;
// Words 5..7: the indirect dispatch size of `block_integrate` (written by `block_list_args`).
const MAP_COUNTER_ARGS: u32 = 5u;
// Pool blocks on the free list (`free_blocks[0..this]`: blocks swapped out, cleared, ready to
// be handed out again before the bump allocation grows).
const MAP_COUNTER_FREE: u32 = 8u;
// Blocks the last `block_swap_out` wrote to the transfer list (the host clears it before).
const MAP_COUNTER_SWAPPED_OUT: u32 = 9u;
// Blocks `block_swap_in` could not bring back for want of pool (cumulative; they stay swapped
// out, the host keeps their voxels).
const MAP_COUNTER_SWAP_IN_REFUSED: u32 = 10u;
// Band blocks a frame needed while they were swapped out, so not fused there (cumulative, once
// per pixel and block: the host swaps in ahead of the camera, so this should stay 0).
const MAP_COUNTER_SWAPPED_HITS: u32 = 11u;
// Words of the counters buffer.
const MAP_COUNTERS: u32 = 12u;

fn block_key(b: vec3<u32>) -> u32 {
    return b.x | (b.y << 11u) | (b.z << 22u);
}

fn block_of_key(key: u32) -> vec3<u32> {
    return vec3<u32>(key & 0x7ffu, (key >> 11u) & 0x7ffu, key >> 22u);
}

// The home slot of a block (before masking): the spatial hash of Teschner et al. 2003 (the one
// voxel hashing uses) on the block coordinates, then a xor-shift-multiply finaliser so that
// the low bits a power-of-two table keeps depend on every input bit.
fn block_hash(b: vec3<u32>) -> u32 {
    var h = (b.x * 73856093u) ^ (b.y * 19349663u) ^ (b.z * 83492791u);
    h ^= h >> 16u;
    h *= 0x45d9f3bu;
    h ^= h >> 16u;
    return h;
}

// Index of voxel (x, y, z) within its block.
fn voxel_in_block(x: u32, y: u32, z: u32) -> u32 {
    return (x & 7u) | ((y & 7u) << 3u) | ((z & 7u) << 6u);
}

// SPDX-License-Identifier: MIT
// Reading a map of either kind: the importing kernel declares `block_table: array<u32>` (the
// sparse map's hash table; a placeholder word for a dense map) and `tsdf_volume: array<u32>`
// (the voxel words: the dense box, or the sparse pool). Voxel coordinates must lie in the
// box (0 <= x < dim_x, ...). Mirrors core/src/cpu/shared.rs::{find_block, voxel_slot, map_word}.
#import map

// The last block this invocation found: a ray or a sample visits the same block many times in
// a row, and a comparison is cheaper than a probe (a memo of a pure function: results do not
// depend on it, so the CPU twins need none).
var<private> cached_key: u32 = EMPTY_KEY;
var<private> cached_block: u32 = NO_BLOCK;

// Pool index of the block at block coordinates `b`, or NO_BLOCK.
fn find_block(d: VolumeDesc, b: vec3<u32>) -> u32 {
    let key = block_key(b);
    if key == cached_key {
        return cached_block;
    }
    cached_key = key;
    cached_block = probe_block(d, b, key);
    return cached_block;
}

// Pool index of the block at `b` (whose key is `key`) by probing the table, or NO_BLOCK (absent,
// refused a block, or swapped out).
fn probe_block(d: VolumeDesc, b: vec3<u32>, key: u32) -> u32 {
    let s = find_slot(d, b, key);
    if s == NO_SLOT {
        return NO_BLOCK;
    }
    let block = block_table[2u * s + 1u];
    return select(block, NO_BLOCK, block == SWAPPED_BLOCK);
}

// The hash slot holding block `b`'s key (`key`), or NO_SLOT when it is not in the table.
fn find_slot(d: VolumeDesc, b: vec3<u32>, key: u32) -> u32 {
    let mask = d.hash_slots - 1u;
    var s = block_hash(b) & mask;
    for (var i = 0u; i < MAP_MAX_PROBES; i++) {
        let k = block_table[2u * s];
        if k == key {
            return s;
        }
        if k == EMPTY_KEY {
            return NO_SLOT;
        }
        s = (s + 1u) & mask;
    }
    return NO_SLOT;
}

// Index of voxel (x, y, z) in `tsdf_volume` (and the colour words), or NO_SLOT where a sparse
// map has no block.
fn voxel_slot(d: VolumeDesc, x: u32, y: u32, z: u32) -> u32 {
    if !map_is_sparse(d) {
        return voxel_index(d, x, y, z);
    }
    let block = find_block(d, vec3<u32>(x, y, z) >> vec3<u32>(BRICK_SHIFT));
    if block == NO_BLOCK {
        return NO_SLOT;
    }
    return block * BLOCK_VOXELS + voxel_in_block(x, y, z);
}

// The voxel word of (x, y, z): 0 (never observed) where a sparse map has no block.
fn map_word(d: VolumeDesc, x: u32, y: u32, z: u32) -> u32 {
    let s = voxel_slot(d, x, y, z);
    if s == NO_SLOT {
        return 0u;
    }
    return tsdf_volume[s];
}

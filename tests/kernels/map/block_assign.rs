// SPDX-License-Identifier: MIT
//! `block_assign`: every key of a real frame's table gets its own pool block, recorded in
//! `block_coords`, and the count matches the twin's; keys that already have a block keep it;
//! with a pool smaller than the frame, exactly the pool is handed out, the rest are counted as
//! refused and left without a block (never an index past the pool), as in the twin.

use std::collections::BTreeSet;

use webfusion_core::cpu::{self, shared::{MAP_COUNTER_BLOCKS_USED, MAP_COUNTER_FREE, MAP_COUNTER_POOL_FULL, MAP_COUNTERS, NO_BLOCK}};
use webfusion_core::kernels::block_assign::BlockAssignParams;
use webfusion_core::tsdf::VolumeDesc;
use webfusion_tests::{Slot, cast, finish, gpu, run_kernel_slots};

use super::scene::{POOL_BLOCKS, alloc_params, assignments, camera_pose, empty_table, frame, keys, poses, sparse_desc};

/// GPU (table, coords, counters) after one assignment.
fn run(desc: &VolumeDesc, table: &[u32], coords: &[u32], counters: &[u32]) -> (Vec<u32>, Vec<u32>, Vec<u32>) {
    run_with_free(desc, table, coords, counters, &[0])
}

/// GPU (table, coords, counters) after one assignment with a free list.
fn run_with_free(desc: &VolumeDesc, table: &[u32], coords: &[u32], counters: &[u32], free: &[u32]) -> (Vec<u32>, Vec<u32>, Vec<u32>) {
    let gpu = gpu();
    let slots = [Slot::InOut(bytemuck::cast_slice(table)), Slot::InOut(bytemuck::cast_slice(coords)), Slot::InOut(bytemuck::cast_slice(counters)), Slot::In(bytemuck::cast_slice(free))];
    let out = run_kernel_slots(&gpu, &gpu.kernels.block_assign, &BlockAssignParams { volume: *desc }, &slots, [desc.hash_slots, 1, 1]);
    finish(&gpu);
    (cast(&out[0]), cast(&out[1]), cast(&out[2]))
}

/// The frame's table before assignment.
fn allocated(desc: &VolumeDesc) -> Vec<u32> {
    let (k, depth) = frame();
    let (mut table, mut counters) = empty_table(desc);
    cpu::block_alloc(&alloc_params(*desc, k), &camera_pose(&poses()[0]), depth, &mut table, &mut counters);
    table
}

/// Checks a table after assignment: `expected` keys have distinct blocks below the pool, each
/// recorded in `coords`, and the other keys have none.
fn check(desc: &VolumeDesc, table: &[u32], coords: &[u32], expected: usize) -> Result<(), String> {
    let a = assignments(table);
    if a.len() != expected {
        return Err(format!("{} keys have blocks, expected {expected}", a.len()));
    }
    let blocks: BTreeSet<u32> = a.values().copied().collect();
    if blocks.len() != a.len() {
        return Err("two keys share a block".into());
    }
    if let Some(b) = blocks.iter().find(|&&b| b >= desc.pool_blocks) {
        return Err(format!("block {b} lies past the pool of {}", desc.pool_blocks));
    }
    if let Some((k, b)) = a.iter().find(|&(&k, &b)| coords[b as usize] != k) {
        return Err(format!("block {b} records key {:#x}, not {k:#x}", coords[*b as usize]));
    }
    Ok(())
}

#[test]
fn every_key_gets_its_own_block() {
    let desc = sparse_desc(POOL_BLOCKS);
    let table = allocated(&desc);
    let n = keys(&table).len();
    let (coords, counters) = (vec![0u32; desc.pool_blocks as usize], vec![0u32; MAP_COUNTERS]);
    let (g_table, g_coords, g_counters) = run(&desc, &table, &coords, &counters);
    check(&desc, &g_table, &g_coords, n).unwrap_or_else(|e| panic!("GPU: {e}"));
    let (mut c_table, mut c_coords, mut c_counters) = (table.clone(), coords, counters);
    cpu::block_assign(&BlockAssignParams { volume: desc }, &mut c_table, &mut c_coords, &mut c_counters, &[]);
    check(&desc, &c_table, &c_coords, n).unwrap_or_else(|e| panic!("CPU: {e}"));
    assert_eq!(g_counters, c_counters, "counters: GPU vs twin");
    assert_eq!(g_counters[MAP_COUNTER_BLOCKS_USED] as usize, n, "one block per key");
    // Negative controls: a shared block, a block past the pool and a wrong record are caught.
    let first = g_table.chunks(2).position(|s| s[1] != NO_BLOCK).expect("an assigned slot");
    let second = g_table.chunks(2).skip(first + 1).position(|s| s[1] != NO_BLOCK).expect("another") + first + 1;
    let mut shared = g_table.clone();
    shared[2 * second + 1] = shared[2 * first + 1];
    assert!(check(&desc, &shared, &g_coords, n).is_err(), "a shared block is caught");
    let mut past = g_table.clone();
    past[2 * first + 1] = desc.pool_blocks;
    assert!(check(&desc, &past, &g_coords, n).is_err(), "a block past the pool is caught");
    let mut wrong = g_coords.clone();
    wrong[g_table[2 * first + 1] as usize] ^= 1;
    assert!(check(&desc, &g_table, &wrong, n).is_err(), "a wrong key record is caught");
    // A second assignment changes nothing.
    let (again, again_coords, again_counters) = run(&desc, &g_table, &g_coords, &g_counters);
    assert!(again == g_table && again_coords == g_coords && again_counters == g_counters, "assigned keys keep their blocks");
}

#[test]
fn a_small_pool_hands_out_exactly_itself_and_counts_the_rest() {
    let desc = sparse_desc(100);
    let table = allocated(&desc);
    let n = keys(&table).len();
    assert!(n > 200, "the frame needs more than the pool ({n} blocks)");
    let (coords, counters) = (vec![0u32; 100], vec![0u32; MAP_COUNTERS]);
    let (g_table, g_coords, g_counters) = run(&desc, &table, &coords, &counters);
    check(&desc, &g_table, &g_coords, 100).unwrap_or_else(|e| panic!("GPU: {e}"));
    assert_eq!(g_counters[MAP_COUNTER_BLOCKS_USED], 100, "the counter stops at the pool");
    assert_eq!(g_counters[MAP_COUNTER_POOL_FULL] as usize, n - 100, "every refused key is counted");
    let (mut c_table, mut c_coords, mut c_counters) = (table, coords, counters);
    cpu::block_assign(&BlockAssignParams { volume: desc }, &mut c_table, &mut c_coords, &mut c_counters, &[]);
    assert_eq!(g_counters, c_counters, "counters: GPU vs twin");
}

#[test]
fn the_free_list_is_used_before_the_pool_grows() {
    // 100 blocks were handed out before, 30 of them came back to the free list (swapped out):
    // the frame's keys take those 30 first, each once, then the bump allocation goes on from 100.
    let desc = sparse_desc(POOL_BLOCKS);
    let table = allocated(&desc);
    let n = keys(&table).len();
    let free: Vec<u32> = (0..30).map(|i| 3 * i + 1).collect();
    let mut counters = vec![0u32; MAP_COUNTERS];
    counters[MAP_COUNTER_BLOCKS_USED] = 100;
    counters[MAP_COUNTER_FREE] = free.len() as u32;
    let coords = vec![0u32; desc.pool_blocks as usize];
    let (g_table, g_coords, g_counters) = run_with_free(&desc, &table, &coords, &counters, &free);
    check(&desc, &g_table, &g_coords, n).unwrap_or_else(|e| panic!("GPU: {e}"));
    let (mut c_table, mut c_coords, mut c_counters) = (table, coords, counters);
    cpu::block_assign(&BlockAssignParams { volume: desc }, &mut c_table, &mut c_coords, &mut c_counters, &free);
    check(&desc, &c_table, &c_coords, n).unwrap_or_else(|e| panic!("CPU: {e}"));
    assert_eq!(g_counters, c_counters, "counters: GPU vs twin");
    assert_eq!(g_counters[MAP_COUNTER_FREE], 0, "the free list is used up");
    assert_eq!(g_counters[MAP_COUNTER_BLOCKS_USED] as usize, 100 + n - free.len(), "the bump allocation covers the rest");
    let given: BTreeSet<u32> = assignments(&g_table).into_values().collect();
    let expected: BTreeSet<u32> = free.iter().copied().chain(100..100 + (n - free.len()) as u32).collect();
    assert_eq!(given, expected, "exactly the free blocks and the next bump blocks are handed out");
    // Negative control: an assignment that ignored the free list would hand out other blocks.
    let (ignored_table, _, _) = run(&desc, &allocated(&desc), &vec![0u32; desc.pool_blocks as usize], &{
        let mut c = vec![0u32; MAP_COUNTERS];
        c[MAP_COUNTER_BLOCKS_USED] = 100;
        c
    });
    let ignored: BTreeSet<u32> = assignments(&ignored_table).into_values().collect();
    assert_ne!(ignored, expected, "the set comparison sees a free list that was not used");
}

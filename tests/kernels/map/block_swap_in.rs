// SPDX-License-Identifier: MIT
//! `block_swap_in`: blocks swapped out by `block_swap_out` and handed back in the host's order
//! (reversed) return to the pool with the same contents by key (a full round trip, compared with
//! the map before the swap-out), taking the free list's blocks; the twin agrees. An entry whose
//! key is resident (a stale host copy) is skipped; a pool with no room refuses every entry,
//! counts it and leaves the key swapped out.

use webfusion_core::cpu::{self, shared::{MAP_COUNTER_BLOCKS_USED, MAP_COUNTER_FREE, MAP_COUNTER_POOL_FULL, MAP_COUNTER_SWAP_IN_REFUSED, MAP_COUNTER_SWAPPED_OUT, SWAPPED_BLOCK}};
use webfusion_core::kernels::block_swap_in::BlockSwapInParams;
use webfusion_core::tsdf::VolumeDesc;
use webfusion_tests::{Slot, cast, finish, gpu, run_kernel_slots};

use super::block_swap_out::{listed, params, run_cpu, transfer_words, turned_pose};
use super::scene::{POOL_BLOCKS, PoolState, camera_pose, sparse_desc};

/// A transfer list holding `entries` (key, surface, voxels, colours) in order.
fn transfer_of(capacity: u32, entries: &[(u32, (u32, Vec<u32>, Vec<u32>))]) -> Vec<u32> {
    let c = capacity as usize;
    let mut t = vec![0u32; transfer_words(capacity)];
    for (i, (key, (surface, voxels, colors))) in entries.iter().enumerate() {
        t[i] = *key;
        t[c + i] = *surface;
        t[2 * c + i * 512..2 * c + (i + 1) * 512].copy_from_slice(voxels);
        t[2 * c + c * 512 + i * 512..2 * c + c * 512 + (i + 1) * 512].copy_from_slice(colors);
    }
    t
}

fn run_gpu(p: &BlockSwapInParams, s: &PoolState, transfer: &[u32]) -> PoolState {
    let gpu = gpu();
    let c = |v: &Vec<u32>| bytemuck::cast_slice::<u32, u8>(v).to_vec();
    let (table, coords, voxels, colors, surface, counters) = (c(&s.table), c(&s.coords), c(&s.voxels), c(&s.colors), c(&s.surface), c(&s.counters));
    let slots = [Slot::InOut(&table), Slot::InOut(&coords), Slot::InOut(&voxels), Slot::InOut(&colors), Slot::InOut(&surface), Slot::InOut(&counters), Slot::In(bytemuck::cast_slice(&s.free)), Slot::In(bytemuck::cast_slice(transfer))];
    let out = run_kernel_slots(&gpu, &gpu.kernels.block_swap_in, p, &slots, [p.capacity, 1, 1]);
    finish(&gpu);
    PoolState { table: cast(&out[0]), coords: cast(&out[1]), voxels: cast(&out[2]), colors: cast(&out[3]), surface: cast(&out[4]), counters: cast(&out[5]), free: s.free.clone() }
}

fn run_cpu_in(p: &BlockSwapInParams, s: &PoolState, transfer: &[u32]) -> PoolState {
    let mut t = s.clone();
    cpu::block_swap_in(p, &mut t.table, &mut t.coords, &mut t.voxels, &mut t.colors, &mut t.surface, &mut t.counters, &s.free, transfer);
    t
}

fn in_params(desc: &VolumeDesc, count: u32, capacity: u32) -> BlockSwapInParams {
    BlockSwapInParams { volume: *desc, count, capacity, color_enabled: 1, ..Default::default() }
}

#[test]
fn swapped_out_blocks_come_back_whole() {
    let desc = sparse_desc(POOL_BLOCKS);
    let before = PoolState::filled(&desc);
    let capacity = 4096;
    let (out, out_list) = run_cpu(&params(&desc, capacity), &camera_pose(&turned_pose()), &before);
    let mut entries: Vec<_> = listed(&out_list, capacity, out.counters[MAP_COUNTER_SWAPPED_OUT]).into_iter().collect();
    entries.reverse();
    let n = entries.len() as u32;
    assert!(n > 100, "the swap-out moved blocks ({n})");
    // One stale entry: a resident block's key with other words, which must be skipped.
    let stale_key = *out.contents().keys().next().expect("a resident block");
    entries.push((stale_key, (7, vec![9; 512], vec![9; 512])));
    let transfer = transfer_of(capacity, &entries);
    let p = in_params(&desc, n + 1, capacity);
    let g = run_gpu(&p, &out, &transfer);
    let c = run_cpu_in(&p, &out, &transfer);
    assert_eq!(g.contents(), before.contents(), "GPU: the map holds what it held before the swap-out");
    assert_eq!(c.contents(), before.contents(), "twin: the same");
    assert_eq!(g.counters, c.counters, "counters: GPU vs twin");
    assert_eq!(g.counters[MAP_COUNTER_FREE], 0, "the free list was used first");
    assert_eq!(g.counters[MAP_COUNTER_BLOCKS_USED], before.counters[MAP_COUNTER_BLOCKS_USED], "the pool did not grow");
    assert!(!g.table.chunks(2).any(|s| s[1] == SWAPPED_BLOCK), "no key is left swapped out");
    // Negative control: the comparison sees one block that did not come back.
    let mut missing = g.clone();
    let slot = missing.table.chunks(2).position(|s| s[0] == entries[0].0).expect("the key's slot");
    missing.table[2 * slot + 1] = SWAPPED_BLOCK;
    assert_ne!(missing.contents(), before.contents(), "a block left out is caught");
}

#[test]
fn a_full_pool_refuses_and_keeps_the_keys_swapped_out() {
    let desc = sparse_desc(POOL_BLOCKS);
    let before = PoolState::filled(&desc);
    let capacity = 4096;
    let (mut out, out_list) = run_cpu(&params(&desc, capacity), &camera_pose(&turned_pose()), &before);
    let entries: Vec<_> = listed(&out_list, capacity, out.counters[MAP_COUNTER_SWAPPED_OUT]).into_iter().collect();
    let n = entries.len() as u32;
    // No free blocks and the bump allocation at the pool's end.
    out.counters[MAP_COUNTER_FREE] = 0;
    out.counters[MAP_COUNTER_BLOCKS_USED] = desc.pool_blocks;
    let p = in_params(&desc, n, capacity);
    let g = run_gpu(&p, &out, &transfer_of(capacity, &entries));
    assert_eq!(g.counters[MAP_COUNTER_SWAP_IN_REFUSED], n, "every entry is refused");
    assert_eq!(g.counters[MAP_COUNTER_POOL_FULL], n, "and counted as the pool being full");
    assert_eq!(g.contents(), out.contents(), "the pool is unchanged");
    assert_eq!(g.table, out.table, "the keys stay swapped out");
    let c = run_cpu_in(&p, &out, &transfer_of(capacity, &entries));
    assert_eq!(g.counters, c.counters, "counters: GPU vs twin");
}

// SPDX-License-Identifier: MIT
//! `block_swap_out`: a real frame's blocks, seen from a camera that turned and moved away, leave
//! the pool exactly when the twin's kept-region test says so: each moved block's key, surface
//! word, voxels and colours arrive in the transfer list (compared by key: GPU order is
//! scheduling-dependent), its pool block is cleared and on the free list, its key stays in the
//! table as SWAPPED_BLOCK, and every kept block is untouched. A list shorter than the candidates
//! takes exactly its capacity; a disabled pose or a zero capacity moves nothing.

use std::collections::BTreeSet;

use glam::{DQuat, DVec3};
use webfusion_core::cpu::{self, map::block_swap_out::{ViewRegion, block_centre}, shared::{EMPTY_KEY, MAP_COUNTER_BLOCKS_USED, MAP_COUNTER_FREE, MAP_COUNTER_SWAPPED_OUT, SWAPPED_BLOCK, block_of_key}};
use webfusion_core::kernels::block_swap_out::{BlockSwapOutParams, CameraPose};
use webfusion_core::tsdf::VolumeDesc;
use webfusion_core::Se3;
use webfusion_tests::{Slot, cast, finish, gpu, run_kernel_slots};

use super::scene::{Contents, POOL_BLOCKS, PoolState, camera_pose, sparse_desc};

/// The kept region of these tests: 0.5 m around the camera, or within 2.5 m in a 40° cone.
const KEEP: ViewRegion = ViewRegion { near_m: 0.5, range_m: 2.5, cos_half_angle: 0.766_044_4 };

pub(crate) fn params(desc: &VolumeDesc, capacity: u32) -> BlockSwapOutParams {
    BlockSwapOutParams { volume: *desc, capacity, color_enabled: 1, keep_near_m: KEEP.near_m, keep_range_m: KEEP.range_m, keep_cos_half_angle: KEEP.cos_half_angle, ..Default::default() }
}

/// Words of a transfer list of `capacity` entries with colour.
pub(crate) fn transfer_words(capacity: u32) -> usize {
    2 * capacity as usize + 2 * 512 * capacity as usize
}

/// A camera 0.3 m to the side of the frame's, turned 50° away from it.
pub(crate) fn turned_pose() -> Se3 {
    Se3::new(DQuat::from_rotation_y(0.87), DVec3::new(0.3, 0.0, 0.2))
}

/// Runs the kernel on the GPU: (state after, transfer list).
pub(crate) fn run_gpu(p: &BlockSwapOutParams, pose: &CameraPose, s: &PoolState) -> (PoolState, Vec<u32>) {
    let gpu = gpu();
    let c = |v: &Vec<u32>| bytemuck::cast_slice::<u32, u8>(v).to_vec();
    let (table, coords, voxels, colors, surface, counters, free) = (c(&s.table), c(&s.coords), c(&s.voxels), c(&s.colors), c(&s.surface), c(&s.counters), c(&s.free));
    let slots = [Slot::In(bytemuck::bytes_of(pose)), Slot::InOut(&table), Slot::InOut(&coords), Slot::InOut(&voxels), Slot::InOut(&colors), Slot::InOut(&surface), Slot::InOut(&counters), Slot::InOut(&free), Slot::Out(4 * transfer_words(p.capacity.max(1)))];
    let out = run_kernel_slots(&gpu, &gpu.kernels.block_swap_out, p, &slots, [p.volume.pool_blocks, 1, 1]);
    finish(&gpu);
    (PoolState { table: cast(&out[0]), coords: cast(&out[1]), voxels: cast(&out[2]), colors: cast(&out[3]), surface: cast(&out[4]), counters: cast(&out[5]), free: cast(&out[6]) }, cast(&out[7]))
}

/// Runs the twin: (state after, transfer list).
pub(crate) fn run_cpu(p: &BlockSwapOutParams, pose: &CameraPose, s: &PoolState) -> (PoolState, Vec<u32>) {
    let mut t = s.clone();
    let mut transfer = vec![0u32; transfer_words(p.capacity.max(1))];
    cpu::block_swap_out(p, pose, &mut t.table, &mut t.coords, &mut t.voxels, &mut t.colors, &mut t.surface, &mut t.counters, &mut t.free, &mut transfer);
    (t, transfer)
}

/// The transfer list's entries by key.
pub(crate) fn listed(transfer: &[u32], capacity: u32, count: u32) -> Contents {
    let c = capacity as usize;
    (0..count as usize).map(|i| (transfer[i], (transfer[c + i], transfer[2 * c + i * 512..2 * c + (i + 1) * 512].to_vec(), transfer[2 * c + c * 512 + i * 512..2 * c + c * 512 + (i + 1) * 512].to_vec()))).collect()
}

/// Checks a swap-out of `before` into (`after`, `transfer`): the listed blocks are exactly
/// `before`'s blocks with their contents, gone from the pool (cleared, freed, swapped in the
/// table), and every other block is untouched. Returns the moved keys.
pub(crate) fn check(before: &PoolState, after: &PoolState, transfer: &[u32], capacity: u32) -> Result<BTreeSet<u32>, String> {
    let count = after.counters[MAP_COUNTER_SWAPPED_OUT];
    if count > capacity {
        return Err(format!("{count} entries listed in a list of {capacity}"));
    }
    let moved = listed(transfer, capacity, count);
    if moved.len() != count as usize {
        return Err("a block is listed twice".into());
    }
    let held = before.contents();
    for (key, contents) in &moved {
        if held.get(key) != Some(contents) {
            return Err(format!("block {:?}: the listed words are not the block's", block_of_key(*key)));
        }
    }
    let now = after.contents();
    for (key, contents) in &held {
        match (moved.contains_key(key), now.get(key)) {
            (true, Some(_)) => return Err(format!("block {:?} was listed and is still in the pool", block_of_key(*key))),
            (false, c) if c != Some(contents) => return Err(format!("block {:?} was kept but changed", block_of_key(*key))),
            _ => {}
        }
    }
    let swapped: BTreeSet<u32> = after.table.chunks(2).filter(|s| s[1] == SWAPPED_BLOCK).map(|s| s[0]).collect();
    if swapped != moved.keys().copied().collect() {
        return Err(format!("{} keys are marked swapped out, {} were listed", swapped.len(), moved.len()));
    }
    let freed: BTreeSet<u32> = after.free[..after.counters[MAP_COUNTER_FREE] as usize].iter().copied().collect();
    let vacated: BTreeSet<u32> = (0..after.counters[MAP_COUNTER_BLOCKS_USED]).filter(|&b| after.coords[b as usize] == EMPTY_KEY).collect();
    if freed.len() != moved.len() || freed != vacated {
        return Err(format!("{} blocks on the free list, {} vacated, {} moved", freed.len(), vacated.len(), moved.len()));
    }
    if let Some(b) = freed.iter().find(|&&b| after.voxels[b as usize * 512..(b as usize + 1) * 512].iter().chain(&after.colors[b as usize * 512..(b as usize + 1) * 512]).any(|&w| w != 0) || after.surface[b as usize] != 0) {
        return Err(format!("freed block {b} was not cleared"));
    }
    Ok(moved.into_keys().collect())
}

/// The keys outside the kept region at `pose`, computed from the block centres.
fn outside(desc: &VolumeDesc, s: &PoolState, pose: &Se3) -> BTreeSet<u32> {
    let camera = pose.translation_m.as_vec3().to_array();
    let axis = (pose.rotation * DVec3::Z).as_vec3().to_array();
    s.contents()
        .into_keys()
        .filter(|&key| {
            let (centre, r) = block_centre(desc, block_of_key(key));
            !KEEP.contains(std::array::from_fn(|i| centre[i] - camera[i]), axis, r)
        })
        .collect()
}

#[test]
fn blocks_outside_the_kept_region_move_to_the_list_whole() {
    let desc = sparse_desc(POOL_BLOCKS);
    let before = PoolState::filled(&desc);
    let pose = turned_pose();
    let expected = outside(&desc, &before, &pose);
    let held = before.contents().len();
    assert!(expected.len() > 100 && expected.len() + 100 < held, "the test moves some blocks and keeps others ({} of {held})", expected.len());
    let p = params(&desc, 4096);
    let (g_after, g_transfer) = run_gpu(&p, &camera_pose(&pose), &before);
    let g = check(&before, &g_after, &g_transfer, 4096).unwrap_or_else(|e| panic!("GPU: {e}"));
    let (c_after, c_transfer) = run_cpu(&p, &camera_pose(&pose), &before);
    let c = check(&before, &c_after, &c_transfer, 4096).unwrap_or_else(|e| panic!("CPU: {e}"));
    assert_eq!(g, expected, "GPU: exactly the blocks outside the kept region move");
    assert_eq!(c, expected, "twin: the same");
    assert_eq!(g_after.contents(), c_after.contents(), "the pools keep the same blocks");
    assert_eq!(g_after.counters, c_after.counters, "counters: GPU vs twin");
    eprintln!("{} of {held} blocks swapped out", g.len());
    // Negative controls: a changed word in the list, a kept block changed, a block not freed.
    let mut bad = g_transfer.clone();
    bad[2 * 4096 + 17] ^= 1;
    assert!(check(&before, &g_after, &bad, 4096).is_err(), "a changed listed word is caught");
    let mut changed = g_after.clone();
    let kept = changed.contents().into_keys().next().expect("a kept block");
    let b = webfusion_core::cpu::shared::find_block(&changed.table, &desc, block_of_key(kept)) as usize;
    changed.voxels[b * 512] ^= 1 << 20;
    assert!(check(&before, &changed, &g_transfer, 4096).is_err(), "a changed kept block is caught");
    let mut unfreed = g_after.clone();
    unfreed.counters[MAP_COUNTER_FREE] -= 1;
    assert!(check(&before, &unfreed, &g_transfer, 4096).is_err(), "a block missing from the free list is caught");
}

#[test]
fn a_short_list_takes_exactly_its_capacity_and_nothing_moves_when_disabled() {
    let desc = sparse_desc(POOL_BLOCKS);
    let before = PoolState::filled(&desc);
    let pose = turned_pose();
    let candidates = outside(&desc, &before, &pose);
    let p = params(&desc, 50);
    let (after, transfer) = run_gpu(&p, &camera_pose(&pose), &before);
    let moved = check(&before, &after, &transfer, 50).unwrap_or_else(|e| panic!("GPU: {e}"));
    assert_eq!(moved.len(), 50, "the list fills to its capacity");
    assert!(moved.is_subset(&candidates), "only blocks outside the region move");
    // Disabled: a lost frame's pose, or no capacity.
    let mut disabled = camera_pose(&pose);
    disabled.enabled = 0;
    for (what, p, pose) in [("disabled pose", params(&desc, 4096), disabled), ("zero capacity", params(&desc, 0), camera_pose(&pose))] {
        let (after, _) = run_gpu(&p, &pose, &before);
        assert_eq!(after, before, "{what}: nothing changes");
    }
}

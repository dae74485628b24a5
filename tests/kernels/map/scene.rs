// SPDX-License-Identifier: MIT
//! What the sparse-map tests share: a sparse map's description, a real Kinect frame's depth
//! fused at known poses, and the table the CPU twins build from it. Hash tables and pool order
//! depend on the order GPU invocations run, so the tests compare them as sets keyed by block.

use std::collections::{BTreeMap, BTreeSet};

use glam::{DQuat, DVec3};
use webfusion_core::cpu::{self, shared::{EMPTY_KEY, MAP_COUNTERS, NO_BLOCK}};
use webfusion_core::kernels::GpuIntrinsics;
use webfusion_core::kernels::block_alloc::{BlockAllocParams, CameraPose};
use webfusion_core::kernels::block_assign::BlockAssignParams;
use webfusion_core::kernels::block_visible::BlockVisibleParams;
use webfusion_core::map::depth_tile_params;
use webfusion_core::tsdf::{TsdfConfig, VolumeDesc};
use webfusion_core::{PinholeIntrinsics, Se3};

use crate::preprocess::chain::real_cpu_chain;

/// Voxel edge of the tests' sparse maps, metres (blocks of 16 cm: a frame allocates a few
/// thousand).
pub(crate) const VOXEL_M: f32 = 0.02;
/// Pool of the tests' sparse maps, blocks.
pub(crate) const POOL_BLOCKS: u32 = 8192;

/// A sparse map's description, its box centred on the identity camera.
pub(crate) fn sparse_desc(pool_blocks: u32) -> VolumeDesc {
    let config = TsdfConfig::sparse(VOXEL_M, pool_blocks);
    config.desc(config.origin_for_first_camera(&Se3::IDENTITY))
}

/// The real frame's intrinsics and unfiltered depth, metres.
pub(crate) fn frame() -> (PinholeIntrinsics, &'static [f32]) {
    let chain = real_cpu_chain();
    (chain.levels[0].intrinsics, &chain.depth_unfiltered_m)
}

/// The poses the tests fuse at: the identity, and a small motion as between two frames.
pub(crate) fn poses() -> [Se3; 2] {
    [Se3::IDENTITY, Se3::new(DQuat::from_axis_angle(DVec3::new(0.2, 1.0, 0.1).normalize(), 0.05), DVec3::new(0.03, -0.02, 0.05))]
}

/// `block_visible`'s parameters for `desc` and the frame's camera `k`, with the mapper's tiles.
pub(crate) fn visible_params(desc: VolumeDesc, k: PinholeIntrinsics) -> BlockVisibleParams {
    let t = depth_tile_params(&k);
    BlockVisibleParams { volume: desc, intrinsics: GpuIntrinsics::from(k), tile_px: t.tile_px, tiles_x: t.tiles_x, tiles_y: t.tiles_y, ..Default::default() }
}

/// The twin's depth tiles of `depth` (an image of `k`'s size) at the mapper's tile size.
pub(crate) fn depth_tiles(k: &PinholeIntrinsics, depth: &[f32]) -> Vec<f32> {
    let t = depth_tile_params(k);
    let mut out = vec![0.0; (t.tiles_x * t.tiles_y) as usize];
    cpu::depth_tile_max(&t, depth, &mut out);
    out
}

pub(crate) fn camera_pose(world_from_camera: &Se3) -> CameraPose {
    webfusion_core::fusion::predictor::camera_pose(Some(world_from_camera))
}

pub(crate) fn alloc_params(desc: VolumeDesc, k: PinholeIntrinsics) -> BlockAllocParams {
    BlockAllocParams { volume: desc, intrinsics: GpuIntrinsics::from(k) }
}

/// An empty hash table and zeroed counters for `desc`.
pub(crate) fn empty_table(desc: &VolumeDesc) -> (Vec<u32>, Vec<u32>) {
    (vec![EMPTY_KEY; 2 * desc.hash_slots as usize], vec![0; MAP_COUNTERS])
}

/// The keys in a hash table.
pub(crate) fn keys(table: &[u32]) -> BTreeSet<u32> {
    table.chunks(2).map(|s| s[0]).filter(|&k| k != EMPTY_KEY).collect()
}

/// key -> pool block of every key that has one.
pub(crate) fn assignments(table: &[u32]) -> BTreeMap<u32, u32> {
    table.chunks(2).filter(|s| s[0] != EMPTY_KEY && s[1] != NO_BLOCK).map(|s| (s[0], s[1])).collect()
}

/// The CPU twins' table, block keys and counters after allocating and assigning the frame
/// fused at each of `poses` in turn.
pub(crate) fn cpu_map(desc: &VolumeDesc, poses: &[Se3]) -> (Vec<u32>, Vec<u32>, Vec<u32>) {
    let (k, depth) = frame();
    let (mut table, mut counters) = empty_table(desc);
    let mut coords = vec![0u32; desc.pool_blocks as usize];
    for pose in poses {
        cpu::block_alloc(&alloc_params(*desc, k), &camera_pose(pose), depth, &mut table, &mut counters);
        cpu::block_assign(&BlockAssignParams { volume: *desc }, &mut table, &mut coords, &mut counters, &[]);
    }
    (table, coords, counters)
}

/// A filled sparse map as the swap kernels see it, every buffer in binding order.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct PoolState {
    pub(crate) table: Vec<u32>,
    pub(crate) coords: Vec<u32>,
    pub(crate) voxels: Vec<u32>,
    pub(crate) colors: Vec<u32>,
    pub(crate) surface: Vec<u32>,
    pub(crate) counters: Vec<u32>,
    pub(crate) free: Vec<u32>,
}

/// What a map holds, by block key: (surface-brick word, voxel words, colour words) of every
/// key that has a block in the pool.
pub(crate) type Contents = BTreeMap<u32, (u32, Vec<u32>, Vec<u32>)>;

impl PoolState {
    /// The real frame's blocks (allocated and assigned at the identity pose), each voxel and
    /// colour word a distinct pattern of its block's key and index (the swap kernels move words
    /// without reading them), every other block's surface word set.
    pub(crate) fn filled(desc: &VolumeDesc) -> Self {
        let (table, coords, counters) = cpu_map(desc, &poses()[..1]);
        let n = desc.pool_blocks as usize * 512;
        let mut voxels = vec![0u32; n];
        let mut colors = vec![0u32; n];
        let mut surface = vec![0u32; desc.pool_blocks as usize];
        for b in 0..counters[0] as usize {
            let key = coords[b];
            for v in 0..512 {
                voxels[b * 512 + v] = key.wrapping_mul(2_654_435_761).wrapping_add(v as u32 * 7919) | 1;
                colors[b * 512 + v] = key.rotate_left(13) ^ (v as u32) << 3;
            }
            surface[b] = key & 1;
        }
        Self { table, coords, voxels, colors, surface, counters, free: vec![0; desc.pool_blocks as usize] }
    }

    /// Blocks in the pool now.
    pub(crate) fn contents(&self) -> Contents {
        assignments(&self.table)
            .into_iter()
            .filter(|&(_, b)| b != webfusion_core::cpu::shared::SWAPPED_BLOCK)
            .map(|(key, b)| {
                let r = b as usize * 512..(b as usize + 1) * 512;
                (key, (self.surface[b as usize], self.voxels[r.clone()].to_vec(), self.colors[r].to_vec()))
            })
            .collect()
    }
}

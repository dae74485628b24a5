// SPDX-License-Identifier: MIT
//! Swapping (InfiniTAM's): a sparse map larger than its GPU pool keeps the blocks near the
//! camera resident and the rest in host memory (wasm memory in the browser), so a room maps at
//! fine voxels within a fixed GPU budget.
//!
//! ```text
//! frame f, GPU (one submission, no wait)             host
//! block_swap_in   blocks the host chose  <-------  the host's blocks inside the fetch region
//! block_alloc .. block_integrate (the frame)           of the last known pose, nearest first
//! block_swap_out  blocks outside the kept region  --> transfer list, read back a frame or more
//!                 (only while the pool is above        later into the host's store
//!                 `evict_above` of its blocks)
//! ```
//!
//! A swapped-out block keeps its key in the hash table with the pool index SWAPPED_BLOCK, so
//! allocation gives it no fresh block and every reader sees it as unobserved; its pool block is
//! cleared and goes to the free list, which allocation uses before growing the pool. The fetch
//! region lies inside the kept region with margins to spare ([`SwapConfig::for_camera`]), so a
//! block does not move back and forth at the border, and the camera finds the blocks it sees back
//! on the GPU several frames before it sees them; a frame that meets a block still on the host is
//! counted (`MapStats::swapped_hits`), never silently merged. Nothing is lost on the way: a
//! block is in exactly one of the pool, the transfer list in flight or the host's store, and a
//! swap-in the pool refused (counted on the GPU) is put back into the store.

use std::collections::{HashMap, VecDeque};

use crate::cpu::map::block_swap_out::{ViewRegion, block_centre};
use crate::cpu::shared::{BLOCK_VOXELS, MAP_COUNTER_SWAPPED_OUT, block_of_key};
use crate::engine::{FrameEncoder, ReadbackRing};
use crate::kernels::block_swap_in::{self, BlockSwapInParams};
use crate::kernels::block_swap_out::{self, BlockSwapOutParams};
use crate::map::{MapBlock, MapStats, SparseMap};
use crate::tsdf::{TsdfStore, VolumeDesc};
use crate::{Gpu, PinholeIntrinsics, Result, Se3};

/// Most blocks moved in each direction per frame.
pub const DEFAULT_BLOCKS_PER_FRAME: u32 = 2048;

/// When and what a map swaps.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SwapConfig {
    /// Most blocks moved in each direction per frame (the transfer lists' capacity).
    pub blocks_per_frame: u32,
    /// Blocks are swapped out while more than this fraction of the pool is resident.
    pub evict_above: f32,
    /// Blocks are swapped in only while fewer than this fraction of the pool is resident (room
    /// left for the blocks new surfaces allocate).
    pub fill_below: f32,
    /// Resident blocks outside this region may be swapped out.
    pub keep: ViewRegion,
    /// Blocks on the host inside this region (a subset of `keep`) are swapped back in.
    pub fetch: ViewRegion,
}

impl SwapConfig {
    /// Regions for a camera with intrinsics `k` whose depth stops at `max_depth_m`, fusing with
    /// truncation `truncation_m`. The camera sees a cone of half-angle θ (the image's half
    /// diagonal) up to `max_depth_m` / cos θ + μ from its centre (depth is measured along the
    /// axis: a corner ray's samples lie farther away). The fetch region widens it by 15° and
    /// 0.5 m and always
    /// holds the 1 m around the camera: a hand-held or robot camera at 30 Hz moves a few cm and
    /// turns a few degrees per frame, so blocks come back many frames before they are seen, from
    /// a pose a frame or two old and at most `blocks_per_frame` a frame. The kept region widens it
    /// by 30° and 1 m (1.5 m around the camera), so a block between the two stays where it is.
    pub fn for_camera(k: &PinholeIntrinsics, max_depth_m: f32, truncation_m: f32) -> Self {
        let half_diagonal_px = (0.5 * k.width_px as f32).hypot(0.5 * k.height_px as f32);
        let theta = (half_diagonal_px / k.fx_px.min(k.fy_px)).atan();
        let reach = max_depth_m / theta.cos() + truncation_m;
        let cos = |extra_deg: f32| (theta + extra_deg.to_radians()).min(std::f32::consts::PI).cos();
        Self {
            blocks_per_frame: DEFAULT_BLOCKS_PER_FRAME,
            evict_above: 0.75,
            fill_below: 0.9,
            keep: ViewRegion { near_m: 1.5, range_m: reach + 1.0, cos_half_angle: cos(30.0) },
            fetch: ViewRegion { near_m: 1.0, range_m: reach + 0.5, cos_half_angle: cos(15.0) },
        }
    }
}

/// A block in host memory: its surface-brick word, voxel words and colour words.
#[derive(Clone, Debug)]
struct HostBlock {
    surface: u32,
    voxels: Box<[u32]>,
    colors: Option<Box<[u32]>>,
}

impl HostBlock {
    fn bytes(&self) -> u64 {
        4 + 4 * (self.voxels.len() + self.colors.as_ref().map_or(0, |c| c.len())) as u64
    }
}

/// What one submitted frame swapped in (confirmed by its report).
type SwapInBatch = Vec<(u32, HostBlock)>;

/// The host side of a sparse map's swapping: the kernels' bindings, the transfer lists and the
/// store of swapped-out blocks.
#[derive(Debug)]
pub struct MapSwapper {
    config: SwapConfig,
    desc: VolumeDesc,
    color: bool,
    capacity: u32,
    transfer_in: wgpu::Buffer,
    transfer_out: wgpu::Buffer,
    in_params: wgpu::Buffer,
    in_bind_group: wgpu::BindGroup,
    _out_params: wgpu::Buffer,
    out_bind_group: wgpu::BindGroup,
    out_readback: ReadbackRing<u64>,
    /// Incremented by every reset: a swap-out list of an earlier generation is dropped.
    generation: u64,
    store: HashMap<u32, HostBlock>,
    store_bytes: u64,
    /// Per submitted frame whose report has not come, what it swapped in.
    unconfirmed: VecDeque<SwapInBatch>,
    /// This frame's plan: entries written to the swap-in list, and whether it swaps out.
    swap_in_now: u32,
    swap_out_now: bool,
    /// The last report's counters.
    last: Option<MapStats>,
    swapped_out_total: u64,
    swapped_in_total: u64,
}

impl MapSwapper {
    /// Swapping for `map`, whose kernels read the camera pose from `pose` (a `CameraPose` at
    /// offset 0).
    pub fn new(gpu: &Gpu, map: &SparseMap, pose: &wgpu::Buffer, config: SwapConfig) -> Self {
        let desc = map.desc();
        let color = map.has_color();
        let capacity = config.blocks_per_frame.clamp(1, desc.pool_blocks);
        let words = Self::transfer_words(capacity, color);
        let transfer_in = gpu.storage_buffer::<u32>("core.map.swap.transfer_in", words);
        let transfer_out = gpu.storage_buffer::<u32>("core.map.swap.transfer_out", words);
        let color_enabled = u32::from(color);
        let in_params = gpu.uniform_buffer("core.block_swap_in.params", &BlockSwapInParams { volume: desc, count: 0, capacity, color_enabled, ..Default::default() });
        let in_bind_group = block_swap_in::Bindings {
            params: &in_params,
            block_table: map.block_table(),
            block_coords: map.block_coords(),
            tsdf_volume: map.voxels(),
            color_volume: map.colors(),
            surface_bricks: map.surface_bricks(),
            map_counters: map.counters(),
            free_blocks: map.free_blocks(),
            swap_transfer: &transfer_in,
        }
        .bind_group(gpu);
        let out_params = gpu.uniform_buffer(
            "core.block_swap_out.params",
            &BlockSwapOutParams {
                volume: desc,
                capacity,
                color_enabled,
                keep_near_m: config.keep.near_m,
                keep_range_m: config.keep.range_m,
                keep_cos_half_angle: config.keep.cos_half_angle,
                ..Default::default()
            },
        );
        let out_bind_group = block_swap_out::Bindings {
            params: &out_params,
            pose,
            block_table: map.block_table(),
            block_coords: map.block_coords(),
            tsdf_volume: map.voxels(),
            color_volume: map.colors(),
            surface_bricks: map.surface_bricks(),
            map_counters: map.counters(),
            free_blocks: map.free_blocks(),
            swap_transfer: &transfer_out,
        }
        .bind_group(gpu);
        let out_readback = ReadbackRing::new(gpu, "core.map.swap.out", 4 + 4 * words as u64, 1);
        Self {
            config,
            desc,
            color,
            capacity,
            transfer_in,
            transfer_out,
            in_params,
            in_bind_group,
            _out_params: out_params,
            out_bind_group,
            out_readback,
            generation: 0,
            store: HashMap::new(),
            store_bytes: 0,
            unconfirmed: VecDeque::new(),
            swap_in_now: 0,
            swap_out_now: false,
            last: None,
            swapped_out_total: 0,
            swapped_in_total: 0,
        }
    }

    /// Words of a transfer list of `capacity` entries (layout in `block_swap_out.wgsl`).
    fn transfer_words(capacity: u32, color: bool) -> usize {
        let c = capacity as usize;
        2 * c + c * BLOCK_VOXELS as usize * if color { 2 } else { 1 }
    }

    /// The settings.
    pub fn config(&self) -> &SwapConfig {
        &self.config
    }

    /// Blocks held in host memory.
    pub fn blocks_on_host(&self) -> usize {
        self.store.len()
    }

    /// Forgets every block on the host and in flight (the map was reset).
    pub fn reset(&mut self) {
        self.generation += 1;
        self.store.clear();
        self.store_bytes = 0;
        self.unconfirmed.clear();
        self.last = None;
        self.swap_in_now = 0;
        self.swap_out_now = false;
        self.swapped_out_total = 0;
        self.swapped_in_total = 0;
    }

    /// Plans this frame's swapping from the last report and the camera pose the host knows
    /// best (the last reported, or the given pose of a pose-driven mapper), and uploads the
    /// blocks to swap in. Without a report yet, nothing moves.
    pub fn prepare(&mut self, gpu: &Gpu, world_from_camera: Option<&Se3>) {
        self.swap_in_now = 0;
        self.swap_out_now = false;
        let Some(last) = self.last else { return };
        let pool = self.desc.pool_blocks as f32;
        let in_flight: usize = self.unconfirmed.iter().map(Vec::len).sum();
        let resident = last.blocks_used as f32 + in_flight as f32;
        self.swap_out_now = self.out_readback.free_slot().is_some() && resident > self.config.evict_above * pool;
        let room = (self.config.fill_below * pool - resident).max(0.0) as usize;
        let Some(pose) = world_from_camera else { return };
        if self.store.is_empty() || room == 0 {
            return;
        }
        let camera = pose.translation_m.as_vec3().to_array();
        let axis = (pose.rotation * glam::DVec3::Z).as_vec3().to_array();
        let mut wanted: Vec<(f32, u32)> = self
            .store
            .keys()
            .filter_map(|&key| {
                let (centre, radius_m) = block_centre(&self.desc, block_of_key(key));
                let v: [f32; 3] = std::array::from_fn(|i| centre[i] - camera[i]);
                self.config.fetch.contains(v, axis, radius_m).then(|| ((v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt(), key))
            })
            .collect();
        wanted.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        wanted.truncate(room.min(self.capacity as usize));
        if wanted.is_empty() {
            return;
        }
        let n = BLOCK_VOXELS as usize;
        let c = self.capacity as usize;
        let mut keys = Vec::with_capacity(wanted.len());
        let mut surface = Vec::with_capacity(wanted.len());
        let mut voxels = Vec::with_capacity(wanted.len() * n);
        let mut colors = Vec::with_capacity(if self.color { wanted.len() * n } else { 0 });
        let mut batch = Vec::with_capacity(wanted.len());
        for &(_, key) in &wanted {
            let block = self.store.remove(&key).expect("wanted keys come from the store");
            self.store_bytes -= block.bytes();
            keys.push(key);
            surface.push(block.surface);
            voxels.extend_from_slice(&block.voxels);
            if let Some(c) = &block.colors {
                colors.extend_from_slice(c);
            }
            batch.push((key, block));
        }
        let write = |offset_words: usize, data: &[u32]| gpu.queue.write_buffer(&self.transfer_in, 4 * offset_words as u64, bytemuck::cast_slice(data));
        write(0, &keys);
        write(c, &surface);
        write(2 * c, &voxels);
        if self.color {
            write(2 * c + c * n, &colors);
        }
        self.swap_in_now = batch.len() as u32;
        gpu.write_buffer(&self.in_params, &[BlockSwapInParams { volume: self.desc, count: self.swap_in_now, capacity: self.capacity, color_enabled: u32::from(self.color), ..Default::default() }]);
        self.unconfirmed.push_back(batch);
    }

    /// Records the planned swap-in into an open pass (before the frame's allocation).
    pub fn record_in(&self, gpu: &Gpu, pass: &mut wgpu::ComputePass<'_>) {
        if self.swap_in_now > 0 {
            gpu.kernels.block_swap_in.dispatch_in(pass, &self.in_bind_group, [self.swap_in_now, 1, 1]);
        }
    }

    /// Clears the swap-out count before the frame's passes (when this frame swaps out).
    pub fn encode_clear(&self, frame: &mut FrameEncoder<'_>, counters: &wgpu::Buffer) {
        if self.swap_out_now {
            frame.encoder().clear_buffer(counters, (MAP_COUNTER_SWAPPED_OUT * 4) as u64, Some(4));
        }
    }

    /// Records the planned swap-out into an open pass (after the frame's integration).
    pub fn record_out(&self, gpu: &Gpu, pass: &mut wgpu::ComputePass<'_>) {
        if self.swap_out_now {
            gpu.kernels.block_swap_out.dispatch_in(pass, &self.out_bind_group, [self.desc.pool_blocks, 1, 1]);
        }
    }

    /// Copies the swap-out count and list into the readback buffer (after the passes).
    pub fn encode_readback(&self, frame: &mut FrameEncoder<'_>, counters: &wgpu::Buffer) {
        if !self.swap_out_now {
            return;
        }
        let (_, slot) = self.out_readback.free_slot().expect("a frame swaps out only with its readback slot free");
        frame.encoder().copy_buffer_to_buffer(counters, (MAP_COUNTER_SWAPPED_OUT * 4) as u64, slot, 0, 4);
        frame.encoder().copy_buffer_to_buffer(&self.transfer_out, 0, slot, 4, self.transfer_out.size());
    }

    /// After the frame's submission: starts reading the swap-out list back, and remembers what
    /// it swapped in until its report confirms it (`on_report`).
    pub fn submitted(&mut self, gpu: &Gpu, submission: wgpu::SubmissionIndex) {
        if self.swap_in_now == 0 {
            self.unconfirmed.push_back(Vec::new());
        }
        if self.swap_out_now {
            let (slot, _) = self.out_readback.free_slot().expect("checked when planned");
            self.out_readback.start(gpu, slot, submission, self.generation);
        }
        self.swap_in_now = 0;
        self.swap_out_now = false;
    }

    /// The next submitted frame's counters (reports come in submission order): confirms what it
    /// swapped in, or puts it back into the store when the pool refused some of it (refused
    /// blocks stayed swapped out on the GPU; the others are resident again, and a stale host
    /// copy of a resident block is never swapped in: `block_swap_in` skips keys not swapped
    /// out). Fills in the host's part of `stats`.
    pub fn on_report(&mut self, stats: &mut MapStats) {
        let batch = self.unconfirmed.pop_front().unwrap_or_default();
        let refused_before = self.last.map_or(0, |s| s.swap_in_refused);
        let refused = stats.swap_in_refused.saturating_sub(refused_before) as usize;
        self.swapped_in_total += batch.len().saturating_sub(refused) as u64;
        if refused > 0 {
            for (key, block) in batch {
                if let std::collections::hash_map::Entry::Vacant(e) = self.store.entry(key) {
                    self.store_bytes += block.bytes();
                    e.insert(block);
                }
            }
        }
        self.last = Some(*stats);
        self.fill_stats(stats);
    }

    /// Sets `stats`' host fields.
    pub fn fill_stats(&self, stats: &mut MapStats) {
        stats.blocks_on_host = self.store.len() as u32;
        stats.host_bytes = self.store_bytes;
        stats.swapped_out_total = self.swapped_out_total;
        stats.swapped_in_total = self.swapped_in_total;
    }

    /// Moves a completed swap-out list into the store (never waits).
    pub fn poll(&mut self, gpu: &Gpu) -> Result<()> {
        for done in self.out_readback.collect(gpu)? {
            if done.tag == self.generation {
                self.take_out_list(&done.bytes);
            }
        }
        Ok(())
    }

    /// Waits for a swap-out list in flight and moves it into the store.
    pub async fn flush(&mut self, gpu: &Gpu) -> Result<()> {
        while let Some(done) = self.out_readback.wait_oldest(gpu).await? {
            if done.tag == self.generation {
                self.take_out_list(&done.bytes);
            }
        }
        Ok(())
    }

    fn take_out_list(&mut self, bytes: &[u8]) {
        let words: Vec<u32> = bytemuck::pod_collect_to_vec(bytes);
        let count = words[0].min(self.capacity) as usize;
        let list = &words[1..];
        let (c, n) = (self.capacity as usize, BLOCK_VOXELS as usize);
        self.swapped_out_total += count as u64;
        for i in 0..count {
            let voxels = list[2 * c + i * n..2 * c + (i + 1) * n].into();
            let colors = self.color.then(|| list[2 * c + c * n + i * n..2 * c + c * n + (i + 1) * n].into());
            let block = HostBlock { surface: list[c + i], voxels, colors };
            self.store_bytes += block.bytes();
            if let Some(old) = self.store.insert(list[i], block) {
                self.store_bytes -= old.bytes();
            }
        }
    }

    /// Takes `resident` blocks as in use on the GPU until the first report says otherwise (a
    /// loaded map: its first frame may already swap in).
    pub fn assume_resident(&mut self, resident: u32) {
        self.last = Some(MapStats { blocks_used: resident, pool_blocks: self.desc.pool_blocks, ..MapStats::default() });
    }

    /// Puts `blocks` into the host's store (a loaded map's blocks beyond the GPU's share: their
    /// keys are in the table as swapped out).
    pub fn store_blocks(&mut self, blocks: Vec<MapBlock>) {
        for b in blocks {
            let block = HostBlock { surface: crate::map::surface_word(&b.voxels), voxels: b.voxels.into(), colors: self.color.then(|| b.colors.into()) };
            self.store_bytes += block.bytes();
            if let Some(old) = self.store.insert(crate::cpu::shared::block_key(b.coords), block) {
                self.store_bytes -= old.bytes();
            }
        }
    }

    /// The blocks on the host, in any order.
    pub fn host_blocks(&self) -> impl Iterator<Item = MapBlock> + '_ {
        self.store.iter().map(|(&key, b)| MapBlock { coords: block_of_key(key), voxels: b.voxels.to_vec(), colors: b.colors.as_ref().map_or_else(Vec::new, |c| c.to_vec()) })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// TUM's default Kinect calibration.
    const K: PinholeIntrinsics = PinholeIntrinsics { fx_px: 525.0, fy_px: 525.0, cx_px: 319.5, cy_px: 239.5, width_px: 640, height_px: 480 };

    #[test]
    fn every_sample_the_camera_fuses_lies_in_the_fetch_region_and_that_in_the_kept_one() {
        let (max_depth_m, mu) = (5.0f32, 0.047f32);
        let c = SwapConfig::for_camera(&K, max_depth_m, mu);
        let axis = [0.0, 0.0, 1.0];
        let mut checked = 0;
        for (x, y) in [(0.0, 0.0), (639.0, 479.0), (0.0, 479.0), (319.5, 239.5), (639.0, 240.0), (100.0, 30.0)] {
            for z in [0.3f32, 1.0, 2.5, 4.0, max_depth_m] {
                let ray = [(x - K.cx_px) / K.fx_px, (y - K.cy_px) / K.fy_px, 1.0f32];
                let norm = (ray[0] * ray[0] + ray[1] * ray[1] + 1.0).sqrt();
                // The far end of the sample's truncation band, along its ray.
                let far = (z * norm + mu) / norm;
                let p = ray.map(|r| r * far);
                assert!(c.fetch.contains(p, axis, 0.0), "pixel ({x}, {y}) at {z} m lies outside the fetch region");
                assert!(c.keep.contains(p, axis, 0.0), "pixel ({x}, {y}) at {z} m lies outside the kept region");
                checked += 1;
            }
        }
        assert_eq!(checked, 30);
        // The fetch region lies inside the kept one: points on a grid around the camera.
        for i in -20..=20 {
            for j in -20..=20 {
                for k in -20..=20 {
                    let p = [i as f32 * 0.4, j as f32 * 0.4, k as f32 * 0.4];
                    assert!(!c.fetch.contains(p, axis, 0.0) || c.keep.contains(p, axis, 0.0), "{p:?} is fetched but not kept");
                }
            }
        }
        // Negative control: with the depth taken as a distance (the old reach), a corner ray's
        // far samples fall outside the fetch region.
        let theta = (400.0f32 / 525.0).atan();
        let corner_far = [(0.0 - K.cx_px) / K.fx_px, (0.0 - K.cy_px) / K.fy_px, 1.0].map(|r| r * max_depth_m);
        let short = ViewRegion { range_m: max_depth_m + mu + 0.5, ..c.fetch };
        assert!(!short.contains(corner_far, axis, 0.0) && c.fetch.contains(corner_far, axis, 0.0), "the corner at {} rad needs the radial reach", theta);
    }
}

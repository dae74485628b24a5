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
    /// What the camera sees: the cone of its image about the optical axis, as far as a fused
    /// sample's truncation band reaches.
    pub seen: ViewRegion,
    /// How far the kept region extends beyond `seen` at full margins: resident blocks outside it
    /// may be swapped out.
    pub keep_margin: RegionMargin,
    /// How far the fetch region extends beyond `seen` at full margins: blocks on the host inside
    /// it are swapped back in. Never wider than `keep_margin`, so the fetch region lies inside
    /// the kept one at every scale.
    pub fetch_margin: RegionMargin,
    /// The smallest fraction of the margins the swapper shrinks them to when the kept region no
    /// longer fits the pool ([`MapSwapper`]'s pressure rule).
    pub min_margin_scale: f32,
}

/// How far a region extends beyond what the camera sees.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RegionMargin {
    /// Radius around the camera centre that is always inside, metres.
    pub near_m: f32,
    /// Added to the reach of the seen cone, metres.
    pub range_m: f32,
    /// Added to the seen cone's half-angle, degrees.
    pub angle_deg: f32,
}

impl SwapConfig {
    /// Regions for a camera with intrinsics `k` whose depth stops at `max_depth_m`, fusing with
    /// truncation band `truncation_m` there. The camera sees a cone of half-angle θ (the image's
    /// half diagonal) up to `max_depth_m` / cos θ + the band from its centre (depth is measured along the
    /// axis: a corner ray's samples lie farther away). The fetch region widens it by 15° and
    /// 0.5 m and always holds the 1 m around the camera: a hand-held or robot camera at 30 Hz
    /// moves a few cm and turns a few degrees per frame, so blocks come back many frames before
    /// they are seen, from a pose a frame or two old and at most `blocks_per_frame` a frame. The
    /// kept region widens it by 30° and 1 m (1.5 m around the camera), so a block between the two
    /// stays where it is. Under pressure the margins shrink to an eighth (fetch: 1.9°, 6 cm,
    /// 12.5 cm around the camera), still more than a frame's motion at 30 Hz.
    pub fn for_camera(k: &PinholeIntrinsics, max_depth_m: f32, truncation_m: f32) -> Self {
        let half_diagonal_px = (0.5 * k.width_px as f32).hypot(0.5 * k.height_px as f32);
        let theta = (half_diagonal_px / k.fx_px.min(k.fy_px)).atan();
        let reach = max_depth_m / theta.cos() + truncation_m;
        Self {
            blocks_per_frame: DEFAULT_BLOCKS_PER_FRAME,
            evict_above: 0.75,
            fill_below: 0.9,
            seen: ViewRegion { near_m: 0.0, range_m: reach, cos_half_angle: theta.cos() },
            keep_margin: RegionMargin { near_m: 1.5, range_m: 1.0, angle_deg: 30.0 },
            fetch_margin: RegionMargin { near_m: 1.0, range_m: 0.5, angle_deg: 15.0 },
            min_margin_scale: 0.125,
        }
    }

    /// The kept region with its margins scaled by `scale` (1: full margins).
    pub fn keep_region(&self, scale: f32) -> ViewRegion {
        Self::widened(&self.seen, &self.keep_margin, scale)
    }

    /// The fetch region with its margins scaled by `scale` (1: full margins).
    pub fn fetch_region(&self, scale: f32) -> ViewRegion {
        Self::widened(&self.seen, &self.fetch_margin, scale)
    }

    fn widened(seen: &ViewRegion, margin: &RegionMargin, scale: f32) -> ViewRegion {
        let half_angle = seen.cos_half_angle.clamp(-1.0, 1.0).acos() + (scale * margin.angle_deg).to_radians();
        ViewRegion {
            near_m: seen.near_m + scale * margin.near_m,
            range_m: seen.range_m + scale * margin.range_m,
            cos_half_angle: half_angle.min(std::f32::consts::PI).cos(),
        }
    }
}

/// Consecutive frames with the pool below the eviction mark and every wanted block swapped in
/// before the swapper doubles shrunk margins again (a second at 30 Hz: margins grow back only
/// once the smaller ones have kept the map comfortably within the pool for a while, so the
/// regions do not flap between two sizes every few frames).
const RELAX_AFTER_FRAMES: u32 = 30;

/// Plans over which the swapper remembers the camera's largest motion between two plans (a
/// second at 30 Hz).
const MOTION_WINDOW: u32 = 30;

/// The pressure rule of [`MapSwapper::prepare`]: the fraction of the regions' margins in force.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Margins {
    /// 1, or less while the kept region does not fit the pool.
    scale: f32,
    /// Whether the last swap-out list made at `scale` held every resident block outside the
    /// kept region (fewer than the list's capacity): eviction can make no more room.
    eviction_exhausted: bool,
    /// Consecutive comfortable frames at shrunk margins.
    calm_frames: u32,
    /// Times the margins shrank.
    shrinks: u32,
}

impl Margins {
    fn new() -> Self {
        Self { scale: 1.0, eviction_exhausted: false, calm_frames: 0, shrinks: 0 }
    }

    /// One frame's plan: `above_mark`, the pool is above the eviction mark; `starved`, the fetch
    /// region holds more blocks on the host than the pool has room for, or the full pool refused
    /// new blocks.
    /// `floor` is the smallest scale allowed now (the camera's motion, [`MapSwapper::motion_floor`]);
    /// a scale below it rises to it at once.
    fn adapt(&mut self, config: &SwapConfig, floor: f32, above_mark: bool, starved: bool) {
        let floor = floor.max(config.min_margin_scale).min(1.0);
        if self.scale < floor {
            self.scale = floor;
            self.calm_frames = 0;
        } else if starved && above_mark && self.eviction_exhausted && self.scale > floor {
            self.scale = (0.5 * self.scale).max(floor);
            self.shrinks += 1;
            // The smaller region is judged by a swap-out list made with it.
            self.eviction_exhausted = false;
            self.calm_frames = 0;
        } else if !starved && !above_mark && self.scale < 1.0 {
            self.calm_frames += 1;
            if self.calm_frames >= RELAX_AFTER_FRAMES {
                self.scale = (2.0 * self.scale).min(1.0);
                self.calm_frames = 0;
            }
        } else {
            self.calm_frames = 0;
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
    out_params: wgpu::Buffer,
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
    /// The regions' margins under pressure.
    margins: Margins,
    /// Whether the last report counted new blocks the full pool refused.
    allocation_refused: bool,
    /// The pose the last plan used, and the camera's motion between consecutive plans over the
    /// last [`MOTION_WINDOW`] plans (degrees, metres), oldest first.
    last_plan_pose: Option<Se3>,
    recent_motion: VecDeque<(f32, f32)>,
    /// The margin scale of the kept region in `out_params`.
    out_params_scale: f32,
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
            &Self::out_params_for(desc, capacity, color, &config.keep_region(1.0)),
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
            out_params,
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
            margins: Margins::new(),
            allocation_refused: false,
            last_plan_pose: None,
            recent_motion: VecDeque::with_capacity(MOTION_WINDOW as usize),
            out_params_scale: 1.0,
        }
    }

    fn out_params_for(volume: VolumeDesc, capacity: u32, color: bool, keep: &ViewRegion) -> BlockSwapOutParams {
        BlockSwapOutParams {
            volume,
            capacity,
            color_enabled: u32::from(color),
            keep_near_m: keep.near_m,
            keep_range_m: keep.range_m,
            keep_cos_half_angle: keep.cos_half_angle,
            ..Default::default()
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

    /// The fraction of the regions' margins in force: 1, or less while the kept region does not
    /// fit the pool (see [`Self::prepare`]).
    pub fn margin_scale(&self) -> f32 {
        self.margins.scale
    }

    /// The fetch region in force (margins scaled by [`Self::margin_scale`]).
    pub fn fetch_region(&self) -> ViewRegion {
        self.config.fetch_region(self.margins.scale)
    }

    /// The smallest margin scale the camera's recent motion allows: the fetch region plans from a
    /// pose up to two frames old for a frame to come, so its margins must cover three frames of
    /// the largest motion between plans seen over the last [`MOTION_WINDOW`] (angle beyond the
    /// cone, distance beyond the near radius); never below the configured floor.
    fn motion_floor(&mut self, world_from_camera: Option<&Se3>) -> f32 {
        if let (Some(pose), Some(last)) = (world_from_camera, self.last_plan_pose.as_ref()) {
            let step = last.inverse() * *pose;
            if self.recent_motion.len() == MOTION_WINDOW as usize {
                self.recent_motion.pop_front();
            }
            self.recent_motion.push_back((step.rotation_angle_rad().to_degrees() as f32, step.translation_m.length() as f32));
        }
        if let Some(pose) = world_from_camera {
            self.last_plan_pose = Some(*pose);
        }
        let (deg, m) = self.recent_motion.iter().fold((0.0f32, 0.0f32), |(d, t), &(a, b)| (d.max(a), t.max(b)));
        let fetch = &self.config.fetch_margin;
        (3.0 * deg / fetch.angle_deg).max(3.0 * m / fetch.near_m).max(self.config.min_margin_scale).min(1.0)
    }

    /// Sets the smallest margin scale the pressure rule may shrink to: 1 pins the full margins.
    pub fn set_min_margin_scale(&mut self, scale: f32) {
        self.config.min_margin_scale = scale.clamp(0.0, 1.0);
    }

    /// Times the margins shrank under pressure.
    pub fn margin_shrinks(&self) -> u32 {
        self.margins.shrinks
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
        self.margins = Margins::new();
        self.allocation_refused = false;
        self.last_plan_pose = None;
        self.recent_motion.clear();
    }

    /// Plans this frame's swapping from the last report and the camera pose the host knows
    /// best (the last reported, or the given pose of a pose-driven mapper), and uploads the
    /// blocks to swap in. Without a report yet, nothing moves.
    ///
    /// **Pressure.** The regions' margins are sized for a camera whose surroundings fit the
    /// pool. When they do not (fine voxels, a camera turning in place in a large room), the kept
    /// region alone can fill the pool: eviction then finds nothing more to move, swap-ins have
    /// no room, the camera meets blocks still on the host and new surfaces find no free block.
    /// So when the host holds blocks of the fetch region that it cannot swap in for want of room,
    /// or the last frame's new blocks were refused by the full pool, while the pool is above the
    /// eviction mark and the last swap-out list took every block outside the kept region, both
    /// margins halve (down to `min_margin_scale`): the next swap-out evicts the blocks the
    /// camera is least likely to see soon, the ones farthest outside its view, and the fetch
    /// region follows the camera more tightly. They double again after [`RELAX_AFTER_FRAMES`]
    /// comfortable frames (pool below the eviction mark, nothing wanted left on the host).
    pub fn prepare(&mut self, gpu: &Gpu, world_from_camera: Option<&Se3>) {
        self.swap_in_now = 0;
        self.swap_out_now = false;
        let Some(last) = self.last else { return };
        let pool = self.desc.pool_blocks as f32;
        let in_flight: usize = self.unconfirmed.iter().map(Vec::len).sum();
        let resident = last.blocks_used as f32 + in_flight as f32;
        let above_mark = resident > self.config.evict_above * pool;
        self.swap_out_now = self.out_readback.free_slot().is_some() && above_mark;
        let room = (self.config.fill_below * pool - resident).max(0.0) as usize;
        let mut wanted: Vec<(f32, u32)> = match world_from_camera {
            Some(pose) if !self.store.is_empty() => {
                let camera = pose.translation_m.as_vec3().to_array();
                let axis = (pose.rotation * glam::DVec3::Z).as_vec3().to_array();
                let fetch = self.fetch_region();
                self.store
                    .keys()
                    .filter_map(|&key| {
                        let (centre, radius_m) = block_centre(&self.desc, block_of_key(key));
                        let v: [f32; 3] = std::array::from_fn(|i| centre[i] - camera[i]);
                        fetch.contains(v, axis, radius_m).then(|| ((v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt(), key))
                    })
                    .collect()
            }
            _ => Vec::new(),
        };
        let floor = self.motion_floor(world_from_camera);
        self.margins.adapt(&self.config, floor, above_mark, wanted.len() > room || self.allocation_refused);
        if self.swap_out_now && self.out_params_scale != self.margins.scale {
            let keep = self.config.keep_region(self.margins.scale);
            gpu.write_buffer(&self.out_params, &[Self::out_params_for(self.desc, self.capacity, self.color, &keep)]);
            self.out_params_scale = self.margins.scale;
        }
        if wanted.is_empty() || room == 0 {
            return;
        }
        wanted.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        wanted.truncate(room.min(self.capacity as usize));
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
            self.out_readback.start(gpu, slot, submission, self.out_tag());
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
        self.allocation_refused = stats.pool_full > self.last.map_or(0, |s| s.pool_full);
        self.last = Some(*stats);
        self.fill_stats(stats);
    }

    /// Sets `stats`' host fields.
    pub fn fill_stats(&self, stats: &mut MapStats) {
        stats.blocks_on_host = self.store.len() as u32;
        stats.host_bytes = self.store_bytes;
        stats.swapped_out_total = self.swapped_out_total;
        stats.swapped_in_total = self.swapped_in_total;
        stats.swap_margin_shrinks = self.margins.shrinks;
        stats.swap_margin_percent = (100.0 * self.margins.scale).round() as u32;
    }

    /// A swap-out list's tag: the map's generation (high half) and the margin scale its kept
    /// region was made with (low half).
    fn out_tag(&self) -> u64 {
        (self.generation << 32) | u64::from(self.out_params_scale.to_bits())
    }

    /// Moves a completed swap-out list into the store (never waits).
    pub fn poll(&mut self, gpu: &Gpu) -> Result<()> {
        for done in self.out_readback.collect(gpu)? {
            self.take_out_list(done.tag, &done.bytes);
        }
        Ok(())
    }

    /// Waits for a swap-out list in flight and moves it into the store.
    pub async fn flush(&mut self, gpu: &Gpu) -> Result<()> {
        while let Some(done) = self.out_readback.wait_oldest(gpu).await? {
            self.take_out_list(done.tag, &done.bytes);
        }
        Ok(())
    }

    /// Takes a swap-out list tagged `tag` (a list of an earlier generation is dropped).
    fn take_out_list(&mut self, tag: u64, bytes: &[u8]) {
        if tag >> 32 != self.generation {
            return;
        }
        let words: Vec<u32> = bytemuck::pod_collect_to_vec(bytes);
        let count = words[0].min(self.capacity) as usize;
        // Fewer than the capacity: every block outside the kept region in force went.
        self.margins.eviction_exhausted = words[0] < self.capacity && tag as u32 == self.margins.scale.to_bits();
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
                for scale in [1.0, c.min_margin_scale] {
                    assert!(c.fetch_region(scale).contains(p, axis, 0.0), "pixel ({x}, {y}) at {z} m lies outside the fetch region at margin scale {scale}");
                    assert!(c.keep_region(scale).contains(p, axis, 0.0), "pixel ({x}, {y}) at {z} m lies outside the kept region at margin scale {scale}");
                }
                checked += 1;
            }
        }
        assert_eq!(checked, 30);
        // The fetch region lies inside the kept one at every scale, and a shrunk one inside the
        // full one: points on a grid around the camera.
        let (fetch, keep) = (c.fetch_region(1.0), c.keep_region(1.0));
        let (fetch_min, keep_min) = (c.fetch_region(c.min_margin_scale), c.keep_region(c.min_margin_scale));
        let (mut fetched, mut fetched_min) = (0, 0);
        for i in -20..=20 {
            for j in -20..=20 {
                for k in -20..=20 {
                    let p = [i as f32 * 0.4, j as f32 * 0.4, k as f32 * 0.4];
                    assert!(!fetch.contains(p, axis, 0.0) || keep.contains(p, axis, 0.0), "{p:?} is fetched but not kept");
                    assert!(!fetch_min.contains(p, axis, 0.0) || keep_min.contains(p, axis, 0.0), "{p:?} is fetched but not kept at the smallest margins");
                    assert!(!keep_min.contains(p, axis, 0.0) || keep.contains(p, axis, 0.0), "{p:?} is kept at the smallest margins only");
                    fetched += usize::from(fetch.contains(p, axis, 0.0));
                    fetched_min += usize::from(fetch_min.contains(p, axis, 0.0));
                }
            }
        }
        assert!(fetched_min * 3 < fetched * 2, "the smallest margins fetch clearly less ({fetched_min} of {fetched} grid points)");
        // Full margins are the regions the swapper always used.
        let theta = (400.0f32 / 525.0).atan();
        let reach = max_depth_m / theta.cos() + mu;
        assert!((keep.range_m - (reach + 1.0)).abs() < 1e-5 && (keep.cos_half_angle - (theta + 30f32.to_radians()).cos()).abs() < 1e-5 && keep.near_m == 1.5, "{keep:?}");
        // Negative control: with the depth taken as a distance (the old reach), a corner ray's
        // far samples fall outside the fetch region.
        let theta = (400.0f32 / 525.0).atan();
        let corner_far = [(0.0 - K.cx_px) / K.fx_px, (0.0 - K.cy_px) / K.fy_px, 1.0].map(|r| r * max_depth_m);
        let short = ViewRegion { range_m: max_depth_m + mu + 0.5, ..fetch };
        assert!(!short.contains(corner_far, axis, 0.0) && fetch.contains(corner_far, axis, 0.0), "the corner at {} rad needs the radial reach", theta);
    }

    #[test]
    fn margins_shrink_only_when_eviction_cannot_make_room_and_grow_back_after_calm_frames() {
        let c = SwapConfig::for_camera(&K, 5.0, 0.047);
        let mut m = Margins::new();
        // Starved and above the mark, but eviction has not been seen to run dry: no change.
        m.adapt(&c, c.min_margin_scale, true, true);
        assert_eq!(m.scale, 1.0);
        // Eviction ran dry but nothing is wanted (or the pool is below the mark): no change.
        m.eviction_exhausted = true;
        m.adapt(&c, c.min_margin_scale, true, false);
        m.adapt(&c, c.min_margin_scale, false, true);
        assert_eq!((m.scale, m.shrinks), (1.0, 0));
        // All three: the margins halve, and wait for a list made at the new scale.
        m.adapt(&c, c.min_margin_scale, true, true);
        assert_eq!((m.scale, m.shrinks, m.eviction_exhausted), (0.5, 1, false));
        m.adapt(&c, c.min_margin_scale, true, true);
        assert_eq!(m.scale, 0.5, "not again before a list made with the smaller region");
        for _ in 0..10 {
            m.eviction_exhausted = true;
            m.adapt(&c, c.min_margin_scale, true, true);
        }
        assert_eq!((m.scale, m.shrinks), (c.min_margin_scale, 3), "down to the floor, no further");
        // Calm frames: the scale doubles after RELAX_AFTER_FRAMES of them in a row; a busy frame
        // restarts the count.
        for _ in 0..RELAX_AFTER_FRAMES - 1 {
            m.adapt(&c, c.min_margin_scale, false, false);
        }
        m.adapt(&c, c.min_margin_scale, true, false);
        for _ in 0..RELAX_AFTER_FRAMES - 1 {
            m.adapt(&c, c.min_margin_scale, false, false);
        }
        assert_eq!(m.scale, c.min_margin_scale, "a busy frame restarted the count");
        m.adapt(&c, c.min_margin_scale, false, false);
        assert_eq!(m.scale, 2.0 * c.min_margin_scale);
        for _ in 0..3 * RELAX_AFTER_FRAMES {
            m.adapt(&c, c.min_margin_scale, false, false);
        }
        assert_eq!(m.scale, 1.0, "back to full margins, and no further");
        // The camera's motion sets a floor: margins never shrink below it, and rise to it.
        m.eviction_exhausted = true;
        m.adapt(&c, 0.6, true, true);
        assert_eq!(m.scale, 0.6, "halving stops at the motion's floor");
        m.adapt(&c, 0.8, true, false);
        assert_eq!(m.scale, 0.8, "a faster camera widens shrunk margins at once");
    }
}

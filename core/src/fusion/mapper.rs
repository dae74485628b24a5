// SPDX-License-Identifier: MIT
//! The mapper stage: a map (dense box or sparse voxel blocks, [`crate::map`]) and the
//! integration of a depth (and colour) image into it at the pose a pose buffer holds — the
//! tracker's, or one the host writes (pose-driven mapping).

use crate::engine::FrameEncoder;
use crate::kernels::GpuIntrinsics;
use crate::kernels::block_alloc::{self, BlockAllocParams};
use crate::kernels::block_assign::{self, BlockAssignParams};
use crate::kernels::block_integrate::{self, BlockIntegrateParams};
use crate::kernels::block_list_args::{self, BlockListArgsParams};
use crate::kernels::block_visible::{self, BlockVisibleParams};
use crate::kernels::depth_tile_max;
use crate::kernels::tsdf_integrate::{self, TsdfIntegrateParams};
use crate::map::swap::{MapSwapper, SwapConfig};
use crate::map::{Map, MapBlock, MapStats, SparseMap, depth_tile_params};
use crate::preprocess::DepthPreprocessor;
use crate::tsdf::{TsdfConfig, TsdfStore};
use crate::{Gpu, Result, Se3};

/// The integration kernels of one map kind, bound to a preprocessor and a pose buffer.
#[derive(Debug)]
enum Integration {
    /// `tsdf_integrate` over the dense box's columns.
    Dense { bind_group: wgpu::BindGroup },
    /// The sparse map's allocation, visibility and block integration.
    Sparse {
        alloc: wgpu::BindGroup,
        assign: wgpu::BindGroup,
        /// `depth_tile_max` over the depth fused, and its tile count.
        tiles: (wgpu::BindGroup, u32),
        /// The tiles' largest depths, which `visible` reads.
        _tile_max_m: wgpu::Buffer,
        visible: wgpu::BindGroup,
        args: wgpu::BindGroup,
        integrate: wgpu::BindGroup,
        /// Swapping to host memory, when the config asks for it (boxed: it is large, and the
        /// dense variant holds one bind group).
        swapper: Option<Box<MapSwapper>>,
    },
}

/// A map and its integration, bound to one preprocessor and pose buffer.
#[derive(Debug)]
pub struct Mapper {
    map: Map,
    _params: Vec<wgpu::Buffer>,
    integration: Integration,
    image_size: [u32; 2],
}

impl Mapper {
    /// A map of `config` (its kind included) with its box's voxel (0, 0, 0) corner at
    /// `origin_in_world`, fusing the preprocessor's depth (unfiltered when the filter is on, as
    /// KinectFusion does) and colour at the pose in `pose` (a `CameraPose` at offset 0).
    pub fn new(
        gpu: &Gpu,
        config: TsdfConfig,
        origin_in_world: [f32; 3],
        preprocessor: &DepthPreprocessor,
        pose: &wgpu::Buffer,
    ) -> Result<Self> {
        let map = Map::new(gpu, config, origin_in_world)?;
        let intrinsics = GpuIntrinsics::from(preprocessor.levels[0].intrinsics);
        let max_depth_m = preprocessor.config().max_depth_m;
        let depth_m = Self::fused_depth(preprocessor);
        let volume = map.desc();
        let color_enabled = u32::from(map.has_color());
        let (params, integration) = match &map {
            Map::Dense(dense) => {
                let params = gpu.uniform_buffer(
                    "core.tsdf_integrate.params",
                    &TsdfIntegrateParams {
                        volume,
                        intrinsics,
                        color_enabled,
                        max_depth_m,
                        ..Default::default()
                    },
                );
                let bind_group = tsdf_integrate::Bindings {
                    params: &params,
                    pose,
                    depth_m,
                    color: &preprocessor.color,
                    tsdf_volume: dense.voxels(),
                    color_volume: dense.colors(),
                    surface_bricks: dense.surface_bricks(),
                }
                .bind_group(gpu);
                (vec![params], Integration::Dense { bind_group })
            }
            Map::Sparse(sparse) => {
                let counters = sparse.counters();
                let alloc_params = gpu.uniform_buffer(
                    "core.block_alloc.params",
                    &BlockAllocParams { volume, intrinsics },
                );
                let assign_params =
                    gpu.uniform_buffer("core.block_assign.params", &BlockAssignParams { volume });
                let tiles = depth_tile_params(&preprocessor.levels[0].intrinsics);
                let tile_count = tiles.tiles_x * tiles.tiles_y;
                let tile_max_m = gpu.storage_buffer::<f32>("core.map.depth_tile_max_m", tile_count as usize);
                let tiles_params = gpu.uniform_buffer("core.depth_tile_max.params", &tiles);
                let visible_params = gpu.uniform_buffer(
                    "core.block_visible.params",
                    &BlockVisibleParams {
                        volume,
                        intrinsics,
                        tile_px: tiles.tile_px,
                        tiles_x: tiles.tiles_x,
                        tiles_y: tiles.tiles_y,
                        ..Default::default()
                    },
                );
                let args_params = gpu.uniform_buffer(
                    "core.block_list_args.params",
                    &BlockListArgsParams {
                        max_workgroups: gpu.limits.max_compute_workgroups_per_dimension,
                        ..Default::default()
                    },
                );
                let integrate_params = gpu.uniform_buffer(
                    "core.block_integrate.params",
                    &BlockIntegrateParams {
                        volume,
                        intrinsics,
                        color_enabled,
                        ..Default::default()
                    },
                );
                let integration = Integration::Sparse {
                    alloc: block_alloc::Bindings {
                        params: &alloc_params,
                        pose,
                        depth_m,
                        block_table: sparse.block_table(),
                        map_counters: counters,
                    }
                    .bind_group(gpu),
                    assign: block_assign::Bindings {
                        params: &assign_params,
                        block_table: sparse.block_table(),
                        block_coords: sparse.block_coords(),
                        map_counters: counters,
                        free_blocks: sparse.free_blocks(),
                    }
                    .bind_group(gpu),
                    tiles: (
                        depth_tile_max::Bindings {
                            params: &tiles_params,
                            depth_m,
                            tile_max_m: &tile_max_m,
                        }
                        .bind_group(gpu),
                        tile_count,
                    ),
                    visible: block_visible::Bindings {
                        params: &visible_params,
                        pose,
                        block_coords: sparse.block_coords(),
                        map_counters: counters,
                        visible_blocks: sparse.visible_blocks(),
                        tile_max_m: &tile_max_m,
                    }
                    .bind_group(gpu),
                    _tile_max_m: tile_max_m,
                    args: block_list_args::Bindings {
                        params: &args_params,
                        map_counters: counters,
                    }
                    .bind_group(gpu),
                    integrate: block_integrate::Bindings {
                        params: &integrate_params,
                        pose,
                        depth_m,
                        color: &preprocessor.color,
                        tsdf_volume: sparse.voxels(),
                        color_volume: sparse.colors(),
                        surface_bricks: sparse.surface_bricks(),
                        block_coords: sparse.block_coords(),
                        visible_blocks: sparse.visible_blocks(),
                        map_counters: counters,
                    }
                    .bind_group(gpu),
                    swapper: config.swap.then(|| {
                        let swap = SwapConfig::for_camera(&preprocessor.levels[0].intrinsics, max_depth_m, config.truncation_band_m(max_depth_m));
                        Box::new(MapSwapper::new(gpu, sparse, pose, swap))
                    }),
                };
                (
                    vec![
                        alloc_params,
                        assign_params,
                        tiles_params,
                        visible_params,
                        args_params,
                        integrate_params,
                    ],
                    integration,
                )
            }
        };
        let k = preprocessor.levels[0].intrinsics;
        Ok(Self {
            map,
            _params: params,
            integration,
            image_size: [k.width_px, k.height_px],
        })
    }

    /// The depth this mapper fuses (the unfiltered depth when the bilateral filter is on).
    pub fn fused_depth(preprocessor: &DepthPreprocessor) -> &wgpu::Buffer {
        preprocessor
            .depth_unfiltered_m
            .as_ref()
            .unwrap_or(&preprocessor.levels[0].depth_m)
    }

    /// The map.
    pub fn volume(&self) -> &Map {
        &self.map
    }

    /// Where the map's box has its voxel (0, 0, 0) corner in the world (what a saved map
    /// records to be placed again).
    pub fn origin_in_world(&self) -> [f32; 3] {
        match &self.map {
            Map::Dense(dense) => {
                let d = dense.desc();
                [d.origin_x_m, d.origin_y_m, d.origin_z_m]
            }
            Map::Sparse(sparse) => sparse.origin_in_world(),
        }
    }

    /// The sparse map, when the map is one.
    pub fn sparse(&self) -> Option<&SparseMap> {
        self.map.sparse()
    }

    /// The swapper of a sparse map that swaps.
    pub fn swapper(&self) -> Option<&MapSwapper> {
        match &self.integration {
            Integration::Sparse { swapper, .. } => swapper.as_deref(),
            Integration::Dense { .. } => None,
        }
    }

    /// A swapping sparse map's swapper, mutably (to pin its margins).
    pub fn swapper_mut(&mut self) -> Option<&mut MapSwapper> {
        match &mut self.integration {
            Integration::Sparse { swapper, .. } => swapper.as_deref_mut(),
            Integration::Dense { .. } => None,
        }
    }

    /// Plans the next frame's swapping (a sparse map that swaps) from the camera pose the host
    /// knows best, and uploads what it swaps in. Call before [`Self::encode`].
    pub fn prepare_frame(&mut self, gpu: &Gpu, world_from_camera: Option<&Se3>) {
        if let Some(s) = self.swapper_mut() {
            s.prepare(gpu, world_from_camera);
        }
    }

    /// After the frame's submission (see [`MapSwapper::submitted`]).
    pub fn frame_submitted(&mut self, gpu: &Gpu, submission: &wgpu::SubmissionIndex) {
        if let Some(s) = self.swapper_mut() {
            s.submitted(gpu, submission.clone());
        }
    }

    /// A frame's map counters as its report read them back, completed with the host's side.
    pub fn on_report(&mut self, stats: &mut MapStats) {
        if let Some(s) = self.swapper_mut() {
            s.on_report(stats);
        }
    }

    /// The map's counters read back now, completed with the swapper's host side (what a
    /// frame's report carries); `None` for a dense box, which keeps none.
    pub async fn stats(&self, gpu: &Gpu) -> Result<Option<MapStats>> {
        let Some(sparse) = self.sparse() else { return Ok(None) };
        let mut stats = sparse.stats(gpu).await?;
        if let Some(s) = self.swapper() {
            s.fill_stats(&mut stats);
        }
        Ok(Some(stats))
    }

    /// Takes completed swap-out lists into host memory (never waits).
    pub fn poll(&mut self, gpu: &Gpu) -> Result<()> {
        match self.swapper_mut() {
            Some(s) => s.poll(gpu),
            None => Ok(()),
        }
    }

    /// Waits for swap-out lists in flight.
    pub async fn flush(&mut self, gpu: &Gpu) -> Result<()> {
        match self.swapper_mut() {
            Some(s) => s.flush(gpu).await,
            None => Ok(()),
        }
    }

    /// Forgets the model (and the blocks on the host).
    pub fn reset(&mut self, gpu: &Gpu) {
        self.map.reset(gpu);
        if let Some(s) = self.swapper_mut() {
            s.reset();
        }
    }

    /// Every block of the map, sorted by block key: a sparse map's on the GPU and on the host,
    /// a dense box's observed 8³ tiles. Waits for the GPU and for swap-outs in flight.
    pub async fn download_blocks(&mut self, gpu: &Gpu) -> Result<Vec<MapBlock>> {
        self.flush(gpu).await?;
        let sparse = match &self.map {
            Map::Dense(dense) => return crate::map::dense_blocks(gpu, dense).await,
            Map::Sparse(sparse) => sparse,
        };
        let mut blocks = sparse.download_blocks(gpu).await?;
        if let Some(s) = self.swapper() {
            let resident: std::collections::HashSet<[u32; 3]> = blocks.iter().map(|b| b.coords).collect();
            blocks.extend(s.host_blocks().filter(|b| !resident.contains(&b.coords)));
            blocks.sort_by_key(|b| crate::cpu::shared::block_key(b.coords));
        }
        Ok(blocks)
    }

    /// Replaces the map's contents with `blocks` (a saved map). A sparse map keeps on the GPU
    /// the blocks a camera at `near` may see first (its fetch region), then the nearest, up to
    /// the swapping mark of its pool (the blocks' order without a pose), and gives the rest to
    /// the host (swapped back in as the camera comes near); without swapping, more blocks than
    /// the pool is an error.
    pub fn upload_blocks(&mut self, gpu: &Gpu, mut blocks: Vec<MapBlock>, near: Option<&Se3>) -> Result<()> {
        let (sparse, swapper) = match (&self.map, &mut self.integration) {
            (Map::Dense(dense), _) => return crate::map::upload_dense_blocks(gpu, dense, &blocks),
            (Map::Sparse(sparse), Integration::Sparse { swapper, .. }) => (sparse, swapper),
            (Map::Sparse(_), Integration::Dense { .. }) => unreachable!("a sparse map has sparse integration"),
        };
        let d = sparse.desc();
        let room = match swapper {
            Some(s) => ((s.config().evict_above * d.pool_blocks as f32) as usize).max(1),
            None => d.pool_blocks as usize,
        };
        if let Some(pose) = near {
            // Blocks the camera may see first (the swapper's fetch region), then by distance.
            let c = pose.translation_m.as_vec3().to_array();
            let axis = (pose.rotation * glam::DVec3::Z).as_vec3().to_array();
            let fetch = swapper.as_ref().map(|s| s.fetch_region());
            let priority = |b: &MapBlock| {
                let (centre, radius_m) = crate::cpu::map::block_swap_out::block_centre(&d, b.coords);
                let v: [f32; 3] = std::array::from_fn(|i| centre[i] - c[i]);
                let outside = fetch.is_some_and(|f| !f.contains(v, axis, radius_m));
                (outside, v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
            };
            blocks.sort_by(|a, b| {
                let (pa, pb) = (priority(a), priority(b));
                pa.0.cmp(&pb.0).then(pa.1.total_cmp(&pb.1))
            });
        }
        let rest = if blocks.len() > room { blocks.split_off(room) } else { Vec::new() };
        match swapper {
            Some(s) => {
                s.reset();
                let keys: Vec<[u32; 3]> = rest.iter().map(|b| b.coords).collect();
                sparse.upload_blocks_swapped(gpu, &blocks, &keys)?;
                s.store_blocks(rest);
                s.assume_resident(blocks.len() as u32);
            }
            None if !rest.is_empty() => {
                sparse.reset(gpu);
                return Err(crate::Error::InvalidConfig(format!("the map holds {} blocks, more than the pool of {} (allow swapping, or a larger budget)", blocks.len() + rest.len(), d.pool_blocks)));
            }
            None => sparse.upload_blocks(gpu, &blocks)?,
        }
        Ok(())
    }

    /// The map's mesh: of every block, on the GPU and (a swapping map's) on the host. Waits for
    /// the GPU.
    pub async fn extract_mesh(&mut self, gpu: &Gpu) -> Result<crate::mesh::Mesh> {
        self.flush(gpu).await?;
        let on_host = self.swapper().map_or(0, |s| s.blocks_on_host());
        match &self.map {
            Map::Sparse(sparse) if on_host > 0 => {
                let (config, origin) = (*sparse.config(), sparse.origin_in_world());
                let blocks = self.download_blocks(gpu).await?;
                crate::map::mesh_of_blocks(gpu, &config, origin, &blocks).await
            }
            map => crate::mesh::extract_mesh(gpu, map).await,
        }
    }

    /// Records the integration as stage `stage` of a frame (skipped on the GPU when the pose
    /// is disabled). A sparse map first clears its visible count, then swaps in what
    /// [`Self::prepare_frame`] planned, allocates, assigns, lists the visible blocks,
    /// integrates them and swaps out what lies outside the kept region (while the pool is
    /// above its mark), copying the swap-out list for the host.
    pub fn encode(&self, gpu: &Gpu, frame: &mut FrameEncoder<'_>, stage: &'static str) {
        if let Map::Sparse(sparse) = &self.map {
            Self::clear_visible_count(frame, sparse);
            if let Some(s) = self.swapper() {
                s.encode_clear(frame, sparse.counters());
            }
        }
        self.record(gpu, &mut frame.stage(stage));
        if let (Map::Sparse(sparse), Some(s)) = (&self.map, self.swapper()) {
            s.encode_readback(frame, sparse.counters());
        }
    }

    /// Records one part of the integration alone as stage `stage` (what `bench` times; each
    /// part reads what the earlier ones wrote, so run alone on a fused map they time the same
    /// work as in a frame). A dense map has only [`IntegratePart::Blocks`].
    pub fn encode_part(&self, gpu: &Gpu, frame: &mut FrameEncoder<'_>, stage: &'static str, part: IntegratePart) {
        if let (Map::Sparse(sparse), IntegratePart::Visible) = (&self.map, part) {
            Self::clear_visible_count(frame, sparse);
        }
        self.record_part(gpu, &mut frame.stage(stage), part);
    }

    /// Clears a sparse map's visible count, before the pass that lists the visible blocks.
    fn clear_visible_count(frame: &mut FrameEncoder<'_>, sparse: &SparseMap) {
        let visible_word = (crate::cpu::shared::MAP_COUNTER_VISIBLE * 4) as u64;
        frame.encoder().clear_buffer(sparse.counters(), visible_word, Some(4));
    }

    /// Records the integration into an open compute pass, after [`Self::encode`] cleared a
    /// sparse map's visible count: a sparse map's swap-in, its parts in order, its swap-out.
    fn record(&self, gpu: &Gpu, pass: &mut wgpu::ComputePass<'_>) {
        let swapper = self.swapper();
        if let Some(s) = swapper {
            s.record_in(gpu, pass);
        }
        for part in [IntegratePart::Allocate, IntegratePart::Visible, IntegratePart::Blocks] {
            self.record_part(gpu, pass, part);
        }
        if let Some(s) = swapper {
            s.record_out(gpu, pass);
        }
    }

    /// Records one part of the integration into an open compute pass.
    fn record_part(&self, gpu: &Gpu, pass: &mut wgpu::ComputePass<'_>, part: IntegratePart) {
        let d = self.map.desc();
        match (&self.integration, &self.map) {
            (Integration::Dense { bind_group }, _) => {
                if part == IntegratePart::Blocks {
                    gpu.kernels.tsdf_integrate.dispatch_in(pass, bind_group, [d.dim_x, d.dim_y, 1]);
                }
            }
            (Integration::Sparse { alloc, assign, tiles, visible, args, integrate, .. }, map) => match part {
                IntegratePart::Allocate => {
                    let [w, h] = self.image_size;
                    gpu.kernels.block_alloc.dispatch_in(pass, alloc, [w, h, 1]);
                    gpu.kernels.block_assign.dispatch_in(pass, assign, [d.hash_slots, 1, 1]);
                }
                IntegratePart::Visible => {
                    gpu.kernels.depth_tile_max.dispatch_in(pass, &tiles.0, [tiles.1, 1, 1]);
                    gpu.kernels.block_visible.dispatch_in(pass, visible, [d.pool_blocks, 1, 1]);
                    gpu.kernels.block_list_args.dispatch_in(pass, args, [1, 1, 1]);
                }
                IntegratePart::Blocks => {
                    if let Map::Sparse(sparse) = map {
                        block_integrate::dispatch_indirect_in(gpu, pass, integrate, sparse.counters());
                    }
                }
            },
        }
    }
}

/// The parts of an integration, in the order a frame records them.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum IntegratePart {
    /// A sparse map's allocation: `block_alloc` (the blocks every pixel's truncation band
    /// crosses) and `block_assign` (pool blocks for new keys).
    Allocate,
    /// A sparse map's visible list: `depth_tile_max`, `block_visible`, `block_list_args`.
    Visible,
    /// The voxel update: `block_integrate` over the visible blocks, or the dense box's
    /// `tsdf_integrate`.
    Blocks,
}


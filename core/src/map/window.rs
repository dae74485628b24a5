// SPDX-License-Identifier: MIT
//! Rendering a saved sparse map larger than the GPU pool (a room at 1 cm is 75-100k blocks; a
//! 128 MiB storage binding holds 65,536): the host keeps every block, and before each view the
//! pool holds a window of them that contains every block the view can read.
//!
//! What a view reads is bounded by geometry: the raycast's rays leave the camera centre inside
//! the image's cone (half-angle θ: the widest pixel's ray) and stop at the sensor's farthest
//! depth, i.e. within `max_depth / cos θ` of the centre; a trilinear sample or the colour
//! lookup reads voxels at most one voxel beyond the ray. So a block whose bounding sphere,
//! grown by two voxels, misses that truncated cone is never read. Where each ray starts comes
//! from its tile's depth interval (`raycast_range`), which a surface brick widens wherever the
//! bounding rectangle of its projection reaches, so the window also holds every block whose
//! footprint reaches the image: then a view renders exactly as it would with the whole map on
//! the GPU. (The sensor model after the raycast, projector shadows included, works on the
//! rendered images, not on the map.)
//!
//! [`ViewedMap::prepare`] checks the view's blocks against the window; when one is missing it
//! uploads a new window: the view's blocks, then the others nearest the camera centre until
//! the pool is full, so the next views of a trajectory (or a planner's nearby queries) usually
//! find theirs resident and cost nothing more. A new window keeps the blocks it shares with
//! the old one in their pool blocks and writes only the voxels of the blocks that enter
//! ([`SparseMap::replace_blocks`]; the hash table, keys and surface words are written whole).
//! A view that by itself reaches more blocks than the pool holds is a typed error
//! ([`Error::ViewExceedsPool`]), never a silently partial image. A map that fits the pool is
//! uploaded once, as before.
//!
//! A view for looking at the map (the page's free view of a map too big for the device) may
//! instead ask for the nearest of its blocks ([`ViewedMap::prepare_nearest`]): the pool then
//! holds the view's blocks nearest the camera centre, and the view is exact within a reported
//! distance ([`NearestWindow::complete_within_m`]): a ray's samples within that distance of the
//! centre read only resident blocks. Beyond it surfaces may be missing; the caller says so.

use glam::DVec3;

use super::file::MapFileHeader;
use super::{Map, MapBlock, SparseMap, max_pool_blocks, resident_map, saved_map_config};
use crate::cpu::fusion::raycast_range::brick_footprint;
use crate::cpu::map::block_swap_out::block_centre;
use crate::kernels::GpuIntrinsics;
use crate::tsdf::{MapKind, TsdfStore, VolumeDesc};
use crate::{Error, Gpu, PinholeIntrinsics, Result, Se3};

/// The part of space a view of a map can read: a cone about the optical axis, from the camera
/// centre to `reach_m`, for a camera with `intrinsics` searching `depth_range_m`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ViewCone {
    /// The angle between the optical axis and the widest pixel ray, radians.
    pub half_angle_rad: f64,
    /// The farthest any ray goes, metres.
    pub reach_m: f64,
    /// The camera.
    pub intrinsics: PinholeIntrinsics,
    /// The nearest and farthest depth (along the optical axis) the rays search, metres.
    pub depth_range_m: (f32, f32),
}

impl ViewCone {
    /// The cone of a camera with intrinsics `k` searching depths `depth_range_m` (along the
    /// optical axis): the widest ray through the image's outer pixel edges, as far as the
    /// farthest depth along it.
    pub fn for_camera(k: &PinholeIntrinsics, depth_range_m: (f32, f32)) -> Self {
        let (fx, fy) = (f64::from(k.fx_px), f64::from(k.fy_px));
        let xs = [-0.5, f64::from(k.width_px) - 0.5].map(|x| (x - f64::from(k.cx_px)) / fx);
        let ys = [-0.5, f64::from(k.height_px) - 0.5].map(|y| (y - f64::from(k.cy_px)) / fy);
        let tan = xs.iter().flat_map(|x| ys.iter().map(move |y| x.hypot(*y))).fold(0.0, f64::max);
        let half_angle_rad = tan.atan();
        Self { half_angle_rad, reach_m: f64::from(depth_range_m.1) / half_angle_rad.cos(), intrinsics: *k, depth_range_m }
    }

    /// Whether `raycast_range` would let the box `lo`..`hi` (world metres) widen a tile of the
    /// view from `camera_from_world` (its footprint, `cpu::fusion::raycast_range::brick_footprint`,
    /// over an image a pixel wider on every side and a depth range 1 % wider, so that rounding
    /// never leaves out a box the kernel counts). A box the cone misses can still cover a tile
    /// with the bounding rectangle of its projection, and a tile's interval sets where its rays
    /// start: the window holds such boxes too, so the rays march exactly as with the whole map.
    fn widens_a_tile(&self, camera_from_world: &[[f32; 4]; 4], lo: [f32; 3], hi: [f32; 3]) -> bool {
        let k = &self.intrinsics;
        let grown = PinholeIntrinsics { cx_px: k.cx_px + 1.0, cy_px: k.cy_px + 1.0, width_px: k.width_px + 2, height_px: k.height_px + 2, ..*k };
        let range = (0.99 * self.depth_range_m.0, 1.01 * self.depth_range_m.1);
        brick_footprint(&GpuIntrinsics::from(grown), camera_from_world, range, lo, hi).is_some()
    }

    /// Whether a sphere of radius `radius_m` centred `v` from the camera centre (`axis` the
    /// unit optical axis) meets the cone: within the reach of the centre, and at an angle to the
    /// axis of at most the half-angle plus the angle the sphere subtends (exact for a sphere
    /// and a cone; a sphere holding the centre always meets it).
    pub fn meets_sphere(&self, v: DVec3, axis: DVec3, radius_m: f64) -> bool {
        self.miss_by(v, axis, radius_m) <= 0.0
    }

    /// How far the sphere of [`Self::meets_sphere`] misses the cone: the angle (radians) the
    /// cone would have to widen by to meet it, plus the distance past its reach as a fraction of
    /// the reach; zero or less when it meets it. Windows rank the blocks a view does not need by
    /// it, so that the next views of a turning or walking camera find theirs resident.
    pub fn miss_by(&self, v: DVec3, axis: DVec3, radius_m: f64) -> f64 {
        let dist = v.length();
        if dist <= radius_m {
            return 0.0;
        }
        let angle = (v.dot(axis) / dist).clamp(-1.0, 1.0).acos();
        let widen_rad = (angle - self.half_angle_rad - (radius_m / dist).asin()).max(0.0);
        let beyond = (dist - radius_m - self.reach_m).max(0.0) / self.reach_m;
        widen_rad + beyond
    }
}

/// A saved map's blocks on the host, and the window of them the GPU pool holds.
#[derive(Debug)]
pub struct MapWindow {
    /// Every block; the first `resident` are the ones in the pool.
    blocks: Vec<MapBlock>,
    /// Centre of each block (same order), world metres.
    centres: Vec<DVec3>,
    /// Bounding-sphere radius of a block plus the two voxels beyond a ray a view reads, metres.
    radius_m: f64,
    /// A block's edge, metres.
    block_edge_m: f64,
    /// How many of `blocks` (a prefix) the pool holds.
    resident: usize,
    /// Blocks the pool holds at most.
    capacity: usize,
    /// Windows uploaded so far.
    uploads: u64,
    /// Blocks whose voxels were written to the pool so far (a new window writes only the blocks
    /// that enter it).
    blocks_written: u64,
    /// The view the resident window was planned for when it could not hold all of that view's
    /// blocks ([`Self::prepare_nearest`]); `None` when it holds every block of its view.
    partial: Option<PartialView>,
}

/// A view a window holds only the nearest blocks of.
#[derive(Clone, Copy, Debug, PartialEq)]
struct PartialView {
    world_from_camera: Se3,
    cone: ViewCone,
    window: NearestWindow,
}

/// What [`MapWindow::prepare_nearest`] made resident for a view.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NearestWindow {
    /// Whether a new window was uploaded.
    pub uploaded: bool,
    /// Blocks the view may read that the pool could not hold (0: the view is exact).
    pub left_out: usize,
    /// Every block the view's rays read within this distance of the camera centre is resident,
    /// metres (infinite when nothing was left out): the view is exact for surfaces nearer.
    pub complete_within_m: f64,
}

impl NearestWindow {
    const COMPLETE: Self = Self { uploaded: false, left_out: 0, complete_within_m: f64::INFINITY };
}

/// A new window: the blocks (indices, in upload order) and what of the view it leaves out.
struct Plan {
    order: Vec<usize>,
    left_out: usize,
    complete_within_m: f64,
}

impl MapWindow {
    /// A window of `capacity` blocks over `blocks` of a map described by `desc`; nothing is
    /// resident until the first [`Self::prepare`].
    pub fn new(desc: &VolumeDesc, blocks: Vec<MapBlock>, capacity: usize) -> Self {
        let centres = blocks
            .iter()
            .map(|b| {
                let (c, _) = block_centre(desc, b.coords);
                DVec3::new(f64::from(c[0]), f64::from(c[1]), f64::from(c[2]))
            })
            .collect();
        let (_, half_diagonal_m) = block_centre(desc, [0; 3]);
        let radius_m = f64::from(half_diagonal_m) + 2.0 * f64::from(desc.voxel_size_m);
        let block_edge_m = f64::from(desc.voxel_size_m) * f64::from(1u32 << crate::cpu::shared::BRICK_SHIFT);
        Self { blocks, centres, radius_m, block_edge_m, resident: 0, capacity, uploads: 0, blocks_written: 0, partial: None }
    }

    /// Which blocks the pool must hold for the view at `world_from_camera` bounded by `cone`:
    /// `None` when it holds them already, else the new window as indices into `blocks`: the
    /// view's blocks, then the others by how far they miss its cone ([`ViewCone::miss_by`]; the
    /// nearer first among equals), up to the capacity. Errors when the view alone needs more
    /// than the pool holds, unless `nearest_first`: then the window holds the view's blocks
    /// nearest the camera centre, as many as fit.
    fn plan(&self, world_from_camera: &Se3, cone: &ViewCone, nearest_first: bool) -> Result<Option<Plan>> {
        let centre = world_from_camera.translation_m;
        let axis = world_from_camera.rotation * DVec3::Z;
        let camera_from_world = world_from_camera.inverse().to_cols_f32();
        let half_edge_m = 0.5 * self.block_edge_m;
        // How far block i misses the view: 0 when the view may read it.
        let miss = |i: usize| {
            let c = self.centres[i];
            let miss = cone.miss_by(c - centre, axis, self.radius_m);
            let (lo, hi) = ((c - DVec3::splat(half_edge_m)).as_vec3().to_array(), (c + DVec3::splat(half_edge_m)).as_vec3().to_array());
            if miss > 0.0 && cone.widens_a_tile(&camera_from_world, lo, hi) { 0.0 } else { miss.max(0.0) }
        };
        // The window holds the view when no block outside it is needed.
        if self.uploads > 0 && (self.resident..self.blocks.len()).all(|i| miss(i) > 0.0) {
            return Ok(None);
        }
        let miss: Vec<f64> = (0..self.blocks.len()).map(miss).collect();
        let needed = (0..self.blocks.len()).filter(|&i| miss[i] <= 0.0);
        let view_blocks = needed.count();
        if view_blocks > self.capacity && !nearest_first {
            return Err(Error::ViewExceedsPool { view_blocks, pool_blocks: self.capacity });
        }
        let mut order: Vec<usize> = (0..self.blocks.len()).collect();
        let distance = |i: usize| (self.centres[i] - centre).length_squared();
        order.sort_by(|&a, &b| miss[a].total_cmp(&miss[b]).then(distance(a).total_cmp(&distance(b))));
        // The view's blocks come first, nearest first: those past the capacity are left out,
        // and the nearest of them bounds where the view is complete (a sample within
        // `radius_m` of a block's centre may read it).
        let left_out = view_blocks.saturating_sub(self.capacity);
        let complete_within_m = match left_out {
            0 => f64::INFINITY,
            _ => (distance(order[self.capacity]).sqrt() - self.radius_m).max(0.0),
        };
        order.truncate(self.capacity);
        Ok(Some(Plan { order, left_out, complete_within_m }))
    }

    /// Puts the blocks `resident` (indices, each once) first in that order, the others after
    /// them in their present order, and makes the first ones the resident prefix.
    fn make_resident(&mut self, resident: Vec<usize>) {
        let mut first = vec![false; self.blocks.len()];
        for &i in &resident {
            first[i] = true;
        }
        self.resident = resident.len();
        let mut order = resident;
        order.extend((0..self.blocks.len()).filter(|&i| !first[i]));
        let mut blocks: Vec<Option<MapBlock>> = std::mem::take(&mut self.blocks).into_iter().map(Some).collect();
        self.blocks = order.iter().map(|&i| blocks[i].take().expect("each index once")).collect();
        self.centres = order.iter().map(|&i| self.centres[i]).collect();
    }

    /// Makes the pool of `map` hold every block the view at `world_from_camera` bounded by
    /// `cone` may read, uploading a new window when it does not. Returns whether it uploaded.
    pub fn prepare(&mut self, gpu: &Gpu, map: &SparseMap, world_from_camera: &Se3, cone: &ViewCone) -> Result<bool> {
        let Some(plan) = self.plan(world_from_camera, cone, false)? else {
            return Ok(false);
        };
        self.upload(gpu, map, &plan.order)?;
        self.partial = None;
        Ok(true)
    }

    /// Like [`Self::prepare`], but a view that alone reaches more blocks than the pool holds
    /// gets the nearest of them (see [`NearestWindow`]) instead of an error. The same view
    /// asked for again keeps its window.
    pub fn prepare_nearest(&mut self, gpu: &Gpu, map: &SparseMap, world_from_camera: &Se3, cone: &ViewCone) -> Result<NearestWindow> {
        if let Some(p) = self.partial.filter(|p| p.world_from_camera == *world_from_camera && p.cone == *cone) {
            return Ok(NearestWindow { uploaded: false, ..p.window });
        }
        let Some(plan) = self.plan(world_from_camera, cone, true)? else {
            return Ok(NearestWindow::COMPLETE);
        };
        self.upload(gpu, map, &plan.order)?;
        let window = NearestWindow { uploaded: true, left_out: plan.left_out, complete_within_m: plan.complete_within_m };
        self.partial = (plan.left_out > 0).then_some(PartialView { world_from_camera: *world_from_camera, cone: *cone, window });
        Ok(window)
    }

    /// Makes `window` (indices into `blocks`) the pool's content: when the pool is full and
    /// stays full, the blocks it keeps stay in their pool blocks and only those entering are
    /// written; otherwise the pool is uploaded whole.
    fn upload(&mut self, gpu: &Gpu, map: &SparseMap, window: &[usize]) -> Result<()> {
        let result = if self.resident == self.capacity && window.len() == self.capacity {
            let replaced = self.reorder_keeping(window);
            self.blocks_written += replaced.len() as u64;
            map.replace_blocks(gpu, &self.blocks[..self.resident], &replaced)
        } else {
            self.make_resident(window.to_vec());
            self.blocks_written += self.resident as u64;
            map.upload_blocks(gpu, &self.blocks[..self.resident])
        };
        if let Err(e) = result {
            // The pool's contents are undefined (an upload empties it first): nothing is
            // resident, and the next view plans again and uploads whole.
            self.resident = 0;
            self.partial = None;
            return Err(e);
        }
        self.uploads += 1;
        Ok(())
    }

    /// Like [`Self::make_resident`] for a full pool that stays full: a block of `window` already
    /// resident keeps its place, and the blocks entering take the places of those leaving.
    /// Returns those places (the pool blocks to write).
    fn reorder_keeping(&mut self, window: &[usize]) -> Vec<usize> {
        let mut in_window = vec![false; self.blocks.len()];
        for &i in window {
            in_window[i] = true;
        }
        let mut entering = window.iter().copied().filter(|&i| i >= self.resident);
        let mut resident = Vec::with_capacity(self.resident);
        let mut replaced = Vec::new();
        for (slot, &kept) in in_window.iter().enumerate().take(self.resident) {
            if kept {
                resident.push(slot);
            } else {
                resident.push(entering.next().expect("as many blocks enter as leave"));
                replaced.push(slot);
            }
        }
        self.make_resident(resident);
        replaced
    }

    /// Windows uploaded so far.
    pub fn uploads(&self) -> u64 {
        self.uploads
    }

    /// Blocks whose voxels were written to the pool so far.
    pub fn blocks_written(&self) -> u64 {
        self.blocks_written
    }

    /// Blocks the pool holds at most.
    pub fn capacity(&self) -> usize {
        self.capacity
    }

    /// Blocks of the whole map (on the host).
    pub fn blocks(&self) -> usize {
        self.blocks.len()
    }
}

/// A saved map made ready for rendering views: wholly on the GPU when its blocks fit one
/// pool, else a [`MapWindow`] over them.
#[derive(Debug)]
pub struct ViewedMap {
    map: Map,
    /// The blocks of a map held whole on the GPU (a windowed map's are in its window).
    blocks: Vec<MapBlock>,
    window: Option<MapWindow>,
}

impl ViewedMap {
    /// Loads `blocks` of the map `header` describes. A sparse map gets a pool of at most
    /// `max_pool` blocks (`None`: the largest the device binds); more blocks than that are
    /// windowed.
    pub fn load(gpu: &Gpu, header: &MapFileHeader, blocks: Vec<MapBlock>, max_pool: Option<u32>) -> Result<Self> {
        let largest = max_pool_blocks(gpu.limits.max_storage_buffer_binding_size);
        let capacity = max_pool.map_or(largest, |p| p.min(largest)).max(1);
        if header.kind == MapKind::Dense || blocks.len() <= capacity as usize {
            return Ok(Self { map: resident_map(gpu, header, &blocks)?, blocks, window: None });
        }
        let sparse = SparseMap::new(gpu, saved_map_config(header, capacity), header.origin_in_world)?;
        let window = MapWindow::new(&sparse.desc(), blocks, capacity as usize);
        Ok(Self { map: Map::Sparse(sparse), blocks: Vec::new(), window: Some(window) })
    }

    /// Makes the GPU hold every block the view at `world_from_camera` bounded by `cone` may
    /// read (a new window when a windowed map's pool does not). Returns whether it uploaded.
    pub fn prepare(&mut self, gpu: &Gpu, world_from_camera: &Se3, cone: &ViewCone) -> Result<bool> {
        match (&mut self.window, &self.map) {
            (Some(window), Map::Sparse(sparse)) => window.prepare(gpu, sparse, world_from_camera, cone),
            _ => Ok(false),
        }
    }

    /// Like [`Self::prepare`], for a view that only looks at the map: when it alone reaches more
    /// blocks than the pool holds, the pool holds the nearest of them ([`NearestWindow`]).
    pub fn prepare_nearest(&mut self, gpu: &Gpu, world_from_camera: &Se3, cone: &ViewCone) -> Result<NearestWindow> {
        match (&mut self.window, &self.map) {
            (Some(window), Map::Sparse(sparse)) => window.prepare_nearest(gpu, sparse, world_from_camera, cone),
            _ => Ok(NearestWindow::COMPLETE),
        }
    }

    /// The map to render (call [`Self::prepare`] for each view first).
    pub fn map(&self) -> &Map {
        &self.map
    }

    /// The window, when the map is larger than its pool.
    pub fn window(&self) -> Option<&MapWindow> {
        self.window.as_ref()
    }

    /// The map's blocks, given back (a windowed map's in the window's order).
    pub fn into_blocks(self) -> Vec<MapBlock> {
        match self.window {
            Some(window) => window.blocks,
            None => self.blocks,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn kinect() -> PinholeIntrinsics {
        PinholeIntrinsics { fx_px: 525.0, fy_px: 525.0, cx_px: 319.5, cy_px: 239.5, width_px: 640, height_px: 480 }
    }

    #[test]
    fn the_cone_holds_the_corner_rays_and_the_farthest_depth() {
        let cone = ViewCone::for_camera(&kinect(), (0.4, 4.0));
        // The corner pixel's outer edge: 320 px and 240 px off the centre at f = 525.
        let corner = DVec3::new(320.0 / 525.0, 240.0 / 525.0, 1.0);
        assert!((cone.half_angle_rad - (corner.x.hypot(corner.y)).atan()).abs() < 1e-12);
        assert!((cone.reach_m - 4.0 * corner.length()).abs() < 1e-9);
        // A point on the corner ray at 4 m depth lies on the cone's edge; a sphere there meets it.
        let p = corner * 4.0;
        assert!(cone.meets_sphere(p, DVec3::Z, 1e-6));
        // Behind the camera, beside it beyond the cone, or past the reach (the corner ray's
        // length at the farthest depth, 5.0 m, in every direction of the cone): missed.
        assert!(!cone.meets_sphere(DVec3::new(0.0, 0.0, -1.0), DVec3::Z, 0.1));
        assert!(!cone.meets_sphere(DVec3::new(2.0, 0.0, 0.5), DVec3::Z, 0.1));
        assert!(!cone.meets_sphere(DVec3::new(0.0, 0.0, cone.reach_m + 0.11), DVec3::Z, 0.1));
        assert!(cone.meets_sphere(DVec3::new(0.0, 0.0, cone.reach_m + 0.09), DVec3::Z, 0.1));
        // A sphere holding the centre, or reaching into the cone from beside it: met.
        assert!(cone.meets_sphere(DVec3::new(0.05, 0.0, -0.05), DVec3::Z, 0.1));
        // Beside the cone: the sphere meets it exactly when it reaches the cone's surface,
        // |v| sin(φ − θ) away (φ its angle to the axis).
        let beside = DVec3::new(1.5, 0.0, 1.0);
        let gap = beside.length() * (beside.x.atan2(beside.z) - cone.half_angle_rad).sin();
        assert!(cone.meets_sphere(beside, DVec3::Z, gap + 0.01));
        assert!(!cone.meets_sphere(beside, DVec3::Z, gap - 0.01));
    }
}

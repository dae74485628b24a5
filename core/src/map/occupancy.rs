// SPDX-License-Identifier: MIT
//! Seed 000's occupancy grid, with three states: occupied, free, and never observed.
//!
//! A TSDF knows space only near surfaces (within the truncation μ); a planner also needs to
//! know which of the rest was seen empty, and must never take unseen space for empty. So each
//! cell of the grid ([`GridSpec`]: x fastest, then y, then z, its centre at a chosen point of
//! the map's frame) gets one byte:
//!
//! - [`OCCUPIED`] (255): the map observed a surface within the cell, or the inside just behind
//!   one: the TSDF at the voxel nearest the cell's centre is observed and at most
//!   `(√3/2)·(cell + voxel)` in front of the surface (the TSDF is 1-Lipschitz, so no smaller
//!   value can put the surface outside the cell), or behind it.
//! - [`FREE`] (0): observed empty. Either the TSDF there is observed and farther in front of the
//!   surface than that, or the cell lies wholly in front of the surface that a view of the map
//!   ([`CarveView`], the map rendered at a pose it was fused from) sees along every ray through
//!   the cell, by more than μ (nearer than μ the TSDF band decides): light from that surface
//!   crossed it. A view's pixels without a return carve nothing.
//! - [`UNKNOWN`] (128): everything else: behind surfaces, outside every view, beyond range.
//!
//! Carving is conservative: a cell is carved by projection (its bounding sphere's footprint in
//! the view's depth image, whose minimum comes from a min-pyramid in at most 3x3 texels), and
//! whole 8³-cell bricks are settled at once where the footprint's minimum and maximum depths
//! allow (wholly in front: free; wholly behind every surface: untouched). A cell in the image
//! the footprint cannot settle (near a surface seen at an angle, whose footprint's nearest
//! depth is another ray's) is tested ray by ray: free when every pixel ray through it has a
//! return beyond the point where it leaves the cell, by more than μ.

use glam::DVec3;

use crate::cpu::shared::{voxel_anchor, voxel_in_block, voxel_tsdf, voxel_weight};
use crate::map::MapBlock;
use crate::map::file::MapFileHeader;
use crate::{Error, PinholeIntrinsics, Result, Se3};

/// A cell the map observed a surface in (or just behind one).
pub const OCCUPIED: u8 = 255;
/// A cell observed empty.
pub const FREE: u8 = 0;
/// A cell never observed: not known to be free.
pub const UNKNOWN: u8 = 128;

/// Largest grid, cells (4 GiB of bytes).
pub const MAX_GRID_CELLS: u64 = 1 << 32;

/// Cells along each edge of the bricks carving settles at once.
const BRICK_CELLS: u32 = 8;

/// Where the grid lies: `dims` cells of `cell_m` along x, y, z of the map's frame, the grid's
/// centre at `center_m`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GridSpec {
    /// Cells along x, y and z.
    pub dims: [u32; 3],
    /// Cell edge, metres.
    pub cell_m: f64,
    /// The grid's centre in the map's frame, metres.
    pub center_m: [f64; 3],
}

impl GridSpec {
    /// Seed 000's grid: 1024 x 1024 x 480 cells of 1 cm (10.24 x 10.24 x 4.8 m) centred on the
    /// origin.
    pub const SEED_000: Self = Self { dims: [1024, 1024, 480], cell_m: 0.01, center_m: [0.0; 3] };

    /// Refuses empty, non-finite or oversized grids, naming the problem.
    pub fn validate(&self) -> Result<()> {
        if self.dims.contains(&0) {
            return Err(Error::InvalidConfig(format!("grid dims {:?}: every axis needs at least one cell", self.dims)));
        }
        let cells = self.cell_count();
        if cells > MAX_GRID_CELLS {
            return Err(Error::InvalidConfig(format!("grid dims {:?}: {cells} cells, more than the {MAX_GRID_CELLS} (4 GiB) a grid may hold", self.dims)));
        }
        if !(self.cell_m.is_finite() && self.cell_m > 0.0) {
            return Err(Error::InvalidConfig(format!("grid cell size {} m must be finite and positive", self.cell_m)));
        }
        if !self.center_m.iter().all(|c| c.is_finite()) {
            return Err(Error::InvalidConfig(format!("grid centre {:?} must be finite", self.center_m)));
        }
        Ok(())
    }

    /// Cells in the grid.
    pub fn cell_count(&self) -> u64 {
        self.dims.iter().map(|&d| u64::from(d)).product()
    }

    /// The corner of cell (0, 0, 0): the grid's lowest x, y, z, metres.
    pub fn corner_m(&self) -> DVec3 {
        DVec3::from_array(self.center_m) - 0.5 * self.cell_m * DVec3::new(f64::from(self.dims[0]), f64::from(self.dims[1]), f64::from(self.dims[2]))
    }

    /// The centre of cell `(x, y, z)`, metres.
    pub fn cell_center(&self, x: u32, y: u32, z: u32) -> DVec3 {
        self.corner_m() + self.cell_m * (DVec3::new(f64::from(x), f64::from(y), f64::from(z)) + 0.5)
    }

    /// Index of cell `(x, y, z)` in the grid's bytes (x fastest).
    pub fn index(&self, x: u32, y: u32, z: u32) -> usize {
        (u64::from(x) + u64::from(self.dims[0]) * (u64::from(y) + u64::from(self.dims[1]) * u64::from(z))) as usize
    }
}

/// One view that carves free space: depth seen from a pose (in the map's frame) where the map
/// was observed, typically the map rendered there by the virtual sensor.
#[derive(Clone, Copy, Debug)]
pub struct CarveView<'a> {
    /// The camera's pose in the map's frame.
    pub world_from_camera: Se3,
    /// The depth image's camera.
    pub intrinsics: PinholeIntrinsics,
    /// Depth along z per pixel, metres, row-major; 0 or NaN where nothing was seen.
    pub depth_m: &'a [f32],
}

/// The grid and how many cells are in each state.
#[derive(Clone, Debug, PartialEq)]
pub struct OccupancyGrid {
    /// Where it lies.
    pub spec: GridSpec,
    /// One byte per cell ([`OCCUPIED`], [`FREE`], [`UNKNOWN`]), x fastest, then y, then z.
    pub cells: Vec<u8>,
}

/// Cells per state.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct OccupancyCounts {
    /// [`OCCUPIED`] cells.
    pub occupied: u64,
    /// [`FREE`] cells.
    pub free: u64,
    /// [`UNKNOWN`] cells.
    pub unknown: u64,
}

impl OccupancyGrid {
    /// The state of cell `(x, y, z)`.
    pub fn at(&self, x: u32, y: u32, z: u32) -> u8 {
        self.cells[self.spec.index(x, y, z)]
    }

    /// Cells per state.
    pub fn counts(&self) -> OccupancyCounts {
        let mut counts = OccupancyCounts::default();
        for &c in &self.cells {
            match c {
                OCCUPIED => counts.occupied += 1,
                FREE => counts.free += 1,
                _ => counts.unknown += 1,
            }
        }
        counts
    }

    /// Which pixels of a view looked through space this grid does not know to be free: the
    /// sensor's "the ray left observed space before it hit anything". A pixel's ray, from the
    /// camera at `world_from_camera` (the grid's frame) through the pixel of `k`, is sampled
    /// every half cell over the sensor's measuring range `range_m` (near, far; planar depths
    /// along z, or distances along the ray with `radial`): from the near end (a depth sensor
    /// sees nothing nearer, and no view carves the cells it stands in; at least √3 cells out)
    /// to √3 cells short of its hit, `hit_m[i]` (0 or NaN: no hit, then to the far end), so the
    /// surface's own band is not counted. The pixel is marked if a sample falls in an
    /// [`UNKNOWN`] cell or outside the grid. Rows are split over `threads`.
    pub fn rays_through_unknown(&self, k: PinholeIntrinsics, world_from_camera: &Se3, hit_m: &[f32], radial: bool, range_m: (f64, f64), threads: usize) -> Result<Vec<bool>> {
        if hit_m.len() != k.pixel_count() {
            return Err(Error::InvalidConfig(format!("{} depths for a {}x{} camera", hit_m.len(), k.width_px, k.height_px)));
        }
        let (near_m, far_m) = range_m;
        if !(near_m.is_finite() && far_m.is_finite() && near_m >= 0.0 && far_m > near_m) {
            return Err(Error::InvalidConfig(format!("the sensor's range [{near_m}, {far_m}] m is empty")));
        }
        let spec = &self.spec;
        let (corner, cell, guard) = (spec.corner_m(), spec.cell_m, 3_f64.sqrt() * spec.cell_m);
        let dims = spec.dims.map(i64::from);
        let eye = world_from_camera.translation_m;
        let ray_marks = |x: u32, y: u32, hit: f32| -> bool {
            let ray = DVec3::new((f64::from(x) - f64::from(k.cx_px)) / f64::from(k.fx_px), (f64::from(y) - f64::from(k.cy_px)) / f64::from(k.fy_px), 1.0);
            let along = ray.length();
            let to_ray = if radial { 1.0 } else { along };
            let end_m = if hit.is_finite() && hit > 0.0 { f64::from(hit) * to_ray - guard } else { far_m * to_ray };
            let dir = world_from_camera.rotation * (ray / along);
            let mut t = (near_m * to_ray).max(guard);
            while t <= end_m {
                let c = ((eye + t * dir - corner) / cell).floor();
                let (cx, cy, cz) = (c.x as i64, c.y as i64, c.z as i64);
                if cx < 0 || cy < 0 || cz < 0 || cx >= dims[0] || cy >= dims[1] || cz >= dims[2] {
                    return true;
                }
                if self.cells[spec.index(cx as u32, cy as u32, cz as u32)] == UNKNOWN {
                    return true;
                }
                t += 0.5 * cell;
            }
            false
        };
        let mut marks = vec![false; hit_m.len()];
        let width = k.width_px as usize;
        let rows_per_thread = (k.height_px as usize).div_ceil(threads.max(1)).max(1);
        std::thread::scope(|scope| {
            for (chunk_index, chunk) in marks.chunks_mut(rows_per_thread * width).enumerate() {
                let ray_marks = &ray_marks;
                scope.spawn(move || {
                    for (i, mark) in chunk.iter_mut().enumerate() {
                        let pixel = chunk_index * rows_per_thread * width + i;
                        *mark = ray_marks((pixel % width) as u32, (pixel / width) as u32, hit_m[pixel]);
                    }
                });
            }
        });
        Ok(marks)
    }
}

/// An occupancy grid being built: free space carved from views, then the TSDF's cells marked.
#[derive(Debug)]
pub struct OccupancyBuilder {
    spec: GridSpec,
    cells: Vec<u8>,
    threads: usize,
}

impl OccupancyBuilder {
    /// An all-unknown grid `spec`, built on `threads` threads (slabs along z).
    pub fn new(spec: &GridSpec, threads: usize) -> Result<Self> {
        spec.validate()?;
        Ok(Self { spec: *spec, cells: vec![UNKNOWN; spec.cell_count() as usize], threads: threads.max(1) })
    }

    /// Carves the cells that lie wholly in front of what each view sees by more than
    /// `margin_m` (the map's truncation μ: nearer the surface the TSDF decides).
    pub fn carve(&mut self, views: &[CarveView], margin_m: f64) -> Result<()> {
        for (i, view) in views.iter().enumerate() {
            if view.depth_m.len() != view.intrinsics.pixel_count() {
                return Err(Error::InvalidConfig(format!("carving view {i}: {} depths for a {}x{} camera", view.depth_m.len(), view.intrinsics.width_px, view.intrinsics.height_px)));
            }
        }
        let pyramids: Vec<ViewPyramid> = views.iter().map(ViewPyramid::new).collect();
        let spec = &self.spec;
        // Slabs of whole bricks along z, one per thread.
        let slab_bytes = spec.dims[0] as usize * spec.dims[1] as usize;
        let bricks_per_slab = spec.dims[2].div_ceil(BRICK_CELLS).div_ceil(self.threads as u32) as usize;
        std::thread::scope(|scope| {
            for (slab, chunk) in self.cells.chunks_mut(slab_bytes * BRICK_CELLS as usize * bricks_per_slab).enumerate() {
                let pyramids = &pyramids;
                scope.spawn(move || {
                    let z0 = (slab * bricks_per_slab) as u32 * BRICK_CELLS;
                    let z1 = z0 + (chunk.len() / slab_bytes) as u32;
                    for pyramid in pyramids {
                        carve(spec, pyramid, margin_m, z0..z1, chunk);
                    }
                });
            }
        });
        Ok(())
    }

    /// Marks what the saved map (`header`, `blocks`) observed and returns the grid.
    pub fn finish(mut self, header: &MapFileHeader, blocks: &[MapBlock]) -> OccupancyGrid {
        apply_tsdf(header, blocks, &self.spec, &mut self.cells);
        OccupancyGrid { spec: self.spec, cells: self.cells }
    }
}

/// The occupancy grid `spec` of the saved map (`header`, `blocks`), with free space carved from
/// `views` (none: only the TSDF band is known) beyond the map's truncation.
pub fn occupancy_grid(header: &MapFileHeader, blocks: &[MapBlock], spec: &GridSpec, views: &[CarveView], threads: usize) -> Result<OccupancyGrid> {
    let mut builder = OccupancyBuilder::new(spec, threads)?;
    builder.carve(views, f64::from(header.truncation_m))?;
    Ok(builder.finish(header, blocks))
}

/// Marks the cells the TSDF observed: occupied near or behind a surface, free farther in front.
fn apply_tsdf(header: &MapFileHeader, blocks: &[MapBlock], spec: &GridSpec, cells: &mut [u8]) {
    let anchor = voxel_anchor(&crate::map::saved_map_config(header, 1).desc(header.origin_in_world));
    let voxel_m = f64::from(header.voxel_size_m);
    let mu_m = f64::from(header.truncation_m);
    let origin = DVec3::from_array(header.origin_in_world.map(f64::from));
    let occupied_within_m = 0.5 * 3_f64.sqrt() * (spec.cell_m + voxel_m);
    let corner = spec.corner_m();
    for block in blocks {
        // The block's box in the world, and the cells whose centres fall in it.
        let lo_voxel = DVec3::from_array(block.coords.map(|c| f64::from(c * 8))) - DVec3::from_array(anchor.map(f64::from));
        let lo_m = origin + lo_voxel * voxel_m;
        let hi_m = lo_m + DVec3::splat(8.0 * voxel_m);
        let first = ((lo_m - corner) / spec.cell_m - 0.5).map(f64::ceil);
        let last = ((hi_m - corner) / spec.cell_m - 0.5).map(f64::ceil) - 1.0;
        let dims = DVec3::new(f64::from(spec.dims[0]), f64::from(spec.dims[1]), f64::from(spec.dims[2]));
        let first = first.max(DVec3::ZERO);
        let last = last.min(dims - 1.0);
        if first.cmpgt(last).any() {
            continue;
        }
        for z in first.z as u32..=last.z as u32 {
            for y in first.y as u32..=last.y as u32 {
                for x in first.x as u32..=last.x as u32 {
                    let p = spec.cell_center(x, y, z);
                    // The voxel whose cell holds p, within this block (clamped against rounding).
                    let v = ((p - lo_m) / voxel_m).floor().clamp(DVec3::ZERO, DVec3::splat(7.0));
                    let word = block.voxels[voxel_in_block(v.x as u32, v.y as u32, v.z as u32) as usize];
                    if voxel_weight(word) == 0 {
                        continue;
                    }
                    let sdf_m = f64::from(voxel_tsdf(word)) * mu_m;
                    cells[spec.index(x, y, z)] = if sdf_m <= occupied_within_m { OCCUPIED } else { FREE };
                }
            }
        }
    }
}

/// A view's depth as min and max pyramids (level L: a texel per 2^L x 2^L pixels), with the
/// camera's inverse pose.
struct ViewPyramid {
    camera_from_world: Se3,
    world_from_camera: Se3,
    k: PinholeIntrinsics,
    /// Per level: (width, height, min depths, max depths); no return reads as 0 in both.
    levels: Vec<(u32, u32, Vec<f32>, Vec<f32>)>,
}

impl ViewPyramid {
    fn new(view: &CarveView) -> Self {
        let k = view.intrinsics;
        let base: Vec<f32> = view.depth_m.iter().map(|&d| if d.is_finite() && d > 0.0 { d } else { 0.0 }).collect();
        let mut levels = vec![(k.width_px, k.height_px, base.clone(), base)];
        while levels.last().is_some_and(|(w, h, _, _)| *w > 1 || *h > 1) {
            let (w, h, mins, maxs) = levels.last().expect("a level");
            let (nw, nh) = (w.div_ceil(2), h.div_ceil(2));
            let (mut nmin, mut nmax) = (vec![f32::INFINITY; (nw * nh) as usize], vec![0.0_f32; (nw * nh) as usize]);
            for y in 0..*h {
                for x in 0..*w {
                    let (i, j) = ((y * w + x) as usize, ((y / 2) * nw + x / 2) as usize);
                    nmin[j] = nmin[j].min(mins[i]);
                    nmax[j] = nmax[j].max(maxs[i]);
                }
            }
            levels.push((nw, nh, nmin, nmax));
        }
        Self { camera_from_world: view.world_from_camera.inverse(), world_from_camera: view.world_from_camera, k, levels }
    }

    fn to_camera(&self, p_world: DVec3) -> DVec3 {
        self.camera_from_world.transform_point(p_world)
    }

    /// Where a sphere of `radius_m` around `p_camera` projects: the (min, max) depth over the
    /// pixels it can cover when that footprint lies wholly inside the image.
    fn footprint(&self, p_camera: DVec3, radius_m: f64) -> Footprint {
        let near = p_camera.z - radius_m;
        if near <= 1e-6 {
            return if p_camera.z + radius_m <= 0.0 { Footprint::Outside } else { Footprint::Partial };
        }
        let k = &self.k;
        let (fx, fy) = (f64::from(k.fx_px), f64::from(k.fy_px));
        // Pixel centres are at integer coordinates (`camera_ray`); a sphere's projection fits in
        // a square of half-side f·r/(z − r) about its centre's projection.
        let u = fx * p_camera.x / p_camera.z + f64::from(k.cx_px);
        let v = fy * p_camera.y / p_camera.z + f64::from(k.cy_px);
        let r_px = fx.max(fy) * radius_m / near;
        let (x0, x1, y0, y1) = ((u - r_px).floor(), (u + r_px).ceil(), (v - r_px).floor(), (v + r_px).ceil());
        let (w, h) = (f64::from(k.width_px - 1), f64::from(k.height_px - 1));
        if x1 < 0.0 || y1 < 0.0 || x0 > w || y0 > h {
            return Footprint::Outside;
        }
        if x0 < 0.0 || y0 < 0.0 || x1 > w || y1 > h {
            return Footprint::Partial;
        }
        let (x0, x1, y0, y1) = (x0 as u32, x1 as u32, y0 as u32, y1 as u32);
        // The coarsest level whose texels are no wider than the span: at most 3x3 texels cover
        // it, and they cover less than twice the span each way.
        let span = (x1 - x0).max(y1 - y0) + 1;
        let level = (span.ilog2() as usize).min(self.levels.len() - 1);
        let (w, _, mins, maxs) = &self.levels[level];
        let (mut lo, mut hi) = (f32::INFINITY, 0.0_f32);
        for ty in (y0 >> level)..=(y1 >> level) {
            for tx in (x0 >> level)..=(x1 >> level) {
                let i = (ty * w + tx) as usize;
                lo = lo.min(mins[i]);
                hi = hi.max(maxs[i]);
            }
        }
        Footprint::Inside { nearest_m: f64::from(lo), farthest_m: f64::from(hi) }
    }

    /// Whether every pixel ray through the world box [`lo_m`, `hi_m`] (a cell wholly in the
    /// image) has a return beyond the box by more than `margin_m`, and at least one does: the
    /// exact test behind the footprint's, for cells near a surface seen at an angle, where the
    /// footprint's nearest depth is a different ray's. Pixel (x, y)'s ray is the camera centre
    /// plus t·R·((x − cx)/fx, (y − cy)/fy, 1), so t is its camera depth; it meets the box over
    /// [t_in, t_out] (slabs), and only pixels whose centres the box's projection covers can.
    fn rays_clear_cell(&self, lo_m: DVec3, hi_m: DVec3, margin_m: f64) -> bool {
        let k = &self.k;
        let (fx, fy, cx, cy) = (f64::from(k.fx_px), f64::from(k.fy_px), f64::from(k.cx_px), f64::from(k.cy_px));
        let (mut u0, mut u1, mut v0, mut v1) = (f64::INFINITY, f64::NEG_INFINITY, f64::INFINITY, f64::NEG_INFINITY);
        for corner in 0..8 {
            let c = DVec3::new(if corner & 1 == 0 { lo_m.x } else { hi_m.x }, if corner & 2 == 0 { lo_m.y } else { hi_m.y }, if corner & 4 == 0 { lo_m.z } else { hi_m.z });
            let q = self.to_camera(c);
            if q.z <= 1e-6 {
                return false;
            }
            let (u, v) = (fx * q.x / q.z + cx, fy * q.y / q.z + cy);
            (u0, u1, v0, v1) = (u0.min(u), u1.max(u), v0.min(v), v1.max(v));
        }
        let (x0, x1) = (u0.ceil().max(0.0), u1.floor().min(f64::from(k.width_px - 1)));
        let (y0, y1) = (v0.ceil().max(0.0), v1.floor().min(f64::from(k.height_px - 1)));
        if x0 > x1 || y0 > y1 {
            return false;
        }
        let origin = self.world_from_camera.translation_m;
        let (w, _, depth, _) = &self.levels[0];
        let mut crossed = false;
        for y in y0 as u32..=y1 as u32 {
            for x in x0 as u32..=x1 as u32 {
                let dir = self.world_from_camera.rotation * DVec3::new((f64::from(x) - cx) / fx, (f64::from(y) - cy) / fy, 1.0);
                let (mut t_in, mut t_out) = (0.0_f64, f64::INFINITY);
                for axis in 0..3 {
                    let (o, d, lo, hi) = (origin[axis], dir[axis], lo_m[axis], hi_m[axis]);
                    if d.abs() < 1e-12 {
                        if o < lo || o > hi {
                            t_out = -1.0;
                        }
                        continue;
                    }
                    let (ta, tb) = ((lo - o) / d, (hi - o) / d);
                    t_in = t_in.max(ta.min(tb));
                    t_out = t_out.min(ta.max(tb));
                }
                if t_in > t_out {
                    continue;
                }
                crossed = true;
                let d_m = f64::from(depth[(y * w + x) as usize]);
                if d_m <= 0.0 || t_out >= d_m - margin_m {
                    return false;
                }
            }
        }
        crossed
    }
}

/// Where a sphere falls in a view.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Footprint {
    /// Wholly outside the view (beside it or behind the camera): the view says nothing.
    Outside,
    /// Partly outside, or reaching the camera plane: parts of it must be looked at alone.
    Partial,
    /// Inside, over pixels whose depths span this range (0 for a pixel without a return).
    Inside { nearest_m: f64, farthest_m: f64 },
}

/// Carves the cells with z in `zs` (whole bricks; `slab` holds exactly those z-slices) that lie
/// wholly in front of the surface `view` sees, by more than `margin_m`.
fn carve(spec: &GridSpec, view: &ViewPyramid, margin_m: f64, zs: std::ops::Range<u32>, slab: &mut [u8]) {
    let cell_radius_m = 0.5 * 3_f64.sqrt() * spec.cell_m;
    let slab_index = |x: u32, y: u32, z: u32| spec.index(x, y, z) - spec.index(0, 0, zs.start);
    let far_m = view.levels[view.levels.len() - 1].3[0];
    if far_m <= 0.0 {
        return;
    }
    for bz in (zs.start..zs.end).step_by(BRICK_CELLS as usize) {
        for by in (0..spec.dims[1]).step_by(BRICK_CELLS as usize) {
            for bx in (0..spec.dims[0]).step_by(BRICK_CELLS as usize) {
                let hi = [(bx + BRICK_CELLS).min(spec.dims[0]), (by + BRICK_CELLS).min(spec.dims[1]), (bz + BRICK_CELLS).min(zs.end)];
                let lo_m = spec.corner_m() + spec.cell_m * DVec3::new(f64::from(bx), f64::from(by), f64::from(bz));
                let hi_m = spec.corner_m() + spec.cell_m * DVec3::new(f64::from(hi[0]), f64::from(hi[1]), f64::from(hi[2]));
                let centre = view.to_camera(0.5 * (lo_m + hi_m));
                let radius_m = 0.5 * (hi_m - lo_m).length();
                // Beyond every surface the view saw: nothing to carve.
                if centre.z - radius_m > f64::from(far_m) {
                    continue;
                }
                match view.footprint(centre, radius_m) {
                    Footprint::Outside => continue,
                    Footprint::Inside { nearest_m, .. } if centre.z + radius_m < nearest_m - margin_m => {
                        for z in bz..hi[2] {
                            for y in by..hi[1] {
                                let row = slab_index(bx, y, z);
                                slab[row..row + (hi[0] - bx) as usize].fill(FREE);
                            }
                        }
                        continue;
                    }
                    Footprint::Inside { farthest_m, .. } if centre.z - radius_m > farthest_m => continue,
                    Footprint::Inside { .. } | Footprint::Partial => {}
                }
                for z in bz..hi[2] {
                    for y in by..hi[1] {
                        for x in bx..hi[0] {
                            let p = view.to_camera(spec.cell_center(x, y, z));
                            let free = match view.footprint(p, cell_radius_m) {
                                Footprint::Inside { nearest_m, .. } if p.z + cell_radius_m < nearest_m - margin_m => true,
                                // Beyond every return over the footprint: nothing to carve.
                                Footprint::Inside { farthest_m, .. } if p.z - cell_radius_m > farthest_m => false,
                                Footprint::Inside { .. } => {
                                    let lo_m = spec.corner_m() + spec.cell_m * DVec3::new(f64::from(x), f64::from(y), f64::from(z));
                                    slab[slab_index(x, y, z)] == UNKNOWN && view.rays_clear_cell(lo_m, lo_m + DVec3::splat(spec.cell_m), margin_m)
                                }
                                Footprint::Outside | Footprint::Partial => false,
                            };
                            if free {
                                slab[slab_index(x, y, z)] = FREE;
                            }
                        }
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn wall_view(depth_m: f32, holes: &[(u32, u32)]) -> (PinholeIntrinsics, Vec<f32>) {
        let k = PinholeIntrinsics { fx_px: 100.0, fy_px: 100.0, cx_px: 49.5, cy_px: 39.5, width_px: 100, height_px: 80 };
        let mut depth = vec![depth_m; k.pixel_count()];
        for &(x, y) in holes {
            depth[(y * k.width_px + x) as usize] = 0.0;
        }
        (k, depth)
    }

    /// Whether a cell of `spec` lies wholly inside the camera's view pyramid (identity pose).
    fn in_view(spec: &GridSpec, k: &PinholeIntrinsics, p: DVec3) -> bool {
        let r = 0.5 * 3_f64.sqrt() * spec.cell_m;
        let near = p.z - r;
        if near <= 0.0 {
            return false;
        }
        let u = f64::from(k.fx_px) * p.x / p.z + f64::from(k.cx_px);
        let v = f64::from(k.fy_px) * p.y / p.z + f64::from(k.cy_px);
        let r_px = f64::from(k.fx_px) * r / near;
        u - r_px >= 0.0 && v - r_px >= 0.0 && u + r_px <= f64::from(k.width_px - 1) && v + r_px <= f64::from(k.height_px - 1)
    }

    #[test]
    fn rays_through_never_observed_cells_are_marked_and_the_rest_not() {
        // A grid of 5 cm cells over x, y in [-1, 1), z in [0, 4): free, except an unknown slab
        // at z in [2, 2.5) over x < 0, and an occupied wall at z in [3.5, 3.6).
        let spec = GridSpec { dims: [40, 40, 80], cell_m: 0.05, center_m: [0.0, 0.0, 2.0] };
        let mut cells = vec![FREE; spec.cell_count() as usize];
        for z in 0..80 {
            for y in 0..40 {
                for x in 0..40 {
                    let c = spec.cell_center(x, y, z);
                    if (2.0..2.5).contains(&c.z) && c.x < 0.0 {
                        cells[spec.index(x, y, z)] = UNKNOWN;
                    } else if (3.5..3.6).contains(&c.z) {
                        cells[spec.index(x, y, z)] = OCCUPIED;
                    }
                }
            }
        }
        let grid = OccupancyGrid { spec, cells };
        // A camera at the origin looking along +z; 21x21 pixels spanning ±0.2 rad.
        let k = PinholeIntrinsics { fx_px: 50.0, fy_px: 50.0, cx_px: 10.0, cy_px: 10.0, width_px: 21, height_px: 21 };
        let (near, wall, none) = (vec![1.5_f32; 441], vec![3.5_f32; 441], vec![0.0_f32; 441]);
        let at = Se3::IDENTITY;
        let left = |marks: &[bool]| (0..441).filter(|&i| i % 21 < 10 && marks[i]).count();
        let right = |marks: &[bool]| (0..441).filter(|&i| i % 21 > 10 && marks[i]).count();
        // Hits at 1.5 m stop before the slab: nothing marked.
        let m = grid.rays_through_unknown(k, &at, &near, false, (0.0, 8.0), 2).expect("marks");
        assert_eq!(m.iter().filter(|&&b| b).count(), 0);
        // Hits on the wall at 3.5 m: the left half (x < 0 at the slab) looked through it.
        let m = grid.rays_through_unknown(k, &at, &wall, false, (0.0, 8.0), 3).expect("marks");
        assert_eq!((left(&m), right(&m)), (210, 0), "every left ray, no right one");
        // No hits: every ray leaves the grid (at z = 4 m) within the 8 m range; with a 3 m range
        // only the left half looks through unknown space.
        assert!(grid.rays_through_unknown(k, &at, &none, false, (0.0, 8.0), 1).expect("marks").iter().all(|&b| b));
        let m = grid.rays_through_unknown(k, &at, &none, false, (0.0, 3.0), 2).expect("marks");
        assert_eq!((left(&m), right(&m)), (210, 0));
        // The sensor measures from 2.6 m on: the slab lies nearer, nothing is marked.
        assert!(grid.rays_through_unknown(k, &at, &wall, false, (2.6, 8.0), 2).expect("marks").iter().all(|&b| !b));
        // Radial distances: a hit at 1.5 m along the ray stops before the slab everywhere.
        assert!(grid.rays_through_unknown(k, &at, &near, true, (0.0, 8.0), 2).expect("marks").iter().all(|&b| !b));
        // Turned half a turn about y, the camera looks out of the grid: every ray is marked.
        let back = Se3::new(glam::DQuat::from_rotation_y(std::f64::consts::PI), DVec3::new(0.0, 0.0, 0.5));
        assert!(grid.rays_through_unknown(k, &back, &wall, false, (0.0, 8.0), 2).expect("marks").iter().all(|&b| b));
        assert!(grid.rays_through_unknown(k, &at, &near[..10], false, (0.0, 8.0), 2).is_err_and(|e| e.to_string().contains("10 depths")));
        assert!(grid.rays_through_unknown(k, &at, &near, false, (0.0, f64::NAN), 2).is_err());
    }

    #[test]
    fn a_wall_carves_what_lies_wholly_in_front_of_it_and_nothing_else() {
        // A camera at the origin sees a wall at 2 m everywhere; cells of 5 cm over z 0..4 m.
        let spec = GridSpec { dims: [40, 32, 80], cell_m: 0.05, center_m: [0.0, 0.0, 2.0] };
        let (k, depth) = wall_view(2.0, &[]);
        let view = CarveView { world_from_camera: Se3::IDENTITY, intrinsics: k, depth_m: &depth };
        // A margin that puts the layer of cells centred at 1.825 m in front of the wall by it
        // (back faces at 1.85 m) while their bounding spheres reach past it (to 1.868 m).
        let margin_m = 0.14;
        let mut builder = OccupancyBuilder::new(&spec, 2).expect("grid");
        builder.carve(&[view], margin_m).expect("carve");
        let grid = OccupancyGrid { spec, cells: builder.cells };
        let r = 0.5 * 3_f64.sqrt() * spec.cell_m;
        let (mut free, mut should, mut sphere_short) = (0, 0, 0);
        for z in 0..spec.dims[2] {
            for y in 0..spec.dims[1] {
                for x in 0..spec.dims[0] {
                    let p = spec.cell_center(x, y, z);
                    let state = grid.at(x, y, z);
                    // Sound: only cells wholly in view whose every ray leaves them in front of the
                    // wall by the margin (the rays leave an axis-aligned cell by its back face, at
                    // most half a cell behind its centre).
                    let in_front = p.z + 0.5 * spec.cell_m < 2.0 - margin_m;
                    if state == FREE {
                        free += 1;
                        assert!(in_view(&spec, &k, p) && in_front, "cell {x},{y},{z} at {p} carved");
                    } else {
                        assert_eq!(state, UNKNOWN, "only free or unknown without a map");
                    }
                    // Complete: every such cell is carved (brick decisions lose none), also those
                    // whose bounding sphere reaches past the margin (tested ray by ray).
                    if in_view(&spec, &k, p) && in_front {
                        sphere_short += usize::from(p.z + r >= 2.0 - margin_m);
                        should += 1;
                        assert_eq!(state, FREE, "cell {x},{y},{z} at {p} in view in front of the wall");
                    }
                }
            }
        }
        assert!(free > 1000 && free == should, "{free} carved of {should}");
        assert!(sphere_short > 100, "{sphere_short} cells carved by their rays alone");

        // One pixel without a return: the cells whose footprint covers it stay unknown.
        let (k, depth) = wall_view(2.0, &[(50, 40)]);
        let holed = CarveView { world_from_camera: Se3::IDENTITY, intrinsics: k, depth_m: &depth };
        let mut builder = OccupancyBuilder::new(&spec, 1).expect("grid");
        builder.carve(&[holed], margin_m).expect("carve");
        let grid = OccupancyGrid { spec, cells: builder.cells };
        let counts = grid.counts();
        assert!(counts.free < free && counts.free > free / 2, "the hole keeps its ray unknown: {} vs {free}", counts.free);
        // The cell on the hole's ray at 1 m is unknown; one beside it is free.
        let ray = |x_px: f64| {
            let p = DVec3::new((x_px - 49.5) / 100.0, (40.0 - 39.5) / 100.0, 1.0);
            let c = ((p - spec.corner_m()) / spec.cell_m).floor();
            grid.at(c.x as u32, c.y as u32, c.z as u32)
        };
        assert_eq!(ray(50.0), UNKNOWN, "on the hole's ray");
        assert_eq!(ray(20.0), FREE, "beside it");

        // A wrong-sized view is an error naming it.
        let mut builder = OccupancyBuilder::new(&spec, 1).expect("grid");
        let bad = CarveView { world_from_camera: Se3::IDENTITY, intrinsics: k, depth_m: &depth[1..] };
        assert!(builder.carve(&[bad], margin_m).expect_err("short view").to_string().contains("7999 depths"));
    }

    #[test]
    fn grids_that_cannot_be_written_are_refused_by_name() {
        let bad = |spec: GridSpec, needle: &str| {
            let message = spec.validate().expect_err("accepted").to_string();
            assert!(message.contains(needle), "{needle:?} not in {message:?}");
        };
        bad(GridSpec { dims: [0, 10, 10], ..GridSpec::SEED_000 }, "at least one cell");
        bad(GridSpec { dims: [100_000, 100_000, 1000], ..GridSpec::SEED_000 }, "4 GiB");
        bad(GridSpec { cell_m: f64::NAN, ..GridSpec::SEED_000 }, "finite and positive");
        bad(GridSpec { cell_m: -0.01, ..GridSpec::SEED_000 }, "finite and positive");
        bad(GridSpec { center_m: [0.0, f64::INFINITY, 0.0], ..GridSpec::SEED_000 }, "centre");
        GridSpec::SEED_000.validate().expect("seed 000's grid");
        assert_eq!(GridSpec::SEED_000.cell_count(), 1024 * 1024 * 480);
        let spec = GridSpec { dims: [4, 2, 2], cell_m: 0.5, center_m: [1.0, 0.0, 0.0] };
        assert_eq!(spec.corner_m(), DVec3::new(0.0, -0.5, -0.5), "the centre is the grid's centre");
        assert_eq!(spec.cell_center(3, 1, 0), DVec3::new(1.75, 0.25, -0.25));
        assert_eq!(spec.index(3, 1, 1), 3 + 4 * (1 + 2));
    }
}

// SPDX-License-Identifier: MIT
//! Planes that persist across frames: the world model 003 planned and never built (its
//! Fig. 3.1). Each frame's planes, moved into the world by the frame's camera pose, are
//! associated with the world planes, and each world plane keeps a texel grid on its own frame
//! that grows as new views reach further, with a colour accumulated per texel over every view
//! that saw it; a wall seen over hundreds of frames is one plane with one texture and one
//! quadtree mesh ([`super::mesh`]).
//!
//! - **Association**: a frame plane joins the world plane whose normal is within
//!   [`WorldConfig::association_angle_deg`] of its own and which passes nearest its centroid,
//!   if within the labelling distance at the centroid's depth ([`PlaneConfig::label_distance_m`]:
//!   the tolerance within which the frame's own pixels joined it); else it starts a new one.
//!   Taking the nearest rather than the first keeps a whiteboard on a wall apart from the wall.
//! - **Parameters**: a world plane's normal is the pixel-weighted mean of its views' normals,
//!   and it passes through the pixel-weighted mean of their centroids.
//! - **Texels**: a world plane's frame is fixed when it is created (origin at its first view's
//!   centroid, `u` along that view's tangent) and its texels are [`WorldConfig::px_per_m`]
//!   apart. For each view, every texel within the box of the view's pixels is projected into
//!   the frame (003's destination-driven rectification, [`super::mesh::rectify`]: no gaps
//!   whatever the view's distance) and takes the colour of the pixel it lands on when that
//!   pixel carries the view's label.
//! - **Merging**: world planes drift as views add up (a plane first seen at a grazing angle or
//!   from a poorly tracked pose settles later), so two may come to describe one surface. After
//!   each frame, a plane the frame touched merges with another whose normal is within the
//!   association angle and where each passes the other's centroid within the labelling
//!   distance at that centroid's depth in the frame's camera (the association's own test, made
//!   symmetric, so a whiteboard beside its wall stays apart). The plane with fewer pixels is
//!   folded into the other: its views, pixels and normal and centroid sums are added, and its
//!   texels are resampled into the survivor's grid (each survivor texel over the merged
//!   plane's observed box takes the sums of the texel its centre falls in). It is kept, emptied,
//!   with [`WorldPlane::merged_into`] naming the survivor, so indices handed out before stay
//!   valid ([`PlaneWorld::resolve`]).

use super::mesh::{PlaneFrame, PlaneMesh, TexelGrid, geometry_shift_for, pixel_box, rectify};
use super::{PlaneConfig, Segmentation};
use crate::{ColorImage, PinholeIntrinsics, Se3};
use glam::DVec3;

/// Parameters of the world model.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WorldConfig {
    /// Texels per metre of the world planes' grids, a power of two (128: 7.8 mm texels, about
    /// a Kinect pixel's footprint at 2 m, so an 8 m wall fits one 1024-texel texture).
    pub px_per_m: f32,
    /// Largest angle between a view's normal and a world plane's for them to be one plane,
    /// degrees: twice the merge angle within a frame (5°), since views also differ by the
    /// error of their camera poses.
    pub association_angle_deg: f32,
    /// Most texels along either side of one world plane's grid (2048 at 128 per metre: 16 m);
    /// views beyond are clipped and counted.
    pub max_grid_texels: u32,
    /// Largest side of the cells the meshes' outlines follow, metres (see
    /// [`PlaneMesh::build`]): 1.6 cm, about the default map's marching-cubes voxel (1.2 cm)
    /// and a Kinect pixel's footprint at 3 m on a surface seen at 70° incidence; at 128
    /// texels per metre, cells of 2 x 2 texels.
    pub geometry_cell_m: f32,
}

impl Default for WorldConfig {
    fn default() -> Self {
        WorldConfig { px_per_m: 128.0, association_angle_deg: 10.0, max_grid_texels: 2048, geometry_cell_m: 0.016 }
    }
}

/// A world plane's texel grid, in texel indices of its frame: texel (i, j) has its centre at
/// ((i + ½), (j + ½)) / px_per_m in the frame's (u, v).
#[derive(Clone, Debug, Default, PartialEq)]
struct Texels {
    first: [i32; 2],
    size: [u32; 2],
    /// Σ colour of the views that saw each texel.
    sum: Vec<[f32; 3]>,
    /// Views that saw each texel.
    count: Vec<u32>,
}

impl Texels {
    /// Grows to hold texels `[lo, hi)` (each axis), at most `max` texels along a side (then
    /// keeping the part nearest the grid so far); returns the range now held.
    fn grow(&mut self, lo: [i32; 2], hi: [i32; 2], max: u32) -> ([i32; 2], [i32; 2]) {
        let (old_lo, old_hi) = (self.first, [self.first[0] + self.size[0] as i32, self.first[1] + self.size[1] as i32]);
        let empty = self.size[0] == 0;
        let mut new_lo = if empty { lo } else { [old_lo[0].min(lo[0]), old_lo[1].min(lo[1])] };
        let mut new_hi = if empty { hi } else { [old_hi[0].max(hi[0]), old_hi[1].max(hi[1])] };
        for a in 0..2 {
            let max = max as i32;
            if new_hi[a] - new_lo[a] > max {
                // Keep what is held and extend towards the request, below first, as far as the
                // limit allows.
                let (keep_lo, keep_hi) = if empty { (lo[a], lo[a]) } else { (old_lo[a], old_hi[a]) };
                let room = max - (keep_hi - keep_lo);
                let below = (keep_lo - new_lo[a]).min(room);
                new_lo[a] = keep_lo - below;
                new_hi[a] = keep_hi + (new_hi[a] - keep_hi).min(room - below);
            }
        }
        if new_lo != old_lo || new_hi != old_hi || empty {
            let size = [(new_hi[0] - new_lo[0]).max(0) as u32, (new_hi[1] - new_lo[1]).max(0) as u32];
            let mut sum = vec![[0.0f32; 3]; (size[0] * size[1]) as usize];
            let mut count = vec![0u32; sum.len()];
            for j in 0..self.size[1] as i32 {
                for i in 0..self.size[0] as i32 {
                    let (x, y) = (old_lo[0] + i - new_lo[0], old_lo[1] + j - new_lo[1]);
                    let (src, dst) = ((j * self.size[0] as i32 + i) as usize, (y * size[0] as i32 + x) as usize);
                    sum[dst] = self.sum[src];
                    count[dst] = self.count[src];
                }
            }
            *self = Texels { first: new_lo, size, sum, count };
        }
        let held_hi = [self.first[0] + self.size[0] as i32, self.first[1] + self.size[1] as i32];
        ([lo[0].max(self.first[0]), lo[1].max(self.first[1])], [hi[0].min(held_hi[0]), hi[1].min(held_hi[1])])
    }
}

/// A plane of the world model.
#[derive(Clone, Debug, PartialEq)]
pub struct WorldPlane {
    /// Unit normal, world frame.
    pub normal: [f32; 3],
    /// d of `normal·p + d = 0`, metres.
    pub offset_m: f32,
    /// Pixel-weighted mean of its views' centroids, metres.
    pub centroid_m: [f32; 3],
    /// Views (frame planes) associated with it.
    pub views: u32,
    /// Pixels over all its views.
    pub pixels: u64,
    /// Index of the first and last frame that saw it.
    pub frames: [u64; 2],
    /// Its texel grid's frame (fixed at creation).
    pub frame: PlaneFrame,
    /// The plane it was merged into (which holds its views and texels now), or `None` while it
    /// is a plane of the world.
    pub merged_into: Option<usize>,
    sum_normal: DVec3,
    sum_centroid: DVec3,
    texels: Texels,
}

impl WorldPlane {
    /// Texels seen by at least one view.
    pub fn observed_texels(&self) -> usize {
        self.texels.count.iter().filter(|&&c| c > 0).count()
    }

    /// Projects `p` onto the plane along its normal.
    fn onto(&self, p: [f32; 3]) -> [f32; 3] {
        let e = self.normal[0] * p[0] + self.normal[1] * p[1] + self.normal[2] * p[2] + self.offset_m;
        std::array::from_fn(|i| p[i] - e * self.normal[i])
    }
}

/// One frame's planes, as [`PlaneWorld::add_frame`] takes them.
#[derive(Clone, Copy, Debug)]
pub struct PlaneView<'a> {
    /// The frame's position in its source.
    pub index: u64,
    /// Its camera's pose.
    pub world_from_camera: Se3,
    /// Its segmentation (planes in the camera frame).
    pub segmentation: &'a Segmentation,
    /// Per full-resolution pixel the plane its surface is meshed from
    /// ([`super::mesh::complete_labels`], or the segmentation's own labels).
    pub labels: &'a [u32],
    /// Its colour image, registered to the depth.
    pub colour: &'a ColorImage,
    /// Its camera.
    pub intrinsics: PinholeIntrinsics,
}

/// What [`PlaneWorld::add_frame`] did with a frame's planes.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct FrameAssociation {
    /// Per frame plane, the world plane it joined or started.
    pub world_plane: Vec<usize>,
    /// Of those, how many started a new world plane.
    pub created: usize,
    /// World planes merged into another after this frame.
    pub merged: usize,
    /// Texels outside [`WorldConfig::max_grid_texels`], not stored.
    pub clipped_texels: u64,
}

/// The world model: planes and their texel grids.
#[derive(Clone, Debug, Default)]
pub struct PlaneWorld {
    /// Parameters.
    pub config: WorldConfig,
    /// The planes, in order of creation.
    pub planes: Vec<WorldPlane>,
}

fn to_dvec(a: [f32; 3]) -> DVec3 {
    DVec3::new(f64::from(a[0]), f64::from(a[1]), f64::from(a[2]))
}

fn to_f32(v: DVec3) -> [f32; 3] {
    [v.x as f32, v.y as f32, v.z as f32]
}

impl PlaneWorld {
    /// An empty world.
    pub fn new(config: WorldConfig) -> Self {
        PlaneWorld { config, planes: Vec::new() }
    }

    /// Adds one frame's planes (`view`); `plane_config` is the segmentation's (for the
    /// labelling distance).
    pub fn add_frame(&mut self, view: &PlaneView<'_>, plane_config: &PlaneConfig) -> FrameAssociation {
        let (world_from_camera, seg, frame_index) = (&view.world_from_camera, view.segmentation, view.index);
        let camera_from_world = world_from_camera.inverse();
        let cos_assoc = self.config.association_angle_deg.to_radians().cos();
        let mut out = FrameAssociation::default();
        for (i, plane) in seg.planes.iter().enumerate() {
            let n_w = world_from_camera.rotation * to_dvec(plane.normal);
            let c_w = world_from_camera.transform_point(to_dvec(plane.centroid_m));
            let tol = f64::from(plane_config.label_distance_m(plane.centroid_m[2]));
            let best = self
                .planes
                .iter()
                .enumerate()
                .filter(|(_, w)| w.merged_into.is_none() && to_dvec(w.normal).dot(n_w) >= f64::from(cos_assoc))
                .map(|(j, w)| (j, (to_dvec(w.normal).dot(c_w) + f64::from(w.offset_m)).abs()))
                .filter(|&(_, e)| e <= tol)
                .min_by(|a, b| a.1.total_cmp(&b.1))
                .map(|(j, _)| j);
            let weight = f64::from(plane.pixels);
            let j = match best {
                Some(j) => j,
                None => {
                    let t_w = world_from_camera.rotation * to_dvec(plane.tangent);
                    let frame = PlaneFrame::new(to_f32(n_w), -n_w.dot(c_w) as f32, to_f32(c_w), to_f32(t_w));
                    self.planes.push(WorldPlane {
                        normal: frame.normal,
                        offset_m: frame.offset_m(),
                        centroid_m: to_f32(c_w),
                        views: 0,
                        pixels: 0,
                        frames: [frame_index, frame_index],
                        frame,
                        merged_into: None,
                        sum_normal: DVec3::ZERO,
                        sum_centroid: DVec3::ZERO,
                        texels: Texels::default(),
                    });
                    out.created += 1;
                    self.planes.len() - 1
                }
            };
            let w = &mut self.planes[j];
            w.sum_normal += weight * n_w;
            w.sum_centroid += weight * c_w;
            w.views += 1;
            w.pixels += u64::from(plane.pixels);
            w.frames = [w.frames[0].min(frame_index), w.frames[1].max(frame_index)];
            let n = w.sum_normal.normalize();
            let c = w.sum_centroid / (w.pixels as f64);
            (w.normal, w.centroid_m, w.offset_m) = (to_f32(n), to_f32(c), -n.dot(c) as f32);
            out.clipped_texels += Self::add_texels(w, i as u32, view, &camera_from_world, self.config);
            out.world_plane.push(j);
        }
        let mut touched = out.world_plane.clone();
        touched.sort_unstable();
        touched.dedup();
        let (merged, clipped) = self.merge_planes(&touched, &camera_from_world, plane_config);
        out.merged = merged;
        out.clipped_texels += clipped;
        out.world_plane = out.world_plane.iter().map(|&j| self.resolve(j)).collect();
        out
    }

    /// The plane of the world that plane `j` is part of now (itself unless merged).
    pub fn resolve(&self, mut j: usize) -> usize {
        while let Some(k) = self.planes[j].merged_into {
            j = k;
        }
        j
    }

    /// Indices of the planes of the world (not merged into another).
    pub fn live(&self) -> impl Iterator<Item = usize> + '_ {
        (0..self.planes.len()).filter(|&j| self.planes[j].merged_into.is_none())
    }

    /// Merges the planes `touched` by a frame (seen from `camera_from_world`) with the others
    /// that describe the same surface (see the module docs), until none does; returns the
    /// merges and the texels clipped by the survivors' grid limit.
    fn merge_planes(&mut self, touched: &[usize], camera_from_world: &Se3, plane_config: &PlaneConfig) -> (usize, u64) {
        let cos_assoc = f64::from(self.config.association_angle_deg.to_radians().cos());
        let (mut merges, mut clipped) = (0, 0);
        loop {
            let same = |a: &WorldPlane, b: &WorldPlane| {
                let within = |p: &WorldPlane, q: &WorldPlane| {
                    let c = to_dvec(q.centroid_m);
                    let z = camera_from_world.transform_point(c).z.abs() as f32;
                    (to_dvec(p.normal).dot(c) + f64::from(p.offset_m)).abs() <= f64::from(plane_config.label_distance_m(z))
                };
                to_dvec(a.normal).dot(to_dvec(b.normal)) >= cos_assoc && within(a, b) && within(b, a)
            };
            let pair = touched.iter().map(|&a| self.resolve(a)).find_map(|a| self.live().find(|&b| b != a && same(&self.planes[a], &self.planes[b])).map(|b| (a, b)));
            let Some((a, b)) = pair else { break };
            let (keep, fold) = if (self.planes[a].pixels, b) >= (self.planes[b].pixels, a) { (a, b) } else { (b, a) };
            clipped += self.fold(keep, fold);
            merges += 1;
        }
        (merges, clipped)
    }

    /// Folds plane `fold` into plane `keep` (see the module docs); returns the texels clipped.
    fn fold(&mut self, keep: usize, fold: usize) -> u64 {
        let res = self.config.px_per_m;
        let src = std::mem::take(&mut self.planes[fold].texels);
        let (sf, sum_normal, sum_centroid, views, pixels, frames) = {
            let f = &mut self.planes[fold];
            f.merged_into = Some(keep);
            (f.frame, f.sum_normal, f.sum_centroid, f.views, f.pixels, f.frames)
        };
        let max_texels = self.config.max_grid_texels;
        let k = &mut self.planes[keep];
        k.sum_normal += sum_normal;
        k.sum_centroid += sum_centroid;
        k.views += views;
        k.pixels += pixels;
        k.frames = [k.frames[0].min(frames[0]), k.frames[1].max(frames[1])];
        let n = k.sum_normal.normalize();
        let c = k.sum_centroid / (k.pixels as f64);
        (k.normal, k.centroid_m, k.offset_m) = (to_f32(n), to_f32(c), -n.dot(c) as f32);
        // The folded plane's observed texels, as a box of corners in the world.
        let observed: Vec<usize> = (0..src.count.len()).filter(|&i| src.count[i] > 0).collect();
        if observed.is_empty() {
            return 0;
        }
        let texel_xy = |i: usize| [src.first[0] + (i as u32 % src.size[0]) as i32, src.first[1] + (i as u32 / src.size[0]) as i32];
        let (mut lo, mut hi) = ([i32::MAX; 2], [i32::MIN; 2]);
        for &i in &observed {
            let xy = texel_xy(i);
            for a in 0..2 {
                lo[a] = lo[a].min(xy[a]);
                hi[a] = hi[a].max(xy[a] + 1);
            }
        }
        // Texel coordinates (texels from the frame's origin) in `to` of texel coordinates `t` in
        // `from`, through the world.
        let texels_in = |from: &PlaneFrame, to: &PlaneFrame, t: [f32; 2]| to.to_plane(from.point([t[0] / res, t[1] / res])).map(|c| c * res);
        let (mut dlo, mut dhi) = ([f32::INFINITY; 2], [f32::NEG_INFINITY; 2]);
        for corner in [[lo[0], lo[1]], [hi[0], lo[1]], [lo[0], hi[1]], [hi[0], hi[1]]] {
            let uv = texels_in(&sf, &k.frame, corner.map(|c| c as f32));
            for a in 0..2 {
                dlo[a] = dlo[a].min(uv[a]);
                dhi[a] = dhi[a].max(uv[a]);
            }
        }
        let want_lo = [dlo[0].floor() as i32, dlo[1].floor() as i32];
        let want_hi = [dhi[0].ceil() as i32, dhi[1].ceil() as i32];
        let want = i64::from(want_hi[0] - want_lo[0]) * i64::from(want_hi[1] - want_lo[1]);
        let (glo, ghi) = k.texels.grow(want_lo, want_hi, max_texels);
        let held = i64::from((ghi[0] - glo[0]).max(0)) * i64::from((ghi[1] - glo[1]).max(0));
        let stride = k.texels.size[0] as i32;
        for y in glo[1]..ghi[1] {
            for x in glo[0]..ghi[0] {
                let uv = texels_in(&k.frame, &sf, [x as f32 + 0.5, y as f32 + 0.5]);
                let (sx, sy) = (uv[0].floor() as i32 - src.first[0], uv[1].floor() as i32 - src.first[1]);
                if sx < 0 || sy < 0 || sx >= src.size[0] as i32 || sy >= src.size[1] as i32 {
                    continue;
                }
                let s = (sy * src.size[0] as i32 + sx) as usize;
                if src.count[s] == 0 {
                    continue;
                }
                let t = ((y - k.texels.first[1]) * stride + (x - k.texels.first[0])) as usize;
                for (sum, v) in k.texels.sum[t].iter_mut().zip(src.sum[s]) {
                    *sum += v;
                }
                k.texels.count[t] += src.count[s];
            }
        }
        (want - held).max(0) as u64
    }

    /// Accumulates the colours of frame plane `label` into `w`'s texels: every texel in the
    /// box of the view's pixels with that label ([`pixel_box`]); returns the texels clipped
    /// by the grid's size limit.
    fn add_texels(w: &mut WorldPlane, label: u32, view: &PlaneView<'_>, camera_from_world: &Se3, config: WorldConfig) -> u64 {
        let res = config.px_per_m;
        let Some([min, max]) = pixel_box(&w.frame, view.labels, label, &view.intrinsics, &view.world_from_camera) else { return 0 };
        let lo = [(min[0] * res).floor() as i32, (min[1] * res).floor() as i32];
        let hi = [(max[0] * res).ceil() as i32, (max[1] * res).ceil() as i32];
        let want = i64::from(hi[0] - lo[0]) * i64::from(hi[1] - lo[1]);
        let (lo, hi) = w.texels.grow(lo, hi, config.max_grid_texels);
        let held = i64::from((hi[0] - lo[0]).max(0)) * i64::from((hi[1] - lo[1]).max(0));
        if lo[0] >= hi[0] || lo[1] >= hi[1] {
            return (want - held).max(0) as u64;
        }
        // The held part of the box as a texel grid on the plane as it now is (the frame's
        // origin and axes moved onto it), in the camera frame: then 003's rectification
        // (kernel `plane_rectify`) gives each texel its pixel's colour.
        let now = PlaneFrame::new(w.normal, w.offset_m, w.frame.origin_m, w.frame.u_axis);
        let r = camera_from_world.rotation;
        let in_camera = PlaneFrame {
            origin_m: to_f32(camera_from_world.transform_point(to_dvec(now.origin_m))),
            u_axis: to_f32(r * to_dvec(now.u_axis)),
            v_axis: to_f32(r * to_dvec(now.v_axis)),
            normal: to_f32(r * to_dvec(now.normal)),
        };
        let grid = TexelGrid { frame: in_camera, px_per_m: res, min_m: [lo[0] as f32 / res, lo[1] as f32 / res], width: (hi[0] - lo[0]) as u32, height: (hi[1] - lo[1]) as u32 };
        let colours = rectify(&grid, &view.intrinsics, view.labels, label, view.colour);
        let stride = w.texels.size[0] as i32;
        for (k, c) in colours.iter().enumerate() {
            let Some(c) = c else { continue };
            let (i, j) = (lo[0] + (k as u32 % grid.width) as i32, lo[1] + (k as u32 / grid.width) as i32);
            let t = ((j - w.texels.first[1]) * stride + (i - w.texels.first[0])) as usize;
            for (sum, &v) in w.texels.sum[t].iter_mut().zip(c) {
                *sum += f32::from(v);
            }
            w.texels.count[t] += 1;
        }
        (want - held).max(0) as u64
    }

    /// The textured quadtree mesh of world plane `j` in the world frame: its observed texels
    /// with their mean colours; vertices lie on the plane's current parameters. `None` if no
    /// texel was observed.
    pub fn mesh(&self, j: usize) -> Option<PlaneMesh> {
        let w = &self.planes[j];
        if w.observed_texels() == 0 {
            return None;
        }
        let res = self.config.px_per_m;
        // The box of the observed texels (the grid grew to each view's whole box).
        let t = &w.texels;
        let (mut lo, mut hi) = ([u32::MAX; 2], [0u32; 2]);
        for (i, _) in t.count.iter().enumerate().filter(|(_, c)| **c > 0) {
            let xy = [i as u32 % t.size[0], i as u32 / t.size[0]];
            for a in 0..2 {
                lo[a] = lo[a].min(xy[a]);
                hi[a] = hi[a].max(xy[a] + 1);
            }
        }
        let grid = TexelGrid { frame: w.frame, px_per_m: res, min_m: [(t.first[0] + lo[0] as i32) as f32 / res, (t.first[1] + lo[1] as i32) as f32 / res], width: hi[0] - lo[0], height: hi[1] - lo[1] };
        let mut colours = Vec::with_capacity((grid.width * grid.height) as usize);
        for y in lo[1]..hi[1] {
            for x in lo[0]..hi[0] {
                let i = (y * t.size[0] + x) as usize;
                let n = t.count[i];
                colours.push((n > 0).then(|| t.sum[i].map(|v| (v / n as f32).round().clamp(0.0, 255.0) as u8)));
            }
        }
        let mut mesh = PlaneMesh::build(grid, &colours, geometry_shift_for(res, self.config.geometry_cell_m));
        for p in &mut mesh.positions_m {
            *p = w.onto(*p);
        }
        Some(mesh)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::RgbdCalibration;
    use crate::cpu::preprocess::chain::preprocess;
    use crate::planes::mesh::{blend_reach_px, complete_labels, tests::coverage};
    use crate::planes::reference::segment;
    use crate::preprocess::PreprocessConfig;
    use crate::sim::plane_scenes::{PlaneScene, UNITS_PER_METRE};
    use glam::DQuat;

    const K: PinholeIntrinsics = PinholeIntrinsics { fx_px: 262.5, fy_px: 262.5, cx_px: 159.5, cy_px: 119.5, width_px: 320, height_px: 240 };

    /// A room corner seen from five poses sweeping 40° and 60 cm, with exact poses: each true
    /// plane becomes one world plane, whose mesh lies on it and covers what the views saw.
    #[test]
    fn views_of_a_room_corner_make_one_plane_per_wall() {
        let base = PlaneScene::room_corner();
        let (config, pre_config) = (PlaneConfig::default(), PreprocessConfig::default());
        let calibration = RgbdCalibration { intrinsics: K, depth_units_per_metre: UNITS_PER_METRE as f32 };
        let mut world = PlaneWorld::new(WorldConfig::default());
        let mut renders = Vec::new();
        for (v, noise) in [(0, None), (1, Some(1)), (2, None), (3, Some(2)), (4, None)] {
            let t = f64::from(v) / 4.0 - 0.5;
            let mut scene = base.clone();
            scene.world_from_camera = Se3::new(DQuat::from_rotation_y((40.0 * t).to_radians()) * base.world_from_camera.rotation, DVec3::new(0.6 * t, 0.0, 0.1 * t));
            let r = scene.render(&K, noise);
            let pre = preprocess(&calibration, &pre_config, &r.frame);
            let seg = segment(&pre.levels, Some(&pre.depth_unfiltered_m), &config);
            let labels = complete_labels(&seg, &pre.depth_unfiltered_m, &K, &config, blend_reach_px(&pre_config));
            let view = PlaneView { index: v as u64, world_from_camera: scene.world_from_camera, segmentation: &seg, labels: &labels, colour: &r.frame.color, intrinsics: K };
            let a = world.add_frame(&view, &config);
            assert_eq!(a.clipped_texels, 0);
            renders.push((scene, r));
        }
        let truth: Vec<_> = base.planes_in_camera().iter().map(|p| p.map(|p| p.in_frame(&base.world_from_camera.inverse()))).collect();
        assert_eq!(world.planes.len(), 3, "{:?}", world.planes.iter().map(|p| (p.normal, p.offset_m, p.views)).collect::<Vec<_>>());
        for (j, w) in world.planes.iter().enumerate() {
            let n = to_dvec(w.normal);
            let (s, t) = truth.iter().enumerate().filter_map(|(s, t)| t.map(|t| (s, t))).max_by(|a, b| a.1.normal.dot(n).total_cmp(&b.1.normal.dot(n))).expect("true planes");
            let angle = t.normal.dot(n).clamp(-1.0, 1.0).acos().to_degrees();
            let mesh = world.mesh(j).expect("a mesh");
            let worst_m = mesh.positions_m.iter().map(|p| t.distance_m(to_dvec(*p)).abs()).fold(0.0, f64::max);
            let (mut covered, mut total) = (0.0, 0.0);
            for (scene, r) in &renders {
                let in_camera: Vec<_> = scene.planes_in_camera();
                let (c, a) = coverage(&K, r, &in_camera, s, &mesh, &scene.world_from_camera);
                covered += c;
                total += a;
            }
            eprintln!("world plane {j} = surface {s}: {} views, normal off {angle:.2}°, worst vertex {:.1} mm off, {} quads, texture {}x{}, covers {:.1} % of what the views saw", w.views, worst_m * 1e3, mesh.quads, mesh.texture.width_px, mesh.texture.height_px, 100.0 * covered / total);
            assert!(angle < 1.0 && worst_m < 0.01 && covered / total >= 0.95);
            let seen = renders.iter().filter(|(_, r)| r.plane_of_pixel.iter().filter(|&&l| l == s as u32).count() * 50 > K.pixel_count()).count();
            assert!(w.views as usize >= seen, "seen well in {seen} views, associated in {}", w.views);
        }
    }

    /// A wall seen first at 1.03 m, then from nearer poses at 1.00 m (3 cm: beyond the
    /// labelling distance at 1 m, so a second plane starts), then from 3 m away, where the
    /// sensor's noise makes 3 cm one surface (3σ(3 m) = 4.2 cm): the two planes merge into one
    /// whose texels are the union of both, and earlier indices resolve to it. A whiteboard
    /// 2.5 cm in front of the wall, seen from 1 m, stays a plane of its own.
    #[test]
    fn planes_that_come_to_describe_one_surface_merge_and_a_whiteboard_stays_apart() {
        let config = PlaneConfig::default();
        let k = PinholeIntrinsics { fx_px: 100.0, fy_px: 100.0, cx_px: 49.5, cy_px: 49.5, width_px: 100, height_px: 100 };
        let colour = ColorImage::new(100, 100, vec![200; 100 * 100 * 3]).expect("colour");
        let mut world = PlaneWorld::new(WorldConfig::default());
        // A view from a camera `back_m` behind the origin (looking along +z) of the wall at
        // world depth `z_m` over the image's columns `cols`.
        let add = |world: &mut PlaneWorld, index: u64, back_m: f64, z_m: f32, cols: std::ops::Range<usize>, pixels: u32| {
            let labels: Vec<u32> = (0..100 * 100).map(|i| if cols.contains(&(i % 100)) { 0 } else { crate::planes::NO_LABEL }).collect();
            let z_cam = z_m + back_m as f32;
            let plane = crate::planes::Plane { normal: [0.0, 0.0, -1.0], offset_m: z_cam, centroid_m: [0.0, 0.0, z_cam], pixels, area_m2: 0.0, tangent: [1.0, 0.0, 0.0], extent_m: [[0.0; 2]; 2], rms_m: 0.0, bend_deg: 0.0 };
            let seg = Segmentation { labels: labels.clone(), planes: vec![plane], curved_rejected: 0 };
            let view = PlaneView { index, world_from_camera: Se3::new(glam::DQuat::IDENTITY, DVec3::new(0.0, 0.0, -back_m)), segmentation: &seg, labels: &labels, colour: &colour, intrinsics: k };
            let a = world.add_frame(&view, &config);
            (a, world.live().collect::<Vec<_>>(), world.planes.clone())
        };
        let (a, _, _) = add(&mut world, 0, 0.0, 1.03, 0..50, 1000);
        assert_eq!((a.created, a.merged), (1, 0));
        let (a, live, planes) = add(&mut world, 1, 0.0, 1.0, 50..100, 1000);
        assert_eq!((a.created, a.merged, live.len()), (1, 0, 2), "3 cm apart at 1 m: two planes");
        let texels_before: usize = planes.iter().map(WorldPlane::observed_texels).sum();
        let (a, live, planes) = add(&mut world, 2, 2.0, 1.015, 0..100, 1000);
        eprintln!("after the far view: {:?}", planes.iter().map(|p| (p.offset_m, p.views, p.merged_into)).collect::<Vec<_>>());
        assert_eq!((a.created, a.merged, live.len()), (0, 1, 1), "from 3 m the two are one surface");
        let w = &planes[live[0]];
        assert_eq!((w.views, w.pixels), (3, 3000));
        assert!((w.offset_m - 1.015).abs() < 1e-3, "the pixel-weighted plane: {}", w.offset_m);
        assert!(w.observed_texels() >= texels_before, "the merged plane keeps both planes' texels: {} < {texels_before}", w.observed_texels());
        assert_eq!(a.world_plane, vec![live[0]]);
        assert!((0..planes.len()).all(|j| world.resolve(j) == live[0]));
        assert!(world.mesh(live[0]).is_some());
        // A whiteboard 2.5 cm in front of the merged wall, seen from 1 m: its own plane.
        let (wb, live, _) = add(&mut world, 3, 0.0, 0.99, 40..60, 500);
        assert_eq!((wb.created, wb.merged, live.len()), (1, 0, 2));
    }

    #[test]
    fn grids_grow_and_keep_their_texels() {
        let mut t = Texels::default();
        assert_eq!(t.grow([2, 3], [5, 6], 100), ([2, 3], [5, 6]));
        t.count[0] = 7; // texel (2, 3)
        assert_eq!(t.grow([-4, 0], [1, 4], 100), ([-4, 0], [1, 4]));
        assert_eq!((t.first, t.size), ([-4, 0], [9, 6]));
        assert_eq!(t.count[(3 * 9 + 6) as usize], 7);
        // Past the limit: clipped, the old texels kept.
        let (lo, hi) = t.grow([-100, 0], [0, 2], 20);
        assert_eq!(t.size[0], 20);
        assert_eq!(hi[0] - lo[0], 20 - 9 + 4);
        assert_eq!(t.count.iter().sum::<u32>(), 7);
    }
}

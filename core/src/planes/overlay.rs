// SPDX-License-Identifier: MIT
//! The textured planar model drawn into a rendered view (the browser's free view): the world
//! planes' quadtree meshes ([`PlaneWorld::mesh`]) as the `plane_overlay` kernel sees them,
//! each a plane with a texel grid on it, where a texel a quad covers carries the colour the
//! mesh's texture gives it. A ray meets the plane and reads the texel: no rasterisation, and
//! what is drawn is what `scene.glb` holds (the same quads, the same texture).

use glam::DVec3;

use super::world::PlaneWorld;
use crate::fusion::predictor::camera_pose;
use crate::kernels::gpu_data::{OverlayPlane, PlaneOverlayParams};
use crate::kernels::plane_overlay;
use crate::{Error, Gpu, PinholeIntrinsics, Result, Se3};

/// Most texel words an overlay holds by default (64 MiB: within WebGPU's default 128 MiB
/// storage binding; 2048² texels, the largest grid a world plane may grow to, fit four times).
pub const DEFAULT_MAX_OVERLAY_TEXELS: usize = 1 << 24;

/// The world planes as the kernel takes them.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct OverlayModel {
    /// One per drawn plane, largest covered area first.
    pub planes: Vec<OverlayPlane>,
    /// Their texel words, one plane's grid after another (0: no quad covers the texel; else
    /// RGB with an opaque alpha).
    pub texels: Vec<u32>,
    /// World planes with a mesh left out because their grids did not fit the texel budget.
    pub left_out: usize,
}

impl OverlayModel {
    /// The live planes of `world` that have a mesh, largest covered area first, as long as
    /// their grids fit `max_texels` words together (a plane that does not fit is skipped and
    /// counted; a smaller one after it may still fit).
    pub fn from_world(world: &PlaneWorld, max_texels: usize) -> Self {
        let mut meshes: Vec<_> = world.live().filter_map(|j| world.mesh(j).map(|m| (j, m))).collect();
        meshes.sort_by(|a, b| b.1.area_m2.total_cmp(&a.1.area_m2));
        let mut model = OverlayModel::default();
        for (j, mesh) in meshes {
            let g = &mesh.grid;
            let (w, h) = (g.width as usize, g.height as usize);
            if model.texels.len() + w * h > max_texels {
                model.left_out += 1;
                continue;
            }
            let plane = &world.planes[j];
            let first_texel = model.texels.len() as u32;
            // The texture is the grid padded to powers of two and halved per axis to fit.
            let shift = |grid_px: u32, texture_px: u32| (grid_px.next_power_of_two() / texture_px.max(1)).trailing_zeros();
            let (sx, sy) = (shift(g.width, mesh.texture.width_px), shift(g.height, mesh.texture.height_px));
            for y in 0..h {
                for x in 0..w {
                    let word = if mesh.cells[y * w + x] {
                        let t = (((y >> sy) * mesh.texture.width_px as usize) + (x >> sx)) * 3;
                        let rgb = &mesh.texture.rgb8[t..t + 3];
                        u32::from_le_bytes([rgb[0], rgb[1], rgb[2], 0xff])
                    } else {
                        0
                    };
                    model.texels.push(word);
                }
            }
            let f = &g.frame;
            let v3 = |a: [f32; 3]| DVec3::new(f64::from(a[0]), f64::from(a[1]), f64::from(a[2]));
            let (origin, n_frame, n) = (v3(f.origin_m), v3(f.normal), v3(plane.normal));
            let px = f64::from(g.px_per_m);
            // The mesh's vertex at in-frame coordinates s is frame.point(s) moved along the
            // plane's normal n onto the plane (`PlaneWorld::mesh`). Back from a point p on
            // the plane: s_u = (p − o)·(u − k_u n_f) with k_u = (u·n)/(n·n_f), and likewise v;
            // texel coordinates are (s − min) · px.
            let to_texel = |axis: [f32; 3], min_m: f32| {
                let a = v3(axis);
                let row = (a - (a.dot(n) / n.dot(n_frame)) * n_frame) * px;
                let w = -row.dot(origin) - f64::from(min_m) * px;
                [row.x as f32, row.y as f32, row.z as f32, w as f32]
            };
            model.planes.push(OverlayPlane {
                plane: [plane.normal[0], plane.normal[1], plane.normal[2], plane.offset_m],
                to_texel_x: to_texel(f.u_axis, g.min_m[0]),
                to_texel_y: to_texel(f.v_axis, g.min_m[1]),
                width: g.width,
                height: g.height,
                first_texel,
                _pad0: 0,
            });
        }
        model
    }
}

/// A view the overlay draws into.
#[derive(Clone, Copy, Debug)]
pub struct OverlayTarget<'a> {
    /// Intrinsics of the view.
    pub intrinsics: PinholeIntrinsics,
    /// The view's surface depth, metres per pixel (NaN: none), `width_px` per row.
    pub depth_m: &'a wgpu::Buffer,
    /// The view's RGBA8 pixels, drawn over in place.
    pub rgba8: &'a wgpu::Buffer,
    /// Pixels from one row of `rgba8` to the next.
    pub row_stride_px: u32,
}

/// The overlay's model on the GPU ([`OverlayModel`]), drawn into views with `plane_overlay`.
#[derive(Debug)]
pub struct PlaneOverlay {
    label: String,
    planes: wgpu::Buffer,
    texels: wgpu::Buffer,
    params: wgpu::Buffer,
    pose: wgpu::Buffer,
    plane_count: u32,
}

impl PlaneOverlay {
    /// An overlay with no planes.
    pub fn new(gpu: &Gpu, label: &str) -> Self {
        Self {
            label: label.to_owned(),
            planes: gpu.storage_buffer::<OverlayPlane>(&format!("{label}.planes"), 1),
            texels: gpu.storage_buffer::<u32>(&format!("{label}.texels"), 1),
            params: gpu.uniform_buffer(&format!("{label}.params"), &PlaneOverlayParams::default()),
            pose: gpu.uniform_buffer(&format!("{label}.pose"), &camera_pose(None)),
            plane_count: 0,
        }
    }

    /// Planes drawn.
    pub fn plane_count(&self) -> u32 {
        self.plane_count
    }

    /// Replaces the model (buffers grow as needed). An error, with the previous model kept,
    /// if its texels exceed the device's largest storage binding.
    pub fn upload(&mut self, gpu: &Gpu, model: &OverlayModel) -> Result<()> {
        let bytes = (4 * model.texels.len()) as u64;
        let limit = gpu.device.limits().max_storage_buffer_binding_size;
        if bytes > limit {
            return Err(Error::InvalidConfig(format!("the plane overlay's {} texels ({bytes} bytes) exceed the device's largest storage binding ({limit} bytes)", model.texels.len())));
        }
        if self.planes.size() < (std::mem::size_of_val(model.planes.as_slice())) as u64 {
            self.planes = gpu.storage_buffer::<OverlayPlane>(&format!("{}.planes", self.label), model.planes.len().next_power_of_two());
        }
        if self.texels.size() < bytes {
            self.texels = gpu.storage_buffer::<u32>(&format!("{}.texels", self.label), model.texels.len().next_power_of_two().min((limit / 4) as usize));
        }
        if !model.planes.is_empty() {
            gpu.write_buffer(&self.planes, &model.planes);
            gpu.write_buffer(&self.texels, &model.texels);
        }
        self.plane_count = model.planes.len() as u32;
        Ok(())
    }

    /// Records the drawing of the planes into `target` as seen from `world_from_camera` (the
    /// planes' world), at camera depths within `depth_range_m`, a plane hidden where the
    /// view's surface lies more than `occlusion_m` in front of it. Nothing is recorded
    /// without planes. The parameters and pose are written on the queue: one draw per
    /// submission.
    pub fn draw(&self, gpu: &Gpu, encoder: &mut wgpu::CommandEncoder, target: &OverlayTarget<'_>, world_from_camera: &Se3, depth_range_m: (f32, f32), occlusion_m: f32) {
        if self.plane_count == 0 {
            return;
        }
        let k = target.intrinsics;
        let params = PlaneOverlayParams {
            intrinsics: k.into(),
            row_stride_px: target.row_stride_px,
            plane_count: self.plane_count,
            near_m: depth_range_m.0,
            far_m: depth_range_m.1,
            occlusion_m,
            ..Default::default()
        };
        gpu.write_buffer(&self.params, std::slice::from_ref(&params));
        gpu.write_buffer(&self.pose, std::slice::from_ref(&camera_pose(Some(world_from_camera))));
        let bind_group = plane_overlay::Bindings { params: &self.params, pose: &self.pose, planes: &self.planes, texels: &self.texels, depth_m: target.depth_m, rgba8: target.rgba8 }.bind_group(gpu);
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("core.plane_overlay"), timestamp_writes: None });
        gpu.kernels.plane_overlay.dispatch_in(&mut pass, &bind_group, [k.width_px, k.height_px, 1]);
    }
}

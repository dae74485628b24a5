// SPDX-License-Identifier: MIT
//! The TSDF volume: configuration, its GPU description and the dense voxel store.
//!
//! Layout (see `shaders/wgsl/shared/tsdf.wgsl`): one u32 per voxel, x fastest, packing a
//! signed-normalised 16-bit TSDF in truncation units (low half) and a 16-bit weight (high half).
//! 256³ voxels take 64 MiB, half of the 128 MiB binding every device is created with (larger
//! where the adapter offers it, see [`crate::gpu::LARGEST_STORAGE_BINDING_BYTES`]); the optional
//! colour volume takes as much again in its own binding.
//!
//! The pipeline talks to the store through [`TsdfStore`] (its description and buffers), so a
//! sparse voxel-block-hashing store can replace [`DenseTsdfVolume`] later without touching
//! tracking or export.

use crate::cpu::shared::{MAP_DENSE, MAP_SPARSE};
use crate::map::{DEFAULT_POOL_BLOCKS, SPARSE_DIMS_VOXELS, max_pool_blocks};
use crate::{Error, Gpu, Result, Se3};

pub use crate::map::MapKind;

/// Default voxels per axis.
pub const DEFAULT_VOLUME_DIM_VOXELS: u32 = 256;
/// Default edge length of the cubic volume, metres (256 voxels of 11.7 mm).
pub const DEFAULT_VOLUME_SIZE_M: f32 = 3.0;
/// Default truncation distance, in voxels (μ = 4 voxels = 4.7 cm at the default size).
pub const DEFAULT_TRUNCATION_VOXELS: f32 = 4.0;
/// Default width of a sample's truncation band where the sensor's noise exceeds μ, in standard
/// deviations of the Kinect noise model (see [`TsdfConfig::noise_band_sigmas`]).
pub const DEFAULT_NOISE_BAND_SIGMAS: f32 = 3.0;
/// Default cap of the running-average weight (frames): bounds how slowly old data fades.
pub const DEFAULT_MAX_WEIGHT: u32 = 128;

/// Where the volume sits relative to the first camera.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum VolumePlacement {
    /// The first camera sits at the centre of the volume's near face, looking at its centre:
    /// best for an object or desk in front of the camera (KinectFusion's setting).
    #[default]
    InFront,
    /// The first camera sits at the volume's centre: best for a camera turning in place
    /// (e.g. TUM fr1/rpy, which turns 90° away from its first view).
    Centred,
}

/// Creation-time settings of the volume.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TsdfConfig {
    /// Voxels along x, y, z.
    pub dims_voxels: [u32; 3],
    /// Voxel edge length, metres.
    pub voxel_size_m: f32,
    /// Truncation distance μ, metres: the band a depth sample updates either side of its
    /// surface, where the sensor's noise is smaller.
    pub truncation_m: f32,
    /// Where the sensor's noise is larger than μ (a Kinect beyond 2–3 m), each sample's band
    /// widens to this many standard deviations σ_z(z) of the Kinect model at its depth (up to
    /// 16 voxels; `shared/tsdf.wgsl::truncation_band_m`); 0 keeps μ at every depth. A band
    /// narrower than the noise biases the fused surface away from the camera: samples in front
    /// are clamped to +1 while those behind beyond the band are dropped (at 5 m, σ = 4.1 cm:
    /// 13 mm for μ = 4.7 cm, 56 mm for μ = 2 cm); at 3σ both tails hold 0.3 % of the samples.
    pub noise_band_sigmas: f32,
    /// Cap of the integration weight.
    pub max_weight: u32,
    /// Also fuse colour (a second u32 per voxel, RGB8).
    pub color: bool,
    /// Placement relative to the first camera (the dense box; a sparse map's box is centred
    /// on it).
    pub placement: VolumePlacement,
    /// Dense box or sparse voxel blocks.
    pub kind: MapKind,
    /// Blocks of 8³ voxels in a sparse map's pool (see [`crate::map::pool_blocks_for_budget`]);
    /// unused by a dense map.
    pub pool_blocks: u32,
    /// Whether a sparse map swaps blocks far from the camera to host memory once its pool
    /// fills ([`crate::map::swap`]); unused by a dense map.
    pub swap: bool,
}

impl Default for TsdfConfig {
    /// The default map: sparse voxel blocks (the default pool, swapping when it fills) of the
    /// dense default cube's voxel size (3 m / 256 = 11.7 mm).
    fn default() -> Self {
        Self::sparse(DEFAULT_VOLUME_SIZE_M / DEFAULT_VOLUME_DIM_VOXELS as f32, DEFAULT_POOL_BLOCKS)
    }
}

impl TsdfConfig {
    /// A dense cube of `dim` voxels of `voxel_size_m`, with the default truncation (in voxels,
    /// widened by the noise model), weight cap and colour on.
    pub fn cube(dim: u32, voxel_size_m: f32) -> Self {
        Self { dims_voxels: [dim; 3], voxel_size_m, truncation_m: DEFAULT_TRUNCATION_VOXELS * voxel_size_m, noise_band_sigmas: DEFAULT_NOISE_BAND_SIGMAS, max_weight: DEFAULT_MAX_WEIGHT, color: true, placement: VolumePlacement::InFront, kind: MapKind::Dense, pool_blocks: DEFAULT_POOL_BLOCKS, swap: true }
    }

    /// A sparse map of `pool_blocks` blocks of 8³ voxels of `voxel_size_m`, with the default
    /// truncation (in voxels), weight cap and colour on.
    pub fn sparse(voxel_size_m: f32, pool_blocks: u32) -> Self {
        Self { kind: MapKind::Sparse, pool_blocks, ..Self::cube(DEFAULT_VOLUME_DIM_VOXELS, voxel_size_m) }
    }

    /// Voxels along x, y, z of the map's box: the dense box, or a sparse map's addressable range.
    pub fn box_dims_voxels(&self) -> [u32; 3] {
        match self.kind {
            MapKind::Dense => self.dims_voxels,
            MapKind::Sparse => SPARSE_DIMS_VOXELS,
        }
    }

    /// Voxels stored: the dense box's, or a sparse pool's.
    pub fn voxel_count(&self) -> u64 {
        match self.kind {
            MapKind::Dense => self.dims_voxels.iter().map(|&d| u64::from(d)).product(),
            MapKind::Sparse => u64::from(self.pool_blocks) * u64::from(crate::cpu::shared::BLOCK_VOXELS),
        }
    }

    /// Edge lengths of the map's box, metres.
    pub fn extent_m(&self) -> [f32; 3] {
        self.box_dims_voxels().map(|d| d as f32 * self.voxel_size_m)
    }

    /// Bytes of GPU memory the store takes (TSDF words, colour words, surface bricks; for a
    /// sparse map also its hash table, block keys, visible list, free list and counters).
    pub fn memory_bytes(&self) -> u64 {
        let words = self.voxel_count() * 4 * if self.color { 2 } else { 1 };
        match self.kind {
            MapKind::Dense => words + self.dims_voxels.iter().map(|&d| u64::from(d.div_ceil(8))).product::<u64>() * 4,
            MapKind::Sparse => words + u64::from(self.pool_blocks) * 16 + u64::from(crate::map::hash_slots_for_pool(self.pool_blocks)) * 8 + (crate::cpu::shared::MAP_COUNTERS * 4) as u64,
        }
    }

    /// Rejects settings the kernels cannot honour.
    pub fn validate(&self, max_binding_bytes: u64) -> Result<()> {
        let bad = |why: String| Err(Error::InvalidConfig(format!("TSDF volume: {why}")));
        if !(self.voxel_size_m > 0.0 && self.voxel_size_m.is_finite()) {
            return bad(format!("voxel size {} m must be positive", self.voxel_size_m));
        }
        let largest_pool = max_pool_blocks(max_binding_bytes);
        if self.kind == MapKind::Sparse && !(1..=largest_pool).contains(&self.pool_blocks) {
            return bad(format!("a sparse map's pool of {} blocks must hold 1..={largest_pool} (the device's {} MiB storage binding holds {largest_pool} blocks of 2 KiB)", self.pool_blocks, max_binding_bytes.min(crate::gpu::LARGEST_STORAGE_BINDING_BYTES) >> 20));
        }
        if self.kind == MapKind::Sparse && self.truncation_m > 8.0 * self.voxel_size_m {
            return bad(format!("truncation {} m: a sparse map allows at most a block (8 voxels, {} m)", self.truncation_m, 8.0 * self.voxel_size_m));
        }
        if self.kind == MapKind::Dense && self.dims_voxels.iter().any(|&d| !(2..=2048).contains(&d)) {
            return bad(format!("dimensions {:?} must be 2..=2048 voxels per axis", self.dims_voxels));
        }
        if !(self.truncation_m >= self.voxel_size_m && self.truncation_m.is_finite()) {
            return bad(format!("truncation {} m must be at least one voxel ({} m)", self.truncation_m, self.voxel_size_m));
        }
        if !(self.noise_band_sigmas >= 0.0 && self.noise_band_sigmas.is_finite()) {
            return bad(format!("noise band of {} standard deviations must be finite and at least 0", self.noise_band_sigmas));
        }
        if !(1..=0xffff).contains(&self.max_weight) {
            return bad(format!("max weight {} must be 1..=65535", self.max_weight));
        }
        if self.voxel_count() * 4 > max_binding_bytes {
            return bad(format!("{} voxels need {} MiB, over the device's {} MiB storage binding", self.voxel_count(), (self.voxel_count() * 4) >> 20, max_binding_bytes >> 20));
        }
        Ok(())
    }

    /// The description the kernels get, for a map with its origin (a dense box's voxel
    /// (0, 0, 0) corner, a sparse map's anchor voxel's corner) at `origin_in_world`.
    pub fn desc(&self, origin_in_world: [f32; 3]) -> VolumeDesc {
        let [dim_x, dim_y, dim_z] = self.box_dims_voxels();
        let (kind, hash_slots, pool_blocks) = match self.kind {
            MapKind::Dense => (MAP_DENSE, 0, 0),
            MapKind::Sparse => (MAP_SPARSE, crate::map::hash_slots_for_pool(self.pool_blocks), self.pool_blocks),
        };
        VolumeDesc {
            dim_x,
            dim_y,
            dim_z,
            kind,
            hash_slots,
            pool_blocks,
            max_weight: self.max_weight,
            origin_x_m: origin_in_world[0],
            origin_y_m: origin_in_world[1],
            origin_z_m: origin_in_world[2],
            voxel_size_m: self.voxel_size_m,
            truncation_m: self.truncation_m,
            noise_band_sigmas: self.noise_band_sigmas,
            _pad0: 0,
            _pad1: 0,
            _pad2: 0,
        }
    }

    /// The truncation band of a depth sample measured at `depth_m`, metres (see
    /// [`Self::noise_band_sigmas`]).
    pub fn truncation_band_m(&self, depth_m: f32) -> f32 {
        crate::cpu::shared::truncation_band_m(&self.desc([0.0; 3]), depth_m)
    }

    /// The map's origin for the first camera at `world_from_camera`: the corner of voxel
    /// (0, 0, 0) of a dense box, following [`Self::placement`]. The volume stays axis-aligned in
    /// world; with an identity first pose (the usual case) [`VolumePlacement::InFront`] spans
    /// x, y in [-e/2, e/2] and z in [0, e] of the first camera's frame. A sparse map's box is
    /// centred on the first camera: its origin is the corner of its anchor voxel
    /// (`voxel_anchor`, the middle of the box), the first camera's position snapped to the voxel
    /// lattice through the world origin (so a dense box placed at the identity and a sparse map
    /// share their voxel centres).
    pub fn origin_for_first_camera(&self, world_from_camera: &Se3) -> [f32; 3] {
        if self.kind == MapKind::Sparse {
            let c = world_from_camera.translation_m;
            let v = f64::from(self.voxel_size_m);
            let snap = |c: f64| ((c / v).round() * v) as f32;
            return [snap(c.x), snap(c.y), snap(c.z)];
        }
        let [ex, ey, ez] = self.extent_m();
        let ahead_m = match self.placement {
            VolumePlacement::InFront => f64::from(ez) / 2.0,
            VolumePlacement::Centred => 0.0,
        };
        let centre = world_from_camera.transform_point(glam::DVec3::new(0.0, 0.0, ahead_m));
        [centre.x as f32 - ex / 2.0, centre.y as f32 - ey / 2.0, centre.z as f32 - ez / 2.0]
    }
}

/// Mirror of WGSL `VolumeDesc` (shaders/wgsl/shared/tsdf.wgsl), generated from its layout.
pub use crate::kernels::gpu_data::VolumeDesc;

impl VolumeDesc {
    /// Voxel words stored: the dense box's, or a sparse pool's.
    pub fn voxel_count(&self) -> usize {
        if self.kind == MAP_SPARSE {
            return self.pool_blocks as usize * crate::cpu::shared::BLOCK_VOXELS as usize;
        }
        self.dim_x as usize * self.dim_y as usize * self.dim_z as usize
    }

    /// Surface-brick words: bricks of 8³ voxels (`cpu::shared::brick_dims`) covering a dense
    /// box, or a sparse map's pool blocks.
    pub fn brick_count(&self) -> usize {
        if self.kind == MAP_SPARSE {
            return self.pool_blocks as usize;
        }
        crate::cpu::shared::brick_dims(self).iter().map(|&b| b as usize).product()
    }

    /// World-space corners (min, max) of the map's box, metres.
    pub fn bounds_in_world(&self) -> ([f32; 3], [f32; 3]) {
        let lo = crate::cpu::shared::box_corner_in_world(self);
        let dims = [self.dim_x, self.dim_y, self.dim_z];
        (lo, std::array::from_fn(|i| lo[i] + dims[i] as f32 * self.voxel_size_m))
    }
}

/// What the pipeline needs from a TSDF store: its description and the buffers the kernels bind.
pub trait TsdfStore {
    /// Description of the volume (dimensions, placement, truncation).
    fn desc(&self) -> VolumeDesc;
    /// Voxel words (TSDF + weight).
    fn voxels(&self) -> &wgpu::Buffer;
    /// Colour words (RGB8), or a one-word placeholder when colour is off.
    fn colors(&self) -> &wgpu::Buffer;
    /// One word per brick of 8³ voxels (a sparse map: per pool block), non-zero once a voxel in
    /// it has held a TSDF below `FAR_TSDF` (integration marks them; the raycast skips the others).
    fn surface_bricks(&self) -> &wgpu::Buffer;
    /// A sparse map's hash table ((key, pool index) per slot); a placeholder word for a dense map.
    fn block_table(&self) -> &wgpu::Buffer;
    /// A sparse map's key per pool block; a placeholder word for a dense map.
    fn block_coords(&self) -> &wgpu::Buffer;
    /// Whether colour is fused.
    fn has_color(&self) -> bool;
    /// Forgets everything fused so far.
    fn reset(&self, gpu: &Gpu);
    /// GPU memory held, bytes.
    fn memory_bytes(&self) -> u64;
}

/// The dense store: every voxel of the box allocated.
#[derive(Debug)]
pub struct DenseTsdfVolume {
    config: TsdfConfig,
    desc: VolumeDesc,
    voxels: wgpu::Buffer,
    colors: wgpu::Buffer,
    surface_bricks: wgpu::Buffer,
    /// The placeholder word bound where kernels take a sparse map's table and keys.
    no_blocks: wgpu::Buffer,
}

impl DenseTsdfVolume {
    /// Allocates an empty (never observed) volume with its corner at `origin_in_world`.
    pub fn new(gpu: &Gpu, config: TsdfConfig, origin_in_world: [f32; 3]) -> Result<Self> {
        let config = TsdfConfig { kind: MapKind::Dense, ..config };
        config.validate(gpu.limits.max_storage_buffer_binding_size)?;
        let n = config.voxel_count() as usize;
        let voxels = gpu.storage_buffer::<u32>("core.tsdf.voxels", n);
        let colors = gpu.storage_buffer::<u32>("core.tsdf.colors", if config.color { n } else { 1 });
        let desc = config.desc(origin_in_world);
        let surface_bricks = gpu.storage_buffer::<u32>("core.tsdf.surface_bricks", desc.brick_count());
        let no_blocks = gpu.storage_buffer::<u32>("core.tsdf.no_blocks", 1);
        let volume = Self { config, desc, voxels, colors, surface_bricks, no_blocks };
        volume.reset(gpu);
        Ok(volume)
    }

    /// The settings it was created with.
    pub fn config(&self) -> &TsdfConfig {
        &self.config
    }
}

impl TsdfStore for DenseTsdfVolume {
    fn desc(&self) -> VolumeDesc {
        self.desc
    }
    fn voxels(&self) -> &wgpu::Buffer {
        &self.voxels
    }
    fn colors(&self) -> &wgpu::Buffer {
        &self.colors
    }
    fn surface_bricks(&self) -> &wgpu::Buffer {
        &self.surface_bricks
    }
    fn block_table(&self) -> &wgpu::Buffer {
        &self.no_blocks
    }
    fn block_coords(&self) -> &wgpu::Buffer {
        &self.no_blocks
    }
    fn has_color(&self) -> bool {
        self.config.color
    }
    fn reset(&self, gpu: &Gpu) {
        let mut encoder = gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("core.tsdf.reset") });
        encoder.clear_buffer(&self.voxels, 0, None);
        encoder.clear_buffer(&self.colors, 0, None);
        encoder.clear_buffer(&self.surface_bricks, 0, None);
        gpu.queue.submit([encoder.finish()]);
    }
    fn memory_bytes(&self) -> u64 {
        self.voxels.size() + self.colors.size() + self.surface_bricks.size()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_truncation_band_is_mu_where_the_sensor_is_precise_and_3_sigma_where_it_is_not() {
        // 11.7 mm voxels, μ = 4.7 cm: 3σ_z(z) of the Kinect model passes μ at 3.1 m.
        let c = TsdfConfig::default();
        assert_eq!(c.truncation_band_m(1.0), c.truncation_m);
        assert_eq!(c.truncation_band_m(3.0), c.truncation_m);
        let sigma_4m = crate::cpu::shared::kinect_sigma_m(4.0);
        assert!((c.truncation_band_m(4.0) - 3.0 * sigma_4m).abs() < 1e-7, "{} at 4 m", c.truncation_band_m(4.0));
        // At most 16 voxels, however noisy.
        assert_eq!(c.truncation_band_m(20.0), 16.0 * c.voxel_size_m);
        // 0 σ: μ at every depth (negative control).
        let fixed = TsdfConfig { noise_band_sigmas: 0.0, ..c };
        assert_eq!(fixed.truncation_band_m(4.0), c.truncation_m);
        // A band of no finite or negative width is refused with its name.
        for bad in [-1.0, f32::NAN, f32::INFINITY] {
            let err = TsdfConfig { noise_band_sigmas: bad, ..c }.validate(u64::MAX).expect_err("refused");
            assert!(err.to_string().contains("noise band"), "{bad}: {err}");
        }
        assert!(c.validate(u64::MAX).is_ok());
    }
}

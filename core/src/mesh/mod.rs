// SPDX-License-Identifier: MIT
//! Mesh extraction from a TSDF store by marching cubes, and export to PLY and glTF binary.
//!
//! Three kernels run over the cells (cubes between 8 voxel centres), grouped in 8 x 8 x 4
//! blocks, with no atomics at all:
//!
//! 1. `mc_count`: one invocation per block classifies its 256 cells against the table of
//!    [`mc_table`] (cells with an unobserved corner or only truncated corners give nothing)
//!    and writes the block's triangle count;
//! 2. `mc_scan`: one workgroup turns block counts into exclusive block offsets, lists the
//!    blocks with triangles, and writes the grand total and `mc_generate`'s dispatch size into
//!    [`McCounters`], flagging [`MC_FAILED_OUTPUT`] past the output capacity;
//! 3. `mc_generate`, dispatched indirectly, one workgroup per listed block: re-classifies its
//!    cells, scans their counts in workgroup memory and writes its triangles at block offset +
//!    local offset, only those in the requested range of triangle indices.
//!
//! Without atomics the output is the same, triangle for triangle, on every run and every
//! device (up to float rounding in the vertices). Each vertex carries the id of the voxel edge
//! it lies on, and [`Mesh::from_triangle_soup`] welds on that id into an indexed mesh.
//! Everything on the host is async with only async readbacks, so it runs unchanged in the
//! browser.
//!
//! Workgroup barriers are what costs on CPU adapters (lavapipe runs such workgroups as
//! coroutines, ~20 us each): only `mc_scan` and the `mc_generate` workgroups of blocks the
//! surface crosses use them.

pub mod glb;
pub mod mc_table;
pub mod ply;

use std::collections::HashMap;

pub use glb::write_glb;
pub use ply::write_ply;

use crate::cpu;
use crate::kernels::mc_count::{self, McCountParams, McGrid};
use crate::kernels::mc_generate::{self, McGenerateParams, McVertex};
use crate::kernels::mc_scan::{self, MC_FAILED_OUTPUT, McCounters, McScanParams, counters_buffer};
use crate::tsdf::{TsdfStore, VolumeDesc};
use crate::{Error, Gpu, Result};

/// Bytes one output triangle takes on the GPU (3 [`McVertex`]).
pub const BYTES_PER_TRIANGLE: u64 = 3 * std::mem::size_of::<McVertex>() as u64;

/// An indexed triangle mesh, world frame, metres. Triangles wind counter-clockwise seen from
/// free space (positive TSDF); normals point there too.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Mesh {
    /// Vertex positions, world metres.
    pub positions_m: Vec<[f32; 3]>,
    /// Unit vertex normals.
    pub normals: Vec<[f32; 3]>,
    /// Vertex colours, 8 bits per channel (white where the store has no colour).
    pub colors_rgb8: Vec<[u8; 3]>,
    /// Vertex indices of each triangle.
    pub triangles: Vec<[u32; 3]>,
}

/// Edge statistics of a triangle mesh: a closed, consistently oriented 2-manifold has every
/// edge shared by exactly two triangles that traverse it in opposite directions.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct MeshTopology {
    /// Distinct undirected edges.
    pub n_edges: usize,
    /// Edges used by one triangle only (holes, borders).
    pub n_boundary_edges: usize,
    /// Edges used by more than two triangles.
    pub n_non_manifold_edges: usize,
    /// Edges used by two triangles in the same direction (inconsistent winding).
    pub n_misoriented_edges: usize,
}

impl MeshTopology {
    /// Closed and consistently oriented, every edge shared by exactly two triangles.
    pub fn is_watertight(&self) -> bool {
        self.n_boundary_edges == 0 && self.n_non_manifold_edges == 0 && self.n_misoriented_edges == 0
    }
}

impl Mesh {
    /// Welds a triangle soup (3 vertices per triangle, as `mc_generate` writes it) into an
    /// indexed mesh: vertices with equal `edge_id` become one, numbered in order of first use.
    ///
    /// # Panics
    /// If `soup.len()` is not a multiple of 3.
    pub fn from_triangle_soup(soup: &[McVertex]) -> Self {
        assert!(soup.len().is_multiple_of(3), "a triangle soup has 3 vertices per triangle, got {}", soup.len());
        let mut mesh = Mesh { triangles: Vec::with_capacity(soup.len() / 3), ..Default::default() };
        let mut index_of_edge: HashMap<u32, u32> = HashMap::with_capacity(soup.len() / 2);
        for tri in soup.chunks_exact(3) {
            let mut t = [0u32; 3];
            for (slot, v) in t.iter_mut().zip(tri) {
                *slot = *index_of_edge.entry(v.edge_id).or_insert_with(|| {
                    mesh.positions_m.push([v.x_m, v.y_m, v.z_m]);
                    mesh.normals.push([v.normal_x, v.normal_y, v.normal_z]);
                    let c = v.color_rgb8.to_le_bytes();
                    mesh.colors_rgb8.push([c[0], c[1], c[2]]);
                    (mesh.positions_m.len() - 1) as u32
                });
            }
            mesh.triangles.push(t);
        }
        mesh
    }

    /// Vertices.
    pub fn vertex_count(&self) -> usize {
        self.positions_m.len()
    }

    /// Triangles.
    pub fn triangle_count(&self) -> usize {
        self.triangles.len()
    }

    /// Total triangle area, square metres.
    pub fn surface_area_m2(&self) -> f64 {
        self.triangles
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| self.positions_m[i as usize].map(f64::from));
                let u = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
                let v = [c[0] - a[0], c[1] - a[1], c[2] - a[2]];
                let n = [u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]];
                0.5 * (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt()
            })
            .sum()
    }

    /// Per-edge statistics; see [`MeshTopology`].
    pub fn topology(&self) -> MeshTopology {
        // Per undirected edge: (uses, uses going from the smaller index to the larger).
        let mut edges: HashMap<(u32, u32), (u32, u32)> = HashMap::with_capacity(self.triangles.len() * 3 / 2);
        for t in &self.triangles {
            for k in 0..3 {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                let e = edges.entry((a.min(b), a.max(b))).or_default();
                e.0 += 1;
                e.1 += u32::from(a < b);
            }
        }
        let mut out = MeshTopology { n_edges: edges.len(), ..Default::default() };
        for &(uses, forward) in edges.values() {
            match uses {
                1 => out.n_boundary_edges += 1,
                2 if forward != 1 => out.n_misoriented_edges += 1,
                2 => {}
                _ => out.n_non_manifold_edges += 1,
            }
        }
        out
    }
}

/// How [`extract_mesh_with`] sizes its output.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct MeshOptions {
    /// Room in the output buffer, triangles. `None` (the default): count first, read the
    /// total back, then generate into a buffer of exactly that size (one more GPU round trip,
    /// no overflow). `Some(n)`: record all three passes at once with room for `n` triangles;
    /// a larger mesh is [`Error::OutputOverflow`] unless `grow` is set.
    pub capacity_triangles: Option<u32>,
    /// With `capacity_triangles: Some(n)`, on overflow keep the first `n` triangles and
    /// generate the rest into a new buffer instead of returning [`Error::OutputOverflow`].
    pub grow: bool,
    /// Cap on any output buffer, triangles; `None` = what one storage binding holds
    /// ([`fn@max_capacity_triangles`]). Larger meshes are generated in several ranges.
    pub max_capacity_triangles: Option<u32>,
}

/// Extracts the zero level set of `store` on the GPU (output sized exactly after counting) and
/// welds it into an indexed mesh.
pub async fn extract_mesh(gpu: &Gpu, store: &dyn TsdfStore) -> Result<Mesh> {
    extract_mesh_with(gpu, store, &MeshOptions::default()).await
}

/// [`extract_mesh`] with explicit output sizing.
pub async fn extract_mesh_with(gpu: &Gpu, store: &dyn TsdfStore, options: &MeshOptions) -> Result<Mesh> {
    Ok(Mesh::from_triangle_soup(&extract_triangles(gpu, store, options).await?))
}

/// The most triangles one `vertices` binding of `gpu` holds.
pub fn max_capacity_triangles(gpu: &Gpu) -> u32 {
    let bytes = gpu.limits.max_storage_buffer_binding_size.min(gpu.limits.max_buffer_size);
    u32::try_from(bytes / BYTES_PER_TRIANGLE).unwrap_or(u32::MAX)
}

/// Runs the three kernels and reads back the triangle soup (3 [`McVertex`] per triangle, in
/// the deterministic order of blocks, cells and table slots).
///
/// With `options.capacity_triangles: Some(n)` and `grow` unset, a mesh of more than `n`
/// triangles is [`Error::OutputOverflow`] with the triangle count it needs.
pub async fn extract_triangles(gpu: &Gpu, store: &dyn TsdfStore, options: &MeshOptions) -> Result<Vec<McVertex>> {
    let volume = store.desc();
    let grid = McGrid::for_volume(&volume)?;
    let max_per_dimension = gpu.limits.max_compute_workgroups_per_dimension;
    let max_capacity = options.max_capacity_triangles.unwrap_or(u32::MAX).clamp(1, max_capacity_triangles(gpu));
    let first_capacity = options.capacity_triangles.map(|c| c.clamp(1, max_capacity));

    let table_words = mc_table::mc_table().packed();
    let table = gpu.storage_buffer::<u32>("core.mc.table", table_words.len());
    gpu.write_buffer(&table, &table_words);
    let block_counts = gpu.storage_buffer::<u32>("core.mc.block_counts", grid.n_blocks as usize);
    let block_offsets = gpu.storage_buffer::<u32>("core.mc.block_offsets", grid.n_blocks as usize);
    let active_blocks = gpu.storage_buffer::<u32>("core.mc.active_blocks", grid.active_blocks_len(max_per_dimension));
    let counters = counters_buffer(gpu);

    let count_params = gpu.uniform_buffer("core.mc_count.params", &McCountParams::new(volume, grid));
    let scan_params = McScanParams {
        n_blocks: grid.n_blocks,
        capacity_triangles: first_capacity.unwrap_or(max_capacity),
        max_workgroups_per_dimension: max_per_dimension,
        _pad0: 0,
    };
    let scan_params = gpu.uniform_buffer("core.mc_scan.params", &scan_params);
    let count_bg = mc_count::Bindings { params: &count_params, tsdf_volume: store.voxels(), mc_table: &table, block_counts: &block_counts, block_table: store.block_table(), block_coords: store.block_coords() }.bind_group(gpu);
    let scan_bg = mc_scan::Bindings { params: &scan_params, block_counts: &block_counts, block_offsets: &block_offsets, active_blocks: &active_blocks, counters: &counters }.bind_group(gpu);
    // Records mc_generate for triangles first..first + capacity into a new buffer.
    let generate = |encoder: &mut wgpu::CommandEncoder, first: u32, capacity: u32| {
        let params = gpu.uniform_buffer("core.mc_generate.params", &McGenerateParams::new(volume, grid, first, capacity, store.has_color()));
        let vertices = gpu.storage_buffer::<McVertex>("core.mc.vertices", 3 * capacity as usize);
        let bg = mc_generate::Bindings {
            params: &params,
            tsdf_volume: store.voxels(),
            colors: store.colors(),
            mc_table: &table,
            active_blocks: &active_blocks,
            block_offsets: &block_offsets,
            vertices: &vertices,
            block_table: store.block_table(),
            block_coords: store.block_coords(),
        }
        .bind_group(gpu);
        crate::kernels::mc_generate::encode_indirect(gpu, encoder, &bg, &counters);
        vertices
    };

    let mut encoder = gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("core.mc") });
    crate::kernels::mc_count::encode(gpu, &mut encoder, &count_bg, &grid);
    crate::kernels::mc_scan::encode(gpu, &mut encoder, &scan_bg);
    let first_pass = first_capacity.map(|capacity| (capacity, generate(&mut encoder, 0, capacity)));
    gpu.submit_and_wait(encoder).await?;
    let c = gpu.read_buffer::<McCounters>(&counters, 1).await?[0];
    let total = c.n_triangles;

    let mut soup = Vec::with_capacity(3 * total as usize);
    let mut first = 0u32;
    if let Some((capacity, vertices)) = first_pass {
        if c.failed & MC_FAILED_OUTPUT == 0 {
            return read_vertices(gpu, &vertices, total).await;
        }
        if !options.grow {
            return Err(Error::OutputOverflow { stage: "mc_generate", needed: total.into(), capacity: capacity.into() });
        }
        // Keep the triangles that fit; the counts, offsets and dispatch size stay valid.
        soup.extend(read_vertices(gpu, &vertices, capacity).await?);
        first = capacity;
    }
    // The rest, into a buffer sized to it (or the cap), in as many ranges as needed.
    let capacity = (total - first).min(max_capacity);
    while first < total {
        let mut encoder = gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("core.mc.generate") });
        let vertices = generate(&mut encoder, first, capacity);
        gpu.submit_and_wait(encoder).await?;
        let n = capacity.min(total - first);
        soup.extend(read_vertices(gpu, &vertices, n).await?);
        first += n;
    }
    Ok(soup)
}

async fn read_vertices(gpu: &Gpu, vertices: &wgpu::Buffer, n_triangles: u32) -> Result<Vec<McVertex>> {
    if n_triangles == 0 {
        return Ok(Vec::new());
    }
    gpu.read_buffer::<McVertex>(vertices, 3 * n_triangles as usize).await
}

/// CPU twin of [`extract_mesh`]: the three CPU references, then the same weld. `colors` is
/// one RGB8 word per voxel, or `None` for white vertices.
pub fn extract_mesh_cpu(tsdf_volume: &[u32], colors: Option<&[u32]>, volume: &VolumeDesc) -> Result<Mesh> {
    Ok(Mesh::from_triangle_soup(&extract_triangles_cpu(tsdf_volume, colors, volume)?))
}

/// Dispatch-size limit the CPU path assumes (WebGPU's default).
pub const CPU_MAX_WORKGROUPS_PER_DIMENSION: u32 = 65_535;

/// CPU twin of [`extract_triangles`] for a dense box, with an output sized to the total.
pub fn extract_triangles_cpu(tsdf_volume: &[u32], colors: Option<&[u32]>, volume: &VolumeDesc) -> Result<Vec<McVertex>> {
    extract_map_triangles_cpu(tsdf_volume, colors, &[0], &[0], volume)
}

/// CPU twin of [`extract_triangles`] for a map of either kind (`block_table` and
/// `block_coords`: a sparse map's hash table and key per pool block).
pub fn extract_map_triangles_cpu(tsdf_volume: &[u32], colors: Option<&[u32]>, block_table: &[u32], block_coords: &[u32], volume: &VolumeDesc) -> Result<Vec<McVertex>> {
    let grid = McGrid::for_volume(volume)?;
    let n_voxels = volume.voxel_count();
    if tsdf_volume.len() < n_voxels || colors.is_some_and(|c| c.len() < n_voxels) {
        return Err(Error::InvalidConfig(format!(
            "marching cubes: volume of {n_voxels} voxels but {} voxel words and {:?} colour words given",
            tsdf_volume.len(),
            colors.map(<[u32]>::len)
        )));
    }
    let table = mc_table::mc_table().packed();
    let mut block_counts = vec![0u32; grid.n_blocks as usize];
    cpu::mc_count(&McCountParams::new(*volume, grid), tsdf_volume, &table, &mut block_counts, block_table, block_coords);
    let mut block_offsets = vec![0u32; grid.n_blocks as usize];
    let mut active_blocks = vec![0u32; grid.active_blocks_len(CPU_MAX_WORKGROUPS_PER_DIMENSION)];
    let mut counters = McCounters::default();
    let scan_params = McScanParams { n_blocks: grid.n_blocks, capacity_triangles: u32::MAX, max_workgroups_per_dimension: CPU_MAX_WORKGROUPS_PER_DIMENSION, _pad0: 0 };
    cpu::mc_scan(&scan_params, &block_counts, &mut block_offsets, &mut active_blocks, &mut counters);
    let total = counters.n_triangles;
    let mut soup = vec![McVertex::default(); 3 * total as usize];
    let p = McGenerateParams::new(*volume, grid, 0, total, colors.is_some());
    let [x, y, z] = counters.generate_workgroups();
    cpu::mc_generate(&p, tsdf_volume, colors.unwrap_or(&[0]), &table, &active_blocks, &block_offsets, &mut soup, block_table, block_coords, x * y * z);
    Ok(soup)
}

/// Builds voxel words from a signed distance function (metres, positive outside), sampled at
/// every voxel centre, scaled by the truncation and packed with `weight`: synthetic volumes
/// for tests and demos.
pub fn tsdf_from_sdf(volume: &VolumeDesc, weight: u32, sdf_m: impl Fn([f32; 3]) -> f32) -> Vec<u32> {
    let mut words = Vec::with_capacity(volume.voxel_count());
    for z in 0..volume.dim_z {
        for y in 0..volume.dim_y {
            for x in 0..volume.dim_x {
                let p = cpu::shared::voxel_centre_in_world(volume, x, y, z);
                words.push(cpu::shared::pack_voxel(sdf_m(p) / volume.truncation_m, weight));
            }
        }
    }
    words
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::tsdf::TsdfConfig;

    fn sphere_volume(dim: u32, radius_m: f32) -> (VolumeDesc, Vec<u32>, [f32; 3]) {
        let voxel_m = 0.01;
        let desc = TsdfConfig::cube(dim, voxel_m).desc([0.0; 3]);
        // Off-grid centre so no voxel sits exactly on the surface.
        let c = [dim as f32 * voxel_m * 0.5 + 0.0013, dim as f32 * voxel_m * 0.5 - 0.0007, dim as f32 * voxel_m * 0.5 + 0.0003];
        let words = tsdf_from_sdf(&desc, 1, |p| ((p[0] - c[0]).powi(2) + (p[1] - c[1]).powi(2) + (p[2] - c[2]).powi(2)).sqrt() - radius_m);
        (desc, words, c)
    }

    #[test]
    fn sphere_is_watertight_with_the_right_area_and_outward_normals() {
        let r = 0.12;
        let (desc, words, c) = sphere_volume(40, r);
        let mesh = extract_mesh_cpu(&words, None, &desc).unwrap();
        let topo = mesh.topology();
        assert!(topo.is_watertight(), "{topo:?}");
        // Euler characteristic of a sphere: V - E + F = 2.
        assert_eq!(mesh.vertex_count() as i64 - topo.n_edges as i64 + mesh.triangle_count() as i64, 2, "genus 0");
        let area = mesh.surface_area_m2();
        let exact = 4.0 * std::f64::consts::PI * f64::from(r).powi(2);
        assert!((area / exact - 1.0).abs() < 0.01, "area {area} vs 4 pi r^2 = {exact}");
        for (i, p) in mesh.positions_m.iter().enumerate() {
            let d = [p[0] - c[0], p[1] - c[1], p[2] - c[2]];
            let dist = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
            assert!((dist - r).abs() < 0.1 * desc.voxel_size_m, "vertex {i} at {dist} m from the centre");
            let n = mesh.normals[i];
            let cos = (n[0] * d[0] + n[1] * d[1] + n[2] * d[2]) / dist;
            assert!(cos > 0.999, "vertex {i}: normal {n:?} is not radial (cos {cos})");
        }
        // Winding: every triangle's geometric normal points outward.
        for t in &mesh.triangles {
            let [a, b, cc] = t.map(|i| mesh.positions_m[i as usize]);
            let u = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
            let v = [cc[0] - a[0], cc[1] - a[1], cc[2] - a[2]];
            let n = [u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]];
            let out = [a[0] - c[0], a[1] - c[1], a[2] - c[2]];
            assert!(n[0] * out[0] + n[1] * out[1] + n[2] * out[2] >= 0.0, "triangle {t:?} faces inward");
        }
    }

    #[test]
    fn random_fields_give_closed_consistent_surfaces() {
        // Random TSDF inside a border of free space: every saddle configuration occurs, and the
        // face rule must still close every surface.
        let dim = 14;
        let desc = TsdfConfig::cube(dim, 0.01).desc([0.0; 3]);
        let mut state = 0x2545_f491_4f6c_dd1du64;
        let mut words = Vec::new();
        for z in 0..dim {
            for y in 0..dim {
                for x in 0..dim {
                    state ^= state << 13;
                    state ^= state >> 7;
                    state ^= state << 17;
                    let border = [x, y, z].iter().any(|&v| v == 0 || v == dim - 1);
                    let t = if border { 1.0 } else { (state >> 40) as f32 / (1u64 << 24) as f32 * 1.6 - 0.8 };
                    words.push(cpu::shared::pack_voxel(t, 1));
                }
            }
        }
        let mesh = extract_mesh_cpu(&words, None, &desc).unwrap();
        assert!(mesh.triangle_count() > 1000, "a busy field: {} triangles", mesh.triangle_count());
        let topo = mesh.topology();
        assert!(topo.is_watertight(), "{topo:?}");
        // Negative control: dropping a triangle opens the surface and is detected.
        let mut holed = mesh.clone();
        holed.triangles.pop();
        assert_eq!(holed.topology().n_boundary_edges, 3, "a missing triangle leaves 3 boundary edges");
        let mut flipped = mesh.clone();
        flipped.triangles[0].swap(1, 2);
        assert_eq!(flipped.topology().n_misoriented_edges, 3, "a flipped triangle misorients its 3 edges");
    }

    #[test]
    fn unobserved_and_truncated_cells_are_skipped() {
        let (desc, mut words, _) = sphere_volume(24, 0.06);
        let full = extract_mesh_cpu(&words, None, &desc).unwrap();
        // Unobserve one voxel on the surface: the 8 cells around it lose their triangles and
        // the surface gets a hole.
        let surface_voxel = (0..words.len()).find(|&i| cpu::shared::voxel_tsdf(words[i]).abs() < 0.1).unwrap();
        words[surface_voxel] &= 0xffff;
        let holed = extract_mesh_cpu(&words, None, &desc).unwrap();
        assert!(holed.triangle_count() < full.triangle_count(), "fewer triangles");
        assert!(holed.topology().n_boundary_edges > 0, "an open hole");
        // All truncated, mixed signs (+1 next to -1): no triangles.
        let flip = tsdf_from_sdf(&desc, 1, |p| if p[0] < 0.12 { -1.0 } else { 1.0 });
        assert_eq!(extract_triangles_cpu(&flip, None, &desc).unwrap().len(), 0, "a +1/-1 step is no surface");
        let step = tsdf_from_sdf(&desc, 1, |p| if p[0] < 0.12 { -0.01 } else { 0.01 });
        assert!(!extract_triangles_cpu(&step, None, &desc).unwrap().is_empty(), "a small step is a surface");
    }

    #[test]
    fn colours_interpolate_along_the_edge() {
        let desc = TsdfConfig::cube(4, 0.1).desc([0.0; 3]);
        // Plane x = 0.2 m: crossing between voxel centres x = 0.15 and 0.25 at t = 0.5.
        let words = tsdf_from_sdf(&desc, 1, |p| p[0] - 0.2);
        let colors: Vec<u32> = (0..desc.voxel_count()).map(|i| if i % 4 < 2 { 0x0000_00ff } else { 0x00ff_0000 }).collect();
        let mesh = extract_mesh_cpu(&words, Some(&colors), &desc).unwrap();
        assert!(mesh.vertex_count() > 0, "a plane");
        for (p, c) in mesh.positions_m.iter().zip(&mesh.colors_rgb8) {
            assert!((p[0] - 0.2).abs() < 1e-6, "vertex x {}", p[0]);
            assert_eq!(*c, [128, 0, 128], "half red, half blue");
        }
        let white = extract_mesh_cpu(&words, None, &desc).unwrap();
        assert!(white.colors_rgb8.iter().all(|c| *c == [255; 3]), "no colour: white");
        assert!(white.normals.iter().all(|n| (n[0] - 1.0).abs() < 1e-6), "normals along +x, toward free space");
    }
}

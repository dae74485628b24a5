// SPDX-License-Identifier: MIT
//! Marching cubes over a sparse map: a sphere stored as voxel blocks meshes to the same closed
//! surface as the sphere in a dense box on the same voxel lattice (same triangle count, every
//! vertex within a micrometre of the dense mesh's, watertight across block seams, the area of the
//! sphere), the GPU matches the CPU twin, and blocks round-trip through download and upload
//! unchanged. Bad uploads (too many blocks, a block outside the box, one given twice) are
//! typed errors that leave the map empty.

use std::collections::BTreeMap;

use webfusion_core::cpu::shared::{BLOCK_VOXELS, BRICK_SHIFT, pack_voxel, voxel_centre_in_world};
use webfusion_core::map::{MapBlock, SparseMap};
use webfusion_core::mesh::{Mesh, extract_map_triangles_cpu, extract_mesh, extract_triangles, tsdf_from_sdf, MeshOptions};
use webfusion_core::tsdf::{DenseTsdfVolume, TsdfConfig, TsdfStore, VolumeDesc};
use webfusion_core::{Gpu, Se3};
use webfusion_tests::{finish, gpu};

const VOXEL_M: f32 = 0.02;
const CENTRE_M: [f32; 3] = [0.1, -0.05, 1.0];
const RADIUS_M: f32 = 0.3;

fn sphere_sdf(p: [f32; 3]) -> f32 {
    (0..3).map(|i| (p[i] - CENTRE_M[i]).powi(2)).sum::<f32>().sqrt() - RADIUS_M
}

/// The sphere's blocks in a sparse map of `desc`: every block of the sphere's bounding box
/// (plus μ) with a voxel within the truncation band.
fn sphere_blocks(desc: &VolumeDesc) -> Vec<MapBlock> {
    let origin = webfusion_core::cpu::shared::box_corner_in_world(desc);
    let block_m = VOXEL_M * (1 << BRICK_SHIFT) as f32;
    let reach = RADIUS_M + desc.truncation_m + block_m;
    let lo: [u32; 3] = std::array::from_fn(|i| ((CENTRE_M[i] - reach - origin[i]) / block_m).floor() as u32);
    let hi: [u32; 3] = std::array::from_fn(|i| ((CENTRE_M[i] + reach - origin[i]) / block_m).ceil() as u32);
    let mut blocks = Vec::new();
    for bz in lo[2]..hi[2] {
        for by in lo[1]..hi[1] {
            for bx in lo[0]..hi[0] {
                let voxels: Vec<u32> = (0..BLOCK_VOXELS)
                    .map(|l| {
                        let g = [(bx << BRICK_SHIFT) + (l & 7), (by << BRICK_SHIFT) + ((l >> 3) & 7), (bz << BRICK_SHIFT) + (l >> 6)];
                        pack_voxel(sphere_sdf(voxel_centre_in_world(desc, g[0], g[1], g[2])) / desc.truncation_m, 1)
                    })
                    .collect();
                if voxels.iter().any(|&w| webfusion_core::cpu::shared::voxel_tsdf(w).abs() < 1.0) {
                    blocks.push(MapBlock { coords: [bx, by, bz], voxels, colors: Vec::new() });
                }
            }
        }
    }
    blocks
}

fn sparse_map(gpu: &Gpu, pool_blocks: u32) -> SparseMap {
    let config = TsdfConfig { color: false, ..TsdfConfig::sparse(VOXEL_M, pool_blocks) };
    SparseMap::new(gpu, config, config.origin_for_first_camera(&Se3::IDENTITY)).expect("sparse map")
}

/// Cell of the vertex grid: larger than any allowed vertex distance.
const CELL_M: f32 = 1e-3;

/// Vertices of `mesh` by position rounded to 1 mm cells (for nearest look-ups).
fn vertex_grid(mesh: &Mesh) -> BTreeMap<[i64; 3], Vec<[f32; 3]>> {
    let mut grid: BTreeMap<[i64; 3], Vec<[f32; 3]>> = BTreeMap::new();
    for v in &mesh.positions_m {
        grid.entry(v.map(|c| (c / CELL_M).floor() as i64)).or_default().push(*v);
    }
    grid
}

/// Largest distance from a vertex of `a` to the nearest vertex of `b` (searching ±1 cell: a
/// vertex farther than a cell counts as infinitely far).
fn max_vertex_distance(a: &Mesh, b: &Mesh) -> f32 {
    let grid = vertex_grid(b);
    let mut worst = 0.0f32;
    for v in &a.positions_m {
        let c = v.map(|c| (c / CELL_M).floor() as i64);
        let mut best = f32::INFINITY;
        for dz in -1..=1 {
            for dy in -1..=1 {
                for dx in -1..=1 {
                    for w in grid.get(&[c[0] + dx, c[1] + dy, c[2] + dz]).into_iter().flatten() {
                        best = best.min((0..3).map(|i| (v[i] - w[i]).powi(2)).sum::<f32>().sqrt());
                    }
                }
            }
        }
        worst = worst.max(best);
    }
    worst
}

#[test]
fn a_sparse_sphere_meshes_like_the_dense_one() {
    let gpu = gpu();
    let map = sparse_map(&gpu, 2048);
    let blocks = sphere_blocks(&map.desc());
    eprintln!("{} blocks of 8³ voxels hold the sphere", blocks.len());
    map.upload_blocks(&gpu, &blocks).expect("upload");
    let sparse = pollster::block_on(extract_mesh(&gpu, &map)).expect("sparse mesh");
    // The dense box on the same lattice (the default in-front placement at the identity).
    let dense_config = TsdfConfig { color: false, ..TsdfConfig::cube(96, VOXEL_M) };
    let dense_desc = dense_config.desc(dense_config.origin_for_first_camera(&Se3::IDENTITY));
    let dense_store = DenseTsdfVolume::new(&gpu, dense_config, [dense_desc.origin_x_m, dense_desc.origin_y_m, dense_desc.origin_z_m]).expect("dense box");
    gpu.write_buffer(dense_store.voxels(), &tsdf_from_sdf(&dense_desc, 1, sphere_sdf));
    let dense = pollster::block_on(extract_mesh(&gpu, &dense_store)).expect("dense mesh");
    let (area, exact) = (sparse.surface_area_m2(), 4.0 * std::f64::consts::PI * f64::from(RADIUS_M).powi(2));
    let apart = max_vertex_distance(&sparse, &dense).max(max_vertex_distance(&dense, &sparse));
    eprintln!("sparse {} triangles, dense {}; vertices at most {:.1} µm apart; area {area:.4} vs {exact:.4} m²", sparse.triangle_count(), dense.triangle_count(), apart * 1e6);
    assert_eq!(sparse.triangle_count(), dense.triangle_count(), "the same surface");
    // Both maps compute positions from origins near the sphere (a sparse map from its anchor
    // voxel, not its box corner 164 m away): the vertices agree to f32 rounding (0.1 µm seen).
    assert!(apart < 1e-6, "vertices within a micrometre: {apart} m");
    assert!(sparse.topology().is_watertight(), "closed across block seams: {:?}", sparse.topology());
    assert!((area / exact - 1.0).abs() < 0.01, "area {area} vs 4πr² {exact}");
    // GPU vs the CPU twin on the map's own buffers.
    let d = map.desc();
    let voxels: Vec<u32> = pollster::block_on(gpu.read_buffer(map.voxels(), d.voxel_count())).expect("voxels");
    let table: Vec<u32> = pollster::block_on(gpu.read_buffer(map.block_table(), 2 * d.hash_slots as usize)).expect("table");
    let coords: Vec<u32> = pollster::block_on(gpu.read_buffer(map.block_coords(), d.pool_blocks as usize)).expect("coords");
    let cpu = extract_map_triangles_cpu(&voxels, None, &table, &coords, &d).expect("CPU twin");
    let gpu_soup = pollster::block_on(extract_triangles(&gpu, &map, &MeshOptions::default())).expect("GPU soup");
    assert_eq!(gpu_soup.len(), cpu.len(), "GPU and twin make as many vertices");
    let worst = gpu_soup.iter().zip(&cpu).map(|(g, c)| (g.x_m - c.x_m).abs().max((g.y_m - c.y_m).abs()).max((g.z_m - c.z_m).abs())).fold(0.0f32, f32::max);
    assert!(worst < 1e-5, "GPU vs twin vertices within 10 µm: {worst}");
    assert!(gpu_soup.iter().zip(&cpu).all(|(g, c)| g.edge_id == c.edge_id), "the same welding edges");
    finish(&gpu);
}

#[test]
fn blocks_round_trip_and_bad_uploads_are_refused() {
    let gpu = gpu();
    let map = sparse_map(&gpu, 2048);
    let mut blocks = sphere_blocks(&map.desc());
    blocks.reverse();
    map.upload_blocks(&gpu, &blocks).expect("upload");
    let back = pollster::block_on(map.download_blocks(&gpu)).expect("download");
    blocks.sort_by_key(|b| webfusion_core::cpu::shared::block_key(b.coords));
    assert_eq!(back, blocks, "the same blocks with the same voxels, in key order");
    let stats = pollster::block_on(map.stats(&gpu)).expect("stats");
    assert_eq!(stats.blocks_used as usize, blocks.len(), "the counters know the blocks");

    let small = sparse_map(&gpu, 16);
    let err = small.upload_blocks(&gpu, &blocks).expect_err("too many blocks");
    assert!(err.to_string().contains("pool holds 16"), "{err}");
    let mut twice = blocks[..3].to_vec();
    twice.push(blocks[0].clone());
    assert!(map.upload_blocks(&gpu, &twice).expect_err("a block twice").to_string().contains("twice"));
    let mut outside = blocks[..1].to_vec();
    outside[0].coords[2] = 5000;
    assert!(map.upload_blocks(&gpu, &outside).expect_err("outside").to_string().contains("outside the box"));
    assert!(pollster::block_on(map.download_blocks(&gpu)).expect("download").is_empty(), "a refused upload leaves the map empty");
    finish(&gpu);
}

#[test]
fn the_devices_largest_pool_is_addressed_to_its_last_block_and_one_more_is_refused() {
    // The largest pool one storage binding of this device holds (65,536 blocks on a device with
    // WebGPU's default 128 MiB binding, more where the adapter offers larger bindings: the
    // device requests them). The sphere's blocks are uploaded last, so they occupy the pool's
    // top slots, past every index a smaller pool has.
    let gpu = gpu();
    let largest = webfusion_core::map::max_pool_blocks(gpu.limits.max_storage_buffer_binding_size);
    assert!(largest >= webfusion_core::map::PORTABLE_MAX_POOL_BLOCKS, "every device holds the portable pool: {largest}");
    let map = sparse_map(&gpu, largest);
    let sphere = sphere_blocks(&map.desc());
    let sphere_keys: std::collections::BTreeSet<u32> = sphere.iter().map(|b| webfusion_core::cpu::shared::block_key(b.coords)).collect();
    // Filler: observed free space (TSDF +1) in blocks far from the sphere, along x at z = 0.
    let free = pack_voxel(1.0, 1);
    let fillers = (largest as usize) - sphere.len();
    let mut blocks: Vec<MapBlock> = (0..fillers as u32)
        .map(|i| MapBlock { coords: [i % 2048, (i / 2048) % 2048, 1 + i / (2048 * 2048)], voxels: vec![free; BLOCK_VOXELS as usize], colors: Vec::new() })
        .filter(|b| !sphere_keys.contains(&webfusion_core::cpu::shared::block_key(b.coords)))
        .collect();
    assert_eq!(blocks.len(), fillers, "no filler block meets the sphere's");
    blocks.extend(sphere.iter().cloned());
    map.upload_blocks(&gpu, &blocks).expect("a full pool uploads");
    let stats = pollster::block_on(map.stats(&gpu)).expect("stats");
    assert_eq!(stats.blocks_used, largest, "every block of the pool in use");
    let full = pollster::block_on(extract_mesh(&gpu, &map)).expect("mesh of the full pool");
    // The same sphere alone in a small pool: the same surface.
    let small = sparse_map(&gpu, 2048);
    small.upload_blocks(&gpu, &sphere).expect("upload");
    let alone = pollster::block_on(extract_mesh(&gpu, &small)).expect("mesh of the sphere alone");
    eprintln!("pool of {largest} blocks ({} MiB binding): {} triangles, the sphere alone {}", gpu.limits.max_storage_buffer_binding_size >> 20, full.triangle_count(), alone.triangle_count());
    assert!(alone.triangle_count() > 1000, "the sphere meshes: {}", alone.triangle_count());
    assert_eq!(full.triangle_count(), alone.triangle_count(), "the pool's top blocks mesh as the sphere");
    assert!(max_vertex_distance(&full, &alone).max(max_vertex_distance(&alone, &full)) < 1e-6, "the same vertices");
    // A pool one block larger than a binding holds is refused, naming the binding.
    let config = TsdfConfig { color: false, ..TsdfConfig::sparse(VOXEL_M, largest + 1) };
    let err = SparseMap::new(&gpu, config, config.origin_for_first_camera(&Se3::IDENTITY)).map(|_| ()).expect_err("one block too many").to_string();
    assert!(err.contains(&format!("1..={largest}")) && err.contains("storage binding"), "{err}");
    finish(&gpu);
}

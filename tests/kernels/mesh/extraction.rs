// SPDX-License-Identifier: MIT
//! Marching cubes end to end: a CPU-built TSDF uploaded into a `DenseTsdfVolume`, extracted
//! on the GPU (`mc_count` -> `mc_scan` -> `mc_generate` -> weld) and on the CPU reference, then
//! compared triangle by triangle; watertightness and area of a closed sphere; the overflow
//! error, buffer growth and multi-range generation; a 256^3 volume with timings. Also the
//! test volumes and u32 comparison helpers the three `mc_*` kernel tests share.

use std::time::Instant;

use webfusion_core::kernels::mc_count::{self as mc_count, McCountParams, McGrid};
use webfusion_core::kernels::mc_generate::{self as mc_generate, McGenerateParams, McVertex};
use webfusion_core::kernels::mc_scan::{self as mc_scan, McCounters, McScanParams, counters_buffer};
use webfusion_core::mesh::{self, Mesh, MeshOptions, mc_table::mc_table};
use webfusion_core::tsdf::{DenseTsdfVolume, TsdfConfig, TsdfStore, VolumeDesc};
use webfusion_core::{Error, Gpu, cpu::shared::pack_voxel};
use webfusion_tests::{Tolerance, assert_negative_control, compare_f32, finish, gpu};

/// Vertex positions: GPU and CPU compute `centre + t * voxel` with `t = v0 / (v0 - v1)`; GPU
/// division may be off by 2.5 ulp, i.e. ~3e-7 of a voxel. 1e-6 m absolute covers the volumes
/// here (a few metres wide: ulp(4 m) = 4.8e-7 m).
pub(crate) const POSITION_TOL: Tolerance = Tolerance { absolute: 1e-6, relative: 0.0 };
/// Unit-normal components: six trilinear samples (with a division each) differenced and
/// normalised; 2e-5 absolute.
pub(crate) const NORMAL_TOL: Tolerance = Tolerance { absolute: 2e-5, relative: 0.0 };
/// Colour channels: the interpolated value may round to the neighbouring 8-bit level.
pub(crate) const COLOR_TOL_LEVELS: u8 = 1;

/// A test volume: description, voxel words and optional colour words.
#[derive(Clone, Debug)]
pub(crate) struct TestVolume {
    pub(crate) desc: VolumeDesc,
    pub(crate) words: Vec<u32>,
    pub(crate) colors: Option<Vec<u32>>,
}

impl TestVolume {
    pub(crate) fn colors_or_placeholder(&self) -> &[u32] {
        self.colors.as_deref().unwrap_or(&[0])
    }
}

/// Colour that varies smoothly with position (so interpolation is visible).
fn position_color(p: [f32; 3], extent_m: f32) -> u32 {
    webfusion_core::cpu::shared::pack_rgb8(p.map(|v| v / extent_m))
}

/// A sphere of `radius_voxels` in a cube of `dim` voxels of `voxel_m`, its centre off the voxel
/// grid, weight 1 everywhere, optional colour.
pub(crate) fn sphere(dim: u32, voxel_m: f32, radius_voxels: f32, color: bool) -> (TestVolume, [f32; 3], f32) {
    let desc = TsdfConfig::cube(dim, voxel_m).desc([-0.3, 0.2, 1.0]);
    let (lo, hi) = desc.bounds_in_world();
    let c: [f32; 3] = std::array::from_fn(|i| 0.5 * (lo[i] + hi[i]) + [0.13, -0.07, 0.03][i] * voxel_m);
    let r = radius_voxels * voxel_m;
    let words = mesh::tsdf_from_sdf(&desc, 1, |p| ((p[0] - c[0]).powi(2) + (p[1] - c[1]).powi(2) + (p[2] - c[2]).powi(2)).sqrt() - r);
    let extent = dim as f32 * voxel_m;
    let colors = color.then(|| voxel_centres(&desc).map(|p| position_color([p[0] - lo[0], p[1] - lo[1], p[2] - lo[2]], extent)).collect());
    (TestVolume { desc, words, colors }, c, r)
}

fn voxel_centres(d: &VolumeDesc) -> impl Iterator<Item = [f32; 3]> + '_ {
    (0..d.dim_z).flat_map(move |z| (0..d.dim_y).flat_map(move |y| (0..d.dim_x).map(move |x| webfusion_core::cpu::shared::voxel_centre_in_world(d, x, y, z))))
}

/// xorshift64: a fixed, dependency-free random stream.
pub(crate) struct Rng(u64);

impl Rng {
    pub(crate) fn new(seed: u64) -> Self {
        Self(seed | 1)
    }
    pub(crate) fn next_u32(&mut self) -> u32 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 32) as u32
    }
    pub(crate) fn unit(&mut self) -> f32 {
        (self.next_u32() >> 8) as f32 / (1u32 << 24) as f32
    }
}

/// A non-cubic volume of random TSDF (every case and saddle occurs), with ~3 % unobserved
/// voxels and ~10 % truncated (+-1) ones, random weights and colours.
pub(crate) fn random_field(dims: [u32; 3], seed: u64, color: bool) -> TestVolume {
    let mut desc = TsdfConfig::cube(2, 0.02).desc([0.1, -0.2, 0.5]);
    (desc.dim_x, desc.dim_y, desc.dim_z) = (dims[0], dims[1], dims[2]);
    let mut rng = Rng::new(seed);
    let words = (0..desc.voxel_count())
        .map(|_| {
            let u = rng.unit();
            let weight = if u < 0.03 { 0 } else { 1 + rng.next_u32() % 100 };
            let tsdf = if u > 0.9 { if rng.unit() < 0.5 { -1.0 } else { 1.0 } } else { rng.unit() * 1.6 - 0.8 };
            pack_voxel(tsdf, weight)
        })
        .collect();
    let colors = color.then(|| (0..desc.voxel_count()).map(|_| rng.next_u32() & 0x00ff_ffff).collect());
    TestVolume { desc, words, colors }
}

/// Exact comparison of u32 outputs.
pub(crate) fn compare_u32(what: &str, gpu: &[u32], cpu: &[u32]) -> Result<usize, String> {
    if gpu.len() != cpu.len() {
        return Err(format!("{what}: GPU gave {} values, CPU {}", gpu.len(), cpu.len()));
    }
    match gpu.iter().zip(cpu).position(|(g, c)| g != c) {
        Some(i) => Err(format!("{what}[{i}]: GPU {:#x} vs CPU {:#x}", gpu[i], cpu[i])),
        None => Ok(gpu.len()),
    }
}

/// [`compare_u32`] must reject a changed value, an unwritten (sentinel) one and a truncated
/// result.
pub(crate) fn assert_negative_control_u32(what: &str, gpu: &[u32], cpu: &[u32]) {
    compare_u32(what, gpu, cpu).unwrap_or_else(|e| panic!("negative control needs a passing pair first: {e}"));
    let ix = cpu.iter().position(|&v| v != 0).unwrap_or(0);
    let mut moved = gpu.to_vec();
    moved[ix] = moved[ix].wrapping_add(1);
    assert!(compare_u32(what, &moved, cpu).is_err(), "{what}: a changed value was accepted");
    let mut sentinel = gpu.to_vec();
    sentinel[ix] = webfusion_tests::SENTINEL_F32.to_bits();
    assert!(compare_u32(what, &sentinel, cpu).is_err(), "{what}: an unwritten (sentinel) value was accepted");
    assert!(compare_u32(what, &gpu[..gpu.len() - 1], cpu).is_err(), "{what}: a short result was accepted");
}

/// Largest |GPU - CPU| of each vertex quantity.
#[derive(Clone, Copy, Debug, Default)]
#[expect(dead_code, reason = "read through Debug in the test logs")]
pub(crate) struct SoupDiff {
    pub(crate) max_position_err_m: f32,
    pub(crate) max_normal_err: f32,
    pub(crate) max_color_err_levels: u8,
}

fn positions(s: &[McVertex]) -> Vec<f32> {
    s.iter().flat_map(|v| [v.x_m, v.y_m, v.z_m]).collect()
}
fn normals(s: &[McVertex]) -> Vec<f32> {
    s.iter().flat_map(|v| [v.normal_x, v.normal_y, v.normal_z]).collect()
}

/// Compares triangle soups vertex by vertex: edge ids exact, positions and normals within
/// tolerance, colour channels within [`COLOR_TOL_LEVELS`].
pub(crate) fn compare_soups(gpu: &[McVertex], cpu: &[McVertex]) -> Result<SoupDiff, String> {
    let ids = |s: &[McVertex]| s.iter().map(|v| v.edge_id).collect::<Vec<_>>();
    compare_u32("edge_id", &ids(gpu), &ids(cpu))?;
    let p = compare_f32("position_m", &positions(gpu), &positions(cpu), POSITION_TOL)?;
    let n = compare_f32("normal", &normals(gpu), &normals(cpu), NORMAL_TOL)?;
    let mut max_color = 0u8;
    for (i, (g, c)) in gpu.iter().zip(cpu).enumerate() {
        let (g, c) = (g.color_rgb8.to_le_bytes(), c.color_rgb8.to_le_bytes());
        let err = (0..4).map(|k| g[k].abs_diff(c[k])).max().unwrap_or(0);
        if err > COLOR_TOL_LEVELS {
            return Err(format!("color_rgb8[{i}]: GPU {g:?} vs CPU {c:?}"));
        }
        max_color = max_color.max(err);
    }
    Ok(SoupDiff { max_position_err_m: p.max_abs_err, max_normal_err: n.max_abs_err, max_color_err_levels: max_color })
}

/// Negative controls of [`compare_soups`]: each perturbation must be rejected.
pub(crate) fn assert_negative_control_soup(gpu: &[McVertex], cpu: &[McVertex]) {
    compare_soups(gpu, cpu).unwrap_or_else(|e| panic!("negative control needs a passing pair first: {e}"));
    assert_negative_control("position_m", &positions(gpu), &positions(cpu), POSITION_TOL);
    assert_negative_control("normal", &normals(gpu), &normals(cpu), NORMAL_TOL);
    let ix = gpu.len() / 2;
    let mut id = gpu.to_vec();
    id[ix].edge_id += 3;
    assert!(compare_soups(&id, cpu).is_err(), "a vertex on another edge was accepted");
    let mut color = gpu.to_vec();
    color[ix].color_rgb8 ^= 0x0000_0400;
    assert!(compare_soups(&color, cpu).is_err(), "a colour 4 levels off was accepted");
    assert!(compare_soups(&gpu[3..], cpu).is_err(), "a missing triangle was accepted");
    let mut swapped = gpu.to_vec();
    swapped.swap(0, 1);
    assert!(compare_soups(&swapped, cpu).is_err(), "reversed winding was accepted");
}

/// Vertices sharing an edge id must be bit-identical in a soup: every cell computes an edge's
/// vertex from the same two voxels in the same order, so welding loses nothing.
pub(crate) fn assert_welds_exactly(what: &str, soup: &[McVertex]) {
    let mut first = std::collections::HashMap::new();
    for v in soup {
        let f = first.entry(v.edge_id).or_insert(*v);
        assert!(bytemuck::bytes_of(f) == bytemuck::bytes_of(v), "{what}: edge {} has two different vertices: {f:?} vs {v:?}", v.edge_id);
    }
}

/// Uploads a test volume into a dense store.
pub(crate) fn upload(gpu: &Gpu, vol: &TestVolume) -> DenseTsdfVolume {
    let config = TsdfConfig {
        dims_voxels: [vol.desc.dim_x, vol.desc.dim_y, vol.desc.dim_z],
        voxel_size_m: vol.desc.voxel_size_m,
        truncation_m: vol.desc.truncation_m,
        max_weight: vol.desc.max_weight,
        color: vol.colors.is_some(),
        ..TsdfConfig::cube(2, vol.desc.voxel_size_m)
    };
    let store = DenseTsdfVolume::new(gpu, config, [vol.desc.origin_x_m, vol.desc.origin_y_m, vol.desc.origin_z_m]).expect("allocate volume");
    assert_eq!(store.desc(), vol.desc, "the store describes the test volume");
    gpu.write_buffer(store.voxels(), &vol.words);
    if let Some(c) = &vol.colors {
        gpu.write_buffer(store.colors(), c);
    }
    store
}

fn check_sphere(what: &str, mesh: &Mesh, c: [f32; 3], r: f32, voxel_m: f32) {
    let topo = mesh.topology();
    assert!(topo.is_watertight(), "{what}: {topo:?}");
    assert_eq!(mesh.vertex_count() as i64 - topo.n_edges as i64 + mesh.triangle_count() as i64, 2, "{what}: Euler characteristic of a sphere");
    let exact = 4.0 * std::f64::consts::PI * f64::from(r).powi(2);
    let area = mesh.surface_area_m2();
    eprintln!("{what}: {} triangles, {} vertices, area {area:.6} m^2 = {:.4} x 4 pi r^2", mesh.triangle_count(), mesh.vertex_count(), area / exact);
    assert!((area / exact - 1.0).abs() < 0.01, "{what}: area {area} vs {exact}");
    for p in &mesh.positions_m {
        let d = ((p[0] - c[0]).powi(2) + (p[1] - c[1]).powi(2) + (p[2] - c[2]).powi(2)).sqrt();
        assert!((d - r).abs() < 0.05 * voxel_m, "{what}: vertex {p:?} is {d} m from the centre, radius {r}");
    }
}

#[test]
fn sphere_extracts_watertight_and_matches_cpu() {
    let gpu = gpu();
    for color in [true, false] {
        let (vol, c, r) = sphere(64, 0.01, 22.3, color);
        let store = upload(&gpu, &vol);
        let g = pollster::block_on(mesh::extract_triangles(&gpu, &store, &MeshOptions::default())).expect("GPU extraction");
        let cpu = mesh::extract_triangles_cpu(&vol.words, vol.colors.as_deref(), &vol.desc).expect("CPU extraction");
        assert_eq!(g.len(), cpu.len(), "same triangle count");
        let diff = compare_soups(&g, &cpu).unwrap();
        eprintln!("sphere 64^3 (colour {color}): {} triangles, {diff:?}", g.len() / 3);
        assert_negative_control_soup(&g, &cpu);
        assert_welds_exactly("GPU soup", &g);
        let m = Mesh::from_triangle_soup(&g);
        check_sphere("GPU sphere", &m, c, r, 0.01);
        assert_eq!(m.triangles, Mesh::from_triangle_soup(&cpu).triangles, "identical welded connectivity");
        if !color {
            assert!(m.colors_rgb8.iter().all(|c| *c == [255; 3]), "no colour: white");
        }
        let m2 = pollster::block_on(mesh::extract_mesh(&gpu, &store)).unwrap();
        assert_eq!(m2, m, "extraction is deterministic");
    }
    finish(&gpu);
}

#[test]
fn random_field_matches_cpu() {
    let gpu = gpu();
    let vol = random_field([23, 17, 30], 7, true);
    let store = upload(&gpu, &vol);
    let g = pollster::block_on(mesh::extract_triangles(&gpu, &store, &MeshOptions::default())).unwrap();
    let cpu = mesh::extract_triangles_cpu(&vol.words, vol.colors.as_deref(), &vol.desc).unwrap();
    let diff = compare_soups(&g, &cpu).unwrap();
    eprintln!("random 23x17x30: {} triangles, {diff:?}", g.len() / 3);
    assert!(g.len() / 3 > 5000, "a busy field");
    assert_negative_control_soup(&g, &cpu);
    assert_welds_exactly("GPU soup", &g);
    let topo = Mesh::from_triangle_soup(&g).topology();
    assert_eq!((topo.n_non_manifold_edges, topo.n_misoriented_edges), (0, 0), "manifold and consistently wound where open: {topo:?}");
    finish(&gpu);
}

#[test]
fn overflow_is_a_typed_error_and_growth_recovers() {
    let gpu = gpu();
    let (vol, ..) = sphere(40, 0.01, 12.7, true);
    let store = upload(&gpu, &vol);
    let cpu = mesh::extract_triangles_cpu(&vol.words, vol.colors.as_deref(), &vol.desc).unwrap();
    let needed = (cpu.len() / 3) as u64;
    let strict = MeshOptions { capacity_triangles: Some(100), grow: false, max_capacity_triangles: None };
    match pollster::block_on(mesh::extract_triangles(&gpu, &store, &strict)) {
        Err(Error::OutputOverflow { stage, needed: n, capacity }) => {
            assert_eq!((stage, n, capacity), ("mc_generate", needed, 100), "overflow reports the real need");
        }
        other => panic!("expected OutputOverflow, got {:?}", other.map(|s| s.len())),
    }
    let exact = MeshOptions { capacity_triangles: Some(needed as u32), grow: false, max_capacity_triangles: None };
    let fits = pollster::block_on(mesh::extract_triangles(&gpu, &store, &exact)).expect("exactly enough room is no overflow");
    compare_soups(&fits, &cpu).unwrap();
    let grown = pollster::block_on(mesh::extract_triangles(&gpu, &store, &MeshOptions { capacity_triangles: Some(1), grow: true, max_capacity_triangles: None })).unwrap();
    compare_soups(&grown, &cpu).unwrap();
    // Buffers of at most 997 triangles: generated in ceil(needed / 997) ranges, after counting
    // or after a first pass of 10.
    assert!(needed > 3 * 997, "several ranges ({needed} triangles)");
    for capacity_triangles in [None, Some(10)] {
        let ranged = pollster::block_on(mesh::extract_triangles(&gpu, &store, &MeshOptions { capacity_triangles, grow: true, max_capacity_triangles: Some(997) })).unwrap();
        compare_soups(&ranged, &cpu).unwrap();
    }
    finish(&gpu);
}

#[test]
fn empty_and_unobserved_volumes_give_no_triangles() {
    let gpu = gpu();
    let (mut vol, ..) = sphere(16, 0.02, 5.0, false);
    let store = upload(&gpu, &vol);
    store.reset(&gpu);
    assert!(pollster::block_on(mesh::extract_mesh(&gpu, &store)).unwrap().triangles.is_empty(), "never observed: nothing");
    vol.words = mesh::tsdf_from_sdf(&vol.desc, 3, |_| 0.5);
    let store = upload(&gpu, &vol);
    assert!(pollster::block_on(mesh::extract_mesh(&gpu, &store)).unwrap().triangles.is_empty(), "all free space: nothing");
    finish(&gpu);
}

/// GPU time of each pass, one submit each, milliseconds.
fn timed_passes(gpu: &Gpu, store: &dyn TsdfStore, capacity: u32) -> ([f64; 3], McCounters) {
    let desc = store.desc();
    let grid = McGrid::new(&desc).unwrap();
    let table_words = mc_table().packed();
    let table = gpu.storage_buffer::<u32>("test.mc.table", table_words.len());
    gpu.write_buffer(&table, &table_words);
    let block_counts = gpu.storage_buffer::<u32>("test.mc.block_counts", grid.n_blocks as usize);
    let block_offsets = gpu.storage_buffer::<u32>("test.mc.block_offsets", grid.n_blocks as usize);
    let max = gpu.limits.max_compute_workgroups_per_dimension;
    let active_blocks = gpu.storage_buffer::<u32>("test.mc.active_blocks", grid.active_blocks_len(max));
    let counters = counters_buffer(gpu);
    let vertices = gpu.storage_buffer::<McVertex>("test.mc.vertices", 3 * capacity as usize);
    let cp_buf = gpu.uniform_buffer("test.mc_count.params", &McCountParams::new(desc, grid));
    let sp = McScanParams { n_blocks: grid.n_blocks, capacity_triangles: capacity, max_workgroups_per_dimension: max, _pad0: 0 };
    let sp_buf = gpu.uniform_buffer("test.mc_scan.params", &sp);
    let gp_buf = gpu.uniform_buffer("test.mc_generate.params", &McGenerateParams::new(desc, grid, 0, capacity, store.has_color()));
    let count_bg = mc_count::Bindings { params: &cp_buf, tsdf_volume: store.voxels(), mc_table: &table, block_counts: &block_counts, block_table: store.block_table(), block_coords: store.block_coords() }.bind_group(gpu);
    let scan_bg = mc_scan::Bindings { params: &sp_buf, block_counts: &block_counts, block_offsets: &block_offsets, active_blocks: &active_blocks, counters: &counters }.bind_group(gpu);
    let gen_bg = mc_generate::Bindings {
        params: &gp_buf,
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
    pollster::block_on(gpu.wait(None)).unwrap();
    let mut ms = [0.0; 3];
    for (stage, slot) in ms.iter_mut().enumerate() {
        let mut encoder = gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("test.mc.timed") });
        match stage {
            0 => webfusion_core::kernels::mc_count::encode(gpu, &mut encoder, &count_bg, &grid),
            1 => webfusion_core::kernels::mc_scan::encode(gpu, &mut encoder, &scan_bg),
            _ => webfusion_core::kernels::mc_generate::encode_indirect(gpu, &mut encoder, &gen_bg, &counters),
        }
        let t0 = Instant::now();
        pollster::block_on(gpu.submit_and_wait(encoder)).unwrap();
        *slot = t0.elapsed().as_secs_f64() * 1e3;
    }
    let c = pollster::block_on(gpu.read_buffer::<McCounters>(&counters, 1)).unwrap()[0];
    (ms, c)
}

#[test]
fn volume_256_extracts_on_gpu_and_matches_cpu() {
    let gpu = gpu();
    // 256^3 voxels of 1 cm: 16.6 M cells in 32 x 32 x 64 = 65 536 blocks (1024 mc_count
    // workgroups of 64 invocations). Radius 100 voxels.
    let (vol, c, r) = sphere(256, 0.01, 100.0, true);
    let store = upload(&gpu, &vol);
    let grid = McGrid::new(&vol.desc).unwrap();
    assert_eq!((grid.n_cells(), grid.n_blocks), (255 * 255 * 255, 65_536), "cells and blocks of 256^3");
    assert_eq!(grid.count_workgroups(gpu.limits.max_compute_workgroups_per_dimension), [1024, 1, 1], "mc_count dispatch");
    let (ms, counters) = timed_passes(&gpu, &store, 1 << 19);
    let t0 = Instant::now();
    let soup = pollster::block_on(mesh::extract_triangles(&gpu, &store, &MeshOptions::default())).unwrap();
    let extract_ms = t0.elapsed().as_secs_f64() * 1e3;
    let t0 = Instant::now();
    let one_submit = pollster::block_on(mesh::extract_triangles(&gpu, &store, &MeshOptions { capacity_triangles: Some(1 << 19), ..Default::default() })).unwrap();
    let one_submit_ms = t0.elapsed().as_secs_f64() * 1e3;
    assert_eq!(one_submit, soup, "both sizing strategies give the same soup");
    let t1 = Instant::now();
    let m = Mesh::from_triangle_soup(&soup);
    let weld_ms = t1.elapsed().as_secs_f64() * 1e3;
    let t2 = Instant::now();
    let cpu = mesh::extract_triangles_cpu(&vol.words, vol.colors.as_deref(), &vol.desc).unwrap();
    let cpu_ms = t2.elapsed().as_secs_f64() * 1e3;
    eprintln!(
        "256^3 on {}: mc_count {:.1} ms, mc_scan {:.1} ms, mc_generate {:.1} ms; extract_triangles (count, read total, generate, read back) {extract_ms:.1} ms, with a 2^19 buffer in one submit {one_submit_ms:.1} ms; weld {weld_ms:.1} ms; CPU reference {cpu_ms:.1} ms",
        gpu.adapter_summary(),
        ms[0],
        ms[1],
        ms[2]
    );
    assert_eq!(counters.n_triangles as usize, soup.len() / 3, "timed passes count the same triangles");
    eprintln!("256^3: {} of {} blocks have triangles", counters.n_active_blocks, grid.n_blocks);
    assert_eq!(soup.len(), cpu.len(), "same triangle count as the CPU");
    let diff = compare_soups(&soup, &cpu).unwrap();
    eprintln!("256^3: {} triangles, {diff:?}", soup.len() / 3);
    assert_negative_control_soup(&soup, &cpu);
    check_sphere("256^3 sphere", &m, c, r, 0.01);
    finish(&gpu);
}

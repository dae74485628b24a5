// SPDX-License-Identifier: MIT
//! `mc_generate`: triangles written at block offset + local offset. Edge ids exact; positions
//! within 1e-6 m, normal components within 2e-5, colours within one 8-bit level (the
//! tolerances of `mesh.rs`, which explain them).

use webfusion_core::cpu;
use webfusion_core::kernels::mc_count::{McCountParams, McGrid};
use webfusion_core::kernels::mc_generate::{McGenerateParams, McVertex};
use webfusion_core::kernels::mc_scan::{McCounters, McScanParams};
use webfusion_core::mesh::mc_table::mc_table;
use webfusion_tests::{SENTINEL_F32, Slot, cast, finish, gpu, run_kernel_slots};

use crate::mesh::extraction::{TestVolume, assert_negative_control_soup, assert_welds_exactly, compare_soups, random_field, sphere};

/// The first two passes' outputs, from their CPU references.
struct Blocks {
    grid: McGrid,
    active_blocks: Vec<u32>,
    block_offsets: Vec<u32>,
    counters: McCounters,
}

fn blocks(vol: &TestVolume, max_workgroups_per_dimension: u32) -> Blocks {
    let grid = McGrid::new(&vol.desc).unwrap();
    let table = mc_table().packed();
    let mut counts = vec![0; grid.n_blocks as usize];
    cpu::mc_count(&McCountParams::new(vol.desc, grid), &vol.words, &table, &mut counts, &[0], &[0]);
    let mut block_offsets = vec![0; grid.n_blocks as usize];
    let mut active_blocks = vec![0; grid.active_blocks_len(max_workgroups_per_dimension)];
    let mut counters = McCounters::default();
    let p = McScanParams { n_blocks: grid.n_blocks, capacity_triangles: u32::MAX, max_workgroups_per_dimension, _pad0: 0 };
    cpu::mc_scan(&p, &counts, &mut block_offsets, &mut active_blocks, &mut counters);
    Blocks { grid, active_blocks, block_offsets, counters }
}

/// Runs the kernel for triangles `first..first + capacity` with the dispatch `mc_scan` sizes
/// for a limit of `max_per_dimension`; returns (GPU, CPU) vertices, both starting from
/// sentinel-filled buffers.
fn run(vol: &TestVolume, first: u32, capacity: u32, max_per_dimension: u32) -> (Vec<McVertex>, Vec<McVertex>) {
    let gpu = gpu();
    let b = blocks(vol, max_per_dimension);
    let p = McGenerateParams::new(vol.desc, b.grid, first, capacity, vol.colors.is_some());
    let table = mc_table().packed();
    let [x, y, z] = b.counters.generate_workgroups();
    let n_vertices = 3 * capacity as usize;
    let no_blocks = [0u32];
    let slots = [
        Slot::In(bytemuck::cast_slice(&vol.words)),
        Slot::In(bytemuck::cast_slice(vol.colors_or_placeholder())),
        Slot::In(bytemuck::cast_slice(&table)),
        Slot::In(bytemuck::cast_slice(&b.active_blocks)),
        Slot::In(bytemuck::cast_slice(&b.block_offsets)),
        Slot::Out(n_vertices * std::mem::size_of::<McVertex>()),
        Slot::In(bytemuck::cast_slice(&no_blocks)),
        Slot::In(bytemuck::cast_slice(&no_blocks)),
    ];
    let wg = gpu.kernels.mc_generate.kernel.workgroup_size;
    let out = run_kernel_slots(&gpu, &gpu.kernels.mc_generate, &p, &slots, [x * wg[0], y, z]);
    let s = SENTINEL_F32.to_bits();
    let sentinel: McVertex = bytemuck::cast([s; 8]);
    let mut c = vec![sentinel; n_vertices];
    cpu::mc_generate(&p, &vol.words, vol.colors_or_placeholder(), &table, &b.active_blocks, &b.block_offsets, &mut c, &no_blocks, &no_blocks, x * y * z);
    finish(&gpu);
    (cast(&out[0]), c)
}

fn total(vol: &TestVolume) -> u32 {
    blocks(vol, 65_535).counters.n_triangles
}

#[test]
fn sphere_with_colour_matches_cpu() {
    let (vol, ..) = sphere(40, 0.01, 13.4, true);
    let total = total(&vol);
    let (g, c) = run(&vol, 0, total, 65_535);
    let diff = compare_soups(&g, &c).unwrap();
    eprintln!("sphere 40^3: {total} triangles, {diff:?}");
    assert_negative_control_soup(&g, &c);
    assert_welds_exactly("GPU", &g);
}

#[test]
fn random_field_without_colour_matches_cpu() {
    let vol = random_field([19, 26, 15], 5, false);
    let total = total(&vol);
    let (g, c) = run(&vol, 0, total, 65_535);
    let diff = compare_soups(&g, &c).unwrap();
    eprintln!("random 19x26x15: {total} triangles, {diff:?}");
    assert!(g.iter().all(|v| v.color_rgb8 == 0x00ff_ffff), "white without colour");
    assert_negative_control_soup(&g, &c);
    assert_welds_exactly("GPU", &g);
}

#[test]
fn a_range_of_triangles_lands_at_the_start_of_the_buffer() {
    let vol = random_field([17, 18, 19], 9, true);
    let total = total(&vol);
    let (full, _) = run(&vol, 0, total, 65_535);
    let (first, capacity) = (total / 3, total / 2);
    let (g, c) = run(&vol, first, capacity, 65_535);
    compare_soups(&g, &c).unwrap();
    let range = 3 * first as usize..3 * (first + capacity) as usize;
    compare_soups(&g, &full[range.clone()]).unwrap();
    assert_negative_control_soup(&g, &full[range]);
    // Past the end: the tail stays unwritten (sentinel) on both.
    let (g, c) = run(&vol, total - 10, 40, 65_535);
    let s = SENTINEL_F32.to_bits();
    assert!(g[30..].iter().all(|v| v.edge_id == s) && c[30..].iter().all(|v| v.edge_id == s), "nothing past the total is written");
    compare_soups(&g[..30], &c[..30]).unwrap();
}

#[test]
fn two_dimensional_dispatch_with_padding_writes_the_same_triangles() {
    let vol = random_field([30, 21, 25], 13, true);
    let b = blocks(&vol, 7);
    let [x, y, _] = b.counters.generate_workgroups();
    assert!(y > 1 && x * y > b.counters.n_active_blocks, "a padded 2D dispatch: {x} x {y} for {} blocks", b.counters.n_active_blocks);
    let total = b.counters.n_triangles;
    let (g, c) = run(&vol, 0, total, 7);
    let (g1, _) = run(&vol, 0, total, 65_535);
    compare_soups(&g, &c).unwrap();
    compare_soups(&g, &g1).unwrap();
    assert_negative_control_soup(&g, &c);
}

// SPDX-License-Identifier: MIT
//! `mc_count`: triangles per block of cells, integer sums: exact.

use webfusion_core::cpu;
use webfusion_core::kernels::mc_count::{MC_CELLS_PER_BLOCK, MC_COUNT_WG_SIZE, McCountParams, McGrid};
use webfusion_core::mesh::mc_table::mc_table;
use webfusion_tests::{Slot, cast, finish, gpu, run_kernel_slots};

use crate::mesh::extraction::{TestVolume, assert_negative_control_u32, compare_u32, random_field, sphere};

/// Runs the kernel with at most `max_per_dimension` workgroups along x (forcing a 2D dispatch
/// when small); returns (GPU, CPU) block counts. Outputs start as sentinels, so every block
/// must be written.
fn run(vol: &TestVolume, max_per_dimension: u32) -> (Vec<u32>, Vec<u32>) {
    let gpu = gpu();
    let grid = McGrid::new(&vol.desc).unwrap();
    let p = McCountParams::new(vol.desc, grid);
    let table = mc_table().packed();
    let [x, y, z] = grid.count_workgroups(max_per_dimension);
    assert!(x * y * z * MC_COUNT_WG_SIZE >= grid.n_blocks && x <= max_per_dimension, "dispatch {x}x{y}x{z} covers {} blocks", grid.n_blocks);
    let no_blocks = [0u32];
    let slots = [Slot::In(bytemuck::cast_slice(&vol.words)), Slot::In(bytemuck::cast_slice(&table)), Slot::Out(4 * grid.n_blocks as usize), Slot::In(bytemuck::cast_slice(&no_blocks)), Slot::In(bytemuck::cast_slice(&no_blocks))];
    let out = run_kernel_slots(&gpu, &gpu.kernels.mc_count, &p, &slots, [x * MC_COUNT_WG_SIZE, y, z]);
    let mut c = vec![0; grid.n_blocks as usize];
    cpu::mc_count(&p, &vol.words, &table, &mut c, &no_blocks, &no_blocks);
    finish(&gpu);
    (cast(&out[0]), c)
}

#[test]
fn sphere_block_counts_match_cpu() {
    let (vol, ..) = sphere(48, 0.01, 17.2, false);
    let (g, c) = run(&vol, 65535);
    compare_u32("block_counts", &g, &c).unwrap();
    let total: u32 = c.iter().sum();
    assert!(total > 1000 && c.iter().filter(|&&n| n == 0).count() > c.len() / 3, "{total} triangles, most blocks empty");
    assert_negative_control_u32("block_counts", &g, &c);
}

#[test]
fn random_field_block_counts_match_cpu() {
    let vol = random_field([21, 19, 34], 3, false);
    let (g, c) = run(&vol, 65535);
    compare_u32("block_counts", &g, &c).unwrap();
    assert_negative_control_u32("block_counts", &g, &c);
}

#[test]
fn two_dimensional_dispatch_numbers_blocks_the_same() {
    let vol = random_field([40, 75, 29], 11, false);
    let grid = McGrid::new(&vol.desc).unwrap();
    // 39 x 74 x 28 cells = 5 x 10 x 7 = 350 blocks = 6 workgroups of 64: 2 x 3 with at most 2
    // per dimension, 34 idle invocations.
    assert_eq!((grid.n_blocks, grid.count_workgroups(2)), (350, [2, 3, 1]), "a 2D grid with idle invocations");
    let (g1, c) = run(&vol, 65535);
    let (g2, _) = run(&vol, 2);
    compare_u32("block_counts (1D)", &g1, &c).unwrap();
    compare_u32("block_counts (2D)", &g2, &c).unwrap();
    assert_negative_control_u32("block_counts (2D)", &g2, &c);
}

#[test]
fn block_size_matches_the_reflected_workgroups() {
    use webfusion_shaders as s;
    assert_eq!(s::MC_COUNT.workgroup_size, [MC_COUNT_WG_SIZE, 1, 1], "mc_count: one block per invocation");
    assert_eq!(s::MC_GENERATE.workgroup_size, [MC_CELLS_PER_BLOCK, 1, 1], "mc_generate: one cell per invocation");
    assert_eq!(s::MC_SCAN.workgroup_size, [cpu::mesh::marching_cubes::SCAN_WG_SIZE as u32, 1, 1], "mc_scan: one SCAN_WG_SIZE workgroup");
    assert_eq!(cpu::mesh::marching_cubes::SCAN_WG_SIZE as u32, MC_CELLS_PER_BLOCK, "the block scan covers one block");
}

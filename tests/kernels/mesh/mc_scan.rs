// SPDX-License-Identifier: MIT
//! `mc_scan`: exclusive block offsets, the list of blocks with triangles, grand total,
//! overflow flag and `mc_generate`'s dispatch size; integer sums: exact.

use webfusion_core::cpu;
use webfusion_core::kernels::mc_scan::{MC_FAILED_OUTPUT, MC_NO_BLOCK, McCounters, McScanParams};
use webfusion_tests::{cast, finish, gpu, run_kernel};

use crate::mesh::extraction::{Rng, assert_negative_control_u32, compare_u32};

/// GPU and CPU outputs: offsets, active blocks (with padding) and counters.
type ScanOut = (Vec<u32>, Vec<u32>, McCounters);

/// Runs the kernel on `counts`; returns (GPU, CPU) outputs. The active list has room for the
/// largest padding (`n + n / max + 1`); entries past the padding stay sentinel on the GPU, 0
/// on the CPU, and are cut off before comparing.
fn run(counts: &[u32], capacity_triangles: u32, max_workgroups_per_dimension: u32) -> (ScanOut, ScanOut) {
    let gpu = gpu();
    let n = counts.len();
    let p = McScanParams { n_blocks: n as u32, capacity_triangles, max_workgroups_per_dimension, _pad0: 0 };
    let inputs: [&[u8]; 1] = [bytemuck::cast_slice(counts)];
    let active_len = n + n / max_workgroups_per_dimension as usize + 1;
    let out = run_kernel(&gpu, &gpu.kernels.mc_scan, &p, &inputs, &[4 * n, 4 * active_len, std::mem::size_of::<McCounters>()], gpu.kernels.mc_scan.kernel.workgroup_size);
    let mut offsets = vec![0; n];
    let mut active = vec![0; active_len];
    let mut counters = McCounters::default();
    cpu::mc_scan(&p, counts, &mut offsets, &mut active, &mut counters);
    finish(&gpu);
    let g_counters = cast::<McCounters>(&out[2])[0];
    let padded = |c: &McCounters| (c.generate_workgroups_x * c.generate_workgroups_y) as usize;
    let mut g_active: Vec<u32> = cast(&out[1]);
    g_active.truncate(padded(&g_counters));
    active.truncate(padded(&counters));
    ((cast(&out[0]), g_active, g_counters), (offsets, active, counters))
}

/// Block counts as marching cubes produces them: mostly zero, up to 5 per cell.
fn counts(n: usize, seed: u64) -> Vec<u32> {
    let mut rng = Rng::new(seed);
    (0..n).map(|_| if rng.unit() < 0.6 { 0 } else { rng.next_u32() % 1281 }).collect()
}

#[test]
fn offsets_active_blocks_and_totals_match_cpu_and_the_running_sum() {
    // Around the segment boundaries (256 invocations) and the 256^3 block count; dispatch
    // limits that force 2D dispatches of mc_generate with padding.
    for (n, seed, max) in [(1, 1, 65_535), (3, 2, 65_535), (255, 3, 7), (256, 4, 65_535), (257, 5, 10), (1000, 6, 65_535), (65_536, 7, 65_535), (65_536, 8, 1000)] {
        let c = counts(n, seed);
        let total: u32 = c.iter().sum();
        for capacity in [total, total.saturating_sub(1)] {
            let ((g_off, g_act, g_ctr), (c_off, c_act, c_ctr)) = run(&c, capacity, max);
            compare_u32("block_offsets", &g_off, &c_off).unwrap();
            compare_u32("active_blocks", &g_act, &c_act).unwrap();
            assert_eq!(g_ctr, c_ctr, "counters, {n} blocks");
            // Independent oracles: the running sum, the non-empty blocks in order, the padding.
            let mut running = 0;
            for (i, &v) in c.iter().enumerate() {
                assert_eq!(c_off[i], running, "CPU offset {i} of {n}");
                running += v;
            }
            let listed: Vec<u32> = (0..n as u32).filter(|&i| c[i as usize] != 0).collect();
            let [x, y, z] = c_ctr.generate_workgroups();
            assert!(x <= max && z == 1 && (x * y) as usize >= listed.len() && (x * y) as usize - listed.len() < y as usize, "dispatch {x}x{y}x{z} for {}", listed.len());
            assert_eq!(&c_act[..listed.len()], &listed[..], "active blocks of {n}");
            assert!(c_act[listed.len()..].iter().all(|&b| b == MC_NO_BLOCK), "padding");
            let overflow = total > capacity;
            let want = McCounters {
                n_triangles: total,
                capacity_triangles: capacity,
                failed: if overflow { MC_FAILED_OUTPUT } else { 0 },
                n_active_blocks: listed.len() as u32,
                generate_workgroups_x: x,
                generate_workgroups_y: y,
                generate_workgroups_z: 1,
                _pad0: 0,
            };
            assert_eq!(c_ctr, want, "{n} blocks");
            if n > 1 {
                assert_negative_control_u32("block_offsets", &g_off, &c_off);
                assert_negative_control_u32("active_blocks", &g_act, &c_act);
            }
        }
    }
}

#[test]
fn no_triangles_dispatch_nothing() {
    let ((g_off, g_act, g_ctr), (_, _, c_ctr)) = run(&[0; 300], 10, 65_535);
    assert_eq!(g_ctr, c_ctr, "counters");
    assert_eq!((g_ctr.n_triangles, g_ctr.n_active_blocks, g_ctr.generate_workgroups()), (0, 0, [0, 1, 1]), "an empty dispatch");
    assert!(g_off.iter().all(|&o| o == 0) && g_act.is_empty(), "offsets all 0, no active block");
}

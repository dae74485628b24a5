// SPDX-License-Identifier: MIT
//! `quadtree_decimate`: both phases against the CPU twin, exactly (integer work), on a ragged
//! disc with a hole (small quads, phase 0), on a large grid covered but for scattered holes
//! and a ragged edge (quads of up to 256 cells, phase 1), and on a grid whose sides are not
//! multiples of 16; the result covers each covered cell with exactly one quad. Negative
//! controls: a quad undone, a degree changed, a sentinel, the grid shifted by a row.

use webfusion_core::cpu;
use webfusion_core::kernels::quadtree_decimate::QuadtreeDecimateParams;
use webfusion_tests::{Slot, cast, finish, gpu, run_kernel_slots};

fn params(w: usize, h: usize, phase: u32) -> QuadtreeDecimateParams {
    QuadtreeDecimateParams { width: w as u32, height: h as u32, phase, ..Default::default() }
}

/// Runs one phase on the GPU from `degrees` (phase 1's input; ignored by phase 0).
fn gpu_phase(covered: &[u32], degrees: &[i32], w: usize, h: usize, phase: u32) -> Vec<i32> {
    let gpu = gpu();
    let scale = if phase == 1 { 16 } else { 1 };
    let out = run_kernel_slots(&gpu, &gpu.kernels.quadtree_decimate, &params(w, h, phase), &[Slot::In(bytemuck::cast_slice(covered)), Slot::InOut(bytemuck::cast_slice(degrees))], [w.div_ceil(scale).next_multiple_of(16) as u32, h.div_ceil(scale).next_multiple_of(16) as u32, 1]);
    finish(&gpu);
    cast(&out[0])
}

fn compare(what: &str, g: &[i32], c: &[i32]) -> Result<(), String> {
    if g.len() != c.len() {
        return Err(format!("{what}: {} GPU degrees vs {} CPU", g.len(), c.len()));
    }
    match g.iter().zip(c).position(|(a, b)| a != b) {
        Some(i) => Err(format!("{what}: cell {i}: GPU {} vs CPU {}", g[i], c[i])),
        None => Ok(()),
    }
}

fn controls(what: &str, g: &[i32], c: &[i32], w: usize) {
    let big = (0..c.len()).max_by_key(|&i| c[i]).expect("cells");
    assert!(c[big] > 1, "{what}: a control needs a merged quad");
    let mut undone = g.to_vec();
    undone[big] = 1;
    let mut changed = g.to_vec();
    changed[big] *= 2;
    let mut sentinel = g.to_vec();
    sentinel[big] = webfusion_tests::SENTINEL_F32.to_bits() as i32;
    let mut shifted = g[w..].to_vec();
    shifted.extend_from_slice(&g[..w]);
    for (case, bad) in [("a quad undone", undone), ("a degree changed", changed), ("a sentinel", sentinel), ("a shifted grid", shifted)] {
        assert!(compare(what, &bad, c).is_err(), "{what}: the comparison accepted {case}");
    }
}

/// Both phases, GPU against twin; returns the final degrees.
fn check(what: &str, covered: &[bool], w: usize, h: usize) -> Vec<i32> {
    let flags: Vec<u32> = covered.iter().map(|&c| u32::from(c)).collect();
    let mut c = vec![-1i32; w * h];
    cpu::quadtree_decimate(&params(w, h, 0), &flags, &mut c);
    let g = gpu_phase(&flags, &vec![-7; w * h], w, h, 0);
    compare(&format!("{what}, phase 0"), &g, &c).unwrap();
    controls(&format!("{what}, phase 0"), &g, &c, w);
    let g1 = gpu_phase(&flags, &c, w, h, 1);
    cpu::quadtree_decimate(&params(w, h, 1), &flags, &mut c);
    compare(&format!("{what}, phase 1"), &g1, &c).unwrap();
    // Each covered cell in exactly one quad, no other cell in any.
    let times = webfusion_core::planes::mesh::quad_cover_counts(&c, w, h);
    assert!(times.iter().zip(covered).all(|(&t, &cov)| t == u32::from(cov)), "{what}: quads do not tile the covered cells");
    let largest = c.iter().copied().max().unwrap_or(0);
    eprintln!("{what}: {} quads for {} covered cells, the largest {largest} cells wide", c.iter().filter(|&&s| s > 0).count(), covered.iter().filter(|&&x| x).count());
    c
}

#[test]
fn a_ragged_disc_with_a_hole() {
    let (w, h) = (70, 50);
    let covered: Vec<bool> = (0..w * h)
        .map(|i| {
            let (x, y) = ((i % w) as f32 - 33.0, (i / w) as f32 - 24.0);
            let r = (x * x + y * y).sqrt();
            r < 23.0 + 2.0 * (x * 0.7).sin() && r > 4.0
        })
        .collect();
    check("disc", &covered, w, h);
}

#[test]
fn a_large_grid_merges_to_256_cell_quads() {
    let (w, h) = (600, 530);
    let covered: Vec<bool> = (0..w * h)
        .map(|i| {
            let (x, y) = (i % w, i / w);
            // Scattered holes and a ragged right edge.
            let hole = (x * 7919 + y * 104_729) % 9973 == 0;
            !hole && x < 560 + (y * 13 % 29)
        })
        .collect();
    let d = check("large", &covered, w, h);
    assert_eq!(d.iter().copied().max(), Some(256), "quads of 256 cells");
}

#[test]
fn sides_that_are_not_multiples_of_16() {
    let (w, h) = (37, 23);
    let covered = vec![true; w * h];
    let d = check("37 x 23", &covered, w, h);
    assert_eq!(d[0], 16);
}

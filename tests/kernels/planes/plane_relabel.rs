// SPDX-License-Identifier: MIT
//! `plane_relabel`: labels renumbered after planes were dropped or sorted, against the CPU
//! twin, on the real frame's labels with a renumbering that drops one plane and swaps two.
//! Exact; negative controls on a renumbered, a dropped and an unlabelled pixel.

use webfusion_core::cpu;
use webfusion_core::kernels::plane_relabel::PlaneRelabelParams;
use webfusion_core::planes::NO_LABEL;
use webfusion_tests::{Slot, cast, compare_u32_mostly, finish, gpu, run_kernel_slots};

use super::plane_keys::real_fixture;

#[test]
fn labels_follow_the_renumbering() {
    let (_, planes, labels) = real_fixture();
    assert!(planes.len() >= 3);
    // Plane 0 dropped, 1 and 2 swapped, the rest shifted down.
    let mut renumber: Vec<u32> = (0..planes.len() as u32).map(|i| i.wrapping_sub(1)).collect();
    renumber[0] = NO_LABEL;
    renumber.swap(1, 2);
    let p = PlaneRelabelParams { pixel_count: labels.len() as u32, ..Default::default() };
    let gpu = gpu();
    let out = run_kernel_slots(&gpu, &gpu.kernels.plane_relabel, &p, &[Slot::In(bytemuck::cast_slice(&renumber)), Slot::InOut(bytemuck::cast_slice(&labels))], [labels.len() as u32, 1, 1]);
    finish(&gpu);
    let g: Vec<u32> = cast(&out[0]);
    let mut c = labels.clone();
    cpu::plane_relabel(&p, &renumber, &mut c);
    compare_u32_mostly("real frame", &g, &c, 0).unwrap();
    for (ix, (&before, &after)) in labels.iter().zip(&c).enumerate() {
        let expected = if before == NO_LABEL { NO_LABEL } else { renumber[before as usize] };
        assert_eq!(after, expected, "pixel {ix}");
    }
    for (what, l) in [("a renumbered pixel", 1u32), ("a dropped pixel", 0), ("an unlabelled pixel", NO_LABEL)] {
        let ix = labels.iter().position(|&x| x == l).unwrap_or_else(|| panic!("{what} exists"));
        let mut bad = g.clone();
        bad[ix] = if bad[ix] == NO_LABEL { 0 } else { NO_LABEL };
        assert!(compare_u32_mostly("real frame", &bad, &c, 0).is_err(), "the comparison accepted {what} changed");
    }
}

// SPDX-License-Identifier: MIT
//! `plane_extent`: each plane's extent along its in-plane axes by integer atomics on
//! order-preserving keys, against the CPU twin, on the real frame's labels and the twins'
//! fits of its planes. Decoded extents within 1e-6 m (a fused dot product may move a key);
//! every extent brackets 0 (the centroid lies inside) and matches a direct f64 min/max over the
//! labelled points within 1e-5 m. Negative controls move a bound and leave one unwritten.

use webfusion_core::cpu;
use webfusion_core::cpu::planes::plane_extent::{decode_extent, from_ordered_key, ordered_key};
use webfusion_core::cpu::planes::moments::PLANE_MOMENT_VEC4S;
use webfusion_core::cpu::planes::plane_fit::plane_fit_moments;
use webfusion_core::cpu::planes::plane_list::{PLANE_RECORD_VEC4S, PLANE_LIST_VEC4S};
use webfusion_core::kernels::plane_extent::PlaneExtentParams;
use webfusion_core::planes::NO_LABEL;
use webfusion_tests::{Slot, cast, finish, gpu, run_kernel_slots};

use super::plane_keys::real_fixture;
use super::plane_sums_reduce::real_moments;

fn compare(g: &[u32], c: &[u32]) -> Result<(), String> {
    for (k, (gw, cw)) in g.chunks(4).zip(c.chunks(4)).enumerate() {
        let (ge, ce) = (decode_extent(gw), decode_extent(cw));
        for a in 0..2 {
            for b in 0..2 {
                if !((ge[a][b] - ce[a][b]).abs() <= 1e-6) {
                    return Err(format!("plane {k}: extent {ge:?} vs {ce:?}"));
                }
            }
        }
    }
    Ok(())
}

#[test]
fn real_planes_extents_like_the_twin() {
    assert_eq!(from_ordered_key(ordered_key(-2.5)), -2.5);
    assert!(ordered_key(-1.0) < ordered_key(-0.5) && ordered_key(-0.5) < ordered_key(0.0) && ordered_key(0.0) < ordered_key(0.25));
    let (pre, _, labels) = real_fixture();
    let (_, _, sets) = real_moments();
    let mut list = vec![[0.0f32; 4]; PLANE_LIST_VEC4S];
    for (k, m) in sets.iter().enumerate() {
        list[k * PLANE_RECORD_VEC4S..k * PLANE_RECORD_VEC4S + PLANE_MOMENT_VEC4S].copy_from_slice(m);
        list[k * PLANE_RECORD_VEC4S + PLANE_MOMENT_VEC4S..(k + 1) * PLANE_RECORD_VEC4S].copy_from_slice(&plane_fit_moments(m));
    }
    let vertex = &pre.levels[0].vertex_in_camera;
    let p = PlaneExtentParams { pixel_count: labels.len() as u32, ..Default::default() };
    let zeros = vec![0u32; 4 * sets.len()];
    let gpu = gpu();
    let out = run_kernel_slots(&gpu, &gpu.kernels.plane_extent, &p, &[Slot::In(bytemuck::cast_slice(vertex)), Slot::In(bytemuck::cast_slice(&labels)), Slot::In(bytemuck::cast_slice(&list)), Slot::InOut(bytemuck::cast_slice(&zeros))], [labels.len() as u32, 1, 1]);
    finish(&gpu);
    let g: Vec<u32> = cast(&out[0]);
    let mut c = zeros.clone();
    cpu::plane_extent(&p, vertex, &labels, &list, &mut c);
    compare(&g, &c).unwrap();
    for k in 0..sets.len() {
        let e = decode_extent(&c[4 * k..4 * k + 4]);
        let fit = &list[k * PLANE_RECORD_VEC4S + PLANE_MOMENT_VEC4S..(k + 1) * PLANE_RECORD_VEC4S];
        let mut direct = [[f64::INFINITY, f64::NEG_INFINITY]; 2];
        for (ix, &l) in labels.iter().enumerate() {
            if l == k as u32 && l != NO_LABEL {
                let v = vertex[ix];
                for a in 0..2 {
                    let u: f64 = (0..3).map(|i| f64::from(v[i] - fit[1][i]) * f64::from(fit[2 + a][i])).sum();
                    direct[a] = [direct[a][0].min(u), direct[a][1].max(u)];
                }
            }
        }
        eprintln!("plane {k}: extent {e:?}");
        for a in 0..2 {
            assert!(e[a][0] < 0.0 && 0.0 < e[a][1], "plane {k}: brackets its centroid");
            assert!((f64::from(e[a][0]) - direct[a][0]).abs() < 1e-5 && (f64::from(e[a][1]) - direct[a][1]).abs() < 1e-5, "plane {k}: {e:?} vs {direct:?}");
        }
    }
    let mut moved = g.clone();
    moved[1] = ordered_key(from_ordered_key(moved[1]) + 1e-3);
    assert!(compare(&moved, &c).is_err(), "a moved bound accepted");
    let mut unwritten = g.clone();
    unwritten[0] = 0;
    assert!(compare(&unwritten, &c).is_err(), "an unwritten bound accepted");
}

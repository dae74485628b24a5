// SPDX-License-Identifier: MIT
//! `depth_tile_max`: the deepest valid depth of each tile of a real Kinect frame, with a
//! region blanked so that whole tiles have none, at the mapper's tile size and at one that
//! leaves ragged tiles at the right and bottom edges: the GPU writes exactly the twin's values,
//! every tile's value is the largest depth among its own pixels, a tile without depth reads
//! NO_DEPTH_TILE; a moved, NaN, unwritten or filled value is caught (negative controls).

use webfusion_core::cpu::{self, shared::NO_DEPTH_TILE};
use webfusion_core::kernels::depth_tile_max::DepthTileMaxParams;
use webfusion_core::map::DEPTH_TILE_PX;
use webfusion_tests::{Slot, Tolerance, assert_negative_control, cast, compare_f32, finish, gpu, run_kernel_slots};

use super::scene::frame;

#[test]
fn the_gpu_writes_each_tiles_deepest_depth() {
    let gpu = gpu();
    let (k, depth) = frame();
    let (w, h) = (k.width_px, k.height_px);
    // No depth in the top-left 100 x 60 pixels: whole tiles without any.
    let mut depth = depth.to_vec();
    for y in 0..60 {
        for x in 0..100 {
            depth[(y * w + x) as usize] = f32::NAN;
        }
    }
    for tile_px in [DEPTH_TILE_PX, 7] {
        let (tiles_x, tiles_y) = (w.div_ceil(tile_px), h.div_ceil(tile_px));
        let p = DepthTileMaxParams { width_px: w, height_px: h, tile_px, tiles_x, tiles_y, ..Default::default() };
        let n = (tiles_x * tiles_y) as usize;
        let out = run_kernel_slots(&gpu, &gpu.kernels.depth_tile_max, &p, &[Slot::In(bytemuck::cast_slice(&depth)), Slot::Out(4 * n)], [tiles_x * tiles_y, 1, 1]);
        let g: Vec<f32> = cast(&out[0]);
        let mut c = vec![0.0f32; n];
        cpu::depth_tile_max(&p, &depth, &mut c);
        let what = format!("tiles of {tile_px} px");
        compare_f32(&what, &g, &c, Tolerance::EXACT).unwrap_or_else(|e| panic!("GPU vs twin: {e}"));
        assert_negative_control(&what, &g, &c, Tolerance::EXACT);
        // Each tile against its own pixels, counted independently of the twin's loops.
        let mut deepest = vec![NO_DEPTH_TILE; n];
        for (i, &d) in depth.iter().enumerate() {
            let (x, y) = (i as u32 % w, i as u32 / w);
            let t = ((y / tile_px) * tiles_x + x / tile_px) as usize;
            if d.is_finite() && d > 0.0 {
                deepest[t] = deepest[t].max(d);
            }
        }
        assert_eq!(g, deepest, "{what}: each tile's deepest valid depth");
        let empty = g.iter().filter(|&&v| v == NO_DEPTH_TILE).count();
        assert!(empty >= ((100 / tile_px) * (60 / tile_px)) as usize, "{what}: the blanked tiles have no depth ({empty} without)");
        assert!(g.iter().filter(|&&v| v > 0.0).count() > n / 2, "{what}: most tiles have depth");
    }
    finish(&gpu);
}

// SPDX-License-Identifier: MIT
//! CPU reference of `shaders/wgsl/planes/quadtree_decimate.wgsl`.

use crate::kernels::quadtree_decimate::QuadtreeDecimateParams;

const TILE: usize = 16;

/// Runs one phase over the whole grid as the kernel's workgroups do, tile by tile.
pub fn quadtree_decimate(params: &QuadtreeDecimateParams, covered: &[u32], degrees: &mut [i32]) {
    let scale = if params.phase == 1 { TILE } else { 1 };
    let (w, h) = (params.width as usize, params.height as usize);
    // Invocations per axis, then tiles of 16 x 16 of them.
    let (nx, ny) = (w.div_ceil(scale), h.div_ceil(scale));
    for ty in 0..ny.div_ceil(TILE) {
        for tx in 0..nx.div_ceil(TILE) {
            let mut tile = [-1i32; TILE * TILE];
            let mut start = [-1i32; TILE * TILE];
            for ly in 0..TILE {
                for lx in 0..TILE {
                    let (cx, cy) = ((tx * TILE + lx) * scale, (ty * TILE + ly) * scale);
                    if cx < w && cy < h {
                        let cell = cy * w + cx;
                        start[ly * TILE + lx] = if params.phase == 0 { if covered[cell] != 0 { 1 } else { -1 } } else if degrees[cell] == TILE as i32 { 1 } else { -1 };
                    }
                }
            }
            tile.copy_from_slice(&start);
            let mut step = 1;
            while step < TILE {
                let mut merge = [false; TILE * TILE];
                for ly in (0..TILE).step_by(2 * step) {
                    for lx in (0..TILE).step_by(2 * step) {
                        let l = ly * TILE + lx;
                        let s = step as i32;
                        merge[l] = tile[l] == s && tile[l + step] == s && tile[l + step * TILE] == s && tile[l + step * TILE + step] == s;
                    }
                }
                for l in 0..TILE * TILE {
                    if merge[l] {
                        tile[l] = 2 * step as i32;
                        tile[l + step] = -1;
                        tile[l + step * TILE] = -1;
                        tile[l + step * TILE + step] = -1;
                    }
                }
                step *= 2;
            }
            for ly in 0..TILE {
                for lx in 0..TILE {
                    let (cx, cy) = ((tx * TILE + lx) * scale, (ty * TILE + ly) * scale);
                    if cx >= w || cy >= h {
                        continue;
                    }
                    let (cell, l) = (cy * w + cx, ly * TILE + lx);
                    if params.phase == 0 {
                        degrees[cell] = tile[l];
                    } else if start[l] == 1 {
                        degrees[cell] = if tile[l] > 0 { tile[l] * TILE as i32 } else { -1 };
                    }
                }
            }
        }
    }
}

// SPDX-License-Identifier: MIT
//! Seed 003's planar meshes (§4.4 of its digest), CPU reference: each plane gets its own
//! frame and a grid of square texels on it; the texels its pixels cover are rectified into a
//! texture, and a quadtree over the texel grid turns each fully covered 2ᵏ x 2ᵏ block into one
//! quad (two triangles), so a plane of any size costs triangles only along its outline.
//!
//! - **Plane frame**: origin on the plane, axes `u` (the tangent, the points' largest spread),
//!   `v = n × u`, normal `n`; (u, v, n) is right-handed, so a quad counter-clockwise in (u, v)
//!   faces along `n`, towards the cameras that saw it.
//! - **Texel grid**: texel (x, y) spans `min_m + [x, x + 1] x [y, y + 1] / px_per_m` in (u, v),
//!   `px_per_m` a power of two (003: textures of different views then compare by halving or
//!   doubling). A texel is covered when the pixel its centre projects to belongs to the plane.
//! - **Quadtree** ([`quadtree_degrees`], 003's Algorithm 4 with its errata fixed: neighbours at
//!   `step`, and read-then-write per step): a texel's degree is the side of the quad whose
//!   first texel it is, −1 for none; four quads of one side filling an aligned block become
//!   one, up to [`MAX_QUAD_TEXELS`]. Quads are made of whole covered texels, so the mesh
//!   covers exactly the covered texels (003's spanned texel centres, see the function).
//! - **Compaction** ([`quadtree_mesh`]): the quads' corners on the lattice of texel corners
//!   in row-major order, two counter-clockwise triangles per quad.
//!
//! [`frame_plane_mesh`] meshes one plane of one frame (003's per-frame output); the world
//! model ([`super::world`]) meshes its accumulated grids with the same functions.

use super::{NO_LABEL, Plane, PlaneConfig, Segmentation};
use crate::{ColorImage, PinholeIntrinsics};

/// Largest quad side, texels (003: 256, from its two 16 x 16 phases).
pub const MAX_QUAD_TEXELS: u32 = 256;
/// Largest texture side, texels (003: 1024).
pub const MAX_TEXTURE_PX: u32 = 1024;

fn dot(a: [f32; 3], b: [f32; 3]) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn cross(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}

fn normalised(a: [f32; 3]) -> [f32; 3] {
    let l = dot(a, a).sqrt();
    a.map(|v| v / l)
}

/// A plane's own frame (see the module): `p = origin + s_u u + s_v v` for in-plane
/// coordinates (s_u, s_v), metres.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlaneFrame {
    /// A point on the plane, metres.
    pub origin_m: [f32; 3],
    /// First in-plane axis, unit.
    pub u_axis: [f32; 3],
    /// Second in-plane axis, `normal × u_axis`.
    pub v_axis: [f32; 3],
    /// Unit normal.
    pub normal: [f32; 3],
}

impl PlaneFrame {
    /// The frame of plane `normal·p + offset_m = 0` with its origin at `near_m` moved onto the
    /// plane and its `u` axis along `tangent` made orthogonal to the normal.
    pub fn new(normal: [f32; 3], offset_m: f32, near_m: [f32; 3], tangent: [f32; 3]) -> Self {
        let n = normalised(normal);
        let off = dot(n, near_m) + offset_m;
        let origin_m = [near_m[0] - off * n[0], near_m[1] - off * n[1], near_m[2] - off * n[2]];
        let tn = dot(tangent, n);
        let mut u = [tangent[0] - tn * n[0], tangent[1] - tn * n[1], tangent[2] - tn * n[2]];
        if dot(u, u) < 1e-12 {
            // Any axis across the normal.
            let a = if n[0].abs() < 0.9 { [1.0, 0.0, 0.0] } else { [0.0, 1.0, 0.0] };
            u = cross(a, n);
        }
        let u = normalised(u);
        PlaneFrame { origin_m, u_axis: u, v_axis: cross(n, u), normal: n }
    }

    /// The frame of a segmented plane, at its centroid.
    pub fn of_plane(plane: &Plane) -> Self {
        Self::new(plane.normal, plane.offset_m, plane.centroid_m, plane.tangent)
    }

    /// Offset d of `normal·p + d = 0`.
    pub fn offset_m(&self) -> f32 {
        -dot(self.normal, self.origin_m)
    }

    /// In-plane coordinates of `p` (its orthogonal projection), metres.
    pub fn to_plane(&self, p: [f32; 3]) -> [f32; 2] {
        let r = [p[0] - self.origin_m[0], p[1] - self.origin_m[1], p[2] - self.origin_m[2]];
        [dot(r, self.u_axis), dot(r, self.v_axis)]
    }

    /// The point at in-plane coordinates `s`.
    pub fn point(&self, s: [f32; 2]) -> [f32; 3] {
        std::array::from_fn(|i| self.origin_m[i] + s[0] * self.u_axis[i] + s[1] * self.v_axis[i])
    }
}

/// A grid of square texels on a plane (see the module).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TexelGrid {
    /// The plane.
    pub frame: PlaneFrame,
    /// Texels per metre, a power of two.
    pub px_per_m: f32,
    /// In-plane coordinates of texel (0, 0)'s corner, metres.
    pub min_m: [f32; 2],
    /// Texels along `u`.
    pub width: u32,
    /// Texels along `v`.
    pub height: u32,
}

impl TexelGrid {
    /// The texel (x, y) holding in-plane coordinates `s`, if inside the grid.
    pub fn texel_of(&self, s: [f32; 2]) -> Option<[u32; 2]> {
        let x = ((s[0] - self.min_m[0]) * self.px_per_m).floor();
        let y = ((s[1] - self.min_m[1]) * self.px_per_m).floor();
        (x >= 0.0 && y >= 0.0 && x < self.width as f32 && y < self.height as f32).then_some([x as u32, y as u32])
    }
}

/// 003's texture resolution: the smallest power of two, in texels per metre, at least the
/// densest pixel spacing of the projected bounding box `[min, max]` (in-plane, metres) of a
/// plane seen with `k` (each box edge's length on screen over its length on the plane); then
/// halved until the box fits [`MAX_TEXTURE_PX`]. `None` if a corner is behind the camera.
pub fn texture_px_per_m(frame: &PlaneFrame, min_m: [f32; 2], max_m: [f32; 2], k: &PinholeIntrinsics) -> Option<f32> {
    let corners = [[min_m[0], min_m[1]], [max_m[0], min_m[1]], [max_m[0], max_m[1]], [min_m[0], max_m[1]]];
    let mut screen = [[0.0f32; 2]; 4];
    for (c, s) in corners.iter().zip(&mut screen) {
        let p = frame.point(*c);
        if p[2] <= 1e-6 {
            return None;
        }
        *s = [p[0] / p[2] * k.fx_px + k.cx_px, p[1] / p[2] * k.fy_px + k.cy_px];
    }
    let edge = |a: usize, b: usize| ((screen[a][0] - screen[b][0]).powi(2) + (screen[a][1] - screen[b][1]).powi(2)).sqrt();
    let (w_m, h_m) = ((max_m[0] - min_m[0]).max(1e-6), (max_m[1] - min_m[1]).max(1e-6));
    let density = (edge(0, 1).max(edge(3, 2)) / w_m).max(edge(1, 2).max(edge(0, 3)) / h_m).ceil().max(1.0);
    let mut px_per_m = (density as u32).next_power_of_two() as f32;
    while (w_m * px_per_m).ceil() > MAX_TEXTURE_PX as f32 || (h_m * px_per_m).ceil() > MAX_TEXTURE_PX as f32 {
        px_per_m *= 0.5;
    }
    Some(px_per_m)
}

/// Degree of a texel that starts no quad.
pub const NO_QUAD: i32 = -1;

/// 003's parallel quadtree decimation (Algorithm 4) of a `width` x `height` texel grid whose
/// covered texels are `covered`, row-major: per texel the side (texels) of the quad whose
/// first (lowest x, lowest y) texel it is, [`NO_QUAD`] for a texel that starts none (not
/// covered, or inside a larger quad). Quads have power-of-two sides up to
/// [`MAX_QUAD_TEXELS`] and start at multiples of their side; each step reads every block's
/// four quads, then writes (the order 003's code uses; its printed version races). The work is
/// 003's two phases of 16 x 16 tiles, kernel `quadtree_decimate`.
///
/// Unlike 003, a quad is made of texels: a covered texel is a unit quad, and the mesh spans
/// the covered texels exactly. 003's quads spanned texel *centres* (a unit quad needed four
/// covered texels), which drops half a texel along every border and every strip one texel
/// wide; on the synthetic stairs that was a tenth of each riser.
///
/// # Panics
/// If `covered` is not `width * height` long.
pub fn quadtree_degrees(covered: &[bool], width: usize, height: usize) -> Vec<i32> {
    assert_eq!(covered.len(), width * height, "one flag per texel");
    // Kernel `quadtree_decimate`, both phases.
    let flags: Vec<u32> = covered.iter().map(|&c| u32::from(c)).collect();
    let mut degrees = vec![NO_QUAD; covered.len()];
    for phase in 0..2 {
        let params = crate::kernels::quadtree_decimate::QuadtreeDecimateParams { width: width as u32, height: height as u32, phase, ..Default::default() };
        crate::cpu::quadtree_decimate(&params, &flags, &mut degrees);
    }
    degrees
}

/// The mesh of a degree grid ([`quadtree_degrees`], `width` texels wide): each texel of
/// degree s > 0 at (x, y) is a quad with corners 0 = (x, y), 1 = (x + s, y), 2 = (x, y + s),
/// 3 = (x + s, y + s) on the lattice of texel corners ((width + 1) x (height + 1) points), as
/// triangles 0-1-2 and 2-1-3 (counter-clockwise with x along u and y along v). The vertices
/// are the lattice points that are some quad's corner, in row-major order (003's stream
/// compaction, which also needed its hole patching to make every corner a vertex), each given
/// as its lattice (x, y).
pub fn quadtree_mesh(degrees: &[i32], width: usize) -> (Vec<[u32; 2]>, Vec<[u32; 3]>) {
    let height = degrees.len() / width.max(1);
    let lw = width + 1;
    let mut used = vec![false; lw * (height + 1)];
    for (i, &d) in degrees.iter().enumerate() {
        if d > 0 {
            let (x, y, s) = (i % width, i / width, d as usize);
            for (cx, cy) in [(x, y), (x + s, y), (x, y + s), (x + s, y + s)] {
                used[cy * lw + cx] = true;
            }
        }
    }
    let mut index = vec![u32::MAX; used.len()];
    let mut vertices = Vec::new();
    for (i, &u) in used.iter().enumerate() {
        if u {
            index[i] = vertices.len() as u32;
            vertices.push([(i % lw) as u32, (i / lw) as u32]);
        }
    }
    let mut triangles = Vec::new();
    for (i, &d) in degrees.iter().enumerate() {
        if d > 0 {
            let (x, y, s) = (i % width, i / width, d as usize);
            let corner = |cx: usize, cy: usize| index[cy * lw + cx];
            let (c0, c1, c2, c3) = (corner(x, y), corner(x + s, y), corner(x, y + s), corner(x + s, y + s));
            triangles.push([c0, c1, c2]);
            triangles.push([c2, c1, c3]);
        }
    }
    (vertices, triangles)
}

/// Per cell the number of quads of `degrees` covering it (1 inside a quad, 0 outside: more
/// would be a bug).
pub fn quad_cover_counts(degrees: &[i32], width: usize, height: usize) -> Vec<u32> {
    let mut counts = vec![0u32; width * height];
    for (i, &d) in degrees.iter().enumerate() {
        if d > 0 {
            let (x, y) = (i % width, i / width);
            for cy in y..(y + d as usize).min(height) {
                for cx in x..(x + d as usize).min(width) {
                    counts[cy * width + cx] += 1;
                }
            }
        }
    }
    counts
}

/// A plane's textured quadtree mesh.
#[derive(Clone, Debug, PartialEq)]
pub struct PlaneMesh {
    /// The texel grid it was built on.
    pub grid: TexelGrid,
    /// Vertex positions, metres, in the frame the plane was given in.
    pub positions_m: Vec<[f32; 3]>,
    /// Texture coordinates of each vertex (glTF's convention: (0, 0) the texture's first
    /// texel's corner, v down the rows).
    pub uv: Vec<[f32; 2]>,
    /// Counter-clockwise seen from the side the normal points to.
    pub triangles: Vec<[u32; 3]>,
    /// The texture: RGB, power-of-two sides at most [`MAX_TEXTURE_PX`]; a texel a quad covers
    /// that no view saw takes its observed neighbours' mean ([`fill_covered_texels`]); black
    /// where no texel
    /// was observed; row 0 is texel row 0 (v = 0).
    pub texture: ColorImage,
    /// Quads (each two triangles).
    pub quads: u32,
    /// Area the quads cover, m².
    pub area_m2: f32,
    /// Per texel whether a quad covers it ([`quad_cover_counts`]).
    pub cells: Vec<bool>,
}

impl PlaneMesh {
    /// Whether the mesh covers the plane point at in-plane coordinates `s` (of its grid's
    /// frame).
    pub fn covers(&self, s: [f32; 2]) -> bool {
        let g = &self.grid;
        g.texel_of(s).is_some_and(|[x, y]| self.cells[(y * g.width + x) as usize])
    }
}

impl PlaneMesh {
    /// The mesh of `grid` with its covered texels' colours `colours` (row-major, `None` where
    /// not covered): the quadtree over cells of 2^`geometry_shift` x 2^`geometry_shift`
    /// texels, a cell covered when at least half of its texels are, and the texture, padded
    /// to power-of-two sides and halved (2 x 2 means of the covered texels) until it fits
    /// [`MAX_TEXTURE_PX`]; the texture coordinates map the same plane points either way.
    ///
    /// Coarser geometry than texture: a plane's outline is known only to about a pixel's
    /// footprint (the label of a pixel straddling the border decides it), so texels finer than
    /// that only trace each pixel's staircase along the border, a quad or two per texel of
    /// outline; the majority rule keeps the outline where it was on average.
    ///
    /// # Panics
    /// If `colours` is not one per texel.
    pub fn build(grid: TexelGrid, colours: &[Option<[u8; 3]>], geometry_shift: u32) -> PlaneMesh {
        let (w, h) = (grid.width as usize, grid.height as usize);
        assert_eq!(colours.len(), w * h, "one colour per texel");
        let step = 1usize << geometry_shift;
        let (gw, gh) = (w.div_ceil(step), h.div_ceil(step));
        let mut votes = vec![[0u32; 2]; gw * gh];
        for (i, c) in colours.iter().enumerate() {
            let v = &mut votes[(i / w) / step * gw + (i % w) / step];
            v[0] += u32::from(c.is_some());
            v[1] += 1;
        }
        let covered: Vec<bool> = votes.iter().map(|v| v[0] > 0 && 2 * v[0] >= v[1]).collect();
        let degrees = quadtree_degrees(&covered, gw, gh);
        let (vertices, triangles) = quadtree_mesh(&degrees, gw);
        // Lattice points in texels, the last row and column clamped to the grid's edge.
        let texel = |[x, y]: [u32; 2]| [((x as usize) * step).min(w) as f32, ((y as usize) * step).min(h) as f32];
        let (pw, ph) = (grid.width.next_power_of_two(), grid.height.next_power_of_two());
        let positions_m = vertices.iter().map(|&v| {
            let [x, y] = texel(v);
            grid.frame.point([grid.min_m[0] + x / grid.px_per_m, grid.min_m[1] + y / grid.px_per_m])
        }).collect();
        let uv = vertices.iter().map(|&v| {
            let [x, y] = texel(v);
            [x / pw as f32, y / ph as f32]
        }).collect();
        let quads = degrees.iter().filter(|&&d| d > 0).count() as u32;
        let geometry_cells: Vec<bool> = quad_cover_counts(&degrees, gw, gh).iter().map(|&c| c > 0).collect();
        let cells: Vec<bool> = (0..w * h).map(|i| geometry_cells[(i / w) / step * gw + (i % w) / step]).collect();
        let texel_m2 = 1.0 / (grid.px_per_m * grid.px_per_m);
        let area_m2 = cells.iter().filter(|&&c| c).count() as f32 * texel_m2;
        // Texture at the grid's resolution, then halved to fit.
        let filled = fill_covered_texels(colours, &cells, w, step as u32);
        let mut tex: Vec<Option<[f32; 3]>> = vec![None; (pw * ph) as usize];
        for y in 0..h {
            for x in 0..w {
                tex[y * pw as usize + x] = filled[y * w + x];
            }
        }
        let (mut tw, mut th) = (pw as usize, ph as usize);
        while tw > MAX_TEXTURE_PX as usize || th > MAX_TEXTURE_PX as usize {
            let (nw, nh) = ((tw / 2).max(1), (th / 2).max(1));
            let mut half = vec![None; nw * nh];
            for y in 0..nh {
                for x in 0..nw {
                    let mut sum = [0.0f32; 3];
                    let mut n = 0.0;
                    for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                        let (sx, sy) = ((2 * x + dx).min(tw - 1), (2 * y + dy).min(th - 1));
                        if let Some(c) = tex[sy * tw + sx] {
                            (0..3).for_each(|i| sum[i] += c[i]);
                            n += 1.0;
                        }
                    }
                    half[y * nw + x] = (n > 0.0).then(|| sum.map(|s| s / n));
                }
            }
            (tex, tw, th) = (half, nw, nh);
        }
        let rgb8 = tex.iter().flat_map(|c| c.map_or([0, 0, 0], |c| c.map(|v| v.round().clamp(0.0, 255.0) as u8))).collect();
        let texture = ColorImage { width_px: tw as u32, height_px: th as u32, rgb8 };
        PlaneMesh { grid, positions_m, uv, triangles, texture, quads, area_m2, cells }
    }
}

/// The colours of a grid `width` texels wide (`None`: no view saw the texel) with each texel
/// a quad covers (`covered`) but no view saw given the mean of its observed 8-neighbours,
/// spreading one texel per pass for at most `passes` passes (a quad's cell of `passes` texels
/// across is at least half observed, so its gaps close): a pixel left unlabelled inside a
/// plane (a dropout, a noisy normal) would otherwise be a black speck in the texture.
pub fn fill_covered_texels(colours: &[Option<[u8; 3]>], covered: &[bool], width: usize, passes: u32) -> Vec<Option<[f32; 3]>> {
    let mut out: Vec<Option<[f32; 3]>> = colours.iter().map(|c| c.map(|c| c.map(f32::from))).collect();
    let height = colours.len() / width.max(1);
    for _ in 0..passes {
        let prev = out.clone();
        let mut changed = false;
        for i in (0..out.len()).filter(|&i| covered[i] && prev[i].is_none()) {
            let (x, y) = ((i % width) as i64, (i / width) as i64);
            let (mut sum, mut n) = ([0.0f32; 3], 0.0f32);
            for (dx, dy) in [(-1, -1), (0, -1), (1, -1), (-1, 0), (1, 0), (-1, 1), (0, 1), (1, 1)] {
                let (nx, ny) = (x + dx, y + dy);
                if nx < 0 || ny < 0 || nx >= width as i64 || ny >= height as i64 {
                    continue;
                }
                if let Some(c) = prev[(ny * width as i64 + nx) as usize] {
                    (0..3).for_each(|a| sum[a] += c[a]);
                    n += 1.0;
                }
            }
            if n > 0.0 {
                out[i] = Some(sum.map(|v| v / n));
                changed = true;
            }
        }
        if !changed {
            break;
        }
    }
    out
}

/// The textured quadtree mesh of plane `index` of a frame's segmentation, in the camera frame
/// (003's per-frame output): the bounding box, in the plane's frame, of where the rays through
/// the corners of its labelled pixels (`labels`, e.g. [`complete_labels`]) meet it (003 boxed
/// the points, which the edge-preserving filter pulls in at every border), the texture
/// resolution for that box ([`texture_px_per_m`]), and each texel's colour from the pixel its
/// centre projects to when that pixel carries the label ([`rectify`]). `None` for a plane
/// with no labelled pixel or one reaching behind the camera.
pub fn frame_plane_mesh(plane: &Plane, index: u32, labels: &[u32], k: &PinholeIntrinsics, colour: &ColorImage) -> Option<PlaneMesh> {
    let grid = frame_plane_grid(plane, index, labels, k)?;
    let px_per_m = grid.px_per_m;
    let colours = rectify(&grid, k, labels, index, colour);
    // Geometry cells about a pixel's footprint on the plane (its mean: area over pixels).
    let footprint_m = (plane.area_m2 / plane.pixels.max(1) as f32).sqrt();
    Some(PlaneMesh::build(grid, &colours, geometry_shift_for(px_per_m, footprint_m)))
}

/// The largest shift whose cells (2^shift texels of 1 / `px_per_m`) are at most `cell_m`.
pub fn geometry_shift_for(px_per_m: f32, cell_m: f32) -> u32 {
    let mut shift = 0;
    while shift < 8 && ((2u32 << shift) as f32) / px_per_m <= cell_m {
        shift += 1;
    }
    shift
}

/// The box `[min, max]`, in the in-plane coordinates of `frame` (given in the world of
/// `world_from_camera`), of the points where the rays through the centres and corners of the
/// pixels labelled `label` meet the plane (a corner only where it meets the plane within
/// twice the centre's depth); `None` if no labelled pixel's ray meets it in front of the
/// camera.
pub fn pixel_box(frame: &PlaneFrame, labels: &[u32], label: u32, k: &PinholeIntrinsics, world_from_camera: &crate::Se3) -> Option<[[f32; 2]; 2]> {
    use glam::DVec3;
    let f64v = |a: [f32; 3]| DVec3::new(f64::from(a[0]), f64::from(a[1]), f64::from(a[2]));
    // Everything below is linear in the pixel's homogeneous coordinates X = (x, y, 1) (f64):
    // the ray r(X) = ((x - cx)/fx, (y - cy)/fy, 1) in the camera frame; with the plane
    // n_c·p + d_c = 0 in that frame, the ray meets it at depth t = -d_c / (n_c·r); there the
    // in-plane coordinate along axis a (world axis a_w, origin o_w) is
    //   s_a = a_w·(R r t + T - o_w) = t (a_c·r) + a_w·(T - o_w),  a_c = Rᵀ a_w,
    // so each point costs three dot products of X and one division (a homography).
    let r_inv = world_from_camera.rotation.inverse();
    let n_w = f64v(frame.normal);
    let n_c = r_inv * n_w;
    let d_c = f64::from(frame.offset_m()) + n_w.dot(world_from_camera.translation_m);
    let origin_to_camera = world_from_camera.translation_m - f64v(frame.origin_m);
    let axes = [f64v(frame.u_axis), f64v(frame.v_axis)];
    let (a_c, shift) = (axes.map(|a| r_inv * a), axes.map(|a| a.dot(origin_to_camera)));
    // A camera-frame direction d as coefficients of X: d·r(X) = (dx/fx) x + (dy/fy) y + const.
    let (fx, fy, cx, cy) = (f64::from(k.fx_px), f64::from(k.fy_px), f64::from(k.cx_px), f64::from(k.cy_px));
    let linear = |d: DVec3| DVec3::new(d.x / fx, d.y / fy, d.z - d.x * cx / fx - d.y * cy / fy);
    let (den, num) = (linear(n_c), a_c.map(linear));
    let t_at = |p: DVec3| -d_c / den.dot(p);
    let (mut min, mut max) = ([f32::INFINITY; 2], [f32::NEG_INFINITY; 2]);
    let w = k.width_px as usize;
    for (row, line) in labels.chunks_exact(w).enumerate() {
        if label == NO_LABEL || !line.contains(&label) {
            continue;
        }
        let y = row as f64;
        for (col, _) in line.iter().enumerate().filter(|&(_, &l)| l == label) {
            let x = col as f64;
            let t_centre = t_at(DVec3::new(x, y, 1.0));
            if !(t_centre.is_finite() && t_centre > 0.0) {
                continue;
            }
            for (dx, dy) in [(0.0, 0.0), (-0.5, -0.5), (0.5, -0.5), (-0.5, 0.5), (0.5, 0.5)] {
                let p = DVec3::new(x + dx, y + dy, 1.0);
                let t = t_at(p);
                // A pixel seen at a grazing angle reaches far along the plane: its corners
                // are kept only within twice its centre's depth (or half).
                if !(t >= 0.5 * t_centre && t <= 2.0 * t_centre) {
                    continue;
                }
                for a in 0..2 {
                    let s = (t * num[a].dot(p) + shift[a]) as f32;
                    min[a] = min[a].min(s);
                    max[a] = max[a].max(s);
                }
            }
        }
    }
    (min[0] <= max[0]).then_some([min, max])
}

/// The texel grid of plane `index` of a frame (see [`frame_plane_mesh`]).
pub fn frame_plane_grid(plane: &Plane, index: u32, labels: &[u32], k: &PinholeIntrinsics) -> Option<TexelGrid> {
    let frame = PlaneFrame::of_plane(plane);
    let [min, max] = pixel_box(&frame, labels, index, k, &crate::Se3::IDENTITY)?;
    let px_per_m = texture_px_per_m(&frame, min, max, k)?;
    let width = (((max[0] - min[0]) * px_per_m).ceil() as u32).max(1);
    let height = (((max[1] - min[1]) * px_per_m).ceil() as u32).max(1);
    Some(TexelGrid { frame, px_per_m, min_m: min, width, height })
}

/// How far (pixels) the preprocessor blends a border into the normals next to it: the
/// bilateral window's radius plus the gradient smoothing's plus one for the central difference.
pub fn blend_reach_px(preprocess: &crate::preprocess::PreprocessConfig) -> u32 {
    preprocess.bilateral.map_or(0, |b| b.radius_px) + preprocess.gradient_smoothing.map_or(0, |g| g.radius_px) + 1
}

/// The labels a plane's surface is meshed and textured from: the segmentation's, plus each
/// unlabelled pixel whose raw depth (`raw_depth_m`, before the edge-preserving filter) is
/// within the labelling distance ([`PlaneConfig::label_distance_m`]) of the depth at which
/// its ray meets a plane that labels a pixel within `reach_px` of it (the plane needing the
/// smallest depth error, the sensor's noise being along the ray). Along a plane's border the
/// filtered normals blend into the next surface's and fail the labelling's angle test, though
/// the raw points there are still on the plane: on the synthetic stairs that border is a
/// quarter of each tread. Where two planes meet, depth error rather than distance decides: a
/// noisy point near a stair's inner corner is nearer the tread seen at a grazing angle, but
/// needs less depth error to be on the riser that faces the camera. Farther out, and for
/// pixels off every plane, nothing changes.
pub fn complete_labels(seg: &Segmentation, raw_depth_m: &[f32], k: &PinholeIntrinsics, config: &PlaneConfig, reach_px: u32) -> Vec<u32> {
    // Kernels `plane_window` (both axes), then `plane_complete`.
    let window = window_masks(&seg.labels, seg.planes.len() as u32, k, reach_px);
    let planes: Vec<[f32; 4]> = seg.planes.iter().map(|p| [p.normal[0], p.normal[1], p.normal[2], p.offset_m]).collect();
    let mut out = vec![NO_LABEL; seg.labels.len()];
    crate::cpu::plane_complete(&plane_complete_params(k, config), raw_depth_m, &seg.labels, &window, &planes, &mut out);
    out
}

/// Per pixel of `labels` (planes `0..plane_count`), the planes labelling a pixel within the
/// (2 `reach_px` + 1)² window around it, a bit each: kernel `plane_window`'s two passes.
pub fn window_masks(labels: &[u32], plane_count: u32, k: &PinholeIntrinsics, reach_px: u32) -> Vec<[u32; 2]> {
    let mut rows = vec![[0u32; 2]; labels.len()];
    crate::cpu::plane_window(&plane_window_params(k, reach_px, 0), labels, &[plane_count], &[], &mut rows);
    let mut window = vec![[0u32; 2]; labels.len()];
    crate::cpu::plane_window(&plane_window_params(k, reach_px, 1), labels, &[plane_count], &rows, &mut window);
    window
}

/// Kernel `plane_window`'s parameters for images of intrinsics `k` along `axis` (0: rows).
pub fn plane_window_params(k: &PinholeIntrinsics, reach_px: u32, axis: u32) -> crate::kernels::plane_window::PlaneWindowParams {
    crate::kernels::plane_window::PlaneWindowParams { width_px: k.width_px, height_px: k.height_px, reach_px, axis }
}

/// Kernel `plane_complete`'s parameters for images of intrinsics `k`.
pub fn plane_complete_params(k: &PinholeIntrinsics, config: &PlaneConfig) -> crate::kernels::plane_complete::PlaneCompleteParams {
    crate::kernels::plane_complete::PlaneCompleteParams {
        width_px: k.width_px,
        height_px: k.height_px,
        min_distance_m: config.label_min_distance_m,
        fx_px: k.fx_px,
        fy_px: k.fy_px,
        cx_px: k.cx_px,
        cy_px: k.cy_px,
        ..Default::default()
    }
}

/// 003's texture rectification, per destination texel (kernel `plane_rectify`): the texel's
/// centre (a point of the grid's plane, in the camera frame) projected with `k` to its nearest
/// pixel, and that pixel's colour if it carries `label`.
pub fn rectify(grid: &TexelGrid, k: &PinholeIntrinsics, labels: &[u32], label: u32, colour: &ColorImage) -> Vec<Option<[u8; 3]>> {
    let params = rectify_params(grid, k, label);
    let packed = pack_rgba8(colour);
    let mut texels = vec![0u32; (grid.width * grid.height) as usize];
    crate::cpu::plane_rectify(&params, labels, &packed, &mut texels);
    texels.iter().map(|&t| (t >> 24 != 0).then_some([t as u8, (t >> 8) as u8, (t >> 16) as u8])).collect()
}

/// The parameters of kernel `plane_rectify` for `grid` (camera frame), seen with `k`, and the
/// plane's `label`.
pub fn rectify_params(grid: &TexelGrid, k: &PinholeIntrinsics, label: u32) -> crate::kernels::plane_rectify::PlaneRectifyParams {
    let f = &grid.frame;
    crate::kernels::plane_rectify::PlaneRectifyParams {
        origin_x: f.origin_m[0],
        origin_y: f.origin_m[1],
        origin_z: f.origin_m[2],
        u_x: f.u_axis[0],
        u_y: f.u_axis[1],
        u_z: f.u_axis[2],
        v_x: f.v_axis[0],
        v_y: f.v_axis[1],
        v_z: f.v_axis[2],
        min_u_m: grid.min_m[0],
        min_v_m: grid.min_m[1],
        px_per_m: grid.px_per_m,
        width: grid.width,
        height: grid.height,
        label,
        image_width_px: k.width_px,
        image_height_px: k.height_px,
        fx_px: k.fx_px,
        fy_px: k.fy_px,
        cx_px: k.cx_px,
        cy_px: k.cy_px,
        ..Default::default()
    }
}

/// A colour image packed one pixel per u32, RGBA8 little-endian (R in the low byte, alpha 255).
pub fn pack_rgba8(colour: &ColorImage) -> Vec<u32> {
    colour.rgb8.chunks_exact(3).map(|c| u32::from_le_bytes([c[0], c[1], c[2], 255])).collect()
}


#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::planes::PlaneConfig;
    use crate::planes::reference::segment;
    use crate::cpu::preprocess::chain::preprocess;
    use crate::preprocess::PreprocessConfig;
    use crate::sim::plane_scenes::{NO_PLANE, PlaneScene, RenderedScene, ScenePlane, UNITS_PER_METRE};
    use crate::{RgbdCalibration, Se3};

    /// A covered texel no view saw takes its observed neighbours' mean, a gap two texels wide
    /// closes in two passes (not one), and a texel no quad covers stays unseen.
    #[test]
    fn covered_gaps_in_a_texture_are_filled_from_their_neighbours() {
        // A row of 5: seen, gap, gap, seen, and an uncovered unseen texel.
        let colours = [Some([10, 20, 30]), None, None, Some([30, 40, 50]), None];
        let covered = [true, true, true, true, false];
        let one = fill_covered_texels(&colours, &covered, 5, 1);
        assert_eq!(one[1], Some([10.0, 20.0, 30.0]));
        assert_eq!(one[2], Some([30.0, 40.0, 50.0]));
        assert_eq!(one[4], None, "not covered: left unseen");
        let wide = [Some([0, 0, 0]), None, None, None, Some([90, 90, 90])];
        let one = fill_covered_texels(&wide, &[true; 5], 5, 1);
        assert_eq!(one[2], None, "the middle of a 3-texel gap needs two passes");
        let two = fill_covered_texels(&wide, &[true; 5], 5, 2);
        assert_eq!(two[2], Some([45.0, 45.0, 45.0]));
        // In a quadtree mesh: a plane seen everywhere but one texel has no black texel.
        let grid = TexelGrid { frame: PlaneFrame::new([0.0, 0.0, -1.0], 2.0, [0.0, 0.0, 2.0], [1.0, 0.0, 0.0]), px_per_m: 64.0, min_m: [0.0, 0.0], width: 8, height: 8 };
        let mut seen = vec![Some([200u8, 100, 50]); 64];
        seen[9] = None;
        let mesh = PlaneMesh::build(grid, &seen, 1);
        assert!(mesh.cells[9], "its cell is covered (3 of 4 texels seen)");
        assert_eq!(&mesh.texture.rgb8[3 * 9..3 * 9 + 3], &[200, 100, 50], "filled, not black");
    }

    #[test]
    fn a_full_grid_is_one_quad_per_256_block() {
        let (w, h) = (256, 256);
        let d = quadtree_degrees(&vec![true; w * h], w, h);
        let (v, t) = quadtree_mesh(&d, w);
        assert_eq!((v.len(), t.len()), (4, 2));
        assert_eq!(v, vec![[0, 0], [256, 0], [0, 256], [256, 256]]);
        // One more column: a second row of quads down its side, halving as they go.
        let (w, h) = (257, 256);
        let d = quadtree_degrees(&vec![true; w * h], w, h);
        assert_eq!(d.iter().filter(|&&s| s > 0).count(), 1 + 256);
    }

    #[test]
    fn quads_cover_exactly_the_covered_texels() {
        // A disc with a hole and a ragged edge: every covered texel is in exactly one quad, no
        // other texel is in any.
        let (w, h) = (70, 50);
        let covered: Vec<bool> = (0..w * h)
            .map(|i| {
                let (x, y) = ((i % w) as f32 - 33.0, (i / w) as f32 - 24.0);
                let r = (x * x + y * y).sqrt();
                r < 23.0 + 2.0 * (x * 0.7).sin() && r > 4.0
            })
            .collect();
        let d = quadtree_degrees(&covered, w, h);
        let times = quad_cover_counts(&d, w, h);
        for i in 0..w * h {
            assert_eq!(times[i], u32::from(covered[i]), "texel ({}, {})", i % w, i / w);
        }
        let (vertices, triangles) = quadtree_mesh(&d, w);
        let texels = covered.iter().filter(|&&c| c).count();
        assert!(triangles.len() * 3 < texels * 2, "{} triangles for {texels} texels: the quadtree did not decimate (unit quads would be two per texel)", triangles.len());
        // Counter-clockwise in (x, y), and the area is the texels'.
        let mut area = 0.0;
        for t in &triangles {
            let [a, b, c] = t.map(|i| vertices[i as usize].map(|v| v as f32));
            let twice = (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]);
            assert!(twice > 0.0);
            area += 0.5 * twice;
        }
        assert_eq!(area as usize, texels);
    }

    /// A Kinect's resolution: at half of it a stair riser is 20 rows tall, and the one row at
    /// each edge that noise makes a toss-up is a tenth of it.
    const K: PinholeIntrinsics = PinholeIntrinsics { fx_px: 525.0, fy_px: 525.0, cx_px: 319.5, cy_px: 239.5, width_px: 640, height_px: 480 };

    /// Of the pixels that see true plane `surface` (`truth` in the camera frame), the
    /// footprint areas (m²) of those whose true point (moved by `world_from_camera`) the mesh
    /// covers, and of all.
    pub(crate) fn coverage(k: &PinholeIntrinsics, r: &RenderedScene, truth: &[Option<ScenePlane>], surface: usize, mesh: &PlaneMesh, world_from_camera: &Se3) -> (f64, f64) {
        let (mut covered, mut total) = (0.0f64, 0.0f64);
        for (ix, &l) in r.plane_of_pixel.iter().enumerate() {
            if l != surface as u32 {
                continue;
            }
            let t = truth[surface].expect("pixels of a plane");
            let ray = crate::sim::room::camera_ray(k, (ix % k.width_px as usize) as u32, (ix / k.width_px as usize) as u32);
            let p = ray * (-t.offset_m / t.normal.dot(ray));
            let footprint = p.z.powi(3) / (f64::from(k.fx_px * k.fy_px) * t.normal.dot(p).abs());
            total += footprint;
            let q = world_from_camera.transform_point(p);
            if mesh.covers(mesh.grid.frame.to_plane([q.x as f32, q.y as f32, q.z as f32])) {
                covered += footprint;
            }
        }
        (covered, total)
    }

    #[test]
    fn synthetic_scene_meshes_lie_on_their_planes_and_cover_them() {
        let mut failures = Vec::new();
        for scene in PlaneScene::all() {
            for noise in [None, Some(3)] {
                let r = scene.render(&K, noise);
                let calibration = RgbdCalibration { intrinsics: K, depth_units_per_metre: UNITS_PER_METRE as f32 };
                let pre = preprocess(&calibration, &PreprocessConfig::default(), &r.frame);
                let config = PlaneConfig::default();
                let seg = segment(&pre.levels, Some(&pre.depth_unfiltered_m), &config);
                let labels = complete_labels(&seg, &pre.depth_unfiltered_m, &K, &config, blend_reach_px(&PreprocessConfig::default()));
                let truth = scene.planes_in_camera();
                for (k, plane) in seg.planes.iter().enumerate() {
                    let mut votes = vec![0usize; truth.len()];
                    for (ix, &l) in seg.labels.iter().enumerate() {
                        if l == k as u32 && r.plane_of_pixel[ix] != NO_PLANE {
                            votes[r.plane_of_pixel[ix] as usize] += 1;
                        }
                    }
                    let s = (0..truth.len()).max_by_key(|&s| votes[s]).expect("surfaces");
                    let t = truth[s].expect("a plane surface");
                    let mesh = frame_plane_mesh(plane, k as u32, &labels, &K, &r.frame.color).expect("a mesh");
                    let worst_m = mesh.positions_m.iter().map(|p| t.distance_m(glam::DVec3::new(f64::from(p[0]), f64::from(p[1]), f64::from(p[2]))).abs()).fold(0.0, f64::max);
                    let (covered, total) = coverage(&K, &r, &truth, s, &mesh, &Se3::IDENTITY);
                    let cover = covered / total;
                    let texels = mesh.cells.iter().filter(|&&c| c).count();
                    // The target's planes: those over 2 % of the image.
                    let big = r.plane_of_pixel.iter().filter(|&&l| l == s as u32).count() * 50 > K.pixel_count();
                    eprintln!(
                        "{} ({}): plane {k} = surface {s}{}: {} quads ({} triangles) for {texels} texels, {} px/m, texture {}x{}, worst vertex {:.1} mm off the true plane, covers {:.1} %",
                        scene.name,
                        if noise.is_some() { "noisy" } else { "exact" },
                        if big { "" } else { " (under 2 % of the image)" },
                        mesh.quads,
                        mesh.triangles.len(),
                        mesh.grid.px_per_m,
                        mesh.texture.width_px,
                        mesh.texture.height_px,
                        worst_m * 1e3,
                        cover * 100.0
                    );
                    if worst_m >= 0.01 || (big && cover < 0.95) {
                        failures.push(format!("{} {noise:?} surface {s}", scene.name));
                    }
                }
            }
        }
        assert!(failures.is_empty(), "failed: {failures:?}");
    }

    #[test]
    fn frame_axes_are_right_handed_and_on_the_plane() {
        let f = PlaneFrame::new([0.0, -1.0, 0.0], 1.2, [0.3, 0.9, 2.0], [1.0, 0.2, 0.0]);
        assert!((dot(cross(f.u_axis, f.v_axis), f.normal) - 1.0).abs() < 1e-6);
        assert!((dot(f.normal, f.origin_m) + 1.2).abs() < 1e-6);
        let p = f.point([0.4, -0.7]);
        assert!((dot(f.normal, p) + f.offset_m()).abs() < 1e-6);
        let s = f.to_plane(p);
        assert!((s[0] - 0.4).abs() < 1e-6 && (s[1] + 0.7).abs() < 1e-6);
    }

    /// The box from the homography equals the box from intersecting each ray with the plane in
    /// the world and taking its in-plane coordinates (the definition), for a posed camera and a
    /// tilted plane whose horizon crosses the image (rays above it miss, rays just below it graze);
    /// a label no pixel carries, and a plane behind the camera, have no box.
    #[test]
    fn pixel_box_is_the_box_of_the_rays_meeting_the_plane() {
        let k = PinholeIntrinsics { fx_px: 60.0, fy_px: 55.0, cx_px: 31.5, cy_px: 23.5, width_px: 64, height_px: 48 };
        let world_from_camera = Se3::new(glam::DQuat::from_euler(glam::EulerRot::XYZ, -0.35, -0.2, 0.1), glam::DVec3::new(0.4, -0.3, 0.2));
        // A floor-like plane below and ahead of the camera, tilted so the top rows graze it.
        let frame = PlaneFrame::new([0.1, -0.9, 0.3], 0.8, [0.0, 0.9, 2.0], [1.0, 0.0, 0.0]);
        let labels: Vec<u32> = (0..64 * 48).map(|i| if (i / 64) % 3 == 0 || i % 7 == 0 { 2 } else { 1 }).collect();
        let direct = |label: u32| {
            let n = glam::DVec3::new(f64::from(frame.normal[0]), f64::from(frame.normal[1]), f64::from(frame.normal[2]));
            let d = f64::from(frame.offset_m());
            let (mut min, mut max) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
            for (i, _) in labels.iter().enumerate().filter(|&(_, &l)| l == label) {
                let (x, y) = ((i % 64) as f64, (i / 64) as f64);
                // Depth along the camera's z where the ray through (x, y) meets the plane.
                let hit = |x: f64, y: f64| {
                    let ray_c = glam::DVec3::new((x - 31.5) / 60.0, (y - 23.5) / 55.0, 1.0);
                    let ray_w = world_from_camera.rotation * ray_c;
                    let t = -(n.dot(world_from_camera.translation_m) + d) / n.dot(ray_w);
                    (t, world_from_camera.translation_m + ray_w * t)
                };
                let (t0, _) = hit(x, y);
                if !(t0 > 0.0 && t0.is_finite()) {
                    continue;
                }
                for (dx, dy) in [(0.0, 0.0), (-0.5, -0.5), (0.5, -0.5), (-0.5, 0.5), (0.5, 0.5)] {
                    let (t, p) = hit(x + dx, y + dy);
                    if t >= 0.5 * t0 && t <= 2.0 * t0 {
                        let o = glam::DVec3::new(f64::from(frame.origin_m[0]), f64::from(frame.origin_m[1]), f64::from(frame.origin_m[2]));
                        let r = p - o;
                        let s = [r.dot(glam::DVec3::from_array(frame.u_axis.map(f64::from))), r.dot(glam::DVec3::from_array(frame.v_axis.map(f64::from)))];
                        for a in 0..2 {
                            min[a] = min[a].min(s[a]);
                            max[a] = max[a].max(s[a]);
                        }
                    }
                }
            }
            [min, max]
        };
        for label in [1, 2] {
            let [min, max] = pixel_box(&frame, &labels, label, &k, &world_from_camera).expect("labelled pixels see the plane");
            let [dmin, dmax] = direct(label);
            assert!(dmax[0] - dmin[0] > 1.0 && dmax[1] - dmin[1] > 1.0, "a box of metres: {dmin:?} {dmax:?}");
            for a in 0..2 {
                // Within f32's rounding of the result (rows near the horizon reach hundreds of
                // metres along the plane).
                let close = |got: f32, want: f64| (f64::from(got) - want).abs() <= 1e-6 * (1.0 + want.abs());
                assert!(close(min[a], dmin[a]) && close(max[a], dmax[a]), "label {label}: {min:?} {max:?} vs {dmin:?} {dmax:?}");
            }
        }
        assert_eq!(pixel_box(&frame, &labels, 3, &k, &world_from_camera), None);
        // A plane facing the camera's way 1 m behind it: no ray meets it in front.
        let forward = world_from_camera.rotation * glam::DVec3::Z;
        let behind_m = world_from_camera.translation_m - forward;
        let behind = PlaneFrame::new(forward.as_vec3().to_array(), -forward.dot(behind_m) as f32, behind_m.as_vec3().to_array(), [1.0, 0.0, 0.0]);
        assert_eq!(pixel_box(&behind, &labels, 1, &k, &world_from_camera), None);
    }
}

// SPDX-License-Identifier: MIT
//! Marching-cubes tables, generated here from first principles rather than copied.
//!
//! # Conventions (shared with `shaders/wgsl/shared/marching_cubes.wgsl`)
//!
//! - Corner `c` of a cell has offset `(c & 1, (c >> 1) & 1, (c >> 2) & 1)` voxels from the
//!   cell's base voxel. Bit `c` of a cell's *case* is set when that corner's TSDF is negative
//!   (behind the surface); zero and positive TSDF (free space) leave it clear.
//! - Cube edge `e` runs along axis `a = e / 4` from corner offset `o` to `o + unit(a)`, where
//!   `o[a] = 0`, `o[(a + 1) % 3] = (e % 4) & 1` and `o[(a + 2) % 3] = (e % 4) >> 1`
//!   ([`edge_start_offset`]).
//! - Triangles wind counter-clockwise seen from free space: the normal `(b - a) x (c - a)`
//!   points toward positive TSDF.
//!
//! # Construction
//!
//! For each of the 256 cases, every cube face contributes iso-segments between its crossed
//! edges. Walking a face's boundary counter-clockwise as seen from outside the cell, each
//! segment starts at an edge where the walk *enters* the negative region and ends at the next
//! crossed edge. On a face with four crossings (diagonal corners of equal sign, the saddle) this
//! pairing cuts off each negative corner on its own ("negative corners stay separate"). The
//! rule reads only that face's four signs, so the two cells sharing a face pair its crossings
//! identically and the mesh has no cracks. Each crossed edge starts exactly one segment and ends
//! exactly one, so the segments chain into closed, consistently oriented polygons (negative side
//! on the right seen from outside the cell), which are then fanned into triangles. The fan
//! apex is chosen so that no fan diagonal joins two edges of a common face: the only triangle
//! edges lying in a cell face are then the face's own segments, which is what makes the welded
//! mesh a closed 2-manifold wherever all cells are present.

use std::sync::OnceLock;

/// Most triangles any case produces (asserted when the table is built).
pub const MAX_TRIANGLES_PER_CELL: usize = 5;
/// u32 words per case in [`McTable::packed`].
pub const PACKED_WORDS_PER_CASE: usize = 4;
/// Cube edges.
pub const N_EDGES: usize = 12;

/// The tables, indexed by case (bit `c` set = corner `c` negative).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct McTable {
    /// Bit `e` set when cube edge `e` is crossed by the surface.
    pub edge_masks: [u16; 256],
    /// Number of triangles of each case.
    pub triangle_counts: [u8; 256],
    /// The triangles of each case as cube-edge triples (first `triangle_counts[case]` used).
    pub triangles: [[[u8; 3]; MAX_TRIANGLES_PER_CELL]; 256],
}

/// The tables, built once.
pub fn mc_table() -> &'static McTable {
    static TABLE: OnceLock<McTable> = OnceLock::new();
    TABLE.get_or_init(build_table)
}

/// Offset of cube corner `corner` from the cell's base voxel.
pub const fn corner_offset(corner: u32) -> [u32; 3] {
    [corner & 1, (corner >> 1) & 1, (corner >> 2) & 1]
}

/// Axis (0 = x, 1 = y, 2 = z) along which cube edge `edge` runs.
pub const fn edge_axis(edge: u32) -> u32 {
    edge / 4
}

/// Offset from the cell's base voxel of the lower end of cube edge `edge`.
pub const fn edge_start_offset(edge: u32) -> [u32; 3] {
    let axis = edge / 4;
    let k = edge % 4;
    let mut o = [0u32; 3];
    o[((axis + 1) % 3) as usize] = k & 1;
    o[((axis + 2) % 3) as usize] = k >> 1;
    o
}

/// The corner at the lower end of `edge` and the one at its upper end.
pub const fn edge_corners(edge: u32) -> (u32, u32) {
    let o = edge_start_offset(edge);
    let c0 = o[0] | (o[1] << 1) | (o[2] << 2);
    (c0, c0 | (1 << edge_axis(edge)))
}

/// The cube edge joining two corners that differ in exactly one bit.
fn edge_between(c0: u32, c1: u32) -> u32 {
    let diff = c0 ^ c1;
    assert!(diff.count_ones() == 1, "corners {c0} and {c1} are not adjacent");
    let axis = diff.trailing_zeros();
    let lo = corner_offset(c0.min(c1));
    let k = lo[((axis + 1) % 3) as usize] | (lo[((axis + 2) % 3) as usize] << 1);
    axis * 4 + k
}

/// The two faces `(axis, side)` cube edge `edge` lies on.
fn edge_faces(edge: u32) -> [(u32, u32); 2] {
    let axis = edge_axis(edge);
    let o = edge_start_offset(edge);
    let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
    [(u, o[u as usize]), (v, o[v as usize])]
}

fn edges_share_a_face(a: u32, b: u32) -> bool {
    let fa = edge_faces(a);
    edge_faces(b).iter().any(|f| fa.contains(f))
}

/// The four corners of face `(axis, side)` in counter-clockwise order seen from outside the
/// cube (looking against the face's outward normal).
fn face_corners_ccw(axis: u32, side: u32) -> [u32; 4] {
    let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
    // unit(u) x unit(v) = unit(axis): (0,0) (1,0) (1,1) (0,1) in (u, v) is CCW seen from +axis.
    let uv: [(u32, u32); 4] = if side == 1 { [(0, 0), (1, 0), (1, 1), (0, 1)] } else { [(0, 0), (0, 1), (1, 1), (1, 0)] };
    uv.map(|(cu, cv)| (side << axis) | (cu << u) | (cv << v))
}

/// Oriented iso-segments (start edge, end edge) of one case, over all six faces.
fn case_segments(case: u32) -> Vec<(u32, u32)> {
    let negative = |c: u32| (case >> c) & 1 == 1;
    let mut segments = Vec::new();
    for axis in 0..3 {
        for side in 0..2 {
            let corners = face_corners_ccw(axis, side);
            // Boundary edges i: corners[i] -> corners[i + 1]; crossed if the signs differ.
            let crossed: Vec<usize> = (0..4).filter(|&i| negative(corners[i]) != negative(corners[(i + 1) % 4])).collect();
            for (j, &i) in crossed.iter().enumerate() {
                let enters = !negative(corners[i]) && negative(corners[(i + 1) % 4]);
                if enters {
                    let next = crossed[(j + 1) % crossed.len()];
                    segments.push((edge_between(corners[i], corners[(i + 1) % 4]), edge_between(corners[next], corners[(next + 1) % 4])));
                }
            }
        }
    }
    segments
}

/// Closed polygons (cube-edge loops) of one case.
fn case_polygons(case: u32) -> Vec<Vec<u32>> {
    let segments = case_segments(case);
    let mut next = [u32::MAX; N_EDGES];
    for &(a, b) in &segments {
        assert!(next[a as usize] == u32::MAX, "case {case}: edge {a} starts two segments");
        next[a as usize] = b;
    }
    let mut visited = [false; N_EDGES];
    let mut polygons = Vec::new();
    for start in 0..N_EDGES as u32 {
        if next[start as usize] == u32::MAX || visited[start as usize] {
            continue;
        }
        let mut polygon = Vec::new();
        let mut e = start;
        while !visited[e as usize] {
            visited[e as usize] = true;
            polygon.push(e);
            e = next[e as usize];
            assert!(e != u32::MAX, "case {case}: open segment chain");
        }
        assert!(e == start, "case {case}: segment chain does not close");
        polygons.push(polygon);
    }
    polygons
}

/// Fans `polygon` from the first apex whose diagonals join no two edges of a common face.
fn fan(case: u32, polygon: &[u32]) -> Vec<[u32; 3]> {
    let n = polygon.len();
    assert!(n >= 3, "case {case}: degenerate polygon {polygon:?}");
    let apex = (0..n)
        .find(|&a| (2..n - 1).all(|j| !edges_share_a_face(polygon[a], polygon[(a + j) % n])))
        .unwrap_or_else(|| panic!("case {case}: polygon {polygon:?} has no apex free of in-face diagonals"));
    (1..n - 1).map(|j| [polygon[apex], polygon[(apex + j) % n], polygon[(apex + j + 1) % n]]).collect()
}

fn build_table() -> McTable {
    let mut table = McTable { edge_masks: [0; 256], triangle_counts: [0; 256], triangles: [[[0; 3]; MAX_TRIANGLES_PER_CELL]; 256] };
    for case in 0..256u32 {
        let mut mask = 0u16;
        for e in 0..N_EDGES as u32 {
            let (c0, c1) = edge_corners(e);
            if ((case >> c0) & 1) != ((case >> c1) & 1) {
                mask |= 1 << e;
            }
        }
        table.edge_masks[case as usize] = mask;
        let triangles: Vec<[u32; 3]> = case_polygons(case).iter().flat_map(|p| fan(case, p)).collect();
        assert!(triangles.len() <= MAX_TRIANGLES_PER_CELL, "case {case} needs {} triangles", triangles.len());
        table.triangle_counts[case as usize] = triangles.len() as u8;
        for (slot, t) in triangles.iter().enumerate() {
            table.triangles[case as usize][slot] = t.map(|e| e as u8);
        }
    }
    table
}

impl McTable {
    /// The layout the kernels read (`mc_table` binding), [`PACKED_WORDS_PER_CASE`] words per
    /// case: word 0 = edge mask (bits 0..12) | triangle count << 12; words 1 and 2 = the
    /// triangles' cube edges as 4-bit nibbles, slot `s = 3 * triangle + vertex` in word
    /// `1 + s / 8` at bit `4 * (s % 8)`; word 3 = 0.
    pub fn packed(&self) -> Vec<u32> {
        let mut words = vec![0u32; 256 * PACKED_WORDS_PER_CASE];
        for case in 0..256 {
            let w = &mut words[case * PACKED_WORDS_PER_CASE..(case + 1) * PACKED_WORDS_PER_CASE];
            w[0] = u32::from(self.edge_masks[case]) | (u32::from(self.triangle_counts[case]) << 12);
            for t in 0..usize::from(self.triangle_counts[case]) {
                for v in 0..3 {
                    let slot = 3 * t + v;
                    w[1 + slot / 8] |= u32::from(self.triangles[case][t][v]) << (4 * (slot % 8));
                }
            }
        }
        words
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn edges_are_well_formed() {
        for e in 0..12 {
            let (c0, c1) = edge_corners(e);
            assert_eq!(c1 ^ c0, 1 << edge_axis(e), "edge {e} runs along its axis");
            assert_eq!(edge_between(c0, c1), e, "edge {e} round-trips through its corners");
        }
        let mut all: Vec<(u32, u32)> = (0..12).map(edge_corners).collect();
        all.sort_unstable();
        all.dedup();
        assert_eq!(all.len(), 12, "12 distinct edges");
    }

    #[test]
    fn triangles_use_exactly_the_crossed_edges() {
        let t = mc_table();
        let mut max = 0;
        for case in 0..256 {
            let mut used = 0u16;
            for tri in &t.triangles[case][..usize::from(t.triangle_counts[case])] {
                for &e in tri {
                    assert!(t.edge_masks[case] & (1 << e) != 0, "case {case}: triangle uses uncrossed edge {e}");
                    used |= 1 << e;
                }
                assert!(tri[0] != tri[1] && tri[1] != tri[2] && tri[0] != tri[2], "case {case}: degenerate triangle {tri:?}");
            }
            assert_eq!(used, t.edge_masks[case], "case {case}: every crossed edge is used");
            max = max.max(t.triangle_counts[case]);
        }
        assert_eq!(usize::from(max), MAX_TRIANGLES_PER_CELL, "the bound is tight");
        assert_eq!(t.triangle_counts[0], 0, "all positive: nothing");
        assert_eq!(t.triangle_counts[255], 0, "all negative: nothing");
    }

    #[test]
    fn single_negative_corner_faces_away_from_it() {
        // Corner 0 negative: one triangle on the x, y, z edges at the origin, whose normal must
        // point toward +(1, 1, 1) (free space).
        let t = mc_table();
        assert_eq!(t.triangle_counts[1], 1, "one triangle");
        let mid = |e: u8| {
            let o = edge_start_offset(u32::from(e));
            let mut p = o.map(|v| v as f32);
            p[edge_axis(u32::from(e)) as usize] += 0.5;
            p
        };
        let [a, b, c] = t.triangles[1][0].map(mid);
        let (u, v) = ([b[0] - a[0], b[1] - a[1], b[2] - a[2]], [c[0] - a[0], c[1] - a[1], c[2] - a[2]]);
        let n = [u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]];
        assert!(n.iter().all(|&x| x > 0.0), "normal {n:?} points to free space");
    }

    #[test]
    fn packed_table_decodes_back() {
        let t = mc_table();
        let words = t.packed();
        assert_eq!(words.len(), 256 * PACKED_WORDS_PER_CASE, "size");
        for case in 0..256 {
            let w = &words[case * 4..case * 4 + 4];
            assert_eq!(w[0] & 0xfff, u32::from(t.edge_masks[case]), "mask");
            assert_eq!(w[0] >> 12, u32::from(t.triangle_counts[case]), "count");
            for s in 0..3 * usize::from(t.triangle_counts[case]) {
                assert_eq!((w[1 + s / 8] >> (4 * (s % 8))) & 15, u32::from(t.triangles[case][s / 3][s % 3]), "case {case} slot {s}");
            }
            assert_eq!(w[3], 0, "reserved word");
        }
    }
}

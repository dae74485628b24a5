// SPDX-License-Identifier: MIT
//! Binary little-endian PLY export of a [`Mesh`].
//!
//! Vertex element: `float x y z` (metres), `float nx ny nz`, `uchar red green blue`; face
//! element: `list uchar uint vertex_indices` (always 3). Readable by MeshLab, CloudCompare,
//! Open3D and Blender.

use std::io::{BufWriter, Write};

use super::Mesh;

/// Writes `mesh` as binary little-endian PLY.
pub fn write_ply(mesh: &Mesh, w: impl Write) -> std::io::Result<()> {
    let mut w = BufWriter::new(w);
    write!(
        w,
        "ply\nformat binary_little_endian 1.0\ncomment webfusion marching cubes, world frame, metres\n\
         element vertex {}\nproperty float x\nproperty float y\nproperty float z\n\
         property float nx\nproperty float ny\nproperty float nz\n\
         property uchar red\nproperty uchar green\nproperty uchar blue\n\
         element face {}\nproperty list uchar uint vertex_indices\nend_header\n",
        mesh.vertex_count(),
        mesh.triangle_count()
    )?;
    for ((p, n), c) in mesh.positions_m.iter().zip(&mesh.normals).zip(&mesh.colors_rgb8) {
        for v in p.iter().chain(n) {
            w.write_all(&v.to_le_bytes())?;
        }
        w.write_all(c)?;
    }
    for t in &mesh.triangles {
        w.write_all(&[3])?;
        for i in t {
            w.write_all(&i.to_le_bytes())?;
        }
    }
    w.flush()
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// A small closed mesh: a tetrahedron with distinct normals and colours.
    pub(crate) fn tetrahedron() -> Mesh {
        Mesh {
            positions_m: vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.5]],
            normals: vec![[-0.577, -0.577, -0.577], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
            colors_rgb8: vec![[255, 0, 0], [0, 255, 0], [0, 0, 255], [10, 20, 30]],
            triangles: vec![[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]],
        }
    }

    /// Reads back what [`write_ply`] writes (and only that layout).
    fn read_ply(bytes: &[u8]) -> Mesh {
        let header_end = bytes.windows(11).position(|w| w == b"end_header\n").expect("end_header") + 11;
        let header = std::str::from_utf8(&bytes[..header_end]).expect("ASCII header");
        let mut lines = header.lines();
        assert_eq!(lines.next(), Some("ply"), "magic line");
        assert_eq!(lines.next(), Some("format binary_little_endian 1.0"), "format");
        let count = |element: &str| -> usize {
            header.lines().find_map(|l| l.strip_prefix(&format!("element {element} "))).expect("element line").parse().expect("count")
        };
        let (n_vertices, n_faces) = (count("vertex"), count("face"));
        let properties: Vec<&str> = header.lines().filter_map(|l| l.strip_prefix("property ")).collect();
        assert_eq!(
            properties,
            [
                "float x",
                "float y",
                "float z",
                "float nx",
                "float ny",
                "float nz",
                "uchar red",
                "uchar green",
                "uchar blue",
                "list uchar uint vertex_indices"
            ],
            "properties in order"
        );
        let mut body = &bytes[header_end..];
        let mut take = |n: usize| {
            let (a, b) = body.split_at(n);
            body = b;
            a
        };
        let f32_at = |b: &[u8], i: usize| f32::from_le_bytes(b[4 * i..4 * i + 4].try_into().expect("4 bytes"));
        let mut mesh = Mesh::default();
        for _ in 0..n_vertices {
            let v = take(27);
            mesh.positions_m.push([f32_at(v, 0), f32_at(v, 1), f32_at(v, 2)]);
            mesh.normals.push([f32_at(v, 3), f32_at(v, 4), f32_at(v, 5)]);
            mesh.colors_rgb8.push([v[24], v[25], v[26]]);
        }
        for _ in 0..n_faces {
            assert_eq!(take(1), [3], "triangles only");
            let f = take(12);
            mesh.triangles.push(std::array::from_fn(|k| u32::from_le_bytes(f[4 * k..4 * k + 4].try_into().expect("4 bytes"))));
        }
        assert!(body.is_empty(), "{} trailing bytes", body.len());
        mesh
    }

    #[test]
    fn ply_round_trips() {
        let mesh = tetrahedron();
        let mut bytes = Vec::new();
        write_ply(&mesh, &mut bytes).unwrap();
        assert_eq!(read_ply(&bytes), mesh, "what was written reads back bit for bit");
        // Negative control: a truncated file does not parse to the same mesh.
        let cut = std::panic::catch_unwind(|| read_ply(&bytes[..bytes.len() - 5]));
        assert!(cut.is_err(), "a truncated file is rejected");
        let mut empty = Vec::new();
        write_ply(&Mesh::default(), &mut empty).unwrap();
        assert_eq!(read_ply(&empty), Mesh::default(), "an empty mesh is a valid PLY");
    }
}

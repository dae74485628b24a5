// SPDX-License-Identifier: MIT
//! Scene export of planar meshes: glTF 2.0 binary (`.glb`, textures embedded) and OBJ + MTL +
//! PNG, each plane one textured mesh, plus optionally the vertex-coloured mesh of the rest of
//! the scene (the marching-cubes remainder).
//!
//! glTF: one node and one mesh per plane, each one indexed triangle primitive with `POSITION`
//! (with the `min`/`max` the spec requires), `NORMAL` (the plane's) and `TEXCOORD_0`, and a
//! material whose base colour is the plane's texture (a PNG in the BIN chunk, linear filtering,
//! clamped); metalness 0, roughness 1 (a matte surface: the texture is the observed colour).
//! The remainder, when given, is one more node with `COLOR_0` and the default material.
//! Positions are metres in the frame the meshes are in. OBJ: one `o plane_<i>` group each with
//! `usemtl plane_<i>`, whose `map_Kd` is `<stem>_textures/plane_<i>.png`; OBJ's texture `v`
//! runs up the image, so it is 1 − glTF's.

use std::io::Write;

use super::mesh::PlaneMesh;
use crate::codec::png;
use crate::mesh::Mesh;
use crate::mesh::glb::{GLB_CHUNK_BIN, GLB_CHUNK_JSON, GLB_MAGIC, GLB_VERSION};

const FLOAT: u32 = 5126;
const UNSIGNED_BYTE: u32 = 5121;
const UNSIGNED_INT: u32 = 5125;
const ARRAY_BUFFER: u32 = 34962;
const ELEMENT_ARRAY_BUFFER: u32 = 34963;
const LINEAR: u32 = 9729;
const CLAMP_TO_EDGE: u32 = 33071;

/// The fused mesh less the triangles the planar meshes cover: those whose centroid lies within
/// two voxels of a world plane and over one of its covered texels.
pub fn mesh_remainder(mesh: &Mesh, planes: &[PlaneMesh], voxel_m: f32) -> Mesh {
    let tol = 2.0 * voxel_m;
    let keep: Vec<bool> = mesh
        .triangles
        .iter()
        .map(|t| {
            let c: [f32; 3] = std::array::from_fn(|k| t.iter().map(|&i| mesh.positions_m[i as usize][k]).sum::<f32>() / 3.0);
            !planes.iter().any(|p| {
                let f = &p.grid.frame;
                let e = f.normal[0] * c[0] + f.normal[1] * c[1] + f.normal[2] * c[2] + f.offset_m();
                e.abs() <= tol && p.covers(f.to_plane(c))
            })
        })
        .collect();
    // Keep the vertices the kept triangles use, renumbered.
    let mut index = vec![u32::MAX; mesh.positions_m.len()];
    let mut out = Mesh::default();
    for (t, _) in mesh.triangles.iter().zip(&keep).filter(|(_, k)| **k) {
        out.triangles.push(t.map(|i| {
            if index[i as usize] == u32::MAX {
                index[i as usize] = out.positions_m.len() as u32;
                out.positions_m.push(mesh.positions_m[i as usize]);
                out.normals.push(mesh.normals[i as usize]);
                out.colors_rgb8.push(mesh.colors_rgb8[i as usize]);
            }
            index[i as usize]
        }));
    }
    out
}

/// The BIN chunk and the JSON arrays that describe it, as they are filled.
#[derive(Default)]
struct Builder {
    bin: Vec<u8>,
    views: Vec<serde_json::Value>,
    accessors: Vec<serde_json::Value>,
}

impl Builder {
    /// Appends `bytes` as one buffer view (4-byte aligned); returns its index.
    fn view(&mut self, bytes: &[u8], target: Option<u32>) -> usize {
        self.bin.resize(self.bin.len().next_multiple_of(4), 0);
        let mut v = serde_json::json!({"buffer": 0, "byteOffset": self.bin.len(), "byteLength": bytes.len()});
        if let Some(t) = target {
            v["target"] = t.into();
        }
        self.bin.extend_from_slice(bytes);
        self.views.push(v);
        self.views.len() - 1
    }

    /// Appends an accessor over a new view of `bytes`; returns its index.
    fn accessor(&mut self, bytes: &[u8], target: u32, mut accessor: serde_json::Value) -> usize {
        accessor["bufferView"] = self.view(bytes, Some(target)).into();
        self.accessors.push(accessor);
        self.accessors.len() - 1
    }

    fn positions(&mut self, positions: &[[f32; 3]]) -> usize {
        let (mut min, mut max) = ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
        for p in positions {
            for k in 0..3 {
                min[k] = min[k].min(p[k]);
                max[k] = max[k].max(p[k]);
            }
        }
        let bytes: Vec<u8> = positions.iter().flatten().flat_map(|v| v.to_le_bytes()).collect();
        self.accessor(&bytes, ARRAY_BUFFER, serde_json::json!({"componentType": FLOAT, "count": positions.len(), "type": "VEC3", "min": min, "max": max}))
    }

    fn floats(&mut self, values: &[f32], count: usize, kind: &str) -> usize {
        let bytes: Vec<u8> = values.iter().flat_map(|v| v.to_le_bytes()).collect();
        self.accessor(&bytes, ARRAY_BUFFER, serde_json::json!({"componentType": FLOAT, "count": count, "type": kind}))
    }

    fn indices(&mut self, triangles: &[[u32; 3]]) -> usize {
        let bytes: Vec<u8> = triangles.iter().flatten().flat_map(|i| i.to_le_bytes()).collect();
        self.accessor(&bytes, ELEMENT_ARRAY_BUFFER, serde_json::json!({"componentType": UNSIGNED_INT, "count": 3 * triangles.len(), "type": "SCALAR"}))
    }
}

/// Writes `planes` (textured) and `remainder` (vertex colours) as one glTF 2.0 binary scene.
/// Planes without triangles are left out.
///
/// # Errors
/// From `w`, or when a texture cannot be encoded.
pub fn write_scene_glb(planes: &[PlaneMesh], remainder: Option<&Mesh>, mut w: impl Write) -> std::io::Result<()> {
    let mut b = Builder::default();
    let (mut nodes, mut meshes, mut materials, mut textures, mut images) = (Vec::new(), Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for (i, plane) in planes.iter().enumerate().filter(|(_, p)| !p.triangles.is_empty()) {
        let n = plane.grid.frame.normal;
        let position = b.positions(&plane.positions_m);
        let normals: Vec<f32> = (0..plane.positions_m.len()).flat_map(|_| n).collect();
        let normal = b.floats(&normals, plane.positions_m.len(), "VEC3");
        let uv: Vec<f32> = plane.uv.iter().flatten().copied().collect();
        let texcoord = b.floats(&uv, plane.uv.len(), "VEC2");
        let indices = b.indices(&plane.triangles);
        let png = png::encode_rgb8(&plane.texture).map_err(std::io::Error::other)?;
        let view = b.view(&png, None);
        images.push(serde_json::json!({"bufferView": view, "mimeType": "image/png", "name": format!("plane_{i}")}));
        textures.push(serde_json::json!({"sampler": 0, "source": images.len() - 1}));
        materials.push(serde_json::json!({
            "name": format!("plane_{i}"),
            "pbrMetallicRoughness": {"baseColorTexture": {"index": textures.len() - 1}, "metallicFactor": 0.0, "roughnessFactor": 1.0},
        }));
        meshes.push(serde_json::json!({"name": format!("plane_{i}"), "primitives": [{"attributes": {"POSITION": position, "NORMAL": normal, "TEXCOORD_0": texcoord}, "indices": indices, "material": materials.len() - 1}]}));
        nodes.push(serde_json::json!({"name": format!("plane_{i}"), "mesh": meshes.len() - 1}));
    }
    if let Some(rest) = remainder.filter(|m| !m.triangles.is_empty()) {
        let position = b.positions(&rest.positions_m);
        let normals: Vec<f32> = rest.normals.iter().flatten().copied().collect();
        let normal = b.floats(&normals, rest.normals.len(), "VEC3");
        let colours: Vec<u8> = rest.colors_rgb8.iter().flat_map(|c| [c[0], c[1], c[2], 255]).collect();
        b.accessors.push(serde_json::json!({"componentType": UNSIGNED_BYTE, "normalized": true, "count": rest.colors_rgb8.len(), "type": "VEC4"}));
        let colour = b.accessors.len() - 1;
        b.accessors[colour]["bufferView"] = b.view(&colours, Some(ARRAY_BUFFER)).into();
        let indices = b.indices(&rest.triangles);
        meshes.push(serde_json::json!({"name": "remainder", "primitives": [{"attributes": {"POSITION": position, "NORMAL": normal, "COLOR_0": colour}, "indices": indices}]}));
        nodes.push(serde_json::json!({"name": "remainder", "mesh": meshes.len() - 1}));
    }
    let node_ids: Vec<usize> = (0..nodes.len()).collect();
    let mut json = serde_json::json!({
        "asset": {"version": "2.0", "generator": concat!("webfusion ", env!("CARGO_PKG_VERSION"))},
        "scene": 0,
        "scenes": [{"nodes": node_ids}],
    });
    if !nodes.is_empty() {
        json["nodes"] = nodes.into();
        json["meshes"] = meshes.into();
        json["accessors"] = b.accessors.into();
        json["bufferViews"] = b.views.into();
        json["buffers"] = serde_json::json!([{"byteLength": b.bin.len()}]);
    }
    if !images.is_empty() {
        json["materials"] = materials.into();
        json["textures"] = textures.into();
        json["images"] = images.into();
        json["samplers"] = serde_json::json!([{"magFilter": LINEAR, "minFilter": LINEAR, "wrapS": CLAMP_TO_EDGE, "wrapT": CLAMP_TO_EDGE}]);
    }
    let mut json = serde_json::to_vec(&json).map_err(std::io::Error::other)?;
    json.resize(json.len().next_multiple_of(4), b' ');
    let mut bin = b.bin;
    bin.resize(bin.len().next_multiple_of(4), 0);
    let chunk_len = |n: usize| u32::try_from(n).map_err(|_| std::io::Error::other(format!("glTF binary chunks are at most 4 GiB, this one is {n} bytes")));
    let total = 12 + 8 + json.len() + if bin.is_empty() { 0 } else { 8 + bin.len() };
    let mut out = Vec::with_capacity(total);
    for v in [GLB_MAGIC, GLB_VERSION, chunk_len(total)?, chunk_len(json.len())?, GLB_CHUNK_JSON] {
        out.extend(v.to_le_bytes());
    }
    out.extend(&json);
    if !bin.is_empty() {
        out.extend(chunk_len(bin.len())?.to_le_bytes());
        out.extend(GLB_CHUNK_BIN.to_le_bytes());
        out.extend(&bin);
    }
    w.write_all(&out)?;
    w.flush()
}

/// An OBJ scene's files.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ObjScene {
    /// `<stem>.obj`.
    pub obj: String,
    /// `<stem>.mtl`.
    pub mtl: String,
    /// Per plane with triangles, `(<stem>_textures/plane_<i>.png, its PNG bytes)`: paths
    /// relative to the OBJ.
    pub textures: Vec<(String, Vec<u8>)>,
}

/// The files of an OBJ scene named `stem`; `remainder` goes into the OBJ as one more group
/// with per-vertex colours (the common `v x y z r g b` extension).
///
/// # Errors
/// When a texture cannot be encoded.
pub fn scene_obj(stem: &str, planes: &[PlaneMesh], remainder: Option<&Mesh>) -> std::io::Result<ObjScene> {
    use std::fmt::Write as _;
    let (mut obj, mut mtl, mut textures) = (String::new(), String::new(), Vec::new());
    let _ = writeln!(obj, "# webfusion planar scene: positions in metres\nmtllib {stem}.mtl");
    // OBJ indices are 1-based and global.
    let (mut v_base, mut vt_base) = (1usize, 1usize);
    for (i, plane) in planes.iter().enumerate().filter(|(_, p)| !p.triangles.is_empty()) {
        let texture = format!("{stem}_textures/plane_{i}.png");
        textures.push((texture.clone(), png::encode_rgb8(&plane.texture).map_err(std::io::Error::other)?));
        let _ = writeln!(mtl, "newmtl plane_{i}\nKa 1 1 1\nKd 1 1 1\nKs 0 0 0\nillum 1\nmap_Kd {texture}\n");
        let n = plane.grid.frame.normal;
        let _ = writeln!(obj, "o plane_{i}\nusemtl plane_{i}\nvn {} {} {}", n[0], n[1], n[2]);
        for p in &plane.positions_m {
            let _ = writeln!(obj, "v {} {} {}", p[0], p[1], p[2]);
        }
        for t in &plane.uv {
            let _ = writeln!(obj, "vt {} {}", t[0], 1.0 - t[1]);
        }
        // One normal per plane: the last `vn`, index -1 relative.
        for tri in &plane.triangles {
            let [a, b, c] = tri.map(|k| k as usize);
            let _ = writeln!(obj, "f {}/{}/-1 {}/{}/-1 {}/{}/-1", v_base + a, vt_base + a, v_base + b, vt_base + b, v_base + c, vt_base + c);
        }
        v_base += plane.positions_m.len();
        vt_base += plane.uv.len();
    }
    if let Some(rest) = remainder.filter(|m| !m.triangles.is_empty()) {
        let _ = writeln!(obj, "o remainder");
        for (p, c) in rest.positions_m.iter().zip(&rest.colors_rgb8) {
            let _ = writeln!(obj, "v {} {} {} {:.4} {:.4} {:.4}", p[0], p[1], p[2], f32::from(c[0]) / 255.0, f32::from(c[1]) / 255.0, f32::from(c[2]) / 255.0);
        }
        for tri in &rest.triangles {
            let [a, b, c] = tri.map(|k| k as usize + v_base);
            let _ = writeln!(obj, "f {a} {b} {c}");
        }
    }
    Ok(ObjScene { obj, mtl, textures })
}

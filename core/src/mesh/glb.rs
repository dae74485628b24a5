// SPDX-License-Identifier: MIT
//! glTF 2.0 binary (`.glb`) export of a [`Mesh`].
//!
//! One scene, one node, one mesh with one indexed triangle primitive: `POSITION` (float vec3,
//! with the `min`/`max` the spec requires), `NORMAL` (float vec3), `COLOR_0` (normalized
//! unsigned byte vec4, alpha 255) and u32 indices, each in its own tightly packed buffer view
//! of the single BIN chunk. Chunks are 4-byte aligned: the JSON chunk padded with spaces, the
//! BIN chunk with zeros. glTF has no units field: positions are metres, as the spec assumes.
//! An empty mesh gives a valid file with an empty scene and no BIN chunk.

use std::fmt::Write as _;
use std::io::Write;

use super::Mesh;

/// `glTF` in little-endian.
pub const GLB_MAGIC: u32 = 0x4654_6c67;
/// Container version.
pub const GLB_VERSION: u32 = 2;
/// Chunk type `JSON`.
pub const GLB_CHUNK_JSON: u32 = 0x4e4f_534a;
/// Chunk type `BIN\0`.
pub const GLB_CHUNK_BIN: u32 = 0x004e_4942;

const FLOAT: u32 = 5126;
const UNSIGNED_BYTE: u32 = 5121;
const UNSIGNED_INT: u32 = 5125;
const ARRAY_BUFFER: u32 = 34962;
const ELEMENT_ARRAY_BUFFER: u32 = 34963;
const TRIANGLES: u32 = 4;

/// Writes `mesh` as a glTF 2.0 binary file.
pub fn write_glb(mesh: &Mesh, mut w: impl Write) -> std::io::Result<()> {
    let n_vertices = mesh.vertex_count();
    let generator = concat!("webfusion ", env!("CARGO_PKG_VERSION"));
    let (json, bin) = if n_vertices == 0 || mesh.triangles.is_empty() {
        (format!(r#"{{"asset":{{"version":"2.0","generator":"{generator}"}},"scene":0,"scenes":[{{}}]}}"#), Vec::new())
    } else {
        let mut bin = Vec::with_capacity(n_vertices * 28 + mesh.triangles.len() * 12);
        let mut min = [f32::INFINITY; 3];
        let mut max = [f32::NEG_INFINITY; 3];
        for p in &mesh.positions_m {
            for k in 0..3 {
                min[k] = min[k].min(p[k]);
                max[k] = max[k].max(p[k]);
            }
            bin.extend(p.iter().flat_map(|v| v.to_le_bytes()));
        }
        let normals_offset = bin.len();
        bin.extend(mesh.normals.iter().flatten().flat_map(|v| v.to_le_bytes()));
        let colors_offset = bin.len();
        bin.extend(mesh.colors_rgb8.iter().flat_map(|c| [c[0], c[1], c[2], 255]));
        let indices_offset = bin.len();
        bin.extend(mesh.triangles.iter().flatten().flat_map(|i| i.to_le_bytes()));
        let n_indices = 3 * mesh.triangles.len();
        let list = |v: [f32; 3]| format!("[{},{},{}]", v[0], v[1], v[2]);
        let mut json = String::new();
        write!(
            json,
            r#"{{"asset":{{"version":"2.0","generator":"{generator}"}},"scene":0,"scenes":[{{"nodes":[0]}}],"nodes":[{{"mesh":0}}],"#
        )
        .expect("write to String");
        write!(
            json,
            r#""meshes":[{{"primitives":[{{"attributes":{{"POSITION":0,"NORMAL":1,"COLOR_0":2}},"indices":3,"mode":{TRIANGLES}}}]}}],"#
        )
        .expect("write to String");
        write!(json, r#""buffers":[{{"byteLength":{}}}],"#, bin.len()).expect("write to String");
        write!(
            json,
            r#""bufferViews":[{{"buffer":0,"byteOffset":0,"byteLength":{normals_offset},"target":{ARRAY_BUFFER}}},{{"buffer":0,"byteOffset":{normals_offset},"byteLength":{},"target":{ARRAY_BUFFER}}},{{"buffer":0,"byteOffset":{colors_offset},"byteLength":{},"target":{ARRAY_BUFFER}}},{{"buffer":0,"byteOffset":{indices_offset},"byteLength":{},"target":{ELEMENT_ARRAY_BUFFER}}}],"#,
            colors_offset - normals_offset,
            indices_offset - colors_offset,
            bin.len() - indices_offset
        )
        .expect("write to String");
        write!(
            json,
            r#""accessors":[{{"bufferView":0,"componentType":{FLOAT},"count":{n_vertices},"type":"VEC3","min":{},"max":{}}},{{"bufferView":1,"componentType":{FLOAT},"count":{n_vertices},"type":"VEC3"}},{{"bufferView":2,"componentType":{UNSIGNED_BYTE},"normalized":true,"count":{n_vertices},"type":"VEC4"}},{{"bufferView":3,"componentType":{UNSIGNED_INT},"count":{n_indices},"type":"SCALAR"}}]}}"#,
            list(min),
            list(max)
        )
        .expect("write to String");
        (json, bin)
    };
    let mut json = json.into_bytes();
    json.resize(json.len().next_multiple_of(4), b' ');
    let mut bin = bin;
    bin.resize(bin.len().next_multiple_of(4), 0);
    let chunk_len = |n: usize| u32::try_from(n).map_err(|_| std::io::Error::other(format!("glTF binary chunks are at most 4 GiB, this one is {n} bytes")));
    let total = 12 + 8 + json.len() + if bin.is_empty() { 0 } else { 8 + bin.len() };
    w.write_all(&GLB_MAGIC.to_le_bytes())?;
    w.write_all(&GLB_VERSION.to_le_bytes())?;
    w.write_all(&chunk_len(total)?.to_le_bytes())?;
    w.write_all(&chunk_len(json.len())?.to_le_bytes())?;
    w.write_all(&GLB_CHUNK_JSON.to_le_bytes())?;
    w.write_all(&json)?;
    if !bin.is_empty() {
        w.write_all(&chunk_len(bin.len())?.to_le_bytes())?;
        w.write_all(&GLB_CHUNK_BIN.to_le_bytes())?;
        w.write_all(&bin)?;
    }
    w.flush()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Just enough JSON for the checks below (objects, arrays, numbers, strings, booleans).
    #[derive(Clone, Debug, PartialEq)]
    enum Json {
        Null,
        Bool(bool),
        Number(f64),
        Str(String),
        Array(Vec<Json>),
        Object(Vec<(String, Json)>),
    }

    impl Json {
        fn get(&self, key: &str) -> &Json {
            match self {
                Json::Object(m) => m.iter().find(|(k, _)| k == key).map(|(_, v)| v).unwrap_or(&Json::Null),
                _ => &Json::Null,
            }
        }
        fn at(&self, i: usize) -> &Json {
            match self {
                Json::Array(a) => &a[i],
                _ => panic!("not an array: {self:?}"),
            }
        }
        fn num(&self) -> f64 {
            match self {
                Json::Number(n) => *n,
                _ => panic!("not a number: {self:?}"),
            }
        }
        fn len(&self) -> usize {
            match self {
                Json::Array(a) => a.len(),
                _ => panic!("not an array: {self:?}"),
            }
        }
    }

    fn parse(s: &str) -> Json {
        let b = s.as_bytes();
        let mut i = 0;
        let v = value(b, &mut i);
        skip_ws(b, &mut i);
        assert_eq!(i, b.len(), "trailing characters after the JSON value");
        v
    }

    fn skip_ws(b: &[u8], i: &mut usize) {
        while *i < b.len() && b[*i].is_ascii_whitespace() {
            *i += 1;
        }
    }

    fn value(b: &[u8], i: &mut usize) -> Json {
        skip_ws(b, i);
        match b[*i] {
            b'{' => {
                *i += 1;
                let mut m = Vec::new();
                skip_ws(b, i);
                if b[*i] == b'}' {
                    *i += 1;
                    return Json::Object(m);
                }
                loop {
                    skip_ws(b, i);
                    let Json::Str(k) = value(b, i) else { panic!("object key must be a string") };
                    skip_ws(b, i);
                    assert_eq!(b[*i], b':', "colon after key {k}");
                    *i += 1;
                    m.push((k, value(b, i)));
                    skip_ws(b, i);
                    *i += 1;
                    match b[*i - 1] {
                        b',' => {}
                        b'}' => return Json::Object(m),
                        c => panic!("unexpected {:?} in object", c as char),
                    }
                }
            }
            b'[' => {
                *i += 1;
                let mut a = Vec::new();
                skip_ws(b, i);
                if b[*i] == b']' {
                    *i += 1;
                    return Json::Array(a);
                }
                loop {
                    a.push(value(b, i));
                    skip_ws(b, i);
                    *i += 1;
                    match b[*i - 1] {
                        b',' => {}
                        b']' => return Json::Array(a),
                        c => panic!("unexpected {:?} in array", c as char),
                    }
                }
            }
            b'"' => {
                let start = *i + 1;
                *i = start + b[start..].iter().position(|&c| c == b'"').expect("closing quote");
                let s = std::str::from_utf8(&b[start..*i]).expect("UTF-8").to_owned();
                *i += 1;
                Json::Str(s)
            }
            b't' | b'f' | b'n' => {
                for (word, v) in [("true", Json::Bool(true)), ("false", Json::Bool(false)), ("null", Json::Null)] {
                    if b[*i..].starts_with(word.as_bytes()) {
                        *i += word.len();
                        return v;
                    }
                }
                panic!("bad literal");
            }
            _ => {
                let start = *i;
                while *i < b.len() && matches!(b[*i], b'-' | b'+' | b'.' | b'e' | b'E' | b'0'..=b'9') {
                    *i += 1;
                }
                Json::Number(std::str::from_utf8(&b[start..*i]).expect("ASCII").parse().unwrap_or_else(|e| panic!("bad number: {e}")))
            }
        }
    }

    fn u32_at(b: &[u8], at: usize) -> u32 {
        u32::from_le_bytes(b[at..at + 4].try_into().expect("4 bytes"))
    }

    /// Checks the container and returns (JSON, BIN chunk).
    fn split_glb(bytes: &[u8]) -> (Json, &[u8]) {
        assert_eq!(u32_at(bytes, 0), GLB_MAGIC, "magic glTF");
        assert_eq!(u32_at(bytes, 4), 2, "version 2");
        assert_eq!(u32_at(bytes, 8) as usize, bytes.len(), "total length");
        let json_len = u32_at(bytes, 12) as usize;
        assert_eq!(u32_at(bytes, 16), GLB_CHUNK_JSON, "first chunk is JSON");
        assert_eq!(json_len % 4, 0, "JSON chunk 4-byte aligned");
        let json = std::str::from_utf8(&bytes[20..20 + json_len]).expect("UTF-8 JSON");
        assert!(json.trim_end_matches(' ').len() + 3 >= json.len(), "at most 3 padding spaces");
        let rest = &bytes[20 + json_len..];
        if rest.is_empty() {
            return (parse(json), rest);
        }
        let bin_len = u32_at(rest, 0) as usize;
        assert_eq!(u32_at(rest, 4), GLB_CHUNK_BIN, "second chunk is BIN");
        assert_eq!(bin_len % 4, 0, "BIN chunk 4-byte aligned");
        assert_eq!(rest.len(), 8 + bin_len, "BIN chunk is the rest of the file");
        (parse(json), &rest[8..])
    }

    #[test]
    fn glb_is_well_formed_and_holds_the_mesh() {
        let mut mesh = crate::mesh::ply::tests::tetrahedron();
        // An odd vertex count makes the JSON and BIN padding non-trivial.
        mesh.positions_m.push([0.25, 0.25, -0.5]);
        mesh.normals.push([0.0, 0.0, -1.0]);
        mesh.colors_rgb8.push([1, 2, 3]);
        let mut bytes = Vec::new();
        write_glb(&mesh, &mut bytes).unwrap();
        let (json, bin) = split_glb(&bytes);
        assert_eq!(json.get("asset").get("version"), &Json::Str("2.0".into()), "asset version");
        let buffer_len = json.get("buffers").at(0).get("byteLength").num() as usize;
        assert!(buffer_len <= bin.len() && bin.len() - buffer_len < 4, "buffer fits the BIN chunk, padding < 4");
        let prim = json.get("meshes").at(0).get("primitives").at(0);
        assert_eq!(prim.get("mode").num(), 4.0, "triangles");
        let accessors = json.get("accessors");
        let views = json.get("bufferViews");
        let n = mesh.vertex_count() as f64;
        for (attribute, component, kind, count) in [("POSITION", 5126.0, "VEC3", n), ("NORMAL", 5126.0, "VEC3", n), ("COLOR_0", 5121.0, "VEC4", n)] {
            let a = accessors.at(prim.get("attributes").get(attribute).num() as usize);
            assert_eq!((a.get("componentType").num(), a.get("type"), a.get("count").num()), (component, &Json::Str(kind.into()), count), "{attribute}");
        }
        let indices = accessors.at(prim.get("indices").num() as usize);
        assert_eq!((indices.get("componentType").num(), indices.get("count").num()), (5125.0, 3.0 * mesh.triangle_count() as f64), "u32 indices");
        assert_eq!(accessors.at(2).get("normalized"), &Json::Bool(true), "COLOR_0 bytes are normalized");
        let position = accessors.at(0);
        assert_eq!((position.get("min").at(2).num(), position.get("max").at(2).num()), (-0.5, 1.5), "POSITION min/max");
        for v in 0..views.len() {
            let view = views.at(v);
            let (offset, len) = (view.get("byteOffset").num() as usize, view.get("byteLength").num() as usize);
            assert!(offset % 4 == 0 && offset + len <= buffer_len, "view {v} aligned and inside the buffer");
        }
        // The data: positions, colours and indices read back from their views.
        let view_bytes = |accessor: usize| {
            let view = views.at(accessors.at(accessor).get("bufferView").num() as usize);
            let offset = view.get("byteOffset").num() as usize;
            &bin[offset..offset + view.get("byteLength").num() as usize]
        };
        let positions: Vec<f32> = view_bytes(0).chunks(4).map(|c| f32::from_le_bytes(c.try_into().expect("4 bytes"))).collect();
        assert_eq!(positions, mesh.positions_m.concat(), "positions");
        assert_eq!(view_bytes(2).chunks(4).map(|c| [c[0], c[1], c[2]]).collect::<Vec<_>>(), mesh.colors_rgb8, "colours");
        assert!(view_bytes(2).chunks(4).all(|c| c[3] == 255), "opaque");
        let indices: Vec<u32> = view_bytes(3).chunks(4).map(|c| u32::from_le_bytes(c.try_into().expect("4 bytes"))).collect();
        assert_eq!(indices, mesh.triangles.concat(), "indices");
        // Negative controls of the checker: a wrong length and a wrong magic are rejected.
        let mut bad = bytes.clone();
        bad[8] ^= 4;
        assert!(std::panic::catch_unwind(|| split_glb(&bad)).is_err(), "a wrong total length is rejected");
        let mut bad = bytes.clone();
        bad[0] = b'x';
        assert!(std::panic::catch_unwind(|| split_glb(&bad)).is_err(), "a wrong magic is rejected");
    }

    #[test]
    fn empty_mesh_is_a_valid_empty_scene() {
        let mut bytes = Vec::new();
        write_glb(&Mesh::default(), &mut bytes).unwrap();
        let (json, bin) = split_glb(&bytes);
        assert!(bin.is_empty(), "no BIN chunk");
        assert_eq!(json.get("meshes"), &Json::Null, "no mesh");
        assert_eq!(json.get("scenes").len(), 1, "one empty scene");
    }
}

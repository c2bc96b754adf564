//! Reading meshes: OBJ corner cases, glTF/GLB with node transforms and UVs, and bad input of every
//! kind (each must be an error naming the file, never a panic).

mod common;

use std::path::{Path, PathBuf};

use nuvo_geometry::{GeometryError, TriMesh, load_mesh};

fn write(dir: &Path, name: &str, bytes: impl AsRef<[u8]>) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, bytes).unwrap();
    p
}

/// Loads `text` as `name` and returns the error message, asserting that it names the file.
fn load_err(dir: &Path, name: &str, bytes: impl AsRef<[u8]>) -> String {
    let p = write(dir, name, bytes);
    let e = load_mesh(&p).err().unwrap_or_else(|| panic!("{name} should not load")).to_string();
    assert!(e.contains(name), "error for {name} does not name the file: {e}");
    eprintln!("{name}: {e}");
    e
}

const TRI: &str = "v 0 0 0\nv 1 0 0\nv 0 1 0\n";

#[test]
fn obj_relative_indices_polygons_and_uvs() {
    let dir = tempfile::tempdir().unwrap();
    let m = load_mesh(&write(dir.path(), "rel.obj", format!("{TRI}f -3 -2 -1\n"))).unwrap();
    assert_eq!(m.triangles, vec![[0, 1, 2]]);
    let pent = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0.5 1.5 0\nv 0 1 0\nf 1 2 3 4 5\n";
    assert_eq!(load_mesh(&write(dir.path(), "pent.OBJ", pent)).unwrap().triangles.len(), 3);
    let uv = format!("{TRI}vt 0 0\nvt 1 0\nvt 0 1\nf 1/-3 2/-2 3/-1\n");
    let m = load_mesh(&write(dir.path(), "uv.obj", uv)).unwrap();
    let layer = m.uv.unwrap();
    assert_eq!(layer.coords.len(), 3);
    assert_eq!(layer.triangles.len(), 1);
}

#[test]
fn obj_bad_input_is_a_clear_error() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let cases: Vec<(&str, Vec<u8>, &str)> = vec![
        ("empty.obj", vec![], "no faces"),
        ("nofaces.obj", TRI.into(), "no faces"),
        ("zero_index.obj", format!("{TRI}f 0 1 2\n").into(), "OBJ"),
        ("out_of_range.obj", format!("{TRI}f 1 2 9\n").into(), "OBJ"),
        ("neg_out_of_range.obj", format!("{TRI}f -1 -2 -9\n").into(), "OBJ"),
        ("vt_out_of_range.obj", format!("{TRI}vt 0 0\nf 1/1 2/5 3/1\n").into(), "OBJ"),
        ("nan.obj", "v nan 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n".into(), "non-finite"),
        ("inf.obj", "v 0 0 0\nv inf 0 0\nv 0 1 0\nf 1 2 3\n".into(), "non-finite"),
        ("truncated.obj", "v 0 0 0\nv 1 0 0\nv 0 1".into(), "OBJ"),
        ("garbage.obj", (0..4000u32).map(|i| (i.wrapping_mul(2654435761) >> 13) as u8).collect(), ""),
        ("mixed_uv.obj", format!("{TRI}v 1 1 0\nvt 0 0\nf 1/1 2/1 3/1\nf 2 4 3\n").into(), "texture"),
    ];
    for (name, bytes, needle) in cases {
        let e = load_err(d, name, bytes);
        assert!(e.contains(needle), "{name}: {e}");
    }
    // Zero or relative texture indices must not panic, whatever tobj makes of them.
    for (name, text) in
        [("vt_zero.obj", "vt 0 0\nf 1/0 2/0 3/0\n"), ("vt_neg.obj", "vt 0 0\nf 1/-1 2/-1 3/-1\n")]
    {
        let r = load_mesh(&write(d, name, format!("{TRI}{text}")));
        if let Ok(m) = r {
            assert!(m.validate().is_ok());
        }
    }
    let e = load_mesh(&d.join("missing.obj")).unwrap_err();
    assert!(matches!(e, GeometryError::Io { .. }) && e.to_string().contains("missing.obj"), "{e}");
    let e = load_err(d, "mesh.stl", "solid x");
    assert!(e.contains(".obj") && e.contains(".glb"), "{e}");
}

/// A tiny glTF builder: one triangle (0,0,0), (1,0,0), (0,1,0) with UVs and u16 indices.
struct Gltf {
    bin: Vec<u8>,
}

impl Gltf {
    fn triangle() -> Gltf {
        let mut bin = Vec::new();
        for v in [0.0f32, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0] {
            bin.extend_from_slice(&v.to_le_bytes());
        }
        for v in [0.0f32, 0.0, 1.0, 0.0, 0.0, 0.25] {
            bin.extend_from_slice(&v.to_le_bytes());
        }
        for i in [0u16, 1, 2, 0] {
            bin.extend_from_slice(&i.to_le_bytes());
        }
        Gltf { bin }
    }

    /// The JSON document; `extra_nodes` etc. are spliced in verbatim.
    fn json(
        &self,
        uri: Option<&str>,
        nodes: &str,
        scene_nodes: &str,
        pos_view_extra: &str,
        pos_count: usize,
    ) -> String {
        let uri = uri.map(|u| format!(r#""uri": "{u}", "#)).unwrap_or_default();
        format!(
            r#"{{"asset": {{"version": "2.0"}},
  "buffers": [{{{uri}"byteLength": {len}}}],
  "bufferViews": [{{"buffer": 0, "byteOffset": 0, "byteLength": 36 {pos_view_extra}}},
                  {{"buffer": 0, "byteOffset": 36, "byteLength": 24}},
                  {{"buffer": 0, "byteOffset": 60, "byteLength": 6}}],
  "accessors": [{{"bufferView": 0, "componentType": 5126, "count": {pos_count}, "type": "VEC3",
                  "min": [0, 0, 0], "max": [1, 1, 0]}},
                {{"bufferView": 1, "componentType": 5126, "count": 3, "type": "VEC2"}},
                {{"bufferView": 2, "componentType": 5123, "count": 3, "type": "SCALAR"}}],
  "meshes": [{{"primitives": [{{"attributes": {{"POSITION": 0, "TEXCOORD_0": 1}}, "indices": 2}}]}}],
  "nodes": [{nodes}],
  "scenes": [{{"nodes": [{scene_nodes}]}}], "scene": 0}}"#,
            len = self.bin.len()
        )
    }

    fn glb(&self, json: &str) -> Vec<u8> {
        let mut j = json.as_bytes().to_vec();
        while !j.len().is_multiple_of(4) {
            j.push(b' ');
        }
        let mut b = self.bin.clone();
        while !b.len().is_multiple_of(4) {
            b.push(0);
        }
        let total = 12 + 8 + j.len() + 8 + b.len();
        let mut out = Vec::new();
        out.extend_from_slice(b"glTF");
        out.extend_from_slice(&2u32.to_le_bytes());
        out.extend_from_slice(&(total as u32).to_le_bytes());
        out.extend_from_slice(&(j.len() as u32).to_le_bytes());
        out.extend_from_slice(b"JSON");
        out.extend_from_slice(&j);
        out.extend_from_slice(&(b.len() as u32).to_le_bytes());
        out.extend_from_slice(b"BIN\0");
        out.extend_from_slice(&b);
        out
    }
}

const NODES: &str = r#"{"mesh": 0, "translation": [10, 0, 0]},
    {"children": [2], "scale": [2, 2, 2]},
    {"mesh": 0, "translation": [0, 1, 0]},
    {"mesh": 0, "scale": [-1, 1, 1]}"#;

fn check_instances(m: &TriMesh) {
    assert_eq!(m.triangles.len(), 3);
    let tri = |f: usize| m.corners(f);
    assert_eq!(tri(0), [[10.0, 0.0, 0.0], [11.0, 0.0, 0.0], [10.0, 1.0, 0.0]]);
    // Child of a scaled parent: scale(2) * translate(0, 1, 0).
    let t1 = (0..3).map(tri).find(|t| t[0] == [0.0, 2.0, 0.0]).expect("nested instance");
    assert_eq!(t1[1], [2.0, 2.0, 0.0]);
    // The mirrored instance keeps an outward (+z) normal because its winding was flipped.
    for f in 0..3 {
        assert!(m.face_normal_scaled(f)[2] > 0.0, "face {f} flipped: {:?}", tri(f));
    }
    let uv = m.uv.as_ref().expect("every primitive has TEXCOORD_0");
    // glTF v points down; stored flipped to OBJ's convention.
    let uvs: Vec<[f32; 2]> = uv.triangles[0].iter().map(|&i| uv.coords[i as usize]).collect();
    assert_eq!(uvs, vec![[0.0, 1.0], [1.0, 1.0], [0.0, 0.75]]);
}

#[test]
fn gltf_and_glb_with_node_transforms_and_uvs() {
    let dir = tempfile::tempdir().unwrap();
    let g = Gltf::triangle();
    write(dir.path(), "tri.bin", &g.bin);
    let p = write(dir.path(), "tri.gltf", g.json(Some("tri.bin"), NODES, "0, 1, 3", "", 3));
    check_instances(&load_mesh(&p).unwrap());
    let p = write(dir.path(), "tri.glb", g.glb(&g.json(None, NODES, "0, 1, 3", "", 3)));
    check_instances(&load_mesh(&p).unwrap());
}

#[test]
fn gltf_triangle_strips_are_read_with_consistent_winding() {
    let dir = tempfile::tempdir().unwrap();
    let mut bin = Vec::new();
    for v in [0.0f32, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 1.0, 1.0, 0.0] {
        bin.extend_from_slice(&v.to_le_bytes());
    }
    write(dir.path(), "strip.bin", &bin);
    let json = r#"{"asset": {"version": "2.0"}, "buffers": [{"uri": "strip.bin", "byteLength": 48}],
      "bufferViews": [{"buffer": 0, "byteLength": 48}],
      "accessors": [{"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3",
                     "min": [0, 0, 0], "max": [1, 1, 0]}],
      "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "mode": 5}]}],
      "nodes": [{"mesh": 0}], "scenes": [{"nodes": [0]}]}"#;
    let m = load_mesh(&write(dir.path(), "strip.gltf", json)).unwrap();
    assert_eq!(m.triangles.len(), 2);
    assert!(m.uv.is_none());
    assert!((0..2).all(|f| m.face_normal_scaled(f)[2] > 0.0), "{:?}", m.triangles);
}

#[test]
fn gltf_bad_input_is_a_clear_error() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let g = Gltf::triangle();
    write(d, "tri.bin", &g.bin);
    let good = g.glb(&g.json(None, r#"{"mesh": 0}"#, "0", "", 3));
    let cases: Vec<(&str, Vec<u8>, &str)> = vec![
        ("empty.glb", vec![], "glTF"),
        ("garbage.gltf", b"{ this is not json".to_vec(), "glTF"),
        ("truncated.glb", good[..good.len() / 2].to_vec(), "glTF"),
        (
            "stride.gltf",
            g.json(Some("tri.bin"), r#"{"mesh": 0}"#, "0", r#", "byteStride": 8"#, 3).into(),
            "stride",
        ),
        ("count.gltf", g.json(Some("tri.bin"), r#"{"mesh": 0}"#, "0", "", 100).into(), "do not fit"),
        ("missing_bin.gltf", g.json(Some("nope.bin"), r#"{"mesh": 0}"#, "0", "", 3).into(), "buffer"),
        (
            "cycle.gltf",
            g.json(Some("tri.bin"), r#"{"mesh": 0, "children": [1]}, {"children": [0]}"#, "0", "", 3).into(),
            "",
        ),
    ];
    for (name, bytes, needle) in cases {
        let e = load_err(d, name, bytes);
        assert!(e.contains(needle), "{name}: {e}");
    }
    // An index out of range: patch the third index (bytes 64..66) to 7.
    let mut bad = Gltf::triangle();
    bad.bin[64..66].copy_from_slice(&7u16.to_le_bytes());
    let e = load_err(d, "index.glb", bad.glb(&bad.json(None, r#"{"mesh": 0}"#, "0", "", 3)));
    assert!(e.contains("out of range"), "{e}");
    // NaN coordinates.
    let mut nan = Gltf::triangle();
    nan.bin[0..4].copy_from_slice(&f32::NAN.to_le_bytes());
    let e = load_err(d, "nan.glb", nan.glb(&nan.json(None, r#"{"mesh": 0}"#, "0", "", 3)));
    assert!(e.contains("non-finite"), "{e}");
}

#[test]
fn shared_test_meshes_load_with_the_documented_face_counts() {
    use nuvo_geometry::testdata::data_file;
    for (name, faces) in [
        ("stanford-bunny.obj", 69_451),
        ("spot.obj", 5_856),
        ("fandisk.obj", 12_946),
        ("rocker-arm.obj", 20_088),
        ("teapot.obj", 6_320),
        ("unruly_bunny.obj", 375_680),
    ] {
        let m = load_mesh(&data_file(&format!("meshes/{name}"))).unwrap();
        assert_eq!(m.triangles.len(), faces, "{name}");
        assert!(m.has_area());
    }
    let spot = load_mesh(&data_file("meshes/spot.obj")).unwrap();
    let uv = spot.uv.expect("spot carries texture coordinates");
    assert_eq!(uv.coords.len(), 3_225);
}

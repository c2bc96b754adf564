//! Mutated files (byte flips, truncations, spliced tokens) must give `Ok` or a clear error, never a
//! panic, for every reader. Deterministic: the mutations come from a fixed seed.

use std::path::Path;

use nuvo_geometry::npy::write_npy_bytes;
use rand::{Rng, SeedableRng};

const TOKENS: &[&[u8]] = &[
    b"-1",
    b"0",
    b"nan",
    b"inf",
    b"4294967295",
    b"/",
    b"//",
    b" ",
    b"\n",
    b"-999999999",
    b"1e39",
    b"f",
    b"vt",
    b"element vertex 3\n",
    b"(",
    b")",
    b"'",
    b"{",
    b"}",
    b"\x00",
];

fn mutate(rng: &mut impl Rng, base: &[u8]) -> Vec<u8> {
    let mut v = base.to_vec();
    for _ in 0..rng.random_range(1..4) {
        if v.is_empty() {
            break;
        }
        let i = rng.random_range(0..v.len());
        match rng.random_range(0..4) {
            0 => v[i] = rng.random(),
            1 => v.truncate(i),
            2 => {
                let t = TOKENS[rng.random_range(0..TOKENS.len())];
                v.splice(i..i, t.iter().copied());
            }
            _ => {
                let j = rng.random_range(i..v.len());
                v.drain(i..j);
            }
        }
    }
    v
}

/// Writes `count` mutations of `base` as `name` and runs `load` on each.
fn run<T, E: std::fmt::Display>(
    dir: &Path,
    name: &str,
    base: &[u8],
    count: usize,
    load: impl Fn(&Path) -> Result<T, E>,
) {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(name.len() as u64);
    let p = dir.join(name);
    let mut errors = 0;
    for _ in 0..count {
        std::fs::write(&p, mutate(&mut rng, base)).unwrap();
        if let Err(e) = load(&p) {
            errors += 1;
            assert!(e.to_string().contains(name), "error does not name the file: {e}");
        }
    }
    assert!(errors > 0, "{name}: no mutation was rejected; the test is not exercising the reader");
}

#[test]
fn mutated_files_never_panic() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let obj = b"v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nvn 0 0 1\nf 1/1/1 2/2/1 3/3/1 4/4/1\nf -4/-4 -2/-2 -1/-1\n";
    run(d, "m.obj", obj, 400, nuvo_geometry::load_mesh);
    let ply = b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nproperty float nx\nproperty float ny\nproperty float nz\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0 0 0 1\n1 0 0 0 0 1\n0 1 0 0 0 1\n3 0 1 2\n";
    run(d, "m.ply", ply, 400, nuvo_geometry::point_cloud::read_points);
    run(d, "m.xyz", b"0 0 0\n1 0 0 0 0 1\n0,1,0\n", 200, nuvo_geometry::point_cloud::read_points);
    let npy = write_npy_bytes(&[3, 3, 3], "|u1", &[7; 27], false);
    run(d, "m.npy", &npy, 400, nuvo_geometry::npy::read_npy);
    let gltf = br#"{"asset": {"version": "2.0"}, "buffers": [{"uri": "data:application/octet-stream;base64,AAAAAAAAAAAAAAAAAACAPwAAAAAAAAAAAAAAAAAAgD8AAAAAAAABAAIAAAA=", "byteLength": 44}],
      "bufferViews": [{"buffer": 0, "byteLength": 36}, {"buffer": 0, "byteOffset": 36, "byteLength": 6}],
      "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3", "min": [0,0,0], "max": [1,1,0]},
                    {"bufferView": 1, "componentType": 5123, "count": 3, "type": "SCALAR"}],
      "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}],
      "nodes": [{"mesh": 0, "children": [1]}, {"mesh": 0, "translation": [1, 0, 0]}], "scenes": [{"nodes": [0]}]}"#;
    assert_eq!(
        nuvo_geometry::load_mesh(&{
            let p = d.join("ok.gltf");
            std::fs::write(&p, gltf).unwrap();
            p
        })
        .unwrap()
        .triangles
        .len(),
        2
    );
    run(d, "m.gltf", gltf, 400, nuvo_geometry::load_mesh);
}

/// `load_colours` on mutated coloured files (and mutated MTL files and textures next to a fixed
/// OBJ): `Ok` (possibly with warnings, each naming the file) or an error naming it, never a panic.
#[test]
fn mutated_coloured_files_never_panic() {
    use nuvo_geometry::appearance::load_colours;
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let load = |p: &Path| {
        load_colours(p).map(|loaded| {
            let name = p.file_name().unwrap().to_str().unwrap();
            for w in &loaded.warnings {
                assert!(w.contains(name), "warning does not name the file: {w}");
            }
        })
    };
    let mut png = std::io::Cursor::new(Vec::new());
    image::RgbImage::from_pixel(3, 2, image::Rgb([9, 99, 199]))
        .write_to(&mut png, image::ImageFormat::Png)
        .unwrap();
    let png = png.into_inner();
    std::fs::write(d.join("t.png"), &png).unwrap();
    let mtl = b"newmtl a\nKd 1 0.5 0.25\nmap_Kd -s 1 1 1 t.png\nnewmtl b\nKd 0 0 1\n";
    std::fs::write(d.join("m.mtl"), mtl).unwrap();
    let obj = b"mtllib m.mtl\nv 0 0 0 1 0 0\nv 1 0 0 0 1 0\nv 1 1 0 0 0 1\nv 0 1 0 1 1 1\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nusemtl a\nf 1/1 2/2 3/3\nusemtl b\nf 1/1 3/3 4/4\n";
    run(d, "c.obj", obj, 300, load);
    // The MTL file and the texture mutated under a fixed OBJ never fail: they are warnings.
    let fixed = String::from_utf8(obj.to_vec()).unwrap().replace("m.mtl", "x.mtl");
    std::fs::write(d.join("fixed.obj"), fixed).unwrap();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
    for _ in 0..200 {
        std::fs::write(d.join("x.mtl"), mutate(&mut rng, mtl)).unwrap();
        std::fs::write(d.join("t.png"), mutate(&mut rng, &png)).unwrap();
        load(&d.join("fixed.obj")).unwrap();
    }
    std::fs::write(d.join("t.png"), &png).unwrap();
    let ply = b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nproperty uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n0 0 0 255 0 0\n1 0 0 0 255 0\n0 1 0 0 0 255\n";
    run(d, "c.ply", ply, 300, load);
    run(d, "c.xyz", b"0 0 0 0 0 1 255 0 0\n1 0 0 0 0 1 0 255 0\n0,1,0,0,0,1,0,0,255\n", 200, load);
    // One triangle with TEXCOORD_0 and COLOR_0 (normalised bytes) and a textured material.
    let gltf = br#"{"asset": {"version": "2.0"}, "buffers": [{"uri": "data:application/octet-stream;base64,AAAAAAAAAAAAAAAAAACAPwAAAAAAAAAAAAAAAAAAgD8AAAAAAAAAAAAAAAAAAIA/AAAAAAAAAAAAAIA//wAA/wD/AP8AAP//", "byteLength": 72}],
      "bufferViews": [{"buffer": 0, "byteLength": 36}, {"buffer": 0, "byteOffset": 36, "byteLength": 24}, {"buffer": 0, "byteOffset": 60, "byteLength": 12}],
      "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3", "min": [0,0,0], "max": [1,1,0]},
                    {"bufferView": 1, "componentType": 5126, "count": 3, "type": "VEC2"},
                    {"bufferView": 2, "componentType": 5121, "normalized": true, "count": 3, "type": "VEC4"}],
      "images": [{"uri": "t.png"}], "textures": [{"source": 0}],
      "materials": [{"pbrMetallicRoughness": {"baseColorFactor": [1, 0.5, 1, 1], "baseColorTexture": {"index": 0}}}],
      "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "TEXCOORD_0": 1, "COLOR_0": 2}, "material": 0}]}],
      "nodes": [{"mesh": 0}], "scenes": [{"nodes": [0]}]}"#;
    let ok = d.join("ok.gltf");
    std::fs::write(&ok, gltf).unwrap();
    let loaded = load_colours(&ok).unwrap();
    assert!(loaded.colours.is_some() && loaded.warnings.is_empty(), "{:?}", loaded.warnings);
    run(d, "c.gltf", gltf, 400, load);
}

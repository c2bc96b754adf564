//! `nuvo unwrap` end to end: a mesh it has never seen, with no config; the user's vertices and faces
//! kept; `config.toml` reproducing the run; glTF in, glTF scene out; bad input refused cleanly.

use std::path::{Path, PathBuf};

mod common;
use common::{FAST_UNWRAP, nuvo, run};

/// A closed latitude-longitude sphere (squashed into an ellipsoid, so it has a preferred axis),
/// written as OBJ with 1-based indices and awkward coordinates that do not survive a scale and back.
fn write_ellipsoid(path: &Path) -> (Vec<String>, Vec<String>) {
    let (rings, segments) = (12, 16);
    let mut v = Vec::new();
    v.push(format!("v 0.1 0.3 {}", 0.7 + 1.0 / 3.0));
    for r in 1..rings {
        let theta = std::f64::consts::PI * r as f64 / rings as f64;
        for s in 0..segments {
            let phi = std::f64::consts::TAU * s as f64 / segments as f64;
            let (x, y, z) = (theta.sin() * phi.cos(), theta.sin() * phi.sin(), theta.cos());
            v.push(format!("v {} {} {}", 0.1 + 0.6 * x as f32, 0.3 + 0.35 * y as f32, 0.7 + z as f32 / 3.0));
        }
    }
    v.push(format!("v 0.1 0.3 {}", 0.7 - 1.0 / 3.0));
    let ring = |r: usize, s: usize| 2 + (r - 1) * segments + s % segments;
    let mut f = Vec::new();
    for s in 0..segments {
        f.push(format!("f 1 {} {}", ring(1, s), ring(1, s + 1)));
        for r in 1..rings - 1 {
            let (a, b, c, d) = (ring(r, s), ring(r + 1, s), ring(r + 1, s + 1), ring(r, s + 1));
            f.push(format!("f {a} {b} {c}"));
            f.push(format!("f {a} {c} {d}"));
        }
        let last = v.len();
        f.push(format!("f {last} {} {}", ring(rings - 1, s + 1), ring(rings - 1, s)));
    }
    std::fs::write(path, format!("{}\n{}\n", v.join("\n"), f.join("\n"))).unwrap();
    (v, f)
}

fn unwrap(input: &Path, out: &Path, extra: &[&str]) -> std::process::Output {
    let mut cmd = nuvo();
    cmd.arg("unwrap").arg(input).arg("-o").arg(out);
    for s in FAST_UNWRAP {
        cmd.args(["--set", s]);
    }
    run(cmd.args(extra))
}

fn numbers(line: &str) -> Vec<f32> {
    line.split_whitespace().skip(1).map(|w| w.split('/').next().unwrap().parse().unwrap()).collect()
}

#[test]
fn a_new_mesh_unwraps_with_no_config_and_keeps_its_vertices_and_faces() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("ellipsoid.obj");
    let (v, f) = write_ellipsoid(&input);
    let out = dir.path().join("run");
    let o = unwrap(&input, &out, &[]);
    assert!(o.status.success());
    let stdout = String::from_utf8_lossy(&o.stdout);
    for said in ["sampling: uniform", "charts: ", "share of the surface", "reproduces it with `nuvo train"] {
        assert!(stdout.contains(said), "`{said}` missing from:\n{stdout}");
    }
    for file in ["atlas.obj", "atlas.glb", "vertex_map.json", "metrics.json", "config.toml", "unwrap.json"] {
        assert!(out.join(file).is_file(), "{file} missing");
    }
    // The OBJ: the input's vertices bit for bit, in order; its faces in order; a UV per corner.
    let obj = std::fs::read_to_string(out.join("atlas.obj")).unwrap();
    let out_v: Vec<&str> = obj.lines().filter(|l| l.starts_with("v ")).collect();
    let out_f: Vec<&str> = obj.lines().filter(|l| l.starts_with("f ")).collect();
    assert_eq!(out_v.len(), v.len());
    for (a, b) in out_v.iter().zip(&v) {
        assert_eq!(numbers(a), numbers(b), "vertex moved");
    }
    assert_eq!(out_f.len(), f.len());
    for (a, b) in out_f.iter().zip(&f) {
        assert_eq!(numbers(a), numbers(b), "face changed or reordered");
        assert!(a.split_whitespace().skip(1).all(|c| c.contains('/')), "no UV on {a}");
    }
    // The vertex map names, for every GLB vertex, the input vertex at the same place.
    let map: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("vertex_map.json")).unwrap()).unwrap();
    let map: Vec<usize> =
        map["glb_to_input"].as_array().unwrap().iter().map(|x| x.as_u64().unwrap() as usize).collect();
    let glb = nuvo_geometry::load_mesh(&out.join("atlas.glb")).unwrap();
    assert!(map.len() >= v.len());
    for t in &glb.triangles {
        for &k in t {
            let want = numbers(&v[map[k as usize]]);
            let got = glb.positions[k as usize];
            for c in 0..3 {
                assert!(
                    (got[c] - want[c]).abs() < 1e-6,
                    "GLB vertex {k} is not input vertex {}",
                    map[k as usize]
                );
            }
        }
    }
    // The layout is refined and packed island by island, and the counts are of what was written.
    let metrics: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("metrics.json")).unwrap()).unwrap();
    assert_eq!(metrics["layout"]["packing"], "islands");
    let refine = &metrics["layout"]["refine"];
    assert!(refine["flipped_after"].as_u64().unwrap() <= refine["flipped_before"].as_u64().unwrap());
    assert_eq!(metrics["layout"]["islands"], metrics["metrics"]["partuv"]["charts"]);
    assert_eq!(metrics["metrics"]["partuv"]["uv_in_unit_square"], true);
    // unwrap.json has the decisions and the numbers behind them.
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("unwrap.json")).unwrap()).unwrap();
    let decided: Vec<&str> =
        report["decisions"].as_array().unwrap().iter().map(|d| d["what"].as_str().unwrap()).collect();
    assert_eq!(decided, ["source", "sampling", "charts", "steps"]);
    assert_eq!(report["chart_trials"].as_array().unwrap().len(), 8);
    assert_eq!(report["profile"]["components"], 1);
}

#[test]
fn an_input_with_colour_gets_its_colour_baked_into_texture_png() {
    let dir = tempfile::tempdir().unwrap();
    let plain = dir.path().join("plain.obj");
    let (v, f) = write_ellipsoid(&plain);
    // The same ellipsoid with a vertex colour of its height.
    let coloured: Vec<String> = v
        .iter()
        .map(|l| {
            let z = numbers(l)[2];
            format!("{l} {} 0.2 {}", (z - 0.3).clamp(0.0, 1.0), (1.0 - z).clamp(0.0, 1.0))
        })
        .collect();
    let input = dir.path().join("coloured.obj");
    std::fs::write(&input, format!("{}\n{}\n", coloured.join("\n"), f.join("\n"))).unwrap();
    let out = dir.path().join("run");
    let o = unwrap(&input, &out, &["--charts", "2"]);
    assert!(o.status.success());
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(stdout.contains("texture: texture.png (the input has vertex colours"), "{stdout}");
    assert!(out.join("texture.png").is_file());
    let config = std::fs::read_to_string(out.join("config.toml")).unwrap();
    assert!(config.contains("texture = true"), "{config}");
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("unwrap.json")).unwrap()).unwrap();
    assert!(report["decisions"].as_array().unwrap().iter().any(|d| d["what"] == "texture"));
    // The same coloured mesh as a PLY (faces: a mesh, not a point cloud; `red green blue` bytes).
    let ply = dir.path().join("coloured.ply");
    let mut text = format!(
        "ply\nformat ascii 1.0\nelement vertex {}\nproperty float x\nproperty float y\nproperty float z\n\
         property uchar red\nproperty uchar green\nproperty uchar blue\nelement face {}\n\
         property list uchar int vertex_indices\nend_header\n",
        v.len(),
        f.len()
    );
    for l in &coloured {
        let n = numbers(l);
        let c: Vec<u8> = n[3..].iter().map(|x| (x * 255.0).round() as u8).collect();
        text += &format!("{} {} {} {} {} {}\n", n[0], n[1], n[2], c[0], c[1], c[2]);
    }
    for l in &f {
        let i: Vec<usize> = numbers(l).iter().map(|&x| x as usize - 1).collect();
        text += &format!("3 {} {} {}\n", i[0], i[1], i[2]);
    }
    std::fs::write(&ply, text).unwrap();
    let from_ply = dir.path().join("ply");
    let o = unwrap(&ply, &from_ply, &["--charts", "2"]);
    assert!(o.status.success());
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(stdout.contains("source: mesh") && stdout.contains("texture: texture.png"), "{stdout}");
    let obj = std::fs::read_to_string(from_ply.join("atlas.obj")).unwrap();
    assert_eq!(obj.lines().filter(|l| l.starts_with("v ")).count(), v.len());
    assert_eq!(obj.lines().filter(|l| l.starts_with("f ")).count(), f.len());
    // `--set output.texture=false` keeps the checkerboard.
    let off = dir.path().join("off");
    assert!(unwrap(&input, &off, &["--charts", "2", "--set", "output.texture=false"]).status.success());
    assert!(!off.join("texture.png").exists() && off.join("atlas.obj").is_file());
}

#[test]
fn config_toml_reproduces_the_run_exactly() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("ellipsoid.obj");
    write_ellipsoid(&input);
    let first = dir.path().join("first");
    assert!(unwrap(&input, &first, &["--charts", "3"]).status.success());
    let second = dir.path().join("second");
    let o = run(nuvo().arg("train").arg(first.join("config.toml")).arg("--out").arg(&second));
    assert!(o.status.success());
    for file in ["checkpoint.safetensors", "atlas.obj", "metrics.json"] {
        let (a, b) = (std::fs::read(first.join(file)).unwrap(), std::fs::read(second.join(file)).unwrap());
        assert!(a == b, "{file} differs between `nuvo unwrap` and `nuvo train` of its config.toml");
    }
}

#[test]
fn a_gltf_scene_comes_back_with_its_nodes_and_materials_and_new_uvs() {
    let dir = tempfile::tempdir().unwrap();
    let obj = dir.path().join("ellipsoid.obj");
    write_ellipsoid(&obj);
    // A GLB with a node, a textured material and normals: the atlas.glb of a first unwrap.
    let first = dir.path().join("first");
    assert!(unwrap(&obj, &first, &["--charts", "2"]).status.success());
    let input = dir.path().join("scene_in.glb");
    std::fs::copy(first.join("atlas.glb"), &input).unwrap();
    let out = dir.path().join("second");
    let o = unwrap(&input, &out, &["--charts", "3", "--set", "output.atlas_resolution=1024"]);
    assert!(o.status.success());
    let scene = out.join("scene.glb");
    assert!(scene.is_file() && out.join("scene_vertex_map.json").is_file());
    let (before, after) =
        (nuvo_geometry::load_mesh(&input).unwrap(), nuvo_geometry::load_mesh(&scene).unwrap());
    assert_eq!(before.triangles.len(), after.triangles.len());
    for f in 0..before.triangles.len() {
        assert_eq!(before.corners(f), after.corners(f), "face {f} moved");
    }
    let new_uv = after.uv.as_ref().expect("TEXCOORD_0 written");
    let baked = nuvo_geometry::load_mesh(&out.join("atlas.obj")).unwrap();
    let baked_uv = baked.uv.unwrap();
    for f in 0..after.triangles.len() {
        for k in 0..3 {
            let (a, b) = (
                new_uv.coords[new_uv.triangles[f][k] as usize],
                baked_uv.coords[baked_uv.triangles[f][k] as usize],
            );
            assert!(
                (a[0] - b[0]).abs() < 1e-6 && (a[1] - b[1]).abs() < 1e-6,
                "face {f} corner {k}: {a:?} vs {b:?}"
            );
        }
    }
    let json = |p: &Path| gltf::Gltf::open(p).unwrap().document.into_json();
    let (a, b) = (json(&input), json(&scene));
    assert_eq!(a.nodes.len(), b.nodes.len());
    // The input's texture (the first run's checkerboard) was baked through the new UVs, and the
    // scene shows it: a copy of its material with the baked image, the original kept.
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(stdout.contains("texture: texture.png"), "{stdout}");
    assert_eq!((a.materials.len() + 1, a.images.len() + 1), (b.materials.len(), b.images.len()));
    let colours = |p: &Path| match nuvo_geometry::appearance::load_colours(p).unwrap().colours {
        Some(nuvo_geometry::appearance::Colours::Surface(s)) => s,
        other => panic!("{}: {other:?}", p.display()),
    };
    let (was, now, atlas) = (colours(&input), colours(&scene), colours(&out.join("atlas.obj")));
    // The two files' UVs agree to 1e-6 (checked above, the OBJ's text rounds them), and a bilinear
    // lookup of a 1024² texture of colours in [0, 1] moves by at most 1024 per unit of UV along
    // each axis: so the same texture read through them agrees to 2 · 1024 · 1e-6 ≈ 2e-3 (where a
    // face centre sits on a checker edge; 1e-5 held only where it does not).
    let tolerance = 2.0 * 1024.0 * 1e-6 + 1e-5;
    let mut error = 0.0;
    for f in 0..was.mesh.triangles.len() {
        let centre = [1.0 / 3.0; 3];
        let (n, a) = (now.colour(f, centre), atlas.colour(f, centre));
        for k in 0..3 {
            assert!((n[k] - a[k]).abs() < tolerance, "face {f}: scene.glb shows {n:?}, atlas.obj {a:?}");
            error += (n[k] - was.colour(f, centre)[k]).abs() as f64;
        }
    }
    let mean = error / (3 * was.mesh.triangles.len()) as f64;
    eprintln!("scene.glb against the input's appearance: mean error {mean:.4} at face centres");
    assert!(mean < 0.02, "scene.glb's colours differ from the input's by {mean:.4} on average");
}

fn refused(input: &Path, out: &Path) -> String {
    let o = nuvo().arg("unwrap").arg(input).arg("-o").arg(out).output().unwrap();
    assert_eq!(o.status.code(), Some(1), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(
        !out.exists() || std::fs::read_dir(out).unwrap().next().is_none(),
        "wrote into {}",
        out.display()
    );
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    assert_eq!(err.lines().count(), 1, "one line: {err}");
    err
}

#[test]
fn bad_inputs_get_one_clear_error_and_nothing_is_written() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let path = |name: &str, text: &str| -> PathBuf {
        let p = dir.path().join(name);
        std::fs::write(&p, text).unwrap();
        p
    };
    let e = refused(&path("shape.stl", "solid x"), &out);
    assert!(e.contains("shape.stl") && e.contains("unsupported input type `.stl`"), "{e}");
    let e = refused(&path("empty.obj", ""), &out);
    assert!(e.contains("empty.obj") && e.contains("empty"), "{e}");
    let e = refused(&path("nan.obj", "v 0 0 0\nv 1 0 0\nv 0 nan 0\nf 1 2 3\n"), &out);
    assert!(e.contains("nan.obj"), "{e}");
    let e = refused(&dir.path().join("missing.glb"), &out);
    assert!(e.contains("missing.glb"), "{e}");
    let e = refused(&path("flat.obj", "v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n"), &out);
    assert!(e.contains("flat.obj") && e.contains("zero area"), "{e}");
    let input = dir.path().join("ok.obj");
    write_ellipsoid(&input);
    let o = nuvo().arg("unwrap").arg(&input).args(["--charts", "zero"]).output().unwrap();
    assert_eq!(o.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&o.stderr).contains("--charts zero"));
}

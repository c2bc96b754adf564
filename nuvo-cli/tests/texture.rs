//! Appearance transfer end to end (issue 22): a textured or vertex-coloured input trained and baked
//! with `output.texture` keeps its colours in the new atlas's `texture.png`, measured at random
//! surface points against the input; `nuvo bake --texture-from` bakes another file's colours;
//! images that cannot be read are warnings and the atlas is still written.

mod common;

use std::path::{Path, PathBuf};

use common::{SMALLEST_MODEL, nuvo, run};
use nuvo_atlas::pictures::{RgbImage, write_png};
use nuvo_atlas::uvstats::uv_charts;
use nuvo_geometry::appearance::{ColourImage, Colours, SurfaceColours, load_colours};
use nuvo_geometry::sampling::uniform::AreaSampler;
use nuvo_geometry::testdata::data_file;
use rand::{Rng, SeedableRng};

/// A quick run on `mesh` whose outputs carry its colour: the layout `nuvo unwrap` writes (refined,
/// injective islands packed at one texel density) at `resolution`².
fn textured_config(dir: &Path, mesh: &Path, resolution: u32, steps: u64) -> PathBuf {
    let text = format!(
        r#"seed = 5
[geometry]
source = "mesh"
path = {mesh:?}
{SMALLEST_MODEL}
[training]
steps = {steps}
batch_3d = 512
batch_uv = 512
[warm_start]
steps = {steps}
[output]
dir = "unused"
atlas_resolution = {resolution}
refine = true
injective = true
packing = "islands"
texture = true
eval_views = 2
eval_resolution = 96
renders = 1
render_resolution = 96
"#
    );
    let p = dir.join("textured.toml");
    std::fs::write(&p, text).unwrap();
    p
}

fn surface(path: &Path) -> SurfaceColours {
    let loaded = load_colours(path).unwrap();
    assert!(loaded.warnings.is_empty(), "{:?}", loaded.warnings);
    match loaded.colours {
        Some(Colours::Surface(s)) => s,
        other => panic!("{} has no surface colours: {other:?}", path.display()),
    }
}

/// How closely the new atlas's colours follow the input's at `n` area-uniform random surface
/// points (faces correspond one to one: `atlas.obj` keeps the input's faces in order).
struct RoundTrip {
    /// PSNR over all points, dB (colours in `[0, 1]`).
    psnr: f64,
    /// PSNR over points within `seam_texels` texels (in the new atlas) of their island's edge.
    psnr_near_seams: f64,
    /// PSNR over the other points.
    psnr_inside: f64,
    /// Share of points near seams.
    near_seams: f64,
    /// PSNR over points on small islands (under 1% of the surface each), and their share.
    psnr_small_islands: f64,
    small_islands: f64,
}

fn round_trip(input: &SurfaceColours, output: &SurfaceColours, n: usize, resolution: f64) -> RoundTrip {
    let mesh = &input.mesh;
    assert_eq!(mesh.triangles.len(), output.mesh.triangles.len());
    let sampler = AreaSampler::new(mesh).unwrap();
    let uv = output.mesh.uv.as_ref().expect("atlas.obj has UVs");
    let seam = seam_distance(&output.mesh, resolution);
    let (island, islands) = uv_charts(&output.mesh, uv);
    let mut island_area = vec![0.0; islands];
    for (f, &i) in island.iter().enumerate() {
        island_area[i as usize] += mesh.face_area(f) as f64 / sampler.total_area();
    }
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
    let (mut all, mut near, mut inside) = ((0.0, 0usize), (0.0, 0usize), (0.0, 0usize));
    let mut small = (0.0, 0usize);
    for _ in 0..n {
        let f = sampler.face(rng.random());
        let (a, b): (f32, f32) = (rng.random(), rng.random());
        let (a, b) = if a + b > 1.0 { (1.0 - a, 1.0 - b) } else { (a, b) };
        let bary = [1.0 - a - b, a, b];
        let (want, got) = (input.colour(f, bary), output.colour(f, bary));
        let se: f64 = (0..3).map(|k| (want[k] as f64 - got[k] as f64).powi(2)).sum::<f64>() / 3.0;
        all = (all.0 + se, all.1 + 1);
        if island_area[island[f] as usize] < 0.01 {
            small = (small.0 + se, small.1 + 1);
        }
        // Texel-space distance of the point to its face's nearest island edge, where it has one.
        let t = uv.triangles[f].map(|i| uv.coords[i as usize]);
        let p = [0, 1].map(|k| (0..3).map(|c| bary[c] * t[c][k]).sum::<f32>() as f64 * resolution);
        if seam(f, p) <= 2.0 {
            near = (near.0 + se, near.1 + 1);
        } else {
            inside = (inside.0 + se, inside.1 + 1);
        }
    }
    let psnr = |(sum, count): (f64, usize)| 10.0 * (count.max(1) as f64 / sum.max(1e-12)).log10();
    RoundTrip {
        psnr: psnr(all),
        psnr_near_seams: psnr(near),
        psnr_inside: psnr(inside),
        near_seams: near.1 as f64 / n as f64,
        psnr_small_islands: psnr(small),
        small_islands: small.1 as f64 / n as f64,
    }
}

/// For a face and a texel-space point on it, the distance (texels) to the nearest edge of that
/// face which lies on its island's boundary (infinite when the face has none).
fn seam_distance(mesh: &nuvo_geometry::TriMesh, resolution: f64) -> impl Fn(usize, [f64; 2]) -> f64 + '_ {
    let uv = mesh.uv.as_ref().unwrap();
    let mut uses = std::collections::HashMap::new();
    for t in &uv.triangles {
        for k in 0..3 {
            let (a, b) = (t[k].min(t[(k + 1) % 3]), t[k].max(t[(k + 1) % 3]));
            *uses.entry((a, b)).or_insert(0) += 1;
        }
    }
    move |f, p| {
        let t = uv.triangles[f];
        (0..3)
            .filter(|&k| uses[&(t[k].min(t[(k + 1) % 3]), t[k].max(t[(k + 1) % 3]))] == 1)
            .map(|k| {
                let [a, b] =
                    [t[k], t[(k + 1) % 3]].map(|i| uv.coords[i as usize].map(|c| c as f64 * resolution));
                let ab = [b[0] - a[0], b[1] - a[1]];
                let len2 = (ab[0] * ab[0] + ab[1] * ab[1]).max(1e-18);
                let s = (((p[0] - a[0]) * ab[0] + (p[1] - a[1]) * ab[1]) / len2).clamp(0.0, 1.0);
                ((p[0] - a[0] - s * ab[0]).powi(2) + (p[1] - a[1] - s * ab[1]).powi(2)).sqrt()
            })
            .fold(f64::INFINITY, f64::min)
    }
}

/// `s` with every texture replaced by its mip level `level` (box-filtered, as a GPU's mip chain).
fn at_mip_level(mut s: SurfaceColours, level: u32) -> SurfaceColours {
    for m in &mut s.materials {
        let Some(t) = &m.texture else { continue };
        let raw = t.pixels.iter().flatten().copied().collect();
        let mip = nuvo_atlas::texture::mip_level(&RgbImage::from_raw(t.width, t.height, raw).unwrap(), level);
        let pixels = mip.pixels().map(|p| p.0).collect();
        let image = ColourImage {
            origin: format!("{} mip {level}", t.origin),
            width: mip.width(),
            height: mip.height(),
            pixels,
        };
        m.texture = Some(std::sync::Arc::new(image));
    }
    s
}

fn report(what: &str, rt: &RoundTrip) {
    eprintln!(
        "{what}: PSNR {:.2} dB; within 2 texels of a seam {:.2} dB ({:.1}% of points), elsewhere {:.2} dB; \
         on islands under 1% of the surface {:.2} dB ({:.1}% of points)",
        rt.psnr,
        rt.psnr_near_seams,
        100.0 * rt.near_seams,
        rt.psnr_inside,
        rt.psnr_small_islands,
        100.0 * rt.small_islands
    );
}

/// A 1024² texture of stripes and rings with periods of 12–40 texels in every channel.
fn high_frequency_texture() -> RgbImage {
    use std::f32::consts::TAU;
    let side = 1024u32;
    let raw = (0..side * side)
        .flat_map(|i| {
            let (x, y) = ((i % side) as f32, (i / side) as f32);
            let r = 0.5 + 0.45 * (TAU * x / 16.0).sin() * (TAU * y / 40.0).cos();
            let g = 0.5 + 0.45 * (TAU * (x + y) / 24.0).sin();
            let d = ((x - 512.0).powi(2) + (y - 300.0).powi(2)).sqrt();
            let b = 0.5 + 0.45 * (TAU * d / 12.0).cos();
            [r, g, b].map(|c| (c * 255.0).round() as u8)
        })
        .collect();
    RgbImage::from_raw(side, side, raw).unwrap()
}

/// `spot.obj` (its own UVs) with `texture.png` through them, written into `dir`.
fn textured_spot(dir: &Path) -> PathBuf {
    let text = std::fs::read_to_string(data_file("meshes/spot.obj")).unwrap();
    let obj = dir.join("spot_textured.obj");
    std::fs::write(&obj, format!("mtllib spot_textured.mtl\nusemtl painted\n{text}")).unwrap();
    std::fs::write(dir.join("spot_textured.mtl"), "newmtl painted\nKd 1 1 1\nmap_Kd painted.png\n").unwrap();
    write_png(&dir.join("painted.png"), &high_frequency_texture()).unwrap();
    obj
}

#[test]
fn a_textured_mesh_keeps_its_appearance_through_the_new_atlas() {
    let dir = tempfile::tempdir().unwrap();
    let obj = textured_spot(dir.path());
    let cfg = textured_config(dir.path(), &obj, 2048, 60);
    let out = dir.path().join("run");
    let o = run(nuvo().arg("train").arg(&cfg).arg("--out").arg(&out));
    assert!(o.status.success());
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(stdout.contains("texture 2048²") && stdout.contains("same faces"), "{stdout}");
    let mtl = std::fs::read_to_string(out.join("atlas.mtl")).unwrap();
    assert!(mtl.contains("map_Kd texture.png"), "{mtl}");
    let metrics: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("metrics.json")).unwrap()).unwrap();
    assert_eq!(metrics["texture"]["lookup"], "same faces");
    // The GLB carries the same texture as its base colour.
    let (doc, _, images) = gltf::import(out.join("atlas.glb")).unwrap();
    let material = doc.materials().next().unwrap();
    assert!(material.pbr_metallic_roughness().base_color_texture().is_some());
    assert_eq!((images[0].width, images[0].height), (2048, 2048));

    let rt = round_trip(&surface(&obj), &surface(&out.join("atlas.obj")), 100_000, 2048.0);
    report("spot, texture through its own UVs -> new atlas at 2048²", &rt);
    assert!(rt.psnr >= 35.0, "PSNR {:.2} dB < 35", rt.psnr);
}

/// The bundled bunny with vertex colours of several frequencies, written as `v x y z r g b`.
fn coloured_bunny(dir: &Path) -> PathBuf {
    let mesh = nuvo_geometry::load_mesh(&common::repo().join("assets/stanford-bunny.obj")).unwrap();
    let b = mesh.bounds().unwrap();
    let mut text = String::new();
    for p in &mesh.positions {
        let q: [f32; 3] = std::array::from_fn(|k| (p[k] - b.min[k]) / (b.max[k] - b.min[k]).max(1e-9));
        let r = 0.5 + 0.45 * (20.0 * q[0]).sin();
        let g = 0.5 + 0.45 * (31.0 * q[1] + 7.0 * q[2]).cos();
        let bl = 0.5 + 0.45 * (13.0 * (q[0] + q[1] + q[2])).sin();
        text += &format!("v {} {} {} {r:.4} {g:.4} {bl:.4}\n", p[0], p[1], p[2]);
    }
    for t in &mesh.triangles {
        text += &format!("f {} {} {}\n", t[0] + 1, t[1] + 1, t[2] + 1);
    }
    let p = dir.join("coloured_bunny.obj");
    std::fs::write(&p, text).unwrap();
    p
}

#[test]
fn vertex_colours_carry_over_and_another_files_colours_bake_into_a_run() {
    let dir = tempfile::tempdir().unwrap();
    let obj = coloured_bunny(dir.path());
    let cfg = textured_config(dir.path(), &obj, 2048, 60);
    let out = dir.path().join("run");
    assert!(run(nuvo().arg("train").arg(&cfg).arg("--out").arg(&out)).status.success());
    let input = surface(&obj);
    let rt = round_trip(&input, &surface(&out.join("atlas.obj")), 100_000, 2048.0);
    report("bunny, vertex colours -> new atlas at 2048²", &rt);
    assert!(rt.psnr >= 35.0, "PSNR {:.2} dB < 35", rt.psnr);
    // Seen from afar, at mip level 2 (each texel the mean of 4×4), points by the seams still read
    // their own colours: no background bleeds in (the bunny's colours vary over ~20 texels).
    let baked = surface(&out.join("atlas.obj"));
    let rt = round_trip(&input, &at_mip_level(baked, 2), 100_000, 512.0);
    report("the same at mip level 2 (512²)", &rt);
    assert!(rt.psnr_near_seams >= 30.0, "PSNR by the seams at mip level 2: {:.2} dB", rt.psnr_near_seams);

    // The same run baked again from a coloured point cloud of the surface: colours by nearest points.
    let mut cloud = String::from("# x y z nx ny nz r g b\n");
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(2);
    for _ in 0..200_000 {
        let f = rng.random_range(0..input.mesh.triangles.len());
        let (a, b): (f32, f32) = (rng.random(), rng.random());
        let (a, b) = if a + b > 1.0 { (1.0 - a, 1.0 - b) } else { (a, b) };
        let bary = [1.0 - a - b, a, b];
        let c = input.mesh.corners(f);
        let p: [f32; 3] = std::array::from_fn(|k| (0..3).map(|i| bary[i] * c[i][k]).sum());
        let rgb = input.colour(f, bary).map(|x| (x * 255.0).round() as u8);
        cloud += &format!("{} {} {} 0 0 1 {} {} {}\n", p[0], p[1], p[2], rgb[0], rgb[1], rgb[2]);
    }
    let xyz = dir.path().join("cloud.xyz");
    std::fs::write(&xyz, cloud).unwrap();
    let again = dir.path().join("again");
    let o = run(nuvo().arg("bake").arg(&out).arg("--out").arg(&again).arg("--texture-from").arg(&xyz));
    assert!(o.status.success());
    let metrics: serde_json::Value =
        serde_json::from_slice(&std::fs::read(again.join("metrics.json")).unwrap()).unwrap();
    assert_eq!(metrics["texture"]["lookup"], "nearest points");
    assert!(metrics["texture"]["from"].as_str().unwrap().ends_with("cloud.xyz"));
    let rt = round_trip(&input, &surface(&again.join("atlas.obj")), 100_000, 2048.0);
    report("bunny, from a 200k-point coloured cloud", &rt);
    assert!(rt.psnr >= 30.0, "PSNR {:.2} dB < 30 from the point cloud", rt.psnr);
}

#[test]
fn an_unreadable_texture_is_a_warning_and_the_atlas_is_still_written() {
    let dir = tempfile::tempdir().unwrap();
    let obj = textured_spot(dir.path());
    std::fs::write(dir.path().join("painted.png"), b"not a png at all").unwrap();
    let cfg = textured_config(dir.path(), &obj, 256, 4);
    let out = dir.path().join("run");
    let o = run(nuvo().arg("train").arg(&cfg).arg("--out").arg(&out));
    assert!(o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("warning") && err.contains("painted.png"), "{err}");
    assert!(
        out.join("atlas.obj").is_file()
            && out.join("atlas.glb").is_file()
            && out.join("metrics.json").is_file()
    );
    assert!(!out.join("texture.png").exists());
    let mtl = std::fs::read_to_string(out.join("atlas.mtl")).unwrap();
    assert!(mtl.contains("map_Kd checker.png"), "{mtl}");
    // A missing --texture-from file is an error before anything is written.
    let o = run(nuvo()
        .arg("bake")
        .arg(&out)
        .arg("--out")
        .arg(dir.path().join("b"))
        .arg("--texture-from")
        .arg(dir.path().join("nope.obj")));
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("nope.obj"));
    assert!(!dir.path().join("b").exists());
}

//! The density source: samples on the surface of the shared NeRF-like grid, normals from the
//! gradient, determinism, and bad grids.

mod common;

use std::path::Path;

use common::*;
use nuvo_geometry::density::{DensityOptions, DensitySource};
use nuvo_geometry::npy::write_npy_bytes;
use nuvo_geometry::testdata::{MeshDistance, data_file};
use nuvo_geometry::{GeometrySource, Similarity, SourceRegistry};

fn build(dir: &Path, toml_text: &str) -> Result<Box<dyn GeometrySource>, String> {
    let table: toml::Table = toml::from_str(toml_text).unwrap();
    SourceRegistry::with_builtins().build("density", &table, &ctx(dir)).map_err(|e| e.to_string())
}

#[test]
fn density_samples_lie_within_a_voxel_of_the_extracted_mesh() {
    let npy = data_file("density/unruly_bunny.npy");
    let mesh = nuvo_geometry::load_mesh(&data_file("meshes/unruly_bunny.obj")).unwrap();
    let src = build(npy.parent().unwrap(), "path = 'unruly_bunny.npy'").unwrap();
    // Grid bounds [-1, 1]^3 are already canonical, like the mesh coordinates.
    assert_eq!(src.to_canonical(), Similarity::IDENTITY);
    let s = src.sample(20_000, 7);
    assert_eq!(s.len(), 20_000);
    assert_unit_normals(&s.normals);
    let oracle = MeshDistance::new(mesh.clone(), 1_000_000);
    let voxel = 2.0 / 223.0;
    let d: Vec<f32> = s.positions.iter().map(|p| oracle.distance(*p) / voxel).collect();
    let (p50, p80) = (quantile(&d, 0.5), quantile(&d, 0.8));
    assert!(
        p50 < 0.75 && p80 < 1.25,
        "distance to the mesh in voxels: median {p50:.2}, 80th percentile {p80:.2}"
    );
    // Normals (negative density gradient) agree with the mesh's outward normals at nearby points:
    // the marching-cubes winding of the shared meshes is outward.
    let mesh_src = source(
        mesh,
        nuvo_geometry::mesh_source::SamplingMode::Uniform,
        nuvo_geometry::sampling::NormalMode::Face,
    );
    let sim = mesh_src.to_canonical();
    let ms = mesh_src.sample(400_000, 1);
    let pts: Vec<[f32; 3]> = ms.positions.iter().map(|p| sim.invert(*p)).collect();
    let tree = kiddo::ImmutableKdTree::<f32, 3>::new_from_slice(&pts);
    let mut agree = 0;
    let mut close = 0;
    for (p, n) in s.positions.iter().zip(&s.normals) {
        let nn = tree.nearest_one::<kiddo::SquaredEuclidean>(p);
        if nn.distance.sqrt() < voxel {
            close += 1;
            if dot(*n, ms.normals[nn.item as usize]) > 0.5 {
                agree += 1;
            }
        }
    }
    assert!(agree as f64 > 0.8 * close as f64, "only {agree} of {close} normals agree with the mesh");
}

/// A float32 grid of a soft ball of radius 0.5 (density 50 inside, 0 outside, linear ramp over 0.1).
fn ball_grid(n: usize) -> Vec<u8> {
    let mut data = Vec::with_capacity(n * n * n * 4);
    for i in 0..n {
        for j in 0..n {
            for k in 0..n {
                let c = |i: usize| -1.0 + 2.0 * i as f32 / (n - 1) as f32;
                let r = norm([c(i), c(j), c(k)]);
                let v = 50.0 * ((0.55 - r) / 0.1).clamp(0.0, 1.0);
                data.extend_from_slice(&v.to_le_bytes());
            }
        }
    }
    write_npy_bytes(&[n, n, n], "<f4", &data, false)
}

#[test]
fn a_ball_gives_points_on_its_surface_with_outward_normals_in_any_bounds() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("ball.npy"), ball_grid(48)).unwrap();
    // Bounds in input coordinates: a box of side 4 centred at (10, 0, 0).
    let src = build(dir.path(), "path = 'ball.npy'\nbounds = [[8, -2, -2], [12, 2, 2]]").unwrap();
    assert_eq!(src.to_canonical(), Similarity { center: [10.0, 0.0, 0.0], scale: 0.5 });
    assert_eq!(src.bounds().min, [-1.0; 3]);
    let s = src.sample(5000, 3);
    assert_unit_normals(&s.normals);
    for (p, n) in s.positions.iter().zip(&s.normals) {
        let r = norm(*p);
        // Density is non-zero up to r = 0.55 plus one cell diagonal (0.074) of the 48^3 grid.
        assert!((0.40..0.63).contains(&r), "{p:?} is not near the ball's surface (r = {r})");
        assert!(dot(*p, *n) / r > 0.9, "normal {n:?} at {p:?} is not outward");
    }
    let radii: Vec<f32> = s.positions.iter().map(|p| norm(*p)).collect();
    let median = quantile(&radii, 0.5);
    assert!((0.45..0.56).contains(&median), "median radius {median}");
    let one = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap().install(|| src.sample(3000, 5));
    let three =
        rayon::ThreadPoolBuilder::new().num_threads(3).build().unwrap().install(|| src.sample(3000, 5));
    assert_eq!(one, three);
    assert_ne!(one, src.sample(3000, 6));
    assert_eq!(src.sample(1, 1).len(), 1);
}

#[test]
fn bad_grids_and_options_are_clear_errors() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let f32s = |v: &[f32]| v.iter().flat_map(|x| x.to_le_bytes()).collect::<Vec<u8>>();
    // 200 on the central 2^3 nodes, 0 around them: a surface for the default marching-cubes mesh.
    let blob: Vec<u8> = (0..64)
        .map(|i| if [i / 16, i / 4 % 4, i % 4].iter().all(|c| (1..3).contains(c)) { 200 } else { 0 })
        .collect();
    let good = write_npy_bytes(&[4, 4, 4], "|u1", &blob, false);
    let cases: Vec<(&str, Vec<u8>, &str)> = vec![
        ("empty.npy", vec![], "magic"),
        ("garbage.npy", b"hello, this is not numpy".to_vec(), "magic"),
        ("truncated.npy", good[..good.len() - 10].to_vec(), "holds 54 bytes"),
        ("two_d.npy", write_npy_bytes(&[8, 8], "|u1", &[1; 64], false), "3-D"),
        ("four_d.npy", write_npy_bytes(&[2, 2, 2, 2], "|u1", &[1; 16], false), "3-D"),
        ("flat.npy", write_npy_bytes(&[1, 8, 8], "|u1", &[1; 64], false), "at least 2 nodes"),
        ("int64.npy", write_npy_bytes(&[2, 2, 2], "<i8", &[0; 64], false), "unsupported dtype"),
        ("huge.npy", write_npy_bytes(&[100_000, 100_000, 100_000], "<f4", &[0; 64], false), "declares"),
        (
            "nan.npy",
            write_npy_bytes(&[2, 2, 2], "<f4", &f32s(&[0.0, 1.0, f32::NAN, 0.0, 0.0, 0.0, 0.0, 0.0]), false),
            "not finite",
        ),
        ("zeros.npy", write_npy_bytes(&[4, 4, 4], "|u1", &[0; 64], false), "meets any density"),
    ];
    for (name, bytes, needle) in cases {
        std::fs::write(d.join(name), bytes).unwrap();
        let e = build(d, &format!("path = '{name}'")).err().unwrap_or_else(|| panic!("{name} should fail"));
        assert!(e.contains(name) && e.contains(needle), "{name}: {e}");
    }
    std::fs::write(d.join("good.npy"), &good).unwrap();
    assert!(build(d, "path = 'good.npy'").is_ok());
    for (toml_text, needle) in [
        ("path = 'good.npy'\nbounds = [[1, 0, 0], [0, 1, 1]]", "bounds"),
        ("path = 'good.npy'\nscale = -1.0", "scale"),
        ("path = 'good.npy'\nstep_voxels = 0.0", "step_voxels"),
        ("path = 'good.npy'\nstepvoxels = 0.5", "unknown field `stepvoxels`"),
        ("path = 'good.npy'\ncameras = { radius = 1.0 }", "radius"),
        ("bounds = [[0, 0, 0], [1, 1, 1]]", "missing field `path`"),
        ("path = 'missing.npy'", "missing.npy"),
    ] {
        let e = build(d, toml_text).err().unwrap_or_else(|| panic!("{toml_text} should fail"));
        assert!(e.contains(needle), "{toml_text}: {e}");
    }
    // The options struct is public for programmatic use too.
    let opts = DensityOptions {
        path: "good.npy".into(),
        bounds: [[-1.0; 3], [1.0; 3]],
        scale: None,
        step_voxels: 0.5,
        rays_per_sample: 1.0,
        min_density: None,
        cameras: None,
        mesh_level: None,
        extract_mesh: true,
    };
    assert!(DensitySource::new(&opts, &ctx(d)).is_ok());
}

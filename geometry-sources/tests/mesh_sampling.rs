//! Uniform and visible sampling of meshes: distribution, surface, normals, determinism.

mod common;

use common::*;
use nuvo_geometry::camera::CameraOptions;
use nuvo_geometry::mesh_source::{MeshOptions, MeshSource, SamplingMode};
use nuvo_geometry::sampling::NormalMode;
use nuvo_geometry::{GeometrySource, Similarity};

/// Which cube face (0..6: +x, -x, +y, -y, +z, -z) a point lies on, if any (the axis of its largest
/// coordinate, which must be ±1).
fn cube_face(p: [f32; 3]) -> Option<usize> {
    let k = (0..3).fold(0, |a, k| if p[k].abs() > p[a].abs() { k } else { a });
    ((p[k].abs() - 1.0).abs() < 1e-5).then_some(2 * k + usize::from(p[k] < 0.0))
}

#[test]
fn uniform_samples_on_a_cube_are_uniform_by_area_and_on_the_surface() {
    // The +z face has 2 * 40 * 40 = 3200 of the 3210 triangles: sampling triangles uniformly would
    // put ~99.7% of the points there instead of 1/6.
    let src = source(cube(-1.0, 1.0, 40), SamplingMode::Uniform, NormalMode::Face);
    assert_eq!(src.to_canonical(), Similarity::IDENTITY);
    let n = 60_000;
    let s = src.sample(n, 11);
    assert_eq!(s.len(), n);
    assert_unit_normals(&s.normals);
    let mut counts = [0usize; 6];
    for (p, nrm) in s.positions.iter().zip(&s.normals) {
        let f = cube_face(*p).unwrap_or_else(|| panic!("{p:?} is not on the cube"));
        assert!(p.iter().all(|c| c.abs() <= 1.0 + 1e-5), "{p:?} outside the cube");
        counts[f] += 1;
        // Outward: the normal is the face's axis with the face's sign.
        let mut want = [0.0; 3];
        want[f / 2] = if f.is_multiple_of(2) { 1.0 } else { -1.0 };
        assert!(dot(*nrm, want) > 0.9999, "normal {nrm:?} at {p:?} is not outward");
    }
    // Each count is Binomial(n, 1/6): sd ≈ 91; allow 5 sd.
    let expected = n as f64 / 6.0;
    let sd = (n as f64 * (1.0 / 6.0) * (5.0 / 6.0)).sqrt();
    for (f, &c) in counts.iter().enumerate() {
        assert!((c as f64 - expected).abs() < 5.0 * sd, "face {f}: {c} samples, expected {expected:.0}");
    }
}

#[test]
fn uniform_samples_on_a_sphere_are_uniform_by_area_with_outward_normals() {
    // Archimedes: for uniform points on a sphere, z is uniform on [-1, 1]. The UV sphere's tiny
    // polar triangles would make per-triangle sampling pile up near |z| = 1.
    let src = source(uv_sphere(64, 128), SamplingMode::Uniform, NormalMode::Vertex);
    let n = 50_000;
    let s = src.sample(n, 5);
    assert_unit_normals(&s.normals);
    let mut bins = [0usize; 10];
    for (p, nrm) in s.positions.iter().zip(&s.normals) {
        let r = norm(*p);
        assert!((0.998..=1.0 + 1e-5).contains(&r), "{p:?} is not on the sphere (r = {r})");
        assert!(dot(*p, *nrm) / r > 0.999, "normal {nrm:?} at {p:?} is not outward");
        bins[(((p[2] + 1.0) * 5.0) as usize).min(9)] += 1;
    }
    let expected = n as f64 / 10.0;
    let sd = (n as f64 * 0.1 * 0.9).sqrt();
    for (i, &c) in bins.iter().enumerate() {
        assert!((c as f64 - expected).abs() < 5.0 * sd, "z-bin {i}: {c} samples, expected {expected:.0}");
    }
    // Face normals are outward too, and less exactly radial.
    let s = source(uv_sphere(64, 128), SamplingMode::Uniform, NormalMode::Face).sample(2000, 1);
    assert!(s.positions.iter().zip(&s.normals).all(|(p, n)| dot(*p, *n) / norm(*p) > 0.99));
}

#[test]
fn sampling_is_deterministic_in_seed_and_independent_of_threads() {
    let mesh = uv_sphere(16, 32);
    for mode in [SamplingMode::Uniform, SamplingMode::Visible] {
        let src = source(mesh.clone(), mode, NormalMode::Face);
        let one =
            rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap().install(|| src.sample(3000, 42));
        let two =
            rayon::ThreadPoolBuilder::new().num_threads(3).build().unwrap().install(|| src.sample(3000, 42));
        assert_eq!(one, two, "{mode:?}");
        assert_ne!(one, src.sample(3000, 43), "{mode:?}");
        assert_eq!(src.sample(0, 1).len(), 0);
    }
}

/// A unit box with a smaller box hidden inside it; some outer faces wound inside-out (NeRF meshes'
/// winding cannot be trusted).
fn box_in_box() -> nuvo_geometry::TriMesh {
    let mut m = cube(-1.0, 1.0, 4);
    for t in m.triangles.iter_mut().step_by(3) {
        t.swap(1, 2);
    }
    append(&mut m, &cube(-0.3, 0.3, 4));
    m
}

#[test]
fn visible_samples_of_a_box_never_see_the_hidden_inner_box() {
    let src = source(box_in_box(), SamplingMode::Visible, NormalMode::Face);
    let s = src.sample(20_000, 3);
    assert_eq!(s.len(), 20_000);
    assert_unit_normals(&s.normals);
    let mut faces = [0usize; 6];
    for (p, n) in s.positions.iter().zip(&s.normals) {
        let inf = p.iter().fold(0.0f32, |a, c| a.max(c.abs()));
        assert!(inf > 0.999, "{p:?} is on the hidden inner box");
        faces[cube_face(*p).expect("on the outer box")] += 1;
        // Facing the camera, which is outside: outward, whatever the winding.
        assert!(dot(*p, *n) > 0.0, "normal {n:?} at {p:?} faces away from the cameras");
    }
    assert!(faces.iter().all(|&c| c > 2000), "cameras do not see every side: {faces:?}");
    // Control: uniform sampling of the same mesh does reach the inner box, so the check above can fail.
    let u = source(box_in_box(), SamplingMode::Uniform, NormalMode::Face).sample(20_000, 3);
    assert!(u.positions.iter().any(|p| p.iter().all(|c| c.abs() < 0.31)));
}

#[test]
fn visible_sampling_from_a_camera_file_in_input_coordinates() {
    let dir = tempfile::tempdir().unwrap();
    // The cube in input coordinates: centre (10, 0, 0), half-size 5. One camera in front of +z.
    let mut mesh = cube(-1.0, 1.0, 1);
    for p in &mut mesh.positions {
        *p = [10.0 + 5.0 * p[0], 5.0 * p[1], 5.0 * p[2]];
    }
    let cams = dir.path().join("cams.json");
    std::fs::write(
        &cams,
        r#"{"cameras": [{"position": [10, 0, 20], "look_at": [10, 0, 0], "fov_degrees": 20}]}"#,
    )
    .unwrap();
    let opts = MeshOptions {
        cameras: Some(CameraOptions { file: Some("cams.json".into()), ..Default::default() }),
        ..options(SamplingMode::Visible, NormalMode::Face)
    };
    let src = MeshSource::from_mesh("cube".into(), mesh.clone(), &opts, &ctx(dir.path())).unwrap();
    assert_eq!(src.to_canonical(), Similarity { center: [10.0, 0.0, 0.0], scale: 0.2 });
    let s = src.sample(2000, 9);
    for (p, n) in s.positions.iter().zip(&s.normals) {
        assert!((p[2] - 1.0).abs() < 1e-5, "{p:?} is not on the face the camera looks at");
        assert!(n[2] > 0.9999);
    }
    // A camera looking away from the object: a clear construction error, not an endless loop.
    std::fs::write(&cams, r#"[{"position": [10, 0, 20], "look_at": [10, 0, 40]}]"#).unwrap();
    let e = MeshSource::from_mesh("cube".into(), mesh, &opts, &ctx(dir.path())).err().unwrap().to_string();
    assert!(e.contains("hit the mesh"), "{e}");
}

#[test]
fn meshes_with_only_degenerate_faces_cannot_be_sampled_but_some_degenerate_faces_are_fine() {
    let mut m = cube(-1.0, 1.0, 2);
    m.triangles.push([0, 0, 1]);
    m.triangles.push([2, 2, 2]);
    for mode in [SamplingMode::Uniform, SamplingMode::Visible] {
        let s = source(m.clone(), mode, NormalMode::Vertex).sample(1000, 1);
        assert!(s.positions.iter().all(|p| cube_face(*p).is_some()));
        assert_unit_normals(&s.normals);
    }
    let only = nuvo_geometry::TriMesh {
        positions: vec![[0.0; 3], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]],
        triangles: vec![[0, 1, 2], [0, 0, 1]],
        uv: None,
    };
    let e = MeshSource::from_mesh(
        "flat.obj".into(),
        only,
        &options(SamplingMode::Uniform, NormalMode::Face),
        &ctx(".".as_ref()),
    )
    .err()
    .unwrap()
    .to_string();
    assert!(e.contains("flat.obj") && e.contains("degenerate"), "{e}");
}

#[test]
fn the_canonical_frame_maps_the_input_into_the_unit_cube() {
    let mut mesh = uv_sphere(8, 16);
    for p in &mut mesh.positions {
        *p = [3.0 * p[0] + 100.0, 3.0 * p[1], 3.0 * p[2] - 7.0];
    }
    let src = source(mesh.clone(), SamplingMode::Uniform, NormalMode::Face);
    let b = src.bounds();
    for k in 0..3 {
        assert!(b.min[k] >= -1.0 - 1e-5 && b.max[k] <= 1.0 + 1e-5);
    }
    let sim = src.to_canonical();
    let back = sim.invert(src.mesh().unwrap().positions[5]);
    assert!(back.iter().zip(&mesh.positions[5]).all(|(a, b)| (a - b).abs() < 1e-3));
}

//! The density source's own mesh (marching cubes at `mesh_level`): it matches the reference mesh of
//! the shared grid, is closed and outward on a synthetic ball, lives in the samples' canonical frame,
//! and its options fail clearly.

mod common;

use std::collections::HashMap;
use std::path::Path;

use common::*;
use nuvo_geometry::npy::write_npy_bytes;
use nuvo_geometry::testdata::{MeshDistance, data_file};
use nuvo_geometry::{GeometrySource, Similarity, SourceRegistry, TriMesh};

fn build(dir: &Path, toml_text: &str) -> Result<Box<dyn GeometrySource>, String> {
    let table: toml::Table = toml::from_str(toml_text).unwrap();
    SourceRegistry::with_builtins().build("density", &table, &ctx(dir)).map_err(|e| e.to_string())
}

fn has_distinct_corners(t: &[u32; 3]) -> bool {
    t[0] != t[1] && t[1] != t[2] && t[0] != t[2]
}

fn total_area(m: &TriMesh) -> f64 {
    (0..m.triangles.len()).map(|f| f64::from(m.face_area(f))).sum()
}

/// The signed volume enclosed (positive for outward winding).
fn signed_volume(m: &TriMesh) -> f64 {
    let det = |[a, b, c]: [[f32; 3]; 3]| {
        let (a, b, c) = (a.map(f64::from), b.map(f64::from), c.map(f64::from));
        a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0])
            + a[2] * (b[0] * c[1] - b[1] * c[0])
    };
    (0..m.triangles.len()).map(|f| det(m.corners(f))).sum::<f64>() / 6.0
}

/// `(open, non-manifold)` directed-edge counts: an edge of a closed, consistently wound mesh is used
/// exactly once in each direction.
fn edge_defects(m: &TriMesh) -> (usize, usize) {
    let mut uses: HashMap<(u32, u32), usize> = HashMap::new();
    for t in &m.triangles {
        for k in 0..3 {
            *uses.entry((t[k], t[(k + 1) % 3])).or_default() += 1;
        }
    }
    let open = uses.keys().filter(|&&(a, b)| !uses.contains_key(&(b, a))).count();
    let repeated = uses.values().filter(|&&n| n > 1).count();
    (open, repeated)
}

fn centroid(m: &TriMesh, f: usize) -> [f32; 3] {
    let [a, b, c] = m.corners(f);
    std::array::from_fn(|k| (a[k] + b[k] + c[k]) / 3.0)
}

#[test]
fn the_bunny_grids_mesh_matches_the_reference_marching_cubes_mesh() {
    let npy = data_file("density/unruly_bunny.npy");
    // The reference: scikit-image's marching cubes at level 12, welded; its coordinates are the
    // grid's bounds [-1, 1]^3, which are also the canonical frame.
    let reference = nuvo_geometry::load_mesh(&data_file("meshes/unruly_bunny.obj")).unwrap();
    let src = build(npy.parent().unwrap(), "path = 'unruly_bunny.npy'").unwrap();
    assert_eq!(src.to_canonical(), Similarity::IDENTITY);
    assert!(src.describe().contains("level 12"), "{}", src.describe());
    let mesh = src.mesh().expect("the density source has a mesh");
    mesh.validate().unwrap();
    assert!(mesh.triangles.iter().all(has_distinct_corners), "collapsed triangles kept");
    let voxel = 2.0 / 223.0;

    // Like with like: the reference keeps the triangles that welding collapsed; we drop them.
    let reference_faces = reference.triangles.iter().filter(|t| has_distinct_corners(t)).count();
    let ratio = mesh.triangles.len() as f64 / reference_faces as f64;
    assert!(
        (ratio - 1.0).abs() < 0.02,
        "{} faces vs the reference's {reference_faces}",
        mesh.triangles.len()
    );
    let (ours, theirs) = (mesh.bounds().unwrap(), reference.bounds().unwrap());
    for k in 0..3 {
        assert!((ours.min[k] - theirs.min[k]).abs() <= voxel && (ours.max[k] - theirs.max[k]).abs() <= voxel);
        assert!(ours.min[k] >= -1.0 && ours.max[k] <= 1.0, "the mesh leaves the grid's box: {ours:?}");
    }
    let area = (total_area(mesh), total_area(&reference));
    assert!((area.0 / area.1 - 1.0).abs() < 0.02, "area {area:?}");
    let volume = (signed_volume(mesh), signed_volume(&reference));
    assert!(volume.0 > 0.0 && (volume.0 / volume.1 - 1.0).abs() < 0.01, "signed volume {volume:?}");

    // Vertex by vertex, both ways: ours lie on the reference surface and the reference's on ours.
    for (a, b, what) in
        [(mesh, &reference, "ours to the reference"), (&reference, mesh, "the reference to ours")]
    {
        let oracle = MeshDistance::new(b.clone(), 1_000_000);
        let d: Vec<f32> = a.positions.iter().step_by(11).map(|p| oracle.distance(*p) / voxel).collect();
        let (p90, p99) = (quantile(&d, 0.9), quantile(&d, 0.99));
        assert!(p90 < 0.1 && p99 < 0.5, "vertex distance {what} in voxels: 90th pct {p90}, 99th {p99}");
    }

    // Outward: face normals point down the density gradient (the noisy grid allows a few exceptions).
    let grid = nuvo_geometry::density::DensitySource::new(
        &toml::from_str::<nuvo_geometry::density::DensityOptions>(&format!(
            "path = {:?}\nextract_mesh = false",
            npy.display().to_string()
        ))
        .unwrap(),
        &ctx(Path::new(".")),
    )
    .unwrap();
    let (mut down, mut measured) = (0, 0);
    for f in (0..mesh.triangles.len()).step_by(7) {
        let g = grid.grid().gradient(centroid(mesh, f));
        let n = mesh.face_normal_scaled(f);
        if norm(g) > 0.0 && norm(n) > 0.0 {
            measured += 1;
            down += usize::from(dot(g, n) < 0.0);
        }
    }
    assert!(down as f64 > 0.95 * measured as f64, "{down} of {measured} faces face down the gradient");
}

/// A float32 `n^3` grid of a soft ball of radius 0.5 (in node coordinates `[-1, 1]^3`): density
/// `50 * clamp((0.55 - r) / 0.1, 0, 1)`, so the level-25 surface is the sphere of radius 0.5.
fn ball_npy(n: usize) -> Vec<u8> {
    let c = |i: usize| -1.0 + 2.0 * i as f32 / (n - 1) as f32;
    let mut bytes = Vec::with_capacity(n * n * n * 4);
    for i in 0..n {
        for j in 0..n {
            for k in 0..n {
                let v = 50.0 * ((0.55 - norm([c(i), c(j), c(k)])) / 0.1).clamp(0.0, 1.0);
                bytes.extend_from_slice(&v.to_le_bytes());
            }
        }
    }
    write_npy_bytes(&[n, n, n], "<f4", &bytes, false)
}

#[test]
fn a_ball_gives_a_closed_outward_sphere_in_the_samples_frame() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("ball.npy"), ball_npy(64)).unwrap();
    // Input bounds a box of side 4 around (10, 0, 0): the canonical frame maps it onto [-1, 1]^3, so
    // the sphere of radius 0.5 about the origin is where both the mesh and the samples must be.
    let toml_text = "path = 'ball.npy'\nbounds = [[8, -2, -2], [12, 2, 2]]\nmesh_level = 25";
    let src = build(dir.path(), toml_text).unwrap();
    let mesh = src.mesh().expect("a mesh");
    mesh.validate().unwrap();
    assert_eq!(edge_defects(mesh), (0, 0), "the sphere is not closed and consistently wound");
    let voxel = 2.0 / 63.0;
    for p in &mesh.positions {
        assert!((norm(*p) - 0.5).abs() < 0.05 * voxel, "vertex {p:?} is off the sphere of radius 0.5");
    }
    let area = total_area(mesh);
    let sphere = 4.0 * std::f64::consts::PI * 0.25;
    assert!((area / sphere - 1.0).abs() < 0.01, "area {area}, sphere {sphere}");
    for f in 0..mesh.triangles.len() {
        assert!(dot(mesh.face_normal_scaled(f), centroid(mesh, f)) > 0.0, "face {f} points inwards");
    }
    // The samples, drawn from the volume rendering in the same frame, sit on that mesh.
    let samples = src.sample(2000, 1);
    let oracle = MeshDistance::new(mesh.clone(), 200_000);
    let d: Vec<f32> = samples.positions.iter().map(|p| oracle.distance(*p) / voxel).collect();
    assert!(quantile(&d, 0.5) < 1.0, "samples' median distance to the mesh: {} voxels", quantile(&d, 0.5));
}

#[test]
fn the_default_level_of_a_float_grid_is_where_a_voxel_absorbs_half_the_light() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("ball.npy"), ball_npy(48)).unwrap();
    // Bounds of side 4 over 47 cells: ln 2 / (4 / 47) = 8.14 stored units at scale 1, so the surface
    // sits at r = 0.55 - 0.1 * 8.14 / 50 = 0.5337 (node coordinates = canonical coordinates here).
    let src = build(dir.path(), "path = 'ball.npy'\nbounds = [[8, -2, -2], [12, 2, 2]]").unwrap();
    let level = std::f32::consts::LN_2 / (4.0 / 47.0);
    assert!(src.describe().contains(&format!("level {level}")), "{}", src.describe());
    let radii: Vec<f32> = src.mesh().unwrap().positions.iter().map(|p| norm(*p)).collect();
    let mean = radii.iter().sum::<f32>() / radii.len() as f32;
    assert!((mean - (0.55 - 0.1 * level / 50.0)).abs() < 0.002, "mean radius {mean}");
    // A haze threshold above that default raises it: min_density = 20 (density units, scale 1).
    let src = build(dir.path(), "path = 'ball.npy'\nbounds = [[8, -2, -2], [12, 2, 2]]\nmin_density = 20.0")
        .unwrap();
    assert!(src.describe().contains("level 20"), "{}", src.describe());
}

#[test]
fn mesh_options_are_checked_and_extraction_can_be_skipped() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // A 6^3 uint8 grid: 200 inside the central 2^3 nodes, 0 elsewhere.
    let values: Vec<u8> = (0..216)
        .map(|i| if [i / 36, i / 6 % 6, i % 6].iter().all(|c| (2..4).contains(c)) { 200 } else { 0 })
        .collect();
    std::fs::write(d.join("cube.npy"), write_npy_bytes(&[6, 6, 6], "|u1", &values, false)).unwrap();
    let src = build(d, "path = 'cube.npy'").unwrap();
    assert!(src.mesh().is_some_and(|m| m.has_area()));
    let src = build(d, "path = 'cube.npy'\nextract_mesh = false").unwrap();
    assert!(src.mesh().is_none());
    assert!(src.describe().contains("no mesh (extract_mesh = false)"), "{}", src.describe());
    for (toml_text, needles) in [
        (
            "path = 'cube.npy'\nmesh_level = 300",
            &["cube.npy", "mesh_level = 300", "[0, 200]", "extract_mesh"][..],
        ),
        ("path = 'cube.npy'\nmesh_level = -1", &["mesh_level = -1", "[0, 200]"]),
        ("path = 'cube.npy'\nmesh_level = nan", &["mesh_level = NaN must be a finite number"]),
        ("path = 'cube.npy'\nmesh_level = '12'", &["mesh_level"]),
        ("path = 'cube.npy'\nextract_mesh = 1", &["extract_mesh"]),
    ] {
        let e = build(d, toml_text).err().unwrap_or_else(|| panic!("{toml_text} should fail"));
        assert!(needles.iter().all(|n| e.contains(n)), "{toml_text}: {e}");
    }
}

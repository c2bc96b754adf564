//! `nuvo train` straight on a density grid with no `bake_mesh`: the grid's own marching-cubes mesh
//! gets the atlas, so the run writes the same outputs as a mesh run, in the grid's input coordinates.

use nuvo_geometry::testdata::data_file;

mod common;
use common::{SMALLEST_MODEL, nuvo, run};

#[test]
fn a_density_run_without_bake_mesh_bakes_onto_the_grids_own_mesh() {
    let dir = tempfile::tempdir().unwrap();
    let grid = data_file("density/unruly_bunny.npy");
    // Bounds away from the canonical frame: the box [10, 14] x [0, 4] x [0, 4] (scale 2, shift (12, 2, 2)).
    let cfg = dir.path().join("density.toml");
    std::fs::write(
        &cfg,
        format!(
            r#"seed = 1
[geometry]
source = "density"
path = {grid:?}
bounds = [[10, 0, 0], [14, 4, 4]]
{SMALLEST_MODEL}
[training]
steps = 2
batch_3d = 128
batch_uv = 128
[output]
dir = "unused"
atlas_resolution = 128
eval_views = 1
eval_resolution = 64
renders = 1
render_resolution = 64
"#
        ),
    )
    .unwrap();
    let out_dir = dir.path().join("run");
    let out = run(nuvo().arg("train").arg(&cfg).arg("--out").arg(&out_dir));
    assert!(out.status.success());
    for f in ["atlas.obj", "atlas.mtl", "atlas.glb", "uv_layout.png", "metrics.json", "renders/view_0.png"] {
        assert!(out_dir.join(f).is_file(), "{f} missing");
    }
    assert!(!out_dir.join("points_uv.csv").exists(), "per-point UVs written although the grid has a mesh");
    let m: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out_dir.join("metrics.json")).unwrap()).unwrap();
    assert_eq!(m["steps"], 2);
    // The level-12 marching-cubes mesh of this grid (see geometry-sources/tests/density_mesh.rs).
    let faces = m["bake"]["faces"].as_u64().unwrap();
    assert!((340_000..360_000).contains(&faces), "baked {faces} faces");
    // The OBJ is in the grid's input coordinates: the reference mesh's [-1, 1]^3 box, scaled by 2
    // and moved to (12, 2, 2), every face with UVs.
    let obj = std::fs::read_to_string(out_dir.join("atlas.obj")).unwrap();
    let mut lo = [f32::INFINITY; 3];
    let mut hi = [f32::NEG_INFINITY; 3];
    for line in obj.lines().filter(|l| l.starts_with("v ")) {
        let v: Vec<f32> = line.split_whitespace().skip(1).map(|c| c.parse().unwrap()).collect();
        for k in 0..3 {
            lo[k] = lo[k].min(v[k]);
            hi[k] = hi[k].max(v[k]);
        }
    }
    let (want_lo, want_hi) = ([10.0, 0.0, 0.0], [14.0, 4.0, 4.0]);
    for k in 0..3 {
        assert!(
            (lo[k] - want_lo[k]).abs() < 1e-3 && (hi[k] - want_hi[k]).abs() < 1e-3,
            "OBJ box {lo:?}..{hi:?}"
        );
    }
    let face_lines: Vec<&str> = obj.lines().filter(|l| l.starts_with("f ")).collect();
    assert_eq!(face_lines.len() as u64, faces);
    assert!(face_lines.iter().all(|f| f.split_whitespace().skip(1).all(|c| c.contains('/'))));
}

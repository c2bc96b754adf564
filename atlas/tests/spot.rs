//! Real-data checks on `spot.obj` (Keenan Crane's cow, which carries its own UVs with seams).
//!
//! Reference values, computed independently in NumPy from the OBJ file (area-weighted instead of
//! pixel-weighted, so only roughly comparable): Stretch ≈ 0.54 (spot's UVs vary a lot in scale:
//! the 10th–90th percentiles of s/median(s) are 0.47–7.4), Conformal ≈ 0.89, 13 UV charts, one of
//! them (176 faces) mirrored as a whole, and exactly one face flipped inside its chart.

use nuvo_atlas::export::{GlbOptions, glb_bytes, write_obj};
use nuvo_atlas::load::load_mesh_with_uv;
use nuvo_atlas::metrics::{EvalOptions, evaluate};
use nuvo_atlas::uvstats::UvStats;
use nuvo_geometry::testdata::data_file;
use nuvo_geometry::{Similarity, TriMesh};

fn spot() -> TriMesh {
    load_mesh_with_uv(&data_file("meshes/spot.obj")).expect("spot.obj loads with UVs")
}

#[test]
fn spot_gets_sensible_metrics_at_the_defaults() {
    let m = evaluate(&spot(), &EvalOptions::default()).unwrap();
    let i = &m.image;
    println!(
        "spot: Boundary {:.4} Stretch {:.4} Conformal {:.4} Editability {:.4}; {} charts, utilisation {:.4}, \
         overlap {:.5}, flipped {} faces",
        i.boundary,
        i.stretch,
        i.conformal,
        i.editability,
        m.uv.charts,
        m.uv.utilisation,
        m.uv.overlap_fraction,
        m.uv.flipped_faces
    );
    assert_eq!(i.views_used, 16);
    // Seams are visible from most views, but are thin lines: a few percent of the pixels.
    assert!(i.boundary > 0.95 && i.boundary < 0.999, "boundary {}", i.boundary);
    assert!(i.conformal > 0.8 && i.conformal < 0.95, "conformal {}", i.conformal);
    assert!(i.stretch > 0.45 && i.stretch < 0.65, "stretch {}", i.stretch);
    let expected =
        i.per_view.iter().map(|v| v.boundary * 0.5 * (v.stretch + v.conformal)).sum::<f64>() / 16.0;
    assert!((i.editability - expected).abs() < 1e-12);
    assert_eq!(m.uv.charts, 13);
    assert_eq!(m.uv.flipped_faces, 1);
    assert_eq!(m.uv.flipped_on_creases, 0, "spot has no creases: its flip is in the UVs");
    assert_eq!(m.uv.degenerate_uv_faces, 0);
    assert_eq!(m.uv.degenerate_3d_faces, 0);
    assert!(m.uv.overlap_fraction < 1e-3, "spot's charts do not overlap: {}", m.uv.overlap_fraction);
    assert!(m.uv.utilisation > 0.3 && m.uv.utilisation < 0.7, "utilisation {}", m.uv.utilisation);
    // The JSON of `nuvo eval --json` carries the numbers and the options that produced them.
    let json = serde_json::to_value(&m).unwrap();
    assert_eq!(json["image"]["boundary"].as_f64(), Some(i.boundary));
    assert_eq!(json["options"]["uv_jump"].as_f64(), Some(0.10000000149011612));
    assert_eq!(json["options"]["views"], 16);
    assert_eq!(json["uv"]["charts"], 13);
}

#[test]
fn spot_survives_export_and_reimport_with_identical_metrics() {
    let mesh = spot();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("spot_out.obj");
    // Pretend the mesh was canonicalised; the writer must undo it.
    let frame = Similarity::normalizing(&mesh.bounds().unwrap());
    let mut canonical = mesh.clone();
    canonical.transform(&frame);
    write_obj(&path, &canonical, &frame, None).unwrap();
    let back = load_mesh_with_uv(&path).unwrap();
    assert_eq!(back.triangles, mesh.triangles);
    assert_eq!(back.uv, mesh.uv);
    for (a, b) in back.positions.iter().zip(&mesh.positions) {
        for k in 0..3 {
            assert!((a[k] - b[k]).abs() < 1e-5, "{a:?} vs {b:?}");
        }
    }
    let opts = EvalOptions { views: 4, resolution: 256, ..Default::default() };
    let (m0, m1) = (evaluate(&mesh, &opts).unwrap(), evaluate(&back, &opts).unwrap());
    assert!((m0.image.editability - m1.image.editability).abs() < 1e-3);
    // The texel aspect reads the 3-D positions, which the round trip rounds to f32 (1e-5 above):
    // equal to 1e-4, every other UV statistic exactly.
    let (a0, a1) = (m0.uv.texel_aspect_median, m1.uv.texel_aspect_median);
    let (p0, p1) = (m0.uv.texel_aspect_p90, m1.uv.texel_aspect_p90);
    assert!((a0 - a1).abs() < 1e-4 * a0 && (p0 - p1).abs() < 1e-4 * p0, "{:?} vs {:?}", m0.uv, m1.uv);
    let same_aspect = UvStats { texel_aspect_median: a0, texel_aspect_p90: p0, ..m1.uv.clone() };
    assert_eq!(m0.uv, same_aspect);

    let glb =
        glb_bytes(&mesh, &Similarity::IDENTITY, &GlbOptions { normals: true, texture_png: None }).unwrap();
    let gltf = gltf::Gltf::from_slice(&glb).unwrap();
    let prim = gltf.meshes().next().unwrap().primitives().next().unwrap();
    let blob = gltf.blob.as_deref().unwrap();
    let reader = prim.reader(|_| Some(blob));
    let n = reader.read_positions().unwrap().count();
    // Seams split vertices: more than the 2,930 positions, at most one per distinct (v, vt) pair.
    assert!(n > mesh.positions.len() && n <= mesh.triangles.len() * 3, "{n} vertices");
    assert_eq!(reader.read_indices().unwrap().into_u32().count(), mesh.triangles.len() * 3);
}

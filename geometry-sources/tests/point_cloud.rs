//! The point-cloud source: PLY (ASCII, binary) and XYZ reading, estimated normals against the bunny
//! cloud's stored normals, and bad files.

mod common;

use std::path::Path;

use common::*;
use nuvo_geometry::point_cloud::{NormalSource, PointCloudOptions, PointCloudSource};
use nuvo_geometry::testdata::data_file;
use nuvo_geometry::{GeometrySource, SourceRegistry};

fn build(dir: &Path, toml_text: &str) -> Result<Box<dyn GeometrySource>, String> {
    let table: toml::Table = toml::from_str(toml_text).unwrap();
    SourceRegistry::with_builtins().build("point_cloud", &table, &ctx(dir)).map_err(|e| e.to_string())
}

fn opts(normals: NormalSource) -> PointCloudOptions {
    PointCloudOptions { path: "stanford-bunny_200k.ply".into(), normals, neighbors: 16 }
}

#[test]
fn bunny_cloud_with_file_normals_and_estimated_normals_agree() {
    let ply = data_file("pointclouds/stanford-bunny_200k.ply");
    let dir = ply.parent().unwrap();
    let file = PointCloudSource::new(&opts(NormalSource::Auto), &ctx(dir)).unwrap();
    assert_eq!(file.positions().len(), 200_000);
    assert_unit_normals(file.normals());
    assert!(file.describe().contains("file normals"));
    let b = file.bounds();
    assert!((0..3).all(|k| b.min[k] >= -1.0 - 1e-5 && b.max[k] <= 1.0 + 1e-5));
    assert!((0..3).any(|k| (b.max[k] - 1.0).abs() < 1e-5));

    let t = std::time::Instant::now();
    let est = PointCloudSource::new(&opts(NormalSource::Estimate), &ctx(dir)).unwrap();
    eprintln!("normal estimation for 200k points: {:.2} s", t.elapsed().as_secs_f64());
    assert_eq!(est.positions(), file.positions());
    assert_unit_normals(est.normals());
    let cos: Vec<f32> = est.normals().iter().zip(file.normals()).map(|(a, b)| dot(*a, *b)).collect();
    let n = cos.len() as f64;
    let aligned = cos.iter().filter(|c| c.abs() > 0.9).count() as f64 / n;
    let right_sign = cos.iter().filter(|&&c| c > 0.0).count() as f64 / n;
    eprintln!("|cos| > 0.9: {:.1}%, same sign: {:.1}%", 100.0 * aligned, 100.0 * right_sign);
    assert!(aligned > 0.9, "only {:.1}% of estimated normals within 26° of the stored ones", 100.0 * aligned);
    assert!(right_sign > 0.95, "only {:.1}% of estimated normals have the right sign", 100.0 * right_sign);

    // Samples are stored points with their normals; deterministic.
    let s = file.sample(5000, 1);
    assert_eq!(s, file.sample(5000, 1));
    assert_ne!(s, file.sample(5000, 2));
    let i = file.positions().iter().position(|p| *p == s.positions[0]).expect("a stored point");
    assert_eq!(file.normals()[i], s.normals[0]);
}

/// Points of a unit-ish tetrahedron-free cloud: a 12×12 grid on the plane z = 0.5 with normal +z.
fn plane_points() -> Vec<([f32; 3], [f32; 3])> {
    (0..144).map(|i| ([(i % 12) as f32 * 0.1, (i / 12) as f32 * 0.1, 0.5], [0.0, 0.0, 1.0])).collect()
}

fn ascii_ply(points: &[([f32; 3], [f32; 3])], declared: usize, normals: bool) -> String {
    let mut s = format!(
        "ply\nformat ascii 1.0\ncomment test\nelement vertex {declared}\nproperty float x\nproperty float y\nproperty double z\n"
    );
    if normals {
        s += "property float nx\nproperty float ny\nproperty float nz\n";
    }
    s += "element face 1\nproperty list uchar int vertex_indices\nend_header\n";
    for (p, n) in points {
        s += &format!("{} {} {}", p[0], p[1], p[2]);
        if normals {
            s += &format!(" {} {} {}", n[0], n[1], n[2]);
        }
        s += "\n";
    }
    s + "3 0 1 2\n"
}

fn binary_ply(points: &[([f32; 3], [f32; 3])], declared: usize, big_endian: bool) -> Vec<u8> {
    let fmt = if big_endian { "binary_big_endian" } else { "binary_little_endian" };
    let mut out = format!(
        "ply\nformat {fmt} 1.0\nelement vertex {declared}\nproperty float x\nproperty float y\nproperty float z\n\
         property float nx\nproperty float ny\nproperty float nz\nend_header\n"
    )
    .into_bytes();
    for (p, n) in points {
        for v in p.iter().chain(n) {
            out.extend_from_slice(&if big_endian { v.to_be_bytes() } else { v.to_le_bytes() });
        }
    }
    out
}

#[test]
fn ascii_binary_and_xyz_files_read_the_same_points() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let pts = plane_points();
    std::fs::write(d.join("a.ply"), ascii_ply(&pts, pts.len(), true)).unwrap();
    std::fs::write(d.join("le.ply"), binary_ply(&pts, pts.len(), false)).unwrap();
    std::fs::write(d.join("be.ply"), binary_ply(&pts, pts.len(), true)).unwrap();
    let xyz: String = pts
        .iter()
        .map(|(p, n)| format!("{}, {}, {}, {} {} {}\n", p[0], p[1], p[2], n[0], n[1], n[2]))
        .collect();
    std::fs::write(d.join("a.xyz"), format!("# a comment\n\n{xyz}")).unwrap();
    let reference = build(d, "path = 'a.ply'").unwrap().sample(500, 3);
    for f in ["le.ply", "be.ply", "a.xyz"] {
        assert_eq!(build(d, &format!("path = '{f}'")).unwrap().sample(500, 3), reference, "{f}");
    }
    assert!(reference.normals.iter().all(|n| *n == [0.0, 0.0, 1.0]));
    // Without normals they are estimated; on a plane seen from its centroid side... any consistent
    // sign is acceptable, but all must agree and be ±z.
    std::fs::write(d.join("plain.ply"), ascii_ply(&pts, pts.len(), false)).unwrap();
    let s = build(d, "path = 'plain.ply'").unwrap().sample(500, 3);
    let z0 = s.normals[0][2];
    assert!(z0.abs() > 0.999 && s.normals.iter().all(|n| n[2] * z0 > 0.999));
}

#[test]
fn bad_point_files_are_clear_errors() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let pts = plane_points();
    let mut nan = pts.clone();
    nan[7].0[1] = f32::NAN;
    let mut zero_normal = pts.clone();
    zero_normal[3].1 = [0.0; 3];
    let bin = binary_ply(&pts, pts.len(), false);
    let cases: Vec<(&str, Vec<u8>, &str)> = vec![
        ("empty.ply", vec![], "PLY"),
        ("garbage.ply", b"\x00\x01garbage garbage\n".to_vec(), "PLY"),
        ("count_too_big.ply", ascii_ply(&pts, 200, true).into_bytes(), "vertex"),
        ("count_too_small.ply", ascii_ply(&pts, 100, true).into_bytes(), "element `face`"),
        ("bin_count_too_big.ply", binary_ply(&pts, 145, false), "vertex"),
        ("bin_count_too_small.ply", binary_ply(&pts, 143, false), "fewer elements"),
        ("truncated.ply", bin[..bin.len() - 7].to_vec(), "vertex"),
        ("huge_count.ply", binary_ply(&pts, usize::MAX / 2, false), "vertex"),
        ("nan.ply", binary_ply(&nan, nan.len(), false), "non-finite"),
        ("zero_normal.ply", ascii_ply(&zero_normal, pts.len(), true).into_bytes(), "point 4"),
        (
            "no_vertex.ply",
            b"ply\nformat ascii 1.0\nelement point 1\nproperty float x\nend_header\n1\n".to_vec(),
            "vertex",
        ),
        (
            "no_z.ply",
            b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nend_header\n1 2\n"
                .to_vec(),
            "x, y, z",
        ),
        ("no_points.ply", ascii_ply(&[], 0, true).into_bytes(), "no points"),
        ("bad.xyz", b"1 2 3\n4 five 6\n".to_vec(), "line 2"),
        ("columns.xyz", b"1 2 3\n4 5 6 0 0 1\n".to_vec(), "line 2"),
        ("four.xyz", b"1 2 3 4\n".to_vec(), "line 1"),
        ("inf.xyz", b"1 2 3\ninf 0 0\n".to_vec(), "point 2"),
        ("empty.xyz", b"# nothing\n".to_vec(), "no points"),
        ("cloud.las", b"LASF".to_vec(), ".ply"),
    ];
    for (name, bytes, needle) in cases {
        std::fs::write(d.join(name), bytes).unwrap();
        let e = build(d, &format!("path = '{name}'")).err().unwrap_or_else(|| panic!("{name} should fail"));
        eprintln!("{e}");
        assert!(e.contains(name) && e.contains(needle), "{name}: {e}");
    }
    std::fs::write(d.join("plain.xyz"), "0 0 0\n1 0 0\n0 1 0\n").unwrap();
    for (toml_text, needle) in [
        ("path = 'plain.xyz'\nnormals = 'file'", "no normals"),
        ("path = 'plain.xyz'\nnormals = 'files'", "unknown variant `files`"),
        ("path = 'plain.xyz'\nneighbors = 1", "neighbors"),
        ("path = 'plain.xyz'\nneighbours = 8", "unknown field `neighbours`"),
    ] {
        let e = build(d, toml_text).err().unwrap_or_else(|| panic!("{toml_text} should fail"));
        assert!(e.contains(needle), "{toml_text}: {e}");
    }
}

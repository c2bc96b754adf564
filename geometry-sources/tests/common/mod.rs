//! Shared helpers of the integration tests: small synthetic meshes and statistics.
#![allow(dead_code)]

use std::path::PathBuf;

use nuvo_geometry::mesh_source::{MeshOptions, MeshSource, SamplingMode};
use nuvo_geometry::sampling::NormalMode;
use nuvo_geometry::{BuildContext, TriMesh};

pub fn ctx(dir: &std::path::Path) -> BuildContext {
    BuildContext { base_dir: dir.to_path_buf() }
}

/// An axis-aligned cube `[lo, hi]^3`, outward winding. Face `+z` is split into `k × k` quads (two
/// triangles each), so triangle areas differ wildly between faces.
pub fn cube(lo: f32, hi: f32, k: usize) -> TriMesh {
    let mut m = TriMesh::default();
    // (axis, sign) for each face; u, v span the face so that u × v points outward.
    for (axis, sign) in [(0, 1.0f32), (0, -1.0), (1, 1.0), (1, -1.0), (2, 1.0), (2, -1.0)] {
        let steps = if axis == 2 && sign > 0.0 { k } else { 1 };
        let (ua, va) = ((axis + 1) % 3, (axis + 2) % 3);
        let base = m.positions.len() as u32;
        for j in 0..=steps {
            for i in 0..=steps {
                let mut p = [0.0f32; 3];
                p[axis] = if sign > 0.0 { hi } else { lo };
                p[ua] = lo + (hi - lo) * i as f32 / steps as f32;
                p[va] = lo + (hi - lo) * j as f32 / steps as f32;
                m.positions.push(p);
            }
        }
        let w = steps as u32 + 1;
        for j in 0..steps as u32 {
            for i in 0..steps as u32 {
                let (a, b, c, d) = (
                    base + j * w + i,
                    base + j * w + i + 1,
                    base + (j + 1) * w + i + 1,
                    base + (j + 1) * w + i,
                );
                if sign > 0.0 {
                    m.triangles.push([a, b, c]);
                    m.triangles.push([a, c, d]);
                } else {
                    m.triangles.push([a, c, b]);
                    m.triangles.push([a, d, c]);
                }
            }
        }
    }
    m
}

/// A UV sphere of radius 1 (`rings × segments`), outward winding; its triangles shrink towards the
/// poles, so per-triangle-uniform sampling would crowd the poles.
pub fn uv_sphere(rings: usize, segments: usize) -> TriMesh {
    let mut m = TriMesh::default();
    for r in 0..=rings {
        let theta = std::f32::consts::PI * r as f32 / rings as f32;
        for s in 0..segments {
            let phi = std::f32::consts::TAU * s as f32 / segments as f32;
            m.positions.push([theta.sin() * phi.cos(), theta.sin() * phi.sin(), theta.cos()]);
        }
    }
    let idx = |r: usize, s: usize| (r * segments + s % segments) as u32;
    for r in 0..rings {
        for s in 0..segments {
            let (a, b, c, d) = (idx(r, s), idx(r + 1, s), idx(r + 1, s + 1), idx(r, s + 1));
            if r > 0 {
                m.triangles.push([a, b, d]);
            }
            if r + 1 < rings {
                m.triangles.push([b, c, d]);
            }
        }
    }
    m
}

/// Appends `other` to `m`.
pub fn append(m: &mut TriMesh, other: &TriMesh) {
    let base = m.positions.len() as u32;
    m.positions.extend_from_slice(&other.positions);
    m.triangles.extend(other.triangles.iter().map(|t| t.map(|i| i + base)));
}

pub fn options(sampling: SamplingMode, normals: NormalMode) -> MeshOptions {
    MeshOptions { path: PathBuf::from("synthetic"), sampling, normals, flip_normals: false, cameras: None }
}

pub fn source(mesh: TriMesh, sampling: SamplingMode, normals: NormalMode) -> MeshSource {
    MeshSource::from_mesh(
        "synthetic".into(),
        mesh,
        &options(sampling, normals),
        &ctx(std::path::Path::new(".")),
    )
    .expect("synthetic mesh must build")
}

pub fn dot(a: [f32; 3], b: [f32; 3]) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

pub fn norm(a: [f32; 3]) -> f32 {
    dot(a, a).sqrt()
}

/// Asserts every normal is unit length.
pub fn assert_unit_normals(normals: &[[f32; 3]]) {
    for n in normals {
        assert!((norm(*n) - 1.0).abs() < 1e-4, "normal {n:?} is not unit");
    }
}

/// The `q`-quantile of `v` (sorts a copy).
pub fn quantile(v: &[f32], q: f64) -> f32 {
    let mut s = v.to_vec();
    s.sort_by(f32::total_cmp);
    s[((s.len() - 1) as f64 * q).round() as usize]
}

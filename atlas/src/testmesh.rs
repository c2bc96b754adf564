//! Small synthetic meshes with known answers, for the unit tests of this crate.

use nuvo_geometry::{TriMesh, UvLayer};

/// The plane `z = 0` over `[-1, 1]²` as `n × n` quads of two counter-clockwise triangles (seen from
/// +z), with one UV per vertex given by `map(position)`.
pub(crate) fn grid(n: u32, map: impl Fn([f32; 3]) -> [f32; 2]) -> TriMesh {
    let mut positions = Vec::new();
    for j in 0..=n {
        for i in 0..=n {
            positions.push([-1.0 + 2.0 * i as f32 / n as f32, -1.0 + 2.0 * j as f32 / n as f32, 0.0]);
        }
    }
    let id = |i: u32, j: u32| j * (n + 1) + i;
    let mut triangles = Vec::new();
    for j in 0..n {
        for i in 0..n {
            triangles.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
            triangles.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
        }
    }
    let coords = positions.iter().map(|&p| map(p)).collect();
    TriMesh { positions, uv: Some(UvLayer { coords, triangles: triangles.clone() }), triangles }
}

/// A copy of `mesh` whose UV layer has one coordinate per corner, `f(face, corner, old uv)`.
pub(crate) fn with_uv_per_corner(mesh: &TriMesh, f: impl Fn(usize, usize, [f32; 2]) -> [f32; 2]) -> TriMesh {
    let uv = mesh.uv.as_ref().expect("test mesh has UVs");
    let mut coords = Vec::new();
    let mut triangles = Vec::new();
    for (face, t) in uv.triangles.iter().enumerate() {
        let base = coords.len() as u32;
        for (k, &i) in t.iter().enumerate() {
            coords.push(f(face, k, uv.coords[i as usize]));
        }
        triangles.push([base, base + 1, base + 2]);
    }
    TriMesh { uv: Some(UvLayer { coords, triangles }), ..mesh.clone() }
}

//! Surface samplers for triangle meshes: area-uniform ([`uniform`]) and first-hit-visible
//! ([`visible`]). Both work in the mesh's own (already canonical) coordinates and share how normals
//! are chosen ([`NormalMode`], [`SurfaceNormals`]).

pub mod uniform;
pub mod visible;

use serde::Deserialize;

use crate::math::{V3, cross, madd, normalize, scale, sub};
use crate::mesh::TriMesh;

/// Which normal a mesh sample carries.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum NormalMode {
    /// The triangle's geometric normal (from its winding). Exact for faceted and CAD meshes.
    #[default]
    Face,
    /// Area-weighted vertex normals interpolated with the barycentric coordinates of the sample:
    /// smooth across triangle edges, for meshes that approximate smooth surfaces.
    Vertex,
}

/// Precomputed per-face (and, in [`NormalMode::Vertex`], per-vertex) normals of a mesh.
#[derive(Clone, Debug)]
pub struct SurfaceNormals {
    mode: NormalMode,
    face: Vec<V3>,
    vertex: Vec<V3>,
}

impl SurfaceNormals {
    /// Precomputes the normals `mode` needs. Degenerate faces get a zero normal; they are never
    /// sampled (zero area, never hit).
    pub fn new(mesh: &TriMesh, mode: NormalMode) -> Self {
        let face = (0..mesh.triangles.len())
            .map(|f| normalize(mesh.face_normal_scaled(f)).unwrap_or([0.0; 3]))
            .collect();
        let vertex = if mode == NormalMode::Vertex { mesh.vertex_normals() } else { Vec::new() };
        SurfaceNormals { mode, face, vertex }
    }

    /// The unit normal at barycentric `(b1, b2)` of face `f` (corner weights `1-b1-b2, b1, b2`). In
    /// vertex mode an interpolated normal that vanishes falls back to the face normal.
    pub fn at(&self, mesh: &TriMesh, f: usize, b1: f32, b2: f32) -> V3 {
        let face = self.face.get(f).copied().unwrap_or([0.0; 3]);
        if self.mode == NormalMode::Face {
            return face;
        }
        let [i0, i1, i2] =
            mesh.triangles[f].map(|v| self.vertex.get(v as usize).copied().unwrap_or([0.0; 3]));
        let n = madd(madd(scale(i0, 1.0 - b1 - b2), b1, i1), b2, i2);
        normalize(n).unwrap_or(face)
    }
}

/// The point at barycentric `(b1, b2)` of face `f`.
pub(crate) fn point_on(mesh: &TriMesh, f: usize, b1: f32, b2: f32) -> V3 {
    let [a, b, c] = mesh.corners(f);
    madd(madd(a, b1, sub(b, a)), b2, sub(c, a))
}

/// Twice the area of a triangle given by its corners (for tests and checks).
#[allow(dead_code)]
pub(crate) fn double_area(a: V3, b: V3, c: V3) -> f32 {
    crate::math::norm(cross(sub(b, a), sub(c, a)))
}

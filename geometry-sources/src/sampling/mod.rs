//! Surface samplers for triangle meshes: area-uniform ([`uniform`]) and first-hit-visible
//! ([`visible`]). Both work in the mesh's own (already canonical) coordinates and share how normals
//! are chosen ([`NormalMode`], [`SurfaceNormals`]).

pub mod uniform;
pub mod visible;

use glam::Vec3;
use serde::Deserialize;

use crate::coords::V3;
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
            .map(|f| Vec3::from(mesh.face_normal_scaled(f)).normalize_or_zero().to_array())
            .collect();
        let vertex = if mode == NormalMode::Vertex { mesh.vertex_normals_or([0.0; 3]) } else { Vec::new() };
        SurfaceNormals { mode, face, vertex }
    }

    /// The same normals pointing the other way: for a mesh wound inside out (its triangles
    /// clockwise seen from outside), whose winding normals point into the object.
    pub fn flipped(mut self) -> Self {
        for n in self.face.iter_mut().chain(self.vertex.iter_mut()) {
            *n = n.map(|c| -c);
        }
        self
    }

    /// The unit normal at barycentric `(b1, b2)` of face `f` (corner weights `1-b1-b2, b1, b2`). In
    /// vertex mode an interpolated normal that vanishes falls back to the face normal.
    pub fn at(&self, mesh: &TriMesh, f: usize, b1: f32, b2: f32) -> V3 {
        let face = self.face.get(f).copied().unwrap_or([0.0; 3]);
        if self.mode == NormalMode::Face {
            return face;
        }
        let [i0, i1, i2] =
            mesh.triangles[f].map(|v| Vec3::from(self.vertex.get(v as usize).copied().unwrap_or([0.0; 3])));
        let n = i0 * (1.0 - b1 - b2) + b1 * i1 + b2 * i2;
        n.try_normalize().map_or(face, V3::from)
    }
}

/// The point at barycentric `(b1, b2)` of face `f`.
pub(crate) fn point_on(mesh: &TriMesh, f: usize, b1: f32, b2: f32) -> V3 {
    let [a, b, c] = mesh.corners(f).map(Vec3::from);
    (a + b1 * (b - a) + b2 * (c - a)).to_array()
}

/// Barycentric coordinates `(b1, b2)` of the point of face `f`'s plane nearest to `p`, clamped to
/// the triangle (the weights of corners 1 and 2). Face `f` must have positive area.
pub(crate) fn barycentric(mesh: &TriMesh, f: usize, p: V3) -> (f32, f32) {
    let [a, b, c] = mesh.corners(f).map(Vec3::from);
    let (e1, e2, d) = (b - a, c - a, Vec3::from(p) - a);
    let (d11, d12, d22) = (e1.dot(e1), e1.dot(e2), e2.dot(e2));
    let (d1, d2) = (d.dot(e1), d.dot(e2));
    let det = d11 * d22 - d12 * d12;
    if det.is_nan() || det <= 0.0 {
        return (1.0 / 3.0, 1.0 / 3.0);
    }
    let b1 = ((d22 * d1 - d12 * d2) / det).clamp(0.0, 1.0);
    let b2 = ((d11 * d2 - d12 * d1) / det).clamp(0.0, 1.0 - b1);
    (b1, b2)
}

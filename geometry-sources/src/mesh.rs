//! The triangle mesh shared by every crate that reads, bakes, exports or measures meshes.

use glam::{DVec3, Vec3};

use crate::coords::coordinate_problem;
use crate::frame::{Aabb, Similarity};

/// A triangle mesh, optionally with texture coordinates.
///
/// Invariants (checked by [`TriMesh::validate`], which every loader calls):
/// - every index in `triangles` is `< positions.len()`;
/// - every coordinate is finite;
/// - if `uv` is present, `uv.triangles.len() == triangles.len()` and its indices are in range.
///
/// Degenerate (zero-area) triangles are allowed: NeRF meshes are full of them and samplers simply
/// give them zero weight.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TriMesh {
    /// Vertex positions.
    pub positions: Vec<[f32; 3]>,
    /// Vertex indices of each triangle, counter-clockwise seen from outside.
    pub triangles: Vec<[u32; 3]>,
    /// Per-corner texture coordinates, when the mesh has them.
    pub uv: Option<UvLayer>,
}

/// Texture coordinates indexed per triangle corner, as OBJ stores them (`f v/vt`): a vertex on a UV
/// seam has one position and several UVs. `triangles[f][k]` indexes `coords` for corner `k` of face `f`.
///
/// Convention: OBJ's, with `v` pointing **up** (origin at the bottom-left of the texture image). glTF
/// stores `v` pointing down, so [`crate::gltf_io::load_gltf`] stores `(u, 1 - v)` and a glTF writer
/// must flip back.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct UvLayer {
    /// Texture coordinates `(u, v)`.
    pub coords: Vec<[f32; 2]>,
    /// Per face, the indices into `coords` of its three corners.
    pub triangles: Vec<[u32; 3]>,
}

impl TriMesh {
    /// The three corner positions of triangle `f`.
    pub fn corners(&self, f: usize) -> [[f32; 3]; 3] {
        self.triangles[f].map(|v| self.positions[v as usize])
    }

    /// Twice the area of triangle `f` times its unit normal (the unnormalised cross product).
    pub fn face_normal_scaled(&self, f: usize) -> [f32; 3] {
        let [a, b, c] = self.corners(f).map(Vec3::from);
        (b - a).cross(c - a).to_array()
    }

    /// The area of triangle `f`.
    pub fn face_area(&self, f: usize) -> f32 {
        0.5 * Vec3::from(self.face_normal_scaled(f)).length()
    }

    /// The bounding box of the referenced and unreferenced vertices, `None` for an empty mesh.
    pub fn bounds(&self) -> Option<Aabb> {
        Aabb::from_points(&self.positions)
    }

    /// Applies `s` to every position (UVs are untouched).
    pub fn transform(&mut self, s: &Similarity) {
        for p in &mut self.positions {
            *p = s.apply(*p);
        }
    }

    /// Area-weighted per-vertex normals (unit length), accumulated in `f64` so the tiny triangles
    /// of a large `f32` mesh still count. A vertex whose incident normals cancel, or that no
    /// triangle uses, gets `fallback`: zero where a caller has its own fallback (sampling takes the
    /// face's normal), `+Z` where every normal must be valid (glTF, renders).
    pub fn vertex_normals_or(&self, fallback: [f32; 3]) -> Vec<[f32; 3]> {
        let mut acc = vec![DVec3::ZERO; self.positions.len()];
        for t in &self.triangles {
            if t.iter().any(|&v| v as usize >= self.positions.len()) {
                continue; // an invalid mesh (`validate` names it); nothing to add up
            }
            let [a, b, c] = t.map(|v| Vec3::from(self.positions[v as usize]).as_dvec3());
            let n = (b - a).cross(c - a);
            for &v in t {
                acc[v as usize] += n;
            }
        }
        let fallback = Vec3::from(fallback).as_dvec3();
        acc.into_iter().map(|n| n.normalize_or(fallback).as_vec3().to_array()).collect()
    }

    /// True when at least one face has positive (finite) area, i.e. the surface can be sampled.
    pub fn has_area(&self) -> bool {
        (0..self.triangles.len()).any(|f| {
            let a = self.face_area(f);
            a > 0.0 && a.is_finite()
        })
    }

    /// Checks the invariants listed on the type, reporting the first violation in words.
    pub fn validate(&self) -> Result<(), String> {
        for (i, p) in self.positions.iter().enumerate() {
            if let Some(problem) = coordinate_problem(*p) {
                return Err(format!("vertex {} has {problem}: {p:?}", i + 1));
            }
        }
        let nv = self.positions.len();
        for (f, t) in self.triangles.iter().enumerate() {
            if let Some(&v) = t.iter().find(|&&v| v as usize >= nv) {
                return Err(format!(
                    "face {} refers to vertex {} but there are only {nv} vertices",
                    f + 1,
                    v as usize + 1
                ));
            }
        }
        if let Some(uv) = &self.uv {
            if uv.triangles.len() != self.triangles.len() {
                return Err(format!(
                    "{} faces have texture coordinates but the mesh has {} faces",
                    uv.triangles.len(),
                    self.triangles.len()
                ));
            }
            if let Some(i) = uv.coords.iter().position(|p| p.iter().any(|c| !c.is_finite())) {
                return Err(format!("texture coordinate {} is not finite: {:?}", i + 1, uv.coords[i]));
            }
            let nt = uv.coords.len();
            for (f, t) in uv.triangles.iter().enumerate() {
                if let Some(&v) = t.iter().find(|&&v| v as usize >= nt) {
                    return Err(format!(
                        "face {} refers to texture coordinate {} but there are only {nt}",
                        f + 1,
                        v as usize + 1
                    ));
                }
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn vertex_normals_are_unit_and_unused_vertices_get_the_fallback() {
        let m = TriMesh {
            positions: vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [5.0, 5.0, 5.0]],
            triangles: vec![[0, 2, 1]],
            uv: None,
        };
        let n = m.vertex_normals_or([0.0, 0.0, 1.0]);
        assert_eq!(n[0], [0.0, 1.0, 0.0]);
        assert_eq!(n[3], [0.0, 0.0, 1.0]);
        assert_eq!(m.vertex_normals_or([0.0; 3])[3], [0.0; 3]);
    }

    fn unit_right_triangle() -> TriMesh {
        TriMesh {
            positions: vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
            triangles: vec![[0, 1, 2]],
            uv: None,
        }
    }

    #[test]
    fn area_and_normal_of_a_right_triangle() {
        let m = unit_right_triangle();
        assert_eq!(m.face_area(0), 0.5);
        assert_eq!(m.face_normal_scaled(0), [0.0, 0.0, 1.0]);
    }

    #[test]
    fn validate_reports_out_of_range_and_nan() {
        let mut m = unit_right_triangle();
        assert!(m.validate().is_ok());
        m.triangles[0][2] = 7;
        assert!(m.validate().unwrap_err().contains("vertex 8"));
        let mut m = unit_right_triangle();
        m.positions[1][0] = f32::NAN;
        assert!(m.validate().unwrap_err().contains("vertex 2"));
    }
}

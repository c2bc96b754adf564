//! The bits of mesh geometry the passes share, on glam's `f64` vectors: a mesh position widened to
//! [`DVec3`], twice a UV triangle's signed area, per-vertex normals. Geometry that feeds a ratio or
//! a threshold is done in `f64` by the callers, so that f32 meshes with tiny triangles do not lose
//! the answer to rounding. glam's scalar `DVec3`/`DVec2` (not the SIMD `Vec3A`) evaluate each
//! component in the order written, so results do not depend on the target's vector units.

use glam::{DVec3, Vec2, Vec3};

/// An `f32` position (a [`nuvo_geometry::TriMesh`] vertex, a camera's eye) in `f64`, exactly.
pub(crate) fn to_dvec3(p: [f32; 3]) -> DVec3 {
    Vec3::from(p).as_dvec3()
}

/// Twice the signed area of the 2-D triangle `(a, b, c)`: positive when counter-clockwise in a
/// y-up frame (the UV convention).
pub(crate) fn signed_area2_2d(a: [f32; 2], b: [f32; 2], c: [f32; 2]) -> f64 {
    let [a, b, c] = [a, b, c].map(|p| Vec2::from(p).as_dvec2());
    (b - a).perp_dot(c - a)
}

/// Area-weighted per-vertex normals (unit length). Winding is trusted only locally: a vertex whose
/// incident normals cancel (or that no triangle uses) gets `+Z`, so every normal is valid for glTF.
pub(crate) fn vertex_normals(positions: &[[f32; 3]], triangles: &[[u32; 3]]) -> Vec<[f32; 3]> {
    let mut acc = vec![DVec3::ZERO; positions.len()];
    for t in triangles {
        let [a, b, c] = t.map(|v| to_dvec3(positions[v as usize]));
        let n = (b - a).cross(c - a);
        for &v in t {
            acc[v as usize] += n;
        }
    }
    acc.into_iter().map(|n| n.normalize_or(DVec3::Z).as_vec3().to_array()).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn signed_area_is_positive_counter_clockwise() {
        assert_eq!(signed_area2_2d([0.0, 0.0], [1.0, 0.0], [0.0, 1.0]), 1.0);
        assert_eq!(signed_area2_2d([0.0, 0.0], [0.0, 1.0], [1.0, 0.0]), -1.0);
    }

    #[test]
    fn vertex_normals_are_unit_and_fall_back_to_z() {
        let p = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [5.0, 5.0, 5.0]];
        let n = vertex_normals(&p, &[[0, 2, 1]]);
        assert_eq!(n[0], [0.0, 1.0, 0.0]);
        assert_eq!(n[3], [0.0, 0.0, 1.0]);
    }
}

//! The bits of mesh geometry the passes share, on glam's `f64` vectors: a mesh position widened to
//! [`DVec3`], twice a UV triangle's signed area. Geometry that feeds a ratio or
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn signed_area_is_positive_counter_clockwise() {
        assert_eq!(signed_area2_2d([0.0, 0.0], [1.0, 0.0], [0.0, 1.0]), 1.0);
        assert_eq!(signed_area2_2d([0.0, 0.0], [0.0, 1.0], [1.0, 0.0]), -1.0);
    }
}

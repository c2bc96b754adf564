//! Points as the crate stores and hands them out (`[f32; 3]`, the layout of [`crate::TriMesh`] and
//! of the files), and which of them a loader accepts. Arithmetic on them goes through
//! [`glam::Vec3`] (the scalar type, not `Vec3A`, so results do not depend on SIMD lanes).

pub(crate) type V3 = [f32; 3];

/// Largest coordinate magnitude accepted from a file: squared distances and edge cross products of
/// inputs this large would overflow f32 (max ≈ 3.4e38) before the input is normalised.
pub const MAX_COORDINATE: f32 = 1e18;

/// Why a position read from a file is unusable, if it is: `"a non-finite coordinate"` or one beyond
/// ±[`MAX_COORDINATE`].
pub(crate) fn coordinate_problem(a: V3) -> Option<&'static str> {
    if !glam::Vec3::from(a).is_finite() {
        Some("a non-finite coordinate")
    } else if a.iter().any(|c| c.abs() > MAX_COORDINATE) {
        Some("a coordinate beyond ±1e18, which would overflow f32 areas and distances (rescale the input)")
    } else {
        None
    }
}

//! Tiny fixed-size vector helpers on `[f32; 3]`, so the crate needs no linear-algebra dependency for
//! the handful of operations sampling uses.

pub(crate) type V3 = [f32; 3];

pub(crate) fn add(a: V3, b: V3) -> V3 {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

pub(crate) fn sub(a: V3, b: V3) -> V3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

pub(crate) fn scale(a: V3, s: f32) -> V3 {
    [a[0] * s, a[1] * s, a[2] * s]
}

/// `a + s * b`.
pub(crate) fn madd(a: V3, s: f32, b: V3) -> V3 {
    [a[0] + s * b[0], a[1] + s * b[1], a[2] + s * b[2]]
}

pub(crate) fn dot(a: V3, b: V3) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

pub(crate) fn cross(a: V3, b: V3) -> V3 {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}

pub(crate) fn norm(a: V3) -> f32 {
    dot(a, a).sqrt()
}

/// `a / |a|`, or `None` when `a` is zero or not finite (so callers must choose a fallback).
pub(crate) fn normalize(a: V3) -> Option<V3> {
    let n = norm(a);
    (n > 0.0 && n.is_finite()).then(|| scale(a, 1.0 / n))
}

pub(crate) fn neg(a: V3) -> V3 {
    [-a[0], -a[1], -a[2]]
}

pub(crate) fn is_finite(a: V3) -> bool {
    a.iter().all(|c| c.is_finite())
}

/// Largest coordinate magnitude accepted from a file: squared distances and edge cross products of
/// inputs this large would overflow f32 (max ≈ 3.4e38) before the input is normalised.
pub const MAX_COORDINATE: f32 = 1e18;

/// Why a position read from a file is unusable, if it is: `"a non-finite coordinate"` or one beyond
/// ±[`MAX_COORDINATE`].
pub(crate) fn coordinate_problem(a: V3) -> Option<&'static str> {
    if !is_finite(a) {
        Some("a non-finite coordinate")
    } else if a.iter().any(|c| c.abs() > MAX_COORDINATE) {
        Some("a coordinate beyond ±1e18, which would overflow f32 areas and distances (rescale the input)")
    } else {
        None
    }
}

//! The few 2-D/3-D vector helpers this crate needs, on plain arrays so they interoperate with
//! [`nuvo_geometry::TriMesh`] without conversions. Geometry that feeds a ratio or a threshold is done
//! in `f64` by the callers, so that f32 meshes with tiny triangles do not lose the answer to rounding.

pub(crate) type V3 = [f64; 3];

pub(crate) fn v3(p: [f32; 3]) -> V3 {
    [p[0] as f64, p[1] as f64, p[2] as f64]
}

pub(crate) fn sub(a: V3, b: V3) -> V3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

pub(crate) fn add(a: V3, b: V3) -> V3 {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

pub(crate) fn scale(a: V3, s: f64) -> V3 {
    [a[0] * s, a[1] * s, a[2] * s]
}

pub(crate) fn dot(a: V3, b: V3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

pub(crate) fn cross(a: V3, b: V3) -> V3 {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}

pub(crate) fn norm(a: V3) -> f64 {
    dot(a, a).sqrt()
}

/// `a / |a|`, or `None` for a zero (or non-finite) vector.
pub(crate) fn normalize(a: V3) -> Option<V3> {
    let n = norm(a);
    (n > 0.0 && n.is_finite()).then(|| scale(a, 1.0 / n))
}

/// Twice the signed area of the 2-D triangle `(a, b, c)`: positive when counter-clockwise in a
/// y-up frame (the UV convention).
pub(crate) fn signed_area2_2d(a: [f32; 2], b: [f32; 2], c: [f32; 2]) -> f64 {
    let (ax, ay) = (a[0] as f64, a[1] as f64);
    (b[0] as f64 - ax) * (c[1] as f64 - ay) - (b[1] as f64 - ay) * (c[0] as f64 - ax)
}

/// Area-weighted per-vertex normals (unit length). Winding is trusted only locally: a vertex whose
/// incident normals cancel (or that no triangle uses) gets `+Z`, so every normal is valid for glTF.
pub(crate) fn vertex_normals(positions: &[[f32; 3]], triangles: &[[u32; 3]]) -> Vec<[f32; 3]> {
    let mut acc = vec![[0.0f64; 3]; positions.len()];
    for t in triangles {
        let [a, b, c] = t.map(|v| v3(positions[v as usize]));
        let n = cross(sub(b, a), sub(c, a));
        for &v in t {
            acc[v as usize] = add(acc[v as usize], n);
        }
    }
    acc.into_iter().map(|n| normalize(n).map_or([0.0, 0.0, 1.0], |u| u.map(|c| c as f32))).collect()
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

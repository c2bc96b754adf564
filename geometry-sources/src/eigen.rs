//! The eigenvector of the smallest eigenvalue of a symmetric 3×3 matrix (cyclic Jacobi rotations),
//! which is all PCA normal estimation needs. Jacobi is unconditionally stable for symmetric matrices
//! and converges in a handful of sweeps at 3×3; a 40-line solver saves a linear-algebra dependency.

/// Unit eigenvector of the smallest eigenvalue of the symmetric matrix `m` (only the upper triangle
/// is read). For repeated eigenvalues any unit vector of the eigenspace may be returned.
pub fn smallest_eigenvector(m: [[f64; 3]; 3]) -> [f64; 3] {
    let mut a = [[m[0][0], m[0][1], m[0][2]], [m[0][1], m[1][1], m[1][2]], [m[0][2], m[1][2], m[2][2]]];
    let mut v = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    let scale = a.iter().flatten().fold(0.0f64, |s, x| s.max(x.abs()));
    for _sweep in 0..32 {
        let off = a[0][1].abs() + a[0][2].abs() + a[1][2].abs();
        if off <= 1e-15 * scale || !off.is_finite() {
            break;
        }
        for (p, q) in [(0, 1), (0, 2), (1, 2)] {
            if a[p][q] == 0.0 {
                continue;
            }
            let theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
            let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
            let c = 1.0 / (t * t + 1.0).sqrt();
            let s = t * c;
            for row in &mut a {
                let (x, y) = (row[p], row[q]);
                row[p] = c * x - s * y;
                row[q] = s * x + c * y;
            }
            let (rp, rq) = (a[p], a[q]);
            a[p] = std::array::from_fn(|k| c * rp[k] - s * rq[k]);
            a[q] = std::array::from_fn(|k| s * rp[k] + c * rq[k]);
            for row in &mut v {
                let (x, y) = (row[p], row[q]);
                row[p] = c * x - s * y;
                row[q] = s * x + c * y;
            }
        }
    }
    let i = (0..3).fold(0, |b, k| if a[k][k] < a[b][b] { k } else { b });
    [v[0][i], v[1][i], v[2][i]]
}

#[cfg(test)]
mod tests {
    use super::*;

    fn mul(m: &[[f64; 3]; 3], x: [f64; 3]) -> [f64; 3] {
        std::array::from_fn(|r| (0..3).map(|k| m[r][k] * x[k]).sum())
    }

    #[test]
    fn finds_the_smallest_eigenvector() {
        // Diagonal, permuted.
        let e = smallest_eigenvector([[3.0, 0.0, 0.0], [0.0, 0.5, 0.0], [0.0, 0.0, 2.0]]);
        assert!((e[1].abs() - 1.0).abs() < 1e-12);
        // A rotated diagonal matrix R diag(5, 2, 0.1) R^T with a known smallest eigenvector.
        let n = {
            let v = [1.0f64, 2.0, -2.0];
            let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
            v.map(|x| x / l)
        };
        let u = [2.0 / 3.0, 1.0 / 3.0, 2.0 / 3.0]; // orthogonal to n
        let w = [n[1] * u[2] - n[2] * u[1], n[2] * u[0] - n[0] * u[2], n[0] * u[1] - n[1] * u[0]];
        let m: [[f64; 3]; 3] = std::array::from_fn(|r| {
            std::array::from_fn(|c| 5.0 * u[r] * u[c] + 2.0 * w[r] * w[c] + 0.1 * n[r] * n[c])
        });
        let e = smallest_eigenvector(m);
        let cos: f64 = (0..3).map(|k| e[k] * n[k]).sum();
        assert!((cos.abs() - 1.0).abs() < 1e-9, "{e:?} vs {n:?}");
        let me = mul(&m, e);
        assert!((0..3).all(|k| (me[k] - 0.1 * e[k]).abs() < 1e-9));
        // Degenerate inputs return a unit vector without panicking.
        for m in [[[0.0; 3]; 3], [[1.0; 3]; 3]] {
            let e = smallest_eigenvector(m);
            assert!(((e[0] * e[0] + e[1] * e[1] + e[2] * e[2]).sqrt() - 1.0).abs() < 1e-9);
        }
    }
}

//! Normal estimation for point clouds without normals: PCA over the `k` nearest neighbours (kiddo
//! k-d tree) gives each point an unoriented normal, and orientation is propagated over the k-NN graph
//! along a minimum spanning tree (Hoppe et al. 1992).
//!
//! **Orientation.** Edge weights are `1 - |n_i · n_j|`, so the tree crosses between nearly parallel
//! normals first and reaches creases and thin parts last; each point takes the sign that agrees with
//! its tree parent. Each connected part of the graph is seeded at its point farthest from the cloud's
//! centroid, oriented away from the centroid (at the farthest point of a closed or open surface, the
//! outward normal points away from the centroid).
//!
//! **Limits.** Two sheets closer than the neighbourhood size (thin walls, touching parts) can be
//! bridged and one of them flipped; a component whose farthest point is not on its outside (say a
//! small part inside a hollow shell) may be flipped as a whole; noise larger than the neighbourhood
//! makes PCA normals unreliable. Clouds with trustworthy normals should keep them.

use std::cmp::Reverse;
use std::collections::BinaryHeap;
use std::num::NonZero;

use glam::Vec3;
use nalgebra::{Matrix3, SymmetricEigen};
use rayon::prelude::*;

use crate::coords::V3;

/// Estimates outward unit normals for `points` from their `k` nearest neighbours (`k >= 3`,
/// including the point itself). Deterministic. Points whose neighbourhood is degenerate (all
/// coincident) get the direction away from the centroid.
pub fn estimate_normals(points: &[V3], k: usize) -> Vec<V3> {
    if points.is_empty() {
        return Vec::new();
    }
    let k = k.clamp(3, points.len().max(3));
    let tree = kiddo::ImmutableKdTree::<f32, 3>::new_from_slice(points);
    let qty = NonZero::new(k).unwrap_or(NonZero::<usize>::MIN);
    let neighbours: Vec<Vec<u32>> = points
        .par_iter()
        .map(|p| {
            tree.nearest_n::<kiddo::SquaredEuclidean>(p, qty).into_iter().map(|n| n.item as u32).collect()
        })
        .collect();
    let centroid = Vec3::from(centroid(points));
    let mut normals: Vec<Vec3> = neighbours.par_iter().map(|nb| Vec3::from(pca_normal(points, nb))).collect();
    orient(points, &neighbours, &mut normals, centroid);
    normals.into_iter().map(V3::from).collect()
}

fn centroid(points: &[V3]) -> V3 {
    let mut c = [0.0f64; 3];
    for p in points {
        for k in 0..3 {
            c[k] += f64::from(p[k]);
        }
    }
    c.map(|x| (x / points.len() as f64) as f32)
}

/// The direction of least variance of the neighbourhood (zero when it is degenerate).
fn pca_normal(points: &[V3], nb: &[u32]) -> V3 {
    let pts: Vec<[f64; 3]> = nb.iter().map(|&i| points[i as usize].map(f64::from)).collect();
    let n = pts.len() as f64;
    let mean: [f64; 3] = std::array::from_fn(|k| pts.iter().map(|p| p[k]).sum::<f64>() / n);
    let mut cov = [[0.0f64; 3]; 3];
    for p in &pts {
        let d: [f64; 3] = std::array::from_fn(|k| p[k] - mean[k]);
        for r in 0..3 {
            for c in r..3 {
                cov[r][c] += d[r] * d[c];
            }
        }
    }
    if cov.iter().flatten().all(|&x| x == 0.0) {
        return [0.0; 3];
    }
    let Some(e) = smallest_eigenvector(cov) else { return [0.0; 3] };
    let len = (e[0] * e[0] + e[1] * e[1] + e[2] * e[2]).sqrt();
    if len > 0.0 && len.is_finite() { e.map(|x| (x / len) as f32) } else { [0.0; 3] }
}

/// Iterations after which [`smallest_eigenvector`] gives up (nalgebra's default is no limit). A 3×3
/// matrix converges in a handful, so the cap only guards against an input that never does.
const EIGEN_MAX_ITERATIONS: usize = 100;

/// Unit eigenvector of the smallest eigenvalue of the symmetric matrix whose upper triangle is
/// `upper` (the lower one is not read), `None` if the solver does not converge. Its sign is
/// arbitrary: [`orient`] chooses every normal's sign, comparing only signs of dot products, so the
/// result does not depend on it. For a repeated smallest eigenvalue any unit vector of the
/// eigenspace may be returned.
fn smallest_eigenvector(upper: [[f64; 3]; 3]) -> Option<[f64; 3]> {
    // nalgebra reads the lower triangle: mirror the upper one into it.
    let m = Matrix3::from_fn(|r, c| upper[r.min(c)][r.max(c)]);
    let eigen = SymmetricEigen::try_new(m, f64::EPSILON, EIGEN_MAX_ITERATIONS)?;
    let v = eigen.eigenvectors.column(eigen.eigenvalues.imin());
    Some([v[0], v[1], v[2]])
}

/// Propagates a consistent sign over the symmetric k-NN graph (Prim's algorithm per component).
fn orient(points: &[V3], neighbours: &[Vec<u32>], normals: &mut [Vec3], centroid: Vec3) {
    let n = points.len();
    // Symmetric adjacency in CSR form: the k-NN relation is not symmetric.
    let mut degree = vec![0u32; n + 1];
    for (i, nb) in neighbours.iter().enumerate() {
        for &j in nb {
            if j as usize != i {
                degree[i] += 1;
                degree[j as usize] += 1;
            }
        }
    }
    let mut start = vec![0usize; n + 1];
    for i in 0..n {
        start[i + 1] = start[i] + degree[i] as usize;
    }
    let mut fill = start.clone();
    let mut adj = vec![0u32; start[n]];
    for (i, nb) in neighbours.iter().enumerate() {
        for &j in nb {
            if j as usize != i {
                adj[fill[i]] = j;
                fill[i] += 1;
                adj[fill[j as usize]] = i as u32;
                fill[j as usize] += 1;
            }
        }
    }
    // Points with degenerate neighbourhoods point away from the centroid.
    for (nrm, p) in normals.iter_mut().zip(points) {
        if *nrm == Vec3::ZERO {
            *nrm = (Vec3::from(*p) - centroid).normalize_or(Vec3::Z);
        }
    }
    // Components are seeded in order of decreasing distance from the centroid.
    let mut order: Vec<u32> = (0..n as u32).collect();
    let dist2 = |i: u32| (Vec3::from(points[i as usize]) - centroid).length_squared();
    order.sort_by(|&a, &b| dist2(b).total_cmp(&dist2(a)).then(a.cmp(&b)));
    let mut done = vec![false; n];
    let mut heap: BinaryHeap<Reverse<(u32, u32, u32)>> = BinaryHeap::new();
    for &seed in &order {
        if done[seed as usize] {
            continue;
        }
        let s = seed as usize;
        if normals[s].dot(Vec3::from(points[s]) - centroid) < 0.0 {
            normals[s] = -normals[s];
        }
        done[s] = true;
        push_edges(s, &adj[start[s]..start[s + 1]], normals, &done, &mut heap);
        while let Some(Reverse((_, parent, child))) = heap.pop() {
            let c = child as usize;
            if done[c] {
                continue;
            }
            done[c] = true;
            if normals[c].dot(normals[parent as usize]) < 0.0 {
                normals[c] = -normals[c];
            }
            push_edges(c, &adj[start[c]..start[c + 1]], normals, &done, &mut heap);
        }
    }
}

/// Queues the edges from `i` to unvisited neighbours, keyed by `1 - |cos|` as ordered float bits.
fn push_edges(
    i: usize,
    adj: &[u32],
    normals: &[Vec3],
    done: &[bool],
    heap: &mut BinaryHeap<Reverse<(u32, u32, u32)>>,
) {
    for &j in adj {
        if !done[j as usize] {
            let w = (1.0 - normals[i].dot(normals[j as usize]).abs()).max(0.0);
            heap.push(Reverse((w.to_bits(), i as u32, j)));
        }
    }
}

#[cfg(test)]
mod tests {
    use glam::{DMat3, DVec3};

    use super::*;

    #[test]
    fn finds_the_smallest_eigenvector_from_the_upper_triangle() {
        // Diagonal, permuted.
        let e = smallest_eigenvector([[3.0, 0.0, 0.0], [0.0, 0.5, 0.0], [0.0, 0.0, 2.0]]).unwrap();
        assert!((e[1].abs() - 1.0).abs() < 1e-12);
        // A rotated diagonal matrix R diag(5, 2, 0.1) R^T with a known smallest eigenvector; its
        // lower triangle is overwritten with garbage, which must not be read.
        let n = DVec3::new(1.0, 2.0, -2.0).normalize();
        let u = DVec3::new(2.0, 1.0, 2.0) / 3.0; // orthogonal to n
        let w = n.cross(u);
        let m: [[f64; 3]; 3] = std::array::from_fn(|r| {
            std::array::from_fn(|c| 5.0 * u[r] * u[c] + 2.0 * w[r] * w[c] + 0.1 * n[r] * n[c])
        });
        let mut upper = m;
        (upper[1][0], upper[2][0], upper[2][1]) = (7.0, -3.0, 11.0);
        let e = DVec3::from(smallest_eigenvector(upper).unwrap());
        assert!((e.dot(n).abs() - 1.0).abs() < 1e-9, "{e:?} vs {n:?}");
        let me = DMat3::from_cols_array_2d(&m) * e; // m is symmetric: rows or columns alike
        assert!((me - 0.1 * e).abs().max_element() < 1e-9);
        // Degenerate inputs return a unit vector without panicking.
        for m in [[[0.0; 3]; 3], [[1.0; 3]; 3]] {
            let e = DVec3::from(smallest_eigenvector(m).unwrap());
            assert!((e.length() - 1.0).abs() < 1e-9);
        }
    }

    #[test]
    fn sphere_normals_are_radial_and_outward() {
        // A Fibonacci sphere of radius 2 around (5, 0, 0).
        let n = 2000;
        let pts: Vec<V3> = (0..n)
            .map(|i| {
                let z = 1.0 - 2.0 * (i as f32 + 0.5) / n as f32;
                let r = (1.0 - z * z).sqrt();
                let phi = i as f32 * 2.399_963;
                [5.0 + 2.0 * r * phi.cos(), 2.0 * r * phi.sin(), 2.0 * z]
            })
            .collect();
        let normals = estimate_normals(&pts, 12);
        for (p, nrm) in pts.iter().zip(&normals) {
            let radial = (Vec3::from(*p) - Vec3::new(5.0, 0.0, 0.0)).normalize();
            assert!(radial.dot(Vec3::from(*nrm)) > 0.98, "normal {nrm:?} at {p:?}");
        }
        assert!(estimate_normals(&[], 8).is_empty());
        // Coincident points do not panic.
        let same = estimate_normals(&[[1.0, 1.0, 1.0]; 5], 8);
        assert!(same.iter().all(|&n| (Vec3::from(n).length() - 1.0).abs() < 1e-5));
    }
}

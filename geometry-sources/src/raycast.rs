//! First-hit ray casting against a triangle mesh, and the nearest point of its surface to any point
//! (`crate::appearance` looks colours up there), on `parry3d`'s bounding-volume hierarchy.
//!
//! Chosen by measurement on the 609k-triangle `unruly_vase.obj` (BENCHMARKS.md): parry3d's BVH built
//! faster than the `bvh` crate's and our own binned-SAH BVH (since removed; see the history of
//! `geometry-sources/src/bvh.rs`) and cast rays as fast as our own and about twice as fast as `bvh`.
//! Zero-area triangles are left out (no ray can hit them), so NeRF meshes full of welded slivers cost
//! nothing extra; the hierarchy sees a triangle soup, so non-manifold and disconnected input is fine.

use parry3d::math::Vec3;
use parry3d::query::{PointQueryWithLocation, Ray, RayCast};

use crate::coords::V3;
use crate::mesh::TriMesh;

/// The nearest intersection of a ray with the mesh.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    /// Ray parameter: the hit point is `origin + t * dir`.
    pub t: f32,
    /// Index of the face in the mesh the caster was built from.
    pub face: u32,
}

/// A ray caster over the non-degenerate triangles of one mesh (it copies what it needs). Invariant:
/// `faces[i]` is the mesh face of parry's triangle `i`; `shape` is `None` when there are none.
pub struct RayCaster {
    shape: Option<parry3d::shape::TriMesh>,
    faces: Vec<u32>,
}

impl std::fmt::Debug for RayCaster {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RayCaster").field("triangles", &self.faces.len()).finish()
    }
}

impl RayCaster {
    /// Builds the hierarchy over the faces of `mesh` with positive area.
    pub fn build(mesh: &TriMesh) -> RayCaster {
        let faces: Vec<u32> =
            (0..mesh.triangles.len()).filter(|&f| mesh.face_area(f) > 0.0).map(|f| f as u32).collect();
        let vertices: Vec<Vec3> = mesh.positions.iter().map(|p| Vec3::from(*p)).collect();
        let indices: Vec<[u32; 3]> = faces.iter().map(|&f| mesh.triangles[f as usize]).collect();
        // `new` only fails on an empty index list (validated meshes have indices in range).
        let shape = parry3d::shape::TriMesh::new(vertices, indices).ok();
        RayCaster { shape, faces }
    }

    /// Number of triangles in the hierarchy (faces with positive area).
    pub fn triangle_count(&self) -> usize {
        self.faces.len()
    }

    /// The nearest hit with `t` in `[0, t_max]`, if any; both sides of every triangle count.
    /// `dir` need not be normalised but must be non-zero and finite.
    pub fn intersect(&self, origin: V3, dir: V3, t_max: f32) -> Option<Hit> {
        let shape = self.shape.as_ref()?;
        let ray = Ray::new(Vec3::from(origin), Vec3::from(dir));
        let hit = shape.cast_local_ray_and_get_normal(&ray, t_max, false)?;
        let face = *self.faces.get(hit.subshape as usize)?;
        Some(Hit { t: hit.time_of_impact, face })
    }

    /// The point of the surface nearest `p`: its face and its barycentrics there. `None` when the
    /// hierarchy is empty or `p` is not finite.
    pub fn nearest(&self, p: V3) -> Option<(u32, [f32; 3])> {
        let shape = self.shape.as_ref().filter(|_| p.iter().all(|x| x.is_finite()))?;
        let (projection, (triangle, location)) =
            shape.project_local_point_and_get_location(Vec3::from(p), false);
        let face = *self.faces.get(triangle as usize)?;
        let bary = location.barycentric_coordinates().unwrap_or_else(|| {
            let t = shape.triangle(triangle);
            barycentric(projection.point, [t.a, t.b, t.c])
        });
        Some((face, bary))
    }
}

/// Barycentric coordinates of `p` (on the triangle's plane) in triangle `t`; the first corner for
/// a degenerate triangle.
fn barycentric(p: Vec3, t: [Vec3; 3]) -> [f32; 3] {
    let (e1, e2, d) = (t[1] - t[0], t[2] - t[0], p - t[0]);
    let (d11, d12, d22) = (e1.dot(e1), e1.dot(e2), e2.dot(e2));
    let (d1, d2) = (d.dot(e1), d.dot(e2));
    let det = d11 * d22 - d12 * d12;
    if det <= 0.0 || !det.is_finite() {
        return [1.0, 0.0, 0.0];
    }
    let v = (d22 * d1 - d12 * d2) / det;
    let w = (d11 * d2 - d12 * d1) / det;
    [1.0 - v - w, v, w]
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    /// Brute-force nearest hit (two-sided Möller–Trumbore), for comparison.
    fn brute(mesh: &TriMesh, o: V3, d: V3) -> Option<(f32, u32)> {
        let (o, d) = (Vec3::from(o), Vec3::from(d));
        let mut best: Option<(f32, u32)> = None;
        for f in 0..mesh.triangles.len() {
            let [a, b, c] = mesh.corners(f).map(Vec3::from);
            let (e1, e2) = (b - a, c - a);
            let p = d.cross(e2);
            let det = e1.dot(p);
            if det == 0.0 {
                continue;
            }
            let s = o - a;
            let u = s.dot(p) / det;
            let q = s.cross(e1);
            let v = d.dot(q) / det;
            let t = e2.dot(q) / det;
            if u >= 0.0 && v >= 0.0 && u + v <= 1.0 && t >= 0.0 && best.is_none_or(|(bt, _)| t < bt) {
                best = Some((t, f as u32));
            }
        }
        best
    }

    fn random_soup(n: usize, seed: u64) -> TriMesh {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let mut mesh = TriMesh::default();
        for i in 0..n {
            let c: V3 = std::array::from_fn(|_| rng.random_range(-1.0..1.0));
            for _ in 0..3 {
                mesh.positions.push(std::array::from_fn(|k| c[k] + rng.random_range(-0.1..0.1)));
            }
            let b = 3 * i as u32;
            mesh.triangles.push([b, b + 1, b + 2]);
        }
        // Degenerate triangles must not disturb anything.
        mesh.triangles.push([0, 0, 1]);
        mesh
    }

    #[test]
    fn agrees_with_brute_force_on_a_random_soup() {
        let mesh = random_soup(2000, 1);
        let caster = RayCaster::build(&mesh);
        assert_eq!(caster.triangle_count(), 2000);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(2);
        let mut hits = 0;
        for _ in 0..2000 {
            let o: V3 = std::array::from_fn(|_| rng.random_range(-2.0..2.0));
            let d: V3 = std::array::from_fn(|_| rng.random_range(-1.0..1.0));
            let got = caster.intersect(o, d, f32::MAX);
            let want = brute(&mesh, o, d);
            match (got, want) {
                (Some(h), Some((t, f))) => {
                    hits += 1;
                    assert!((h.t - t).abs() <= 1e-4 * t.max(1.0), "ray {o:?} {d:?}: {h:?} vs {t}");
                    // Ties between overlapping triangles may pick either face.
                    assert!(h.face == f || (h.t - t).abs() < 1e-5);
                }
                (None, None) => {}
                other => panic!("ray {o:?} {d:?}: {other:?}"),
            }
        }
        assert!(hits > 200, "only {hits} hits: the test rays do not exercise the tree");
    }

    #[test]
    fn the_nearest_point_is_on_the_nearest_face() {
        let mesh = random_soup(500, 3);
        let caster = RayCaster::build(&mesh);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(4);
        for _ in 0..300 {
            let p: V3 = std::array::from_fn(|_| rng.random_range(-1.5..1.5));
            let (face, bary) = caster.nearest(p).unwrap();
            assert!(bary.iter().all(|&b| b > -1e-4) && (bary.iter().sum::<f32>() - 1.0).abs() < 1e-4);
            let c = mesh.corners(face as usize);
            let q = Vec3::from(std::array::from_fn(|k| (0..3).map(|i| bary[i] * c[i][k]).sum::<f32>()));
            let got = q.distance(Vec3::from(p));
            // No other face's corners or centre is nearer than the point found.
            for f in 0..500 {
                let c = mesh.corners(f).map(Vec3::from);
                for x in [c[0], c[1], c[2], (c[0] + c[1] + c[2]) / 3.0] {
                    assert!(x.distance(Vec3::from(p)) >= got - 1e-5, "face {f} is nearer than face {face}");
                }
            }
        }
        assert!(caster.nearest([f32::NAN, 0.0, 0.0]).is_none());
    }

    #[test]
    fn only_degenerate_triangles_hit_nothing() {
        let mesh = TriMesh {
            positions: vec![[0.0; 3], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]],
            triangles: vec![[0, 1, 2]],
            uv: None,
        };
        let caster = RayCaster::build(&mesh);
        assert_eq!(caster.triangle_count(), 0);
        assert!(caster.intersect([0.5, 0.0, 1.0], [0.0, 0.0, -1.0], f32::MAX).is_none());
        assert!(caster.nearest([0.5, 0.0, 1.0]).is_none());
    }
}

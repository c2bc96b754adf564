//! First-hit ray casting against a triangle mesh, on `parry3d`'s bounding-volume hierarchy.
//!
//! Chosen by measurement on the 609k-triangle `unruly_vase.obj` (BENCHMARKS.md): parry3d's BVH built
//! faster than the `bvh` crate's and our own binned-SAH BVH (since removed; see the history of
//! `geometry-sources/src/bvh.rs`) and cast rays as fast as our own and about twice as fast as `bvh`.
//! Zero-area triangles are left out (no ray can hit them), so NeRF meshes full of welded slivers cost
//! nothing extra; the hierarchy sees a triangle soup, so non-manifold and disconnected input is fine.

use parry3d::math::Vec3;
use parry3d::query::{Ray, RayCast};

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
    fn only_degenerate_triangles_hit_nothing() {
        let mesh = TriMesh {
            positions: vec![[0.0; 3], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]],
            triangles: vec![[0, 1, 2]],
            uv: None,
        };
        let caster = RayCaster::build(&mesh);
        assert_eq!(caster.triangle_count(), 0);
        assert!(caster.intersect([0.5, 0.0, 1.0], [0.0, 0.0, -1.0], f32::MAX).is_none());
    }
}

//! Locating the shared test data (`shared/data/` beside the workspace), for tests and benchmarks,
//! and an analytic test source (the unit sphere) for trainer tests in other crates.
//!
//! Not part of the API: it lives in the crate only so unit tests, integration tests and examples
//! share one rule. A test that needs the data and cannot find it **fails** with a message saying where
//! it looked; it never skips.

use std::path::PathBuf;

use glam::Vec3;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::{Aabb, BuildContext, GeometryError, GeometrySource, Similarity, SourceRegistry, SurfaceSamples};

/// Uniform samples on the unit sphere (canonical frame), normals pointing out.
pub struct UnitSphere;

impl GeometrySource for UnitSphere {
    fn kind(&self) -> &str {
        "sphere"
    }
    fn sample(&self, n: usize, seed: u64) -> SurfaceSamples {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let positions: Vec<[f32; 3]> = (0..n)
            .map(|_| {
                let z: f32 = rng.random_range(-1.0..1.0);
                let a: f32 = rng.random_range(0.0..std::f32::consts::TAU);
                let r = (1.0 - z * z).sqrt();
                [r * a.cos(), r * a.sin(), z]
            })
            .collect();
        SurfaceSamples { normals: positions.clone(), positions }
    }
    fn bounds(&self) -> Aabb {
        Aabb { min: [-1.0; 3], max: [1.0; 3] }
    }
    fn to_canonical(&self) -> Similarity {
        Similarity::IDENTITY
    }
    fn describe(&self) -> String {
        "unit sphere".into()
    }
}

/// Builds [`UnitSphere`]; it has no options, so any key is an error.
fn build_unit_sphere(
    options: &toml::Table,
    _: &BuildContext,
) -> Result<Box<dyn GeometrySource>, GeometryError> {
    match options.keys().next() {
        None => Ok(Box::new(UnitSphere)),
        Some(k) => Err(GeometryError::Options {
            source_name: "sphere".into(),
            message: format!("unknown field `{k}`, expected nothing"),
        }),
    }
}

/// A registry with just [`UnitSphere`], as `source = "sphere"`.
pub fn sphere_sources() -> SourceRegistry {
    let mut r = SourceRegistry::new();
    r.register("sphere", "unit sphere (tests)", build_unit_sphere);
    r
}

/// A closed box of 12 triangles, counter-clockwise seen from outside, centred on `center` with
/// half-extents `half`: a mesh whose area, visibility and normals every test can work out by hand.
pub fn closed_box(center: [f32; 3], half: [f32; 3]) -> crate::TriMesh {
    let p =
        |x: f32, y: f32, z: f32| [center[0] + x * half[0], center[1] + y * half[1], center[2] + z * half[2]];
    let positions = vec![
        p(-1., -1., -1.),
        p(1., -1., -1.),
        p(1., 1., -1.),
        p(-1., 1., -1.),
        p(-1., -1., 1.),
        p(1., -1., 1.),
        p(1., 1., 1.),
        p(-1., 1., 1.),
    ];
    let triangles = vec![
        [0, 2, 1],
        [0, 3, 2],
        [4, 5, 6],
        [4, 6, 7],
        [0, 1, 5],
        [0, 5, 4],
        [2, 3, 7],
        [2, 7, 6],
        [1, 2, 6],
        [1, 6, 5],
        [0, 4, 7],
        [0, 7, 3],
    ];
    crate::TriMesh { positions, triangles, uv: None }
}

/// `a` and `b` as one mesh (`b`'s vertices after `a`'s).
pub fn merged(a: crate::TriMesh, b: &crate::TriMesh) -> crate::TriMesh {
    let off = a.positions.len() as u32;
    let mut m = a;
    m.positions.extend(&b.positions);
    m.triangles.extend(b.triangles.iter().map(|t| t.map(|v| v + off)));
    m
}

/// `$NUVO_DATA` if set, else `<workspace root>/../shared/data`.
pub fn data_dir() -> PathBuf {
    match std::env::var_os("NUVO_DATA") {
        Some(d) => PathBuf::from(d),
        None => PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..").join("..").join("shared").join("data"),
    }
}

/// The path of `rel` inside [`data_dir`]; panics with a clear message when it is missing (test-only).
pub fn data_file(rel: &str) -> PathBuf {
    let p = data_dir().join(rel);
    assert!(
        p.is_file(),
        "test data {} not found; set NUVO_DATA to the folder holding meshes/, density/ and pointclouds/ \
         (default: <workspace>/../shared/data)",
        p.display()
    );
    p
}

/// Distances from points to a triangle mesh, for checking samples against the surface they should lie
/// on: a k-d tree over dense area-uniform samples finds candidate triangles, and the exact
/// point-triangle distance to the candidates is returned.
pub struct MeshDistance {
    mesh: crate::TriMesh,
    tree: kiddo::ImmutableKdTree<f32, 3>,
    sample_faces: Vec<u32>,
}

impl MeshDistance {
    /// Prepares `mesh` (in whatever frame the query points will be in) with `samples` surface samples.
    pub fn new(mesh: crate::TriMesh, samples: usize) -> MeshDistance {
        use rand::{Rng, SeedableRng};
        let areas = crate::sampling::uniform::AreaSampler::new(&mesh).expect("mesh with area");
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(99);
        let mut points = Vec::with_capacity(samples);
        let mut sample_faces = Vec::with_capacity(samples);
        for _ in 0..samples {
            let f = areas.face(rng.random());
            let (b1, b2) = crate::sampling::uniform::uniform_barycentric(rng.random(), rng.random());
            points.push(crate::sampling::point_on(&mesh, f, b1, b2));
            sample_faces.push(f as u32);
        }
        let tree = kiddo::ImmutableKdTree::new_from_slice(&points);
        MeshDistance { mesh, tree, sample_faces }
    }

    /// The distance from `p` to the nearest of the triangles owning the 8 samples nearest to `p`.
    pub fn distance(&self, p: [f32; 3]) -> f32 {
        let nn =
            self.tree.nearest_n::<kiddo::SquaredEuclidean>(&p, std::num::NonZero::new(8).expect("8 > 0"));
        nn.iter()
            .map(|n| {
                let f = self.sample_faces[n.item as usize] as usize;
                point_triangle_distance(p, self.mesh.corners(f))
            })
            .fold(f32::INFINITY, f32::min)
    }
}

/// Exact distance from `p` to the triangle `[a, b, c]` (closest-point construction from Ericson,
/// *Real-Time Collision Detection*, 5.1.5).
pub fn point_triangle_distance(p: [f32; 3], [a, b, c]: [[f32; 3]; 3]) -> f32 {
    let [p, a, b, c] = [p, a, b, c].map(Vec3::from);
    let (ab, ac, ap) = (b - a, c - a, p - a);
    let (d1, d2) = (ab.dot(ap), ac.dot(ap));
    let closest = if d1 <= 0.0 && d2 <= 0.0 {
        a
    } else {
        let bp = p - b;
        let (d3, d4) = (ab.dot(bp), ac.dot(bp));
        let cp = p - c;
        let (d5, d6) = (ab.dot(cp), ac.dot(cp));
        let vc = d1 * d4 - d3 * d2;
        let vb = d5 * d2 - d1 * d6;
        let va = d3 * d6 - d5 * d4;
        if d3 >= 0.0 && d4 <= d3 {
            b
        } else if d6 >= 0.0 && d5 <= d6 {
            c
        } else if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
            a + d1 / (d1 - d3) * ab
        } else if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
            a + d2 / (d2 - d6) * ac
        } else if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
            b + (d4 - d3) / ((d4 - d3) + (d5 - d6)) * (c - b)
        } else {
            let denom = 1.0 / (va + vb + vc);
            a + vb * denom * ab + vc * denom * ac
        }
    };
    p.distance(closest)
}

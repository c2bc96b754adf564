//! Area-uniform sampling on a triangle mesh, as the paper does for well-behaved meshes: pick a
//! triangle by inverse-transform sampling of the cumulative area, then a uniform point on it.

use rand::Rng;

use super::{SurfaceNormals, point_on};
use crate::mesh::TriMesh;
use crate::seeding::par_generate;
use crate::source::SurfaceSamples;

/// The cumulative-area table of a mesh. Invariant: `cdf` is strictly increasing and non-empty, and
/// `faces[i]` is the face whose area is `cdf[i] - cdf[i-1]`; zero-area faces are left out.
#[derive(Clone, Debug)]
pub struct AreaSampler {
    cdf: Vec<f64>,
    faces: Vec<u32>,
}

impl AreaSampler {
    /// Builds the table; an error when the mesh has no face of positive finite area.
    pub fn new(mesh: &TriMesh) -> Result<Self, String> {
        let mut cdf = Vec::with_capacity(mesh.triangles.len());
        let mut faces = Vec::with_capacity(mesh.triangles.len());
        let mut total = 0.0f64;
        for f in 0..mesh.triangles.len() {
            let a = f64::from(mesh.face_area(f));
            if a > 0.0 && a.is_finite() {
                total += a;
                cdf.push(total);
                faces.push(f as u32);
            }
        }
        if faces.is_empty() {
            return Err(format!(
                "all {} faces are degenerate (zero area), so there is no surface to sample",
                mesh.triangles.len()
            ));
        }
        Ok(AreaSampler { cdf, faces })
    }

    /// Total surface area.
    pub fn total_area(&self) -> f64 {
        self.cdf.last().copied().unwrap_or(0.0)
    }

    /// The face for a uniform `u` in `[0, 1)`.
    pub fn face(&self, u: f64) -> usize {
        let target = u * self.total_area();
        let i = self.cdf.partition_point(|&c| c <= target).min(self.faces.len() - 1);
        self.faces[i] as usize
    }
}

/// Uniform barycentric coordinates `(b1, b2)` on a triangle from two uniforms (the square-root
/// warp, which is area-preserving).
pub(crate) fn uniform_barycentric(r1: f32, r2: f32) -> (f32, f32) {
    let s = r1.sqrt();
    (s * (1.0 - r2), s * r2)
}

/// Draws `n` area-uniform samples of `mesh` (deterministic in `(n, seed)`).
pub fn sample_uniform(
    mesh: &TriMesh,
    areas: &AreaSampler,
    normals: &SurfaceNormals,
    n: usize,
    seed: u64,
) -> SurfaceSamples {
    let pairs = par_generate(n, seed, 0x756e_6966, |rng, count| {
        (0..count)
            .map(|_| {
                let f = areas.face(rng.random::<f64>());
                let (b1, b2) = uniform_barycentric(rng.random(), rng.random());
                (point_on(mesh, f, b1, b2), normals.at(mesh, f, b1, b2))
            })
            .collect()
    });
    let (positions, normals) = pairs.into_iter().unzip();
    SurfaceSamples { positions, normals }
}

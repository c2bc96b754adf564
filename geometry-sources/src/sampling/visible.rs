//! Visible-surface sampling, the paper's mode for meshes extracted from NeRFs: cast random camera
//! rays and keep the first hit of each. Geometry that no camera sees (interior bubbles, the inside
//! of a closed shell, faces hidden behind others) is never sampled, which is the point.

use glam::Vec3;
use rand::Rng;
use rayon::prelude::*;

use super::{SurfaceNormals, barycentric};
use crate::camera::{CameraRig, Ray};
use crate::coords::V3;
use crate::mesh::TriMesh;
use crate::raycast::RayCaster;
use crate::seeding::{chunk_rng, par_generate};
use crate::source::SurfaceSamples;

/// Rays cast at construction to check that the cameras see the mesh at all.
const PROBE_RAYS: usize = 16_384;
/// A sampling chunk gives up drawing rays after this many per requested sample and fills the rest
/// from the probe hits (only reachable when the hit rate is absurdly low; keeps sampling bounded).
const MAX_ATTEMPTS_PER_SAMPLE: usize = 20_000;

/// A ray caster for one mesh and one camera rig. Invariant: `probe_hits` is non-empty.
#[derive(Debug)]
pub struct VisibleSampler {
    caster: RayCaster,
    rig: CameraRig,
    probe_hits: Vec<(V3, V3)>,
    hit_rate: f64,
}

impl VisibleSampler {
    /// Builds the BVH and probes the cameras; an error when none of the probe rays hits the mesh
    /// (cameras looking away, a camera file in the wrong coordinates, ...).
    pub fn new(mesh: &TriMesh, rig: CameraRig, normals: &SurfaceNormals) -> Result<Self, String> {
        let caster = RayCaster::build(mesh);
        let probes: Vec<Option<(V3, V3)>> = (0..PROBE_RAYS.div_ceil(1024))
            .into_par_iter()
            .flat_map_iter(|c| {
                let mut rng = chunk_rng(0x5052_4f42, 0x7072_6f62, c as u64);
                (0..1024).map(|_| rig.random_ray(&mut rng)).collect::<Vec<_>>()
            })
            .map(|ray| first_hit(&caster, mesh, normals, &ray))
            .collect();
        let total = probes.len();
        let probe_hits: Vec<(V3, V3)> = probes.into_iter().flatten().collect();
        if probe_hits.is_empty() {
            return Err(format!(
                "none of {total} camera rays ({}) hit the mesh; check the camera poses and the mesh",
                rig.describe()
            ));
        }
        let hit_rate = probe_hits.len() as f64 / total as f64;
        Ok(VisibleSampler { caster, rig, probe_hits, hit_rate })
    }

    /// Fraction of camera rays that hit the mesh (measured at construction).
    pub fn hit_rate(&self) -> f64 {
        self.hit_rate
    }

    /// The ray caster (for benchmarks and tests).
    pub fn caster(&self) -> &RayCaster {
        &self.caster
    }

    /// The camera rig.
    pub fn rig(&self) -> &CameraRig {
        &self.rig
    }

    /// Draws `n` first hits of random camera rays; rays that miss are redrawn. Normals face the
    /// camera that saw the point (NeRF meshes' winding is not trustworthy).
    pub fn sample(&self, mesh: &TriMesh, normals: &SurfaceNormals, n: usize, seed: u64) -> SurfaceSamples {
        let pairs = par_generate(n, seed, 0x7669_7369, |rng, count| {
            let mut out = Vec::with_capacity(count);
            let mut attempts = 0usize;
            while out.len() < count && attempts < count * MAX_ATTEMPTS_PER_SAMPLE {
                attempts += 1;
                let ray = self.rig.random_ray(rng);
                if let Some(hit) = first_hit(&self.caster, mesh, normals, &ray) {
                    out.push(hit);
                }
            }
            while out.len() < count {
                out.push(self.probe_hits[rng.random_range(0..self.probe_hits.len())]);
            }
            out
        });
        let (positions, normals) = pairs.into_iter().unzip();
        SurfaceSamples { positions, normals }
    }
}

/// The first hit of `ray` with its normal turned towards the ray's origin.
fn first_hit(caster: &RayCaster, mesh: &TriMesh, normals: &SurfaceNormals, ray: &Ray) -> Option<(V3, V3)> {
    let hit = caster.intersect(ray.origin, ray.dir, f32::MAX)?;
    let f = hit.face as usize;
    let p = ray.at(hit.t);
    let (b1, b2) = barycentric(mesh, f, p);
    let n = Vec3::from(normals.at(mesh, f, b1, b2));
    let n = if n.dot(Vec3::from(ray.dir)) > 0.0 { -n } else { n };
    Some((p, n.to_array()))
}

//! Measurable properties of a triangle mesh that decide how to sample it: how fragmented it is and
//! how much of its surface cannot be seen from outside.
//!
//! A clean surface (a scan, a CAD part, an artist's model) is one or a few pieces, all of it visible
//! from somewhere outside, and area-uniform sampling is right for it. A marching-cubes mesh of a
//! neural field has thousands of pieces (floaters), and sheets hidden inside the object (bubbles,
//! inner walls) that uniform sampling would feed to the networks as if they were surface. The
//! profile measures both, so a caller can choose by rule and say why (`nuvo unwrap` does).
//!
//! **Hidden area.** A point of the surface is *seen* when at least one of [`PROFILE_DIRECTIONS`]
//! random rays leaving it (both sides of the surface count, so the winding does not matter) escapes
//! the mesh's bounding sphere without hitting another face. The hidden area fraction is the share
//! of [`PROFILE_POINTS`] area-uniform points that no ray escapes from. A point in a narrow crevice can
//! be counted hidden by chance, so small values (a few percent) are normal on clean meshes.
//!
//! Deterministic: a pure function of the mesh and the seed, independent of the thread count.

use glam::Vec3;
use rayon::prelude::*;
use serde::Serialize;

use crate::camera::random_unit_vector;
use crate::coords::V3;
use crate::frame::Aabb;
use crate::mesh::TriMesh;
use crate::raycast::RayCaster;
use crate::sampling::uniform::{AreaSampler, sample_uniform};
use crate::sampling::{NormalMode, SurfaceNormals};
use crate::seeding::chunk_rng;

/// Area-uniform points the hidden-area estimate tests.
pub const PROFILE_POINTS: usize = 8192;
/// Random directions tried per point before it counts as hidden.
pub const PROFILE_DIRECTIONS: usize = 48;
/// A component holding less than this fraction of the total area counts as a fragment (a floater,
/// a crumb of a marching-cubes mesh).
pub const FRAGMENT_AREA: f64 = 1e-3;

/// What [`profile_mesh`] measured.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct MeshProfile {
    /// Vertices of the mesh.
    pub vertices: usize,
    /// Faces of the mesh.
    pub faces: usize,
    /// Faces of zero area.
    pub degenerate_faces: usize,
    /// Pieces connected through shared vertices.
    pub components: usize,
    /// Share of the total area in the largest piece.
    pub largest_component_area: f64,
    /// Pieces holding less than [`FRAGMENT_AREA`] of the area each.
    pub fragments: usize,
    /// The fragments' summed share of the area.
    pub fragment_area: f64,
    /// Share of the surface no tested ray escapes from (module docs); a sampling estimate over
    /// [`PROFILE_POINTS`] points, so its standard error is at most about 0.006.
    pub hidden_area: f64,
    /// Of the rays that escaped, the share that left through the front of their face (the side
    /// its winding normal points to): near 1 for a mesh wound counter-clockwise seen from outside,
    /// near 0 for one wound inside out, near ½ for open sheets seen from both sides. 1 when no ray
    /// escaped.
    pub outward_escapes: f64,
}

/// Measures `mesh` (module docs). `seed` picks the test points and directions. A mesh without any
/// face of positive area has nothing to measure: every fraction is then 0.
pub fn profile_mesh(mesh: &TriMesh, seed: u64) -> MeshProfile {
    let areas: Vec<f64> = (0..mesh.triangles.len()).map(|f| f64::from(mesh.face_area(f))).collect();
    let total: f64 = areas.iter().filter(|a| a.is_finite()).sum();
    let (labels, components) = vertex_components(mesh);
    let mut component_area = vec![0.0f64; components];
    for (f, t) in mesh.triangles.iter().enumerate() {
        if areas[f].is_finite() {
            component_area[labels[t[0] as usize] as usize] += areas[f];
        }
    }
    let share = |a: f64| if total > 0.0 { a / total } else { 0.0 };
    let largest = component_area.iter().copied().fold(0.0, f64::max);
    let fragment: Vec<f64> = component_area.iter().copied().filter(|&a| share(a) < FRAGMENT_AREA).collect();
    let (hidden_area, outward_escapes) = visibility(mesh, seed);
    MeshProfile {
        vertices: mesh.positions.len(),
        faces: mesh.triangles.len(),
        degenerate_faces: areas.iter().filter(|&&a| a <= 0.0).count(),
        components,
        largest_component_area: share(largest),
        fragments: fragment.len(),
        fragment_area: share(fragment.iter().fold(0.0, |a, b| a + b)),
        hidden_area,
        outward_escapes,
    }
}

/// Component label of every vertex (through the faces; an unreferenced vertex is its own component,
/// but is not counted) and the number of components that have faces.
fn vertex_components(mesh: &TriMesh) -> (Vec<u32>, usize) {
    let n = mesh.positions.len();
    let mut parent: Vec<u32> = (0..n as u32).collect();
    fn find(parent: &mut [u32], mut x: u32) -> u32 {
        while parent[x as usize] != x {
            parent[x as usize] = parent[parent[x as usize] as usize];
            x = parent[x as usize];
        }
        x
    }
    for t in &mesh.triangles {
        for k in 1..3 {
            let (a, b) = (find(&mut parent, t[0]), find(&mut parent, t[k]));
            if a != b {
                parent[a.max(b) as usize] = a.min(b);
            }
        }
    }
    let mut used = vec![false; n];
    for t in &mesh.triangles {
        for &v in t {
            used[v as usize] = true;
        }
    }
    let mut label = vec![u32::MAX; n];
    let mut count = 0u32;
    let mut out = vec![0u32; n];
    for v in 0..n as u32 {
        let r = find(&mut parent, v) as usize;
        if !used[v as usize] {
            continue;
        }
        if label[r] == u32::MAX {
            label[r] = count;
            count += 1;
        }
        out[v as usize] = label[r];
    }
    (out, count as usize)
}

/// The hidden area fraction and the share of escapes through the front (module docs, [`MeshProfile`]).
fn visibility(mesh: &TriMesh, seed: u64) -> (f64, f64) {
    let Ok(sampler) = AreaSampler::new(mesh) else { return (0.0, 1.0) };
    let Some(bounds) = mesh.bounds() else { return (0.0, 1.0) };
    let normals = SurfaceNormals::new(mesh, NormalMode::Face);
    let samples = sample_uniform(mesh, &sampler, &normals, PROFILE_POINTS, seed);
    let caster = RayCaster::build(mesh);
    let (center, radius) = sphere_of(&bounds);
    // Rays start this far off the surface so they do not hit their own face.
    let offset = 1e-5 * radius.max(f32::MIN_POSITIVE);
    const CHUNK: usize = 256;
    let chunks = samples.positions.len().div_ceil(CHUNK);
    // Per chunk: (points from which nothing escaped, escapes through the front, escapes).
    let (hidden, front, escaped) = (0..chunks)
        .into_par_iter()
        .map(|c| {
            let mut rng = chunk_rng(seed, 0x6869_6464, c as u64);
            let range = c * CHUNK..((c + 1) * CHUNK).min(samples.positions.len());
            let mut counts = (0usize, 0usize, 0usize);
            for k in range {
                let (p, n) = (samples.positions[k], samples.normals[k]);
                let exit = (0..PROFILE_DIRECTIONS)
                    .map(|_| random_unit_vector(&mut rng))
                    .find(|&d| escapes(&caster, p, d, offset, center, radius));
                match exit {
                    None => counts.0 += 1,
                    Some(d) => {
                        counts.1 += usize::from(Vec3::from(d).dot(Vec3::from(n)) > 0.0);
                        counts.2 += 1;
                    }
                }
            }
            counts
        })
        .reduce(|| (0, 0, 0), |a, b| (a.0 + b.0, a.1 + b.1, a.2 + b.2));
    let outward = if escaped == 0 { 1.0 } else { front as f64 / escaped as f64 };
    (hidden as f64 / samples.positions.len().max(1) as f64, outward)
}

/// Whether the ray from `p` along the unit `dir` leaves the sphere `(center, radius)` unobstructed.
fn escapes(caster: &RayCaster, p: V3, dir: V3, offset: f32, center: V3, radius: f32) -> bool {
    let start = Vec3::from(p) + offset * Vec3::from(dir);
    let reach = start.distance(Vec3::from(center)) + radius;
    caster.intersect(start.to_array(), dir, reach).is_none()
}

/// The bounding sphere of a box.
fn sphere_of(b: &Aabb) -> (V3, f32) {
    (b.center(), 0.5 * Vec3::from(b.max).distance(Vec3::from(b.min)))
}

#[cfg(test)]
mod tests {
    use super::*;

    use crate::testdata::{closed_box, merged};

    fn cube(c: [f32; 3], h: f32) -> TriMesh {
        closed_box(c, [h; 3])
    }

    #[test]
    fn a_lone_box_is_one_visible_piece() {
        let p = profile_mesh(&cube([0.0; 3], 1.0), 3);
        assert_eq!((p.components, p.fragments, p.faces, p.degenerate_faces), (1, 0, 12, 0));
        assert_eq!(p.largest_component_area, 1.0);
        assert_eq!(p.hidden_area, 0.0);
    }

    #[test]
    fn a_box_inside_a_box_is_hidden_and_its_area_share_is_measured() {
        // Inner half-side 0.5: a quarter of the outer area, so a fifth of the whole is hidden.
        let m = merged(cube([0.0; 3], 1.0), &cube([0.0; 3], 0.5));
        let p = profile_mesh(&m, 1);
        assert_eq!(p.components, 2);
        assert!((p.largest_component_area - 0.8).abs() < 1e-6, "{p:?}");
        assert!((p.hidden_area - 0.2).abs() < 0.02, "{p:?}");
    }

    #[test]
    fn a_box_wound_inside_out_escapes_through_the_back() {
        let outward = profile_mesh(&cube([0.0; 3], 1.0), 5);
        assert_eq!(outward.outward_escapes, 1.0);
        let mut inverted = cube([0.0; 3], 1.0);
        for t in &mut inverted.triangles {
            t.swap(1, 2);
        }
        assert_eq!(profile_mesh(&inverted, 5).outward_escapes, 0.0);
    }

    #[test]
    fn crumbs_count_as_fragments() {
        let mut m = cube([0.0; 3], 1.0);
        for k in 0..5 {
            m = merged(m, &cube([3.0 + k as f32, 0.0, 0.0], 0.01));
        }
        let p = profile_mesh(&m, 2);
        assert_eq!((p.components, p.fragments), (6, 5));
        assert!((p.fragment_area - 5e-4 / (1.0 + 5e-4)).abs() < 1e-6, "{p:?}");
        // Same seed, same numbers.
        assert_eq!(p, profile_mesh(&m, 2));
    }
}

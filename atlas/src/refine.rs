//! Refining the islands of a UV layout towards low distortion without adding flips: a local/global
//! ARAP parameterisation (Liu, Zhang, Xu, Gotsman, Gortler, "A Local/Global Approach to Mesh
//! Parameterization", SGP 2008) of every island, started from the island's current UVs.
//!
//! Nuvo's baked UVs are a good, mostly fold-free initial map, but their angles and areas are only
//! roughly those of the surface (PartUV's angular score ~0.92 where xatlas reaches ~0.99).
//! [`refine_islands`] keeps the layout's islands, their places and their sizes, and replaces the
//! map inside each island by a near-isometric one whenever that is safe.
//!
//! Definitions and choices (exact):
//! - **Island**: a chart of [`crate::uvstats::uv_charts`] (faces joined across a mesh edge whose UVs
//!   are equal at both ends). Islands of fewer than [`MIN_ISLAND_FACES`] faces are left as they are.
//! - **UV vertex**: the unknowns of an island are the distinct `coords` indices its faces use, where
//!   two indices are one unknown when a mesh vertex of the island has the same UV value under both
//!   (a layer that repeats a coordinate per corner is not torn apart). Every index of one unknown
//!   receives the same new value.
//! - **Energy**: `Σ_t A_t ‖J_t − R_t‖²_F` over the island's faces, `J_t` the Jacobian of the face's
//!   affine map from an isometric 2-D copy of its 3-D triangle to UV, `R_t` a rotation. Written per
//!   edge it is `½ Σ_t Σ_{ij ∈ t} cot θ_t^{ij} ‖(u_i − u_j) − R_t (x_i − x_j)‖²`, `θ_t^{ij}` the angle
//!   of `t` opposite the edge.
//! - **Local step**: per face the rotation closest to `J_t`, `R_t = rot(atan2(c − b, a + d))` for
//!   `J_t = [[a, b], [c, d]]`: the closed form of the 2×2 SVD polar factor `U Vᵀ` with the sign of
//!   the last singular pair flipped when `det(U Vᵀ) < 0` (rotations only, `det R = 1`).
//! - **Global step**: the cotangent-weighted Laplacian system `K u = b(R)` for both coordinates at
//!   once. `K` does not change between rounds, so it is factored once per island (sparse Cholesky,
//!   `faer`, with its AMD fill-reducing ordering); each of the [`RefineOptions::iterations`] rounds
//!   is one local step and one two-column solve. The first local step reads the current UVs,
//!   scaled to the island's 3-D area.
//! - **Acceleration**: plain local/global converges linearly and slowly when the current UVs'
//!   rotations are far off (a cut cone opened to the wrong angle needs ~200 rounds). The rounds
//!   are Anderson-accelerated as in Peng, Deng, Zhang, Liu, "Anderson Acceleration for Geometry
//!   Optimization and Physics Simulation" (SIGGRAPH 2018): the next point mixes the last
//!   [`ANDERSON_DEPTH`] global-step results (type-II Anderson, a least-squares fit of their
//!   residuals), and it is taken only when its energy (after its local step) is below the current
//!   point's; otherwise the plain global-step result is, whose energy never rises. So the energy
//!   still decreases monotonically, and the last round is always a plain global step.
//! - **Weights**: `K` is the sum of the per-face stiffness blocks `A_t ∇φᵀ∇φ`, each positive
//!   semi-definite for any triangle, so **negative cotangents (obtuse angles) are kept as they are**:
//!   `K` stays symmetric positive semi-definite, and clamping them would make the global step
//!   minimise a different energy from the one the local step measures. Faces that are **degenerate
//!   in 3-D** (the rule of [`crate::uvstats`]: area ≤ 1e-12 × the squared bounding-box diagonal),
//!   or whose cotangents are not finite or exceed [`MAX_COT`] in size (an angle below ~1e-8 rad),
//!   **get no weight**: they add nothing to `K` or `b` and follow their vertices.
//! - **Gauge**: the energy does not change under a translation of a connected piece (rotations are
//!   fixed by the local step's `R_t`). One vertex per connected component of the weighted faces (its
//!   lowest-numbered unknown) is pinned at its current position and eliminated from the system,
//!   which makes `K` positive definite; an unknown that no weighted face touches is pinned alone.
//! - **Orientation**: the island's majority orientation is [`crate::uvstats`]'s (the sign of its
//!   summed signed UV area). The 2-D copies of the faces are counter-clockwise, so an island whose
//!   majority is clockwise is solved mirrored (`v → −v`) and mirrored back.
//! - **Place and size**: the result is scaled to the island's original total UV area (Σ |A_uv|) and
//!   translated so that its area-weighted UV centroid is the original one (the vertex mean when the
//!   area is zero); its rotation is the one the first local step inherits from the current UVs. A
//!   later packing step decides the final layout.
//! - **Safety**: the refined island is kept only when it has no more flipped faces than before
//!   (orientation against the island's majority, majority recomputed on the new UVs, the rule of
//!   [`crate::uvstats`]), no more faces of (near) zero UV area, and an angular score that is not
//!   lower. The island's angular score is PartUV's ([`crate::partuv`]) restricted to the island:
//!   `1 − mean |cos(T, B)|` over its faces that are degenerate neither in 3-D nor in UV (UV
//!   degeneracy measured on raw UVs, [`DEGENERATE_UV_AREA`], where [`crate::partuv`] measures in
//!   the atlas square: the same for UVs in `[0,1]²`). Because PartUV skips UV-degenerate faces, a
//!   fold whose mirrored half is exactly isometric scores 1 and is left alone. When the full result
//!   fails, the blends `(1 − t) old + t new` for `t = ½, ¼, …` ([`RefineOptions::halvings`] of
//!   them) are tried in turn; when none passes, the island keeps its original UVs (**refused**).
//!   Islands whose Cholesky factorisation fails, whose result is not finite, or that have no 3-D or
//!   UV area are refused too.
//! - **Output**: same positions, same mesh triangles, same face order. The new value of every
//!   unknown is written to its `coords` indices; an index used by several islands (a UV vertex where
//!   islands touch at a point) stays with the first island that uses it and the others get a copy
//!   appended to `coords` (counted in [`RefineReport::split_coords`]) when their values differ.
//!
//! Islands are refined in parallel (rayon), each sequentially; the result does not depend on the
//! thread count.

use std::collections::HashMap;

use faer::linalg::solvers::Solve;
use faer::sparse::{SparseColMat, Triplet};
use faer::{Mat, Side};
use nuvo_geometry::{TriMesh, UvLayer};
use rayon::prelude::*;
use serde::Serialize;

use crate::error::AtlasError;
use crate::geom::to_dvec3;
use crate::metrics::abs_cos_tangents;
use crate::partuv::partuv_metrics;
use crate::uvstats::{
    DEGENERATE_UV_AREA, Dsu, Orientation, degenerate_3d_faces, orientation, require_uv, uv_islands,
};

/// Islands with fewer faces than this are left as they are.
pub const MIN_ISLAND_FACES: usize = 3;
/// A face with a cotangent larger than this in size (an angle below ~1e-8 rad or above π − 1e-8)
/// gets no weight, like a face of zero area: its stiffness would swamp the system's conditioning.
pub const MAX_COT: f64 = 1e8;
/// How many past rounds the Anderson acceleration of the local/global iteration mixes.
pub const ANDERSON_DEPTH: usize = 5;
/// Slack on the angular-score comparison of the safety check, for rounding only.
const ANGULAR_SLACK: f64 = 1e-12;

/// Options of [`refine_islands`].
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct RefineOptions {
    /// Local/global rounds per island (default 10). 0 leaves every island as it is (counted as
    /// refused).
    pub iterations: usize,
    /// How many times the step is halved when the full ARAP result fails the safety check
    /// (default 3: blends `t = ½, ¼, ⅛` are tried after `t = 1`).
    pub halvings: usize,
}

impl Default for RefineOptions {
    fn default() -> Self {
        RefineOptions { iterations: 10, halvings: 3 }
    }
}

/// What [`refine_islands`] did. `refined + refused + small = islands`.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct RefineReport {
    /// UV-connected islands of the input.
    pub islands: usize,
    /// Islands whose UVs were replaced.
    pub refined: usize,
    /// Of the refined islands, those that took a blend `t < 1` of old and new UVs.
    pub blended: usize,
    /// Islands that were solved but kept their original UVs (safety check, failed factorisation,
    /// nothing measurable).
    pub refused: usize,
    /// Islands under [`MIN_ISLAND_FACES`] faces, left as they are.
    pub small: usize,
    /// PartUV's angular score ([`crate::partuv`]) of the input layout.
    pub angular_before: f64,
    /// PartUV's angular score of the output layout.
    pub angular_after: f64,
    /// Faces flipped against their island's majority, before.
    pub flipped_before: usize,
    /// Faces flipped against their island's majority, after (never more than before).
    pub flipped_after: usize,
    /// Coordinates appended because an index shared by several islands needed two values.
    pub split_coords: usize,
}

/// The refined mesh and what was done to it.
#[derive(Clone, Debug, PartialEq)]
pub struct Refined {
    /// The input mesh with new texture coordinates (same positions, triangles and face order).
    pub mesh: TriMesh,
    /// The summary.
    pub report: RefineReport,
}

/// Refines every island of `mesh`'s UV layout towards an isometry (module docs). Errors: no UVs, an
/// invalid mesh.
pub fn refine_islands(mesh: &TriMesh, opts: &RefineOptions) -> Result<Refined, AtlasError> {
    let uv = require_uv(mesh)?;
    let members = uv_islands(mesh, uv);
    let count = members.len();
    let degenerate = degenerate_3d_faces(mesh);
    let ctx = Context { mesh, uv, degenerate: &degenerate, opts };
    let outcomes: Vec<Outcome> = members.par_iter().map(|faces| ctx.island(faces)).collect();

    let new_corners: Vec<Option<&[[f32; 2]]>> = outcomes.iter().map(|o| o.corners.as_deref()).collect();
    let (coords, triangles, split_coords) = write_back(uv, &members, &new_corners);
    let out = TriMesh { uv: Some(UvLayer { coords, triangles }), ..mesh.clone() };
    let angular = |m: &TriMesh| -> Result<f64, AtlasError> {
        if m.triangles.is_empty() { Ok(0.0) } else { Ok(partuv_metrics(m)?.angular_score) }
    };
    let count_kind = |k: Kind| outcomes.iter().filter(|o| o.kind == k).count();
    let report = RefineReport {
        islands: count,
        refined: count_kind(Kind::Refined) + count_kind(Kind::Blended),
        blended: count_kind(Kind::Blended),
        refused: count_kind(Kind::Refused),
        small: count_kind(Kind::Small),
        angular_before: angular(mesh)?,
        angular_after: angular(&out)?,
        flipped_before: outcomes.iter().map(|o| o.flips_before).sum(),
        flipped_after: outcomes.iter().map(|o| o.flips_after).sum(),
        split_coords,
    };
    Ok(Refined { mesh: out, report })
}

/// What happened to one island.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Kind {
    Small,
    Refined,
    Blended,
    Refused,
}

/// One island's result: its flips before and after and, when it changed, the new UV of each corner
/// of its faces (face-major, in the island's face order).
struct Outcome {
    kind: Kind,
    flips_before: usize,
    flips_after: usize,
    corners: Option<Vec<[f32; 2]>>,
}

impl Outcome {
    fn kept(kind: Kind, flips: usize) -> Self {
        Outcome { kind, flips_before: flips, flips_after: flips, corners: None }
    }
}

/// The inputs every island reads.
struct Context<'a> {
    mesh: &'a TriMesh,
    uv: &'a UvLayer,
    degenerate: &'a [bool],
    opts: &'a RefineOptions,
}

/// A face's isometric 2-D copy (corner 0 at the origin, corner 1 on +x, counter-clockwise) and the
/// cotangent of the angle at each corner (the weight of the opposite edge).
#[derive(Clone, Copy)]
pub(crate) struct Frame {
    pub(crate) x: [[f64; 2]; 3],
    cot: [f64; 3],
}

impl Frame {
    /// The frame of face `f`, `None` when it gets no weight (module docs).
    pub(crate) fn of(mesh: &TriMesh, f: usize) -> Option<Frame> {
        let [a, b, c] = mesh.corners(f).map(to_dvec3);
        let (e1, e2) = (b - a, c - a);
        let l1 = e1.length();
        let n2 = e1.cross(e2).length(); // twice the area
        if !(l1 > 0.0 && n2 > 0.0 && n2.is_finite()) {
            return None;
        }
        let x = [[0.0, 0.0], [l1, 0.0], [e1.dot(e2) / l1, n2 / l1]];
        let cot = [e1.dot(e2) / n2, (a - b).dot(c - b) / n2, (a - c).dot(b - c) / n2];
        cot.iter().all(|c| c.is_finite() && c.abs() <= MAX_COT).then_some(Frame { x, cot })
    }

    /// The rotation (as `[cos, sin]`) closest to the Jacobian `J` of the map from this frame to the
    /// UV triangle `q` (module docs: the SVD polar factor restricted to `det = 1`), and the face's
    /// energy `A ‖J − R‖²_F = A (‖J‖² − 2 tr(RᵀJ) + 2)`.
    fn best_rotation(&self, q: [[f64; 2]; 3]) -> ([f64; 2], f64) {
        let [_, [l1, _], [x2, y2]] = self.x;
        let d1 = [q[1][0] - q[0][0], q[1][1] - q[0][1]];
        let d2 = [q[2][0] - q[0][0], q[2][1] - q[0][1]];
        // J = [d1 d2] · X⁻¹ with X = [[l1, x2], [0, y2]].
        let (a, c) = (d1[0] / l1, d1[1] / l1);
        let (b, d) = ((d2[0] - d1[0] * x2 / l1) / y2, (d2[1] - d1[1] * x2 / l1) / y2);
        let (s, t) = (a + d, c - b);
        let r = s.hypot(t); // tr(RᵀJ) at the best R
        let energy = 0.5 * l1 * y2 * (a * a + b * b + c * c + d * d - 2.0 * r + 2.0);
        let rot = if r > 0.0 && r.is_finite() { [s / r, t / r] } else { [1.0, 0.0] };
        (rot, energy)
    }
}

/// Twice the signed area of a 2-D triangle (counter-clockwise positive).
pub(crate) fn area2(p: [[f64; 2]; 3]) -> f64 {
    (p[1][0] - p[0][0]) * (p[2][1] - p[0][1]) - (p[1][1] - p[0][1]) * (p[2][0] - p[0][0])
}

/// Faces against the majority (sign of the summed signed area, ties counter-clockwise) among
/// faces of twice-signed UV areas `a2`, summed in face order as [`crate::uvstats`] does.
fn flips(a2: &[f64]) -> usize {
    let ccw = a2.iter().sum::<f64>() >= 0.0;
    a2.iter().filter(|&&a| orientation(a, ccw) == Orientation::Flipped).count()
}

/// The bits of a UV value as [`uv_charts`] compares them (`−0 == +0`).
pub(crate) fn uv_bits(p: [f32; 2]) -> [u32; 2] {
    [(p[0] + 0.0).to_bits(), (p[1] + 0.0).to_bits()]
}

impl Context<'_> {
    /// Refines one island (module docs).
    fn island(&self, faces: &[u32]) -> Outcome {
        let (mesh, uv) = (self.mesh, self.uv);
        let original: Vec<[[f64; 2]; 3]> = faces
            .iter()
            .map(|&f| uv.triangles[f as usize].map(|i| uv.coords[i as usize].map(|x| x as f64)))
            .collect();
        let before_a2: Vec<f64> = original.iter().map(|&t| area2(t)).collect();
        let flips_before = flips(&before_a2);
        if faces.len() < MIN_ISLAND_FACES {
            return Outcome::kept(Kind::Small, flips_before);
        }
        let refused = Outcome::kept(Kind::Refused, flips_before);
        if self.opts.iterations == 0 {
            return refused;
        }
        let score_before = self.angular(faces, &original);

        let (corners, n) = island_unknowns(mesh, uv, faces);

        // Working UVs: mirrored to a counter-clockwise majority, centred, scaled to 3-D area.
        let sign = if before_a2.iter().sum::<f64>() >= 0.0 { 1.0 } else { -1.0 };
        let mut start = vec![[0.0f64; 2]; n];
        for (t, c) in original.iter().zip(&corners) {
            for k in 0..3 {
                start[c[k] as usize] = [t[k][0], sign * t[k][1]];
            }
        }
        let frames: Vec<Option<Frame>> = faces
            .iter()
            .map(|&f| if self.degenerate[f as usize] { None } else { Frame::of(mesh, f as usize) })
            .collect();
        let (mut a3, mut auv) = (0.0, 0.0);
        for (fr, c) in frames.iter().zip(&corners) {
            if let Some(fr) = fr {
                a3 += 0.5 * area2(fr.x);
                auv += 0.5 * area2(c.map(|i| start[i as usize])).abs();
            }
        }
        let uv_area_before: f64 = before_a2.iter().map(|a| 0.5 * a.abs()).sum();
        if !(a3 > 0.0 && auv > 0.0 && uv_area_before > 0.0) {
            return refused;
        }
        let scale = (a3 / auv).sqrt();
        let centre = centroid(&corners, &start);
        for q in &mut start {
            *q = [(q[0] - centre[0]) * scale, (q[1] - centre[1]) * scale];
        }

        let Some(arap) = Arap::new(&frames, &corners, &start) else {
            return refused;
        };
        let result = arap.solve(&start, self.opts.iterations);
        if result.iter().flatten().any(|x| !x.is_finite()) {
            return refused;
        }

        // Safety: the full step, then halved blends; the first that passes is kept.
        for h in 0..=self.opts.halvings {
            let t = 0.5f64.powi(h as i32);
            let blend: Vec<[f64; 2]> = start
                .iter()
                .zip(&result)
                .map(|(a, b)| [a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])])
                .collect();
            let Some(out) = place(&corners, &blend, sign, uv_area_before, centroid_of(&original)) else {
                continue;
            };
            let out64: Vec<[[f64; 2]; 3]> = out.iter().map(|t| t.map(|q| q.map(|x| x as f64))).collect();
            let a2: Vec<f64> = out64.iter().map(|&t| area2(t)).collect();
            let flips_after = flips(&a2);
            let score = self.angular(faces, &out64);
            if flips_after <= flips_before
                && score.degenerate_uv <= score_before.degenerate_uv
                && score.value >= score_before.value - ANGULAR_SLACK
            {
                let kind = if h == 0 { Kind::Refined } else { Kind::Blended };
                return Outcome {
                    kind,
                    flips_before,
                    flips_after,
                    corners: Some(out.into_iter().flatten().collect()),
                };
            }
        }
        refused
    }

    /// The island's PartUV angular score with UV triangles `tris` and its UV-degenerate faces
    /// (module docs).
    fn angular(&self, faces: &[u32], tris: &[[[f64; 2]; 3]]) -> IslandAngular {
        let (mut sum, mut n, mut degenerate_uv) = (0.0, 0usize, 0usize);
        for (&f, t) in faces.iter().zip(tris) {
            if 0.5 * area2(*t).abs() <= DEGENERATE_UV_AREA {
                degenerate_uv += 1;
                continue;
            }
            if self.degenerate[f as usize] {
                continue;
            }
            let [a, b, c] = self.mesh.corners(f as usize).map(to_dvec3);
            let duv = [t[1][0] - t[0][0], t[1][1] - t[0][1], t[2][0] - t[0][0], t[2][1] - t[0][1]];
            if let Some(c) = abs_cos_tangents(b - a, c - a, duv) {
                sum += c;
                n += 1;
            }
        }
        IslandAngular { value: if n == 0 { 0.0 } else { 1.0 - sum / n as f64 }, degenerate_uv }
    }
}

/// The unknowns of an island (module docs, "UV vertex"): for each of `faces`, the unknown of each
/// corner, and how many unknowns there are. Unknowns are numbered in order of first use.
pub(crate) fn island_unknowns(mesh: &TriMesh, uv: &UvLayer, faces: &[u32]) -> (Vec<[u32; 3]>, usize) {
    let mut local: HashMap<u32, u32> = HashMap::with_capacity(faces.len());
    let mut corner_local: Vec<[u32; 3]> = Vec::with_capacity(faces.len());
    for &f in faces {
        corner_local.push(uv.triangles[f as usize].map(|ci| {
            let next = local.len() as u32;
            *local.entry(ci).or_insert(next)
        }));
    }
    let mut dsu = Dsu::new(local.len());
    let mut by_vertex: HashMap<(u32, [u32; 2]), u32> = HashMap::with_capacity(local.len());
    for (&f, cl) in faces.iter().zip(&corner_local) {
        for (k, &l) in cl.iter().enumerate() {
            let v = mesh.triangles[f as usize][k];
            let key = (v, uv_bits(uv.coords[uv.triangles[f as usize][k] as usize]));
            let first = *by_vertex.entry(key).or_insert(l);
            dsu.union(first, l);
        }
    }
    let mut unknown_of_root = vec![u32::MAX; local.len()];
    let mut n = 0u32;
    let mut unk = |l: u32| {
        let r = dsu.find(l) as usize;
        if unknown_of_root[r] == u32::MAX {
            unknown_of_root[r] = n;
            n += 1;
        }
        unknown_of_root[r]
    };
    let corners: Vec<[u32; 3]> = corner_local.iter().map(|cl| cl.map(&mut unk)).collect();
    (corners, n as usize)
}

/// [`Context::angular`]'s answer.
struct IslandAngular {
    /// `1 − mean |cos(T, B)|` over the measured faces, 0 when none is.
    value: f64,
    /// Faces of (near) zero UV area.
    degenerate_uv: usize,
}

/// The factored global step of one island and what its local step reads.
struct Arap<'a> {
    frames: &'a [Option<Frame>],
    corners: &'a [[u32; 3]],
    /// System row of each unknown, `u32::MAX` for a pinned one.
    free: Vec<u32>,
    /// Unknown of each system row.
    free_to_unknown: Vec<u32>,
    /// The pinned unknowns' share of the right-hand side (constant).
    fixed: Vec<[f64; 2]>,
    llt: faer::sparse::linalg::solvers::Llt<usize, f64>,
}

impl<'a> Arap<'a> {
    /// Pins one unknown per component of the weighted faces (module docs), assembles the lower
    /// triangle of `K` and factors it. `None` when nothing is free or the factorisation fails.
    fn new(frames: &'a [Option<Frame>], corners: &'a [[u32; 3]], start: &[[f64; 2]]) -> Option<Self> {
        let n = start.len();
        let mut comp = Dsu::new(n);
        for (fr, c) in frames.iter().zip(corners) {
            if fr.is_some() {
                comp.union(c[0], c[1]);
                comp.union(c[0], c[2]);
            }
        }
        let mut free = vec![u32::MAX; n];
        let mut free_to_unknown = Vec::with_capacity(n);
        for i in 0..n as u32 {
            if comp.find(i) != i {
                free[i as usize] = free_to_unknown.len() as u32;
                free_to_unknown.push(i);
            }
        }
        let nfree = free_to_unknown.len();
        if nfree == 0 {
            return None;
        }
        let mut triplets: Vec<Triplet<usize, usize, f64>> = Vec::with_capacity(9 * corners.len());
        let mut fixed = vec![[0.0f64; 2]; nfree];
        for (fr, c) in frames.iter().zip(corners) {
            let Some(fr) = fr else { continue };
            for k in 0..3 {
                let (i, j) = (c[(k + 1) % 3], c[(k + 2) % 3]);
                if i == j {
                    continue; // a collapsed edge: constant energy, nothing to add
                }
                let w = fr.cot[k];
                let (fi, fj) = (free[i as usize], free[j as usize]);
                for fa in [fi, fj] {
                    if fa != u32::MAX {
                        triplets.push(Triplet::new(fa as usize, fa as usize, w));
                    }
                }
                let mut add_fixed = |row: u32, q: [f64; 2]| {
                    let r = &mut fixed[row as usize];
                    *r = [r[0] + w * q[0], r[1] + w * q[1]];
                };
                match (fi != u32::MAX, fj != u32::MAX) {
                    (true, true) => triplets.push(Triplet::new(fi.max(fj) as usize, fi.min(fj) as usize, -w)),
                    (true, false) => add_fixed(fi, start[j as usize]),
                    (false, true) => add_fixed(fj, start[i as usize]),
                    (false, false) => {}
                }
            }
        }
        let k = SparseColMat::<usize, f64>::try_new_from_triplets(nfree, nfree, &triplets).ok()?;
        drop(triplets);
        let llt = k.sp_cholesky(Side::Lower).ok()?;
        Some(Arap { frames, corners, free, free_to_unknown, fixed, llt })
    }

    /// The local step at unknown positions `p`: each weighted face's rotation (`[cos, sin]`,
    /// identity for the others) and the energy `Σ A_t ‖J_t − R_t‖²`.
    fn local(&self, p: &[[f64; 2]]) -> (Vec<[f64; 2]>, f64) {
        let mut energy = 0.0;
        let rots = self
            .frames
            .iter()
            .zip(self.corners)
            .map(|(fr, c)| match fr {
                Some(fr) => {
                    let (rot, e) = fr.best_rotation(c.map(|i| p[i as usize]));
                    energy += e;
                    rot
                }
                None => [1.0, 0.0],
            })
            .collect();
        (rots, energy)
    }

    /// The global step: the free unknowns (u column then v column) minimising the energy for
    /// rotations `rots`.
    fn global(&self, rots: &[[f64; 2]]) -> Mat<f64> {
        let nfree = self.free_to_unknown.len();
        let mut rhs = Mat::<f64>::from_fn(nfree, 2, |i, k| self.fixed[i][k]);
        for ((fr, c), &[cs, sn]) in self.frames.iter().zip(self.corners).zip(rots) {
            let Some(fr) = fr else { continue };
            for k in 0..3 {
                let (ci, cj) = ((k + 1) % 3, (k + 2) % 3);
                let (i, j) = (c[ci], c[cj]);
                if i == j {
                    continue;
                }
                let e = [fr.x[ci][0] - fr.x[cj][0], fr.x[ci][1] - fr.x[cj][1]];
                let w = fr.cot[k];
                let r = [w * (cs * e[0] - sn * e[1]), w * (sn * e[0] + cs * e[1])];
                for (v, s) in [(i, 1.0), (j, -1.0)] {
                    let fv = self.free[v as usize];
                    if fv != u32::MAX {
                        rhs[(fv as usize, 0)] += s * r[0];
                        rhs[(fv as usize, 1)] += s * r[1];
                    }
                }
            }
        }
        self.llt.solve_in_place(rhs.as_mut());
        rhs
    }

    /// `p` with its free unknowns set from the stacked vector `x` (u column, then v column).
    fn scatter(&self, x: &[f64], p: &mut [[f64; 2]]) {
        let nfree = self.free_to_unknown.len();
        for (row, &v) in self.free_to_unknown.iter().enumerate() {
            p[v as usize] = [x[row], x[nfree + row]];
        }
    }

    /// `iterations` global solves from `start`, Anderson-accelerated (module docs); returns the
    /// positions of all unknowns after the last one.
    fn solve(&self, start: &[[f64; 2]], iterations: usize) -> Vec<[f64; 2]> {
        let nfree = self.free_to_unknown.len();
        let stack = |m: &Mat<f64>| -> Vec<f64> { (0..2).flat_map(|k| m.col_as_slice(k).to_vec()).collect() };
        let mut p = start.to_vec();
        let mut x: Vec<f64> =
            (0..2).flat_map(|k| self.free_to_unknown.iter().map(move |&v| start[v as usize][k])).collect();
        let (mut rots, mut energy) = self.local(&p);
        let mut history = Anderson::new(ANDERSON_DEPTH, 2 * nfree);
        for round in 1..=iterations {
            let g = stack(&self.global(&rots));
            if round == iterations {
                self.scatter(&g, &mut p);
                break;
            }
            let f: Vec<f64> = g.iter().zip(&x).map(|(a, b)| a - b).collect();
            let candidate = history.step(&g, &f);
            let mut q = p.clone();
            self.scatter(&candidate, &mut q);
            let (r, e) = self.local(&q);
            if candidate != g && !(e < energy && e.is_finite()) {
                // The accelerated point does not lower the energy: take the plain step, which does.
                self.scatter(&g, &mut p);
                (rots, energy) = self.local(&p);
                x = g;
            } else {
                (p, rots, energy, x) = (q, r, e, candidate);
            }
        }
        p
    }
}

/// Anderson acceleration (type II, Walker & Ni 2011) of a fixed-point iteration `x ← G(x)`, as
/// Peng et al. ("Anderson Acceleration for Geometry Optimization and Physics Simulation", 2018)
/// apply it to local/global solvers: from the last `depth` pairs `(G(x_i), f_i = G(x_i) − x_i)`,
/// the next point is `G(x_k) − ΔG θ` with `θ = argmin ‖f_k − ΔF θ‖`.
struct Anderson {
    depth: usize,
    last: Option<(Vec<f64>, Vec<f64>)>,
    /// Columns `(Δg, Δf)`, oldest first.
    diffs: Vec<(Vec<f64>, Vec<f64>)>,
    dim: usize,
}

impl Anderson {
    fn new(depth: usize, dim: usize) -> Self {
        Anderson { depth, last: None, diffs: Vec::new(), dim }
    }

    /// Records `(g, f)` and returns the accelerated point (`g` itself until there is a history, or
    /// when the small least-squares problem cannot be solved).
    fn step(&mut self, g: &[f64], f: &[f64]) -> Vec<f64> {
        if let Some((g0, f0)) = self.last.take() {
            let dg = g.iter().zip(&g0).map(|(a, b)| a - b).collect();
            let df = f.iter().zip(&f0).map(|(a, b)| a - b).collect();
            if self.diffs.len() == self.depth {
                self.diffs.remove(0);
            }
            self.diffs.push((dg, df));
        }
        self.last = Some((g.to_vec(), f.to_vec()));
        let m = self.diffs.len();
        if m == 0 {
            return g.to_vec();
        }
        // Normal equations (ΔFᵀΔF + λI) θ = ΔFᵀ f, λ a tiny ridge for nearly dependent columns.
        let dotp = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
        let mut gram = Mat::<f64>::from_fn(m, m, |i, j| dotp(&self.diffs[i].1, &self.diffs[j].1));
        let ridge = 1e-10 * (0..m).map(|i| gram[(i, i)]).fold(0.0, f64::max) + f64::MIN_POSITIVE;
        for i in 0..m {
            gram[(i, i)] += ridge;
        }
        let mut theta = Mat::<f64>::from_fn(m, 1, |i, _| dotp(&self.diffs[i].1, f));
        let Ok(llt) = gram.llt(Side::Lower) else { return g.to_vec() };
        llt.solve_in_place(theta.as_mut());
        let mut out = g.to_vec();
        for (i, (dg, _)) in self.diffs.iter().enumerate() {
            let t = theta[(i, 0)];
            for (o, d) in out.iter_mut().zip(dg) {
                *o -= t * d;
            }
        }
        debug_assert_eq!(out.len(), self.dim);
        if out.iter().all(|v| v.is_finite()) { out } else { g.to_vec() }
    }
}

/// The area-weighted centroid of the UV triangles (|area| weights), or the mean of the corners
/// when the total area is zero.
pub(crate) fn centroid_of(tris: &[[[f64; 2]; 3]]) -> [f64; 2] {
    let (mut w, mut s, mut m) = (0.0, [0.0f64; 2], [0.0f64; 2]);
    for t in tris {
        let a = area2(*t).abs();
        for q in t {
            s = [s[0] + a * q[0] / 3.0, s[1] + a * q[1] / 3.0];
            m = [m[0] + q[0], m[1] + q[1]];
        }
        w += a;
    }
    if w > 0.0 {
        [s[0] / w, s[1] / w]
    } else {
        let k = (3 * tris.len()).max(1) as f64;
        [m[0] / k, m[1] / k]
    }
}

/// [`centroid_of`] the faces `corners` with unknown positions `p`.
fn centroid(corners: &[[u32; 3]], p: &[[f64; 2]]) -> [f64; 2] {
    let tris: Vec<[[f64; 2]; 3]> = corners.iter().map(|c| c.map(|i| p[i as usize])).collect();
    centroid_of(&tris)
}

/// The island's corners at working positions `p`, mirrored back (`sign`), scaled to UV area
/// `area` and moved to centroid `centre`, in f32; `None` when the result has no area or is not
/// finite.
fn place(
    corners: &[[u32; 3]],
    p: &[[f64; 2]],
    sign: f64,
    area: f64,
    centre: [f64; 2],
) -> Option<Vec<[[f32; 2]; 3]>> {
    let tris: Vec<[[f64; 2]; 3]> =
        corners.iter().map(|c| c.map(|i| [p[i as usize][0], sign * p[i as usize][1]])).collect();
    let now: f64 = tris.iter().map(|t| 0.5 * area2(*t).abs()).sum();
    if !(now > 0.0 && now.is_finite()) {
        return None;
    }
    let s = (area / now).sqrt();
    let c = centroid_of(&tris);
    let out: Vec<[[f32; 2]; 3]> = tris
        .iter()
        .map(|t| t.map(|q| [(centre[0] + s * (q[0] - c[0])) as f32, (centre[1] + s * (q[1] - c[1])) as f32]))
        .collect();
    out.iter().flatten().flatten().all(|x| x.is_finite()).then_some(out)
}

/// The output UV layer (module docs): every island's corner values written to their `coords`
/// indices, an index shared with an earlier island copied when the values differ. Returns the
/// coordinates, the UV triangles and how many coordinates were appended.
pub(crate) fn write_back(
    uv: &UvLayer,
    members: &[Vec<u32>],
    new_corners: &[Option<&[[f32; 2]]>],
) -> (Vec<[f32; 2]>, Vec<[u32; 3]>, usize) {
    let mut coords = uv.coords.clone();
    let mut triangles = uv.triangles.clone();
    let mut claimed = vec![false; coords.len()];
    let original = coords.len();
    let mut copies: HashMap<(u32, [u32; 2]), u32> = HashMap::new();
    for (faces, corners) in members.iter().zip(new_corners) {
        copies.clear();
        for (n, &f) in faces.iter().enumerate() {
            for k in 0..3 {
                let ci = uv.triangles[f as usize][k];
                let want = corners.map_or(uv.coords[ci as usize], |c| c[3 * n + k]);
                if !claimed[ci as usize] {
                    claimed[ci as usize] = true;
                    coords[ci as usize] = want;
                } else if uv_bits(coords[ci as usize]) != uv_bits(want) {
                    let copy = *copies.entry((ci, uv_bits(want))).or_insert_with(|| {
                        coords.push(want);
                        coords.len() as u32 - 1
                    });
                    triangles[f as usize][k] = copy;
                }
            }
        }
    }
    let split = coords.len() - original;
    (coords, triangles, split)
}

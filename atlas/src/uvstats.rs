//! UV-space properties of a mesh's texture coordinates: charts, flips, utilisation and overlaps.
//! These need no camera; [`crate::metrics`] reports them next to the image-space scores and
//! [`crate::bake()`] uses them to check its own output.
//!
//! Definitions (exact):
//! - **Charts**: connected components of faces, two faces being connected when they share a mesh
//!   edge (same two vertex indices) whose UVs at both ends are equal (same coordinate values). Faces
//!   that do not share vertex indices are never connected, so unwelded meshes have more charts.
//! - **Degenerate UV face**: |UV area| ≤ [`DEGENERATE_UV_AREA`]. Not classified as flipped or not.
//! - **Flipped face**: a non-degenerate face whose signed UV area (corners in the face's order) has
//!   the sign opposite to its chart's majority, the majority being the sign carrying more total UV
//!   area in the chart (ties: counter-clockwise). `flipped_fraction` = flipped faces / all faces.
//!   This assumes the 3-D winding is consistent inside a chart, as it is for every mesh in the test
//!   data (a winding error inside a chart would show up as a flip).
//! - **Creased face**: a face sharing a mesh edge with a face whose unit normal makes an angle of
//!   more than 90° with its own (the surface turns back on itself there). A UV map that is a smooth
//!   function of 3-D position, as Nuvo's is, can hardly keep both sides of such a crease the same
//!   way round when the crease is smaller than the sample spacing, so `flipped_on_creases` counts
//!   the flips that the input mesh, rather than the map, explains.
//! - **UV raster**: the unit square `[0,1]²` split into `R × R` texels, a texel covered by a face
//!   when its centre is (rasteriser coverage rule: a centre on an edge shared by two faces belongs
//!   to exactly one, so shared edges never count as overlap). UV outside `[0,1]²` is not counted.
//! - **Utilisation**: covered texels / `R²`.
//! - **Overlap fraction**: texels covered by ≥ 2 faces / covered texels. A face *overlaps* when at
//!   least one of its texels is covered by another face. Faces smaller than a texel may escape
//!   detection: that is the resolution of the measure.
//! - **Texel aspect** of a face: the ratio `σ₁/σ₂ ≥ 1` of the larger to the smaller singular
//!   value of its affine map between the surface and UV space, i.e. how far a square texel's
//!   footprint on the surface is from a square (1: square, 2: twice as long one way as the
//!   other, whichever way). Neither the paper's Stretch and Conformal nor PartUV's angular and
//!   area scores see it when the stretch runs along the texture axes. Over the faces that are
//!   degenerate neither in 3-D nor in UV, unweighted: the median (the mean of the two middle
//!   values for an even count) and the 90th percentile (the value at rank `⌈0.9 n⌉`); 1 for
//!   both when no face is measurable.

use foldhash::{HashMap, HashMapExt};
use std::sync::{Arc, Mutex};

use glam::DVec3;
use nuvo_geometry::{TriMesh, UvLayer};
use rayon::prelude::*;
use serde::Serialize;

use crate::error::AtlasError;
use crate::geom::{signed_area2_2d, to_dvec3};
use crate::raster::{Sampling, Tri2, raster_parallel, rasterize_triangle_exact};

/// UV area at or below which a face counts as degenerate in UV (not flipped, not measurable).
pub const DEGENERATE_UV_AREA: f64 = 1e-12;
/// 3-D area, relative to the squared bounding-box diagonal, at or below which a face counts as
/// degenerate in 3-D. Degenerate faces are skipped by the distortion metrics (their stretch would be
/// a division by zero).
pub const DEGENERATE_AREA_REL: f64 = 1e-12;
/// Default side of the UV raster, in texels.
pub const DEFAULT_UV_RASTER: u32 = 1024;

/// Face-level summary of a UV layout. Serialised as part of the `nuvo eval` JSON.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct UvStats {
    /// Number of faces.
    pub faces: usize,
    /// Number of charts (the labelling given, or UV-connected components; module docs).
    pub charts: usize,
    /// Fraction of `[0,1]²` covered by at least one face, on the UV raster.
    pub utilisation: f64,
    /// Fraction of covered UV raster texels covered more than once.
    pub overlap_fraction: f64,
    /// Faces covering at least one texel that another face also covers.
    pub overlapping_faces: usize,
    /// Faces oriented against their chart's majority.
    pub flipped_faces: usize,
    /// `flipped_faces / faces`.
    pub flipped_fraction: f64,
    /// Flipped faces that are creased (module docs): folds of the input surface, not of the map.
    pub flipped_on_creases: usize,
    /// Faces of (near) zero UV area.
    pub degenerate_uv_faces: usize,
    /// Faces of (near) zero 3-D area.
    pub degenerate_3d_faces: usize,
    /// Median texel aspect over the measurable faces (module docs; 1 = square texels).
    pub texel_aspect_median: f64,
    /// 90th percentile of the texel aspect over the measurable faces (module docs).
    pub texel_aspect_p90: f64,
    /// Side of the UV raster used for utilisation and overlap.
    pub raster_resolution: u32,
}

/// [`UvStats`] plus the per-face evidence behind it, for callers that act on faces (the baker).
#[derive(Clone, Debug, PartialEq)]
pub struct UvAnalysis {
    /// The summary.
    pub stats: UvStats,
    /// Chart of each face.
    pub face_chart: Vec<u32>,
    /// Ids of flipped faces, increasing.
    pub flipped: Vec<u32>,
    /// Ids of overlapping faces, increasing.
    pub overlapping: Vec<u32>,
    /// Ids of faces that are degenerate in UV, increasing.
    pub degenerate_uv: Vec<u32>,
}

/// The UV layer of `mesh` once the mesh passed [`TriMesh::validate`] (so every index is in range
/// and nothing below can panic on it), else [`AtlasError::Invalid`] or [`AtlasError::NoUv`].
pub fn require_uv(mesh: &TriMesh) -> Result<&UvLayer, AtlasError> {
    mesh.validate().map_err(|m| AtlasError::invalid("mesh", m))?;
    mesh.uv.as_ref().ok_or_else(|| AtlasError::NoUv { what: "mesh".into() })
}

/// Analyses the UVs of `mesh`. `face_chart` labels faces with charts (e.g. the baker's chart
/// choice, labels `< max+1`); `None` uses the UV-connected components. `resolution` is the UV
/// raster side (≥ 1).
pub fn analyse_uv(
    mesh: &TriMesh,
    face_chart: Option<&[u32]>,
    resolution: u32,
) -> Result<UvAnalysis, AtlasError> {
    let uv = require_uv(mesh)?;
    if resolution == 0 || resolution > crate::camera::MAX_IMAGE_SIDE {
        return Err(AtlasError::invalid("UV raster resolution", format!("{resolution} is out of range")));
    }
    let edges = MeshEdges::shared(mesh);
    let (face_chart, charts) = match face_chart {
        Some(fc) if fc.len() != mesh.triangles.len() => {
            return Err(AtlasError::invalid(
                "face charts",
                format!("{} labels for {} faces", fc.len(), mesh.triangles.len()),
            ));
        }
        Some(fc) => (fc.to_vec(), fc.iter().max().map_or(0, |&m| m as usize + 1)),
        None => charts_along(&edges.uses, mesh, uv),
    };
    let area2 = signed_uv_area2(uv);
    let degenerate_uv: Vec<u32> = ids(area2.iter().map(|&a| is_degenerate_uv(a)));
    let flipped = flipped_faces(&area2, &face_chart, charts);
    let creased = creases_along(&edges.uses, mesh);
    let flipped_on_creases = flipped.iter().filter(|&&f| creased[f as usize]).count();
    let counts = uv_coverage(uv, resolution);
    let overlapping = overlapping_faces(uv, &counts, resolution);
    let covered = counts.iter().filter(|&&c| c >= 1).count();
    let multiple = counts.iter().filter(|&&c| c >= 2).count();
    let faces = mesh.triangles.len();
    let degenerate_3d = degenerate_3d_faces(mesh);
    let mut aspects: Vec<f64> = (0..faces)
        .into_par_iter()
        .filter(|&f| !degenerate_3d[f] && !is_degenerate_uv(area2[f]))
        .filter_map(|f| {
            let [a, b, c] = mesh.corners(f).map(to_dvec3);
            let [ua, ub, uc] = uv.triangles[f].map(|i| uv.coords[i as usize].map(|x| x as f64));
            texel_aspect(b - a, c - a, [ub[0] - ua[0], ub[1] - ua[1], uc[0] - ua[0], uc[1] - ua[1]])
        })
        .collect();
    let (texel_aspect_median, texel_aspect_p90) = median_and_p90(&mut aspects);
    let stats = UvStats {
        faces,
        charts,
        utilisation: covered as f64 / (resolution as f64).powi(2),
        overlap_fraction: if covered == 0 { 0.0 } else { multiple as f64 / covered as f64 },
        overlapping_faces: overlapping.len(),
        flipped_faces: flipped.len(),
        flipped_fraction: if faces == 0 { 0.0 } else { flipped.len() as f64 / faces as f64 },
        flipped_on_creases,
        degenerate_uv_faces: degenerate_uv.len(),
        degenerate_3d_faces: degenerate_3d.iter().filter(|&&d| d).count(),
        texel_aspect_median,
        texel_aspect_p90,
        raster_resolution: resolution,
    };
    Ok(UvAnalysis { stats, face_chart, flipped, overlapping, degenerate_uv })
}

/// The texel aspect `σ₁/σ₂` of a face (module docs) with 3-D edges `e1 = b − a`, `e2 = c − a`
/// and UV edges `duv = [Δu₁, Δv₁, Δu₂, Δv₂]`; `None` when the map has no finite ratio.
fn texel_aspect(e1: DVec3, e2: DVec3, duv: [f64; 4]) -> Option<f64> {
    // The squared singular values are the eigenvalues of the axes' Gram matrix [[a, b], [b, c]];
    // the UV determinant the axes are scaled by cancels in the ratio.
    let (t, s) = texture_axes(e1, e2, duv);
    let (a, b, c) = (t.length_squared(), t.dot(s), s.length_squared());
    let mean = 0.5 * (a + c);
    let spread = (0.25 * (a - c) * (a - c) + b * b).sqrt();
    let (hi, lo) = (mean + spread, mean - spread);
    let ratio = (hi / lo).sqrt();
    (lo > 0.0 && ratio.is_finite()).then_some(ratio)
}

/// A face's texture axes `∂p/∂u` and `∂p/∂v` times its UV determinant `Δu₁Δv₂ − Δv₁Δu₂`, from
/// its 3-D edges `e1 = b − a`, `e2 = c − a` and UV edges `duv = [Δu₁, Δv₁, Δu₂, Δv₂]`: the
/// columns of the inverse of the UV edge matrix applied to the 3-D edges, without the division
/// (what a scale-free measure of the axes reads).
pub(crate) fn texture_axes(e1: DVec3, e2: DVec3, duv: [f64; 4]) -> (DVec3, DVec3) {
    let [du1, dv1, du2, dv2] = duv;
    (e1 * dv2 - e2 * dv1, e2 * du1 - e1 * du2)
}

/// The median (the mean of the two middle values for an even count) and the 90th percentile
/// (rank `⌈0.9 n⌉`) of `v`, reordering it; `(1, 1)` when it is empty.
fn median_and_p90(v: &mut [f64]) -> (f64, f64) {
    let n = v.len();
    if n == 0 {
        return (1.0, 1.0);
    }
    v.sort_unstable_by(f64::total_cmp);
    let median = if n % 2 == 1 { v[n / 2] } else { 0.5 * (v[n / 2 - 1] + v[n / 2]) };
    let rank = (9 * n).div_ceil(10);
    (median, v[rank - 1])
}

/// UV-connected components of the faces (module docs): `(chart of each face, number of charts)`,
/// charts numbered in order of their first face.
pub fn uv_charts(mesh: &TriMesh, uv: &UvLayer) -> (Vec<u32>, usize) {
    MeshEdges::shared(mesh).uv_charts(mesh, uv)
}

/// A mesh's edge uses kept with the triangles they were found on, so that the UV charts of many
/// UV layouts of one mesh sort its edges once. Why: a bake asks for the charts (and creases) of
/// one mesh again and again while only its UV layer changes (the necks pass for every island it
/// tries and every trial cut, the injective, join and packing passes, the metrics): on the horse
/// 31 sorts of its 290k edge uses, 0.44 s of the bake's wall time.
pub(crate) struct MeshEdges {
    triangles: Vec<[u32; 3]>,
    uses: EdgeUses,
}

/// How many meshes' edge uses [`MeshEdges::shared`] keeps: the bake's one mesh, and one more for
/// a caller that alternates between two (tests running side by side share the memo too).
const SHARED_MESHES: usize = 2;

/// The edge uses of the meshes asked about last, the last asked first, at most `capacity`.
struct RecentEdges {
    entries: Mutex<Vec<Arc<MeshEdges>>>,
    capacity: usize,
}

impl RecentEdges {
    const fn new(capacity: usize) -> Self {
        RecentEdges { entries: Mutex::new(Vec::new()), capacity }
    }

    /// The entry with `mesh`'s triangles (compared in full, so a hit is exactly what sorting
    /// again would give), made the newest; else the edge uses sorted now and kept as the newest
    /// entry, the oldest dropped beyond `capacity`.
    fn of(&self, mesh: &TriMesh) -> Arc<MeshEdges> {
        // A poisoned lock still holds whole entries: each is pushed complete.
        let entries = || self.entries.lock().unwrap_or_else(|poisoned| poisoned.into_inner());
        {
            let mut entries = entries();
            if let Some(i) = entries.iter().position(|e| e.fit(mesh)) {
                let hit = entries.remove(i);
                entries.insert(0, Arc::clone(&hit));
                return hit;
            }
        }
        // Sorted outside the lock: other threads' look-ups need not wait for it.
        let made = Arc::new(MeshEdges { triangles: mesh.triangles.clone(), uses: EdgeUses::of(mesh) });
        let mut entries = entries();
        entries.insert(0, Arc::clone(&made));
        entries.truncate(self.capacity);
        made
    }
}

impl MeshEdges {
    /// The edge uses of `mesh`, from a memo of the [`SHARED_MESHES`] meshes asked about last
    /// when one of them has the same triangles, else sorted now and remembered. The memo lives
    /// as long as the process (about 60 bytes per face of each mesh it holds).
    pub(crate) fn shared(mesh: &TriMesh) -> Arc<MeshEdges> {
        static RECENT: RecentEdges = RecentEdges::new(SHARED_MESHES);
        RECENT.of(mesh)
    }

    /// Whether `mesh` has the triangles these edges were found on (only then may
    /// [`MeshEdges::uv_charts`] be asked about it).
    pub(crate) fn fit(&self, mesh: &TriMesh) -> bool {
        self.triangles == mesh.triangles
    }

    /// [`uv_charts`] of `mesh`, which must [`MeshEdges::fit`].
    pub(crate) fn uv_charts(&self, mesh: &TriMesh, uv: &UvLayer) -> (Vec<u32>, usize) {
        debug_assert!(self.fit(mesh));
        charts_along(&self.uses, mesh, uv)
    }
}

/// The faces of each island of [`uv_charts`], in island order, each list in face order.
pub fn uv_islands(mesh: &TriMesh, uv: &UvLayer) -> Vec<Vec<u32>> {
    let (face_chart, count) = uv_charts(mesh, uv);
    let mut members: Vec<Vec<u32>> = vec![Vec::new(); count];
    for (f, &c) in face_chart.iter().enumerate() {
        members[c as usize].push(f as u32);
    }
    members
}

/// [`uv_charts`] on the mesh's edge uses.
fn charts_along(edges: &EdgeUses, mesh: &TriMesh, uv: &UvLayer) -> (Vec<u32>, usize) {
    // Two uses of an edge join their faces when both ends have the same UVs in both faces.
    let uv_at =
        |e: &EdgeUse, end: usize| uv.coords[uv.triangles[e.face as usize][e.corners[end] as usize] as usize];
    let mut dsu = Dsu::new(mesh.triangles.len());
    for (x, y) in edges.pairs() {
        if uv_at(x, 0) == uv_at(y, 0) && uv_at(x, 1) == uv_at(y, 1) {
            dsu.union(x.face, y.face);
        }
    }
    let mut label = vec![u32::MAX; mesh.triangles.len()];
    let mut out = Vec::with_capacity(mesh.triangles.len());
    let mut count = 0u32;
    for f in 0..mesh.triangles.len() as u32 {
        let r = dsu.find(f) as usize;
        if label[r] == u32::MAX {
            label[r] = count;
            count += 1;
        }
        out.push(label[r]);
    }
    (out, count as usize)
}

/// Whether each face is creased (module docs): it shares an edge with a face whose normal points
/// more than 90° away from its own. Faces of zero 3-D area have no normal and crease nothing.
pub fn creased_faces(mesh: &TriMesh) -> Vec<bool> {
    creases_along(&MeshEdges::shared(mesh).uses, mesh)
}

/// [`creased_faces`] on the mesh's edge uses.
fn creases_along(edges: &EdgeUses, mesh: &TriMesh) -> Vec<bool> {
    let normals: Vec<DVec3> = (0..mesh.triangles.len())
        .into_par_iter()
        .map(|f| {
            let [a, b, c] = mesh.corners(f).map(to_dvec3);
            (b - a).cross(c - a)
        })
        .collect();
    let mut creased = vec![false; mesh.triangles.len()];
    for (x, y) in edges.pairs() {
        if normals[x.face as usize].dot(normals[y.face as usize]) < 0.0 {
            creased[x.face as usize] = true;
            creased[y.face as usize] = true;
        }
    }
    creased
}

/// One face's use of a mesh edge: the edge's sorted vertex pair, the face, and the face's corners
/// at the lower and the higher vertex.
#[derive(Debug, PartialEq)]
struct EdgeUse {
    key: (u32, u32),
    face: u32,
    corners: [u8; 2],
}

/// Every use of every non-collapsed edge of a mesh, sorted by (edge, face) so the uses of one edge
/// are adjacent and their order does not depend on the thread count. Built once per mesh
/// ([`MeshEdges::shared`]) and shared by the chart and crease passes.
struct EdgeUses(Vec<EdgeUse>);

impl EdgeUses {
    fn of(mesh: &TriMesh) -> Self {
        let mut edges: Vec<EdgeUse> = Vec::with_capacity(mesh.triangles.len() * 3);
        for (f, t) in mesh.triangles.iter().enumerate() {
            for k in 0..3 {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                let (k, l) = (k as u8, ((k + 1) % 3) as u8);
                let (key, corners) = match a.cmp(&b) {
                    std::cmp::Ordering::Less => ((a, b), [k, l]),
                    std::cmp::Ordering::Greater => ((b, a), [l, k]),
                    std::cmp::Ordering::Equal => continue, // a collapsed edge connects nothing
                };
                edges.push(EdgeUse { key, face: f as u32, corners });
            }
        }
        edges.par_sort_unstable_by_key(|e| (e.key, e.face));
        EdgeUses(edges)
    }

    /// Every pair of uses of the same edge (each pair once, in sorted order).
    fn pairs(&self) -> impl Iterator<Item = (&EdgeUse, &EdgeUse)> {
        self.0.chunk_by(|x, y| x.key == y.key).flat_map(|group| {
            group.iter().enumerate().flat_map(move |(i, x)| group[i + 1..].iter().map(move |y| (x, y)))
        })
    }
}

/// Twice the signed UV area of every face.
pub(crate) fn signed_uv_area2(uv: &UvLayer) -> Vec<f64> {
    (0..uv.triangles.len()).into_par_iter().map(|f| face_uv_area2(uv, f)).collect()
}

/// Twice the signed UV area of face `f` (counter-clockwise positive).
pub(crate) fn face_uv_area2(uv: &UvLayer, f: usize) -> f64 {
    let [a, b, c] = uv.triangles[f].map(|i| uv.coords[i as usize]);
    signed_area2_2d(a, b, c)
}

/// The faces using each undirected edge `(low, high)` of `faces` (`(face id, corners)`), in the
/// order given; shared by the passes that walk faces across edges.
pub(crate) fn faces_by_edge(faces: impl Iterator<Item = (u32, [u32; 3])>) -> HashMap<(u32, u32), Vec<u32>> {
    let mut by_edge: HashMap<(u32, u32), Vec<u32>> = HashMap::new();
    for (f, c) in faces {
        for k in 0..3 {
            let (a, b) = (c[k], c[(k + 1) % 3]);
            by_edge.entry((a.min(b), a.max(b))).or_default().push(f);
        }
    }
    by_edge
}

/// Whether each face is degenerate in 3-D ([`DEGENERATE_AREA_REL`]).
pub(crate) fn degenerate_3d_faces(mesh: &TriMesh) -> Vec<bool> {
    let eps = degenerate_3d_area(mesh);
    (0..mesh.triangles.len()).into_par_iter().map(|f| is_degenerate_3d(face_area_3d(mesh, f), eps)).collect()
}

/// The 3-D area at or below which a face of `mesh` is degenerate: [`DEGENERATE_AREA_REL`] times
/// the squared diagonal of its bounding box.
pub(crate) fn degenerate_3d_area(mesh: &TriMesh) -> f64 {
    DEGENERATE_AREA_REL * mesh.bounds().map_or(0.0, |b| (to_dvec3(b.max) - to_dvec3(b.min)).length_squared())
}

/// Whether a face of 3-D area `area` ([`face_area_3d`]) is degenerate, `eps` from
/// [`degenerate_3d_area`] (a NaN area is).
pub(crate) fn is_degenerate_3d(area: f64, eps: f64) -> bool {
    area.is_nan() || area <= eps
}

/// The 3-D area of face `f` of `mesh`, in `f64`.
pub(crate) fn face_area_3d(mesh: &TriMesh, f: usize) -> f64 {
    let [a, b, c] = mesh.corners(f).map(to_dvec3);
    0.5 * (b - a).cross(c - a).length()
}

/// Faces whose orientation disagrees with their chart's area-weighted majority (module docs).
fn flipped_faces(area2: &[f64], face_chart: &[u32], charts: usize) -> Vec<u32> {
    let balance = chart_area2_totals(area2, face_chart, charts);
    ids(area2
        .iter()
        .zip(face_chart)
        .map(|(&a, &c)| orientation(a, balance[c as usize] >= 0.0) == Orientation::Flipped))
}

/// Each chart's total of `area2` (twice the signed UV area per face), summed in face order: its
/// sign is the chart's majority orientation (module docs; `≥ 0` counter-clockwise).
pub(crate) fn chart_area2_totals(area2: &[f64], face_chart: &[u32], charts: usize) -> Vec<f64> {
    let mut total = vec![0.0f64; charts];
    for (&a, &c) in area2.iter().zip(face_chart) {
        total[c as usize] += a;
    }
    total
}

/// How a face sits in its chart (module docs).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Orientation {
    /// The majority's way round, with measurable area.
    Right,
    /// Against the majority, with measurable area.
    Flipped,
    /// Of (near) zero UV area: neither.
    Degenerate,
}

/// The orientation of a face with twice-signed-area `area2` in a chart whose majority is
/// counter-clockwise when `majority_ccw`.
pub(crate) fn orientation(area2: f64, majority_ccw: bool) -> Orientation {
    if is_degenerate_uv(area2) {
        Orientation::Degenerate
    } else if (area2 > 0.0) == majority_ccw {
        Orientation::Right
    } else {
        Orientation::Flipped
    }
}

/// Whether twice-signed-area `area2` is a degenerate UV face (|area| ≤ [`DEGENERATE_UV_AREA`]).
fn is_degenerate_uv(area2: f64) -> bool {
    area2.abs() * 0.5 <= DEGENERATE_UV_AREA
}

/// The UV triangle of face `f` in raster pixels of an `r × r` image of `[0,1]²` (v up, row 0 at
/// `v = 1`): the one UV-to-pixel convention of the crate, shared with the layout picture.
pub(crate) fn uv_pixels(uv: &UvLayer, f: usize, r: u32) -> Tri2 {
    uv.triangles[f].map(|i| uv_to_pixel(uv.coords[i as usize], r))
}

/// `[u, v]` → `[x, y]` pixel coordinates on an `r × r` image of `[0,1]²`, v up.
pub(crate) fn uv_to_pixel(p: [f32; 2], r: u32) -> [f32; 2] {
    [p[0] * r as f32, (1.0 - p[1]) * r as f32]
}

/// How many faces cover each texel of the `r × r` UV raster (saturating at `u16::MAX`), each
/// texel centre decided exactly ([`Sampling::Exact`]): faces a hair apart never share one.
pub(crate) fn uv_coverage(uv: &UvLayer, r: u32) -> Vec<u16> {
    let mut counts = vec![0u16; r as usize * r as usize];
    raster_parallel(
        r,
        r,
        &mut counts,
        uv.triangles.len(),
        Sampling::Exact,
        |f| Some(uv_pixels(uv, f, r)),
        |c, _, _| *c = c.saturating_add(1),
    );
    counts
}

/// Faces covering a texel whose count is ≥ 2 (centres decided exactly, as in [`uv_coverage`]).
fn overlapping_faces(uv: &UvLayer, counts: &[u16], r: u32) -> Vec<u32> {
    let flags: Vec<bool> = (0..uv.triangles.len())
        .into_par_iter()
        .map(|f| {
            let mut hit = false;
            rasterize_triangle_exact(uv_pixels(uv, f, r), r, 0..r, |x, y, _| {
                hit |= counts[(y * r + x) as usize] >= 2;
            });
            hit
        })
        .collect();
    ids(flags.into_iter())
}

fn ids(flags: impl Iterator<Item = bool>) -> Vec<u32> {
    flags.enumerate().filter_map(|(i, b)| b.then_some(i as u32)).collect()
}

/// Union–find with path halving; unions keep the smaller root so labels are order-independent.
/// Shared by the UV statistics, the refinement's island splits and `injective`, and public for
/// the `boundary_sources` example's mesh pieces.
pub struct Dsu(Vec<u32>);

impl Dsu {
    /// `n` singletons.
    pub fn new(n: usize) -> Self {
        Dsu((0..n as u32).collect())
    }
    /// The root of `x`'s set (the smallest member ever made a root).
    pub fn find(&mut self, mut x: u32) -> u32 {
        while self.0[x as usize] != x {
            let p = self.0[x as usize];
            self.0[x as usize] = self.0[p as usize];
            x = p;
        }
        x
    }
    /// Joins the sets of `a` and `b`.
    pub fn union(&mut self, a: u32, b: u32) {
        let (ra, rb) = (self.find(a), self.find(b));
        let (lo, hi) = (ra.min(rb), ra.max(rb));
        self.0[hi as usize] = lo;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testmesh::{grid, with_uv_per_corner};

    #[test]
    fn remembered_edge_uses_are_those_of_the_mesh_asked_about() {
        // Three meshes with as many faces and vertices, each with other triangles: a look-up
        // must hand out the entry of the same triangles, or sort anew, and keep the newest two.
        let a = grid(4, |p| [p[0], p[1]]);
        let mut b = a.clone();
        b.triangles.reverse();
        let mut c = a.clone();
        c.triangles[0].rotate_left(1);
        let recent = RecentEdges::new(2);
        let got = |m: &TriMesh| {
            let e = recent.of(m);
            assert!(e.fit(m) && e.uses.0 == EdgeUses::of(m).0);
            e
        };
        let first_a = got(&a);
        assert!(Arc::ptr_eq(&first_a, &got(&a)), "a hit");
        let first_b = got(&b);
        assert!(!Arc::ptr_eq(&first_a, &first_b));
        assert!(Arc::ptr_eq(&first_a, &got(&a)) && Arc::ptr_eq(&first_b, &got(&b)), "both kept");
        got(&a);
        got(&c);
        assert!(Arc::ptr_eq(&first_a, &got(&a)), "the one asked about last kept");
        assert!(!Arc::ptr_eq(&first_b, &got(&b)), "the other dropped");
        assert_eq!(
            uv_charts(&c, c.uv.as_ref().unwrap()),
            charts_along(&EdgeUses::of(&c), &c, c.uv.as_ref().unwrap())
        );
    }

    #[test]
    fn a_unit_square_fills_the_raster_once_without_overlap() {
        let m = grid(4, |p| [(p[0] + 1.0) * 0.5, (p[1] + 1.0) * 0.5]);
        let a = analyse_uv(&m, None, 64).unwrap();
        assert_eq!(a.stats.charts, 1);
        assert_eq!(a.stats.utilisation, 1.0);
        assert_eq!(a.stats.overlap_fraction, 0.0);
        assert_eq!(a.stats.overlapping_faces, 0);
        assert_eq!(a.stats.flipped_faces, 0);
        assert_eq!(a.stats.degenerate_uv_faces, 0);
    }

    /// Two faces of a marching-cubes bunny's atlas a hair apart (their UVs as written; the raster
    /// module's test has the story): not an overlap. Snapped to 1/256 texel, the two were
    /// counted as overlapping (`nuvo eval` said 2 overlapping faces where there were none).
    #[test]
    fn faces_a_hair_apart_are_not_counted_as_overlapping() {
        let coords = vec![
            [0.94395614, 0.11589566],
            [0.94380766, 0.11832395],
            [0.9427842, 0.11736916],
            [0.9446356, 0.11790011],
            [0.943809, 0.1183098],
        ];
        let triangles = vec![[0, 1, 2], [3, 4, 0]];
        let m = TriMesh {
            positions: coords.iter().map(|&[u, v]| [u, v, 0.0]).collect(),
            triangles: triangles.clone(),
            uv: Some(UvLayer { coords, triangles }),
        };
        let a = analyse_uv(&m, None, 1024).unwrap();
        assert_eq!((a.stats.overlapping_faces, a.stats.overlap_fraction), (0, 0.0));
        // A third face laid on the second (its own copies of the coordinates) does overlap it.
        let mut laid = m.clone();
        laid.triangles.push([3, 4, 0]);
        let uv = laid.uv.as_mut().unwrap();
        uv.coords.extend([uv.coords[3], uv.coords[4], uv.coords[0]]);
        uv.triangles.push([5, 6, 7]);
        assert_eq!(analyse_uv(&laid, None, 1024).unwrap().stats.overlapping_faces, 2);
    }

    /// Square texels measure 1 whatever the map's scale and turn; a map twice as long along u as
    /// along v measures 2; a shear measures its singular values' ratio; a texel aspect's median
    /// and 90th percentile see how many faces are stretched.
    #[test]
    fn the_texel_aspect_is_the_ratio_of_the_maps_singular_values() {
        let aspect = |map: fn([f32; 3]) -> [f32; 2]| {
            let s = analyse_uv(&grid(4, map), None, 64).unwrap().stats;
            (s.texel_aspect_median, s.texel_aspect_p90)
        };
        let (m, p) =
            aspect(|p| [0.3 + 0.2 * (0.6 * p[0] - 0.8 * p[1]), 0.4 + 0.2 * (0.8 * p[0] + 0.6 * p[1])]);
        assert!((m - 1.0).abs() < 1e-5 && (p - 1.0).abs() < 1e-5, "{m} {p}");
        let (m, p) = aspect(|p| [0.5 + 0.4 * p[0], 0.5 + 0.2 * p[1]]);
        assert!((m - 2.0).abs() < 1e-5 && (p - 2.0).abs() < 1e-5, "{m} {p}");
        // u = x + y/2, v = y: JᵀJ = [[1, ½], [½, 5/4]] has eigenvalues (9 ± √17) / 8, so
        // σ₁/σ₂ = ((9 + √17) / (9 − √17))^½.
        let (m, _) = aspect(|p| [0.2 + 0.2 * (p[0] + 0.5 * p[1]), 0.5 + 0.2 * p[1]]);
        let want = ((9.0 + 17f64.sqrt()) / (9.0 - 17f64.sqrt())).sqrt();
        assert!((m - want).abs() < 1e-4, "{m} against {want}");
        // One face in eight stretched 3× (its corners' UVs apart from the rest): the median stays
        // 1 and the 90th percentile does not (rank 29 of 32 is past the 28 square faces).
        let base = grid(4, |p| [0.5 + 0.1 * p[0], 0.5 + 0.1 * p[1]]);
        let stretched = crate::testmesh::with_uv_per_corner(&base, |f, _, uv| {
            if f % 8 == 0 { [0.5 + 3.0 * (uv[0] - 0.5), uv[1]] } else { uv }
        });
        let s = analyse_uv(&stretched, None, 64).unwrap().stats;
        assert!((s.texel_aspect_median - 1.0).abs() < 1e-5, "{s:?}");
        assert!((s.texel_aspect_p90 - 3.0).abs() < 1e-4, "{s:?}");
    }

    #[test]
    fn a_seam_makes_two_charts_and_scattering_makes_one_per_face() {
        // Corners of faces left of x = 0 are shifted in UV: the column of edges at x = 0 is a seam.
        let m = grid(4, |p| [(p[0] + 1.0) * 0.25, (p[1] + 1.0) * 0.5]);
        let seamed = with_uv_per_corner(&m, |f, _, uv| {
            let left = m.corners(f).iter().all(|c| c[0] <= 0.0);
            if left { [uv[0] + 0.5, uv[1]] } else { uv }
        });
        assert_eq!(analyse_uv(&seamed, None, 32).unwrap().stats.charts, 2);
        let scattered = with_uv_per_corner(&m, |f, _, uv| [uv[0] + f as f32, uv[1]]);
        assert_eq!(analyse_uv(&scattered, None, 32).unwrap().stats.charts, m.triangles.len());
    }

    #[test]
    fn a_fold_reports_the_minority_as_flipped_and_overlapping() {
        // u = |x - 0.5| folds the plane along x = 0.5: the strip x > 0.5 (1/4 of the faces) is
        // mirrored relative to the rest of its (single) chart and lands on top of it in UV.
        let m = grid(8, |p| [(p[0] - 0.5).abs() * 0.6, (p[1] + 1.0) * 0.5]);
        let a = analyse_uv(&m, None, 128).unwrap();
        assert_eq!(a.stats.charts, 1);
        assert_eq!(a.stats.flipped_faces, m.triangles.len() / 4);
        assert!((a.stats.flipped_fraction - 0.25).abs() < 1e-12);
        for &f in &a.flipped {
            assert!(m.corners(f as usize).iter().all(|c| c[0] >= 0.5), "face {f} is not in the fold");
        }
        // The folded strip covers 1/3 of the used UV area twice.
        assert!((a.stats.overlap_fraction - 1.0 / 3.0).abs() < 0.02, "{}", a.stats.overlap_fraction);
        assert!(a.stats.overlapping_faces >= m.triangles.len() / 2);
    }

    #[test]
    fn flips_on_a_crease_of_the_surface_are_counted_apart() {
        // A 4×4 grid in the plane z = 0, then the column of faces right of x = 0.5 folded back
        // over it by 150° about the line x = 0.5 (normals −0.87 apart: a crease). The UVs are the
        // straight projection (x, y), so the folded column lands mirrored on the column beside it:
        // its 8 faces are flipped. Creased are the faces across the 4 edges on the crease line,
        // one on each side of each edge; 4 of them are folded ones.
        let mut m = grid(4, |p| [(p[0] + 1.0) * 0.5, (p[1] + 1.0) * 0.5]);
        let (c, s) = (150f32.to_radians().cos(), 150f32.to_radians().sin());
        for p in &mut m.positions {
            if p[0] > 0.5 {
                let d = p[0] - 0.5;
                *p = [0.5 + d * c, p[1], d * s];
            }
        }
        let uv = m.uv.as_mut().unwrap();
        uv.coords = m.positions.iter().map(|p| [(p[0] + 1.0) * 0.5, (p[1] + 1.0) * 0.5]).collect();
        let creased = creased_faces(&m);
        let a = analyse_uv(&m, None, 64).unwrap();
        assert_eq!(creased.iter().filter(|&&c| c).count(), 8);
        for f in (0..m.triangles.len()).filter(|&f| creased[f]) {
            let on_line = m.triangles[f].iter().filter(|&&v| m.positions[v as usize][0] == 0.5).count();
            assert_eq!(on_line, 2, "creased face {f} has its edge on the crease line");
        }
        assert_eq!(a.stats.flipped_faces, 8, "the folded column");
        assert_eq!(a.stats.flipped_on_creases, 4);
        // The same fold in UV on a flat surface (the test above) has no crease to blame.
        let flat = grid(8, |p| [(p[0] - 0.5).abs() * 0.6, (p[1] + 1.0) * 0.5]);
        let a = analyse_uv(&flat, None, 64).unwrap();
        assert!(a.stats.flipped_faces > 0);
        assert_eq!(a.stats.flipped_on_creases, 0);
    }

    #[test]
    fn degenerate_faces_are_reported_not_flipped() {
        let mut m = grid(2, |p| [(p[0] + 1.0) * 0.5, (p[1] + 1.0) * 0.5]);
        let uv = m.uv.as_mut().unwrap();
        let t = uv.triangles[0];
        uv.coords.push(uv.coords[t[0] as usize]);
        uv.triangles[0] = [t[0], uv.coords.len() as u32 - 1, t[2]]; // two equal corners: zero area
        let a = analyse_uv(&m, None, 16).unwrap();
        assert_eq!(a.degenerate_uv, vec![0]);
        assert_eq!(a.stats.flipped_faces, 0);
    }

    #[test]
    fn missing_uvs_and_bad_labels_are_errors() {
        let mut m = grid(2, |p| [p[0], p[1]]);
        assert!(analyse_uv(&m, Some(&[0, 1]), 16).is_err());
        m.uv = None;
        assert!(matches!(analyse_uv(&m, None, 16), Err(AtlasError::NoUv { .. })));
    }
}

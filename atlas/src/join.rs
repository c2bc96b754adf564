//! Joining small islands into a neighbouring one (issue 19: "single-face and sliver islands join a
//! neighbouring chart"), and smoothing the seams between islands.
//!
//! Nuvo's bake leaves a few islands of one to a few dozen faces where a chart's region frays (a
//! face whose corners the networks assign to different charts, a sliver the injective pass
//! detached). Each costs a seam all round it and a cell in the atlas for almost no surface. On the
//! Common Shapes atlases 128 of 250 islands held under 0.2% of their mesh's area.
//! [`join_small_islands`] grows each such island's faces onto the neighbour it shares the longest
//! edge with, face by face from their shared edges, and keeps the result only where it stays
//! injective, so it never adds a flip or an overlap.
//!
//! Definitions (exact):
//! - **Islands**: [`crate::uvstats::uv_islands`]. An island is **small** when its 3-D area is below
//!   [`JoinOptions::max_area_share`] of the mesh's. Small islands are tried in order of
//!   increasing area (ties by island index), each once, against the islands as they are then
//!   (so a small island can join one that grew before it).
//! - **Neighbour**: an island with a face across a mesh edge (same two vertices) from one of the
//!   small island's faces; neighbours are tried in order of the summed 3-D length of such edges,
//!   longest first (ties by the lower island index), at most [`MAX_NEIGHBOURS_TRIED`].
//! - **Seeding**: every mesh vertex of a shared edge takes the neighbour's texture coordinate at
//!   it, from the neighbour's face across that edge. When one vertex would take two different
//!   values (the neighbour has its own seam there), or when the growth below fails its check,
//!   the same is tried seeded from the longest shared edge alone (the island then joins across
//!   that edge and its other shared edges stay seams), before the next neighbour.
//! - **Growing**: faces of the small island with two corners placed and the third not are placed
//!   breadth-first (in face order within each wave), the third corner on the side of the placed
//!   edge that gives the face the neighbour's orientation (the sign of its summed signed UV
//!   area), by one of two rules tried in turn: **similar** (the face similar to its 3-D shape,
//!   at the placed edge's UV-to-3-D scale: no angle distortion), then **density** (as far along
//!   the edge as in 3-D at the edge's scale, as far from it as in 3-D at the neighbour's scale
//!   `sqrt(ΣA_uv / ΣA_3d)`, so a seed edge stretched in UV stretches the face only along itself).
//!   A corner placed once keeps its place for every later face.
//! - **Check**: the joined faces must all have that orientation with a UV area above 1e-12 of the
//!   neighbour's UV area per face and a UV-to-3-D area ratio within a factor [`MAX_AREA_RATIO`]
//!   of the neighbour's (faces of no 3-D area excepted), and none may overlap (interiors) a face
//!   of the neighbour or another joined face, and the neighbour's area distortion
//!   ([`crate::partuv`]'s, of one chart) may rise by at most [`MAX_DISTORTION_RISE`]. Otherwise the next rule or neighbour is tried,
//!   and when none passes the island stays as it was.
//! - **Seam smoothing**: then, in passes over the faces in order (at most [`SMOOTHING_PASSES`],
//!   until one moves nothing), a face with two of its edges on the seam to one other island (each
//!   such edge used by exactly two faces) moves to that island, seeded and checked as above,
//!   unless it is its island's last face. The bake's seams follow the networks' chart choice face
//!   by face and so zig-zag; each move replaces two seam edges by the face's third, shorter by
//!   the triangle inequality, so the passes end and the seams straighten (Common Shapes: seam
//!   length −10 to −30%, Boundary up on every mesh).
//! - **Output**: same positions, faces and face order; joined faces use the neighbour's
//!   coordinates at the seeded vertices and new coordinates (appended) at the grown ones. The
//!   small island's old coordinates stay in the layer unused; island packing drops them.
//!
//! Sequential and free of hashing order: the result is deterministic.

use foldhash::{HashMap, HashMapExt};

use nuvo_geometry::{TriMesh, UvLayer};
use rayon::prelude::*;
use serde::Serialize;

use crate::error::AtlasError;
use crate::geom::to_dvec3;
use crate::injective::{TriangleGrid, mean_edge};
use crate::partuv::{area_distortion_summed, face_areas_3d};
use crate::refine::area2;
use crate::uvstats::{require_uv, uv_islands};

/// Passes of seam smoothing over every face, at most (each pass that moves nothing ends it).
pub const SMOOTHING_PASSES: usize = 8;
/// Neighbours tried per small island, longest shared edge first.
pub const MAX_NEIGHBOURS_TRIED: usize = 3;
/// Largest ratio (either way) between a joined face's UV-to-3-D area ratio and its neighbour's
/// whole one: a grown face beyond it would stretch the texture there more than the join is worth.
pub const MAX_AREA_RATIO: f64 = 4.0;
/// How much a join may raise the neighbour's area distortion (the mean folded area ratio).
pub const MAX_DISTORTION_RISE: f64 = 0.01;

/// Which islands [`join_small_islands`] joins.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct JoinOptions {
    /// An island holding less than this share of the mesh's 3-D area is small.
    pub max_area_share: f64,
}

impl Default for JoinOptions {
    /// 0.2% of the surface: twice the share below which `nuvo_geometry::profile` calls a piece a
    /// fragment.
    fn default() -> Self {
        Self { max_area_share: 2e-3 }
    }
}

/// What [`join_small_islands`] did.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct JoinReport {
    /// Islands before.
    pub islands_before: usize,
    /// Small islands found.
    pub small: usize,
    /// Small islands joined into a neighbour.
    pub joined: usize,
    /// Faces those held.
    pub joined_faces: usize,
    /// Faces moved across a seam by the smoothing.
    pub seam_faces_moved: usize,
}

/// A mesh whose small islands have joined their neighbours, and the report.
#[derive(Clone, Debug)]
pub struct Joined {
    /// Same positions and faces, new UV layer.
    pub mesh: TriMesh,
    /// What was done.
    pub report: JoinReport,
}

/// Joins every small island of `mesh` into a neighbouring island where that keeps both injective
/// (module docs).
///
/// Errors ([`AtlasError`]): the mesh has no UVs or an index out of range.
pub fn join_small_islands(mesh: &TriMesh, opts: &JoinOptions) -> Result<Joined, AtlasError> {
    let uv = require_uv(mesh)?;
    let islands = uv_islands(mesh, uv);
    let n = islands.len();
    let area3 = face_areas_3d(mesh);
    let total: f64 = area3.iter().sum();
    let island_area: Vec<f64> =
        islands.iter().map(|fs| fs.iter().map(|&f| area3[f as usize]).sum()).collect();
    let mut label = vec![0u32; mesh.triangles.len()];
    for (i, fs) in islands.iter().enumerate() {
        for &f in fs {
            label[f as usize] = i as u32;
        }
    }
    let mut small: Vec<usize> = (0..n).filter(|&i| island_area[i] < opts.max_area_share * total).collect();
    small.sort_by(|&a, &b| island_area[a].total_cmp(&island_area[b]).then(a.cmp(&b)));
    let mut report = JoinReport { islands_before: n, small: small.len(), ..Default::default() };
    let edge_faces = EdgeFaces::of(mesh);
    let mut work = Work {
        mesh,
        area3,
        coords: uv.coords.iter().map(|p| p.map(f64::from)).collect(),
        tris: uv.triangles.clone(),
        kept: vec![None; islands.len()],
        members: islands,
        label,
    };
    for s in small {
        let faces = work.members[s].clone();
        // Neighbours by shared 3-D edge length.
        let mut shared: Vec<(u32, f64)> = Vec::new();
        for &f in &faces {
            let t = mesh.triangles[f as usize];
            for k in 0..3 {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                let len = to_dvec3(mesh.positions[a as usize]).distance(to_dvec3(mesh.positions[b as usize]));
                for &(g, _) in edge_faces.around(f, k) {
                    let l = work.label[g as usize];
                    if l as usize != s {
                        match shared.iter_mut().find(|(m, _)| *m == l) {
                            Some(e) => e.1 += len,
                            None => shared.push((l, len)),
                        }
                    }
                }
            }
        }
        shared.sort_by(|a, b| b.1.total_cmp(&a.1).then(a.0.cmp(&b.0)));
        let tries = shared.iter().take(MAX_NEIGHBOURS_TRIED).flat_map(|&(nb, _)| {
            [Seeds::All, Seeds::Longest]
                .map(|seeds| [(nb, Growth::Similar, seeds), (nb, Growth::Density, seeds)])
        });
        for (nb, growth, seeds) in tries.flatten() {
            if let Some(placed) = work.try_join(&faces, nb, &edge_faces, growth, seeds) {
                work.commit(s, nb, &faces, placed);
                report.joined += 1;
                report.joined_faces += faces.len();
                break;
            }
        }
    }
    // Seam smoothing: a face with two edges on the seam to one other island moves across it.
    for _ in 0..SMOOTHING_PASSES {
        let mut moved = 0;
        for f in 0..mesh.triangles.len() as u32 {
            let own = work.label[f as usize];
            if work.members[own as usize].len() <= 1 {
                continue;
            }
            let mut seams: Vec<(u32, usize)> = Vec::new(); // (other island, edges on the seam to it)
            for k in 0..3 {
                if let [(g, _), (h, _)] = edge_faces.around(f, k) {
                    let g = if *g == f { *h } else { *g };
                    let l = work.label[g as usize];
                    if l != own {
                        match seams.iter_mut().find(|(m, _)| *m == l) {
                            Some(e) => e.1 += 1,
                            None => seams.push((l, 1)),
                        }
                    }
                }
            }
            let Some(&(nb, _)) = seams.iter().find(|(_, n)| *n >= 2) else { continue };
            if let Some(placed) = work.try_join(&[f], nb, &edge_faces, Growth::Similar, Seeds::All) {
                work.move_face(f, own, nb, placed);
                moved += 1;
            }
        }
        report.seam_faces_moved += moved;
        if moved == 0 {
            break;
        }
    }
    let coords = work.coords.iter().map(|p| p.map(|x| x as f32)).collect();
    Ok(Joined {
        mesh: TriMesh {
            positions: mesh.positions.clone(),
            triangles: mesh.triangles.clone(),
            uv: Some(UvLayer { coords, triangles: work.tris }),
        },
        report,
    })
}

/// The faces on each mesh edge, each with the corner its side of the edge leaves from (the edge
/// `(t[k], t[k + 1])` of face `t` is its corner `k`'s), in face order; asked for by a face and one
/// of its corners. Built once by sorting every edge use (edges from a vertex to itself
/// included), where a hash map of per-edge lists cost an allocation per edge (on the horse a
/// third of the join's time, building and freeing it).
struct EdgeFaces {
    /// `(face, corner)` of every edge use, grouped by edge, each group in face order.
    uses: Vec<(u32, usize)>,
    /// Per face and corner, the range of its edge's group in `uses`.
    group: Vec<[(u32, u32); 3]>,
}

impl EdgeFaces {
    fn of(mesh: &TriMesh) -> EdgeFaces {
        let mut sorted: Vec<((u32, u32), u32, u8)> = mesh
            .triangles
            .iter()
            .enumerate()
            .flat_map(|(f, t)| {
                (0..3).map(move |k| ((t[k].min(t[(k + 1) % 3]), t[k].max(t[(k + 1) % 3])), f as u32, k as u8))
            })
            .collect();
        // Every element differs (a face's corner appears once), so the unstable sort's order is fixed.
        sorted.par_sort_unstable();
        let mut group = vec![[(0u32, 0u32); 3]; mesh.triangles.len()];
        let mut start = 0;
        for run in sorted.chunk_by(|x, y| x.0 == y.0) {
            let range = (start as u32, (start + run.len()) as u32);
            for &(_, f, k) in run {
                group[f as usize][k as usize] = range;
            }
            start += run.len();
        }
        let uses = sorted.into_iter().map(|(_, f, k)| (f, k as usize)).collect();
        EdgeFaces { uses, group }
    }

    /// The faces on face `f`'s edge from its corner `k` (`f` among them), with their corners.
    fn around(&self, f: u32, k: usize) -> &[(u32, usize)] {
        let (start, end) = self.group[f as usize][k];
        &self.uses[start as usize..end as usize]
    }
}

/// The layout being joined.
struct Work<'a> {
    mesh: &'a TriMesh,
    area3: Vec<f64>,
    coords: Vec<[f64; 2]>,
    tris: Vec<[u32; 3]>,
    members: Vec<Vec<u32>>,
    label: Vec<u32>,
    /// Per island, what every try against it reads of it (kept once a try asked).
    kept: Vec<Option<NeighbourValues>>,
}

/// What [`Work::try_join`] reads of the neighbour island, kept between tries: thousands of small
/// islands of a fragmented mesh try the same few large neighbours, and the seam smoothing tries
/// one face at a time against the same large islands; each pass gathering a neighbour of tens of
/// thousands of faces was most of the join's time (the horse's join, 0.5 s on one core). The
/// per-face values are kept in step with the island's members as faces come and go (a face's
/// coordinates never change: joins only append new ones); the totals, sums in the members'
/// order, are summed again after a removal and continued by an appended face's values (a
/// sequential sum's next step), so every value is exactly what a fresh pass over the island
/// gives.
#[derive(Clone, Debug, Default)]
struct NeighbourValues {
    /// Per face (members' order), its UV triangle.
    uv: Vec<[[f64; 2]; 3]>,
    /// Per face, twice its signed UV area.
    signed: Vec<f64>,
    /// Per face, its 3-D area.
    area_3d: Vec<f64>,
    /// The sums over the faces; `None` until asked for and after a face was removed.
    totals: Option<Totals>,
}

/// An island's sums ([`NeighbourValues`]).
#[derive(Clone, Copy, Debug)]
struct Totals {
    /// Twice the signed UV area.
    signed: f64,
    /// Twice the unsigned UV area.
    unsigned: f64,
    /// The 3-D area.
    area3: f64,
    /// Its PartUV area distortion alone, once a try got that far.
    distortion: Option<f64>,
}

impl NeighbourValues {
    /// Appends a face (its UV triangle `uv`, its 3-D area `area3`). The totals, sums in the
    /// members' order, take its values last: the same bits as summing again.
    fn push(&mut self, uv: [[f64; 2]; 3], area3: f64) {
        let signed = area2(uv);
        self.uv.push(uv);
        self.signed.push(signed);
        self.area_3d.push(area3);
        if let Some(t) = &mut self.totals {
            *t = Totals {
                signed: t.signed + signed,
                unsigned: t.unsigned + signed.abs(),
                area3: t.area3 + area3,
                distortion: None,
            };
        }
    }

    /// Removes the face at `index` of the members.
    fn remove(&mut self, index: usize) {
        self.uv.remove(index);
        self.signed.remove(index);
        self.area_3d.remove(index);
        self.totals = None;
    }

    /// The totals, summed now unless kept.
    fn totals(&mut self) -> Totals {
        *self.totals.get_or_insert_with(|| Totals {
            signed: self.signed.iter().sum(),
            unsigned: self.signed.iter().map(|a| a.abs()).sum(),
            area3: self.area_3d.iter().sum(),
            distortion: None,
        })
    }
}

/// A joined island's corners: per face of it, per corner, an existing coordinate or a new one
/// (an index into the new values).
struct Placed {
    corners: Vec<[Corner; 3]>,
    new_values: Vec<[f64; 2]>,
}

/// Which shared edges seed the growth (module docs).
#[derive(Clone, Copy, Debug, PartialEq)]
enum Seeds {
    /// Every edge the small island shares with the neighbour.
    All,
    /// The longest of them only: the rest become seams inside the joined island.
    Longest,
}

/// How a grown face's free corner is placed from its placed edge (module docs).
#[derive(Clone, Copy, Debug, PartialEq)]
enum Growth {
    /// The face similar to its 3-D shape, at the placed edge's scale.
    Similar,
    /// Along the edge at its scale, across it at the neighbour's.
    Density,
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum Corner {
    Existing(u32),
    New(u32),
}

impl Work<'_> {
    /// The faces `faces` grown onto island `nb` and checked (module docs), `None` when they cannot
    /// join it.
    fn try_join(
        &mut self,
        faces: &[u32],
        nb: u32,
        edge_faces: &EdgeFaces,
        growth: Growth,
        seeds: Seeds,
    ) -> Option<Placed> {
        let Totals { signed, unsigned, area3: nb_area3, distortion: alone } = self.neighbour(nb).totals();
        let nb_values = self.kept[nb as usize].as_ref().expect("computed above");
        let nb_faces = &self.members[nb as usize];
        if signed == 0.0 || unsigned <= 0.0 {
            return None;
        }
        let orient = signed.signum();
        let density = unsigned / nb_area3.max(f64::MIN_POSITIVE); // UV area per 3-D area
        let scale = density.sqrt(); // UV length per 3-D length
        // Seeds: the neighbour's coordinate at each vertex of a shared edge (or of the longest).
        let mut shared: Vec<(u32, usize)> = Vec::new();
        let mut longest: Option<(f64, (u32, usize))> = None;
        for &f in faces {
            let t = self.mesh.triangles[f as usize];
            for k in 0..3 {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                let len = to_dvec3(self.mesh.positions[a as usize])
                    .distance(to_dvec3(self.mesh.positions[b as usize]));
                for &(g, j) in edge_faces.around(f, k) {
                    if self.label[g as usize] == nb {
                        shared.push((g, j));
                        if longest.is_none_or(|(l, _)| len > l) {
                            longest = Some((len, (g, j)));
                        }
                    }
                }
            }
        }
        if seeds == Seeds::Longest {
            shared = longest.map(|(_, e)| vec![e]).unwrap_or_default();
        }
        let mut at: HashMap<u32, Corner> = HashMap::new();
        let mut value: HashMap<u32, [f64; 2]> = HashMap::new();
        for &(g, j) in &shared {
            let (gt, gc) = (self.mesh.triangles[g as usize], self.tris[g as usize]);
            for (v, c) in [(gt[j], gc[j]), (gt[(j + 1) % 3], gc[(j + 1) % 3])] {
                let p = self.coords[c as usize];
                match value.get(&v) {
                    Some(q) if *q != p => return None,
                    Some(_) => {}
                    None => {
                        value.insert(v, p);
                        at.insert(v, Corner::Existing(c));
                    }
                }
            }
        }
        if at.is_empty() {
            return None;
        }
        // Grow breadth-first.
        let mut new_values: Vec<[f64; 2]> = Vec::new();
        let mut done = vec![false; faces.len()];
        loop {
            let mut progress = false;
            for (i, &f) in faces.iter().enumerate() {
                if done[i] {
                    continue;
                }
                let t = self.mesh.triangles[f as usize];
                let known: Vec<usize> = (0..3).filter(|&k| value.contains_key(&t[k])).collect();
                match known.len() {
                    3 => done[i] = true,
                    2 => {
                        // Corners in cyclic order: placed `a`, `b`, then the free one `c`.
                        let k = (0..3).find(|k| !known.contains(k)).unwrap();
                        let (a, b, c) = (t[(k + 1) % 3], t[(k + 2) % 3], t[k]);
                        let (ua, ub) = (value[&a], value[&b]);
                        let pos = |v: u32| to_dvec3(self.mesh.positions[v as usize]);
                        let (e, w) = (pos(b) - pos(a), pos(c) - pos(a));
                        let len2 = e.length_squared();
                        if len2 <= 0.0 {
                            return None;
                        }
                        // `c` in the frame of edge a→b: along it and to its left (a, b, c CCW).
                        let along = e.dot(w) / len2;
                        let d = [ub[0] - ua[0], ub[1] - ua[1]];
                        let d_len = d[0].hypot(d[1]);
                        if d_len <= 0.0 {
                            return None;
                        }
                        let left = match growth {
                            Growth::Similar => e.cross(w).length() / len2,
                            Growth::Density => e.cross(w).length() / len2.sqrt() * scale / d_len,
                        };
                        let n = [-d[1] * orient, d[0] * orient];
                        let uc = [ua[0] + along * d[0] + left * n[0], ua[1] + along * d[1] + left * n[1]];
                        new_values.push(uc);
                        value.insert(c, uc);
                        at.insert(c, Corner::New(new_values.len() as u32 - 1));
                        done[i] = true;
                        progress = true;
                    }
                    _ => {}
                }
            }
            if !progress {
                break;
            }
        }
        if !done.iter().all(|&d| d) {
            return None;
        }
        // Check: oriented, not degenerate, no overlap with the neighbour or each other. Triangles
        // are tested counter-clockwise (mirrored when the neighbour is clockwise).
        let min_area2 = 1e-12 * unsigned * 2.0 / nb_faces.len() as f64;
        let ccw = |t: [[f64; 2]; 3]| if orient > 0.0 { t } else { t.map(|p| [-p[0], p[1]]) };
        let joined: Vec<[[f64; 2]; 3]> =
            faces.iter().map(|&f| self.mesh.triangles[f as usize].map(|v| value[&v])).collect();
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for (t, &f) in joined.iter().zip(faces) {
            let area2 = area2(*t);
            if area2 * orient <= min_area2 {
                return None;
            }
            let a3 = self.area3[f as usize];
            if a3 > 0.0 {
                let r = 0.5 * area2.abs() / a3 / density;
                if r.max(1.0 / r) > MAX_AREA_RATIO {
                    return None;
                }
            }
            for p in t {
                for k in 0..2 {
                    lo[k] = lo[k].min(p[k]);
                    hi[k] = hi[k].max(p[k]);
                }
            }
        }
        let near: Vec<(usize, [[f64; 2]; 3])> = nb_values
            .uv
            .iter()
            .filter(|t| (0..2).all(|k| t.iter().any(|p| p[k] >= lo[k]) && t.iter().any(|p| p[k] <= hi[k])))
            .map(|&t| ccw(t))
            .enumerate()
            .collect();
        let joined_ccw: Vec<(usize, [[f64; 2]; 3])> = joined.iter().map(|t| ccw(*t)).enumerate().collect();
        let mut grid = TriangleGrid::new(&near, mean_edge(&joined_ccw).max(mean_edge(&near)));
        for (_, t) in &joined_ccw {
            if !grid.overlapping(*t).is_empty() {
                return None;
            }
            grid.insert(*t);
        }
        // The neighbour's area distortion (PartUV's measure) may rise only a little. Its sums
        // over the neighbour are the kept totals (the same bits as summing its faces again),
        // continued over the joined faces.
        let nb_faces_areas = nb_values.area_3d.iter().copied().zip(nb_values.signed.iter().map(|a| a.abs()));
        let joined_areas: Vec<(f64, f64)> =
            faces.iter().zip(&joined).map(|(&f, &t)| (self.area3[f as usize], area2(t).abs())).collect();
        let alone = alone.unwrap_or_else(|| {
            let sums = [nb_area3, unsigned];
            area_distortion_summed(nb_faces_areas.clone(), nb_faces.len(), sums).value.unwrap_or(1.0)
        });
        let sums = joined_areas.iter().fold([nb_area3, unsigned], |[a, u], &(a3, auv)| [a + a3, u + auv]);
        let grown_faces = nb_faces_areas.chain(joined_areas.iter().copied());
        let grown =
            area_distortion_summed(grown_faces, nb_faces.len() + faces.len(), sums).value.unwrap_or(1.0);
        if let Some(totals) = self.kept[nb as usize].as_mut().and_then(|s| s.totals.as_mut()) {
            totals.distortion = Some(alone);
        }
        if grown > alone + MAX_DISTORTION_RISE {
            return None;
        }
        let corners = faces.iter().map(|&f| self.mesh.triangles[f as usize].map(|v| at[&v])).collect();
        Some(Placed { corners, new_values })
    }

    /// Island `nb`'s [`NeighbourValues`], kept or from a pass over its faces.
    fn neighbour(&mut self, nb: u32) -> &mut NeighbourValues {
        if self.kept[nb as usize].is_none() {
            let mut values = NeighbourValues::default();
            for &g in &self.members[nb as usize] {
                values.push(self.uv_of(g), self.area3[g as usize]);
            }
            self.kept[nb as usize] = Some(values);
        }
        self.kept[nb as usize].as_mut().expect("filled above")
    }

    /// Face `f`'s UV triangle as it stands.
    fn uv_of(&self, f: u32) -> [[f64; 2]; 3] {
        self.tris[f as usize].map(|c| self.coords[c as usize])
    }

    /// Moves face `f` from island `own` to `nb`, its corners as `placed` says.
    fn move_face(&mut self, f: u32, own: u32, nb: u32, placed: Placed) {
        let base = self.coords.len() as u32;
        self.coords.extend_from_slice(&placed.new_values);
        self.tris[f as usize] = placed.corners[0].map(|c| match c {
            Corner::Existing(i) => i,
            Corner::New(i) => base + i,
        });
        self.label[f as usize] = nb;
        let members = &mut self.members[own as usize];
        if let Some(index) = members.iter().position(|&g| g == f) {
            members.remove(index);
            if let Some(kept) = &mut self.kept[own as usize] {
                kept.remove(index);
            }
        }
        self.members[nb as usize].push(f);
        let (uv, area3) = (self.uv_of(f), self.area3[f as usize]);
        if let Some(kept) = &mut self.kept[nb as usize] {
            kept.push(uv, area3);
        }
    }

    /// Writes `placed` for island `s`'s `faces`, which now belong to `nb`.
    fn commit(&mut self, s: usize, nb: u32, faces: &[u32], placed: Placed) {
        self.kept[s] = None;
        let base = self.coords.len() as u32;
        self.coords.extend_from_slice(&placed.new_values);
        for (&f, corners) in faces.iter().zip(&placed.corners) {
            self.tris[f as usize] = corners.map(|c| match c {
                Corner::Existing(i) => i,
                Corner::New(i) => base + i,
            });
            self.label[f as usize] = nb;
        }
        let moved = std::mem::take(&mut self.members[s]);
        if self.kept[nb as usize].is_some() {
            let added: Vec<_> = moved.iter().map(|&f| (self.uv_of(f), self.area3[f as usize])).collect();
            let kept = self.kept[nb as usize].as_mut().expect("checked above");
            for (uv, area3) in added {
                kept.push(uv, area3);
            }
        }
        self.members[nb as usize].extend(moved);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geom::to_dvec3;
    use crate::uvstats::uv_charts;

    #[test]
    fn the_faces_round_an_edge_are_every_face_using_it_in_face_order() {
        // A grid, a face repeated (an edge used three times) and a face with a vertex twice (an
        // edge from a vertex to itself).
        let mut mesh = crate::testmesh::grid(3, |p| [p[0], p[1]]);
        let (t0, t5) = (mesh.triangles[0], mesh.triangles[5]);
        mesh.triangles.insert(2, t5);
        mesh.triangles.push([t0[0], t0[0], t0[1]]);
        let edges = EdgeFaces::of(&mesh);
        let key = |t: [u32; 3], k: usize| (t[k].min(t[(k + 1) % 3]), t[k].max(t[(k + 1) % 3]));
        for (f, &t) in mesh.triangles.iter().enumerate() {
            for k in 0..3 {
                let want: Vec<(u32, usize)> = (0..mesh.triangles.len())
                    .flat_map(|g| (0..3).map(move |j| (g, j)))
                    .filter(|&(g, j)| key(mesh.triangles[g], j) == key(t, k))
                    .map(|(g, j)| (g as u32, j))
                    .collect();
                assert_eq!(edges.around(f as u32, k), want.as_slice(), "face {f} corner {k}");
            }
        }
    }

    /// The kept per-island values after faces moved between islands, and after a small island
    /// joined, are bit for bit those of a fresh pass over the islands as they then are: a kept
    /// value that drifted would change which joins pass their checks.
    #[test]
    fn kept_neighbour_values_equal_a_fresh_pass_after_moves() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        // A 12 × 12 grid with wobbly UVs, its faces split into three islands by column.
        let mesh = crate::testmesh::grid(12, |p| [0.3 * p[0] + 0.01 * (7.0 * p[1]).sin(), 0.3 * p[1]]);
        let uv = mesh.uv.clone().unwrap();
        let label: Vec<u32> = (0..mesh.triangles.len() as u32).map(|f| (f / 2 % 12 / 4).min(2)).collect();
        let mut members = vec![Vec::new(); 3];
        for (f, &l) in label.iter().enumerate() {
            members[l as usize].push(f as u32);
        }
        let mut work = Work {
            mesh: &mesh,
            area3: face_areas_3d(&mesh),
            coords: uv.coords.iter().map(|p| p.map(f64::from)).collect(),
            tris: uv.triangles.clone(),
            kept: vec![None; 3],
            members,
            label,
        };
        let fresh = |w: &Work, i: usize| {
            let mut f = NeighbourValues::default();
            for &g in &w.members[i] {
                f.push(w.uv_of(g), w.area3[g as usize]);
            }
            f.totals();
            f
        };
        let same = |a: &NeighbourValues, b: &NeighbourValues| {
            let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            let (ta, tb) = (a.totals.unwrap(), b.totals.unwrap());
            a.uv == b.uv
                && bits(&a.signed) == bits(&b.signed)
                && bits(&a.area_3d) == bits(&b.area_3d)
                && [ta.signed, ta.unsigned, ta.area3].map(f64::to_bits)
                    == [tb.signed, tb.unsigned, tb.area3].map(f64::to_bits)
        };
        for i in 0..3 {
            work.neighbour(i).totals();
        }
        for step in 0..60u32 {
            // A face of one island moves to another, keeping its own coordinates (one new
            // value moved a little, as a grown corner would be).
            let own = rng.random_range(0..3u32);
            if work.members[own as usize].len() <= 1 {
                continue;
            }
            let nb = (own + rng.random_range(1..3u32)) % 3;
            let f = work.members[own as usize][rng.random_range(0..work.members[own as usize].len())];
            let t = work.tris[f as usize];
            let moved = work.coords[t[2] as usize];
            let placed = Placed {
                corners: vec![[Corner::Existing(t[0]), Corner::Existing(t[1]), Corner::New(0)]],
                new_values: vec![[moved[0] + 1e-3 * step as f64, moved[1]]],
            };
            work.move_face(f, own, nb, placed);
            if step % 3 == 0 {
                // Totals read between moves, as tries do.
                for i in 0..3 {
                    work.neighbour(i).totals();
                }
            }
        }
        // Island 0 joins island 1 whole.
        let faces = work.members[0].clone();
        let corners = faces.iter().map(|&f| work.tris[f as usize].map(Corner::Existing)).collect();
        work.commit(0, 1, &faces, Placed { corners, new_values: Vec::new() });
        assert!(work.members[0].is_empty() && work.kept[0].is_none());
        for i in 1..3u32 {
            work.neighbour(i).totals();
            let kept = work.kept[i as usize].clone().unwrap();
            assert!(same(&kept, &fresh(&work, i as usize)), "island {i}");
        }
    }

    /// A strip of `k` unit squares along x (two faces each), UVs `0.1 · (x, y)`, with the last
    /// square's two faces on UVs of their own (shifted by `shift`, a separate island).
    fn strip_with_a_detached_square(k: usize, shift: [f32; 2]) -> TriMesh {
        let mut positions = Vec::new();
        for i in 0..=k {
            positions.push([i as f32, 0.0, 0.0]);
            positions.push([i as f32, 1.0, 0.0]);
        }
        let mut triangles = Vec::new();
        let mut uvt = Vec::new();
        let mut coords: Vec<[f32; 2]> = positions.iter().map(|p| [0.1 * p[0], 0.1 * p[1]]).collect();
        for i in 0..k as u32 {
            let (a, b, c, d) = (2 * i, 2 * i + 2, 2 * i + 3, 2 * i + 1);
            triangles.push([a, b, c]);
            triangles.push([a, c, d]);
            if i as usize == k - 1 {
                let base = coords.len() as u32;
                for v in [a, b, c, d] {
                    let p = coords[v as usize];
                    coords.push([p[0] + shift[0], p[1] + shift[1]]);
                }
                uvt.push([base, base + 1, base + 2]);
                uvt.push([base, base + 2, base + 3]);
            } else {
                uvt.push([a, b, c]);
                uvt.push([a, c, d]);
            }
        }
        TriMesh { positions, triangles, uv: Some(UvLayer { coords, triangles: uvt }) }
    }

    /// Asserts that the corners of `faces` have UVs `0.1 · (x, y)` of their positions, within `tol`.
    fn assert_at_tenth_of_position(m: &TriMesh, uv: &UvLayer, faces: &[usize], tol: f32) {
        for &f in faces {
            for k in 0..3 {
                let p = m.positions[m.triangles[f][k] as usize];
                let q = uv.coords[uv.triangles[f][k] as usize];
                assert!((q[0] - 0.1 * p[0]).abs() < tol && (q[1] - 0.1 * p[1]).abs() < tol, "{q:?} vs {p:?}");
            }
        }
    }

    #[test]
    fn a_detached_square_grows_back_onto_its_strip() {
        let m = strip_with_a_detached_square(600, [0.5, 0.5]);
        assert_eq!(uv_charts(&m, m.uv.as_ref().unwrap()).1, 2);
        let out = join_small_islands(&m, &JoinOptions::default()).unwrap();
        assert_eq!((out.report.small, out.report.joined, out.report.joined_faces), (1, 1, 2));
        let uv = out.mesh.uv.as_ref().unwrap();
        assert_eq!(uv_charts(&out.mesh, uv).1, 1);
        // Grown isometrically at the strip's density: exactly where the strip would have it.
        let last = 2 * 600 - 1;
        assert_at_tenth_of_position(&m, uv, &[last - 1, last], 1e-4);
    }

    #[test]
    fn an_island_that_would_overlap_its_neighbour_stays_apart() {
        // A strip folded back in UV over itself (a U in 3-D laid flat would overlap): the last
        // square, grown back, would land on the strip's first one.
        let mut m = strip_with_a_detached_square(600, [0.5, 0.5]);
        // Put the strip's first square's UVs where the grown square goes.
        let uv = m.uv.as_mut().unwrap();
        uv.coords[0] = [59.95, 0.0];
        uv.coords[1] = [59.95, 0.1];
        let before = uv_charts(&m, m.uv.as_ref().unwrap()).1;
        let out = join_small_islands(&m, &JoinOptions::default()).unwrap();
        assert_eq!(out.report.joined, 0);
        assert_eq!(uv_charts(&out.mesh, out.mesh.uv.as_ref().unwrap()).1, before);
        assert_eq!(out.mesh.uv, m.uv);
    }

    #[test]
    fn an_island_that_would_be_stretched_stays_apart() {
        // The strip's last shared edge is ten times as long in UV as the density says: grown
        // from it by either rule, the square would be stretched tenfold.
        let mut m = strip_with_a_detached_square(600, [0.5, 0.5]);
        let uv = m.uv.as_mut().unwrap();
        uv.coords[2 * 599 + 1][1] = 1.0;
        let out = join_small_islands(&m, &JoinOptions::default()).unwrap();
        assert_eq!((out.report.small, out.report.joined), (1, 0));
        assert_eq!(out.mesh.uv, m.uv);
    }

    /// A `k × k` grid of unit squares, each cut along its anti-diagonal, in two islands split along
    /// a staircase: squares with `i + j < k` on UVs `0.1 · (x, y)`, the others on the same shifted
    /// by 5 in `u`. Returns the mesh and the summed 3-D length of the seam between them.
    fn staircase(k: u32) -> TriMesh {
        let v = |i: u32, j: u32| i * (k + 1) + j;
        let mut positions = Vec::new();
        for i in 0..=k {
            for j in 0..=k {
                positions.push([i as f32, j as f32, 0.0]);
            }
        }
        let n = positions.len() as u32;
        let mut coords: Vec<[f32; 2]> = positions.iter().map(|p| [0.1 * p[0], 0.1 * p[1]]).collect();
        coords.extend(positions.iter().map(|p| [0.1 * p[0] + 5.0, 0.1 * p[1]]));
        let (mut triangles, mut uvt) = (Vec::new(), Vec::new());
        for i in 0..k {
            for j in 0..k {
                let (a, b, c, d) = (v(i, j), v(i + 1, j), v(i + 1, j + 1), v(i, j + 1));
                let off = if i + j < k { 0 } else { n };
                for t in [[a, b, d], [b, c, d]] {
                    triangles.push(t);
                    uvt.push(t.map(|x| x + off));
                }
            }
        }
        TriMesh { positions, triangles, uv: Some(UvLayer { coords, triangles: uvt }) }
    }

    /// Summed 3-D length of the mesh edges whose two faces lie in different charts.
    fn seam_length(m: &TriMesh) -> f64 {
        let (chart, _) = uv_charts(m, m.uv.as_ref().unwrap());
        let mut faces: HashMap<(u32, u32), Vec<usize>> = HashMap::new();
        for (f, t) in m.triangles.iter().enumerate() {
            for k in 0..3 {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                faces.entry((a.min(b), a.max(b))).or_default().push(f);
            }
        }
        faces
            .iter()
            .filter(|(_, fs)| fs.len() == 2 && chart[fs[0]] != chart[fs[1]])
            .map(|(&(a, b), _)| to_dvec3(m.positions[a as usize]).distance(to_dvec3(m.positions[b as usize])))
            .sum()
    }

    #[test]
    fn a_staircase_seam_is_smoothed_to_a_diagonal() {
        let m = staircase(8);
        let before = seam_length(&m);
        // The staircase: 6 steps of two unit edges and one unit edge at each end.
        assert!((before - 14.0).abs() < 1e-9, "{before}");
        let out = join_small_islands(&m, &JoinOptions::default()).unwrap();
        assert_eq!(out.report.small, 0);
        let uv = out.mesh.uv.as_ref().unwrap();
        assert_eq!(uv_charts(&out.mesh, uv).1, 2);
        // The first island's upper triangle at each of the 6 inner steps (its right and top edges
        // on the seam) moved across: the seam runs along their diagonals, and a unit edge at
        // each end, where the staircase meets the grid's border.
        let after = seam_length(&out.mesh);
        assert!((after - (6.0 * 2f64.sqrt() + 2.0)).abs() < 1e-6, "seam {before} -> {after}");
        assert_eq!(out.report.seam_faces_moved, 6);
        // Still a true image of the grid on each side: every face positive, at its island's place.
        for f in 0..out.mesh.triangles.len() {
            let q = uv.triangles[f].map(|i| uv.coords[i as usize]);
            let area2 = (q[1][0] - q[0][0]) * (q[2][1] - q[0][1]) - (q[1][1] - q[0][1]) * (q[2][0] - q[0][0]);
            assert!(area2 > 0.0, "face {f} flipped");
        }
    }

    #[test]
    fn an_island_at_its_neighbours_own_seam_joins_across_one_edge() {
        // A 3 × 3 grid of unit squares on UVs 0.1 · (x, y): the centre square is an island of its
        // own (shifted UVs), the ring round it is one island cut open along the edge from (0, 1) to
        // (1, 1), where the square left of the centre has its corner (1, 1) on a coordinate of its
        // own, nudged into that square. Seeded from all four shared edges, the centre's corner
        // (1, 1) would take two values: refused. Seeded from one edge and grown, it joins.
        let v = |i: u32, j: u32| i * 4 + j;
        let mut positions = Vec::new();
        for i in 0..4 {
            for j in 0..4 {
                positions.push([i as f32, j as f32, 0.0]);
            }
        }
        let mut coords: Vec<[f32; 2]> = positions.iter().map(|p| [0.1 * p[0], 0.1 * p[1]]).collect();
        let nudged = coords.len() as u32;
        coords.push([0.1 - 0.005, 0.1 + 0.005]);
        let centre = coords.len() as u32;
        coords.extend([[5.1, 5.1], [5.2, 5.1], [5.2, 5.2], [5.1, 5.2]]);
        let (mut triangles, mut uvt) = (Vec::new(), Vec::new());
        for i in 0..3 {
            for j in 0..3 {
                let (a, b, c, d) = (v(i, j), v(i + 1, j), v(i + 1, j + 1), v(i, j + 1));
                for t in [[a, b, c], [a, c, d]] {
                    triangles.push(t);
                    uvt.push(if (i, j) == (1, 1) {
                        t.map(|x| centre + [a, b, c, d].iter().position(|&y| y == x).unwrap() as u32)
                    } else if (i, j) == (0, 1) {
                        t.map(|x| if x == v(1, 1) { nudged } else { x })
                    } else {
                        t
                    });
                }
            }
        }
        let m = TriMesh { positions, triangles, uv: Some(UvLayer { coords, triangles: uvt }) };
        assert_eq!(uv_charts(&m, m.uv.as_ref().unwrap()).1, 2);
        let out = join_small_islands(&m, &JoinOptions { max_area_share: 0.2 }).unwrap();
        assert_eq!((out.report.small, out.report.joined, out.report.joined_faces), (1, 1, 2));
        let uv = out.mesh.uv.as_ref().unwrap();
        assert_eq!(uv_charts(&out.mesh, uv).1, 1);
        // The centre is grown where the grid has it (similar to its 3-D shape, at the seed
        // edge's scale).
        assert_at_tenth_of_position(&m, uv, &[8, 9], 1e-6);
    }

    #[test]
    fn a_large_island_is_not_small() {
        let m = strip_with_a_detached_square(4, [0.5, 0.5]);
        let out = join_small_islands(&m, &JoinOptions::default()).unwrap();
        assert_eq!((out.report.small, out.report.joined), (0, 0));
    }
}

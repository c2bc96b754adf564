//! Baking Nuvo's continuous per-chart maps onto a mesh as ordinary per-corner UVs in one atlas.
//!
//! Inputs are per-vertex MLP outputs: chart probabilities `probs` (`V × n`, row-major) and each
//! chart's UV `uvs` (`V × n × 2`, chart `i`'s own `[0,1]²`). The paper "selects the chart with the
//! maximum probability for each vertex"; a triangle needs **one** chart, or it would interpolate
//! between two unrelated UV squares. Rule used here:
//!
//! **Face chart** = `argmax_i Σ_{corners v} probs[v][i]` (ties → lowest index). When the three
//! corners' own argmax agree this is exactly the paper's per-vertex choice (a sum of rows that all
//! peak at `i` peaks at `i`); when they disagree it picks the chart the face as a whole is most
//! confident in, instead of an arbitrary corner's, which keeps faces on a chart border with the
//! chart that owns most of them.
//!
//! Every corner then gets **its face's chart's** UV at that vertex, mapped into the atlas by the
//! [`AtlasLayout`]. A vertex used by faces of different charts therefore gets one UV per chart
//! (a seam: one position, several UV indices, as OBJ stores it); no triangle mixes charts. Faces
//! are neither dropped nor reordered, positions are untouched.
//!
//! **Round-trip check** (not in the paper; optional, [`RoundTrip`]). A chart's texture map `t_i` is
//! only trained to be injective where the chart assignment gives it the surface, so where `c`'s
//! argmax strays onto a region that `t_i` also sends onto UVs of another region, the two overlap in
//! the atlas. The surface network tells them apart: where `t_i` is a faithful chart, `s_i(t_i(x))`
//! returns to `x`. Given the round-trip distances `|s_i(t_i(x_v)) − x_v|`, a face that overlaps
//! another in the atlas and whose chart fails the round trip at one of its corners (distance above
//! the tolerance) moves to the most probable chart (by the summed probabilities) that passes it at
//! all three corners *and* keeps the face the same way round as that chart's majority (so the move
//! cannot add a flip); a face no chart accepts stays where it was. Only overlapping faces move, so
//! a sloppy surface network elsewhere does not cut the charts up. On the bunny this removes most
//! overlapping faces and changes no score (BENCHMARKS.md, "Round-trip check").
//!
//! **Enclaves** (not in the paper; optional, [`BakeOptions::absorb_enclaves`]). After the round
//! trip, a small patch of one chart surrounded by one other chart moves to that chart where its
//! map has the patch the right way round ([`crate::enclaves`]): chart-label noise of
//! marching-cubes meshes otherwise leaves specks, each an island with a seam all round it.
//!
//! **Untangling** (not in the paper; optional, [`BakeOptions::untangle`]). After the charts are
//! chosen, faces the wrong way round in their chart (fold-overs, mostly tiny triangles on creases of
//! a scanned surface) are turned back by moving single UV vertices inside their chart
//! ([`crate::untangle`]). The flipped-face count never rises, and only UVs of vertices of
//! flipped faces move.

use std::collections::HashMap;

use nuvo_geometry::{TriMesh, UvLayer};
use serde::Serialize;

use crate::enclaves::absorb_enclaves;
use crate::error::AtlasError;
use crate::geom::signed_area2_2d;
use crate::pack::AtlasLayout;
use crate::untangle::{UntangleReport, untangle};
use crate::uvstats::{UvStats, analyse_uv};

/// The per-vertex network outputs a bake reads (`V` vertices, `n` charts, row-major).
#[derive(Clone, Copy, Debug)]
pub struct ChartFields<'a> {
    /// Chart probabilities `c(x_v)`, `V × n`.
    pub probs: &'a [f32],
    /// Every chart's UV `t_i(x_v)` in its own `[0,1]²`, `V × n × 2`.
    pub uvs: &'a [f32],
    /// Optional round-trip check (module docs); `None` bakes by the probabilities alone.
    pub round_trip: Option<RoundTrip<'a>>,
}

/// The round-trip distances `|s_i(t_i(x_v)) − x_v|` (`V × n`) and the largest one a chart may have
/// at the corners of a face it keeps (same units; module docs).
#[derive(Clone, Copy, Debug)]
pub struct RoundTrip<'a> {
    /// Distance per vertex and chart, `V × n`.
    pub distances: &'a [f32],
    /// Largest accepted distance; a positive finite number.
    pub tolerance: f32,
}

/// How the bake post-processes the chart map (each option is off by default: the paper's bake).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct BakeOptions {
    /// Move UV vertices so faces flipped in their chart turn back (module docs, [`crate::untangle`]).
    pub untangle: bool,
    /// Move small specks of one chart inside another to the surrounding chart where it maps them
    /// the right way round (module docs, [`crate::enclaves`]).
    pub absorb_enclaves: bool,
}

/// A baked mesh and what the bake found.
#[derive(Clone, Debug, PartialEq)]
pub struct Baked {
    /// The input mesh with a UV layer in the packed atlas.
    pub mesh: TriMesh,
    /// The chart of each face (module docs).
    pub face_chart: Vec<u32>,
    /// Each vertex's own argmax chart (the paper's per-vertex choice), for diagnostics.
    pub vertex_chart: Vec<u32>,
    /// What the bake found (flips, overlaps, splits).
    pub report: BakeReport,
}

/// Problems of the baked UVs, found by the same code as the metrics ([`analyse_uv`], with the
/// bake's face charts as charts and the layout's resolution as UV raster).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct BakeReport {
    /// UV statistics of the baked layout, charts = the bake's face charts.
    pub stats: UvStats,
    /// Faces oriented against the majority of their chart, increasing ids.
    pub flipped_faces: Vec<u32>,
    /// Faces overlapping another face in the atlas, increasing ids.
    pub overlapping_faces: Vec<u32>,
    /// Faces of zero UV area, increasing ids.
    pub degenerate_uv_faces: Vec<u32>,
    /// Vertices that received more than one UV (they lie on a chart border).
    pub split_vertices: usize,
    /// Corners whose chart UV is outside that chart's `[0,1]²` (they spill into the gutter or a
    /// neighbouring chart).
    pub corners_outside_chart: usize,
    /// Faces whose three corners did not share the same argmax chart.
    pub mixed_faces: usize,
    /// Faces the round-trip check moved off their most probable chart (0 without the check).
    pub reassigned_faces: usize,
    /// Faces of enclaves moved to the chart round them (0 without [`BakeOptions::absorb_enclaves`]).
    pub absorbed_faces: usize,
    /// What untangling did (all zero when it is off).
    pub untangle: UntangleReport,
}

/// Bakes per-vertex chart probabilities and chart UVs of `mesh` into one UV layer in the atlas
/// `layout` (module docs). `n_charts` must equal `layout.charts.len()`. Pure: same inputs, same
/// output. Errors on shape mismatches, non-finite inputs or an invalid mesh, naming the first bad
/// entry.
pub fn bake(
    mesh: &TriMesh,
    fields: &ChartFields<'_>,
    n_charts: usize,
    layout: &AtlasLayout,
    options: &BakeOptions,
) -> Result<Baked, AtlasError> {
    check_inputs(mesh, fields, n_charts, layout)?;
    let n = n_charts;
    let row = |v: u32| &fields.probs[v as usize * n..(v as usize + 1) * n];
    let vertex_chart: Vec<u32> =
        (0..mesh.positions.len() as u32).map(|v| argmax(row(v).iter().copied())).collect();
    let mut face_chart: Vec<u32> =
        mesh.triangles.iter().map(|t| argmax((0..n).map(|i| summed_prob(fields.probs, n, t, i)))).collect();
    let mut layer = assemble(mesh, fields.uvs, n, layout, &face_chart);
    let mut analysis = analyse_uv(&layer.mesh, Some(&face_chart), layout.resolution)?;
    let mut reassigned_faces = 0;
    if let Some(rt) = &fields.round_trip {
        reassigned_faces = apply_round_trip(mesh, fields, rt, n, &analysis.overlapping, &mut face_chart);
        if reassigned_faces > 0 {
            layer = assemble(mesh, fields.uvs, n, layout, &face_chart);
            analysis = analyse_uv(&layer.mesh, Some(&face_chart), layout.resolution)?;
        }
    }
    // With the round-trip check on, an enclave moves only to a chart that passes it at every
    // corner, or absorbing would bring back the overlaps the check removed.
    let round_trip_allows = |f: u32, c: u32| {
        fields.round_trip.as_ref().is_none_or(|rt| rt.passes(n, &mesh.triangles[f as usize], c as usize))
    };
    let mut absorbed_faces = 0;
    if options.absorb_enclaves {
        absorbed_faces = absorb_enclaves(
            mesh,
            |v, c| chart_uv(fields.uvs, n, v, c as usize),
            round_trip_allows,
            &mut face_chart,
        );
        if absorbed_faces > 0 {
            layer = assemble(mesh, fields.uvs, n, layout, &face_chart);
            analysis = analyse_uv(&layer.mesh, Some(&face_chart), layout.resolution)?;
        }
    }
    let mut untangled = UntangleReport::default();
    if options.untangle && !analysis.flipped.is_empty() {
        let tiles: Vec<[[f32; 2]; 2]> = (0..n).map(|c| layout.chart_bounds(c)).collect();
        if let Some(uv) = layer.mesh.uv.as_mut() {
            untangled = untangle(uv, &face_chart, &tiles)?;
        }
        if untangled.moves > 0 {
            analysis = analyse_uv(&layer.mesh, Some(&face_chart), layout.resolution)?;
        }
    }
    let mixed_faces = mesh
        .triangles
        .iter()
        .filter(|t| t.iter().any(|&v| vertex_chart[v as usize] != vertex_chart[t[0] as usize]))
        .count();
    let report = BakeReport {
        stats: analysis.stats,
        flipped_faces: analysis.flipped,
        overlapping_faces: analysis.overlapping,
        degenerate_uv_faces: analysis.degenerate_uv,
        split_vertices: layer.split_vertices,
        corners_outside_chart: layer.corners_outside_chart,
        mixed_faces,
        reassigned_faces,
        absorbed_faces,
        untangle: untangled,
    };
    Ok(Baked { mesh: layer.mesh, face_chart, vertex_chart, report })
}

/// `mesh` with the UV layer of a face-chart assignment, and the counts found while building it.
struct Assembled {
    mesh: TriMesh,
    split_vertices: usize,
    corners_outside_chart: usize,
}

/// Builds the UV layer: every corner gets its face's chart's UV at that vertex, mapped into the
/// atlas, one UV coordinate per (vertex, chart) pair in first-use order (module docs).
fn assemble(mesh: &TriMesh, uvs: &[f32], n: usize, layout: &AtlasLayout, face_chart: &[u32]) -> Assembled {
    let outside = |t: [f32; 2]| t.iter().any(|x| !(0.0..=1.0).contains(x));
    let mut index: HashMap<(u32, u32), u32> = HashMap::new();
    let mut coords = Vec::new();
    let mut corners_outside_chart = 0;
    let triangles: Vec<[u32; 3]> = mesh
        .triangles
        .iter()
        .zip(face_chart)
        .map(|(t, &c)| {
            t.map(|v| {
                let t = chart_uv(uvs, n, v, c as usize);
                corners_outside_chart += outside(t) as usize;
                *index.entry((v, c)).or_insert_with(|| {
                    coords.push(layout.map(c as usize, t));
                    coords.len() as u32 - 1
                })
            })
        })
        .collect();
    let mut uses = vec![0u8; mesh.positions.len()];
    for &(v, _) in index.keys() {
        uses[v as usize] = uses[v as usize].saturating_add(1);
    }
    let split_vertices = uses.iter().filter(|&&u| u > 1).count();
    let mesh = TriMesh { uv: Some(UvLayer { coords, triangles }), ..mesh.clone() };
    Assembled { mesh, split_vertices, corners_outside_chart }
}

/// Moves the `overlapping` faces whose chart fails the round trip (module docs) and returns how
/// many moved.
fn apply_round_trip(
    mesh: &TriMesh,
    fields: &ChartFields<'_>,
    rt: &RoundTrip<'_>,
    n: usize,
    overlapping: &[u32],
    face_chart: &mut [u32],
) -> usize {
    let passes = |t: &[u32; 3], i: usize| rt.passes(n, t, i);
    let area = |t: &[u32; 3], i: usize| {
        let uv = |v: u32| chart_uv(fields.uvs, n, v, i);
        signed_area2_2d(uv(t[0]), uv(t[1]), uv(t[2]))
    };
    // Each chart's majority orientation: the sign of its faces' total signed UV area.
    let mut total = vec![0.0f64; n];
    for (t, &c) in mesh.triangles.iter().zip(face_chart.iter()) {
        total[c as usize] += area(t, c as usize);
    }
    let mut moved = 0;
    for &f in overlapping {
        let (t, c) = (&mesh.triangles[f as usize], &mut face_chart[f as usize]);
        if passes(t, *c as usize) {
            continue;
        }
        let sum = |i: usize| summed_prob(fields.probs, n, t, i);
        let mut candidates: Vec<usize> = (0..n).filter(|&i| i != *c as usize).collect();
        candidates.sort_by(|&a, &b| sum(b).total_cmp(&sum(a)).then(a.cmp(&b)));
        let accepted = candidates.into_iter().find(|&i| passes(t, i) && area(t, i) * total[i] > 0.0);
        if let Some(i) = accepted {
            *c = i as u32;
            moved += 1;
        }
    }
    moved
}

impl RoundTrip<'_> {
    /// Whether chart `i` of `n` maps every corner of face `t` back within the tolerance.
    fn passes(&self, n: usize, t: &[u32; 3], i: usize) -> bool {
        t.iter().all(|&v| self.distances[v as usize * n + i] <= self.tolerance)
    }
}

fn check_inputs(
    mesh: &TriMesh,
    fields: &ChartFields<'_>,
    n: usize,
    layout: &AtlasLayout,
) -> Result<(), AtlasError> {
    let bad = |m: String| Err(AtlasError::invalid("bake input", m));
    mesh.validate().map_err(|m| AtlasError::invalid("mesh", m))?;
    let nv = mesh.positions.len();
    let (probs, uvs) = (fields.probs, fields.uvs);
    if n == 0 || layout.charts.len() != n {
        return bad(format!("{n} charts but the atlas layout has {}", layout.charts.len()));
    }
    if probs.len() != nv * n {
        return bad(format!("probs has {} values, expected {nv} vertices × {n} charts", probs.len()));
    }
    if uvs.len() != nv * n * 2 {
        return bad(format!("uvs has {} values, expected {nv} vertices × {n} charts × 2", uvs.len()));
    }
    if let Some(i) = probs.iter().position(|p| !p.is_finite()) {
        return bad(format!("probs of vertex {} chart {} is {}", i / n, i % n, probs[i]));
    }
    if let Some(i) = uvs.iter().position(|p| !p.is_finite()) {
        return bad(format!("uvs of vertex {} chart {} is {}", i / (2 * n), i / 2 % n, uvs[i]));
    }
    if let Some(rt) = &fields.round_trip {
        if rt.distances.len() != nv * n {
            return bad(format!(
                "round-trip distances have {} values, expected {nv} vertices × {n} charts",
                rt.distances.len()
            ));
        }
        if !(rt.tolerance.is_finite() && rt.tolerance > 0.0) {
            return bad(format!("round-trip tolerance {} is not a positive number", rt.tolerance));
        }
        if let Some(i) = rt.distances.iter().position(|d| !d.is_finite()) {
            return bad(format!(
                "round-trip distance of vertex {} chart {} is {}",
                i / n,
                i % n,
                rt.distances[i]
            ));
        }
    }
    Ok(())
}

/// Chart `i`'s probability summed over the corners of face `t` (`probs` is `V × n`).
fn summed_prob(probs: &[f32], n: usize, t: &[u32; 3], i: usize) -> f32 {
    t.iter().map(|&v| probs[v as usize * n + i]).sum()
}

/// Chart `c`'s own UV at vertex `v` (`uvs` is `V × n × 2`).
pub fn chart_uv(uvs: &[f32], n: usize, v: u32, c: usize) -> [f32; 2] {
    let k = (v as usize * n + c) * 2;
    [uvs[k], uvs[k + 1]]
}

/// Index of the largest value, the lowest index on ties: a point's chart from its row of
/// probabilities, as the bake takes it.
pub fn argmax(values: impl Iterator<Item = f32>) -> u32 {
    let mut best = (0u32, f32::NEG_INFINITY);
    for (i, x) in values.enumerate() {
        if x > best.1 {
            best = (i as u32, x);
        }
    }
    best.0
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testmesh::grid;
    use crate::untangle::UntangleReport;

    /// Inputs without the round-trip check.
    fn plain<'a>(probs: &'a [f32], uvs: &'a [f32]) -> ChartFields<'a> {
        ChartFields { probs, uvs, round_trip: None }
    }

    /// An 8×8-quad plane; vertices with x < 0 prefer chart 0 (0.9 vs 0.1), the others chart 1
    /// (0.2 vs 0.8), so a face belongs to chart 1 exactly when two or more corners have x ≥ 0. Each
    /// chart's UV is the xy map squeezed into its square (chart 1 mirrored in u, to tell them apart).
    fn two_chart_inputs() -> (TriMesh, Vec<f32>, Vec<f32>) {
        let m = grid(8, |_| [0.0, 0.0]);
        let mut probs = Vec::new();
        let mut uvs = Vec::new();
        for p in &m.positions {
            let left = p[0] < 0.0;
            probs.extend(if left { [0.9, 0.1] } else { [0.2, 0.8] });
            let (u, v) = ((p[0] + 1.0) * 0.5, (p[1] + 1.0) * 0.5);
            uvs.extend([u, v, 1.0 - u, v]);
        }
        (m, probs, uvs)
    }

    #[test]
    fn every_face_keeps_its_vertices_and_every_corner_gets_its_face_charts_uv() {
        let (m, probs, uvs) = two_chart_inputs();
        let layout = AtlasLayout::grid(2, 256, 2).unwrap();
        let b = bake(&m, &plain(&probs, &uvs), 2, &layout, &BakeOptions::default()).unwrap();
        assert_eq!(b.mesh.triangles, m.triangles, "faces dropped, duplicated or reordered");
        assert_eq!(b.mesh.positions, m.positions);
        b.mesh.validate().unwrap();
        let uv = b.mesh.uv.as_ref().unwrap();
        let mut charts_of_vertex = vec![Vec::new(); m.positions.len()];
        let mut uv_ids_of_vertex = vec![Vec::new(); m.positions.len()];
        for (f, t) in m.triangles.iter().enumerate() {
            let c = b.face_chart[f] as usize;
            let right = t.iter().filter(|&&v| m.positions[v as usize][0] >= 0.0).count();
            assert_eq!(c, (right >= 2) as usize, "face {f}");
            for (k, &v) in t.iter().enumerate() {
                let v = v as usize;
                let want = layout.map(c, [uvs[(v * 2 + c) * 2], uvs[(v * 2 + c) * 2 + 1]]);
                assert_eq!(uv.coords[uv.triangles[f][k] as usize], want, "face {f} corner {k}");
                charts_of_vertex[v].push(c);
                uv_ids_of_vertex[v].push(uv.triangles[f][k]);
            }
        }
        // A vertex gets exactly one UV index per chart among its faces: shared vertices are split.
        let mut split = 0;
        for v in 0..m.positions.len() {
            charts_of_vertex[v].sort();
            charts_of_vertex[v].dedup();
            uv_ids_of_vertex[v].sort();
            uv_ids_of_vertex[v].dedup();
            assert_eq!(charts_of_vertex[v].len(), uv_ids_of_vertex[v].len(), "vertex {v}");
            split += (charts_of_vertex[v].len() > 1) as usize;
        }
        assert!(split >= 8, "the chart border should split the x = 0 column");
        assert_eq!(b.report.split_vertices, split);
        assert_eq!(b.report.stats.charts, 2);
        assert_eq!(b.report.flipped_faces, Vec::<u32>::new());
        assert_eq!(b.report.overlapping_faces, Vec::<u32>::new());
        assert_eq!(b.report.corners_outside_chart, 0);
    }

    #[test]
    fn a_face_with_disagreeing_corners_takes_the_argmax_of_the_summed_probabilities() {
        let m = TriMesh {
            positions: vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
            triangles: vec![[0, 1, 2]],
            uv: None,
        };
        // Vertex argmaxes: 0, 1, 1 (a per-corner vote would say 1); sums: 1.5, 1.2, 0.3 → chart 0.
        let probs = [0.9, 0.0, 0.1, 0.3, 0.6, 0.1, 0.3, 0.6, 0.1];
        let uvs = [0.5f32; 18];
        let b =
            bake(&m, &plain(&probs, &uvs), 3, &AtlasLayout::grid(3, 64, 1).unwrap(), &BakeOptions::default())
                .unwrap();
        assert_eq!(b.face_chart, vec![0]);
        assert_eq!(b.vertex_chart, vec![0, 1, 1]);
        assert_eq!(b.report.mixed_faces, 1);
    }

    #[test]
    fn a_folded_chart_map_is_reported() {
        // Chart 0's map folded along x = -0.75: u = |x + 0.75|, so the strip x < -0.75 (16 faces, a
        // minority of chart 0) is mirrored onto its neighbour.
        let (m, probs, uvs, _) = folded_with_round_trip();
        let b = bake_two(&m, &plain(&probs, &uvs), BakeOptions::default());
        assert_eq!(b.report.flipped_faces.len(), 16, "{:?}", b.report.flipped_faces);
        assert!(b.report.flipped_faces.iter().all(|&f| m.corners(f as usize).iter().all(|c| c[0] <= -0.75)));
        assert!(!b.report.overlapping_faces.is_empty());
    }

    #[test]
    fn untangling_turns_the_folded_strip_back_inside_its_tile_and_moves_only_its_uvs() {
        let (m, probs, uvs, _) = folded_with_round_trip();
        let fields = plain(&probs, &uvs);
        let plain = bake_two(&m, &fields, BakeOptions::default());
        let b = bake_two(&m, &fields, BakeOptions { untangle: true, ..Default::default() });
        assert_eq!(plain.report.untangle, UntangleReport::default(), "off by default");
        // The strip's fold line is chart 0's edge u = 0, so the strip cannot unfold by going past
        // it: it has to turn back inside chart 0's square, which single moves nearly always do.
        let r = b.report.untangle;
        assert_eq!(r.flipped_before, 16);
        assert!(r.flipped_after <= 2, "{r:?}");
        assert_eq!(b.report.flipped_faces.len(), r.flipped_after, "the report counts as uvstats does");
        assert_eq!(b.face_chart, plain.face_chart, "charts are not changed");
        let uv_b = b.mesh.uv.as_ref().unwrap();
        let tile = AtlasLayout::grid(2, 256, 2).unwrap().chart_bounds(0);
        for (f, t) in uv_b.triangles.iter().enumerate().filter(|&(f, _)| b.face_chart[f] == 0) {
            for p in t.map(|i| uv_b.coords[i as usize]) {
                assert!(
                    (0..2).all(|k| tile[0][k] <= p[k] && p[k] <= tile[1][k]),
                    "face {f}: {p:?} left {tile:?}"
                );
            }
        }
        // Only UVs of vertices of the strip's faces (x ≤ −0.5) moved.
        let uv_p = plain.mesh.uv.as_ref().unwrap();
        for (f, t) in m.triangles.iter().enumerate() {
            for (k, &v) in t.iter().enumerate() {
                let (pb, pp) =
                    (uv_b.coords[uv_b.triangles[f][k] as usize], uv_p.coords[uv_p.triangles[f][k] as usize]);
                if m.positions[v as usize][0] > -0.5 {
                    assert_eq!(pb, pp, "face {f} corner {k}");
                }
            }
        }
    }

    /// [`two_chart_inputs`] with chart 0's map folded along x = −0.75 (u = |x + 0.75|: the strip
    /// x < −0.75 lands mirrored on its neighbour), and round-trip distances saying so: chart 0 fails (1.0) at vertices with x < −0.75, chart 1
    /// passes everywhere (0.0).
    fn folded_with_round_trip() -> (TriMesh, Vec<f32>, Vec<f32>, Vec<f32>) {
        let (m, probs, mut uvs) = two_chart_inputs();
        for (v, p) in m.positions.iter().enumerate() {
            uvs[v * 4] = (p[0] + 0.75).abs();
        }
        let d = m.positions.iter().flat_map(|p| [if p[0] < -0.75 { 1.0 } else { 0.0 }, 0.0]).collect();
        (m, probs, uvs, d)
    }

    /// The two-chart fixtures baked into a 256² atlas with a 2-texel gutter.
    fn bake_two(m: &TriMesh, fields: &ChartFields<'_>, options: BakeOptions) -> Baked {
        bake(m, fields, 2, &AtlasLayout::grid(2, 256, 2).unwrap(), &options).unwrap()
    }

    fn bake_checked(m: &TriMesh, probs: &[f32], uvs: &[f32], distances: &[f32]) -> Baked {
        let rt = RoundTrip { distances, tolerance: 0.5 };
        bake_two(m, &ChartFields { probs, uvs, round_trip: Some(rt) }, BakeOptions::default())
    }

    #[test]
    fn overlapping_faces_failing_the_round_trip_move_to_a_chart_that_passes_it() {
        let (m, probs, uvs, d) = folded_with_round_trip();
        let plain = bake_two(&m, &plain(&probs, &uvs), BakeOptions::default());
        assert_eq!(plain.report.flipped_faces.len(), 16);
        let b = bake_checked(&m, &probs, &uvs, &d);
        for f in 0..m.triangles.len() {
            let folded = m.corners(f).iter().any(|c| c[0] < -0.75);
            let want = if folded { 1 } else { plain.face_chart[f] };
            assert_eq!(b.face_chart[f], want, "face {f}");
        }
        assert_eq!(b.report.reassigned_faces, 16);
        assert_eq!(plain.report.reassigned_faces, 0);
        assert_eq!(b.report.flipped_faces, Vec::<u32>::new());
        assert_eq!(b.report.overlapping_faces, Vec::<u32>::new(), "the fold is gone");
    }

    #[test]
    fn faces_that_do_not_overlap_would_flip_or_fail_everywhere_stay() {
        let (m, probs, uvs, d) = folded_with_round_trip();
        let plain = bake_two(&m, &plain(&probs, &uvs), BakeOptions::default());
        // Chart 0 failing also where nothing overlaps (x > −0.5): those faces stay.
        let d_wide: Vec<f32> = d
            .chunks(2)
            .zip(&m.positions)
            .flat_map(|(d, p)| [d[0].max((p[0] > -0.5) as u8 as f32), d[1]])
            .collect();
        let b = bake_checked(&m, &probs, &uvs, &d_wide);
        assert_eq!(b.report.reassigned_faces, 16, "only the folded strip overlaps");
        // Chart 1 mirrored the other way on the strip: a move would flip the faces there.
        let mut unmirrored = uvs.clone();
        for (v, p) in m.positions.iter().enumerate() {
            if p[0] <= -0.75 {
                unmirrored[v * 4 + 2] = 1.0 - unmirrored[v * 4 + 2];
            }
        }
        let b = bake_checked(&m, &probs, &unmirrored, &d);
        for f in 0..m.triangles.len() {
            if m.corners(f).iter().all(|c| c[0] <= -0.75) {
                assert_eq!(b.face_chart[f], 0, "face {f} would flip in chart 1");
            }
        }
        // Every chart failing: nothing moves.
        let b = bake_checked(&m, &probs, &uvs, &vec![1.0; d.len()]);
        assert_eq!(b.face_chart, plain.face_chart);
        assert_eq!(b.report.reassigned_faces, 0);
    }

    #[test]
    fn bad_round_trip_inputs_are_errors() {
        let (m, probs, uvs) = two_chart_inputs();
        let l = AtlasLayout::grid(2, 64, 1).unwrap();
        let d = vec![0.0f32; m.positions.len() * 2];
        let with = |distances: &[f32], tolerance: f32| {
            let rt = RoundTrip { distances, tolerance };
            bake(
                &m,
                &ChartFields { probs: &probs, uvs: &uvs, round_trip: Some(rt) },
                2,
                &l,
                &BakeOptions::default(),
            )
            .map(|_| ())
            .map_err(|e| e.to_string())
        };
        assert!(with(&d[1..], 0.5).unwrap_err().contains("round-trip distances have"));
        assert!(with(&d, 0.0).unwrap_err().contains("tolerance"));
        assert!(with(&d, f32::NAN).unwrap_err().contains("tolerance"));
        let mut nan = d.clone();
        nan[7] = f32::INFINITY;
        assert!(with(&nan, 0.5).unwrap_err().contains("vertex 3 chart 1"));
        assert!(with(&d, 0.5).is_ok());
    }

    #[test]
    fn bad_shapes_and_values_are_errors_naming_the_entry() {
        let (m, probs, uvs) = two_chart_inputs();
        let l = AtlasLayout::grid(2, 64, 1).unwrap();
        assert!(bake(&m, &plain(&probs[1..], &uvs), 2, &l, &BakeOptions::default()).is_err());
        assert!(bake(&m, &plain(&probs, &uvs[1..]), 2, &l, &BakeOptions::default()).is_err());
        assert!(bake(&m, &plain(&probs, &uvs), 3, &l, &BakeOptions::default()).is_err());
        let mut nan = uvs.clone();
        nan[4 * 3 + 3] = f32::NAN;
        let e = bake(&m, &plain(&probs, &nan), 2, &l, &BakeOptions::default()).unwrap_err().to_string();
        assert!(e.contains("vertex 3 chart 1"), "{e}");
    }
}

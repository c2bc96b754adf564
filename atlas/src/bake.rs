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

use std::collections::HashMap;

use nuvo_geometry::{TriMesh, UvLayer};
use serde::Serialize;

use crate::error::AtlasError;
use crate::pack::AtlasLayout;
use crate::uvstats::{UvStats, analyse_uv};

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
}

/// Bakes per-vertex chart probabilities and chart UVs of `mesh` into one UV layer in the atlas
/// `layout` (module docs). `n_charts` must equal `layout.charts.len()`. Pure: same inputs, same
/// output. Errors on shape mismatches, non-finite inputs or an invalid mesh, naming the first bad
/// entry.
pub fn bake(
    mesh: &TriMesh,
    probs: &[f32],
    uvs: &[f32],
    n_charts: usize,
    layout: &AtlasLayout,
) -> Result<Baked, AtlasError> {
    check_inputs(mesh, probs, uvs, n_charts, layout)?;
    let n = n_charts;
    let row = |v: u32| &probs[v as usize * n..(v as usize + 1) * n];
    let vertex_chart: Vec<u32> =
        (0..mesh.positions.len() as u32).map(|v| argmax(row(v).iter().copied())).collect();
    let face_chart: Vec<u32> = mesh
        .triangles
        .iter()
        .map(|t| argmax((0..n).map(|i| t.iter().map(|&v| row(v)[i]).sum::<f32>())))
        .collect();
    let chart_uv = |v: u32, c: u32| {
        let k = (v as usize * n + c as usize) * 2;
        [uvs[k], uvs[k + 1]]
    };
    // One UV coordinate per (vertex, chart) pair actually used, numbered in first-use order.
    let mut index: HashMap<(u32, u32), u32> = HashMap::new();
    let mut coords = Vec::new();
    let mut corners_outside_chart = 0;
    let triangles: Vec<[u32; 3]> = mesh
        .triangles
        .iter()
        .zip(&face_chart)
        .map(|(t, &c)| {
            t.map(|v| {
                *index.entry((v, c)).or_insert_with(|| {
                    let t = chart_uv(v, c);
                    corners_outside_chart += t.iter().any(|x| !(0.0..=1.0).contains(x)) as usize;
                    coords.push(layout.map(c as usize, t));
                    coords.len() as u32 - 1
                })
            })
        })
        .collect();
    // Count corners, not first uses, outside their chart.
    let corners_outside_chart = if corners_outside_chart == 0 {
        0
    } else {
        mesh.triangles
            .iter()
            .zip(&face_chart)
            .flat_map(|(t, &c)| t.iter().map(move |&v| (v, c)))
            .filter(|&(v, c)| chart_uv(v, c).iter().any(|x| !(0.0..=1.0).contains(x)))
            .count()
    };
    let mut uses = vec![0u8; mesh.positions.len()];
    for &(v, _) in index.keys() {
        uses[v as usize] = uses[v as usize].saturating_add(1);
    }
    let split_vertices = uses.iter().filter(|&&u| u > 1).count();
    let mixed_faces = mesh
        .triangles
        .iter()
        .filter(|t| t.iter().any(|&v| vertex_chart[v as usize] != vertex_chart[t[0] as usize]))
        .count();
    let baked = TriMesh { uv: Some(UvLayer { coords, triangles }), ..mesh.clone() };
    let a = analyse_uv(&baked, Some(&face_chart), layout.resolution)?;
    let report = BakeReport {
        stats: a.stats,
        flipped_faces: a.flipped,
        overlapping_faces: a.overlapping,
        degenerate_uv_faces: a.degenerate_uv,
        split_vertices,
        corners_outside_chart,
        mixed_faces,
    };
    Ok(Baked { mesh: baked, face_chart, vertex_chart, report })
}

fn check_inputs(
    mesh: &TriMesh,
    probs: &[f32],
    uvs: &[f32],
    n: usize,
    layout: &AtlasLayout,
) -> Result<(), AtlasError> {
    let bad = |m: String| Err(AtlasError::invalid("bake input", m));
    mesh.validate().map_err(|m| AtlasError::invalid("mesh", m))?;
    let nv = mesh.positions.len();
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
    Ok(())
}

/// Index of the largest value, the lowest index on ties.
fn argmax(values: impl Iterator<Item = f32>) -> u32 {
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
        let b = bake(&m, &probs, &uvs, 2, &layout).unwrap();
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
        let b = bake(&m, &probs, &uvs, 3, &AtlasLayout::grid(3, 64, 1).unwrap()).unwrap();
        assert_eq!(b.face_chart, vec![0]);
        assert_eq!(b.vertex_chart, vec![0, 1, 1]);
        assert_eq!(b.report.mixed_faces, 1);
    }

    #[test]
    fn a_folded_chart_map_is_reported() {
        let (m, probs, mut uvs) = two_chart_inputs();
        // Fold chart 0's map along x = -0.75: u = |x + 0.75|, so the strip x < -0.75 (16 faces, a
        // minority of chart 0) is mirrored onto its neighbour.
        for (v, p) in m.positions.iter().enumerate() {
            uvs[v * 4] = (p[0] + 0.75).abs();
        }
        let b = bake(&m, &probs, &uvs, 2, &AtlasLayout::grid(2, 256, 2).unwrap()).unwrap();
        assert_eq!(b.report.flipped_faces.len(), 16, "{:?}", b.report.flipped_faces);
        assert!(b.report.flipped_faces.iter().all(|&f| m.corners(f as usize).iter().all(|c| c[0] <= -0.75)));
        assert!(!b.report.overlapping_faces.is_empty());
    }

    #[test]
    fn bad_shapes_and_values_are_errors_naming_the_entry() {
        let (m, probs, uvs) = two_chart_inputs();
        let l = AtlasLayout::grid(2, 64, 1).unwrap();
        assert!(bake(&m, &probs[1..], &uvs, 2, &l).is_err());
        assert!(bake(&m, &probs, &uvs[1..], 2, &l).is_err());
        assert!(bake(&m, &probs, &uvs, 3, &l).is_err());
        let mut nan = uvs.clone();
        nan[4 * 3 + 3] = f32::NAN;
        let e = bake(&m, &probs, &nan, 2, &l).unwrap_err().to_string();
        assert!(e.contains("vertex 3 chart 1"), "{e}");
    }
}

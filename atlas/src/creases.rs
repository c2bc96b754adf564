//! Charting a surface by its sharp creases where the renders say that beats the networks'
//! charts (issue 18).
//!
//! A machined part (fandisk) is a few developable patches (planes, cylinders, cones) that meet
//! at sharp creases. Nuvo's charts cross the creases: a chart holding three faces of a box
//! corner gathers that corner's angle deficit, and SLIM ([`crate::injective`]) spreads what no
//! flat map holds as a little shear and stretch over the whole island. The paper's Conformal
//! and Stretch take medians over pixels, so that spread is what they see: fandisk's 4 islands
//! score Conformal 0.9944 where xatlas's 15 charts along the creases score 0.9995. Charted by
//! its creases instead, most patches flatten to isometries, and the seams lie where the
//! surface already breaks. Cutting the networks' islands along the creases as well (tried
//! first) adds the creases' seams to the charts' own: fandisk's Boundary fell 0.985 → 0.977.
//!
//! Definitions (exact):
//! - **Crease edge**: an edge shared by exactly two faces whose normals are more than
//!   [`CREASE_ANGLE_DEGREES`] apart. Faces without a normal (zero area) crease nothing; edges
//!   of one face (the boundary) or of three and more join nothing.
//! - **Regions**: the faces joined across every edge of two faces that is not a crease. A
//!   region is *small* when it holds less than [`MIN_REGION_SHARE`] of the mesh's 3-D area or
//!   fewer than [`MIN_REGION_FACES`] faces; small regions join, smallest first (ties to the
//!   lower root), the region they share the longest crease with (ties to the lower root), so a
//!   speck between creases (a chamfer's strip, a noisy scan's spike) stays with its neighbour;
//!   a small region with no such neighbour (a separate small piece) stays. The mesh is left
//!   alone when it has more than [`MAX_REGIONS`] regions before that merging (a noisy or
//!   fragmented surface, as a marching-cubes mesh is) or one region after it (a smooth scan:
//!   every Common Shapes mesh but fandisk, cheburashka, suzanne and the teapot, whose patches
//!   are separate pieces).
//! - **Crease charts**: one island per region, started from the region's projection onto the
//!   plane across its area-weighted normal and made injective and near-isometric by
//!   [`make_injective`] with the caller's options (folded projections are embedded anew, cone
//!   points cut open as for the networks' islands).
//! - **Judgement**: both layouts are packed as [`NeckOptions`]'s trials are (512², gutter 1,
//!   turns) and scored by [`crate::metrics::unpacked_editability`] over the views of
//!   [`crate::necks::JUDGE_SEED`], other directions than the evaluation's; the crease charts
//!   replace the networks' layout only when they score higher. Judged packed, not as they come from SLIM: unpacked, fandisk's crease
//!   charts were estimated at 0.9641 against the networks' 0.9740 and scored 0.9848 against
//!   0.9741 once packed (both measured 0.9855 and 0.9794). A trial that fails (an error of
//!   SLIM, the packer or the renderer) keeps the networks' layout and says why in the report.
//!
//! Deterministic: the same mesh and options give the same bits.

use std::collections::HashMap;

use glam::DVec3;
use nuvo_geometry::{TriMesh, UvLayer};
use serde::Serialize;

use crate::error::AtlasError;
use crate::geom::to_dvec3;
use crate::injective::{InjectiveOptions, InjectiveReport, make_injective};
use crate::islands::pack_islands;
use crate::necks::{NeckOptions, judged_editability};
use crate::uvstats::{Dsu, faces_by_edge, require_uv};

/// Angle between two faces' normals above which their shared edge is a crease. Blender's Smart
/// UV Project splits at 66° by default; fandisk's creases are 80–90° and its regions are the
/// same for any threshold from 30° to 60° (measured), while a smooth scan (the bunny, the
/// horse, the cow) has no region of 2% of its area bounded at 60°.
pub const CREASE_ANGLE_DEGREES: f64 = 60.0;
/// The least share of the mesh's 3-D area a region keeps as its own chart.
pub const MIN_REGION_SHARE: f64 = 0.02;
/// The fewest faces a region keeps as its own chart.
pub const MIN_REGION_FACES: usize = 8;
/// Regions (before small ones join) above which the mesh is not charted by its creases.
pub const MAX_REGIONS: usize = 256;

/// What [`crease_charts`] did.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct CreaseReport {
    /// Regions (module docs): the crease charts' count before making them injective; 0 when the
    /// mesh was left alone.
    pub regions: usize,
    /// Summed 3-D length of the creases between regions.
    pub crease_length: f64,
    /// What making the crease charts injective did (`None` when the mesh was left alone).
    pub injective: Option<InjectiveReport>,
    /// The Editability estimated for the networks' layout and for the crease charts, both
    /// packed (`None` when the mesh was left alone).
    pub editability: Option<[f64; 2]>,
    /// The crease charts replaced the networks' layout.
    pub chosen: bool,
    /// Why the trial failed, when it did (the networks' layout is then kept).
    pub failed: Option<String>,
}

/// The layout to keep and what was done.
#[derive(Clone, Debug, PartialEq)]
pub struct CreaseCharts {
    /// `mesh` with the crease charts' UVs when they were chosen (not yet packed), else `mesh`
    /// as it came.
    pub mesh: TriMesh,
    /// The summary.
    pub report: CreaseReport,
}

/// Charts `mesh` by its creases and keeps that layout where it beats the one `mesh` has
/// (module docs); `injective` solves the crease charts as the caller solved its own islands.
/// Errors: no UVs (a failed trial is not an error: module docs).
pub fn crease_charts(mesh: &TriMesh, injective: &InjectiveOptions) -> Result<CreaseCharts, AtlasError> {
    require_uv(mesh)?;
    let mut report = CreaseReport::default();
    let Some((region, regions, crease_length)) = crease_regions(mesh) else {
        return Ok(CreaseCharts { mesh: mesh.clone(), report });
    };
    report.regions = regions;
    report.crease_length = crease_length;
    // A trial that fails leaves the networks' layout as it is: it is an option, not the atlas.
    match trial(mesh, &region, regions, injective, &mut report) {
        Ok(Some(charts)) => return Ok(CreaseCharts { mesh: charts, report }),
        Ok(None) => {}
        Err(e) => report.failed = Some(e.to_string()),
    }
    Ok(CreaseCharts { mesh: mesh.clone(), report })
}

/// Solves the crease charts of `region` and judges them against `mesh`'s layout (module docs):
/// the charts when they score higher. Records what it did in `report`.
fn trial(
    mesh: &TriMesh,
    region: &[u32],
    regions: usize,
    injective: &InjectiveOptions,
    report: &mut CreaseReport,
) -> Result<Option<TriMesh>, AtlasError> {
    let solved = make_injective(&projected(mesh, region, regions), injective)?;
    report.injective = Some(solved.report);
    let judge = NeckOptions::default().packing;
    let packed = [pack_islands(mesh, &judge)?.mesh, pack_islands(&solved.mesh, &judge)?.mesh];
    let Some(e) = judged_editability(mesh, &[&packed[0], &packed[1]])? else { return Ok(None) };
    report.editability = Some([e[0], e[1]]);
    report.chosen = e[1] > e[0];
    Ok(report.chosen.then_some(solved.mesh))
}

/// The region of each face, the number of regions and the 3-D length of the creases between
/// them; `None` when the mesh has more than [`MAX_REGIONS`] regions before small ones join or
/// one after (module docs). Regions are numbered in order of their first face.
pub fn crease_regions(mesh: &TriMesh) -> Option<(Vec<u32>, usize, f64)> {
    let n = mesh.triangles.len();
    let normals: Vec<DVec3> = (0..n)
        .map(|f| {
            let [a, b, c] = mesh.corners(f).map(to_dvec3);
            (b - a).cross(c - a)
        })
        .collect();
    let cos_max = CREASE_ANGLE_DEGREES.to_radians().cos();
    let by_edge = faces_by_edge(mesh.triangles.iter().enumerate().map(|(f, &t)| (f as u32, t)));
    let mut edges: Vec<((u32, u32), [u32; 2])> = by_edge
        .into_iter()
        .filter(|(e, f)| f.len() == 2 && e.0 != e.1)
        .map(|(e, f)| (e, [f[0], f[1]]))
        .collect();
    edges.sort_unstable_by_key(|&(e, _)| e);
    let mut dsu = Dsu::new(n);
    // Crease edges as (face, face, 3-D length), in edge order.
    let mut creases: Vec<(u32, u32, f64)> = Vec::new();
    for ((a, b), [x, y]) in edges {
        let (nx, ny) = (normals[x as usize], normals[y as usize]);
        let den = nx.length() * ny.length();
        if den > 0.0 && nx.dot(ny) < cos_max * den {
            let length =
                (to_dvec3(mesh.positions[a as usize]) - to_dvec3(mesh.positions[b as usize])).length();
            creases.push((x, y, length));
        } else {
            dsu.union(x, y);
        }
    }
    let total: f64 = normals.iter().map(|v| 0.5 * v.length()).sum();
    // Per region root: (3-D area, faces).
    let mut area: HashMap<u32, (f64, usize)> = HashMap::new();
    for (f, v) in normals.iter().enumerate() {
        let e = area.entry(dsu.find(f as u32)).or_default();
        e.0 += 0.5 * v.length();
        e.1 += 1;
    }
    if area.len() > MAX_REGIONS || area.len() < 2 {
        return None;
    }
    let small = |&(a, n): &(f64, usize)| a < MIN_REGION_SHARE * total || n < MIN_REGION_FACES;
    // The smallest region still to place (ties to the lower root).
    let next_small = |area: &HashMap<u32, (f64, usize)>, alone: &[u32]| {
        area.iter()
            .filter(|(r, v)| small(v) && !alone.contains(r))
            .min_by(|a, b| a.1.0.total_cmp(&b.1.0).then(a.0.cmp(b.0)))
            .map(|(&r, _)| r)
    };
    let mut alone: Vec<u32> = Vec::new();
    while let Some(root) = next_small(&area, &alone) {
        let mut shared: HashMap<u32, f64> = HashMap::new();
        for &(x, y, l) in &creases {
            let (rx, ry) = (dsu.find(x), dsu.find(y));
            if rx != ry && (rx == root || ry == root) {
                *shared.entry(if rx == root { ry } else { rx }).or_default() += l;
            }
        }
        let Some(to) = shared.iter().max_by(|a, b| a.1.total_cmp(b.1).then(b.0.cmp(a.0))).map(|(&r, _)| r)
        else {
            alone.push(root);
            continue;
        };
        let (a, b) = (area.remove(&root).expect("a listed region"), area.remove(&to).expect("a neighbour"));
        dsu.union(root, to);
        area.insert(dsu.find(root), (a.0 + b.0, a.1 + b.1));
    }
    if area.len() < 2 {
        return None;
    }
    let mut label: HashMap<u32, u32> = HashMap::new();
    let region: Vec<u32> = (0..n as u32)
        .map(|f| {
            let next = label.len() as u32;
            *label.entry(dsu.find(f)).or_insert(next)
        })
        .collect();
    // A fold from +0 (`sum` of f64 starts at −0, which `metrics.json` printed for separate parts).
    let length = creases
        .iter()
        .filter(|&&(x, y, _)| region[x as usize] != region[y as usize])
        .fold(0.0, |sum, c| sum + c.2);
    Some((region, label.len(), length))
}

/// `mesh` with one island per region: each region's vertices projected onto the plane across
/// its area-weighted normal, the regions set apart along `u` by twice the mesh's diagonal.
fn projected(mesh: &TriMesh, region: &[u32], regions: usize) -> TriMesh {
    let mut normal = vec![DVec3::ZERO; regions];
    for (f, &r) in region.iter().enumerate() {
        let [a, b, c] = mesh.corners(f).map(to_dvec3);
        normal[r as usize] += (b - a).cross(c - a);
    }
    let frames: Vec<(DVec3, DVec3)> = normal
        .iter()
        .map(|n| {
            let n = n.normalize_or(DVec3::Z);
            let t = n.any_orthonormal_vector();
            (t, n.cross(t))
        })
        .collect();
    let apart = 2.0 * mesh.bounds().map_or(1.0, |b| (to_dvec3(b.max) - to_dvec3(b.min)).length().max(1e-6));
    let mut index: HashMap<(u32, u32), u32> = HashMap::new();
    let mut coords = Vec::new();
    let triangles = mesh
        .triangles
        .iter()
        .zip(region)
        .map(|(t, &r)| {
            t.map(|v| {
                *index.entry((r, v)).or_insert_with(|| {
                    let (x, y) = frames[r as usize];
                    let q = to_dvec3(mesh.positions[v as usize]);
                    coords.push([(q.dot(x) + apart * r as f64) as f32, q.dot(y) as f32]);
                    (coords.len() - 1) as u32
                })
            })
        })
        .collect();
    TriMesh { uv: Some(UvLayer { coords, triangles }), ..mesh.clone() }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testmesh::grid;
    use crate::uvstats::uv_charts;

    /// An axis-aligned box `[0, w] × [0, h] × [0, d]`, each side `K × K` quads of two triangles
    /// (outward winding, vertices shared along the edges), without its top (`z = d`) side when
    /// `open`, with UVs from a projection along `z`. Sides in the order bottom, top, `y = 0`,
    /// `y = h`, `x = 0`, `x = w`, each `2 K²` faces.
    fn cuboid(w: f32, h: f32, d: f32, open: bool) -> TriMesh {
        // Each side as its corner and two edge vectors whose cross product points outwards.
        let sides: [([f32; 3], [f32; 3], [f32; 3]); 6] = [
            ([0.0, 0.0, 0.0], [0.0, h, 0.0], [w, 0.0, 0.0]),
            ([0.0, 0.0, d], [w, 0.0, 0.0], [0.0, h, 0.0]),
            ([0.0, 0.0, 0.0], [w, 0.0, 0.0], [0.0, 0.0, d]),
            ([0.0, h, 0.0], [0.0, 0.0, d], [w, 0.0, 0.0]),
            ([0.0, 0.0, 0.0], [0.0, 0.0, d], [0.0, h, 0.0]),
            ([w, 0.0, 0.0], [0.0, h, 0.0], [0.0, 0.0, d]),
        ];
        let mut positions: Vec<[f32; 3]> = Vec::new();
        let mut id = |p: [f32; 3]| {
            positions.iter().position(|q| *q == p).unwrap_or_else(|| {
                positions.push(p);
                positions.len() - 1
            }) as u32
        };
        let mut triangles = Vec::new();
        for (i, (o, a, b)) in sides.into_iter().enumerate() {
            if open && i == 1 {
                continue;
            }
            let at = |s: u32, t: u32| {
                let (s, t) = (s as f32 / K as f32, t as f32 / K as f32);
                std::array::from_fn(|k| o[k] + s * a[k] + t * b[k])
            };
            for t in 0..K {
                for s in 0..K {
                    let q = [id(at(s, t)), id(at(s + 1, t)), id(at(s + 1, t + 1)), id(at(s, t + 1))];
                    triangles.push([q[0], q[1], q[2]]);
                    triangles.push([q[0], q[2], q[3]]);
                }
            }
        }
        let coords = positions.iter().map(|p| [p[0], p[1]]).collect();
        TriMesh { positions, uv: Some(UvLayer { coords, triangles: triangles.clone() }), triangles }
    }

    /// Quads per side of [`cuboid`]'s sides: 8 triangles a side, [`MIN_REGION_FACES`].
    const K: u32 = 2;
    const SIDE: usize = 2 * (K * K) as usize;

    #[test]
    fn a_cube_has_six_regions_bounded_by_its_twelve_edges() {
        let (region, n, length) = crease_regions(&cuboid(2.0, 2.0, 2.0, false)).unwrap();
        assert_eq!(n, 6);
        assert!((length - 24.0).abs() < 1e-9, "twelve edges of length 2: {length}");
        for f in 0..6 * SIDE {
            assert_eq!(region[f], region[f / SIDE * SIDE], "a side is one region");
        }
    }

    #[test]
    fn a_flat_sheet_and_a_shallow_fold_are_left_alone_a_right_angle_is_not() {
        assert!(crease_regions(&grid(8, |p| [p[0], p[1]])).is_none(), "no crease, one region");
        let folded = |angle: f32| {
            let mut m = grid(8, |p| [p[0], p[1]]);
            for p in &mut m.positions {
                if p[0] > 0.0 {
                    let x = p[0];
                    *p = [x * angle.cos(), p[1], x * angle.sin()];
                }
            }
            m
        };
        assert!(crease_regions(&folded(45f32.to_radians())).is_none(), "45° is under the crease angle");
        let (_, n, length) = crease_regions(&folded(90f32.to_radians())).unwrap();
        assert_eq!(n, 2);
        assert!((length - 2.0).abs() < 1e-6, "the fold line is the grid's side: {length}");
    }

    #[test]
    fn the_thin_sides_of_a_slab_join_a_face_they_border() {
        // Sides of 0.1 × 10 hold 0.5% of the area each, under MIN_REGION_SHARE.
        let slab = cuboid(10.0, 10.0, 0.1, false);
        let (region, n, length) = crease_regions(&slab).unwrap();
        assert_eq!(n, 2, "top and bottom, each side strip with one of them: {region:?}");
        assert_ne!(region[0], region[SIDE], "the bottom and the top stay apart");
        // What separates the two regions: each strip's other long edge (4 × 10) and, where two
        // strips that joined different faces meet, their short edges (0.1 each).
        assert!((40.0..=40.5).contains(&length), "{length}");
    }

    #[test]
    fn an_open_box_squashed_into_one_projection_is_charted_by_its_creases() {
        // One island: the box seen from above, its rim pushed out by a fifth of the side, so its
        // walls are trapezoids a fifth of their height: injective, far from an isometry.
        let mut tray = cuboid(1.0, 1.0, 1.0, true);
        let uv = tray.uv.as_mut().unwrap();
        for (c, p) in uv.coords.iter_mut().zip(&tray.positions) {
            let lift = 0.2 * p[2];
            *c = [c[0] + lift * (c[0] - 0.5).signum(), c[1] + lift * (c[1] - 0.5).signum()];
        }
        let out = crease_charts(&tray, &InjectiveOptions::default()).unwrap();
        assert_eq!(out.report.regions, 5);
        let [networks, creases] = out.report.editability.unwrap();
        assert!(out.report.chosen && creases > networks, "{:?}", out.report);
        let uv = out.mesh.uv.as_ref().unwrap();
        assert_eq!(uv_charts(&out.mesh, uv).1, 5, "one island per face of the tray");
        assert_eq!(out.mesh.triangles, tray.triangles, "faces kept in order");
    }

    #[test]
    fn an_isometric_net_of_a_box_is_kept() {
        // The open box unfolded into its cross-shaped net: one island, isometric, four seams
        // fewer than five separate squares.
        let mut tray = cuboid(1.0, 1.0, 1.0, true);
        let mut coords = Vec::new();
        let mut triangles = Vec::new();
        for t in &tray.triangles {
            let ps = t.map(|v| tray.positions[v as usize]);
            triangles.push(ps.map(|p| {
                // Each wall turned down about its bottom edge into the plane z = 0.
                let [x, y, z] = p;
                let q = if ps.iter().all(|q| q[1] == 0.0) {
                    [x, -z]
                } else if ps.iter().all(|q| q[1] == 1.0) {
                    [x, 1.0 + z]
                } else if ps.iter().all(|q| q[0] == 0.0) {
                    [-z, y]
                } else if ps.iter().all(|q| q[0] == 1.0) {
                    [1.0 + z, y]
                } else {
                    [x, y]
                };
                let i = coords.iter().position(|&c| c == q).unwrap_or_else(|| {
                    coords.push(q);
                    coords.len() - 1
                });
                i as u32
            }));
        }
        tray.uv = Some(UvLayer { coords, triangles });
        let out = crease_charts(&tray, &InjectiveOptions::default()).unwrap();
        assert_eq!(out.report.regions, 5);
        assert!(!out.report.chosen, "{:?}", out.report);
        assert_eq!(out.mesh, tray, "the net as it came");
    }
}

//! Repairing fold-overs of a baked chart map by moving single UV vertices (not in the paper).
//!
//! Nuvo's texture map `t_i` is a smooth function of 3-D position, so where the input surface itself
//! folds back over a distance shorter than the sample spacing (scan artefacts: tiny triangles on a
//! crease, `uvstats` "creased faces"), the baked triangle comes out mirrored in UV even though the
//! chart map is fine around it. A texture painted on such a face shows mirrored, and tools that
//! expect an orientation-consistent atlas (normal maps, UV-space filters) misbehave there.
//!
//! [`untangle`] moves UV coordinates of a baked layer, one at a time, so that a flipped face turns the
//! chart's way round without turning any other face over:
//!
//! - **Flipped face**: as in [`crate::uvstats`]: signed UV area of the sign opposite to its chart's
//!   majority (the sign of the chart's total signed area, ties counter-clockwise), and not
//!   degenerate. A face is **right** when it has the majority sign and is not degenerate.
//! - **Fan** of a UV coordinate: the faces that use it, the only faces that change when it moves.
//!   The bake gives each (vertex, chart) pair one UV coordinate, so its fan is the vertex's faces
//!   in that chart.
//! - **Move**: for each corner of a flipped face, the point of the fan's *kernel* (where every fan
//!   face is right) deepest inside it is found by a small linear programme: the largest margin `r`
//!   such that the point lies at distance ≥ `r` on the inner side of every fan face's opposite
//!   edge, inside a box of the fan's size around the corner and inside the chart's tile (its
//!   square in the atlas, so nothing spills into the gutter or another chart). The corner goes to
//!   the first point on the segment from where it is towards that point with margin ≥
//!   `min(r/2, MAX_TARGET_MARGIN)` of the fan's size (so it moves no further than needed, but not
//!   onto an edge; the cap matters on a chart border, where the kernel is open outward). Of the
//!   three corners, the one whose move unflips the most faces is moved (a vertex dragged across
//!   its neighbours goes back, rather than a neighbour following it), then the one that moves
//!   least. Corners outside their tile and fans of more than [`MAX_FAN`] faces (the programme
//!   enumerates triples of constraints) are not moved.
//! - **Fallback**: when a corner's fan has no kernel (its neighbours are folded too, as along a
//!   mirrored strip), the same is done with the half-planes of the fan's right faces plus the
//!   flipped face's own: the face turns back and the right faces stay right, and a later move of
//!   a neighbour can finish the rest.
//!
//! **Invariant**: a move is accepted only when, recounted on the stored `f32` coordinates, it
//! lowers the number of flipped faces in its fan, does not lower the number of right ones, and
//! leaves every chart's majority sign as it was; no face outside the fan changes. So the
//! flipped-face count falls with every move and never rises, by the same count as `uvstats`, and
//! the repair terminates. Faces are visited in id order and every decision is deterministic.
//! Positions, face charts and all other UVs are untouched.

use nuvo_geometry::UvLayer;
use serde::Serialize;

use crate::error::AtlasError;
use crate::uvstats::{Orientation, chart_area2_totals, face_uv_area2, orientation, signed_uv_area2};

/// Largest fan (faces around one UV vertex) the repair considers; a vertex with more is not moved.
pub const MAX_FAN: usize = 24;
/// Passes over the remaining flipped faces; a pass that moves nothing ends the repair early.
const MAX_PASSES: usize = 16;
/// The largest margin a move aims for, in units of the fan's extent: where a fan is open (a chart
/// border) its kernel is unbounded outward and half its depth would carry the vertex far.
const MAX_TARGET_MARGIN: f64 = 0.25;

/// What [`untangle`] did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct UntangleReport {
    /// Faces flipped in their chart before the repair (`uvstats` definition).
    pub flipped_before: usize,
    /// Faces still flipped after it.
    pub flipped_after: usize,
    /// UV vertex moves made (one UV coordinate may move more than once).
    pub moves: usize,
}

/// Moves UV coordinates of `layer` so that faces flipped in their chart (`face_chart`, one label
/// per face) turn the majority way round (module docs). `tiles[c]` is the rectangle `[lo, hi]`
/// chart `c`'s coordinates must stay in (its square in the atlas, so a move never spills into the
/// gutter or another chart); a coordinate already outside its tile is not moved. Works on the final
/// coordinates, so what it checks is what [`crate::uvstats`] measures. Errors, before changing
/// anything, on a label per face missing, a label without a tile, an index out of range or a
/// non-finite coordinate.
pub fn untangle(
    layer: &mut UvLayer,
    face_chart: &[u32],
    tiles: &[[[f32; 2]; 2]],
) -> Result<UntangleReport, AtlasError> {
    check_inputs(layer, face_chart, tiles)?;
    let mut state = State::new(layer, face_chart, tiles);
    let flipped_before = state.flipped_faces().len();
    let mut moves = 0;
    for _ in 0..MAX_PASSES {
        let mut moved_this_pass = 0;
        for f in state.flipped_faces() {
            if state.is_flipped(f) && state.repair(f) {
                moved_this_pass += 1;
            }
        }
        moves += moved_this_pass;
        if moved_this_pass == 0 {
            break;
        }
    }
    Ok(UntangleReport { flipped_before, flipped_after: state.flipped_faces().len(), moves })
}

fn check_inputs(layer: &UvLayer, face_chart: &[u32], tiles: &[[[f32; 2]; 2]]) -> Result<(), AtlasError> {
    let bad = |m: String| Err(AtlasError::invalid("untangle input", m));
    if face_chart.len() != layer.triangles.len() {
        return bad(format!("{} chart labels for {} faces", face_chart.len(), layer.triangles.len()));
    }
    if let Some(f) = face_chart.iter().position(|&c| c as usize >= tiles.len()) {
        return bad(format!("face {f} is in chart {} but there are {} tiles", face_chart[f], tiles.len()));
    }
    let n = layer.coords.len();
    if let Some(f) = layer.triangles.iter().position(|t| t.iter().any(|&i| i as usize >= n)) {
        return bad(format!("face {f} uses a UV index beyond the {n} coordinates"));
    }
    if let Some(i) = layer.coords.iter().position(|p| !(p[0].is_finite() && p[1].is_finite())) {
        return bad(format!("UV coordinate {i} is {:?}", layer.coords[i]));
    }
    if let Some(c) = tiles.iter().position(|t| t.iter().flatten().any(|x| !x.is_finite())) {
        return bad(format!("the tile of chart {c} is {:?}", tiles[c]));
    }
    Ok(())
}

/// The layer plus what the repair looks up and keeps up to date: each chart's total signed area
/// and majority sign, and the faces around every UV coordinate.
struct State<'a> {
    layer: &'a mut UvLayer,
    face_chart: &'a [u32],
    tiles: &'a [[[f32; 2]; 2]],
    /// Twice the signed UV area of each chart, updated with every move.
    total: Vec<f64>,
    /// `+1` or `-1` per chart: the sign a face of that chart should have. Fixed: a move that would
    /// change a chart's majority is refused.
    sign: Vec<f64>,
    /// Faces using each UV coordinate (CSR: `faces_of[start[i]..start[i + 1]]`), each once: its fan.
    start: Vec<usize>,
    faces_of: Vec<u32>,
}

/// An accepted position for one UV coordinate.
struct Move {
    uv: u32,
    to: [f32; 2],
    /// Fan faces no longer flipped after the move.
    fixed: usize,
    distance: f64,
    /// Change of each affected chart's total signed area (twice the area).
    area_change: Vec<(usize, f64)>,
}

/// How the faces of a fan stand.
struct FanCount {
    flipped: usize,
    wrong: usize,
    /// Twice the signed area per chart of the fan's faces.
    area: Vec<(usize, f64)>,
}

impl<'a> State<'a> {
    fn new(layer: &'a mut UvLayer, face_chart: &'a [u32], tiles: &'a [[[f32; 2]; 2]]) -> Self {
        let total = chart_area2_totals(&signed_uv_area2(layer), face_chart, tiles.len());
        let sign = total.iter().map(|&t| if t >= 0.0 { 1.0 } else { -1.0 }).collect();
        let coords = layer.coords.len();
        let mut fans: Vec<Vec<u32>> = vec![Vec::new(); coords];
        for (f, t) in layer.triangles.iter().enumerate() {
            for &i in t {
                if fans[i as usize].last() != Some(&(f as u32)) {
                    fans[i as usize].push(f as u32);
                }
            }
        }
        let mut start = Vec::with_capacity(coords + 1);
        start.push(0);
        for fan in &fans {
            start.push(start.last().copied().unwrap_or(0) + fan.len());
        }
        let faces_of = fans.concat();
        State { layer, face_chart, tiles, total, sign, start, faces_of }
    }

    fn chart(&self, f: usize) -> usize {
        self.face_chart[f] as usize
    }

    /// The sign face `f` should have.
    fn sign_of(&self, f: usize) -> f64 {
        self.sign[self.chart(f)]
    }

    fn fan(&self, i: u32) -> &[u32] {
        &self.faces_of[self.start[i as usize]..self.start[i as usize + 1]]
    }

    /// How face `f` sits in its chart, by the rule `uvstats` counts with.
    fn orientation(&self, f: usize) -> Orientation {
        orientation(face_uv_area2(self.layer, f), self.sign_of(f) > 0.0)
    }

    fn is_flipped(&self, f: usize) -> bool {
        self.orientation(f) == Orientation::Flipped
    }

    /// Flipped faces, in id order.
    fn flipped_faces(&self) -> Vec<usize> {
        (0..self.layer.triangles.len()).filter(|&f| self.is_flipped(f)).collect()
    }

    /// Not right (module docs): flipped or degenerate.
    fn is_wrong_way(&self, f: usize) -> bool {
        self.orientation(f) != Orientation::Right
    }

    /// Counts the fan of `i` as the layer stands.
    fn count_fan(&self, i: u32) -> FanCount {
        let mut count = FanCount { flipped: 0, wrong: 0, area: Vec::new() };
        for &g in self.fan(i) {
            let g = g as usize;
            let (c, a) = (self.chart(g), face_uv_area2(self.layer, g));
            let o = orientation(a, self.sign[c] > 0.0);
            count.flipped += (o == Orientation::Flipped) as usize;
            count.wrong += (o != Orientation::Right) as usize;
            match count.area.iter_mut().find(|(k, _)| *k == c) {
                Some(entry) => entry.1 += a,
                None => count.area.push((c, a)),
            }
        }
        count
    }

    /// Moves one corner of face `f` (module docs); true if a move was made.
    fn repair(&mut self, f: usize) -> bool {
        let corners = self.layer.triangles[f];
        let mut best: Option<Move> = None;
        for i in corners {
            let Some(to) = self.proposal(i, f) else { continue };
            let Some(m) = self.try_move(i, to) else { continue };
            let better = best.as_ref().is_none_or(|b| (m.fixed, -m.distance) > (b.fixed, -b.distance));
            if better {
                best = Some(m);
            }
        }
        let Some(m) = best else { return false };
        self.layer.coords[m.uv as usize] = m.to;
        for (c, d) in m.area_change {
            self.total[c] += d;
        }
        true
    }

    /// Recounts the fan of `i` with `i` at `to` and returns the move if it is accepted (module
    /// docs: fewer flipped faces in the fan, no fewer right ones, no chart's majority changed).
    fn try_move(&mut self, i: u32, to: [f32; 2]) -> Option<Move> {
        let old = self.layer.coords[i as usize];
        let before = self.count_fan(i);
        self.layer.coords[i as usize] = to;
        let after = self.count_fan(i);
        self.layer.coords[i as usize] = old;
        let area_change: Vec<(usize, f64)> =
            after.area.iter().zip(&before.area).map(|(&(c, a), &(_, b))| (c, a - b)).collect();
        let keeps_majority = area_change.iter().all(|&(c, d)| (self.total[c] + d) * self.sign[c] > 0.0);
        let accepted = after.flipped < before.flipped && after.wrong <= before.wrong && keeps_majority;
        let p0 = [old[0] as f64, old[1] as f64];
        accepted.then(|| Move {
            uv: i,
            to,
            fixed: before.flipped - after.flipped,
            distance: (to[0] as f64 - p0[0]).hypot(to[1] as f64 - p0[1]),
            area_change,
        })
    }

    /// Where UV coordinate `i` should go to turn face `f` (one of its fan) back (module docs), or
    /// `None` if its fan is too large, its tile leaves no room or no position does it.
    fn proposal(&self, i: u32, f: usize) -> Option<[f32; 2]> {
        let fan = self.fan(i);
        if fan.len() > MAX_FAN {
            return None;
        }
        let p0 = self.uv(i);
        // Each fan face as (a, b, sign): its other two corners in the face's order after i. A face
        // using i twice has no area to gain and gives no constraint.
        let mut edges: Vec<Edge> = Vec::with_capacity(fan.len());
        let mut wrong = Vec::with_capacity(fan.len());
        for &g in fan {
            let t = self.layer.triangles[g as usize];
            let Some(k) = t.iter().position(|&w| w == i) else { continue };
            let (a, b) = (t[(k + 1) % 3], t[(k + 2) % 3]);
            if a == i || b == i {
                continue;
            }
            edges.push((self.uv(a), self.uv(b), self.sign_of(g as usize)));
            wrong.push((self.is_wrong_way(g as usize), g as usize == f));
        }
        let extent = fan_extent(p0, &edges);
        let tile = self.tiles[self.chart(f)].map(|p| [p[0] as f64, p[1] as f64]);
        let inside = (0..2).all(|k| tile[0][k] <= p0[k] && p0[k] <= tile[1][k]);
        if !inside {
            return None;
        }
        let whole = Kernel::new(p0, extent, &edges, tile);
        let (kernel, (deep, r)) = match whole.deepest_point() {
            Some(d) if d.1 > 0.0 => (whole, d),
            _ => {
                // No position turns the whole fan right: keep the right faces right and turn f.
                let kept: Vec<Edge> =
                    edges.iter().zip(&wrong).filter(|(_, (w, is_f))| !w || *is_f).map(|(e, _)| *e).collect();
                let relaxed = Kernel::new(p0, extent, &kept, tile);
                let d = relaxed.deepest_point().filter(|d| d.1 > 0.0)?;
                (relaxed, d)
            }
        };
        let to = kernel.to_uv(kernel.toward(deep, (0.5 * r).min(MAX_TARGET_MARGIN)));
        (to[0].is_finite() && to[1].is_finite()).then_some(to)
    }

    fn uv(&self, i: u32) -> [f64; 2] {
        let p = self.layer.coords[i as usize];
        [p[0] as f64, p[1] as f64]
    }
}

/// A fan face seen from its moving corner: the opposite edge's two corners, in the face's order,
/// and the sign the face should have.
type Edge = ([f64; 2], [f64; 2], f64);

/// The fan's size around its vertex `origin`: the largest coordinate offset of its other corners
/// (1 for a fan of coincident points).
fn fan_extent(origin: [f64; 2], edges: &[Edge]) -> f64 {
    let extent = edges
        .iter()
        .flat_map(|(a, b, _)| [a, b])
        .map(|p| (p[0] - origin[0]).abs().max((p[1] - origin[1]).abs()))
        .fold(0.0f64, f64::max);
    if extent > 0.0 { extent } else { 1.0 }
}

/// The half-planes where a fan's vertex keeps every fan face the majority way round, in a frame
/// centred on the vertex and scaled by the fan's size (so the tolerances below are relative).
struct Kernel {
    origin: [f64; 2],
    scale: f64,
    /// `(n, d)` per fan face: the signed distance of point `p` inside the face's opposite edge is
    /// `n·p − d` (unit `n`, pointing into the kernel).
    planes: Vec<([f64; 2], f64)>,
    /// `[lo, hi]` of the region the vertex may move in (local frame): the box `|p|∞ ≤ 1` of the
    /// fan's extent intersected with the chart's tile.
    bounds: [[f64; 2]; 2],
}

impl Kernel {
    /// The kernel of the fan faces given by their opposite `edges`, around the vertex at `origin`,
    /// in units of `scale` (> 0), limited to the box of the fan's extent and to the rectangle
    /// `tile` (`[lo, hi]`, UV units).
    fn new(origin: [f64; 2], scale: f64, edges: &[Edge], tile: [[f64; 2]; 2]) -> Self {
        let local = |p: [f64; 2], s: f64| [(p[0] - origin[0]) / s, (p[1] - origin[1]) / s];
        let (lo, hi) = (local(tile[0], scale), local(tile[1], scale));
        let bounds = [[lo[0].max(-1.0), lo[1].max(-1.0)], [hi[0].min(1.0), hi[1].min(1.0)]];
        let planes = edges
            .iter()
            .filter_map(|&(a, b, sign)| {
                let (a, b) = (local(a, scale), local(b, scale));
                // Twice the signed area of (p, a, b) = a×b + p×(a − b), linear in p.
                let n = [sign * (a[1] - b[1]), -sign * (a[0] - b[0])];
                let len = n[0].hypot(n[1]);
                (len > 0.0).then(|| {
                    let d = -sign * (a[0] * b[1] - a[1] * b[0]);
                    ([n[0] / len, n[1] / len], d / len)
                })
            })
            .collect();
        Kernel { origin, scale, planes, bounds }
    }

    fn margin(&self, p: [f64; 2]) -> f64 {
        self.planes.iter().map(|(n, d)| n[0] * p[0] + n[1] * p[1] - d).fold(f64::INFINITY, f64::min)
    }

    /// The point of [`Kernel::bounds`] that maximises the smallest margin, and that margin: a
    /// linear programme in `(x, y, r)` solved by enumerating its vertices (every triple of active
    /// constraints). `None` for an empty fan or empty bounds.
    fn deepest_point(&self) -> Option<([f64; 2], f64)> {
        let [lo, hi] = self.bounds;
        if self.planes.is_empty() || lo[0] > hi[0] || lo[1] > hi[1] {
            return None;
        }
        // Rows a·(x, y, r) ≤ b: fan planes −n·p + r ≤ −d, the bounds, and r ≤ 2.
        let mut rows: Vec<([f64; 3], f64)> =
            self.planes.iter().map(|(n, d)| ([-n[0], -n[1], 1.0], -d)).collect();
        rows.extend([
            ([1.0, 0.0, 0.0], hi[0]),
            ([-1.0, 0.0, 0.0], -lo[0]),
            ([0.0, 1.0, 0.0], hi[1]),
            ([0.0, -1.0, 0.0], -lo[1]),
            ([0.0, 0.0, 1.0], 2.0),
        ]);
        let feasible =
            |z: [f64; 3]| rows.iter().all(|(a, b)| a[0] * z[0] + a[1] * z[1] + a[2] * z[2] <= b + 1e-9);
        let mut best: Option<[f64; 3]> = None;
        for i in 0..rows.len() {
            for j in i + 1..rows.len() {
                for k in j + 1..rows.len() {
                    let Some(z) = solve3([rows[i], rows[j], rows[k]]) else { continue };
                    let better = best.is_none_or(|b| z[2] > b[2] || (z[2] == b[2] && closer(z, b)));
                    if better && feasible(z) {
                        best = Some(z);
                    }
                }
            }
        }
        best.map(|z| ([z[0], z[1]], self.margin([z[0], z[1]])))
    }

    /// The first point on the segment from the vertex (the origin) to `deep` whose margin is at
    /// least `want` (`deep`'s own margin is larger, so there is one).
    fn toward(&self, deep: [f64; 2], want: f64) -> [f64; 2] {
        let mut lambda = 0.0f64;
        for (n, d) in &self.planes {
            let (m0, m1) = (-d, n[0] * deep[0] + n[1] * deep[1] - d);
            if m0 < want && m1 > m0 {
                lambda = lambda.max((want - m0) / (m1 - m0));
            }
        }
        let lambda = lambda.min(1.0);
        [lambda * deep[0], lambda * deep[1]]
    }

    fn to_uv(&self, p: [f64; 2]) -> [f32; 2] {
        [(self.origin[0] + p[0] * self.scale) as f32, (self.origin[1] + p[1] * self.scale) as f32]
    }
}

/// Ties between exactly equally deep points go to the one nearer the vertex, then to the lower x, y.
/// (Depths that differ only by rounding are not ties; the enumeration order is fixed, so the choice
/// is deterministic either way.)
fn closer(z: [f64; 3], b: [f64; 3]) -> bool {
    let (dz, db) = (z[0].hypot(z[1]), b[0].hypot(b[1]));
    dz < db || (dz == db && (z[0], z[1]) < (b[0], b[1]))
}

/// The solution of three equations `a·z = b` (Cramer's rule), or `None` when they are (nearly)
/// dependent.
fn solve3(rows: [([f64; 3], f64); 3]) -> Option<[f64; 3]> {
    let det = |m: [[f64; 3]; 3]| {
        m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1]) - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
            + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
    };
    let a = rows.map(|r| r.0);
    let d = det(a);
    if d.abs() < 1e-12 {
        return None;
    }
    let mut z = [0.0; 3];
    for (col, zc) in z.iter_mut().enumerate() {
        let mut m = a;
        for (row, r) in rows.iter().enumerate() {
            m[row][col] = r.1;
        }
        *zc = det(m) / d;
    }
    Some(z)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testmesh::grid;

    /// A `k × k` grid's UV layer (one UV per vertex): the xy map of the plane into `[0,1]²`,
    /// through `f`.
    fn plane(k: u32, f: impl Fn([f32; 2]) -> [f32; 2]) -> UvLayer {
        grid(k, |p| f([(p[0] + 1.0) * 0.5, (p[1] + 1.0) * 0.5])).uv.unwrap()
    }

    /// The unit square as the tile of each of `n` charts.
    const UNIT: [[[f32; 2]; 2]; 2] = [[[0.0, 0.0], [1.0, 1.0]]; 2];

    fn flipped(layer: &mut UvLayer, charts: &[u32]) -> usize {
        State::new(layer, charts, &UNIT).flipped_faces().len()
    }

    fn run(layer: &mut UvLayer, charts: &[u32]) -> UntangleReport {
        untangle(layer, charts, &UNIT).unwrap()
    }

    /// Vertex (2, 2) of a 4 × 4 grid (id 12, UV (0.5, 0.5)) dragged to `to` (mirrored in u with the
    /// whole chart when `mirror`).
    fn dragged_plane(to: [f32; 2], mirror: bool) -> UvLayer {
        let mut layer = plane(4, |[u, v]| if mirror { [1.0 - u, v] } else { [u, v] });
        layer.coords[12] = if mirror { [1.0 - to[0], to[1]] } else { to };
        layer
    }

    fn moved(a: &UvLayer, b: &UvLayer) -> Vec<usize> {
        (0..a.coords.len()).filter(|&i| a.coords[i] != b.coords[i]).collect()
    }

    #[test]
    fn a_vertex_dragged_past_its_neighbours_is_repaired_by_one_move() {
        // Past the neighbour (3, 3) at (0.75, 0.75): two faces fold. Either vertex 12 goes back into
        // its ring or the neighbour follows it out; either way one vertex moves, nothing flips.
        for mirror in [false, true] {
            let mut layer = dragged_plane([0.9, 0.9], mirror);
            let charts = vec![0u32; layer.triangles.len()];
            let before = layer.clone();
            assert_eq!(flipped(&mut layer, &charts), 2, "mirror {mirror}: the fixture folds");
            let r = run(&mut layer, &charts);
            assert_eq!(
                r,
                UntangleReport { flipped_before: 2, flipped_after: 0, moves: 1 },
                "mirror {mirror}"
            );
            assert_eq!(flipped(&mut layer, &charts), 0);
            assert_eq!(moved(&before, &layer).len(), 1, "mirror {mirror}");
        }
    }

    #[test]
    fn only_the_flipped_faces_chart_moves() {
        // Two charts: faces left of x = 0 in chart 0, the others in chart 1 with their own UV
        // coordinates (ids + 25, as the bake splits a vertex on a chart border). Chart 0's map is
        // folded at vertex 12, which is on the border; chart 1 is mirrored (its majority is
        // clockwise), so a sign shared between charts would see all of it flipped.
        let m = grid(4, |_| [0.0, 0.0]);
        let folded = dragged_plane([0.1, 0.1], false);
        let flat = plane(4, |[u, v]| [1.0 - u, v]);
        let charts: Vec<u32> = (0..m.triangles.len())
            .map(|f| (m.corners(f).iter().map(|c| c[0]).sum::<f32>() > 0.0) as u32)
            .collect();
        let mut layer = UvLayer {
            coords: folded.coords.iter().chain(&flat.coords).copied().collect(),
            triangles: m.triangles.iter().zip(&charts).map(|(t, &c)| t.map(|v| v + 25 * c)).collect(),
        };
        let before = layer.clone();
        let r = run(&mut layer, &charts);
        assert!(r.flipped_before > 0, "{r:?}");
        assert_eq!(r.flipped_after, 0, "{r:?}");
        assert!(moved(&before, &layer).iter().all(|&i| i < 25), "chart 1's UVs moved");
    }

    #[test]
    fn a_face_using_a_coordinate_twice_neither_blocks_nor_fakes_a_repair() {
        // The dragged plane plus a face [12, 12, 13]: zero area wherever 12 goes, so never right.
        let mut layer = dragged_plane([0.9, 0.9], false);
        layer.triangles.push([12, 12, 13]);
        let charts = vec![0u32; layer.triangles.len()];
        let r = run(&mut layer, &charts);
        assert_eq!((r.flipped_before, r.flipped_after), (2, 0), "{r:?}");
        assert_eq!(flipped(&mut layer, &charts), 0);
    }

    #[test]
    fn bad_inputs_are_errors_and_change_nothing() {
        let layer = dragged_plane([0.9, 0.9], false);
        let charts = vec![0u32; layer.triangles.len()];
        let err = |layer: &UvLayer, charts: &[u32], tiles: &[[[f32; 2]; 2]]| {
            let mut copy = layer.clone();
            let e = untangle(&mut copy, charts, tiles).unwrap_err().to_string();
            assert_eq!(format!("{copy:?}"), format!("{layer:?}"), "{e}");
            e
        };
        assert!(err(&layer, &charts[1..], &UNIT).contains("31 chart labels for 32 faces"));
        assert!(err(&layer, &charts, &UNIT[..0]).contains("face 0 is in chart 0 but there are 0 tiles"));
        let mut nan = layer.clone();
        nan.coords[3][1] = f32::NAN;
        assert!(err(&nan, &charts, &UNIT).contains("UV coordinate 3"));
        let mut beyond = layer.clone();
        beyond.triangles[5][2] = 99;
        assert!(err(&beyond, &charts, &UNIT).contains("face 5"));
        assert!(err(&layer, &charts, &[[[0.0, 0.0], [f32::INFINITY, 1.0]]]).contains("tile of chart 0"));
    }

    #[test]
    fn a_map_without_flips_is_left_bit_for_bit() {
        let mut layer = plane(4, |[u, v]| [u * u, v]);
        let before = layer.clone();
        let r = run(&mut layer, &vec![0u32; before.triangles.len()]);
        assert_eq!(r, UntangleReport::default());
        assert_eq!(layer, before);
    }

    #[test]
    fn random_folds_never_gain_flips_and_mostly_go() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let (mut total_before, mut total_after) = (0, 0);
        for _ in 0..50 {
            let mut layer = plane(8, |p| p);
            for p in layer.coords.iter_mut() {
                *p = p.map(|x| x + rng.random_range(-0.09..0.09f32));
            }
            let charts = vec![0u32; layer.triangles.len()];
            let r = run(&mut layer, &charts);
            assert!(r.flipped_after <= r.flipped_before, "{r:?}");
            assert_eq!(r.flipped_after, flipped(&mut layer, &charts));
            total_before += r.flipped_before;
            total_after += r.flipped_after;
        }
        assert!(total_before > 50, "the noise folds the grids ({total_before})");
        assert!(total_after * 10 < total_before, "{total_after} of {total_before} flips left");
    }

    #[test]
    fn the_deepest_point_of_a_square_ring_is_its_centre() {
        // The ring of a vertex at (0.3, 0.2) inside the square [-1, 1]² (counter-clockwise fan).
        let corners = [[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]];
        let edges: Vec<Edge> = (0..4).map(|i| (corners[i], corners[(i + 1) % 4], 1.0)).collect();
        let k = Kernel::new([0.3, 0.2], fan_extent([0.3, 0.2], &edges), &edges, [[-9.0, -9.0], [9.0, 9.0]]);
        let (p, r) = k.deepest_point().unwrap();
        let uv = k.to_uv(p);
        assert!(uv[0].abs() < 1e-6 && uv[1].abs() < 1e-6, "{uv:?}");
        assert!((r * k.scale - 1.0).abs() < 1e-9, "margin {}", r * k.scale);
        // Already inside with margin 0.7: the first point with margin ≥ 0.5 is the vertex itself.
        assert_eq!(k.toward(p, 0.5 / k.scale), [0.0, 0.0]);
    }
}

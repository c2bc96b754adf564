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
//!   face is the majority way round) deepest inside it is found by a small linear programme: the
//!   largest margin `r` such that the point lies at distance ≥ `r` on the inner side of every fan
//!   face's opposite edge, inside a box of the fan's size around the vertex. If the kernel is not
//!   empty, the vertex goes to the first point on the segment from where it is towards that point
//!   with margin ≥ `r/2` (so it moves no further than needed, but not onto an edge). Of the three
//!   corners, the one whose move turns the most faces back is moved (a vertex dragged across its
//!   neighbours goes back, rather than a neighbour following it), then the one that moves least.
//! - **Fallback**: when a corner's fan has no kernel (its neighbours are folded too, as along a
//!   mirrored strip), the same is done with the half-planes of the fan's faces that are the right
//!   way round plus the flipped face's own: the face turns back and no face of the fan turns over,
//!   and a later move of a neighbour can finish the rest.
//!
//! **Invariant**: a move is accepted only when it lowers the number of flipped faces in its fan
//! and does not lower the number of right ones, and no face outside the fan changes; so the
//! flipped-face count falls with every move, never rises, and the repair terminates. Faces are visited in id order and every decision is deterministic.
//! Positions, face charts and all other UVs are untouched. Fans of more than [`MAX_FAN`] faces are
//! left alone (the programme enumerates triples of constraints).

use nuvo_geometry::UvLayer;
use serde::Serialize;

use crate::uvstats::DEGENERATE_UV_AREA;
use crate::vecmath::signed_area2_2d;

/// Largest fan (faces around one UV vertex) the repair considers; a vertex with more is not moved.
pub const MAX_FAN: usize = 24;
/// Passes over the remaining flipped faces; a pass that moves nothing ends the repair early.
const MAX_PASSES: usize = 16;

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
/// per face) turn the majority way round (module docs). Works on the final coordinates, so what it
/// checks is what [`crate::uvstats`] measures. Callers guarantee consistent shapes: one label per
/// face of `layer`, UV indices in range (a validated mesh).
pub fn untangle(layer: &mut UvLayer, face_chart: &[u32]) -> UntangleReport {
    let mut state = State::new(layer, face_chart);
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
    UntangleReport { flipped_before, flipped_after: state.flipped_faces().len(), moves }
}

/// The layer plus what the repair looks up: each chart's majority sign and the faces around every
/// UV coordinate.
struct State<'a> {
    layer: &'a mut UvLayer,
    face_chart: &'a [u32],
    /// `+1` or `-1` per chart: the sign a face of that chart should have.
    sign: Vec<f64>,
    /// Faces using each UV coordinate (CSR: `faces_of[start[i]..start[i + 1]]`): its fan.
    start: Vec<usize>,
    faces_of: Vec<u32>,
}

/// A candidate position for one UV coordinate.
struct Move {
    uv: u32,
    to: [f32; 2],
    /// Fan faces no longer flipped after the move.
    fixed: usize,
    distance: f64,
}

impl<'a> State<'a> {
    fn new(layer: &'a mut UvLayer, face_chart: &'a [u32]) -> Self {
        let charts = face_chart.iter().max().map_or(0, |&m| m as usize + 1);
        let mut total = vec![0.0f64; charts];
        for (f, &c) in face_chart.iter().enumerate() {
            total[c as usize] += face_area2(layer, f);
        }
        let sign = total.iter().map(|&t| if t >= 0.0 { 1.0 } else { -1.0 }).collect();
        let coords = layer.coords.len();
        let mut start = vec![0usize; coords + 1];
        for t in &layer.triangles {
            for &i in t {
                start[i as usize + 1] += 1;
            }
        }
        for i in 0..coords {
            start[i + 1] += start[i];
        }
        let mut fill = start.clone();
        let mut faces_of = vec![0u32; start[coords]];
        for (f, t) in layer.triangles.iter().enumerate() {
            for &i in t {
                faces_of[fill[i as usize]] = f as u32;
                fill[i as usize] += 1;
            }
        }
        State { layer, face_chart, sign, start, faces_of }
    }

    /// The sign face `f` should have.
    fn sign_of(&self, f: usize) -> f64 {
        self.sign[self.face_chart[f] as usize]
    }

    /// Flipped as `uvstats` counts it: the wrong sign and not degenerate.
    fn is_flipped(&self, f: usize) -> bool {
        let a = face_area2(self.layer, f);
        a * self.sign_of(f) < 0.0 && a.abs() * 0.5 > DEGENERATE_UV_AREA
    }

    /// Flipped faces, in id order.
    fn flipped_faces(&self) -> Vec<usize> {
        (0..self.layer.triangles.len()).filter(|&f| self.is_flipped(f)).collect()
    }

    /// Not right (module docs): flipped or degenerate.
    fn is_wrong_way(&self, f: usize) -> bool {
        let a = face_area2(self.layer, f) * self.sign_of(f);
        a * 0.5 <= DEGENERATE_UV_AREA
    }

    /// Moves one corner of face `f` (module docs); true if a move was made.
    fn repair(&mut self, f: usize) -> bool {
        let corners = self.layer.triangles[f];
        let best = corners
            .iter()
            .filter_map(|&i| self.candidate(i, f))
            .min_by(|a, b| b.fixed.cmp(&a.fixed).then(a.distance.total_cmp(&b.distance)));
        match best {
            Some(m) => {
                self.layer.coords[m.uv as usize] = m.to;
                true
            }
            None => false,
        }
    }

    /// Where UV coordinate `i` should go to turn face `f` (one of its fan) back, if the move is
    /// accepted (module docs: fewer flipped faces in the fan, no fewer right ones).
    fn candidate(&self, i: u32, f: usize) -> Option<Move> {
        let fan = &self.faces_of[self.start[i as usize]..self.start[i as usize + 1]];
        if fan.len() > MAX_FAN {
            return None;
        }
        let p0 = self.uv(i);
        // Each fan face as (a, b, sign): its other two corners in the face's order after i.
        let edges: Vec<Edge> = fan
            .iter()
            .map(|&g| {
                let t = self.layer.triangles[g as usize];
                let k = t.iter().position(|&w| w == i).unwrap_or(0);
                (self.uv(t[(k + 1) % 3]), self.uv(t[(k + 2) % 3]), self.sign_of(g as usize))
            })
            .collect();
        let wrong: Vec<bool> = fan.iter().map(|&g| self.is_wrong_way(g as usize)).collect();
        let extent = fan_extent(p0, &edges);
        let whole = Kernel::new(p0, extent, &edges);
        let (kernel, (deep, r)) = match whole.deepest_point() {
            Some(d) if d.1 > 0.0 => (whole, d),
            _ => {
                // No position turns the whole fan right: keep the right faces right and turn f.
                let keep = |k: usize| !wrong[k] || fan[k] as usize == f;
                let kept: Vec<Edge> = (0..fan.len()).filter(|&k| keep(k)).map(|k| edges[k]).collect();
                let relaxed = Kernel::new(p0, extent, &kept);
                let d = relaxed.deepest_point().filter(|d| d.1 > 0.0)?;
                (relaxed, d)
            }
        };
        let to = kernel.to_uv(kernel.toward(deep, 0.5 * r));
        let now = fan.iter().map(|&g| self.is_flipped(g as usize));
        let flipped_now = now.filter(|&x| x).count();
        let (mut flipped_after, mut wrong_after) = (0, 0);
        for (a, b, sign) in &edges {
            let area = signed_area2_2d(to, f32x2(*a), f32x2(*b)) * sign;
            flipped_after += (area < 0.0 && area.abs() * 0.5 > DEGENERATE_UV_AREA) as usize;
            wrong_after += (area * 0.5 <= DEGENERATE_UV_AREA) as usize;
        }
        let wrong_now = wrong.iter().filter(|&&w| w).count();
        (flipped_after < flipped_now && wrong_after <= wrong_now).then(|| Move {
            uv: i,
            to,
            fixed: flipped_now - flipped_after,
            distance: (to[0] as f64 - p0[0]).hypot(to[1] as f64 - p0[1]),
        })
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
}

impl Kernel {
    /// The kernel of the fan faces given by their opposite `edges`, around the vertex at `origin`,
    /// in units of `scale` (> 0).
    fn new(origin: [f64; 2], scale: f64, edges: &[Edge]) -> Self {
        let local = |p: [f64; 2], s: f64| [(p[0] - origin[0]) / s, (p[1] - origin[1]) / s];
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
        Kernel { origin, scale, planes }
    }

    fn margin(&self, p: [f64; 2]) -> f64 {
        self.planes.iter().map(|(n, d)| n[0] * p[0] + n[1] * p[1] - d).fold(f64::INFINITY, f64::min)
    }

    /// The point of the box `|p|∞ ≤ 1` (the fan's extent around the vertex) that maximises the
    /// smallest margin, and that margin: a linear programme in `(x, y, r)` solved by enumerating
    /// its vertices (every triple of active constraints). `None` for an empty fan.
    fn deepest_point(&self) -> Option<([f64; 2], f64)> {
        if self.planes.is_empty() {
            return None;
        }
        // Rows a·(x, y, r) ≤ b: fan planes −n·p + r ≤ −d, the box ±x ≤ 1, ±y ≤ 1, and r ≤ 2.
        let mut rows: Vec<([f64; 3], f64)> =
            self.planes.iter().map(|(n, d)| ([-n[0], -n[1], 1.0], -d)).collect();
        rows.extend([
            ([1.0, 0.0, 0.0], 1.0),
            ([-1.0, 0.0, 0.0], 1.0),
            ([0.0, 1.0, 0.0], 1.0),
            ([0.0, -1.0, 0.0], 1.0),
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

/// Ties between equally deep points go to the one nearer the vertex, then to the lower x, y, so the
/// choice does not depend on the order constraints were enumerated in.
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

fn f32x2(p: [f64; 2]) -> [f32; 2] {
    [p[0] as f32, p[1] as f32]
}

/// Twice the signed area of face `f` of `layer`.
fn face_area2(layer: &UvLayer, f: usize) -> f64 {
    let [a, b, c] = layer.triangles[f].map(|i| layer.coords[i as usize]);
    signed_area2_2d(a, b, c)
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

    fn flipped(layer: &mut UvLayer, charts: &[u32]) -> usize {
        State::new(layer, charts).flipped_faces().len()
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
            let r = untangle(&mut layer, &charts);
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
        // folded at vertex 12, which is on the border.
        let m = grid(4, |_| [0.0, 0.0]);
        let folded = dragged_plane([0.1, 0.1], false);
        let flat = plane(4, |p| p);
        let charts: Vec<u32> = (0..m.triangles.len())
            .map(|f| (m.corners(f).iter().map(|c| c[0]).sum::<f32>() > 0.0) as u32)
            .collect();
        let mut layer = UvLayer {
            coords: folded.coords.iter().chain(&flat.coords).copied().collect(),
            triangles: m.triangles.iter().zip(&charts).map(|(t, &c)| t.map(|v| v + 25 * c)).collect(),
        };
        let before = layer.clone();
        let r = untangle(&mut layer, &charts);
        assert!(r.flipped_before > 0, "{r:?}");
        assert_eq!(r.flipped_after, 0, "{r:?}");
        assert!(moved(&before, &layer).iter().all(|&i| i < 25), "chart 1's UVs moved");
    }

    #[test]
    fn a_map_without_flips_is_left_bit_for_bit() {
        let mut layer = plane(4, |[u, v]| [u * u, v]);
        let before = layer.clone();
        let r = untangle(&mut layer, &vec![0u32; before.triangles.len()]);
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
            let r = untangle(&mut layer, &charts);
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
        let k = Kernel::new([0.3, 0.2], fan_extent([0.3, 0.2], &edges), &edges);
        let (p, r) = k.deepest_point().unwrap();
        let uv = k.to_uv(p);
        assert!(uv[0].abs() < 1e-6 && uv[1].abs() < 1e-6, "{uv:?}");
        assert!((r * k.scale - 1.0).abs() < 1e-9, "margin {}", r * k.scale);
        // Already inside with margin 0.8: the first point with margin ≥ 0.5 is the vertex itself.
        assert_eq!(k.toward(p, 0.5 / k.scale), [0.0, 0.0]);
    }
}

//! Packing islands by their shapes: every island is rasterised into the texels it touches (its
//! *footprint*) and placed on a bitmap of the atlas where its footprint meets no texel within
//! `gutter` of another island's, so islands interlock (an L nests in another L's corner, a long
//! island lies along the diagonal) where their bounding rectangles could not. This is how xatlas
//! packs charts (`PackOptions::bruteForce`), with the search made fast by jumping over occupied
//! runs instead of testing every position.
//!
//! Definitions (exact):
//! - **Orientations**: with `rotate`, each island is tried turned by quarter turns after its own
//!   rotation (the parent module's), and by the odd multiples of 45° in between when that costs
//!   its texture axes (almost) no shear (`Island::diagonal`); without, as it is. Quarter turns are
//!   exact coordinate swaps and keep |cos(T, B)| of every face. Degenerate islands (one texel, the
//!   parent module's rule) take orientation 0.
//! - **Footprint** of an island in one orientation at `t` texels per input UV unit: its points are
//!   `q = t · R(p)` shifted so that their bounding box starts at texel corner `(0, 0)`; a texel
//!   `[x, x+1] × [y, y+1]` is in the footprint when a face of the island (its closed triangle)
//!   meets the open texel square, i.e. the triangle's cut with the closed row slab `[y, y+1]`
//!   spans beyond `x` and short of `x + 1`; a cut that is a single column or point takes the texel
//!   it lies in. So every texel any face covers any part of is in it (bilinear filtering reads
//!   those, and their neighbours, which the gutter covers). Stored per row as maximal runs.
//!   When no face of the island is wound backwards the same set is found from its boundary
//!   ([`Outline`]: the faces on the boundary, and the texels whose centre it winds round), so
//!   the inner faces, nearly all of a large island's, are never rasterised.
//! - **Occupancy**: a bitmap of the `side²` atlas. The texels in the border strips (`floor(gutter/2)`
//!   at the low side of each axis, `ceil(gutter/2)` at the high side) start occupied; placing an
//!   island marks its footprint dilated by `gutter` texels in both axes (a `(2·gutter+1)²` square
//!   round each texel). A footprint fits at `(x, y)` when none of its texels is occupied. Hence
//!   between the texels of two islands there are at least `gutter` free texels in `x` or in `y`
//!   (Chebyshev distance `> gutter`), and each island keeps the border strips free.
//! - **Placement**: islands in the given order; each goes, over its orientations, to the
//!   position that a placement [`Rule`] ranks first (ties: then the first orientation). The
//!   candidates of one orientation are, per row `y`, the least `x` at which it fits (a rule's
//!   key never prefers a larger `x` in the same row). A failed test at a run of a footprint row
//!   jumps `x` past the occupied run that blocked it, so a row costs one test per occupied run
//!   it crosses, not one per texel; rows and columns whose key cannot beat the best found so far
//!   are not searched.
//! - **Rules** (the parent module tries them in this order and keeps the first that fits every
//!   island): [`Rule::LowestTop`], the lowest top edge `y + h`, then the least `x`
//!   (bottom-left, as before rules were added); [`Rule::Corner`], the least `x + w + y + h` (the
//!   far corner nearest the atlas origin), then the least `y`, then `x`; [`Rule::Square`], the
//!   least `max(x + w, y + h)` (the used square grows least), then `y + h`, then `x`. Each is a
//!   greedy heuristic whose success at a given scale depends on the islands' shapes in ways no
//!   one rule wins: measured on the Common Shapes atlases (BENCHMARKS.md, "Three placement
//!   rules"), each packs some meshes 0.05–0.10 tighter than the others.
//!
//! Deterministic: orientations are searched in parallel (rayon) but chosen by the fixed order
//! above, islands are placed sequentially; the place search looks at two places at once but
//! keeps what the search one place after the other finds ([`pack_shapes_searched`]).

use foldhash::{HashMap, HashMapExt};

use std::sync::Mutex;
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};

use rayon::prelude::*;

use super::{Island, rotated};
use crate::refine::area2;

/// One island's footprint in one orientation at one scale.
#[derive(Clone, Debug)]
pub(super) struct Footprint {
    /// Width and height in texels (at least 1 each).
    pub w: u32,
    pub h: u32,
    /// Per row (bottom to top), the inclusive column ranges `(a, b)` of its texels, in order.
    pub rows: Vec<Vec<(u32, u32)>>,
    /// Added to `t · R(p)` to give the point's texel coordinates in the footprint.
    pub shift: [f64; 2],
    /// The rotation `R` applied after the island's own rotation, as `(cos, sin)`.
    pub turn: [f64; 2],
}

/// Where [`pack_shapes`] put an island: its footprint's lower-left texel and its orientation.
#[derive(Clone, Debug)]
pub(super) struct ShapePlaced {
    pub x: u32,
    pub y: u32,
    pub footprint: Footprint,
}

impl ShapePlaced {
    /// The atlas UV (in `[0,1]²`) of the input UV `p` of `island`, at `t` texels per input unit.
    pub fn place(&self, island: &Island, p: [f32; 2], t: f64, side: u32) -> [f32; 2] {
        let q = rotated(rotated(p.map(|x| x as f64), island.rot), self.footprint.turn);
        let s = side as f64;
        let at = [self.x as f64, self.y as f64];
        [0, 1].map(|k| ((at[k] + t * q[k] + self.footprint.shift[k]) / s).clamp(0.0, 1.0) as f32)
    }
}

/// `(cos, sin)` of `k · 45°`, exact at multiples of 90°.
pub(super) fn turn(k: u32) -> [f64; 2] {
    let h = std::f64::consts::FRAC_1_SQRT_2;
    [[1.0, 0.0], [h, h], [0.0, 1.0], [-h, h], [-1.0, 0.0], [-h, -h], [0.0, -1.0], [h, -h]][(k % 8) as usize]
}

/// The orientations tried for `island` (module docs), as multiples of 45°.
fn orientations(island: &Island, rotate: bool) -> Vec<u32> {
    match (rotate && !island.degenerate, island.diagonal) {
        (false, _) => vec![0],
        (true, false) => vec![0, 2, 4, 6],
        (true, true) => (0..8).collect(),
    }
}

/// The faces and boundary of an island that decide its footprint: when no face is wound
/// backwards, a texel that a face meets either has its centre inside the island (where the
/// boundary's winding number, the number of faces over the point, is not 0) or is crossed by
/// the boundary and so met by a face with a boundary edge (the texel is convex: a segment from
/// a covered point to an uncovered centre crosses the boundary inside it). So the footprint is
/// the texels those faces meet plus the texels whose centre the boundary winds round, without
/// rasterising the inner faces (on a 70k-face island, 1–2% of its faces hold a boundary edge).
#[derive(Clone, Debug)]
pub(super) struct Outline {
    /// The faces with an edge on the boundary, in face order.
    faces: Vec<u32>,
    /// The boundary: the faces' directed edges that no other face's edge cancels, each with its
    /// multiplicity's sign folded into its direction (one entry per unit of multiplicity).
    edges: Vec<[u32; 2]>,
}

impl Outline {
    /// The outline of the faces `tris` over `points`; `None` when a face has negative signed
    /// area (then the winding number no longer counts the faces over a point).
    pub(super) fn of(points: &[[f64; 2]], tris: &[[u32; 3]]) -> Option<Outline> {
        if tris.iter().any(|t| area2(t.map(|i| points[i as usize])) < 0.0) {
            return None;
        }
        // Net count of each undirected edge, positive in the direction from the lower index.
        // A fast hasher: the map is only looked up, `order` keeps the edges' order.
        let mut net: HashMap<(u32, u32), i64> = HashMap::with_capacity(3 * tris.len() / 2 + 3);
        let mut order: Vec<(u32, u32)> = Vec::new();
        for t in tris {
            for k in 0..3 {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                let key = (a.min(b), a.max(b));
                let e = net.entry(key).or_insert_with(|| {
                    order.push(key);
                    0
                });
                *e += if a < b { 1 } else { -1 };
            }
        }
        let mut edges = Vec::new();
        for key in &order {
            let n = net[key];
            let e = if n > 0 { [key.0, key.1] } else { [key.1, key.0] };
            edges.extend(std::iter::repeat_n(e, n.unsigned_abs() as usize));
        }
        let faces = tris
            .iter()
            .enumerate()
            .filter(|(_, t)| {
                (0..3).any(|k| {
                    let (a, b) = (t[k], t[(k + 1) % 3]);
                    net[&(a.min(b), a.max(b))] != 0
                })
            })
            .map(|(f, _)| f as u32)
            .collect();
        Some(Outline { faces, edges })
    }
}

/// The footprint of `island` turned by `k · 45°` at `t` texels per input unit (module docs).
pub(super) fn footprint(island: &Island, k: u32, t: f64) -> Footprint {
    let r = turn(k);
    let q: Vec<[f64; 2]> =
        island.points.iter().map(|&p| rotated(p, r)).map(|p| [p[0] * t, p[1] * t]).collect();
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for p in &q {
        for k in 0..2 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    if q.is_empty() {
        (lo, hi) = ([0.0; 2], [0.0; 2]);
    }
    let shift = [-lo[0], -lo[1]];
    let size = [hi[0] - lo[0], hi[1] - lo[1]];
    let cells = size.map(|s| (s.ceil() as u32).max(1));
    let (w, h) = (cells[0], cells[1]);
    let words = (w as usize).div_ceil(64);
    let mut mask = vec![0u64; words * h as usize];
    let local = |p: [f64; 2]| [p[0] + shift[0], p[1] + shift[1]];
    let mut mark = |row: u32, a: u32, b: u32| {
        let base = row as usize * words;
        for x in a..=b {
            mask[base + x as usize / 64] |= 1 << (x % 64);
        }
    };
    let all: Vec<u32>;
    let faces: &[u32] = match &island.outline {
        Some(o) => &o.faces,
        None => {
            all = (0..island.tris.len() as u32).collect();
            &all
        }
    };
    // Every island has a face (islands are sets of faces), so its footprint has a texel.
    for tri in faces.iter().map(|&f| island.tris[f as usize].map(|i| local(q[i as usize]))) {
        let ys = tri.map(|p| p[1]);
        let (y0, y1) = (
            ys.iter().copied().fold(f64::INFINITY, f64::min),
            ys.iter().copied().fold(f64::NEG_INFINITY, f64::max),
        );
        let first = (y0.floor().max(0.0) as u32).min(h - 1);
        let last = ((y1.ceil() as u32).saturating_sub(1)).max(first).min(h - 1);
        for row in first..=last {
            let Some((x0, x1)) = slab_span(&tri, row as f64, row as f64 + 1.0) else { continue };
            let a = (x0.floor().max(0.0) as u32).min(w - 1);
            let b = ((x1.ceil() as u32).saturating_sub(1)).max(a).min(w - 1);
            mark(row, a, b);
        }
    }
    if let Some(o) = &island.outline {
        // The texels whose centre the boundary winds round, row by row: the boundary's crossings
        // of the row's centre line `y + ½` (an edge crosses it when one end is at or below and
        // the other above), sorted, with the winding number between them.
        let mut crossings: Vec<Vec<(f64, i32)>> = vec![Vec::new(); h as usize];
        for e in &o.edges {
            let [a, b] = e.map(|i| local(q[i as usize]));
            if a[1] == b[1] {
                continue;
            }
            let (lo, hi, dir) = if a[1] < b[1] { (a, b, 1) } else { (b, a, -1) };
            // Rows whose centre line `r + ½` lies in `[lo.y, hi.y)`.
            let first = (lo[1] - 0.5).ceil().max(0.0) as u32;
            let end = ((hi[1] - 0.5).ceil().max(0.0) as u32).min(h);
            for row in first..end {
                let y = row as f64 + 0.5;
                let x = lo[0] + (hi[0] - lo[0]) * (y - lo[1]) / (hi[1] - lo[1]);
                crossings[row as usize].push((x, dir));
            }
        }
        for (row, c) in crossings.iter_mut().enumerate() {
            c.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
            let mut winding = 0;
            for pair in c.windows(2) {
                winding += pair[0].1;
                if winding == 0 {
                    continue;
                }
                // Columns whose centre `x + ½` lies strictly between the two crossings.
                let a = (pair[0].0 - 0.5).floor() + 1.0;
                let b = (pair[1].0 - 0.5).ceil() - 1.0;
                if a <= b && b >= 0.0 && a < w as f64 {
                    mark(row as u32, a.max(0.0) as u32, (b as u32).min(w - 1));
                }
            }
        }
    }
    let rows = (0..h as usize).map(|r| runs(&mask[r * words..(r + 1) * words], w)).collect();
    Footprint { w, h, rows, shift, turn: r }
}

/// The `x` extent of the closed triangle `tri` cut by the closed slab `y0 ≤ y ≤ y1`, `None` when
/// they do not meet.
fn slab_span(tri: &[[f64; 2]; 3], y0: f64, y1: f64) -> Option<(f64, f64)> {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    let mut take = |x: f64| {
        lo = lo.min(x);
        hi = hi.max(x);
    };
    for k in 0..3 {
        let (p, q) = (tri[k], tri[(k + 1) % 3]);
        if (y0..=y1).contains(&p[1]) {
            take(p[0]);
        }
        // Where the edge crosses either slab line strictly between its ends.
        for y in [y0, y1] {
            if (p[1] - y) * (q[1] - y) < 0.0 {
                take(p[0] + (q[0] - p[0]) * (y - p[1]) / (q[1] - p[1]));
            }
        }
    }
    (lo <= hi).then_some((lo, hi))
}

/// Maximal runs of set bits among the first `w` of `row`, as inclusive `(a, b)`.
fn runs(row: &[u64], w: u32) -> Vec<(u32, u32)> {
    let mut out = Vec::new();
    let mut x = 0;
    while x < w {
        let a = next(row, x, w, true);
        if a >= w {
            break;
        }
        let b = next(row, a, w, false);
        out.push((a, b - 1));
        x = b;
    }
    out
}

/// The first `x' ≥ x` (below `w`) whose bit is `set`, or `w`. Reads no word past the one holding
/// bit `w - 1`, so a test of a short span costs a word or two, not the rest of the row.
fn next(row: &[u64], x: u32, w: u32, set: bool) -> u32 {
    let mut i = x as usize / 64;
    let end = row.len().min((w as usize).div_ceil(64));
    if i >= end {
        return w;
    }
    let mut word = if set { row[i] } else { !row[i] } & (!0u64 << (x % 64));
    loop {
        if word != 0 {
            return (i as u32 * 64 + word.trailing_zeros()).min(w);
        }
        i += 1;
        if i >= end {
            return w;
        }
        word = if set { row[i] } else { !row[i] };
    }
}

/// The first set bit of `row` among `a..=b` (`a ≤ b` inside the row), if any: [`next`]'s
/// answer to the collision test, computed as the OR of the span's words first, without a
/// branch between them (vectorised), and searched word by word only when that is not zero.
/// Why: most spans a search tests are free, and a footprint's row of a large island spans
/// several words; the word-by-word loop was the hottest part of [`Occupancy::best_fit`].
fn first_occupied(row: &[u64], a: u32, b: u32) -> Option<u32> {
    let (i, j) = (a as usize / 64, b as usize / 64);
    let low = !0u64 << (a % 64);
    let high = !0u64 >> (63 - b % 64);
    if i == j {
        let word = row[i] & low & high;
        return (word != 0).then(|| i as u32 * 64 + word.trailing_zeros());
    }
    let inner = &row[i + 1..j];
    let any = (row[i] & low) | inner.iter().fold(0, |acc, &w| acc | w) | (row[j] & high);
    if any == 0 {
        return None;
    }
    let first = (row[i] & low != 0).then_some((i, row[i] & low));
    let (k, word) = first
        .or_else(|| inner.iter().position(|&w| w != 0).map(|k| (i + 1 + k, inner[k])))
        .unwrap_or((j, row[j] & high));
    Some(k as u32 * 64 + word.trailing_zeros())
}

/// The first footprint row `r` whose `need[r]` texels exceed the longest free run `free[r]` of
/// the atlas row under it, if any. Compared in chunks without a branch inside one, so that the
/// compiler vectorises it: a footprint of a few hundred rows is checked at every candidate row of
/// the atlas, and this check was a third of [`Occupancy::best_fit`]'s time as a short-circuiting
/// scan.
fn first_short(free: &[u32], need: &[u32]) -> Option<usize> {
    const CHUNK: usize = 16;
    let chunks = free.chunks(CHUNK).zip(need.chunks(CHUNK));
    for (c, (f, n)) in chunks.enumerate() {
        if f.iter().zip(n).fold(false, |any, (f, n)| any | (f < n)) {
            return f.iter().zip(n).position(|(f, n)| f < n).map(|r| c * CHUNK + r);
        }
    }
    None
}

/// How [`pack_shapes`] ranks the positions where an island fits (module docs).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Rule {
    /// The lowest top edge, then the least `x`.
    LowestTop,
    /// The least `x + w + y + h`, then `y`, then `x`.
    Corner,
    /// The least `max(x + w, y + h)`, then `y + h`, then `x`.
    Square,
}

/// A position's rank under a rule: smaller first.
type Key = (u32, u32, u32);

impl Rule {
    fn key(self, fp: &Footprint, x: u32, y: u32) -> Key {
        let (right, top) = (x + fp.w, y + fp.h);
        match self {
            Rule::LowestTop => (top, x, 0),
            Rule::Corner => (right + top, y, x),
            Rule::Square => (right.max(top), top, x),
        }
    }
}

/// The atlas bitmap: one bit per texel, set where the texel is occupied (module docs).
#[derive(Clone)]
struct Occupancy {
    side: u32,
    words: usize,
    bits: Vec<u64>,
    /// Per row, its longest run of free texels: a row too short for a footprint row is skipped
    /// without a test.
    longest_free: Vec<u32>,
}

impl Occupancy {
    fn new(side: u32, gutter: u32) -> Self {
        let words = (side as usize).div_ceil(64);
        let mut o = Self {
            side,
            words,
            bits: vec![0; words * side as usize],
            longest_free: vec![side; side as usize],
        };
        let (low, high) = (gutter / 2, gutter - gutter / 2);
        for y in 0..side {
            if y < low || y >= side.saturating_sub(high) {
                o.fill(y, 0, side - 1);
            } else {
                if low > 0 {
                    o.fill(y, 0, low - 1);
                }
                if high > 0 {
                    o.fill(y, side - high, side - 1);
                }
            }
            o.longest_free[y as usize] = o.measure_longest_free(y);
        }
        o
    }

    fn measure_longest_free(&self, y: u32) -> u32 {
        let row = self.row(y);
        let (mut x, mut longest) = (0, 0);
        while x < self.side {
            let a = next(row, x, self.side, false);
            if a >= self.side {
                break;
            }
            let b = next(row, a, self.side, true);
            longest = longest.max(b - a);
            x = b;
        }
        longest
    }

    fn row(&self, y: u32) -> &[u64] {
        &self.bits[y as usize * self.words..(y as usize + 1) * self.words]
    }

    /// Marks texels `a..=b` of row `y`.
    fn fill(&mut self, y: u32, a: u32, b: u32) {
        let row = &mut self.bits[y as usize * self.words..(y as usize + 1) * self.words];
        let (wa, wb) = (a as usize / 64, b as usize / 64);
        for (i, word) in row.iter_mut().enumerate().take(wb + 1).skip(wa) {
            let lo = if i == wa { a % 64 } else { 0 };
            let hi = if i == wb { b % 64 } else { 63 };
            let span = hi - lo + 1;
            *word |= if span == 64 { !0 } else { ((1u64 << span) - 1) << lo };
        }
    }

    /// The position `(x, y)` where `fp` fits that `rule` ranks first, with its key (module docs).
    #[cfg(test)]
    fn best_fit(&self, fp: &Footprint, rule: Rule) -> Option<(Key, u32, u32)> {
        self.best_fit_among(fp, rule, &Rivals::new(1, 1), 0)
    }

    /// [`Occupancy::best_fit`] of `fp`, orientation `turn` of an island whose orientations are
    /// searched together: it offers `rivals` each fit it finds and stops where every position
    /// it has left ranks after the `width` places they hold, so what it returns is its best fit
    /// or ranks after those places too ([`Rivals`]).
    fn best_fit_among(
        &self,
        fp: &Footprint,
        rule: Rule,
        rivals: &Rivals,
        turn: usize,
    ) -> Option<(Key, u32, u32)> {
        if fp.w > self.side || fp.h > self.side {
            return None;
        }
        let need: Vec<u32> =
            fp.rows.iter().map(|r| r.iter().map(|&(a, b)| b - a + 1).max().unwrap_or(0)).collect();
        let mut best: Option<(Key, u32, u32)> = None;
        // No position at (x', y') with x' ≥ x, y' ≥ y ranks before `best` once (x, y) does not:
        // every rule's key (compared whole) never falls as `x` or `y` grows. So a row's scan
        // stops at a position that could only tie or lose, before testing whether it fits: a
        // corner or square rule kept verifying whole footprints at positions whose first key
        // component only tied the best's (counted on the README bunny's bake when only the
        // first component was compared: 42% of the fits verified, a fifth of all row tests).
        let beaten = |best: &Option<(Key, u32, u32)>, x: u32, y: u32| {
            let key = rule.key(fp, x, y);
            best.is_some_and(|(k, ..)| key >= k) || rivals.outrank(key, turn)
        };
        let h = fp.h as usize;
        // The footprint rows in the order they are tested, the last that blocked a position
        // first (move to front): which row blocks decides how far `x` jumps, and the rows that
        // blocked before hold the obstacles that block again. Any order finds the same fit (a
        // jump skips only positions that collide); this one cut the horse's tested positions
        // ninefold and its row tests by half against trying the last blocking row first and
        // the others in footprint order.
        let mut rows: Vec<u32> = (0..fp.h).collect();
        let mut short_last = 0usize; // the footprint row found too short last: tried first
        for y in 0..=self.side - fp.h {
            if beaten(&best, 0, y) {
                break;
            }
            let free = &self.longest_free[y as usize..y as usize + h];
            let last = rows[0] as usize;
            if free[last] < need[last] || free[short_last] < need[short_last] {
                continue;
            }
            if let Some(r) = first_short(free, &need) {
                short_last = r;
                continue;
            }
            let mut x = 0u32;
            'scan: while x + fp.w <= self.side && !beaten(&best, x, y) {
                for p in 0..h {
                    let r = rows[p] as usize;
                    let row = self.row(y + r as u32);
                    for &(a, b) in &fp.rows[r] {
                        if let Some(s) = first_occupied(row, x + a, x + b) {
                            // Every x' with x' + a in the occupied run from `s` collides too.
                            x = next(row, s, self.side, false) - a;
                            rows[..=p].rotate_right(1);
                            continue 'scan;
                        }
                    }
                }
                let key = rule.key(fp, x, y);
                if best.is_none_or(|(k, ..)| key < k) {
                    best = Some((key, x, y));
                    rivals.offer(key, turn);
                }
                break;
            }
        }
        best
    }

    /// Marks `fp` placed at `(x, y)`, dilated by `gutter`.
    fn occupy(&mut self, fp: &Footprint, x: u32, y: u32, gutter: u32) {
        let last = self.side - 1;
        for (r, runs) in fp.rows.iter().enumerate() {
            let yy = y + r as u32;
            for &(a, b) in runs {
                let (a, b) = ((x + a).saturating_sub(gutter), (x + b + gutter).min(last));
                for row in yy.saturating_sub(gutter)..=(yy + gutter).min(last) {
                    self.fill(row, a, b);
                }
            }
        }
        let rows = y.saturating_sub(gutter)..=(y + fp.h - 1 + gutter).min(last);
        for row in rows {
            self.longest_free[row as usize] = self.measure_longest_free(row);
        }
    }
}

/// The best places found so far of an island's orientations searched in parallel
/// ([`Search::places`], which keeps the first `width` of them by key, then orientation), so
/// that one orientation's search stops where every position it has left ranks below `width`
/// other orientations' fits. Why: each orientation's [`Occupancy::best_fit_among`] otherwise
/// scanned the atlas until its own first fit, though another orientation had already fitted
/// lower down (4 or 8 orientations an island). Counted on the README bunny's bake, the
/// sharing cut `best_fit`'s row tests by a quarter (10,134 → 7,505 a call) and the 14 Common
/// Shapes re-bakes' packing phases by 7–9% (BENCHMARKS.md).
///
/// The places kept are the same: an orientation among the first `width` has, at every moment
/// of its search, at most `width − 1` others with a better fit found (each orientation's best
/// so far only falls towards its final one), so the cut, the `width`-th best of the
/// orientations' bests so far, never ranks before its fit and none of the positions up to it
/// is skipped. Which orientation stops where depends on the threads' timing; what is kept does
/// not.
///
/// A place is `(key, orientation)` packed into one `u64` in rank order (16 bits each), so the
/// cut is one atomic read in the scan's loop; a key component of 2¹⁶ or more (an atlas side
/// beyond 32767 texels, larger than `output.atlas_resolution` allows) turns the sharing off.
struct Rivals {
    width: usize,
    /// Per orientation, its best fit so far packed ([`Rivals::pack`]), `u64::MAX` before one.
    bests: Mutex<Vec<u64>>,
    /// The `width`-th least of `bests`.
    cut: AtomicU64,
}

impl Rivals {
    fn new(width: usize, orientations: usize) -> Rivals {
        Rivals { width, bests: Mutex::new(vec![u64::MAX; orientations]), cut: AtomicU64::new(u64::MAX) }
    }

    /// `(key, turn)` as one number in rank order; `None` when a part needs more than 16 bits.
    fn pack(key: Key, turn: usize) -> Option<u64> {
        let parts = [key.0 as u64, key.1 as u64, key.2 as u64, turn as u64];
        parts.iter().all(|&p| p < 1 << 16).then(|| parts.iter().fold(0, |acc, &p| acc << 16 | p))
    }

    /// Whether `width` other orientations have fits ranking before a place of orientation
    /// `turn` with `key`.
    fn outrank(&self, key: Key, turn: usize) -> bool {
        Rivals::pack(key, turn).is_some_and(|p| p > self.cut.load(Ordering::Relaxed))
    }

    /// Records that orientation `turn` fits with `key`.
    fn offer(&self, key: Key, turn: usize) {
        let Some(p) = Rivals::pack(key, turn) else { return };
        let mut bests = self.bests.lock().unwrap_or_else(|e| e.into_inner());
        bests[turn] = bests[turn].min(p);
        if (1..=bests.len()).contains(&self.width) {
            let mut sorted = bests.clone();
            let (_, &mut cut, _) = sorted.select_nth_unstable(self.width - 1);
            self.cut.store(cut, Ordering::Relaxed);
        }
    }
}

/// The footprints of every island in each of its orientations at `texels_per_unit(island)`
/// texels per input unit (the parent's density rule at one atlas scale), islands in parallel.
pub(super) fn footprints(
    islands: &[Island],
    texels_per_unit: impl Fn(&Island) -> f64 + Sync,
    rotate: bool,
) -> Vec<Vec<Footprint>> {
    islands
        .par_iter()
        .map(|island| {
            let t = texels_per_unit(island);
            orientations(island, rotate).into_iter().map(|k| footprint(island, k, t)).collect()
        })
        .collect()
}

/// Packs the islands whose [`footprints`] are given, in `order`, into a `side²` atlas (module
/// docs); `None` when one does not fit.
pub(super) fn pack_shapes(
    footprints: &[Vec<Footprint>],
    order: &[usize],
    side: u32,
    gutter: u32,
    rule: Rule,
) -> Option<Vec<ShapePlaced>> {
    // The search's first path without a departure is the greedy placement itself.
    let mut unlimited = usize::MAX;
    pack_shapes_searched(footprints, order, side, gutter, rule, GREEDY, &mut unlimited)
}

/// [`pack_shapes`] with a limited discrepancy search (Harvey & Ginsberg, "Limited Discrepancy
/// Search", 1995) over the places of the first [`SearchLimits::depth`] islands of `order`: each
/// of them may go, instead of where `rule` ranks first over all its orientations, to where
/// `rule` ranks first in another orientation (the next [`SearchLimits::width`] − 1 of them by
/// `rule`'s key), at most [`SearchLimits::discrepancies`] times along a path; the islands after
/// them are placed as [`pack_shapes`] places them. Paths are tried depth first, the rule's own
/// choice before the others, so the first is [`pack_shapes`]' packing. Returns the first packing
/// that fits every island, or `None` when none does before `budget` (counted in footprint
/// placements searched, `Occupancy::best_fit` calls, and decremented by those made) runs out.
/// Why: at the largest scale the packer reaches, the island that does not fit is one of the
/// first, large ones (on the Common Shapes atlases the third to seventh of 17–23), so the
/// arrangement of the large islands, which the greedy fixes one at a time, limits the packing.
///
/// With [`SearchLimits::speculate`] two places of a searched island are searched at once
/// (`rayon::join`), each from the budget left before them; the second's outcome is then taken
/// as the sequential search's only when the first found nothing and the second used at most
/// what the first left (a search with a larger budget makes the same calls up to the point
/// where the smaller one runs out), else the budget is spent. So the result and the budget
/// left are those of searching the places one after the other, at any thread count; the second
/// core, which each place's own parallel search (4–8 orientations) kept only partly busy, now
/// searches ahead. Measured on the README bunny's bake (2 Zen 5 cores): the pack phase 1.0–1.1
/// → 0.9 s, the teapot's 2.1–2.3 → 1.8–1.9 s, the same atlases.
pub(super) fn pack_shapes_searched(
    footprints: &[Vec<Footprint>],
    order: &[usize],
    side: u32,
    gutter: u32,
    rule: Rule,
    limits: SearchLimits,
    budget: &mut usize,
) -> Option<Vec<ShapePlaced>> {
    let search = Search { footprints, order, gutter, rule, limits, memo: None };
    if limits.deepen { search.deepen(side, &Memo::default(), budget) } else { search.run(side, budget) }
}

/// [`pack_shapes`]' packing of one order by one rule at one scale (the footprints it owns),
/// kept island by island, so that [`GreedyHead::pack`] packs an order that shares its first
/// islands from where they were placed. Why: the order search tries orders that differ from the
/// current one by a swap of two islands (the parent module's `search_orders`); the islands
/// before the swap are placed as in the current order, and when the current order's packing
/// fails at an island before the swap, the other order fails there too, without a placement
/// searched. The occupancy before the swap is rebuilt from the kept places (a fill per island,
/// far cheaper than searching its place) rather than kept per island: one is `side²` bits, 32
/// MB at the largest atlas a config allows, and an order has up to `SEARCH_UP_TO` islands.
pub(super) struct GreedyHead {
    footprints: Vec<Vec<Footprint>>,
    side: u32,
    gutter: u32,
    order: Vec<usize>,
    rule: Rule,
    /// The islands the kept order's packing placed, in order: all of them, or those before the
    /// first that fits nowhere.
    steps: Vec<Step>,
}

impl GreedyHead {
    /// [`pack_shapes`]' packing of `order` by `rule`, kept (type docs).
    pub(super) fn new(
        footprints: Vec<Vec<Footprint>>,
        order: &[usize],
        side: u32,
        gutter: u32,
        rule: Rule,
    ) -> Self {
        let mut head = GreedyHead { footprints, side, gutter, order: order.to_vec(), rule, steps: vec![] };
        let mut steps = Vec::new();
        // Without a budget only an island that fits nowhere stops it: `steps` are those before.
        let _ =
            head.search(order, rule)
                .place_greedily(&mut Occupancy::new(side, gutter), 0, &mut steps, &mut { usize::MAX });
        head.steps = steps;
        head
    }

    /// [`pack_shapes`] of `order` by `rule` with the head's footprints, side and gutter, bit for
    /// bit; when `rule` is the kept rule, only the islands after those `order` shares with the
    /// kept order are placed.
    pub(super) fn pack(&self, order: &[usize], rule: Rule) -> Option<Vec<ShapePlaced>> {
        if rule != self.rule {
            return pack_shapes(&self.footprints, order, self.side, self.gutter, rule);
        }
        let shared = order.iter().zip(&self.order).take_while(|(a, b)| a == b).count();
        if shared > self.steps.len() {
            // The island the kept order's packing could not place comes at the same place, on
            // the same occupancy.
            return None;
        }
        let path = self.steps[..shared].to_vec();
        let mut occ = Occupancy::new(self.side, self.gutter);
        for s in &path {
            occ.occupy(&self.footprints[s.island][s.turn], s.x, s.y, self.gutter);
        }
        let search = self.search(order, rule);
        let found = search.rest(occ, shared, path, &mut { usize::MAX })?;
        search.placed(found)
    }

    fn search<'a>(&'a self, order: &'a [usize], rule: Rule) -> Search<'a> {
        Search { footprints: &self.footprints, order, gutter: self.gutter, rule, limits: GREEDY, memo: None }
    }
}

/// The search without departures: [`pack_shapes`]' greedy placement.
const GREEDY: SearchLimits =
    SearchLimits { depth: 0, width: 1, discrepancies: 0, speculate: false, deepen: false };

/// How far [`pack_shapes_searched`] looks (its docs).
#[derive(Clone, Copy, Debug)]
pub(super) struct SearchLimits {
    /// Islands at the head of the order whose places are searched.
    pub depth: usize,
    /// Places considered per searched island, the rule's own choice included.
    pub width: usize,
    /// Places other than the rule's own choice along one path.
    pub discrepancies: usize,
    /// Whether two places of a searched island are searched at once (the result and the budget
    /// left are the same either way; tests compare the two).
    pub speculate: bool,
    /// Whether the search runs as the iterations of limited discrepancy search: one departure
    /// allowed, then two, up to `discrepancies`, until one finds a packing, sharing one budget.
    /// Each iteration walks again the paths of the one before (a path with fewer departures is
    /// also a path with at most more), in the same order; so what those paths found is kept
    /// ([`Memo`]) and replayed, each call it made paid again from the budget without being
    /// made. So the packing and the budget left are those of one search per iteration, and only
    /// the calls are fewer. Measured on the README bunny's bake (BENCHMARKS.md, "The packing
    /// searches remember what they walked").
    pub deepen: bool,
}

/// One island placed on a search path: its index, orientation (index into its footprints),
/// position, and the rank of that place among the island's places on the path's occupancy (0:
/// the rule's own choice).
#[derive(Clone, Copy, Debug)]
struct Step {
    island: usize,
    turn: usize,
    x: u32,
    y: u32,
    rank: usize,
}

/// What a deepening search ([`SearchLimits::deepen`]) has learnt of its tree, by path (the
/// ranks of the searched islands' places, which fix the occupancy): a searched node's places,
/// and the leaves whose remaining islands did not all fit. Facts of the geometry, the same
/// whichever thread or iteration found them; what a search ended by its budget did not finish
/// is not kept.
#[derive(Default)]
struct Memo {
    known: Mutex<HashMap<Vec<usize>, Known>>,
    /// Calls paid again from the budget without being made (the tests' check that the memo
    /// serves).
    replayed: AtomicUsize,
}

/// One path's entry in the [`Memo`].
#[derive(Clone)]
enum Known {
    /// A searched island's first [`SearchLimits::width`] places (`Search::places`).
    Places(Vec<(usize, u32, u32)>),
    /// A leaf whose remaining islands failed: the number of them searched, the last one the
    /// island that fits nowhere.
    Fails(usize),
}

impl Memo {
    fn get(&self, path: &[Step]) -> Option<Known> {
        self.known.lock().unwrap_or_else(|e| e.into_inner()).get(&ranks(path)).cloned()
    }

    fn put(&self, path: &[Step], known: Known) {
        self.known.lock().unwrap_or_else(|e| e.into_inner()).insert(ranks(path), known);
    }

    /// [`pay`] for `calls` the memo spares; whether the search may go on.
    fn pay_again(&self, budget: &mut usize, calls: usize) -> bool {
        self.replayed.fetch_add(calls.min(*budget), Ordering::Relaxed);
        pay(budget, calls)
    }
}

/// A path's key in the [`Memo`].
fn ranks(path: &[Step]) -> Vec<usize> {
    path.iter().map(|s| s.rank).collect()
}

/// One [`pack_shapes_searched`] call's inputs.
struct Search<'a> {
    footprints: &'a [Vec<Footprint>],
    order: &'a [usize],
    gutter: u32,
    rule: Rule,
    limits: SearchLimits,
    /// Where the paths of earlier iterations are remembered ([`SearchLimits::deepen`]).
    memo: Option<&'a Memo>,
}

impl<'a> Search<'a> {
    /// The iterations `1..=limits.discrepancies` with `memo` ([`SearchLimits::deepen`]).
    fn deepen(self, side: u32, memo: &'a Memo, budget: &mut usize) -> Option<Vec<ShapePlaced>> {
        (1..=self.limits.discrepancies).find_map(|discrepancies| {
            let limits = SearchLimits { discrepancies, ..self.limits };
            Search { limits, memo: Some(memo), ..self }.run(side, budget)
        })
    }

    /// The packing of every island, from an empty `side²` atlas.
    fn run(&self, side: u32, budget: &mut usize) -> Option<Vec<ShapePlaced>> {
        let found =
            self.from(Occupancy::new(side, self.gutter), 0, self.limits.discrepancies, &[], budget)?;
        self.placed(found)
    }

    /// The packing of a path that placed every island, by island.
    fn placed(&self, path: Vec<Step>) -> Option<Vec<ShapePlaced>> {
        let mut out: Vec<Option<ShapePlaced>> = vec![None; self.footprints.len()];
        for Step { island, turn, x, y, .. } in path {
            out[island] = Some(ShapePlaced { x, y, footprint: self.footprints[island][turn].clone() });
        }
        out.into_iter().collect()
    }

    /// Places `order[d..]` on `occ` after the islands of `path`, with at most `discrepancies`
    /// more departures from the rule's choice; the whole path when every island fits.
    fn from(
        &self,
        occ: Occupancy,
        d: usize,
        discrepancies: usize,
        path: &[Step],
        budget: &mut usize,
    ) -> Option<Vec<Step>> {
        if d >= self.limits.depth.min(self.order.len()) {
            return self.rest(occ, d, path.to_vec(), budget);
        }
        let island = self.order[d];
        let width = if discrepancies == 0 { 1 } else { self.limits.width };
        let places = self.places_on_path(&occ, island, width, path, budget);
        let child = |rank: usize, budget: &mut usize| {
            let (turn, x, y) = places[rank];
            let mut next = occ.clone();
            next.occupy(&self.footprints[island][turn], x, y, self.gutter);
            let mut path = path.to_vec();
            path.push(Step { island, turn, x, y, rank });
            self.from(next, d + 1, discrepancies - usize::from(rank > 0), &path, budget)
        };
        let mut rank = 0;
        while rank < places.len() {
            if !self.limits.speculate || rank + 1 == places.len() {
                if let Some(found) = child(rank, budget) {
                    return Some(found);
                }
                rank += 1;
                continue;
            }
            // Two places at once, the second speculatively from the same budget; what the
            // second found then counts only if the sequential search would have found it, with
            // the budget the first left ([`pack_shapes_searched`]' docs).
            let start = *budget;
            let (mut first, mut second) = (start, start);
            let (a, b) = rayon::join(|| child(rank, &mut first), || child(rank + 1, &mut second));
            if a.is_some() {
                *budget = first;
                return a;
            }
            let used = start - second;
            if first == 0 || used > first {
                *budget = 0;
                return None;
            }
            *budget = first - used;
            if b.is_some() {
                return b;
            }
            rank += 2;
        }
        None
    }

    /// Island `island`'s first `width` places on `occ`: in each orientation the place `rule`
    /// ranks first, by that key then orientation (so the first is [`pack_shapes`]' choice).
    /// None when the budget cannot pay for the search.
    fn places(
        &self,
        occ: &Occupancy,
        island: usize,
        width: usize,
        budget: &mut usize,
    ) -> Option<Vec<(usize, u32, u32)>> {
        let fps = &self.footprints[island];
        if !pay(budget, fps.len()) {
            return None;
        }
        let rivals = Rivals::new(width, fps.len());
        let mut found: Vec<(Key, usize, u32, u32)> = fps
            .par_iter()
            .enumerate()
            .filter_map(|(k, fp)| {
                occ.best_fit_among(fp, self.rule, &rivals, k).map(|(key, x, y)| (key, k, x, y))
            })
            .collect();
        found.sort_unstable_by_key(|&(key, k, ..)| (key, k));
        Some(found.into_iter().take(width).map(|(_, k, x, y)| (k, x, y)).collect())
    }

    /// [`Search::places`] of the searched island at the end of `path`, from the [`Memo`] when an
    /// earlier iteration searched them (paying their calls again).
    fn places_on_path(
        &self,
        occ: &Occupancy,
        island: usize,
        width: usize,
        path: &[Step],
        budget: &mut usize,
    ) -> Vec<(usize, u32, u32)> {
        let Some(memo) = self.memo else {
            return self.places(occ, island, width, budget).unwrap_or_default();
        };
        if let Some(Known::Places(mut places)) = memo.get(path) {
            if !memo.pay_again(budget, self.footprints[island].len()) {
                return Vec::new();
            }
            places.truncate(width);
            return places;
        }
        let Some(mut places) = self.places(occ, island, self.limits.width, budget) else {
            return Vec::new();
        };
        memo.put(path, Known::Places(places.clone()));
        places.truncate(width);
        places
    }

    /// `order[d..]` placed on `occ` after `path` as [`pack_shapes`] places them. A leaf the
    /// [`Memo`] knows to fail pays the calls that found it again (as many as the budget holds)
    /// and fails; a leaf found to fail is kept there.
    fn rest(
        &self,
        mut occ: Occupancy,
        d: usize,
        mut path: Vec<Step>,
        budget: &mut usize,
    ) -> Option<Vec<Step>> {
        if let Some(memo) = self.memo
            && let Some(Known::Fails(searched)) = memo.get(&path)
        {
            for &island in &self.order[d..d + searched] {
                if !memo.pay_again(budget, self.footprints[island].len()) {
                    break;
                }
            }
            return None;
        }
        let searched_from = path.len();
        match self.place_greedily(&mut occ, d, &mut path, budget) {
            Ok(()) => Some(path),
            Err(halt) => {
                if let (Some(memo), Halt::FitsNowhere) = (self.memo, halt) {
                    let searched = path.len() - searched_from + 1;
                    memo.put(&path[..searched_from], Known::Fails(searched));
                }
                None
            }
        }
    }

    /// Places `order[d..]` on `occ` one after the other as [`pack_shapes`] does, each appended to
    /// `path`, until one stops it.
    fn place_greedily(
        &self,
        occ: &mut Occupancy,
        d: usize,
        path: &mut Vec<Step>,
        budget: &mut usize,
    ) -> Result<(), Halt> {
        for &island in &self.order[d..] {
            let places = self.places(occ, island, 1, budget).ok_or(Halt::Spent)?;
            let &(turn, x, y) = places.first().ok_or(Halt::FitsNowhere)?;
            occ.occupy(&self.footprints[island][turn], x, y, self.gutter);
            path.push(Step { island, turn, x, y, rank: 0 });
        }
        Ok(())
    }
}

/// Why [`Search::place_greedily`] stopped before the last island.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Halt {
    /// The next island fits nowhere on the occupancy (whatever the budget).
    FitsNowhere,
    /// The budget could not pay for the next island's search.
    Spent,
}

/// Takes `calls` from `budget` when it holds them (else empties it): whether the search may go
/// on.
fn pay(budget: &mut usize, calls: usize) -> bool {
    if *budget < calls {
        *budget = 0;
        return false;
    }
    *budget -= calls;
    true
}

#[cfg(test)]
mod tests {
    use super::*;

    fn square_island(side: f64) -> Island {
        let points = vec![[0.0, 0.0], [side, 0.0], [side, side], [0.0, side]];
        Island {
            rot: [1.0, 0.0],
            min: [0.0; 2],
            extent: [side; 2],
            growth: 1.0,
            degenerate: false,
            area_3d: side * side,
            diagonal: true,
            points,
            tris: vec![[0, 1, 2], [0, 2, 3]],
            outline: None,
        }
    }

    /// `next` against a bit-by-bit search: the first `x' ≥ x` below `w` whose bit is `set`, else
    /// `w`, for limits inside a word, on a word boundary and at the row's end.
    #[test]
    fn the_next_set_or_clear_bit_stops_at_its_limit() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let row: Vec<u64> =
            (0..4).map(|i| if i == 1 { 0 } else { rng.random::<u64>() & rng.random::<u64>() }).collect();
        let bit = |x: u32| row[x as usize / 64] >> (x % 64) & 1 == 1;
        for set in [true, false] {
            for x in 0..256 {
                for w in [x, x + 1, x + 5, x + 63, x + 64, x + 130, 256]
                    .into_iter()
                    .filter(|&w| w >= x && w <= 256)
                {
                    let want = (x..w).find(|&i| bit(i) == set).unwrap_or(w);
                    assert_eq!(next(&row, x, w, set), want, "x {x} w {w} set {set}");
                }
            }
        }
    }

    /// `first_occupied` against a bit-by-bit search, for spans inside a word, across word
    /// boundaries and over many words, on rows with few or many set bits.
    #[test]
    fn the_first_occupied_texel_of_a_span_is_the_first_set_bit() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        for case in 0..40 {
            let row: Vec<u64> = (0..6)
                .map(|_| match case % 3 {
                    0 => 0,
                    1 => 1u64 << rng.random_range(0..64),
                    _ => rng.random::<u64>() & rng.random::<u64>() & rng.random::<u64>(),
                })
                .collect();
            let bit = |x: u32| row[x as usize / 64] >> (x % 64) & 1 == 1;
            for a in 0..384 {
                for b in [a, a + 1, a + 63, a + 64, a + 65, a + 200, 383]
                    .into_iter()
                    .filter(|&b| b >= a && b < 384)
                {
                    let want = (a..=b).find(|&x| bit(x));
                    assert_eq!(first_occupied(&row, a, b), want, "case {case}, {a}..={b}");
                }
            }
        }
    }

    /// `first_short` against a plain scan: rows short at no, one or several places, inside a
    /// chunk, on a chunk boundary and in the ragged last chunk.
    #[test]
    fn the_first_short_row_is_the_first_one_a_plain_scan_finds() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        for len in [1, 5, 16, 17, 40, 333] {
            for _ in 0..200 {
                let free: Vec<u32> = (0..len).map(|_| rng.random_range(0..50)).collect();
                let mut need: Vec<u32> = free.iter().map(|&f| f - f.min(rng.random_range(0..3))).collect();
                for _ in 0..rng.random_range(0..3) {
                    let r = rng.random_range(0..len);
                    need[r] = free[r] + 1;
                }
                let want = free.iter().zip(&need).position(|(f, n)| f < n);
                assert_eq!(first_short(&free, &need), want, "free {free:?} need {need:?}");
            }
        }
    }

    #[test]
    fn an_aligned_square_touches_exactly_its_texels() {
        let fp = footprint(&square_island(1.0), 0, 5.0);
        assert_eq!((fp.w, fp.h), (5, 5));
        assert!(fp.rows.iter().all(|r| r == &vec![(0, 4)]), "{:?}", fp.rows);
        // Turned by 45°: a diamond 5√2 across, its rows widening to the middle and narrowing.
        let fp = footprint(&square_island(1.0), 1, 5.0);
        assert_eq!((fp.w, fp.h), (8, 8));
        assert_eq!(fp.rows[0], vec![(2, 4)]);
        assert_eq!(fp.rows[3], vec![(0, 7)]);
    }

    /// An island of `points` and `tris` (extent and the rest as the unit square's).
    fn island_of(points: Vec<[f64; 2]>, tris: Vec<[u32; 3]>) -> Island {
        Island { points, tris, ..square_island(1.0) }
    }

    /// An `n × n` grid over `[0, 1]²`, its inner vertices moved at random by up to `jitter` of a
    /// cell (small enough that no face turns over), without the quads for which `hole(i, j)`.
    fn jittered_grid(n: u32, jitter: f64, seed: u64, hole: impl Fn(u32, u32) -> bool) -> Island {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let cell = 1.0 / n as f64;
        let mut points = Vec::new();
        for j in 0..=n {
            for i in 0..=n {
                let inner = i > 0 && j > 0 && i < n && j < n;
                let d = if inner {
                    [0, 1].map(|_| jitter * cell * (rng.random::<f64>() - 0.5))
                } else {
                    [0.0; 2]
                };
                points.push([i as f64 * cell + d[0], j as f64 * cell + d[1]]);
            }
        }
        let id = |i: u32, j: u32| j * (n + 1) + i;
        let mut tris = Vec::new();
        for j in 0..n {
            for i in 0..n {
                if !hole(i, j) {
                    tris.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
                    tris.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
                }
            }
        }
        island_of(points, tris)
    }

    #[test]
    fn the_outline_gives_the_footprint_of_every_face() {
        let mut islands = vec![
            jittered_grid(12, 0.6, 1, |_, _| false),
            // An annulus: the boundary has an inner loop.
            jittered_grid(12, 0.6, 2, |i, j| (4..8).contains(&i) && (3..9).contains(&j)),
            // Two separate parts and a notch.
            jittered_grid(16, 0.5, 3, |i, j| i == 7 || (j > 10 && i > 11)),
        ];
        // A grid folded over itself without turning a face: the right half laid again, shifted,
        // over the left (the winding number is 2 where they overlap).
        let mut folded = jittered_grid(8, 0.4, 4, |_, _| false);
        let n = folded.points.len() as u32;
        let copy: Vec<[f64; 2]> = folded.points.iter().map(|p| [p[0] - 0.37, p[1] + 0.11]).collect();
        folded.points.extend(copy);
        let more: Vec<[u32; 3]> = folded.tris.iter().map(|t| t.map(|i| i + n)).collect();
        folded.tris.extend(more);
        islands.push(folded);
        // A face collapsed to a segment (zero area) inside the grid.
        let mut collapsed = jittered_grid(6, 0.0, 5, |_, _| false);
        collapsed.points[8] = collapsed.points[9];
        islands.push(collapsed);
        for island in &mut islands {
            island.outline = Outline::of(&island.points, &island.tris);
            let o = island.outline.as_ref().expect("no face is wound backwards");
            assert!(o.faces.len() < island.tris.len(), "inner faces are skipped");
            let every_face = Island { outline: None, ..island.clone() };
            for k in 0..8 {
                for t in [3.0, 7.3, 20.0, 51.7] {
                    let (a, b) = (footprint(island, k, t), footprint(&every_face, k, t));
                    assert_eq!((a.w, a.h), (b.w, b.h));
                    assert_eq!(a.rows, b.rows, "turn {k}, {t} texels per unit");
                }
            }
        }
        // A face wound backwards: no outline, every face is rasterised.
        let mut flipped = jittered_grid(4, 0.0, 6, |_, _| false);
        flipped.tris[3].swap(1, 2);
        assert!(Outline::of(&flipped.points, &flipped.tris).is_none());
    }

    #[test]
    fn a_thin_sliver_still_touches_the_texels_it_crosses() {
        let island = Island {
            points: vec![[0.1, 0.1], [3.9, 0.1], [3.9, 0.1000001]],
            tris: vec![[0, 1, 2]],
            ..square_island(1.0)
        };
        let fp = footprint(&island, 0, 1.0);
        assert_eq!(fp.rows, vec![vec![(0, 3)]]);
    }

    /// Where `rule` places `fp` in `o`.
    fn fit_at(o: &Occupancy, fp: &Footprint, rule: Rule) -> Option<(u32, u32)> {
        o.best_fit(fp, rule).map(|(_, x, y)| (x, y))
    }

    #[test]
    fn fits_skip_occupied_runs_and_respect_border_and_gutter() {
        let fp = footprint(&square_island(1.0), 0, 3.0);
        let mut o = Occupancy::new(10, 2);
        // Border strips of one texel on every side: the first fit is (1, 1).
        assert_eq!(fit_at(&o, &fp, Rule::LowestTop), Some((1, 1)));
        o.occupy(&fp, 1, 1, 2);
        // Dilated by 2, the square blocks columns and rows 0..=5: next to it from x = 6, and a
        // 3-wide footprint needs columns 6..=8 (column 9 is border).
        assert_eq!(fit_at(&o, &fp, Rule::LowestTop), Some((6, 1)));
        o.occupy(&fp, 6, 1, 2);
        assert_eq!(fit_at(&o, &fp, Rule::LowestTop), Some((1, 6)));
        o.occupy(&fp, 1, 6, 2);
        assert_eq!(fit_at(&o, &fp, Rule::LowestTop), Some((6, 6)));
        o.occupy(&fp, 6, 6, 2);
        assert_eq!(fit_at(&o, &fp, Rule::LowestTop), None);
    }

    /// An occupancy of `side²` without border or gutter, with `blocked[y]` texels occupied from
    /// the left of row `y`.
    fn blocked_from_left(side: u32, blocked: &[u32]) -> Occupancy {
        let mut o = Occupancy::new(side, 0);
        for (y, &n) in blocked.iter().enumerate() {
            if n > 0 {
                o.fill(y as u32, 0, n - 1);
                o.longest_free[y] = o.measure_longest_free(y as u32);
            }
        }
        o
    }

    /// A `side²` occupancy with random blocks and specks set.
    fn random_occupancy(rng: &mut impl rand::Rng, side: u32) -> Occupancy {
        let mut o = Occupancy::new(side, rng.random_range(0..3));
        for _ in 0..rng.random_range(0..12) {
            let (x, y) = (rng.random_range(0..side), rng.random_range(0..side));
            let (w, h) = (rng.random_range(1..side / 2 + 2), rng.random_range(1..side / 2 + 2));
            for yy in y..(y + h).min(side) {
                o.fill(yy, x, (x + w - 1).min(side - 1));
            }
        }
        for _ in 0..rng.random_range(0..40) {
            let (x, y) = (rng.random_range(0..side), rng.random_range(0..side));
            o.fill(y, x, x);
        }
        for y in 0..side {
            o.longest_free[y as usize] = o.measure_longest_free(y);
        }
        o
    }

    /// A footprint of at most `size` texels a side, a row one run or two.
    fn random_footprint(rng: &mut impl rand::Rng, size: u32) -> Footprint {
        let (w, h) = (rng.random_range(1..size), rng.random_range(1..size));
        let rows: Vec<Vec<(u32, u32)>> = (0..h)
            .map(|_| {
                let a = rng.random_range(0..w);
                let b = rng.random_range(a..w);
                if b + 2 < w && rng.random_bool(0.3) {
                    vec![(a, b), (rng.random_range(b + 2..w), w - 1)]
                } else {
                    vec![(a, b)]
                }
            })
            .collect();
        Footprint { w, h, rows, shift: [0.0; 2], turn: [1.0, 0.0] }
    }

    /// `best_fit` against testing every position texel by texel, on random atlases (blocks and
    /// scattered texels) and random footprints (rows of one or two runs): the same position and
    /// key under every rule, or no fit for both. The search's row order and jumps must not
    /// change which position is found.
    #[test]
    fn best_fit_finds_what_testing_every_position_finds() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(17);
        let bit = |o: &Occupancy, x: u32, y: u32| o.row(y)[x as usize / 64] >> (x % 64) & 1 == 1;
        for case in 0..300 {
            let side = rng.random_range(8..90);
            let o = random_occupancy(&mut rng, side);
            let fp = random_footprint(&mut rng, 12);
            let (w, h) = (fp.w, fp.h);
            for rule in [Rule::LowestTop, Rule::Corner, Rule::Square] {
                let mut want: Option<(Key, u32, u32)> = None;
                for (y, x) in (0..side).flat_map(|y| (0..side).map(move |x| (y, x))) {
                    if y + h <= side && x + w <= side {
                        let fits = fp.rows.iter().enumerate().all(|(r, runs)| {
                            runs.iter().all(|&(a, b)| (a..=b).all(|c| !bit(&o, x + c, y + r as u32)))
                        });
                        let key = rule.key(&fp, x, y);
                        if fits && want.is_none_or(|(k, ..)| key < k) {
                            want = Some((key, x, y));
                        }
                    }
                }
                assert_eq!(o.best_fit(&fp, rule), want, "case {case}, {rule:?}");
            }
        }
    }

    /// An island's first `width` places, its orientations searched in parallel and stopped by
    /// each other's fits ([`Rivals`]), are those of every orientation searched alone, by key
    /// then orientation: for every width from one to all orientations, on random occupancies.
    #[test]
    fn orientations_searched_together_keep_the_places_of_each_searched_alone() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(29);
        for case in 0..200 {
            let side = rng.random_range(16..120);
            let o = random_occupancy(&mut rng, side);
            let footprints = vec![(0..8).map(|_| random_footprint(&mut rng, 20)).collect::<Vec<_>>()];
            for rule in [Rule::LowestTop, Rule::Corner, Rule::Square] {
                let mut alone: Vec<(Key, usize, u32, u32)> = footprints[0]
                    .iter()
                    .enumerate()
                    .filter_map(|(k, fp)| o.best_fit(fp, rule).map(|(key, x, y)| (key, k, x, y)))
                    .collect();
                alone.sort_unstable_by_key(|&(key, k, ..)| (key, k));
                for width in 1..=8 {
                    let search = Search {
                        footprints: &footprints,
                        order: &[0],
                        gutter: 0,
                        rule,
                        limits: SearchLimits { width, ..GREEDY },
                        memo: None,
                    };
                    let want: Vec<(usize, u32, u32)> =
                        alone.iter().take(width).map(|&(_, k, x, y)| (k, x, y)).collect();
                    let got = search.places(&o, 0, width, &mut { usize::MAX });
                    assert_eq!(got, Some(want), "case {case}, {rule:?}, width {width}");
                }
            }
        }
    }

    #[test]
    fn each_rule_takes_the_position_its_key_ranks_first() {
        // A 6 × 2 block in the corner; a 3 × 3 square fits right of it on the floor (top 3,
        // far corner (9, 3)) or on top of it at the left (top 5, far corner (3, 5)).
        let o = blocked_from_left(10, &[6, 6]);
        let fp = footprint(&square_island(1.0), 0, 3.0);
        assert_eq!(fit_at(&o, &fp, Rule::LowestTop), Some((6, 0)));
        assert_eq!(fit_at(&o, &fp, Rule::Corner), Some((0, 2)));
        assert_eq!(fit_at(&o, &fp, Rule::Square), Some((0, 2)));
        // A one-texel island: row 0 is free from x = 6 (far corner (7, 1): sum 8, larger side
        // 7), rows 1–3 from x = 7, row 4 from x = 3 (far corner (4, 5): sum 9, larger side 5),
        // the rows above are full.
        let o = blocked_from_left(10, &[6, 7, 7, 7, 3, 10, 10, 10, 10, 10]);
        let fp = footprint(&square_island(1.0), 0, 1.0);
        assert_eq!(fit_at(&o, &fp, Rule::LowestTop), Some((6, 0)));
        assert_eq!(fit_at(&o, &fp, Rule::Corner), Some((6, 0)));
        assert_eq!(fit_at(&o, &fp, Rule::Square), Some((3, 4)));
    }

    /// A `w × h` rectangle's footprints in its two quarter turns (one when square).
    fn rect_turns(w: u32, h: u32) -> Vec<Footprint> {
        let rect = |w: u32, h: u32| Footprint {
            w,
            h,
            rows: vec![vec![(0, w - 1)]; h as usize],
            shift: [0.0; 2],
            turn: [1.0, 0.0],
        };
        if w == h { vec![rect(w, h)] } else { vec![rect(w, h), rect(h, w)] }
    }

    /// Random rectangles filling 60–95% of a random small square, in decreasing area.
    fn random_rects(rng: &mut rand_chacha::ChaCha8Rng) -> (Vec<Vec<Footprint>>, Vec<usize>, u32, u32) {
        use rand::Rng;
        let side = rng.random_range(10..17);
        let gutter = rng.random_range(0..2);
        let fill = rng.random_range(0.6..0.95) * (side * side) as f64;
        let (mut sizes, mut area) = (Vec::new(), 0.0);
        while area < fill {
            let (w, h) = (rng.random_range(1..side / 2 + 2), rng.random_range(1..side / 2 + 2));
            area += ((w + gutter) * (h + gutter)) as f64;
            sizes.push((w, h));
        }
        sizes.sort_by_key(|&(w, h)| std::cmp::Reverse(w * h));
        let order = (0..sizes.len()).collect();
        (sizes.into_iter().map(|(w, h)| rect_turns(w, h)).collect(), order, side, gutter)
    }

    /// Every placed island inside the square and off its border strips, and any two islands'
    /// texels more than `gutter` apart (Chebyshev), checked texel by texel.
    fn assert_valid(placed: &[ShapePlaced], side: u32, gutter: u32) {
        let texels = |p: &ShapePlaced| -> Vec<(i64, i64)> {
            let mut out = Vec::new();
            for (r, runs) in p.footprint.rows.iter().enumerate() {
                for &(a, b) in runs {
                    out.extend((a..=b).map(|c| ((p.x + c) as i64, (p.y + r as u32) as i64)));
                }
            }
            out
        };
        let (low, high) = ((gutter / 2) as i64, (gutter - gutter / 2) as i64);
        let all: Vec<Vec<(i64, i64)>> = placed.iter().map(texels).collect();
        for &(x, y) in all.iter().flatten() {
            assert!(x >= low && y >= low && x < side as i64 - high && y < side as i64 - high, "({x}, {y})");
        }
        for i in 0..all.len() {
            for j in i + 1..all.len() {
                for &(x1, y1) in &all[i] {
                    for &(x2, y2) in &all[j] {
                        assert!((x1 - x2).abs().max((y1 - y2).abs()) > gutter as i64, "islands {i}, {j}");
                    }
                }
            }
        }
    }

    fn spots(placed: &[ShapePlaced]) -> Vec<(u32, u32, u32, u32)> {
        placed.iter().map(|p| (p.x, p.y, p.footprint.w, p.footprint.h)).collect()
    }

    /// The search's first path is the greedy placement: without departures it is exactly
    /// [`pack_shapes`], and with them it still returns the greedy's packing where that fits.
    #[test]
    fn the_place_search_starts_from_the_greedy_packing() {
        use rand::SeedableRng;
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(23);
        for _ in 0..150 {
            let (fps, order, side, gutter) = random_rects(&mut rng);
            for rule in [Rule::LowestTop, Rule::Corner, Rule::Square] {
                let greedy = pack_shapes(&fps, &order, side, gutter, rule);
                for discrepancies in [0, 2] {
                    let limits =
                        SearchLimits { depth: 3, width: 2, discrepancies, speculate: true, deepen: false };
                    let mut unlimited = usize::MAX;
                    let searched =
                        pack_shapes_searched(&fps, &order, side, gutter, rule, limits, &mut unlimited);
                    match (&greedy, &searched) {
                        (Some(g), Some(s)) => assert_eq!(spots(g), spots(s)),
                        (None, None) => {}
                        (None, Some(_)) => assert!(discrepancies > 0, "no departure allowed"),
                        (Some(_), None) => panic!("the greedy packing was not the search's first"),
                    }
                }
            }
        }
    }

    /// Departures from the rule's choice pack some sets the greedy cannot, every packing the
    /// search returns keeps the gutter and the border, and an empty budget finds nothing.
    #[test]
    fn the_place_search_packs_what_the_greedy_cannot() {
        use rand::SeedableRng;
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(29);
        let (mut rescued, mut tried) = (0, 0);
        for _ in 0..300 {
            let (fps, order, side, gutter) = random_rects(&mut rng);
            let limits =
                SearchLimits { depth: 4, width: 2, discrepancies: 2, speculate: true, deepen: false };
            let searched =
                pack_shapes_searched(&fps, &order, side, gutter, Rule::LowestTop, limits, &mut 1_000_000);
            if let Some(placed) = &searched {
                assert_valid(placed, side, gutter);
            }
            if pack_shapes(&fps, &order, side, gutter, Rule::LowestTop).is_none() {
                tried += 1;
                rescued += usize::from(searched.is_some());
            }
            let mut empty = 0;
            assert!(
                pack_shapes_searched(&fps, &order, side, gutter, Rule::LowestTop, limits, &mut empty)
                    .is_none()
            );
        }
        assert!(rescued > 0, "the search packed none of the {tried} sets the greedy could not");
    }

    /// Searching two places at once gives the packing and leaves the budget that searching them
    /// one after the other does, for every budget from none to more than the search needs
    /// (where it runs out on the way, and where it does not).
    #[test]
    fn the_speculative_search_is_the_sequential_one() {
        use rand::SeedableRng;
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(31);
        let mut exhausted = 0;
        for _ in 0..60 {
            let (fps, order, side, gutter) = random_rects(&mut rng);
            let one_by_one =
                SearchLimits { depth: 4, width: 3, discrepancies: 2, speculate: false, deepen: false };
            let two_at_once = SearchLimits { speculate: true, ..one_by_one };
            let search = |limits, budget: &mut usize| {
                pack_shapes_searched(&fps, &order, side, gutter, Rule::LowestTop, limits, budget)
            };
            let mut full = usize::MAX;
            search(one_by_one, &mut full);
            let needed = usize::MAX - full;
            for budget in (0..=needed + 2).step_by((needed / 25).max(1)) {
                let (mut one, mut two) = (budget, budget);
                let a = search(one_by_one, &mut one);
                let b = search(two_at_once, &mut two);
                assert_eq!(a.as_deref().map(spots), b.as_deref().map(spots), "budget {budget}");
                assert_eq!(one, two, "budget {budget}");
                exhausted += usize::from(one == 0);
            }
        }
        assert!(exhausted > 0, "no budget ran out: the reconciliation went untested");
    }

    /// The deepening search, which remembers the paths of its earlier iterations, gives the
    /// packing and leaves the budget that its iterations as separate searches do, for every
    /// budget from none to more than they need; and the remembered paths spare calls.
    #[test]
    fn the_deepening_search_is_its_iterations_one_after_the_other() {
        use rand::SeedableRng;
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(37);
        let (mut replayed, mut exhausted, mut found_late) = (0, 0, 0);
        for _ in 0..400 {
            let (footprints, order, side, gutter) = random_rects(&mut rng);
            let limits =
                SearchLimits { depth: 4, width: 3, discrepancies: 3, speculate: true, deepen: false };
            let apart = |budget: &mut usize| {
                (1..=limits.discrepancies).find_map(|discrepancies| {
                    let limits = SearchLimits { discrepancies, ..limits };
                    pack_shapes_searched(&footprints, &order, side, gutter, Rule::LowestTop, limits, budget)
                })
            };
            let mut full = usize::MAX;
            apart(&mut full);
            let needed = usize::MAX - full;
            let first = SearchLimits { discrepancies: 1, ..limits };
            let mut first_only = usize::MAX;
            let rule = Rule::LowestTop;
            let fails_first =
                pack_shapes_searched(&footprints, &order, side, gutter, rule, first, &mut first_only);
            for budget in (0..=needed + 2).step_by((needed / 25).max(1)) {
                let (mut one, mut two) = (budget, budget);
                let a = apart(&mut one);
                let memo = Memo::default();
                let search =
                    Search { footprints: &footprints, order: &order, gutter, rule, limits, memo: None };
                let b = search.deepen(side, &memo, &mut two);
                assert_eq!(a.as_deref().map(spots), b.as_deref().map(spots), "budget {budget}");
                assert_eq!(one, two, "budget {budget}");
                // The same through the entry point the place search calls.
                let (deepening, mut three) = (SearchLimits { deepen: true, ..limits }, budget);
                let c = pack_shapes_searched(&footprints, &order, side, gutter, rule, deepening, &mut three);
                assert_eq!(a.as_deref().map(spots), c.as_deref().map(spots), "budget {budget}");
                assert_eq!(one, three, "budget {budget}");
                replayed += memo.replayed.load(Ordering::Relaxed);
                exhausted += usize::from(one == 0);
                found_late += usize::from(fails_first.is_none() && b.is_some());
            }
        }
        assert!(replayed > 0, "no call was spared: the memo went unused");
        assert!(exhausted > 0, "no budget ran out: the replay's payments went untested");
        assert!(found_late > 0, "no packing needed a later iteration");
    }

    /// An order packed from a kept head is the order packed from scratch, whether it shares
    /// none, some or all of the kept order's islands, whether the kept packing failed before,
    /// at or after the islands it changes, and by another rule.
    #[test]
    fn an_order_packed_from_a_kept_head_is_the_order_packed_whole() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(41);
        let rules = [Rule::LowestTop, Rule::Corner, Rule::Square];
        let (mut failed_before_swap, mut placed_from_head) = (0, 0);
        for _ in 0..150 {
            let (fps, order, side, gutter) = random_rects(&mut rng);
            let rule = rules[rng.random_range(0..3)];
            let head = GreedyHead::new(fps.clone(), &order, side, gutter, rule);
            let n = order.len();
            for i in 0..n {
                for j in i..(i + 4).min(n) {
                    let mut candidate = order.clone();
                    candidate.swap(i, j);
                    for r in [rule, rules[rng.random_range(0..3)]] {
                        let whole = pack_shapes(&fps, &candidate, side, gutter, r);
                        let kept = head.pack(&candidate, r);
                        assert_eq!(whole.as_deref().map(spots), kept.as_deref().map(spots), "swap {i} {j}");
                        failed_before_swap += usize::from(r == rule && i > head.steps.len());
                        placed_from_head += usize::from(r == rule && i > 0 && kept.is_some());
                    }
                }
            }
        }
        assert!(failed_before_swap > 0 && placed_from_head > 0, "{failed_before_swap} {placed_from_head}");
    }

    #[test]
    fn an_l_nests_into_the_corner_of_another() {
        // Two L islands of three unit squares each (footprints 2×2 minus one texel): the second
        // sits turned by 180° in the first's notch, in a 3 × 2 area that rectangles need 4 × 2 for.
        let l = Island {
            points: vec![[0.0, 0.0], [2.0, 0.0], [2.0, 1.0], [1.0, 1.0], [1.0, 2.0], [0.0, 2.0]],
            tris: vec![[0, 1, 2], [0, 2, 3], [0, 3, 4], [0, 4, 5]],
            extent: [2.0; 2],
            ..square_island(1.0)
        };
        let islands = vec![l.clone(), l];
        let fps = footprints(&islands, |_| 1.0, true);
        let placed = pack_shapes(&fps, &[0, 1], 3, 0, Rule::LowestTop).expect("fits 3 × 3");
        let mut cells = std::collections::HashSet::new();
        for p in &placed {
            for (r, runs) in p.footprint.rows.iter().enumerate() {
                for &(a, b) in runs {
                    for x in a..=b {
                        assert!(cells.insert((p.x + x, p.y + r as u32)), "overlap at {x},{r}");
                    }
                }
            }
        }
        assert_eq!(cells.len(), 6);
        assert!(cells.iter().all(|&(x, y)| x < 3 && y < 2), "{cells:?}");
    }
}

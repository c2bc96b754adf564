//! The one triangle rasteriser of the crate, shared by the screen-space renderer ([`mod@crate::render`]),
//! the UV-space coverage raster ([`crate::uvstats`]) and the UV layout picture
//! ([`crate::pictures`]). They are the same operation: "which pixel centres does this 2-D triangle
//! cover, and with which barycentrics", followed by a per-pixel update that differs.
//!
//! **Coverage rule.** Vertices are snapped to 1/256 pixel (fixed point) and edge functions are
//! evaluated exactly in integers, with a tie-breaking rule equivalent to nudging every sample point by
//! the same infinitesimal offset. Consequence: in a mesh without overlaps every pixel centre is
//! covered by **exactly one** triangle, even centres lying exactly on a shared edge or vertex, as
//! long as snapping makes no overlap — and it can: two faces a hair apart (two edges 10⁻⁴ pixel
//! apart along a seam of a marching-cubes mesh's slivers) may both cover a centre once snapped.
//! So counting which faces cover a texel ([`crate::uvstats`]' overlaps and utilisation) takes
//! [`Sampling::Exact`]: the same rule on the unsnapped coordinates, decided by exact predicates
//! ([`robust::orient2d`]), where no two faces whose interiors are disjoint ever share a centre.
//! Triangles of zero area cover nothing; orientation does not matter (back faces are rasterised).
//!
//! **Determinism.** [`raster_parallel`] splits the image into bands of rows processed in parallel;
//! inside a band, triangles are visited in increasing index order, so an order-dependent per-pixel
//! update (a z-test with ties, a counter) gives bit-identical results for any thread count.

use std::ops::Range;

use rayon::prelude::*;

/// Sub-pixel precision: vertices are snapped to 1/2^8 pixel.
const SUB_BITS: u32 = 8;
const SUB: i64 = 1 << SUB_BITS;
/// Vertices farther than this from the origin (in pixels) make a triangle unrasterisable: exact
/// integer edge functions would overflow. Such a triangle is skipped. With the cameras of this crate
/// it can only happen to a triangle almost touching the camera plane.
pub(crate) const MAX_PIXEL_COORD: f32 = (1u32 << 21) as f32;
/// Rows per band of [`raster_parallel`].
const BAND_ROWS: usize = 16;
/// Triangles per binning task of [`raster_parallel`].
const BIN_CHUNK: usize = 1 << 15;

/// Pixel-space triangle: `x` to the right, `y` down, pixel `(x, y)` has its centre at
/// `(x + 0.5, y + 0.5)`.
pub(crate) type Tri2 = [[f32; 2]; 3];

/// Calls `visit(x, y, l)` for every pixel centre of columns `0..width` and rows `rows` covered by the
/// triangle `v` (coverage rule in the module docs). `l` are the screen-space (affine) barycentrics
/// of the centre with respect to `v`, in `v`'s order; they sum to 1.
pub(crate) fn rasterize_triangle(
    v: Tri2,
    width: u32,
    rows: Range<u32>,
    mut visit: impl FnMut(u32, u32, [f32; 3]),
) {
    let Some(mut p) = snap(v) else { return };
    let mut order = [0usize, 1, 2];
    let mut area = edge(p[0], p[1], p[2]);
    if area == 0 {
        return;
    }
    if area < 0 {
        p.swap(1, 2);
        order.swap(1, 2);
        area = -area;
    }
    let (xs, ys) = (p.map(|q| q[0]), p.map(|q| q[1]));
    let lo = |m: i64| (m - SUB / 2 + SUB - 1).div_euclid(SUB); // first centre >= m
    let hi = |m: i64| (m - SUB / 2).div_euclid(SUB); // last centre <= m
    let x0 = lo(*xs.iter().min().unwrap()).max(0);
    let x1 = hi(*xs.iter().max().unwrap()).min(width as i64 - 1);
    let y0 = lo(*ys.iter().min().unwrap()).max(rows.start as i64);
    let y1 = hi(*ys.iter().max().unwrap()).min(rows.end as i64 - 1);
    if x0 > x1 || y0 > y1 {
        return;
    }
    // Edge k is opposite vertex k, from p[k+1] to p[k+2]; its function is positive inside.
    let edges: [([i64; 2], [i64; 2]); 3] = std::array::from_fn(|k| (p[(k + 1) % 3], p[(k + 2) % 3]));
    let inv_area = 1.0 / area as f64;
    let start = [x0 * SUB + SUB / 2, y0 * SUB + SUB / 2];
    let mut row_e = edges.map(|(a, b)| edge(a, b, start));
    let step_x = edges.map(|(a, b)| -(b[1] - a[1]) * SUB);
    let step_y = edges.map(|(a, b)| (b[0] - a[0]) * SUB);
    // A sample exactly on an edge belongs to the triangle when the edge points "up" (dy < 0) or
    // exactly right: the same as nudging every sample by (+ε, +ε²), so neighbours never both own it.
    let min_e = edges.map(|(a, b)| {
        let d = [b[0] - a[0], b[1] - a[1]];
        if d[1] < 0 || (d[1] == 0 && d[0] > 0) { 0 } else { 1 }
    });
    for y in y0..=y1 {
        let mut e = row_e;
        for x in x0..=x1 {
            if e[0] >= min_e[0] && e[1] >= min_e[1] && e[2] >= min_e[2] {
                let mut l = [0f32; 3];
                for k in 0..3 {
                    l[order[k]] = (e[k] as f64 * inv_area) as f32;
                }
                visit(x as u32, y as u32, l);
            }
            for k in 0..3 {
                e[k] += step_x[k];
            }
        }
        for k in 0..3 {
            row_e[k] += step_y[k];
        }
    }
}

/// Calls `visit(x, y, l)` for every pixel centre of columns `0..width` and rows `rows` covered by
/// the triangle `v`, as [`rasterize_triangle`] does but on `v`'s own coordinates: a centre is
/// covered when it lies strictly inside every edge, or on an edge that owns its ties (the same
/// rule as there), each side decided exactly ([`robust::orient2d`]). So two triangles whose
/// interiors are disjoint never both cover a centre, and two that share an edge (the same
/// coordinates at both ends) cover each centre on it once. `l` are the centre's barycentrics
/// (rounded). Triangles of zero area or with a coordinate that is not finite cover nothing.
pub(crate) fn rasterize_triangle_exact(
    v: Tri2,
    width: u32,
    rows: Range<u32>,
    mut visit: impl FnMut(u32, u32, [f32; 3]),
) {
    if v.iter().flatten().any(|c| !c.is_finite()) {
        return;
    }
    let mut p: [[f64; 2]; 3] = v.map(|q| q.map(f64::from));
    let orient = |a: [f64; 2], b: [f64; 2], c: [f64; 2]| {
        robust::orient2d(
            robust::Coord { x: a[0], y: a[1] },
            robust::Coord { x: b[0], y: b[1] },
            robust::Coord { x: c[0], y: c[1] },
        )
    };
    let mut order = [0usize, 1, 2];
    let area = orient(p[0], p[1], p[2]);
    if area == 0.0 {
        return;
    }
    if area < 0.0 {
        p.swap(1, 2);
        order.swap(1, 2);
    }
    let (xs, ys) = (p.map(|q| q[0]), p.map(|q| q[1]));
    let min = |a: [f64; 3]| a[0].min(a[1]).min(a[2]);
    let max = |a: [f64; 3]| a[0].max(a[1]).max(a[2]);
    // Centres `c + ½` within the bounding box, clipped to the image before any cast.
    let first = |m: f64, lo: f64| (m - 0.5).ceil().max(lo);
    let last = |m: f64, hi: f64| (m - 0.5).floor().min(hi);
    let (x0, x1) = (first(min(xs), 0.0), last(max(xs), width as f64 - 1.0));
    let (y0, y1) = (first(min(ys), rows.start as f64), last(max(ys), rows.end as f64 - 1.0));
    if !(x0 <= x1 && y0 <= y1) {
        return;
    }
    // Edge k is opposite vertex k, from p[k+1] to p[k+2]; inside is its left (positive) side.
    let edges: [([f64; 2], [f64; 2]); 3] = std::array::from_fn(|k| (p[(k + 1) % 3], p[(k + 2) % 3]));
    let owns_ties = edges.map(|(a, b)| {
        let d = [b[0] - a[0], b[1] - a[1]];
        d[1] < 0.0 || (d[1] == 0.0 && d[0] > 0.0)
    });
    let inv_area = 1.0 / area.abs();
    for y in y0 as u32..=y1 as u32 {
        for x in x0 as u32..=x1 as u32 {
            let c = [x as f64 + 0.5, y as f64 + 0.5];
            let e = edges.map(|(a, b)| orient(a, b, c));
            if (0..3).all(|k| e[k] > 0.0 || (e[k] == 0.0 && owns_ties[k])) {
                let mut l = [0f32; 3];
                for k in 0..3 {
                    l[order[k]] = (e[k] * inv_area) as f32;
                }
                visit(x, y, l);
            }
        }
    }
}

/// How [`raster_parallel`] decides which pixel centres a triangle covers (module docs).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Sampling {
    /// Vertices snapped to 1/256 pixel, integer edge functions ([`rasterize_triangle`]): for
    /// pictures, where a centre shared by two faces a hair apart does not matter.
    Snapped,
    /// The triangles' own coordinates, exact predicates ([`rasterize_triangle_exact`]): for
    /// counting which faces cover a pixel.
    Exact,
}

impl Sampling {
    /// Calls `visit(x, y, l)` for every pixel centre of columns `0..width` and rows `rows` that
    /// the triangle `v` covers, sampled this way.
    pub(crate) fn rasterize(
        self,
        v: Tri2,
        width: u32,
        rows: Range<u32>,
        visit: impl FnMut(u32, u32, [f32; 3]),
    ) {
        match self {
            Sampling::Snapped => rasterize_triangle(v, width, rows, visit),
            Sampling::Exact => rasterize_triangle_exact(v, width, rows, visit),
        }
    }
}

/// Rasterises triangles `0..count` into `pixels` (`width × height`, row-major), calling
/// `shade(pixel, triangle, barycentrics)` for every covered pixel. `vertices(i)` gives triangle
/// `i` in pixel space, or `None` to skip it. Parallel over bands of rows, deterministic (module docs).
pub(crate) fn raster_parallel<P: Send>(
    width: u32,
    height: u32,
    pixels: &mut [P],
    count: usize,
    sampling: Sampling,
    vertices: impl Fn(usize) -> Option<Tri2> + Sync,
    shade: impl Fn(&mut P, usize, [f32; 3]) + Sync,
) {
    let (w, h) = (width as usize, height as usize);
    assert_eq!(pixels.len(), w * h, "pixel buffer does not match {width}x{height}");
    if w == 0 || h == 0 {
        return;
    }
    let bands = h.div_ceil(BAND_ROWS);
    // bins[chunk][band]: triangles of that chunk touching that band, in increasing order.
    let bins: Vec<Vec<Vec<u32>>> = (0..count.div_ceil(BIN_CHUNK))
        .into_par_iter()
        .map(|c| {
            let mut out = vec![Vec::new(); bands];
            for i in c * BIN_CHUNK..count.min((c + 1) * BIN_CHUNK) {
                if let Some(r) = vertices(i).and_then(|v| band_range(v, h)) {
                    for band in &mut out[r] {
                        band.push(i as u32);
                    }
                }
            }
            out
        })
        .collect();
    pixels.par_chunks_mut(BAND_ROWS * w).enumerate().for_each(|(b, band)| {
        let y0 = b * BAND_ROWS;
        let rows = y0 as u32..(y0 + band.len() / w) as u32;
        for &i in bins.iter().flat_map(|chunk| &chunk[b]) {
            let i = i as usize;
            if let Some(v) = vertices(i) {
                sampling.rasterize(v, width, rows.clone(), |x, y, l| {
                    shade(&mut band[(y as usize - y0) * w + x as usize], i, l)
                });
            }
        }
    });
}

/// The bands a triangle may touch (conservative; the rasteriser clips exactly), `None` if none.
fn band_range(v: Tri2, height: usize) -> Option<Range<usize>> {
    let ys = v.map(|q| q[1]);
    let (lo, hi) = (ys[0].min(ys[1]).min(ys[2]), ys[0].max(ys[1]).max(ys[2]));
    if !(lo.is_finite() && hi.is_finite()) || hi < 0.0 || lo > height as f32 {
        return None;
    }
    let first = (lo.max(0.0) as usize).saturating_sub(1) / BAND_ROWS;
    let last = (hi.min(height as f32) as usize + 1).min(height - 1) / BAND_ROWS;
    Some(first..last + 1)
}

fn snap(v: Tri2) -> Option<[[i64; 2]; 3]> {
    let mut p = [[0i64; 2]; 3];
    for k in 0..3 {
        for c in 0..2 {
            let x = v[k][c];
            if !x.is_finite() || x.abs() >= MAX_PIXEL_COORD {
                return None;
            }
            p[k][c] = (x as f64 * SUB as f64).round() as i64;
        }
    }
    Some(p)
}

/// Twice the signed area of `(a, b, c)`, exact.
fn edge(a: [i64; 2], b: [i64; 2], c: [i64; 2]) -> i64 {
    (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
}

#[cfg(test)]
mod tests {
    use super::*;

    /// How many of `tris` cover each pixel centre of a `w × h` image, sampled as `sampling` says.
    fn sampled_coverage(sampling: Sampling, tris: &[Tri2], w: u32, h: u32) -> Vec<u32> {
        let mut count = vec![0u32; (w * h) as usize];
        for &t in tris {
            sampling.rasterize(t, w, 0..h, |x, y, _| count[(y * w + x) as usize] += 1);
        }
        count
    }

    fn coverage(tris: &[Tri2], w: u32, h: u32) -> Vec<u32> {
        sampled_coverage(Sampling::Snapped, tris, w, h)
    }

    fn exact_coverage(tris: &[Tri2], w: u32, h: u32) -> Vec<u32> {
        sampled_coverage(Sampling::Exact, tris, w, h)
    }

    #[test]
    fn pixel_aligned_square_is_covered_exactly_once() {
        // Two triangles sharing a diagonal through pixel centres' corners, edges on pixel borders.
        let q = [[2.0, 3.0], [12.0, 3.0], [12.0, 9.0], [2.0, 9.0]];
        let c = coverage(&[[q[0], q[1], q[2]], [q[0], q[2], q[3]]], 16, 16);
        assert_eq!(c.iter().filter(|&&n| n == 1).count(), 60);
        assert!(c.iter().all(|&n| n <= 1));
        assert_eq!(c[(3 * 16 + 2) as usize], 1);
        assert_eq!(c[(9 * 16 + 2) as usize], 0);
    }

    #[test]
    fn samples_on_shared_edges_and_vertices_are_owned_once() {
        // A fan around a vertex sitting exactly on a pixel centre, with edges through centres.
        let c0 = [5.5, 5.5];
        let ring = [
            [0.5, 0.5],
            [5.5, 0.5],
            [10.5, 0.5],
            [10.5, 5.5],
            [10.5, 10.5],
            [5.5, 10.5],
            [0.5, 10.5],
            [0.5, 5.5],
        ];
        let tris: Vec<Tri2> = (0..8).map(|i| [c0, ring[i], ring[(i + 1) % 8]]).collect();
        let c = coverage(&tris, 12, 12);
        assert!(c.iter().all(|&n| n <= 1), "a sample was covered twice");
        // Interior of the 10x10 square of centres (0.5..10.5): the half-open rule keeps 10x10.
        assert_eq!(c.iter().filter(|&&n| n == 1).count(), 100);
        // Either winding gives the same coverage.
        let flipped: Vec<Tri2> = tris.iter().map(|t| [t[0], t[2], t[1]]).collect();
        assert_eq!(coverage(&flipped, 12, 12), c);
    }

    #[test]
    fn barycentrics_reconstruct_the_sample_point() {
        let t = [[1.3, 2.1], [17.8, 4.4], [6.2, 15.9]];
        rasterize_triangle(t, 20, 0..20, |x, y, l| {
            let px = l[0] * t[0][0] + l[1] * t[1][0] + l[2] * t[2][0];
            let py = l[0] * t[0][1] + l[1] * t[1][1] + l[2] * t[2][1];
            assert!((px - (x as f32 + 0.5)).abs() < 1e-2 && (py - (y as f32 + 0.5)).abs() < 1e-2);
            assert!(l.iter().all(|&c| c >= -1e-6) && (l.iter().sum::<f32>() - 1.0).abs() < 1e-5);
        });
    }

    #[test]
    fn parallel_raster_matches_serial_and_keeps_index_order() {
        // Many overlapping triangles; the per-pixel "first writer" must be the lowest index.
        let tris: Vec<Tri2> = (0..300)
            .map(|i| {
                let o = (i % 37) as f32 * 1.7;
                [[o, o * 0.5], [o + 40.0, o * 0.9 + 3.0], [o * 0.3 + 5.0, o + 50.0]]
            })
            .collect();
        let (w, h) = (70u32, 90u32);
        for sampling in [Sampling::Snapped, Sampling::Exact] {
            let mut first = vec![u32::MAX; (w * h) as usize];
            raster_parallel(
                w,
                h,
                &mut first,
                tris.len(),
                sampling,
                |i| Some(tris[i]),
                |p, i, _| {
                    if *p == u32::MAX {
                        *p = i as u32
                    }
                },
            );
            let mut serial = vec![u32::MAX; (w * h) as usize];
            for (i, &t) in tris.iter().enumerate() {
                sampling.rasterize(t, w, 0..h, |x, y, _| {
                    let p = &mut serial[(y * w + x) as usize];
                    if *p == u32::MAX {
                        *p = i as u32
                    }
                });
            }
            assert_eq!(first, serial, "{sampling:?}");
        }
    }

    /// Two faces that share a vertex and lie on either side of a thin wedge (their near-parallel
    /// edges 10⁻³·⁵–10⁻¹·⁵ pixel apart at their far ends, as along a marching-cubes mesh's
    /// slivers): their interiors are disjoint, so exact sampling never lets both cover a centre;
    /// snapped sampling can (the pair from a real atlas at the end: why counting takes exact
    /// sampling).
    #[test]
    fn faces_a_hair_apart_never_share_a_centre_when_sampled_exactly() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        let (w, h) = (24u32, 24u32);
        let mut cases = 0;
        for _ in 0..3000 {
            let s = [rng.random_range(4.0..20.0f64), rng.random_range(4.0..20.0f64)];
            let angle = rng.random_range(0.0..std::f64::consts::TAU);
            let length = rng.random_range(2.0..8.0);
            // The gap at the far end, in pixels; the second edge turned clockwise by it.
            let gap = 10f64.powf(rng.random_range(-3.5..-1.5));
            let turn = gap / length;
            let dir = |a: f64| [a.cos(), a.sin()];
            let (d1, d2) = (dir(angle), dir(angle - turn));
            let at = |d: [f64; 2], t: f64| [s[0] + d[0] * t, s[1] + d[1] * t];
            let left = dir(angle + 1.2);
            let right = dir(angle - turn - 1.2);
            let f = |p: [f64; 2]| p.map(|x| x as f32);
            let a: Tri2 = [f(s), f(at(d1, length)), f(at(left, length))];
            let b: Tri2 = [f(s), f(at(right, length)), f(at(d2, length))];
            // f32 rounding may close the wedge: keep only the pairs still apart in f32, checked
            // exactly (the far ends on the right sides of each other's edge).
            let side = |o: [f32; 2], e: [f32; 2], q: [f32; 2]| {
                robust::orient2d(
                    robust::Coord { x: o[0] as f64, y: o[1] as f64 },
                    robust::Coord { x: e[0] as f64, y: e[1] as f64 },
                    robust::Coord { x: q[0] as f64, y: q[1] as f64 },
                )
            };
            if !(side(a[0], a[1], b[2]) < 0.0 && side(b[0], b[2], a[1]) > 0.0) {
                continue;
            }
            cases += 1;
            let exact = exact_coverage(&[a, b], w, h);
            assert!(exact.iter().all(|&n| n <= 1), "exact sampling counted an overlap: {a:?} {b:?}");
        }
        assert!(cases > 1000, "{cases} cases");
        // Two faces of an unwrapped marching-cubes bunny (faces 337318 and 337319 of the suite's
        // `unruly_bunny` atlas, its UVs as written, at 1024²): they share a vertex, and their
        // near-parallel edges end 0.015 pixel apart. Snapped, both cover the centre of texel
        // (966, 903); exactly, one does.
        let px = |u: f32, v: f32| [u * 1024.0, (1.0 - v) * 1024.0];
        let a: Tri2 = [px(0.94395614, 0.11589566), px(0.94380766, 0.11832395), px(0.9427842, 0.11736916)];
        let b: Tri2 = [px(0.9446356, 0.11790011), px(0.943809, 0.1183098), px(0.94395614, 0.11589566)];
        let texel = (903 * 1024 + 966) as usize;
        assert_eq!(coverage(&[a, b], 1024, 1024)[texel], 2, "snapping no longer overlaps them");
        assert_eq!(exact_coverage(&[a, b], 1024, 1024)[texel], 1);
        assert!(exact_coverage(&[a, b], 1024, 1024).iter().all(|&n| n <= 1));
    }

    /// Two triangles sharing an edge (the same coordinates at both ends) cover every centre of
    /// their union once, centres exactly on the shared edge included, in either winding.
    #[test]
    fn exact_sampling_covers_a_shared_edge_once() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(12);
        // The diagonal of a square through pixel centres, and random quads split along a diagonal.
        let mut quads = vec![[[2.5f32, 2.5], [10.5, 2.5], [10.5, 10.5], [2.5, 10.5]]];
        for _ in 0..200 {
            let c = [rng.random_range(4.0..12.0f32), rng.random_range(4.0..12.0f32)];
            let mut r = |k: f32| [c[0] + k * rng.random_range(1.0..4.0f32), c[1]];
            let (p0, p2) = (r(-1.0), r(1.0));
            let p1 = [c[0] + rng.random_range(-1.0..1.0f32), c[1] - rng.random_range(1.0..4.0f32)];
            let p3 = [c[0] + rng.random_range(-1.0..1.0f32), c[1] + rng.random_range(1.0..4.0f32)];
            quads.push([p0, p1, p2, p3]);
        }
        for q in quads {
            let halves = [[q[0], q[1], q[2]], [q[0], q[2], q[3]]];
            let c = exact_coverage(&halves, 16, 16);
            assert!(c.iter().all(|&n| n <= 1), "{q:?}");
            let flipped: Vec<Tri2> = halves.iter().map(|t| [t[0], t[2], t[1]]).collect();
            assert_eq!(exact_coverage(&flipped, 16, 16), c, "{q:?}");
        }
        // Every centre on the square's diagonal (x = y) is covered once.
        let q = [[2.5f32, 2.5], [10.5, 2.5], [10.5, 10.5], [2.5, 10.5]];
        let c = exact_coverage(&[[q[0], q[1], q[2]], [q[0], q[2], q[3]]], 16, 16);
        assert!((2..10).all(|i| c[(i * 16 + i) as usize] == 1), "{c:?}");
    }

    #[test]
    fn exact_sampling_agrees_with_snapped_away_from_edges_and_gives_barycentrics() {
        let t: Tri2 = [[1.3, 2.1], [17.8, 4.4], [6.2, 15.9]];
        assert_eq!(exact_coverage(&[t], 20, 20), coverage(&[t], 20, 20));
        rasterize_triangle_exact(t, 20, 0..20, |x, y, l| {
            let px = l[0] * t[0][0] + l[1] * t[1][0] + l[2] * t[2][0];
            let py = l[0] * t[0][1] + l[1] * t[1][1] + l[2] * t[2][1];
            assert!((px - (x as f32 + 0.5)).abs() < 1e-3 && (py - (y as f32 + 0.5)).abs() < 1e-3);
        });
        assert!(exact_coverage(&[[[1.0, 1.0], [5.0, 5.0], [9.0, 9.0]]], 10, 10).iter().all(|&n| n == 0));
        assert!(exact_coverage(&[[[f32::NAN, 1.0], [5.0, 5.0], [9.0, 1.0]]], 10, 10).iter().all(|&n| n == 0));
        // Far outside the image: nothing, and no loop over its bounding box.
        assert!(
            exact_coverage(&[[[-1e30, -1e30], [1e30, -1e30], [0.0, -1e29]]], 10, 10).iter().all(|&n| n == 0)
        );
    }

    #[test]
    fn degenerate_and_non_finite_triangles_cover_nothing() {
        assert!(coverage(&[[[1.0, 1.0], [5.0, 5.0], [9.0, 9.0]]], 10, 10).iter().all(|&n| n == 0));
        assert!(coverage(&[[[f32::NAN, 1.0], [5.0, 5.0], [9.0, 1.0]]], 10, 10).iter().all(|&n| n == 0));
    }
}

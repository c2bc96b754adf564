//! The one triangle rasteriser of the crate, shared by the screen-space renderer ([`mod@crate::render`]),
//! the UV-space coverage raster ([`crate::uvstats`]) and the UV layout picture
//! ([`crate::pictures`]). They are the same operation: "which pixel centres does this 2-D triangle
//! cover, and with which barycentrics", followed by a per-pixel update that differs.
//!
//! **Coverage rule.** Vertices are snapped to 1/256 pixel (fixed point) and edge functions are
//! evaluated exactly in integers, with a tie-breaking rule equivalent to nudging every sample point by
//! the same infinitesimal offset. Consequence (relied on by overlap counting): in a mesh without
//! overlaps every pixel centre is covered by **exactly one** triangle, even centres lying exactly on
//! a shared edge or vertex. Triangles of zero area cover nothing; orientation does not matter (back
//! faces are rasterised).
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

/// Rasterises triangles `0..count` into `pixels` (`width × height`, row-major), calling
/// `shade(pixel, triangle, barycentrics)` for every covered pixel. `vertices(i)` gives triangle
/// `i` in pixel space, or `None` to skip it. Parallel over bands of rows, deterministic (module docs).
pub(crate) fn raster_parallel<P: Send>(
    width: u32,
    height: u32,
    pixels: &mut [P],
    count: usize,
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
                rasterize_triangle(v, width, rows.clone(), |x, y, l| {
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

    fn coverage(tris: &[Tri2], w: u32, h: u32) -> Vec<u32> {
        let mut count = vec![0u32; (w * h) as usize];
        for &t in tris {
            rasterize_triangle(t, w, 0..h, |x, y, _| count[(y * w + x) as usize] += 1);
        }
        count
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
        let mut first = vec![u32::MAX; (w * h) as usize];
        raster_parallel(
            w,
            h,
            &mut first,
            tris.len(),
            |i| Some(tris[i]),
            |p, i, _| {
                if *p == u32::MAX {
                    *p = i as u32
                }
            },
        );
        let mut serial = vec![u32::MAX; (w * h) as usize];
        for (i, &t) in tris.iter().enumerate() {
            rasterize_triangle(t, w, 0..h, |x, y, _| {
                let p = &mut serial[(y * w + x) as usize];
                if *p == u32::MAX {
                    *p = i as u32
                }
            });
        }
        assert_eq!(first, serial);
    }

    #[test]
    fn degenerate_and_non_finite_triangles_cover_nothing() {
        assert!(coverage(&[[[1.0, 1.0], [5.0, 5.0], [9.0, 9.0]]], 10, 10).iter().all(|&n| n == 0));
        assert!(coverage(&[[[f32::NAN, 1.0], [5.0, 5.0], [9.0, 1.0]]], 10, 10).iter().all(|&n| n == 0));
    }
}

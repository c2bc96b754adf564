//! Baking a colour texture through a mesh's UVs: every texel an island covers takes the colour of
//! the surface point it maps to, so the appearance of the input (vertex colours, its own textures,
//! coloured points) carries over into the new atlas (issue 22).
//!
//! **Sampling.** Each texel is split into `supersampling²` sub-texel points; a point inside a
//! face's UV triangle takes the source's colour at that face and barycentrics (and the 3-D point
//! they give), and the texel is the mean of its points that some face covers. Points outside every
//! triangle do not count, so a texel on an island's edge is not darkened by the empty space
//! beside it.
//!
//! **Edge texels.** A texel that a face's UV triangle touches (its centre within half a texel
//! diagonal of the triangle) but none of whose points it covers (slivers, thin islands) takes the
//! colour at the point of the nearest such triangle closest to the texel centre: every texel that
//! a surface point maps to has a surface colour, never the background.
//!
//! **Gutters.** Every other texel is then filled ring by ring from its coloured neighbours (the
//! mean of the 8-neighbours filled in earlier rings), until the whole image is filled. Bilinear
//! filtering and every mip level then read surface colours only, whatever the gutter: no
//! background bleeds in at seams. (A mip level coarser than the gutter mixes neighbouring islands'
//! colours; only a wider `output.gutter` avoids that.)
//!
//! **Determinism.** The image is split into bands of rows processed in parallel; inside a band,
//! faces are visited in increasing index order and every sum is taken in that order, so the
//! texture is the same bytes for any thread count. Image conventions are [`crate::pictures`]':
//! row 0 at `v = 1`.

use nuvo_geometry::TriMesh;
use rayon::prelude::*;
use serde::Serialize;

use crate::error::AtlasError;
use crate::pictures::RgbImage;
use crate::uvstats::require_uv;

/// Rows of texels per band of the parallel bake.
const BAND_ROWS: usize = 16;
/// The largest texture side (the PNG and glTF limits are far above; memory is the bound here).
pub const MAX_RESOLUTION: u32 = 16384;
/// The most sub-texel points per texel side.
pub const MAX_SUPERSAMPLING: u32 = 8;

/// The colour of the surface being textured, asked for at a point of one of its faces.
pub trait SurfaceColour: Sync {
    /// RGB in `[0, 1]` at barycentrics `bary` of face `face` of the mesh being textured; `point`
    /// is the 3-D point they give (the mesh's own coordinates), for sources that look colour up
    /// by position rather than by face.
    fn colour(&self, face: usize, bary: [f32; 3], point: [f32; 3]) -> [f32; 3];
}

impl<F: Fn(usize, [f32; 3], [f32; 3]) -> [f32; 3] + Sync> SurfaceColour for F {
    fn colour(&self, face: usize, bary: [f32; 3], point: [f32; 3]) -> [f32; 3] {
        self(face, bary, point)
    }
}

/// How to bake.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TextureOptions {
    /// Side of the square texture in texels, `1..=`[`MAX_RESOLUTION`].
    pub resolution: u32,
    /// Sub-texel points per texel side, `1..=`[`MAX_SUPERSAMPLING`] (2: four points a texel).
    pub supersampling: u32,
}

impl Default for TextureOptions {
    fn default() -> Self {
        TextureOptions { resolution: 2048, supersampling: 2 }
    }
}

/// What the bake did, texel by texel.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct TextureReport {
    /// Side of the texture in texels.
    pub resolution: u32,
    /// Sub-texel points per texel side.
    pub supersampling: u32,
    /// Texels with at least one sub-texel point inside a face.
    pub covered_texels: usize,
    /// Texels a face touches without covering any of their points (coloured at its closest point).
    pub edge_texels: usize,
    /// Texels filled from their neighbours (gutters and empty space).
    pub filled_texels: usize,
    /// Faces with a (numerically) zero-area UV triangle, which no texel can show.
    pub degenerate_faces: usize,
}

/// The texture and its report.
#[derive(Clone, Debug)]
pub struct BakedTexture {
    /// The texture, `resolution²`, row 0 at `v = 1`.
    pub image: RgbImage,
    /// What was done.
    pub report: TextureReport,
}

/// One face's UV triangle in texel space (`x` right, `y` down), ready for barycentric lookups.
struct TexelTriangle {
    /// Corners in texel units.
    q: [[f64; 2]; 3],
    /// The inverse of `[q1 − q0, q2 − q0]`, rows giving `(λ1, λ2)` from `p − q0`.
    inverse: [[f64; 2]; 2],
    /// Texel columns and rows of the bounding box, inclusive, clamped to the image.
    x: (u32, u32),
    y: (u32, u32),
}

impl TexelTriangle {
    fn new(q: [[f64; 2]; 3], resolution: u32) -> Option<TexelTriangle> {
        let (e1, e2) = ([q[1][0] - q[0][0], q[1][1] - q[0][1]], [q[2][0] - q[0][0], q[2][1] - q[0][1]]);
        let det = e1[0] * e2[1] - e1[1] * e2[0];
        if det.abs() < 1e-12 || !det.is_finite() {
            return None;
        }
        let inverse = [[e2[1] / det, -e2[0] / det], [-e1[1] / det, e1[0] / det]];
        // Texels whose centre may lie within half a diagonal of the triangle.
        let reach = std::f64::consts::FRAC_1_SQRT_2;
        let span = |k: usize| {
            let lo = q.iter().map(|p| p[k]).fold(f64::INFINITY, f64::min) - reach;
            let hi = q.iter().map(|p| p[k]).fold(f64::NEG_INFINITY, f64::max) + reach;
            let last = resolution as f64 - 1.0;
            // Texel i has its centre at i + 0.5.
            let (a, b) = ((lo - 0.5).ceil().max(0.0), (hi - 0.5).floor().min(last));
            (a <= b).then_some((a as u32, b as u32))
        };
        Some(TexelTriangle { q, inverse, x: span(0)?, y: span(1)? })
    }

    /// Barycentrics of texel-space point `p`.
    fn barycentrics(&self, p: [f64; 2]) -> [f64; 3] {
        let d = [p[0] - self.q[0][0], p[1] - self.q[0][1]];
        let l1 = self.inverse[0][0] * d[0] + self.inverse[0][1] * d[1];
        let l2 = self.inverse[1][0] * d[0] + self.inverse[1][1] * d[1];
        [1.0 - l1 - l2, l1, l2]
    }

    /// The point of the triangle closest to `p`, as barycentrics, and its squared distance.
    fn closest(&self, p: [f64; 2]) -> ([f64; 3], f64) {
        let l = self.barycentrics(p);
        if l.iter().all(|&x| x >= 0.0) {
            return (l, 0.0);
        }
        // Outside: the closest point lies on one of the three edges.
        let mut best = ([1.0, 0.0, 0.0], f64::INFINITY);
        for k in 0..3 {
            let (i, j) = ((k + 1) % 3, (k + 2) % 3);
            let (a, b) = (self.q[i], self.q[j]);
            let ab = [b[0] - a[0], b[1] - a[1]];
            let len2 = ab[0] * ab[0] + ab[1] * ab[1];
            let t = if len2 > 0.0 {
                (((p[0] - a[0]) * ab[0] + (p[1] - a[1]) * ab[1]) / len2).clamp(0.0, 1.0)
            } else {
                0.0
            };
            let c = [a[0] + t * ab[0], a[1] + t * ab[1]];
            let d2 = (p[0] - c[0]).powi(2) + (p[1] - c[1]).powi(2);
            if d2 < best.1 {
                let mut l = [0.0; 3];
                l[i] = 1.0 - t;
                l[j] = t;
                best = (l, d2);
            }
        }
        best
    }
}

/// One texel's accumulators during a band's pass.
#[derive(Clone, Copy, Default)]
struct Texel {
    sum: [f32; 3],
    samples: u32,
    /// The colour at the closest point of the nearest touching face, and its squared distance.
    edge: Option<([f32; 3], f64)>,
}

/// Bakes `colour` into a `resolution²` texture through `mesh`'s UVs (module docs).
///
/// Errors when the mesh has no UVs or the options are out of range. UVs outside `[0, 1]²` are
/// clipped to the image (they do not wrap). Memory: about 20 bytes a texel besides the image
/// (2048²: 84 MB; 16384²: 5.4 GB) and 100 bytes a face.
pub fn bake_texture(
    mesh: &TriMesh,
    colour: &dyn SurfaceColour,
    opts: &TextureOptions,
) -> Result<BakedTexture, AtlasError> {
    let uv = require_uv(mesh)?;
    let TextureOptions { resolution: res, supersampling: s } = *opts;
    if !(1..=MAX_RESOLUTION).contains(&res) {
        return Err(AtlasError::invalid(
            "texture resolution",
            format!("{res} is not in 1..={MAX_RESOLUTION}"),
        ));
    }
    if !(1..=MAX_SUPERSAMPLING).contains(&s) {
        return Err(AtlasError::invalid(
            "texture supersampling",
            format!("{s} is not in 1..={MAX_SUPERSAMPLING}"),
        ));
    }
    let r = res as f64;
    let triangles: Vec<Option<TexelTriangle>> = (0..mesh.triangles.len())
        .into_par_iter()
        .map(|f| {
            let q = uv.triangles[f].map(|i| {
                let [u, v] = uv.coords[i as usize];
                [u as f64 * r, (1.0 - v as f64) * r]
            });
            TexelTriangle::new(q, res)
        })
        .collect();
    let degenerate_faces = triangles.iter().filter(|t| t.is_none()).count();
    let (w, bands) = (res as usize, (res as usize).div_ceil(BAND_ROWS));
    let mut bins: Vec<Vec<u32>> = vec![Vec::new(); bands];
    for (f, t) in triangles.iter().enumerate() {
        if let Some(t) = t {
            for bin in &mut bins[t.y.0 as usize / BAND_ROWS..=t.y.1 as usize / BAND_ROWS] {
                bin.push(f as u32);
            }
        }
    }
    let offsets: Vec<f64> = (0..s).map(|i| (i as f64 + 0.5) / s as f64).collect();
    let half_diagonal2 = 0.5;
    // Each band's accumulators become colours as soon as the band is done: the whole image is
    // held only as an `Option<[f32; 3]>` per texel (16 bytes; 2048²: 67 MB).
    let (mut colours, sources): (Vec<Option<[f32; 3]>>, Vec<TexelSource>) = bins
        .par_iter()
        .enumerate()
        .flat_map_iter(|(b, faces)| {
            let y0 = b * BAND_ROWS;
            let rows = BAND_ROWS.min(w - y0);
            let mut band = vec![Texel::default(); rows * w];
            for &f in faces {
                let f = f as usize;
                let t = triangles[f].as_ref().expect("binned faces have a triangle");
                let corners = mesh.corners(f);
                let point = |l: [f64; 3]| -> [f32; 3] {
                    std::array::from_fn(|k| (0..3).map(|c| l[c] * corners[c][k] as f64).sum::<f64>() as f32)
                };
                let shade = |l: [f64; 3]| colour.colour(f, l.map(|x| x as f32), point(l));
                let (ya, yb) = ((t.y.0 as usize).max(y0), (t.y.1 as usize).min(y0 + rows - 1));
                for y in ya..=yb {
                    for x in t.x.0 as usize..=t.x.1 as usize {
                        let texel = &mut band[(y - y0) * w + x];
                        let mut hit = false;
                        for &oy in &offsets {
                            for &ox in &offsets {
                                let l = t.barycentrics([x as f64 + ox, y as f64 + oy]);
                                if l.iter().all(|&c| c >= 0.0) {
                                    for (sum, c) in texel.sum.iter_mut().zip(shade(l)) {
                                        *sum += c;
                                    }
                                    texel.samples += 1;
                                    hit = true;
                                }
                            }
                        }
                        if hit || texel.samples > 0 {
                            continue;
                        }
                        let (l, d2) = t.closest([x as f64 + 0.5, y as f64 + 0.5]);
                        if d2 <= half_diagonal2 && texel.edge.is_none_or(|(_, best)| d2 < best) {
                            texel.edge = Some((shade(l), d2));
                        }
                    }
                }
            }
            band.into_iter().map(|t| {
                if t.samples > 0 {
                    (Some(t.sum.map(|c| c / t.samples as f32)), TexelSource::Covered)
                } else {
                    (
                        t.edge.map(|(c, _)| c),
                        if t.edge.is_some() { TexelSource::Edge } else { TexelSource::Empty },
                    )
                }
            })
        })
        .unzip();
    let mut report =
        TextureReport { resolution: res, supersampling: s, degenerate_faces, ..Default::default() };
    report.covered_texels = sources.iter().filter(|&&k| k == TexelSource::Covered).count();
    report.edge_texels = sources.iter().filter(|&&k| k == TexelSource::Edge).count();
    drop(sources);
    report.filled_texels = fill_from_neighbours(&mut colours, w);
    let to_byte = |c: f32| (c.clamp(0.0, 1.0) * 255.0).round() as u8;
    let raw: Vec<u8> = colours.iter().flat_map(|c| c.unwrap_or(EMPTY).map(to_byte)).collect();
    let image = RgbImage::from_raw(res, res, raw).expect("one RGB triple per texel");
    Ok(BakedTexture { image, report })
}

/// Where a texel's colour came from in the band pass (one byte a texel, for the report).
#[derive(Clone, Copy, PartialEq, Eq)]
enum TexelSource {
    /// Sub-texel points inside faces.
    Covered,
    /// The closest point of a face that grazes it.
    Edge,
    /// Nothing yet: filled from its neighbours.
    Empty,
}

/// The colour of an image no face covers at all (nothing to fill from).
const EMPTY: [f32; 3] = [0.5, 0.5, 0.5];

/// Fills every `None` of the `width`-wide image ring by ring: a texel next to (8-neighbourhood)
/// filled ones takes their mean, and the next ring starts from it. Returns how many were filled.
/// Deterministic: each ring reads only earlier rings, in texel order.
fn fill_from_neighbours(colours: &mut [Option<[f32; 3]>], width: usize) -> usize {
    let height = colours.len() / width.max(1);
    let neighbours = |i: usize| {
        let (x, y) = ((i % width) as isize, (i / width) as isize);
        (-1isize..=1)
            .flat_map(move |dy| (-1isize..=1).map(move |dx| (x + dx, y + dy)))
            .filter(move |&(nx, ny)| {
                (nx, ny) != (x, y) && nx >= 0 && ny >= 0 && (nx as usize) < width && (ny as usize) < height
            })
            .map(move |(nx, ny)| ny as usize * width + nx as usize)
    };
    let mut queued = vec![false; colours.len()];
    let mut ring: Vec<usize> = Vec::new();
    for i in 0..colours.len() {
        if colours[i].is_none() && neighbours(i).any(|n| colours[n].is_some()) {
            queued[i] = true;
            ring.push(i);
        }
    }
    let mut filled = 0;
    while !ring.is_empty() {
        let values: Vec<[f32; 3]> = ring
            .iter()
            .map(|&i| {
                let (mut sum, mut count) = ([0f32; 3], 0f32);
                for c in neighbours(i).filter_map(|n| colours[n]) {
                    for k in 0..3 {
                        sum[k] += c[k];
                    }
                    count += 1.0;
                }
                sum.map(|c| c / count)
            })
            .collect();
        for (&i, v) in ring.iter().zip(values) {
            colours[i] = Some(v);
        }
        filled += ring.len();
        let mut next = Vec::new();
        for &i in &ring {
            for n in neighbours(i) {
                if colours[n].is_none() && !queued[n] {
                    queued[n] = true;
                    next.push(n);
                }
            }
        }
        next.sort_unstable();
        ring = next;
    }
    filled
}

/// The mip level `level` of `image` (each texel the mean of a `2^level`-square block, as a GPU's
/// box-filtered mip chain), for checking what a renderer sees from afar.
pub fn mip_level(image: &RgbImage, level: u32) -> RgbImage {
    let block = 1u32 << level.min(16);
    let (w, h) = (image.width().div_ceil(block).max(1), image.height().div_ceil(block).max(1));
    RgbImage::from_fn(w, h, |x, y| {
        let (mut sum, mut n) = ([0u32; 3], 0u32);
        for yy in y * block..((y + 1) * block).min(image.height()) {
            for xx in x * block..((x + 1) * block).min(image.width()) {
                let p = image.get_pixel(xx, yy).0;
                for k in 0..3 {
                    sum[k] += p[k] as u32;
                }
                n += 1;
            }
        }
        image::Rgb(sum.map(|c| ((c + n / 2) / n.max(1)) as u8))
    })
}

#[cfg(test)]
mod tests {
    use nuvo_geometry::UvLayer;

    use super::*;

    /// Two unit squares side by side in 3-D (x in 0..1 and 2..3), each its own island in UV.
    fn two_islands(gap_texels: f32, res: u32) -> TriMesh {
        let positions = vec![
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [1.0, 1.0, 0.0],
            [0.0, 1.0, 0.0],
            [2.0, 0.0, 0.0],
            [3.0, 0.0, 0.0],
            [3.0, 1.0, 0.0],
            [2.0, 1.0, 0.0],
        ];
        let triangles = vec![[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]];
        let (a, g) = (0.1f32, gap_texels / res as f32);
        let coords = vec![
            [a, a],
            [0.45, a],
            [0.45, 0.9],
            [a, 0.9],
            [0.45 + g, a],
            [0.8 + g, a],
            [0.8 + g, 0.9],
            [0.45 + g, 0.9],
        ];
        TriMesh { positions, triangles: triangles.clone(), uv: Some(UvLayer { coords, triangles }) }
    }

    /// A smooth colour of the 3-D point (exact under averaging: it is affine).
    fn gradient(_: usize, _: [f32; 3], p: [f32; 3]) -> [f32; 3] {
        [p[0] / 3.0, p[1], 0.25]
    }

    #[test]
    fn covered_texels_take_the_surface_colour_and_every_texel_is_filled() {
        let mesh = two_islands(8.0, 128);
        let baked =
            bake_texture(&mesh, &gradient, &TextureOptions { resolution: 128, supersampling: 3 }).unwrap();
        let r = &baked.report;
        assert_eq!(r.covered_texels + r.edge_texels + r.filled_texels, 128 * 128, "{r:?}");
        assert!(r.covered_texels > 0 && r.filled_texels > 0 && r.degenerate_faces == 0, "{r:?}");
        // A texel well inside the first island: u = 0.25, v = 0.5 is 3-D point (0.43, 0.5) (affine map).
        let (x, y) = (32u32, 64u32);
        let u = (x as f32 + 0.5) / 128.0;
        let v = 1.0 - (y as f32 + 0.5) / 128.0;
        let p = [(u - 0.1) / 0.35, (v - 0.1) / 0.8, 0.0];
        let want = gradient(0, [0.0; 3], p).map(|c| (c * 255.0).round() as i32);
        let got = baked.image.get_pixel(x, y).0.map(i32::from);
        for k in 0..3 {
            assert!((got[k] - want[k]).abs() <= 1, "texel {got:?} vs surface {want:?}");
        }
    }

    #[test]
    fn the_same_texture_for_any_thread_count() {
        let mesh = two_islands(5.0, 96);
        let opts = TextureOptions { resolution: 96, supersampling: 2 };
        let one = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
        let a = one.install(|| bake_texture(&mesh, &gradient, &opts).unwrap().image);
        let b = bake_texture(&mesh, &gradient, &opts).unwrap().image;
        assert_eq!(a, b);
    }

    #[test]
    fn no_background_bleeds_into_mip_level_two_at_seams() {
        // A constant colour: after filling, every texel of every mip level is that colour, so a
        // renderer's trilinear lookup at an island's edge sees no background.
        let mesh = two_islands(4.0, 64);
        let colour = |_: usize, _: [f32; 3], _: [f32; 3]| [0.8, 0.2, 0.4];
        let baked =
            bake_texture(&mesh, &colour, &TextureOptions { resolution: 64, supersampling: 2 }).unwrap();
        let want = [204u8, 51, 102];
        for level in 0..=2 {
            let mip = mip_level(&baked.image, level);
            assert!(mip.pixels().all(|p| p.0 == want), "level {level} has a texel other than {want:?}");
        }
        // Without the fill, the same mip level would mix in the empty colour at the islands' edges.
        let mut unfilled = baked.image.clone();
        for (i, p) in unfilled.pixels_mut().enumerate() {
            let (x, y) = ((i % 64) as f32 + 0.5, (i / 64) as f32 + 0.5);
            let (u, v) = (x / 64.0, 1.0 - y / 64.0);
            let inside = (0.1..=0.9).contains(&v) && ((0.1..=0.45).contains(&u) || (0.5..=0.86).contains(&u));
            if !inside {
                p.0 = [0, 0, 0];
            }
        }
        assert!(mip_level(&unfilled, 2).pixels().any(|p| p.0 != want && p.0 != [0, 0, 0]));
    }

    #[test]
    fn a_sliver_too_thin_for_any_sample_still_colours_the_texels_it_crosses() {
        // A triangle 0.1 texel tall crossing 20 texels: no sample point of rows other than the
        // one it passes may be inside, but every texel it crosses must show its colour.
        let res = 32;
        let y = 16.5 / res as f32; // through the centres of row 15 (v up)
        let positions = vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.01, 0.0]];
        let coords =
            vec![[5.0 / res as f32, y], [25.0 / res as f32, y], [5.0 / res as f32, y + 0.1 / res as f32]];
        let triangles = vec![[0, 1, 2]];
        let mesh =
            TriMesh { positions, triangles: triangles.clone(), uv: Some(UvLayer { coords, triangles }) };
        let red = |_: usize, _: [f32; 3], _: [f32; 3]| [1.0, 0.0, 0.0];
        let baked = bake_texture(&mesh, &red, &TextureOptions { resolution: res, supersampling: 2 }).unwrap();
        assert!(baked.report.edge_texels > 0, "{:?}", baked.report);
        for x in 6..24 {
            assert_eq!(baked.image.get_pixel(x, 15).0, [255, 0, 0], "texel ({x}, 15)");
        }
    }

    #[test]
    fn out_of_range_options_and_missing_uvs_are_errors() {
        let mesh = two_islands(4.0, 64);
        let grey = |_: usize, _: [f32; 3], _: [f32; 3]| [0.5; 3];
        assert!(bake_texture(&mesh, &grey, &TextureOptions { resolution: 0, supersampling: 2 }).is_err());
        assert!(bake_texture(&mesh, &grey, &TextureOptions { resolution: 64, supersampling: 9 }).is_err());
        let bare = TriMesh { uv: None, ..mesh };
        assert!(matches!(
            bake_texture(&bare, &grey, &TextureOptions::default()),
            Err(AtlasError::NoUv { .. })
        ));
    }
}

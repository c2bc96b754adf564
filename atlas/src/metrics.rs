//! The paper's UV metrics (Nuvo, CVPR 2024, main text §"Metrics" and supplementary §"Metrics"),
//! computed from renders of the mesh over a set of views.
//!
//! Every view is rendered with [`crate::render()`]; each *hit pixel* sees one triangle `f` and has the
//! UV interpolated (perspective-correctly) at the visible point. Per view:
//!
//! - **Boundary** = 1 − (boundary pixels / hit pixels). A hit pixel is a *boundary pixel* when, for
//!   at least one of its 4-neighbours `q` that is also a hit, `|uv(p) − uv(q)| > uv_jump` (Euclidean,
//!   default 0.1) and the two are **not** across a depth discontinuity. Depth discontinuity:
//!   `|d(p) − d(q)| > depth_jump · min(d(p), d(q))` with `d` the view-space depth (default
//!   `depth_jump` 0.02, i.e. a 2 % relative jump; at 800 px and 40° a continuous surface only jumps
//!   that much when seen within ~2.5° of edge-on). Background neighbours and neighbours outside the
//!   image never make a pixel a boundary pixel.
//! - **Stretch**: per triangle `s = UV area / 3-D area`; over the hit pixels (each pixel contributes
//!   the `s` of its triangle: pixel-weighted), `m = median(s)` and
//!   Stretch = `max(0, 1 − median(|s/m − 1|))`. Dividing by `m` makes it scale-free (the paper's
//!   "difference to the median stretch" read relative to the median, so scaling all UVs does not
//!   change it). If `m = 0` (most pixels on UV-degenerate triangles) Stretch is 0.
//! - **Conformal**: per triangle, `T = ∂p/∂u` and `B = ∂p/∂v` of its affine UV→3-D map (the 3-D
//!   directions of +U and +V); Conformal = `1 − median |cos(T, B)|` over the hit pixels. A triangle
//!   degenerate in UV (area ≤ [`DEGENERATE_UV_AREA`]) has no such map and counts as `|cos| = 1`.
//! - **Editability** = Boundary × (Stretch + Conformal) / 2 (supplementary definition).
//!
//! Medians of an even number of samples are the mean of the two middle ones.
//!
//! **Degenerate 3-D triangles** (area ≤ [`crate::uvstats::DEGENERATE_AREA_REL`] × bounding-box
//! diagonal²) are skipped by Stretch and Conformal: pixels seeing them contribute no sample (they
//! still count for Boundary). They have no screen area, so in practice no pixel sees them.
//!
//! **Combining views**: each score is computed per view, then averaged over the views with at least
//! one measurable pixel (the paper reports per-image metrics averaged over a test set). Editability
//! is averaged per view too, so the reported Editability is not exactly the product of the reported
//! means.
//!
//! **Defaults** of [`EvalOptions`]: 16 views from [`crate::camera::orbit_views`] (uniform random
//! directions, seed 0, 40° vertical field of view, the bounding sphere filling the frame), 800 × 800
//! pixels, UV raster of 1024² for [`UvStats`].

use glam::DVec3;
use nuvo_geometry::{TriMesh, UvLayer};
use rayon::prelude::*;
use serde::Serialize;

use crate::camera::{Camera, MAX_IMAGE_SIDE, orbit_views};
use crate::error::AtlasError;
use crate::geom::to_dvec3;
use crate::partuv::{PartUvMetrics, partuv_metrics};
use crate::render::{GBuffer, render};
use crate::uvstats::{
    DEFAULT_UV_RASTER, DEGENERATE_UV_AREA, UvStats, analyse_uv, degenerate_3d_faces, require_uv, uv_charts,
};

/// Options of [`evaluate`]. `Default` gives the documented defaults.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct EvalOptions {
    /// Number of views (≥ 1).
    pub views: usize,
    /// Side of the square renders, in pixels.
    pub resolution: u32,
    /// Seed of the view directions.
    pub seed: u64,
    /// The image-space thresholds.
    #[serde(flatten)]
    pub image: ImageParams,
    /// Side of the UV raster for utilisation and overlap.
    pub uv_raster: u32,
}

impl Default for EvalOptions {
    fn default() -> Self {
        EvalOptions {
            views: 16,
            resolution: 800,
            seed: 0,
            image: ImageParams::default(),
            uv_raster: DEFAULT_UV_RASTER,
        }
    }
}

/// The thresholds of the Boundary metric (module docs).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct ImageParams {
    /// UV distance above which neighbouring pixels are on different charts (paper: 0.1).
    pub uv_jump: f32,
    /// Relative depth jump above which neighbouring pixels are on different surfaces.
    pub depth_jump: f32,
}

impl Default for ImageParams {
    fn default() -> Self {
        ImageParams { uv_jump: 0.1, depth_jump: 0.02 }
    }
}

/// Scores of one view.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ViewScores {
    /// Pixels that see the mesh.
    pub hit_pixels: usize,
    /// Hit pixels on a chart boundary.
    pub boundary_pixels: usize,
    /// `1 − boundary_pixels / hit_pixels`.
    pub boundary: f64,
    /// Stretch score of this view.
    pub stretch: f64,
    /// Conformal score of this view.
    pub conformal: f64,
    /// `boundary · (stretch + conformal) / 2`.
    pub editability: f64,
}

/// Image-space scores, averaged over the views that measured something.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ImageMetrics {
    /// Mean Boundary over the views used.
    pub boundary: f64,
    /// Mean Stretch over the views used.
    pub stretch: f64,
    /// Mean Conformal over the views used.
    pub conformal: f64,
    /// Mean per-view Editability over the views used.
    pub editability: f64,
    /// Views that contributed (a view seeing nothing measurable is skipped).
    pub views_used: usize,
    /// The scores of each view used, in camera order.
    pub per_view: Vec<ViewScores>,
}

/// Everything `nuvo eval` reports.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Metrics {
    /// The image-space scores.
    pub image: ImageMetrics,
    /// The UV-space statistics.
    pub uv: UvStats,
    /// The PartUV comparison's metric set (charts, seam length, angular score, area distortions,
    /// packing efficiency; [`crate::partuv`]).
    pub partuv: PartUvMetrics,
    /// The options that produced these numbers.
    pub options: EvalOptions,
}

impl EvalOptions {
    /// Checks that every option is in its domain.
    pub fn check(&self) -> Result<(), AtlasError> {
        let bad = |m: String| Err(AtlasError::invalid("evaluation options", m));
        if self.views == 0 || self.views > 100_000 {
            return bad(format!("views = {} is not in 1..=100000", self.views));
        }
        if self.resolution == 0 || self.resolution > MAX_IMAGE_SIDE {
            return bad(format!("resolution = {} is not in 1..={MAX_IMAGE_SIDE}", self.resolution));
        }
        if self.uv_raster == 0 || self.uv_raster > MAX_IMAGE_SIDE {
            return bad(format!("UV raster = {} is not in 1..={MAX_IMAGE_SIDE}", self.uv_raster));
        }
        self.image.check()
    }
}

impl ImageParams {
    /// Checks that both thresholds are positive and finite.
    pub fn check(&self) -> Result<(), AtlasError> {
        for (name, x) in [("uv_jump", self.uv_jump), ("depth_jump", self.depth_jump)] {
            if !(x > 0.0 && x.is_finite()) {
                return Err(AtlasError::invalid("evaluation options", format!("{name} = {x} must be > 0")));
            }
        }
        Ok(())
    }
}

/// All metrics of `mesh` (any frame) with its own UVs: image-space scores over the seeded orbit
/// views plus the UV-space statistics and the PartUV metric set ([`crate::partuv`]). Errors: no
/// UVs, an invalid mesh or options, nothing visible.
pub fn evaluate(mesh: &TriMesh, opts: &EvalOptions) -> Result<Metrics, AtlasError> {
    opts.check()?;
    require_uv(mesh)?;
    let bounds = mesh.bounds().ok_or(AtlasError::NothingVisible { views: opts.views })?;
    let cameras = orbit_views(&bounds, opts.views, opts.seed, opts.resolution, opts.resolution);
    let image = image_metrics(mesh, &cameras, &opts.image)?;
    let uv = analyse_uv(mesh, None, opts.uv_raster)?.stats;
    let partuv = partuv_metrics(mesh)?;
    Ok(Metrics { image, uv, partuv, options: *opts })
}

/// Boundary, Stretch, Conformal and Editability of `mesh` seen from `cameras` (module docs).
pub fn image_metrics(
    mesh: &TriMesh,
    cameras: &[Camera],
    params: &ImageParams,
) -> Result<ImageMetrics, AtlasError> {
    params.check()?;
    let uv = require_uv(mesh)?;
    let faces = face_distortion(mesh, uv);
    // The views are rendered and scored side by side (each also in parallel inside); their
    // scores come back in camera order, so the means are the same bits as one by one.
    let per_view: Vec<Option<ViewScores>> = cameras
        .par_iter()
        .map(|cam| Ok(view_scores(uv, &faces, None, &render(mesh, cam)?, params)))
        .collect::<Result<_, AtlasError>>()?;
    summarize_views(per_view.into_iter().flatten().collect(), cameras.len())
}

/// The Editability that each of `layouts` (UV layers of one mesh: the same positions and faces)
/// would score once its islands are packed apart, from one rendering of each view: a pixel is a
/// boundary pixel also where its neighbour sees another island (of
/// [`crate::uvstats::uv_charts`]), whatever their UV distance now. Islands that a pass leaves on
/// top of each other (the parts of a cut, before packing) then count as the seams they will be.
/// It is an estimate, for comparing layouts before packing: the packer may still set two islands
/// side by side across a seam closer than `uv_jump`, which the measured score would not count,
/// and Stretch is taken at the islands' texel densities as they are, which packing makes one.
/// Errors: a layout whose faces differ from `mesh`'s, no UVs, nothing visible.
pub fn unpacked_editability(
    mesh: &TriMesh,
    layouts: &[&TriMesh],
    cameras: &[Camera],
    params: &ImageParams,
) -> Result<Vec<f64>, AtlasError> {
    params.check()?;
    // Per layout: its UVs, each face's distortion, each face's island.
    type Scored<'a> = (&'a UvLayer, Vec<Option<[f32; 2]>>, Vec<u32>);
    let scored: Vec<Scored> = layouts
        .iter()
        .map(|m| {
            if m.triangles != mesh.triangles || m.positions != mesh.positions {
                return Err(AtlasError::invalid("layouts", "a layout's mesh differs from the one rendered"));
            }
            let uv = require_uv(m)?;
            Ok((uv, face_distortion(m, uv), uv_charts(m, uv).0))
        })
        .collect::<Result<_, _>>()?;
    // Per camera (in parallel, back in camera order), each layout's scores of its one rendering.
    let by_view: Vec<Vec<Option<ViewScores>>> = cameras
        .par_iter()
        .map(|cam| {
            let g = render(mesh, cam)?;
            Ok(scored
                .iter()
                .map(|(uv, faces, islands)| view_scores(uv, faces, Some(islands), &g, params))
                .collect())
        })
        .collect::<Result<_, AtlasError>>()?;
    (0..layouts.len())
        .map(|l| {
            let views: Vec<ViewScores> = by_view.iter().filter_map(|v| v[l].clone()).collect();
            Ok(summarize_views(views, cameras.len())?.editability)
        })
        .collect()
}

/// The means over the measured views (module docs), or [`AtlasError::NothingVisible`].
fn summarize_views(per_view: Vec<ViewScores>, cameras: usize) -> Result<ImageMetrics, AtlasError> {
    if per_view.is_empty() {
        return Err(AtlasError::NothingVisible { views: cameras });
    }
    let mean = |f: fn(&ViewScores) -> f64| per_view.iter().map(f).sum::<f64>() / per_view.len() as f64;
    Ok(ImageMetrics {
        boundary: mean(|v| v.boundary),
        stretch: mean(|v| v.stretch),
        conformal: mean(|v| v.conformal),
        editability: mean(|v| v.editability),
        views_used: per_view.len(),
        per_view,
    })
}

/// `1 − median(|s/m − 1|)` with `m = median(s)`, clamped to `[0, 1]`; 0 when `m = 0`. Reorders
/// `stretch`. Panics on an empty slice (callers only pass measured views).
pub fn stretch_score(stretch: &mut [f32]) -> f64 {
    let m = median(stretch);
    if m.is_nan() || m <= 0.0 {
        return 0.0;
    }
    let mut dev: Vec<f32> = stretch.iter().map(|&s| (s as f64 / m - 1.0).abs() as f32).collect();
    (1.0 - median(&mut dev)).clamp(0.0, 1.0)
}

/// `1 − median(abs_cos)`. Reorders `abs_cos`. Panics on an empty slice.
pub fn conformal_score(abs_cos: &mut [f32]) -> f64 {
    1.0 - median(abs_cos)
}

/// Per-face `[stretch, |cos(T, B)|]`, `None` for faces degenerate in 3-D (module docs).
fn face_distortion(mesh: &TriMesh, uv: &UvLayer) -> Vec<Option<[f32; 2]>> {
    let degenerate = degenerate_3d_faces(mesh);
    (0..mesh.triangles.len())
        .into_par_iter()
        .map(|f| {
            if degenerate[f] {
                return None;
            }
            let [a, b, c] = mesh.corners(f).map(to_dvec3);
            let (e1, e2) = (b - a, c - a);
            let area3 = 0.5 * e1.cross(e2).length();
            let [ua, ub, uc] = uv.triangles[f].map(|i| uv.coords[i as usize].map(|x| x as f64));
            let (du1, dv1, du2, dv2) = (ub[0] - ua[0], ub[1] - ua[1], uc[0] - ua[0], uc[1] - ua[1]);
            let area_uv = 0.5 * (du1 * dv2 - du2 * dv1).abs();
            let abs_cos = if area_uv <= DEGENERATE_UV_AREA {
                1.0
            } else {
                abs_cos_tangents(e1, e2, [du1, dv1, du2, dv2]).unwrap_or(1.0)
            };
            Some([(area_uv / area3) as f32, abs_cos as f32])
        })
        .collect()
}

/// `|cos(T, B)|` of a triangle with 3-D edges `e1 = p1 − p0`, `e2 = p2 − p0` and UV edges
/// `[du1, dv1, du2, dv2]` (`uv1 − uv0`, `uv2 − uv0`): `T = ∂p/∂u`, `B = ∂p/∂v`, the columns of the
/// Jacobian of its affine UV→3-D map. `None` when `T` or `B` vanishes (a UV-degenerate triangle, or
/// one degenerate in 3-D along a UV axis). The one formula of Conformal here and of the angular
/// score in [`crate::partuv`].
pub(crate) fn abs_cos_tangents(e1: DVec3, e2: DVec3, duv: [f64; 4]) -> Option<f64> {
    // T, B up to the common factor 1/det, which |cos| ignores.
    let (t, bt) = crate::uvstats::texture_axes(e1, e2, duv);
    let den = t.length() * bt.length();
    (den > 0.0).then(|| (t.dot(bt) / den).abs().min(1.0))
}

/// The boundary pixels of one rendered view (module docs, **Boundary**), in row-major order, each
/// as `(pixel, neighbour)`: its index in `g.pixels` and that of the first 4-neighbour (left,
/// right, up, down) that makes it one. With `islands` (one label per face), a neighbour that sees
/// another island counts whatever the UV distance ([`unpacked_editability`]). Public so that a
/// diagnosis can ask which faces, islands or pieces of a mesh a view's seams fall on (the
/// `boundary_sources` example); Boundary itself only counts them.
pub fn boundary_pixels(
    uv: &UvLayer,
    islands: Option<&[u32]>,
    g: &GBuffer,
    params: &ImageParams,
) -> Vec<(usize, usize)> {
    let (w, h) = (g.width as usize, g.height as usize);
    let uvp: Vec<[f32; 2]> = g
        .pixels
        .par_iter()
        .map(|p| match p.hit() {
            None => [f32::NAN; 2],
            Some(f) => {
                let t = uv.triangles[f as usize].map(|i| uv.coords[i as usize]);
                std::array::from_fn(|k| (0..3).map(|c| p.bary[c] * t[c][k]).sum())
            }
        })
        .collect();
    let jump2 = params.uv_jump * params.uv_jump;
    let is_boundary = |i: usize, j: usize| {
        let (p, q) = (&g.pixels[i], &g.pixels[j]);
        if q.hit().is_none() {
            return false;
        }
        let discontinuous = (p.depth - q.depth).abs() > params.depth_jump * p.depth.min(q.depth);
        let d = [uvp[i][0] - uvp[j][0], uvp[i][1] - uvp[j][1]];
        let apart = islands.is_some_and(|l| match (p.hit(), q.hit()) {
            (Some(a), Some(b)) => l[a as usize] != l[b as usize],
            _ => false,
        });
        !discontinuous && (apart || d[0] * d[0] + d[1] * d[1] > jump2)
    };
    (0..h)
        .into_par_iter()
        .flat_map_iter(|y| {
            let is_boundary = &is_boundary;
            (0..w).filter_map(move |x| {
                let i = y * w + x;
                g.pixels[i].hit()?;
                let left = (x > 0).then(|| i - 1);
                let right = (x + 1 < w).then(|| i + 1);
                let up = (y > 0).then(|| i - w);
                let down = (y + 1 < h).then(|| i + w);
                [left, right, up, down].into_iter().flatten().find(|&j| is_boundary(i, j)).map(|j| (i, j))
            })
        })
        .collect()
}

/// The scores of one rendered view, `None` when it has no measurable pixel. With `islands` (one
/// label per face), neighbours that see faces of different islands are on a boundary whatever
/// their UV distance ([`unpacked_editability`]).
fn view_scores(
    uv: &UvLayer,
    faces: &[Option<[f32; 2]>],
    islands: Option<&[u32]>,
    g: &GBuffer,
    params: &ImageParams,
) -> Option<ViewScores> {
    let hits = g.hit_count();
    let boundary_pixels = boundary_pixels(uv, islands, g, params).len();
    let samples: Vec<[f32; 2]> =
        g.pixels.par_iter().filter_map(|p| p.hit().and_then(|f| faces[f as usize])).collect();
    if hits == 0 || samples.is_empty() {
        return None;
    }
    let boundary = 1.0 - boundary_pixels as f64 / hits as f64;
    let stretch = stretch_score(&mut samples.iter().map(|s| s[0]).collect::<Vec<_>>());
    let conformal = conformal_score(&mut samples.iter().map(|s| s[1]).collect::<Vec<_>>());
    Some(ViewScores {
        hit_pixels: hits,
        boundary_pixels,
        boundary,
        stretch,
        conformal,
        editability: boundary * 0.5 * (stretch + conformal),
    })
}

/// Median, the mean of the two middle values for an even count. Reorders `v`.
fn median(v: &mut [f32]) -> f64 {
    let n = v.len();
    assert!(n > 0, "median of nothing");
    let (below, mid, _) = v.select_nth_unstable_by(n / 2, f32::total_cmp);
    let hi = *mid as f64;
    if n % 2 == 1 {
        hi
    } else {
        let lo = below.iter().copied().fold(f32::NEG_INFINITY, f32::max) as f64;
        0.5 * (lo + hi)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testmesh::{grid, with_uv_per_corner};

    /// Views that see the plane z = 0: from above and below, straight and oblique.
    fn plane_views(res: u32) -> Vec<Camera> {
        let eyes = [[0.0, 0.0, 3.0], [0.0, 0.0, -3.0], [1.5, -1.0, 2.5], [-2.0, 0.5, -2.0], [0.3, 2.0, 2.0]];
        eyes.iter().map(|&e| Camera::look_at(e, [0.0; 3], [0.0, 1.0, 0.0], 60.0, res, res).unwrap()).collect()
    }

    /// Straight above, fov chosen so [-1, 1]² fills the 200 px frame (pixels ∝ 3-D area exactly).
    fn head_on() -> Vec<Camera> {
        let fov = (2.0 * 0.5f32.atan()).to_degrees();
        vec![Camera::look_at([0.0, 0.0, 2.0], [0.0; 3], [0.0, 1.0, 0.0], fov, 200, 200).unwrap()]
    }

    fn assert_close(what: &str, got: f64, want: f64, tol: f64) {
        assert!((got - want).abs() <= tol, "{what}: got {got}, want {want} ± {tol}");
    }

    #[test]
    fn a_plane_mapped_by_its_own_xy_scores_one_everywhere() {
        let m = grid(16, |p| [(p[0] + 1.0) * 0.5, (p[1] + 1.0) * 0.5]);
        let r = image_metrics(&m, &plane_views(200), &ImageParams::default()).unwrap();
        assert_eq!(r.views_used, 5);
        for (name, v) in [("boundary", r.boundary), ("stretch", r.stretch), ("conformal", r.conformal)] {
            assert_close(name, v, 1.0, 1e-4);
        }
        assert_close("editability", r.editability, 1.0, 1e-4);
    }

    /// The plane [-1, 1]² (10 × 10 cells) mapped onto [0, 1]², and the same with the faces left
    /// of x = 0 moved by `du` in u: two islands with a seam along x = 0.
    fn left_half_moved(du: f32) -> (TriMesh, TriMesh) {
        let m = grid(10, |p| [(p[0] + 1.0) * 0.5, (p[1] + 1.0) * 0.5]);
        let halves = with_uv_per_corner(&m, |f, _, uv| {
            let left = m.corners(f).iter().all(|c| c[0] <= 0.0);
            if left { [uv[0] + du, uv[1]] } else { uv }
        });
        (m, halves)
    }

    #[test]
    fn unpacked_editability_counts_a_seam_between_islands_however_close_they_lie() {
        // Head-on 200² over [-1, 1]²: the seam x = 0 falls between pixel columns 99 and 100. The
        // left half moved 0.05 in u is an island of its own, closer than `uv_jump` to the right
        // half: measured, no pixel is a boundary pixel; unpacked, both columns along the seam
        // are (400 of 40,000 pixels), and Stretch and Conformal stay 1.
        let (m, halves) = left_half_moved(0.05);
        let params = ImageParams::default();
        assert_close("measured", image_metrics(&halves, &head_on(), &params).unwrap().editability, 1.0, 1e-9);
        let got = unpacked_editability(&halves, &[&m, &halves], &head_on(), &params).unwrap();
        assert_close("one island", got[0], 1.0, 1e-9);
        assert_close("two islands", got[1], 1.0 - 400.0 / 40_000.0, 1e-9);
        let other = grid(9, |p| [p[0], p[1]]);
        assert!(unpacked_editability(&halves, &[&other], &head_on(), &params).is_err());
    }

    #[test]
    fn boundary_pixels_are_the_two_columns_along_a_seam_each_paired_across_it() {
        // Head-on 200² over [-1, 1]²: the seam x = 0 falls between pixel columns 99 and 100. The
        // left half moved 1.0 in u: columns 99 and 100 are boundary pixels, each made one by its
        // neighbour across the seam (right of column 99, left of column 100), and no other pixel.
        let (m, halves) = left_half_moved(1.0);
        let g = render(&halves, &head_on()[0]).unwrap();
        let uv = halves.uv.as_ref().unwrap();
        let got = boundary_pixels(uv, None, &g, &ImageParams::default());
        assert_eq!(got.len(), 400);
        for (i, j) in got {
            let (x, y) = (i % 200, i / 200);
            assert!(x == 99 || x == 100, "pixel ({x}, {y})");
            assert_eq!(j, if x == 99 { i + 1 } else { i - 1 }, "pixel ({x}, {y})");
        }
        let whole = boundary_pixels(
            m.uv.as_ref().unwrap(),
            None,
            &render(&m, &head_on()[0]).unwrap(),
            &ImageParams::default(),
        );
        assert!(whole.is_empty());
        assert_close(
            "Boundary",
            image_metrics(&halves, &head_on(), &ImageParams::default()).unwrap().boundary,
            0.99,
            1e-12,
        );
    }

    #[test]
    fn a_sheared_map_scores_conformal_one_minus_cos_45() {
        // u = (x + y)/2, v = y  ⇒  x = 2u − v: T = (2, 0), B = (−1, 1), |cos| = 1/√2.
        let m = grid(8, |p| [(p[0] + p[1]) * 0.25, p[1] * 0.5]);
        let r = image_metrics(&m, &plane_views(160), &ImageParams::default()).unwrap();
        assert_close("conformal", r.conformal, 1.0 - std::f64::consts::FRAC_1_SQRT_2, 1e-5);
        assert_close("stretch", r.stretch, 1.0, 1e-5); // the shear is uniform
        assert_close("boundary", r.boundary, 1.0, 1e-4);
    }

    #[test]
    fn one_chart_per_triangle_scores_low_boundary() {
        let m = grid(64, |p| [(p[0] + 1.0) * 0.5, (p[1] + 1.0) * 0.5]);
        let scattered = with_uv_per_corner(&m, |f, _, uv| [uv[0] + (f % 97) as f32, uv[1] + (f / 97) as f32]);
        let r = image_metrics(&scattered, &plane_views(200), &ImageParams::default()).unwrap();
        assert!(r.boundary < 0.5, "boundary {}", r.boundary);
        // Stretch and conformal are untouched by where the charts sit.
        assert_close("stretch", r.stretch, 1.0, 1e-4);
        assert_close("conformal", r.conformal, 1.0, 1e-4);
        let same = image_metrics(&m, &plane_views(200), &ImageParams::default()).unwrap();
        assert!(same.boundary > 0.999);
    }

    #[test]
    fn uniform_scale_and_rotation_score_stretch_one() {
        let (c, s) = (0.6f32, 0.8f32);
        let m = grid(8, |p| [3.0 * (c * p[0] - s * p[1]), 3.0 * (s * p[0] + c * p[1])]);
        let r = image_metrics(&m, &plane_views(160), &ImageParams::default()).unwrap();
        assert_close("stretch", r.stretch, 1.0, 1e-5);
        assert_close("conformal", r.conformal, 1.0, 1e-5);
    }

    #[test]
    fn stretch_of_two_equal_halves_is_two_thirds() {
        // Half the triangles (by pixel weight) at s = 1, half at s = 2: m = 1.5, every deviation is
        // 1/3, Stretch = 1 − 1/3.
        let mut s = vec![1.0f32; 500];
        s.extend(vec![2.0f32; 500]);
        assert_close("two halves", stretch_score(&mut s), 2.0 / 3.0, 1e-6);
        // The same stretches in any scale.
        let mut t: Vec<f32> = (0..1000).map(|i| if i % 2 == 0 { 0.01 } else { 0.02 }).collect();
        assert_close("scaled", stretch_score(&mut t), 2.0 / 3.0, 1e-6);
    }

    #[test]
    fn stretch_of_a_rendered_map_with_half_the_triangles_doubled_in_area_is_two_thirds() {
        // The faces left of x = 0 (half of them) get UVs scaled by √2 (2× area). Seen head-on, the
        // plane's grid lines fall on pixel borders, so exactly half of the 200² pixels see each half:
        // m = (1 + 2)/2 = 1.5, every pixel deviates by 1/3, Stretch = 2/3.
        let m = grid(10, |p| [p[0], p[1]]);
        let halves = with_uv_per_corner(&m, |f, _, uv| {
            let left = m.corners(f).iter().all(|c| c[0] <= 0.0);
            if left { [uv[0] * 2f32.sqrt() - 5.0, uv[1] * 2f32.sqrt()] } else { uv }
        });
        let r = image_metrics(&halves, &head_on(), &ImageParams::default()).unwrap();
        assert_eq!(r.per_view[0].hit_pixels, 200 * 200);
        assert_close("stretch", r.stretch, 2.0 / 3.0, 1e-6);
    }

    #[test]
    fn stretch_of_a_rendered_three_band_map_matches_the_hand_computed_value() {
        // Bands of columns of a 10×10 grid: x < −0.4 (30 % of the area) keeps its area, the middle
        // 40 % is scaled 2× in area, x > 0.4 (30 %) 4×. Seen head-on, pixel weight = area share.
        // m = 2 (the 40 % band holds the median); deviations 0.5 (30 %), 0 (40 %), 1 (30 %);
        // their median is 0.5, so Stretch = 0.5.
        let m = grid(10, |p| [p[0], p[1]]);
        let banded = with_uv_per_corner(&m, |f, _, uv| {
            let cx: f32 = m.corners(f).iter().map(|c| c[0]).sum::<f32>() / 3.0;
            let k = if cx < -0.4 {
                1.0
            } else if cx < 0.4 {
                2f32.sqrt()
            } else {
                2.0
            };
            [uv[0] * k + 10.0 * k, uv[1] * k]
        });
        let r = image_metrics(&banded, &head_on(), &ImageParams::default()).unwrap();
        assert_close("stretch", r.stretch, 0.5, 1e-6);
        assert_close("conformal", r.conformal, 1.0, 1e-6);
        // Halving all UVs changes nothing.
        let half = with_uv_per_corner(&banded, |_, _, uv| [uv[0] * 0.5, uv[1] * 0.5]);
        let r2 = image_metrics(&half, &head_on(), &ImageParams::default()).unwrap();
        assert_close("scaled", r2.stretch, 0.5, 1e-6);
    }

    #[test]
    fn degenerate_triangles_do_not_poison_the_scores() {
        let mut m = grid(8, |p| [(p[0] + 1.0) * 0.5, (p[1] + 1.0) * 0.5]);
        // Zero-area faces (repeated vertex) with degenerate UVs, as NeRF meshes have.
        for f in 0..10u32 {
            m.triangles.push([f, f, f + 1]);
            m.uv.as_mut().unwrap().triangles.push([f, f, f + 1]);
        }
        let r = image_metrics(&m, &plane_views(120), &ImageParams::default()).unwrap();
        for v in [r.boundary, r.stretch, r.conformal, r.editability] {
            assert!(v.is_finite() && (v - 1.0).abs() < 1e-4, "{r:?}");
        }
        let a = analyse_uv(&m, None, 64).unwrap();
        assert_eq!(a.stats.degenerate_3d_faces, 10);
        assert_eq!(a.stats.degenerate_uv_faces, 10);
    }

    #[test]
    fn depth_discontinuities_excuse_uv_jumps() {
        // Two parallel planes with unrelated UVs, the front one smaller: its silhouette has UV jumps
        // against the back plane, but across a depth jump, so no boundary pixel.
        let front = grid(4, |p| [(p[0] + 1.0) * 0.25, (p[1] + 1.0) * 0.25]);
        let mut m = grid(4, |p| [(p[0] + 1.0) * 0.5 + 5.0, (p[1] + 1.0) * 0.5]);
        let n = m.positions.len() as u32;
        let nuv = m.uv.as_ref().unwrap().coords.len() as u32;
        m.positions.extend(front.positions.iter().map(|p| [p[0] * 0.5, p[1] * 0.5, 0.5]));
        m.triangles.extend(front.triangles.iter().map(|t| t.map(|v| v + n)));
        let uv = m.uv.as_mut().unwrap();
        uv.coords.extend(&front.uv.as_ref().unwrap().coords);
        uv.triangles.extend(front.uv.as_ref().unwrap().triangles.iter().map(|t| t.map(|v| v + nuv)));
        let r = image_metrics(&m, &head_on(), &ImageParams::default()).unwrap();
        assert_close("boundary", r.boundary, 1.0, 1e-9);
        // Without the depth test, the silhouette would count.
        let strict = ImageParams { depth_jump: 1e9, ..Default::default() };
        assert!(image_metrics(&m, &head_on(), &strict).unwrap().boundary < 0.999);
    }

    #[test]
    fn evaluate_checks_its_inputs() {
        let mut m = grid(2, |p| [p[0], p[1]]);
        let bad = EvalOptions { views: 0, ..Default::default() };
        assert!(matches!(evaluate(&m, &bad), Err(AtlasError::Invalid { .. })));
        m.uv = None;
        assert!(matches!(evaluate(&m, &EvalOptions::default()), Err(AtlasError::NoUv { .. })));
    }

    #[test]
    fn out_of_range_indices_are_errors_not_panics() {
        let mut m = grid(2, |p| [p[0], p[1]]);
        m.uv.as_mut().unwrap().triangles[3][1] = 999;
        assert!(matches!(evaluate(&m, &EvalOptions::default()), Err(AtlasError::Invalid { .. })));
        assert!(analyse_uv(&m, None, 16).is_err());
        m.triangles[0][0] = 999;
        assert!(render(&m, &plane_views(8)[0]).is_err());
        assert!(crate::pictures::uv_layout(&m, None, 16).is_err());
    }

    #[test]
    fn evaluate_is_deterministic_and_sees_the_plane() {
        let m = grid(8, |p| [(p[0] + 1.0) * 0.5, (p[1] + 1.0) * 0.5]);
        let opts = EvalOptions { views: 6, resolution: 96, uv_raster: 64, ..Default::default() };
        let a = evaluate(&m, &opts).unwrap();
        assert_eq!(a, evaluate(&m, &opts).unwrap());
        assert!(a.image.views_used >= 1);
        assert!(a.image.stretch > 0.999 && a.image.conformal > 0.999);
        assert_eq!(a.uv.charts, 1);
        assert_eq!(a.uv.utilisation, 1.0);
    }
}

//! PNG pictures that let a user judge an atlas at a glance: the UV layout, a labelled checkerboard
//! texture, renders of the mesh wearing it, and the learned normal grids `N_i`.
//!
//! Image conventions: `[0,1]²` UV images have `v` up (row 0 at `v = 1`), as texture editors show
//! them and as OBJ/glTF sample them; textures are sampled bilinearly with clamp-to-edge.

use std::path::{Path, PathBuf};

use glam::DVec3;
/// The RGB image type of every picture (re-exported so users need not depend on `image`).
pub use image::RgbImage;
use image::{ImageEncoder, Rgb, codecs::png::PngEncoder};
use nuvo_geometry::{TriMesh, UvLayer};
use rayon::prelude::*;

use crate::camera::{Camera, MAX_IMAGE_SIDE, orbit_views};
use crate::error::AtlasError;
use crate::error::write_atomic;
use crate::font::{GLYPH, draw_text};
use crate::geom::to_dvec3;
use crate::pack::AtlasLayout;
use crate::raster::{Sampling, raster_parallel};
use crate::render::render;
use crate::uvstats::{require_uv, uv_charts, uv_pixels};

/// Background of renders and of empty UV space.
const BACKGROUND: [u8; 3] = [40, 40, 46];

/// A distinct, stable colour for chart `i` (golden-ratio hue steps).
pub fn chart_colour(i: u32) -> [u8; 3] {
    let h = (i as f64 * 0.618_033_988_749_895).fract();
    hsv(h, 0.55, 0.95)
}

/// The UV layout on a `resolution²` image of `[0,1]²`: faces filled with their chart's colour
/// (`face_chart`, or the UV-connected components when `None`), edges darkened, texels covered by
/// more than one face tinted red. Uses the same rasteriser and coverage rule as the overlap metric.
pub fn uv_layout(
    mesh: &TriMesh,
    face_chart: Option<&[u32]>,
    resolution: u32,
) -> Result<RgbImage, AtlasError> {
    let uv = require_uv(mesh)?;
    check_side("layout resolution", resolution)?;
    let owned;
    let charts = match face_chart {
        Some(c) if c.len() == mesh.triangles.len() => c,
        Some(c) => {
            return Err(AtlasError::invalid(
                "face charts",
                format!("{} labels for {} faces", c.len(), uv.triangles.len()),
            ));
        }
        None => {
            owned = uv_charts(mesh, uv).0;
            &owned
        }
    };
    #[derive(Clone, Copy)]
    struct Texel {
        first: u32,
        count: u16,
        edge: bool,
    }
    let r = resolution;
    let mut texels = vec![Texel { first: u32::MAX, count: 0, edge: false }; (r * r) as usize];
    raster_parallel(
        r,
        r,
        &mut texels,
        uv.triangles.len(),
        Sampling::Exact,
        |f| Some(uv_pixels(uv, f, r)),
        |t, f, l| {
            if t.first == u32::MAX {
                t.first = f as u32;
            }
            t.count = t.count.saturating_add(1);
            t.edge |= distance_to_edge_px(uv_pixels(uv, f, r), l) < 0.75;
        },
    );
    let mut img = RgbImage::new(r, r);
    for (px, t) in img.pixels_mut().zip(&texels) {
        let c = match t.first {
            u32::MAX => BACKGROUND,
            f => {
                let base = chart_colour(charts[f as usize]);
                let base = if t.edge { base.map(|c| (c as f32 * 0.55) as u8) } else { base };
                if t.count > 1 { mix(base, [230, 30, 30], 0.6) } else { base }
            }
        };
        *px = Rgb(c);
    }
    Ok(img)
}

/// The most cells a side of [`checkerboard`] has: one letter per column, `A` to `Z`.
pub const MAX_CHECKER_CELLS: u32 = 26;

/// A `resolution²` checkerboard of `cells × cells` squares over `[0,1]²`, each labelled with its
/// column letter (`A`… along +u) and row number (`1`… along +v), so `A1` touches the UV origin.
/// Hue varies with the column and brightness alternates, so rotations, mirrorings and stretch are
/// visible on a render. `cells` must be in `1..=`[`MAX_CHECKER_CELLS`].
pub fn checkerboard(resolution: u32, cells: u32) -> Result<RgbImage, AtlasError> {
    check_side("checkerboard resolution", resolution)?;
    if !(1..=MAX_CHECKER_CELLS).contains(&cells) || cells > resolution {
        return Err(AtlasError::invalid(
            "checkerboard",
            format!("{cells} cells is not in 1..={MAX_CHECKER_CELLS}"),
        ));
    }
    let cell = |p: u32| (p as u64 * cells as u64 / resolution as u64) as u32;
    let colour = |i: u32, j: u32| {
        let light = (i + j).is_multiple_of(2);
        hsv(i as f64 / cells as f64, if light { 0.35 } else { 0.75 }, if light { 0.98 } else { 0.55 })
    };
    let mut img = RgbImage::from_fn(resolution, resolution, |x, y| {
        let (i, j) = (cell(x), cells - 1 - cell(y));
        Rgb(colour(i, j))
    });
    let side = resolution / cells;
    let scale = (side / (3 * (GLYPH.0 + 1))).max(1);
    for i in 0..cells {
        for j in 0..cells {
            let label = format!("{}{}", (b'A' + i as u8) as char, j + 1);
            let ink = if (i + j) % 2 == 0 { [20, 20, 20] } else { [250, 250, 250] };
            let (x0, y0) = ((i * resolution).div_ceil(cells), ((cells - 1 - j) * resolution).div_ceil(cells));
            draw_text(&label, x0 + side / 10, y0 + side / 10, scale, |x, y| {
                if x < resolution && y < resolution {
                    img.put_pixel(x, y, Rgb(ink));
                }
            });
        }
    }
    Ok(img)
}

/// Renders of `mesh` wearing `texture` from each camera: bilinear texture lookup at the
/// interpolated UV, Lambert shading (two-sided, light at the eye) with smooth vertex normals.
pub fn render_textured(
    mesh: &TriMesh,
    cameras: &[Camera],
    texture: &RgbImage,
) -> Result<Vec<RgbImage>, AtlasError> {
    let uv = require_uv(mesh)?;
    if texture.width() == 0 || texture.height() == 0 {
        return Err(AtlasError::invalid("texture", "the texture image is empty"));
    }
    let normals = mesh.vertex_normals_or([0.0, 0.0, 1.0]);
    cameras
        .iter()
        .map(|cam| {
            let g = render(mesh, cam)?;
            let eye = to_dvec3(cam.eye);
            let pixels: Vec<[u8; 3]> = g
                .pixels
                .par_iter()
                .map(|p| {
                    let Some(f) = p.hit() else { return BACKGROUND };
                    let f = f as usize;
                    let lerp3 = |a: [[f32; 3]; 3]| -> [f64; 3] {
                        std::array::from_fn(|k| (0..3).map(|c| p.bary[c] as f64 * a[c][k] as f64).sum())
                    };
                    let point = DVec3::from(lerp3(mesh.corners(f)));
                    let normal = DVec3::from(lerp3(mesh.triangles[f].map(|v| normals[v as usize])));
                    let light = match (normal.try_normalize(), (eye - point).try_normalize()) {
                        (Some(n), Some(l)) => 0.25 + 0.75 * n.dot(l).abs(),
                        _ => 0.6,
                    };
                    let t = interpolate_uv(uv, f, p.bary);
                    bilinear(texture, t).map(|c| (c as f64 * light).round().min(255.0) as u8)
                })
                .collect();
            Ok(RgbImage::from_fn(g.width, g.height, |x, y| Rgb(pixels[(y * g.width + x) as usize])))
        })
        .collect()
}

/// One chart's learned grid (e.g. the normal grid `N_i`): `height × width` RGB triples in
/// `[-1, 1]`, row-major, row 0 at `v = 0`, column 0 at `u = 0`.
#[derive(Clone, Copy, Debug)]
pub struct ChartGrid<'a> {
    /// Texels along u.
    pub width: usize,
    /// Texels along v.
    pub height: usize,
    /// `height × width × 3` values.
    pub values: &'a [f32],
}

/// The picture of a chart grid: `[-1, 1]` mapped linearly to `0..=255` per channel (so a normal
/// `(0, 0, 1)` is the familiar normal-map blue), `v` up. Values outside `[-1, 1]` are clamped.
pub fn chart_grid_image(grid: &ChartGrid) -> Result<RgbImage, AtlasError> {
    let (w, h) = (grid.width, grid.height);
    if w == 0
        || h == 0
        || w > MAX_IMAGE_SIDE as usize
        || h > MAX_IMAGE_SIDE as usize
        || grid.values.len() != w * h * 3
    {
        return Err(AtlasError::invalid(
            "chart grid",
            format!("{} values for a {w}×{h} RGB grid (expected {})", grid.values.len(), w * h * 3),
        ));
    }
    Ok(RgbImage::from_fn(w as u32, h as u32, |x, y| {
        let row = h - 1 - y as usize;
        let i = (row * w + x as usize) * 3;
        Rgb(std::array::from_fn(|k| {
            let v = grid.values[i + k];
            if v.is_nan() { 0 } else { ((v.clamp(-1.0, 1.0) + 1.0) * 127.5).round() as u8 }
        }))
    }))
}

/// One image per chart packed into a `layout.resolution²` atlas: each chart image is resampled
/// (bilinear) onto its square and its edge texels extended into the gutter, so filtering at chart
/// borders never picks up background.
pub fn pack_images(layout: &AtlasLayout, charts: &[RgbImage]) -> Result<RgbImage, AtlasError> {
    if charts.len() != layout.charts.len() {
        return Err(AtlasError::invalid(
            "chart images",
            format!("{} images for {} charts", charts.len(), layout.charts.len()),
        ));
    }
    let mut img = RgbImage::from_pixel(layout.resolution, layout.resolution, Rgb(BACKGROUND));
    let cell = layout.resolution / layout.columns;
    // Rows in parallel (each pixel is its own chart's alone): the 2048² normal grids took tens
    // of milliseconds on one core at the end of the bake.
    let width = layout.resolution as usize * 3;
    img.par_chunks_mut(width).enumerate().for_each(|(y, row)| {
        let y = y as u32;
        for (p, chart) in layout.charts.iter().zip(charts) {
            let [x0, y0, side] = p.texels;
            let (cx, cy) = (x0 - layout.gutter, y0 - layout.gutter);
            if !(cy..cy + cell).contains(&y) {
                continue;
            }
            let ly = ((y as f32 + 0.5 - y0 as f32) / side as f32).clamp(0.0, 1.0);
            for x in cx..cx + cell {
                let lx = ((x as f32 + 0.5 - x0 as f32) / side as f32).clamp(0.0, 1.0);
                let rgb = bilinear(chart, [lx, 1.0 - ly]).map(|c| c.round() as u8);
                row[x as usize * 3..x as usize * 3 + 3].copy_from_slice(&rgb);
            }
        }
    });
    Ok(img)
}

/// Writes each chart grid as `dir/{stem}_{i}.png` and, with a layout, all of them packed as
/// `dir/{stem}_atlas.png`. Returns the paths written.
pub fn write_chart_grids(
    dir: &Path,
    stem: &str,
    grids: &[ChartGrid],
    layout: Option<&AtlasLayout>,
) -> Result<Vec<PathBuf>, AtlasError> {
    let images = grids.iter().map(chart_grid_image).collect::<Result<Vec<_>, _>>()?;
    let mut written = Vec::new();
    for (i, img) in images.iter().enumerate() {
        let path = dir.join(format!("{stem}_{i}.png"));
        write_png(&path, img)?;
        written.push(path);
    }
    if let Some(layout) = layout {
        let path = dir.join(format!("{stem}_atlas.png"));
        write_png(&path, &pack_images(layout, &images)?)?;
        written.push(path);
    }
    Ok(written)
}

/// What [`write_previews`] draws.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PreviewOptions {
    /// Number of checkerboard renders.
    pub views: usize,
    /// Side of the renders.
    pub resolution: u32,
    /// Seed of the render cameras ([`orbit_views`]).
    pub seed: u64,
    /// Side of the checkerboard texture and of the layout picture.
    pub texture_resolution: u32,
    /// Checkerboard cells per side.
    pub cells: u32,
}

impl Default for PreviewOptions {
    fn default() -> Self {
        PreviewOptions { views: 4, resolution: 512, seed: 0, texture_resolution: 1024, cells: 8 }
    }
}

/// Writes the standard pictures of a UV'd mesh into `dir` (which must exist): `uv_layout.png`,
/// `checker.png` and `checker_view_{k}.png`. Returns the paths written.
pub fn write_previews(dir: &Path, mesh: &TriMesh, opts: &PreviewOptions) -> Result<Vec<PathBuf>, AtlasError> {
    check_side("preview resolution", opts.resolution)?;
    let texture = checkerboard(opts.texture_resolution, opts.cells)?;
    let mut written = vec![dir.join("uv_layout.png"), dir.join("checker.png")];
    write_png(&written[0], &uv_layout(mesh, None, opts.texture_resolution)?)?;
    write_png(&written[1], &texture)?;
    let bounds = mesh.bounds().ok_or_else(|| AtlasError::invalid("mesh", "no vertices"))?;
    let cams = orbit_views(&bounds, opts.views, opts.seed, opts.resolution, opts.resolution);
    for (k, img) in render_textured(mesh, &cams, &texture)?.iter().enumerate() {
        let path = dir.join(format!("checker_view_{k}.png"));
        write_png(&path, img)?;
        written.push(path);
    }
    Ok(written)
}

/// Encodes `img` as PNG and writes it atomically.
pub fn write_png(path: &Path, img: &RgbImage) -> Result<(), AtlasError> {
    let mut bytes = Vec::new();
    PngEncoder::new(&mut bytes)
        .write_image(img.as_raw(), img.width(), img.height(), image::ExtendedColorType::Rgb8)
        .map_err(|e| AtlasError::Encode { path: path.to_path_buf(), message: e.to_string() })?;
    write_atomic(path, |w| w.write_all(&bytes))
}

/// Encodes `img` as PNG bytes (e.g. to embed in a GLB).
pub fn png_bytes(img: &RgbImage) -> Result<Vec<u8>, AtlasError> {
    let mut bytes = Vec::new();
    PngEncoder::new(&mut bytes)
        .write_image(img.as_raw(), img.width(), img.height(), image::ExtendedColorType::Rgb8)
        .map_err(|e| AtlasError::Encode { path: "image.png".into(), message: e.to_string() })?;
    Ok(bytes)
}

fn interpolate_uv(uv: &UvLayer, f: usize, bary: [f32; 3]) -> [f32; 2] {
    let t = uv.triangles[f].map(|i| uv.coords[i as usize]);
    std::array::from_fn(|k| (0..3).map(|c| bary[c] * t[c][k]).sum())
}

/// Bilinear, clamp-to-edge lookup of `img` at UV `t` (`v` up), as floats in `0..=255`.
fn bilinear(img: &RgbImage, t: [f32; 2]) -> [f32; 3] {
    let (w, h) = (img.width() as f32, img.height() as f32);
    let x = (t[0] * w - 0.5).clamp(0.0, w - 1.0);
    let y = ((1.0 - t[1]) * h - 0.5).clamp(0.0, h - 1.0);
    let (x0, y0) = (x.floor() as u32, y.floor() as u32);
    let (x1, y1) = ((x0 + 1).min(img.width() - 1), (y0 + 1).min(img.height() - 1));
    let (fx, fy) = (x - x0 as f32, y - y0 as f32);
    let p = |x, y| img.get_pixel(x, y).0.map(|c| c as f32);
    let (a, b, c, d) = (p(x0, y0), p(x1, y0), p(x0, y1), p(x1, y1));
    std::array::from_fn(|k| {
        let top = a[k] + (b[k] - a[k]) * fx;
        let bottom = c[k] + (d[k] - c[k]) * fx;
        top + (bottom - top) * fy
    })
}

/// Distance in pixels from a point with barycentrics `l` to the nearest edge of `t`.
fn distance_to_edge_px(t: [[f32; 2]; 3], l: [f32; 3]) -> f32 {
    let area2 = ((t[1][0] - t[0][0]) * (t[2][1] - t[0][1]) - (t[1][1] - t[0][1]) * (t[2][0] - t[0][0])).abs();
    (0..3)
        .map(|k| {
            let (a, b) = (t[(k + 1) % 3], t[(k + 2) % 3]);
            let len = ((b[0] - a[0]).powi(2) + (b[1] - a[1]).powi(2)).sqrt();
            if len > 0.0 { l[k] * area2 / len } else { 0.0 }
        })
        .fold(f32::INFINITY, f32::min)
}

fn check_side(what: &'static str, side: u32) -> Result<(), AtlasError> {
    if side == 0 || side > MAX_IMAGE_SIDE {
        return Err(AtlasError::invalid(what, format!("{side} is not in 1..={MAX_IMAGE_SIDE}")));
    }
    Ok(())
}

fn mix(a: [u8; 3], b: [u8; 3], t: f32) -> [u8; 3] {
    std::array::from_fn(|k| (a[k] as f32 * (1.0 - t) + b[k] as f32 * t).round() as u8)
}

fn hsv(h: f64, s: f64, v: f64) -> [u8; 3] {
    let i = (h * 6.0).floor();
    let f = h * 6.0 - i;
    let (p, q, t) = (v * (1.0 - s), v * (1.0 - f * s), v * (1.0 - (1.0 - f) * s));
    let (r, g, b) = match i as i64 % 6 {
        0 => (v, t, p),
        1 => (q, v, p),
        2 => (p, v, t),
        3 => (p, q, v),
        4 => (t, p, v),
        _ => (v, p, q),
    };
    [r, g, b].map(|c| (c * 255.0).round() as u8)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testmesh::{grid, with_uv_per_corner};

    #[test]
    fn layout_colours_charts_and_marks_overlaps() {
        // Two charts side by side in u; then fold one onto the other.
        let m = grid(4, |p| [(p[0] + 1.0) * 0.5, (p[1] + 1.0) * 0.5]);
        let two = with_uv_per_corner(&m, |f, _, uv| {
            if m.corners(f).iter().all(|c| c[0] <= 0.0) {
                [uv[0] - 0.02, uv[1]]
            } else {
                [uv[0] + 0.02, uv[1]]
            }
        });
        let img = uv_layout(&two, None, 100).unwrap();
        let (left, right) = (img.get_pixel(5, 30).0, img.get_pixel(88, 30).0);
        assert_eq!(left, chart_colour(0));
        assert_eq!(right, chart_colour(1));
        assert_eq!(img.get_pixel(50, 50).0, BACKGROUND, "the gap between the charts");
        let folded = grid(4, |p| [(p[0].abs()) * 0.5, (p[1] + 1.0) * 0.5]);
        let img = uv_layout(&folded, None, 100).unwrap();
        let c = img.get_pixel(20, 37).0;
        assert!(c[0] > c[1] && c[0] > c[2], "overlap not tinted red: {c:?}");
    }

    #[test]
    fn checkerboard_puts_a1_at_the_uv_origin_and_labels_cells() {
        let img = checkerboard(256, 8).unwrap();
        // Bottom-left cell (A1) is light, its right neighbour (B1) dark.
        let a1 = img.get_pixel(16, 255 - 4).0;
        let b1 = img.get_pixel(32 + 16, 255 - 4).0;
        let lum = |c: [u8; 3]| c.iter().map(|&x| x as u32).sum::<u32>();
        assert!(lum(a1) > lum(b1));
        // A label was drawn in the top-left of A1 (cell rows 224..256).
        let inked = (224..240)
            .flat_map(|y| (0..32).map(move |x| (x, y)))
            .filter(|&(x, y)| lum(img.get_pixel(x, y).0) < 100)
            .count();
        assert!(inked > 5, "no label ink in A1");
        assert!(checkerboard(256, 0).is_err() && checkerboard(256, 27).is_err());
    }

    #[test]
    fn textured_render_shows_the_texture_where_the_mesh_is() {
        let m = grid(4, |p| [(p[0] + 1.0) * 0.5, (p[1] + 1.0) * 0.5]);
        let tex = RgbImage::from_fn(2, 2, |x, _| if x == 0 { Rgb([200, 0, 0]) } else { Rgb([0, 0, 200]) });
        let cam = Camera::look_at([0.0, 0.0, 3.0], [0.0; 3], [0.0, 1.0, 0.0], 60.0, 64, 64).unwrap();
        let img = &render_textured(&m, &[cam], &tex).unwrap()[0];
        let (l, r) = (img.get_pixel(20, 32).0, img.get_pixel(44, 32).0);
        assert!(l[0] > 150 && l[2] < 50, "left half should be red: {l:?}");
        assert!(r[2] > 150 && r[0] < 50, "right half should be blue: {r:?}");
        assert_eq!(img.get_pixel(0, 0).0, BACKGROUND);
    }

    #[test]
    fn chart_grids_map_minus_one_one_to_bytes_with_v_up() {
        // 1×2 grid: row 0 (v = 0) is (-1, 0, 1), row 1 is (1, 1, -1).
        let values = [-1.0, 0.0, 1.0, 1.0, 1.0, -1.0];
        let img = chart_grid_image(&ChartGrid { width: 1, height: 2, values: &values }).unwrap();
        assert_eq!(img.get_pixel(0, 1).0, [0, 128, 255]);
        assert_eq!(img.get_pixel(0, 0).0, [255, 255, 0]);
        assert!(chart_grid_image(&ChartGrid { width: 2, height: 2, values: &values }).is_err());
    }

    #[test]
    fn packed_images_fill_their_cells_and_gutters() {
        let layout = AtlasLayout::grid(2, 64, 2).unwrap();
        let red = RgbImage::from_pixel(4, 4, Rgb([255, 0, 0]));
        let blue = RgbImage::from_pixel(4, 4, Rgb([0, 0, 255]));
        let img = pack_images(&layout, &[red, blue]).unwrap();
        assert_eq!(img.get_pixel(0, 0).0, [255, 0, 0], "gutter is dilated chart 0");
        assert_eq!(img.get_pixel(40, 10).0, [0, 0, 255]);
        assert_eq!(img.get_pixel(10, 50).0, BACKGROUND, "second row is unused");
    }

    #[test]
    fn pngs_are_written_and_decodable() {
        let dir = tempfile::tempdir().unwrap();
        let m = grid(4, |p| [(p[0] + 1.0) * 0.5, (p[1] + 1.0) * 0.5]);
        let opts = PreviewOptions { views: 2, resolution: 48, texture_resolution: 64, ..Default::default() };
        let paths = write_previews(dir.path(), &m, &opts).unwrap();
        assert_eq!(paths.len(), 4);
        for p in &paths {
            let img = image::open(p).unwrap();
            assert!(img.width() > 0, "{}", p.display());
        }
        let values = vec![0.0f32; 4 * 4 * 3];
        let g = ChartGrid { width: 4, height: 4, values: &values };
        let written =
            write_chart_grids(dir.path(), "normals", &[g, g], Some(&AtlasLayout::grid(2, 32, 1).unwrap()))
                .unwrap();
        assert_eq!(written.len(), 3);
        assert_eq!(image::open(&written[2]).unwrap().width(), 32);
    }
}

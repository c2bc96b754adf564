//! Packing a UV layout's islands into one atlas at one texel density (issue 19, part 2).
//!
//! [`pack_islands`] takes a mesh whose UVs are laid out in any way (Nuvo's baked charts, another
//! tool's atlas) and lays its islands out anew in `[0,1]²`: every island is rotated and scaled
//! (never mirrored, never distorted) so that all of them have the same texel density, and packed
//! as large as the packer manages. Faces, vertices and their order are kept; only the UV layer is
//! new.
//!
//! Definitions (exact):
//! - **Island**: a UV-connected set of faces, [`crate::uvstats::uv_charts`] (faces sharing a mesh
//!   edge whose UVs are equal at both ends). Islands are numbered in order of their first face.
//!   In the output every island has its own texture coordinates: corners of one island that shared
//!   a coordinate still do, corners of two islands never do.
//! - **Areas**: an island's UV area is the sum of its faces' *unsigned* UV areas (flipped faces
//!   count, they do not cancel) over the faces that are not degenerate in 3-D
//!   ([`crate::uvstats`]), its 3-D area the sum of its faces' areas (both in `f64`). A face
//!   without 3-D area has no texel density of its own: the zero-area faces of a marching-cubes
//!   mesh (about 7% of an island's faces on the unruly meshes) get well-shaped UV triangles from
//!   [`crate::injective`], and counting their UV area would shrink the real faces of their
//!   island against every other island's.
//! - **Texel density**: every island is scaled uniformly by `scale · sqrt(area_3d / area_uv)`, so
//!   its new UV area is `scale² · area_3d`: one common `scale` ([`PackedIslands::scale`], UV units
//!   per 3-D unit of length) for the whole atlas.
//! - **Degenerate island**: its 3-D area is at most [`DEGENERATE_AREA_REL`] times the squared
//!   bounding-box diagonal of the mesh, or its UV area at most [`DEGENERATE_AREA_REL`] times the
//!   squared side of the bounding square of all input UVs. Such an island has no texel
//!   density to match: it gets its **own scale**, the one that makes the longer side of its bounding
//!   rectangle one texel long (an island whose UVs are all one point stays a point), and a cell of
//!   one texel. Its shape is still only rotated and scaled.
//! - **Rotation** (`rotate`): each island is first turned so that its minimum-area bounding
//!   rectangle is axis-aligned (that rectangle has a side on an edge of the island's convex hull,
//!   Freeman & Shapira 1975; every hull edge is tried, ties go to the first edge in hull order),
//!   by the smallest such angle (in `(-45°, 45°]`), then the packer may turn it by a further 90°.
//!   Without `rotate` islands keep their orientation. Rotations only: a face's winding, and so
//!   whether it is flipped, is kept.
//! - **Cells and gutter**: at a given `scale`, an island's bounding rectangle measures `(w, h)`
//!   texels of the `resolution²` atlas; its **cell** is `ceil(w) × ceil(h)` texels (at least 1),
//!   with corners on texel corners, and the island sits centred in it. The packer places rectangles
//!   of the cell's size plus `gutter` on each axis in the `resolution²` square, the cell at offset
//!   `floor(gutter / 2)` in its rectangle. So the texels any two islands touch are at least
//!   `gutter` texels apart (whole free texels in between; bilinear filtering reads one texel past
//!   an island's edge, so `gutter ≥ 2` keeps neighbours from bleeding in both directions), and an
//!   island is at least `floor(gutter / 2)` texels from the atlas border on one side and
//!   `ceil(gutter / 2)` on the other (so a repeating texture keeps the gutter across the border).
//! - **Packing**: the largest `scale` found at which all rectangles fit, by bisection on `scale`
//!   (to 1e-6 relative, between 0 and the largest scale at which the rectangles' total area
//!   fits the square; a scale whose cells equal those of a tried one is not packed again). Each
//!   trial packs with MaxRects, best short side fit (Jylänki 2010, "A Thousand Ways to Pack the
//!   Bin"; both orientations tried at each place when `rotate`), the rectangles sorted by
//!   decreasing area, and if they do not fit, by decreasing height. MaxRects' cost grows with the
//!   square of the island count, so beyond [`MAXRECTS_UP_TO`] islands a skyline bottom-left packer
//!   (same paper, same orders and rotations) takes over. Bisection assumes that a scale that fits
//!   makes smaller ones fit, which a heuristic packer does not promise; the result is always the
//!   packing of a scale that did fit.
//!
//!   Why this packer. Measured by the efficiency each reaches in this bisection on the islands of
//!   real atlases (gutter 2; bunny = the bundled bunny's xatlas atlas, 1,062 islands whose areas
//!   fill 0.571 of their minimum-area rectangles, so 0.571 bounds any rectangle packing; spot = its
//!   own 13 charts), at 1024² / 4096²: this MaxRects 0.531 / 0.560 (bunny), 0.619 / 0.628 (spot);
//!   `binpack2d` 1.0 MaxRects BSSF (no rotation, rectangles laid down) 0.531 / 0.542 and
//!   0.613 / 0.616; `crunch` 0.5 0.530 / 0.559 and 0.578 / 0.587, taking ~2 s for the bunny; a
//!   skyline bottom-left packer (three orders) 0.502 / 0.532 and 0.515 / 0.617; `binpack2d`
//!   Guillotine 0.527 / 0.542; `rectangle-pack` 0.4 0.574 / 0.582 on spot (too slow for the
//!   bunny); `etagere` 0.3 shelves 0.344 / 0.365. So no crate is needed.
//! - **Shapes**: rectangles waste what an island leaves empty in its bounding rectangle (an L,
//!   a long limb turned at an angle, a one-chart relief longer than wide). Up to
//!   [`SHAPES_UP_TO`] islands the islands are therefore also packed by their shapes (the
//!   `shapes` module: the texels each face touches, placed on a bitmap of the atlas so that no
//!   texel comes within `gutter` of another island's, turned by multiples of 45° after the
//!   minimum-area rotation; three placement rules, `best_shapes`), by bisection on `scale` from
//!   the rectangles' scale upwards (to [`SHAPE_SCALE_PRECISION`]), and the packing with the larger scale is
//!   kept. The gutter then holds between the texels the islands touch rather than between
//!   their cells, and each island keeps `floor(gutter / 2)` texels free at the low side of
//!   each axis and `ceil(gutter / 2)` at the high side. Measured in BENCHMARKS.md ("Shape
//!   packing"): spot's own 13 charts 0.619 → 0.696 at 1024² (gutter 2). The bisection's best
//!   packing is then improved by a short search over island orders (`search_orders`,
//!   [`IslandPacking::search`] attempts, [`ORDER_SEARCH`] in `nuvo unwrap`'s layout): neighbours
//!   in the order swapped, kept when the packing fits 1% larger. Then (with the order search)
//!   by a search over the places of the order's first, large islands (`search_places`,
//!   `shapes::pack_shapes_searched`): each may take its rule's first place in another
//!   orientation, a few times along a path, the rest placed as before; kept 0.3% larger at a
//!   time, within [`PLACE_SEARCH_BUDGET`] placements searched.
//! - **Efficiency**: the summed unsigned UV area of all faces in the output (over the unit
//!   square's area 1), as [`crate::partuv`] measures packing efficiency.
//!
//! The result is deterministic: the same mesh and options give the same bits at any thread count
//! (islands are prepared and footprints rasterised in parallel but kept in island order, islands
//! are placed one after the other; no hashing order; ties broken by index).

use foldhash::{HashMap, HashMapExt};
use rayon::prelude::*;

use glam::DVec3;
use nuvo_geometry::{TriMesh, UvLayer};

use crate::error::AtlasError;
use crate::geom::to_dvec3;
use crate::uvstats::{
    DEGENERATE_AREA_REL, degenerate_3d_area, face_area_3d, face_uv_area2, is_degenerate_3d, require_uv,
    uv_charts,
};

mod shapes;
use shapes::{Rule, ShapePlaced};

/// Largest atlas side [`pack_islands`] accepts, in texels.
pub const MAX_RESOLUTION: u32 = 1 << 16;

/// How [`pack_islands`] lays islands out (module docs).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct IslandPacking {
    /// Atlas side in texels, `1..=`[`MAX_RESOLUTION`]: the unit the cells and the gutter are
    /// measured in.
    pub resolution: u32,
    /// Free texels kept between any two islands, `< resolution`.
    pub gutter: u32,
    /// Whether islands may be rotated (to their minimum-area bounding rectangle, then by 90°).
    pub rotate: bool,
    /// Packing attempts of the order search after the shape packer's bisection (module docs,
    /// [`ORDER_SEARCH`]), which the search over the large islands' places follows
    /// ([`PLACE_SEARCH_BUDGET`]); 0 for neither (the necks pass's trial layouts: see there).
    pub search: usize,
}

impl Default for IslandPacking {
    /// A 1024² atlas, 2 texels between islands, rotations on, the order search on.
    fn default() -> Self {
        Self { resolution: 1024, gutter: 2, rotate: true, search: ORDER_SEARCH }
    }
}

/// What [`pack_islands`] returns.
#[derive(Clone, Debug, PartialEq)]
pub struct PackedIslands {
    /// The input mesh (same positions and triangles, same order) with the new UV layer.
    pub mesh: TriMesh,
    /// Island of each face, islands numbered in order of their first face.
    pub island_of_face: Vec<u32>,
    /// Number of islands.
    pub islands: usize,
    /// Summed unsigned UV area of the faces in `[0,1]²`.
    pub efficiency: f64,
    /// UV units per 3-D unit of length shared by every non-degenerate island (UV area = `scale²` ×
    /// 3-D area); 0 when every island is degenerate.
    pub scale: f64,
}

/// Lays the UV islands of `mesh` out anew in `[0,1]²` at one texel density (module docs).
///
/// Errors ([`AtlasError`]): the mesh is invalid (an index out of range, a non-finite position or
/// texture coordinate: the message names it), has no UVs, the resolution or gutter is out of range,
/// or the islands do not fit the atlas even at one texel each.
pub fn pack_islands(mesh: &TriMesh, opts: &IslandPacking) -> Result<PackedIslands, AtlasError> {
    let uv = require_uv(mesh)?;
    let IslandPacking { resolution: res, gutter, rotate, search } = *opts;
    check_options(opts)?;
    let (island_of_face, n) = uv_charts(mesh, uv);
    let layout = Layout::of(mesh, uv, &island_of_face, n, rotate);
    let (rect_scale, rects) = best_scale(&layout.islands, res, gutter, rotate).ok_or_else(|| {
        AtlasError::invalid(
            "island packing",
            format!(
                "{n} islands do not fit a {res}² atlas with a {gutter}-texel gutter even at one texel \
                 each; raise the resolution or lower the gutter"
            ),
        )
    })?;
    let shaped = if n <= SHAPES_UP_TO && rect_scale > 0.0 {
        best_shapes(&layout.islands, res, gutter, rotate, rect_scale, search).filter(|(s, _)| *s > rect_scale)
    } else {
        None
    };
    let (scale, arrangement) = match shaped {
        Some((scale, placed)) => (scale, Arrangement::Shapes(placed)),
        None => (rect_scale, Arrangement::Rects(rects)),
    };
    let coords: Vec<[f32; 2]> = layout
        .coords
        .iter()
        .map(|&(island, old)| {
            let i = island as usize;
            let (isl, p) = (&layout.islands[i], uv.coords[old as usize]);
            match &arrangement {
                Arrangement::Rects(packing) => isl.place(p, scale, res, gutter, &packing.cells[i]),
                Arrangement::Shapes(placed) => placed[i].place(isl, p, isl.texels_per_unit(scale, res), res),
            }
        })
        .collect();
    let new_uv = UvLayer { coords, triangles: layout.triangles };
    let efficiency = (0..new_uv.triangles.len()).map(|f| face_uv_area2(&new_uv, f).abs() * 0.5).sum();
    let any_regular = layout.islands.iter().any(|i| !i.degenerate);
    Ok(PackedIslands {
        mesh: TriMesh {
            positions: mesh.positions.clone(),
            triangles: mesh.triangles.clone(),
            uv: Some(new_uv),
        },
        island_of_face,
        islands: n,
        efficiency,
        scale: if any_regular { scale } else { 0.0 },
    })
}

/// Whether the islands of `mesh` fit the atlas of `opts` at the common `scale` (UV units per 3-D
/// unit of length, as [`PackedIslands::scale`]): by their rectangles, or, up to
/// [`SHAPES_UP_TO`] islands, by their shapes, in the orders [`pack_islands`] tries. One
/// packing attempt instead of [`pack_islands`]' bisection on the scale: what a caller that
/// asks "does this layout pack at least this tightly" needs ([`crate::necks`]). Errors as
/// [`pack_islands`]'. To ask about one mesh at several scales, prepare it once with
/// [`ScaleTest::new`].
pub fn packs_at_scale(mesh: &TriMesh, opts: &IslandPacking, scale: f64) -> Result<bool, AtlasError> {
    Ok(ScaleTest::new(mesh, opts)?.packs_at(scale))
}

/// A mesh's islands made ready for [`packs_at_scale`]'s question at any number of scales.
/// Why: the islands, their least-shear turns and the packing orders do not depend on the scale,
/// and working them out (the turns above all) was a third of each of the necks pass's probes,
/// which ask one mesh at up to a dozen scales. The answers are those of [`packs_at_scale`].
pub struct ScaleTest {
    layout: Layout,
    orders: ShapeOrders,
    opts: IslandPacking,
}

impl ScaleTest {
    /// The islands of `mesh` for the atlas of `opts`. Errors as [`pack_islands`]'.
    pub fn new(mesh: &TriMesh, opts: &IslandPacking) -> Result<Self, AtlasError> {
        Self::prepare(mesh, opts, None).map(|(test, _)| test)
    }

    /// As [`ScaleTest::new`], taking every island that `cache` holds unchanged (same faces,
    /// same texture coordinates) from it instead of preparing it again, and returning with the
    /// test the cache this layout leaves (its islands; the hits counted on from `cache`'s).
    /// `cache` is only read, so several trials can share it. The answers are those of
    /// [`ScaleTest::new`]. A cache must only ever see meshes with the same positions (the
    /// layouts of one mesh), which it checks by each island's 3-D area.
    pub fn reusing(
        mesh: &TriMesh,
        opts: &IslandPacking,
        cache: &IslandCache,
    ) -> Result<(Self, IslandCache), AtlasError> {
        Self::prepare(mesh, opts, Some(cache)).map(|(test, next)| (test, next.unwrap_or_default()))
    }

    /// [`ScaleTest::new`] and [`ScaleTest::reusing`]: a cache of this layout only when one was given.
    fn prepare(
        mesh: &TriMesh,
        opts: &IslandPacking,
        cache: Option<&IslandCache>,
    ) -> Result<(Self, Option<IslandCache>), AtlasError> {
        let uv = require_uv(mesh)?;
        check_options(opts)?;
        let (island_of_face, n) = uv_charts(mesh, uv);
        let (layout, next) = Layout::of_cached(mesh, uv, &island_of_face, n, opts.rotate, cache);
        let orders = ShapeOrders::of(&layout.islands);
        Ok((ScaleTest { layout, orders, opts: *opts }, next))
    }

    /// Whether the islands fit at the common `scale` ([`packs_at_scale`]).
    pub fn packs_at(&self, scale: f64) -> bool {
        let IslandPacking { resolution: res, gutter, rotate, .. } = self.opts;
        let islands = &self.layout.islands;
        // No packing fills more than the square, nor holds a cell longer than its side: answered
        // without rasterising footprints at a scale far beyond any that could fit.
        let area: f64 = islands.iter().filter(|i| !i.degenerate).map(|i| i.area_3d).sum();
        let sizes: Vec<[u32; 2]> =
            islands.iter().map(|i| i.cell(scale, res).map(|x| x.saturating_add(gutter))).collect();
        if !(scale.is_finite() && area * scale * scale <= 1.0 && sizes.iter().flatten().all(|&x| x <= res)) {
            return false;
        }
        if pack_rects(&sizes, res, rotate).is_some() {
            return true;
        }
        islands.len() <= SHAPES_UP_TO && self.orders.pack(islands, scale, res, gutter, rotate).is_some()
    }
}

/// Islands prepared for packing (turned to their least shear, outlined), kept from one
/// [`ScaleTest::reusing`] to the next. Why: the necks pass tries dozens of cuts of one
/// mesh, each a layout that differs from the last in one or two islands, and preparing every
/// island again (above all the least-shear turn of every face) was 1.6 s of the horse's 3.8 s
/// pass (BENCHMARKS.md, "More neck cuts"). An island is taken from the cache only when its
/// faces, its texture coordinates (in its own numbering), its 3-D area and the `rotate` option
/// are the same bits, so a hit gives the island that preparing it would. The cache holds the
/// islands of the last layout only (a rejected trial's parts do not pile up).
#[derive(Default)]
pub struct IslandCache {
    /// Keyed by the island's faces, in face order.
    entries: HashMap<Vec<u32>, CachedIsland>,
    /// Islands taken from the cache so far.
    hits: usize,
}

impl IslandCache {
    /// How many islands were taken from the cache instead of being prepared again.
    pub fn hits(&self) -> usize {
        self.hits
    }
}

/// What [`IslandCache`] checks before it reuses an island, and the island.
struct CachedIsland {
    /// The island's texture coordinates before its turn, in its own numbering.
    points: Vec<[f64; 2]>,
    rotate: bool,
    /// Whether its outline was sought (only in layouts of up to [`SHAPES_UP_TO`] islands).
    outlined: bool,
    island: Island,
}

/// The resolution and gutter are in range (errors name them).
fn check_options(opts: &IslandPacking) -> Result<(), AtlasError> {
    let IslandPacking { resolution: res, gutter, .. } = *opts;
    if res == 0 || res > MAX_RESOLUTION {
        return Err(AtlasError::invalid(
            "island packing",
            format!("resolution {res} is not in 1..={MAX_RESOLUTION} texels"),
        ));
    }
    if gutter >= res {
        return Err(AtlasError::invalid(
            "island packing",
            format!("a {gutter}-texel gutter leaves no room in a {res}² atlas"),
        ));
    }
    Ok(())
}

/// The islands of a UV layer and the new layer's connectivity.
struct Layout {
    islands: Vec<Island>,
    /// The new coordinates as `(island, input coordinate)`, in order of first use by a face corner.
    coords: Vec<(u32, u32)>,
    /// The new UV triangles (indices into `coords`).
    triangles: Vec<[u32; 3]>,
}

impl Layout {
    fn of(mesh: &TriMesh, uv: &UvLayer, island_of_face: &[u32], n: usize, rotate: bool) -> Self {
        Self::of_cached(mesh, uv, island_of_face, n, rotate, None).0
    }

    /// [`Layout::of`], reusing the islands `reuse` holds unchanged; with `reuse`, also the
    /// cache of this layout's islands ([`IslandCache`]).
    fn of_cached(
        mesh: &TriMesh,
        uv: &UvLayer,
        island_of_face: &[u32],
        n: usize,
        rotate: bool,
        reuse: Option<&IslandCache>,
    ) -> (Self, Option<IslandCache>) {
        // Maps here are only looked up (never iterated): a fast hasher changes nothing else.
        let mut index: HashMap<(u32, u32), u32> = HashMap::with_capacity(uv.coords.len());
        let mut coords = Vec::with_capacity(uv.coords.len());
        let mut members: Vec<Vec<u32>> = vec![Vec::new(); n];
        let mut area_uv = vec![0.0f64; n];
        let mut area_3d = vec![0.0f64; n];
        let mut metrics: Vec<Vec<[f64; 3]>> = vec![Vec::new(); n];
        let degenerate_area = degenerate_3d_area(mesh);
        // Each face's areas and metric computed in parallel, summed into its island in face
        // order below: the same sums as one loop, and the necks pass prepares a layout per trial
        // (this loop alone was a fifth of the horse's pass).
        let per_face: Vec<(f64, f64, Option<[f64; 3]>)> = (0..uv.triangles.len())
            .into_par_iter()
            .map(|f| {
                let t = uv.triangles[f].map(|j| uv.coords[j as usize]);
                (
                    face_uv_area2(uv, f).abs() * 0.5,
                    face_area_3d(mesh, f),
                    face_metric(mesh.corners(f).map(to_dvec3), t),
                )
            })
            .collect();
        let triangles: Vec<[u32; 3]> = uv
            .triangles
            .iter()
            .enumerate()
            .map(|(f, t)| {
                let i = island_of_face[f];
                let (face_uv, face_3d, metric) = per_face[f];
                // A face without 3-D area has no texel density to match (module docs).
                if !is_degenerate_3d(face_3d, degenerate_area) {
                    area_uv[i as usize] += face_uv;
                }
                area_3d[i as usize] += face_3d;
                if let Some(g) = metric {
                    metrics[i as usize].push(g);
                }
                t.map(|old| {
                    *index.entry((i, old)).or_insert_with(|| {
                        coords.push((i, old));
                        members[i as usize].push(old);
                        (coords.len() - 1) as u32
                    })
                })
            })
            .collect();
        let eps_3d = DEGENERATE_AREA_REL
            * mesh.bounds().map_or(0.0, |b| to_dvec3(b.max).distance(to_dvec3(b.min)).powi(2));
        let eps_uv = DEGENERATE_AREA_REL * uv_square_side(uv).powi(2);
        // Each island's faces in its own numbering of its coordinates (the order of `members`).
        let mut local = Vec::with_capacity(coords.len());
        let mut count = vec![0u32; n];
        for &(i, _) in &coords {
            local.push(count[i as usize]);
            count[i as usize] += 1;
        }
        let mut tris: Vec<Vec<[u32; 3]>> = vec![Vec::new(); n];
        let mut faces: Vec<Vec<u32>> = vec![Vec::new(); n];
        for (f, t) in triangles.iter().enumerate() {
            tris[island_of_face[f] as usize].push(t.map(|j: u32| local[j as usize]));
            faces[island_of_face[f] as usize].push(f as u32);
        }
        let prepared: Vec<(Island, Vec<[f64; 2]>, bool)> = (0..n)
            .into_par_iter()
            .zip(tris)
            .zip(metrics)
            .map(|((i, tris), metric)| {
                let points: Vec<[f64; 2]> =
                    members[i].iter().map(|&c| uv.coords[c as usize].map(|x| x as f64)).collect();
                // Whether an island is degenerate also depends on the whole layer's extent.
                let degenerate = !(area_3d[i] > eps_3d && area_uv[i] > eps_uv);
                let hit = reuse.and_then(|c| c.entries.get(&faces[i])).filter(|c| {
                    c.rotate == rotate
                        && c.outlined == (n <= SHAPES_UP_TO)
                        && c.island.degenerate == degenerate
                        && c.island.area_3d.to_bits() == area_3d[i].to_bits()
                        && c.island.tris == tris
                        && c.points == points
                });
                if let Some(c) = hit {
                    return (c.island.clone(), points, true);
                }
                let mut island =
                    Island::new(&points, tris, &metric, area_uv[i], area_3d[i], degenerate, rotate);
                if n <= SHAPES_UP_TO {
                    island.outline = shapes::Outline::of(&island.points, &island.tris);
                }
                (island, points, false)
            })
            .collect();
        let next = reuse.map(|old| {
            let hits = old.hits + prepared.iter().filter(|(_, _, hit)| *hit).count();
            let entries = faces
                .into_iter()
                .zip(&prepared)
                .map(|(f, (island, points, _))| {
                    let outlined = n <= SHAPES_UP_TO;
                    (f, CachedIsland { points: points.clone(), rotate, outlined, island: island.clone() })
                })
                .collect();
            IslandCache { entries, hits }
        });
        let islands = prepared.into_iter().map(|(island, ..)| island).collect();
        (Self { islands, coords, triangles }, next)
    }
}

/// Side of the bounding square of every UV coordinate (0 for none).
fn uv_square_side(uv: &UvLayer) -> f64 {
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for p in &uv.coords {
        for k in 0..2 {
            lo[k] = lo[k].min(p[k] as f64);
            hi[k] = hi[k].max(p[k] as f64);
        }
    }
    (hi[0] - lo[0]).max(hi[1] - lo[1]).max(0.0)
}

#[derive(Clone)]
/// One island's fixed frame: its rotation, its bounding rectangle in that frame and how its size
/// grows with the atlas scale.
struct Island {
    /// `(cos, sin)` of the rotation applied to the input UVs.
    rot: [f64; 2],
    /// Lower-left corner of the bounding rectangle of the rotated UVs.
    min: [f64; 2],
    /// Its sides, in input UV units.
    extent: [f64; 2],
    /// Texels per input UV unit per unit of atlas scale and resolution (`sqrt(area_3d / area_uv)`),
    /// or, for a degenerate island, texels per input UV unit (fixed).
    growth: f64,
    degenerate: bool,
    /// Its 3-D area.
    area_3d: f64,
    /// The island's coordinates turned by `rot` (input UV units), in the island's own numbering.
    points: Vec<[f64; 2]>,
    /// Its faces in that numbering.
    tris: Vec<[u32; 3]>,
    /// Whether a further 45° turn leaves its shear (mean |cos(T, B)|) within [`TURN_SHEAR`]:
    /// then the shape packer may lay it along a diagonal.
    diagonal: bool,
    /// What the shape packer needs to rasterise it by its boundary (`None`: by every face, or
    /// not packed by its shape at all: [`Layout::of`] finds it only up to [`SHAPES_UP_TO`]
    /// islands).
    outline: Option<shapes::Outline>,
}

impl Island {
    fn new(
        points: &[[f64; 2]],
        tris: Vec<[u32; 3]>,
        metric: &[[f64; 3]],
        area_uv: f64,
        area_3d: f64,
        degenerate: bool,
        rotate: bool,
    ) -> Self {
        let (rot, diagonal) = if rotate {
            let rect = min_area_rotation(&convex_hull(points));
            let terms = ShearTerms::of(metric);
            let rot = least_shear_rotation(&terms, rect);
            let diagonal = terms.mean(compose(rot, shapes::turn(1))) <= terms.mean(rot) + TURN_SHEAR;
            (rot, diagonal)
        } else {
            ([1.0, 0.0], false)
        };
        let points: Vec<[f64; 2]> = points.iter().map(|&p| rotated(p, rot)).collect();
        let (mut min, mut max) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for &q in &points {
            for k in 0..2 {
                min[k] = min[k].min(q[k]);
                max[k] = max[k].max(q[k]);
            }
        }
        let extent = [max[0] - min[0], max[1] - min[1]];
        let growth = if degenerate {
            let longest = extent[0].max(extent[1]);
            if longest > 0.0 { 1.0 / longest } else { 0.0 }
        } else {
            (area_3d / area_uv).sqrt()
        };
        Self { rot, min, extent, growth, degenerate, area_3d, points, tris, diagonal, outline: None }
    }

    /// Texels per input UV unit at atlas `scale` and `res`.
    fn texels_per_unit(&self, scale: f64, res: u32) -> f64 {
        if self.degenerate { self.growth } else { self.growth * scale * res as f64 }
    }

    /// The island's bounding rectangle in texels (unturned) at `scale`.
    fn size(&self, scale: f64, res: u32) -> [f64; 2] {
        let t = self.texels_per_unit(scale, res);
        [self.extent[0] * t, self.extent[1] * t]
    }

    /// The cell (whole texels, at least one) at `scale`.
    fn cell(&self, scale: f64, res: u32) -> [u32; 2] {
        self.size(scale, res).map(|s| (s.ceil() as u32).max(1))
    }

    /// Where the input UV `p` of this island lands in the atlas, the island's cell placed at `at`.
    fn place(&self, p: [f32; 2], scale: f64, res: u32, gutter: u32, at: &Placed) -> [f32; 2] {
        let t = self.texels_per_unit(scale, res);
        let q = rotated(p.map(|x| x as f64), self.rot);
        let mut q = [(q[0] - self.min[0]) * t, (q[1] - self.min[1]) * t];
        let mut size = self.size(scale, res);
        let mut cell = self.cell(scale, res);
        if at.turned {
            // A quarter turn counter-clockwise, shifted back into the positive quadrant.
            q = [size[1] - q[1], q[0]];
            size = [size[1], size[0]];
            cell = [cell[1], cell[0]];
        }
        // Packer rows count from the top of the atlas (v = 1), like `AtlasLayout`'s.
        let half = (gutter / 2) as f64;
        let left = at.x as f64 + half + 0.5 * (cell[0] as f64 - size[0]);
        let bottom = res as f64 - (at.y as f64 + half + cell[1] as f64) + 0.5 * (cell[1] as f64 - size[1]);
        let r = res as f64;
        [((left + q[0]) / r).clamp(0.0, 1.0) as f32, ((bottom + q[1]) / r).clamp(0.0, 1.0) as f32]
    }
}

/// How much a turn must lower an island's mean |cos(T, B)| to replace its minimum-area rotation,
/// and how much a further 45° turn may raise it for the shape packer to use that: below this,
/// the angular score gains or loses less than the tighter packing is worth.
const TURN_SHEAR: f64 = 5e-4;

/// The metric `[T·T, T·B, B·B]` of a face's affine UV→3-D map, `T = ∂p/∂u`, `B = ∂p/∂v`, up to
/// the common factor `1/det²` (which |cos(T, B)| ignores); `None` when the face is degenerate in
/// 3-D or so thin in UV (`|det| ≤ 1e-6 · (|e₁|² + |e₂|²)`) that its axes mean nothing.
fn face_metric(p: [DVec3; 3], t: [[f32; 2]; 3]) -> Option<[f64; 3]> {
    let (e1, e2) = (p[1] - p[0], p[2] - p[0]);
    let d = |k: usize, c: usize| t[k][c] as f64 - t[0][c] as f64;
    let (du1, dv1, du2, dv2) = (d(1, 0), d(1, 1), d(2, 0), d(2, 1));
    let det = du1 * dv2 - du2 * dv1;
    if det.abs() <= 1e-6 * (du1 * du1 + dv1 * dv1 + du2 * du2 + dv2 * dv2) {
        return None;
    }
    let (tt, bt) = crate::uvstats::texture_axes(e1, e2, [du1, dv1, du2, dv2]);
    let g = [tt.dot(tt), tt.dot(bt), bt.dot(bt)];
    (g[0] > 0.0 && g[2] > 0.0 && g.iter().all(|x| x.is_finite())).then_some(g)
}

/// The faces' metrics in the form in which a turn's shear is cheap: per face `m = (G₁₁ + G₂₂)/2`,
/// `h = (G₁₁ − G₂₂)/2` and `G₁₂`, in three arrays. Turned by θ (`G' = R G Rᵀ`), a face has
/// `T·T = m + k`, `B·B = m − k` and `T·B = h sin 2θ + G₁₂ cos 2θ` with `k = h cos 2θ − G₁₂ sin 2θ`,
/// so |cos(T, B)| = |T·B| / √(m² − k²): four products a face for each angle where the turned
/// metric took twelve, over arrays the compiler vectorises. Why: [`least_shear_rotation`]
/// evaluates ~230 angles over every face of an island, for every island the necks pass's
/// trials prepare (0.8 of the horse's 1.7 CPU seconds in that pass, BENCHMARKS.md).
struct ShearTerms {
    m: Vec<f64>,
    h: Vec<f64>,
    g12: Vec<f64>,
}

/// Faces summed side by side in [`ShearTerms::mean`] (its partial sums, added in a fixed order).
const SHEAR_LANES: usize = 4;

impl ShearTerms {
    fn of(metric: &[[f64; 3]]) -> Self {
        ShearTerms {
            m: metric.iter().map(|g| 0.5 * (g[0] + g[2])).collect(),
            h: metric.iter().map(|g| 0.5 * (g[0] - g[2])).collect(),
            g12: metric.iter().map(|g| g[1]).collect(),
        }
    }

    /// Mean |cos(T, B)| of the faces once their UVs are turned by `rot` (`(cos θ, sin θ)`);
    /// 0 for no face. The faces are summed in [`SHEAR_LANES`] partial sums, each in face order,
    /// then added in lane order: the same bits on any machine and thread count.
    fn mean(&self, rot: [f64; 2]) -> f64 {
        let n = self.m.len();
        if n == 0 {
            return 0.0;
        }
        let [c, s] = rot;
        let (cos2, sin2) = (c * c - s * s, 2.0 * c * s);
        let term = |m: f64, h: f64, g: f64| {
            let k = h * cos2 - g * sin2;
            let off = h * sin2 + g * cos2;
            off.abs() / (m * m - k * k).max(f64::MIN_POSITIVE).sqrt()
        };
        let mut lanes = [0.0f64; SHEAR_LANES];
        let split = n - n % SHEAR_LANES;
        let (m, h, g) = (&self.m[..split], &self.h[..split], &self.g12[..split]);
        for ((m, h), g) in
            m.chunks_exact(SHEAR_LANES).zip(h.chunks_exact(SHEAR_LANES)).zip(g.chunks_exact(SHEAR_LANES))
        {
            for l in 0..SHEAR_LANES {
                lanes[l] += term(m[l], h[l], g[l]);
            }
        }
        for i in split..n {
            lanes[i - split] += term(self.m[i], self.h[i], self.g12[i]);
        }
        lanes.iter().sum::<f64>() / n as f64
    }

    fn len(&self) -> usize {
        self.m.len()
    }
}

/// Faces from which [`least_shear_rotation`] evaluates its grid's angles in parallel.
const PAR_SHEAR_FACES: usize = 2000;

/// The turn that makes the island's texture axes shear least on the surface: the angle in
/// `[0°, 90°)` minimising [`shear`] (0.5° grid, then golden-section search within the best grid
/// cell), or `fallback` unless that is lower than `fallback`'s by more than [`TURN_SHEAR`].
///
/// Why: PartUV's angular score and the paper's Conformal measure the angle between `T` and `B`,
/// which for a map that is not exactly conformal depends on how the island is turned in the
/// atlas (a quarter turn only swaps them). Turning each island so that its map's stretch runs
/// along the texture axes makes a checker's squares rectangles on the surface instead of
/// parallelograms; on the Common Shapes atlases it raises the mean angular score by ~0.003.
fn least_shear_rotation(terms: &ShearTerms, fallback: [f64; 2]) -> [f64; 2] {
    let at = |deg: f64| {
        let r = deg.to_radians();
        [r.cos(), r.sin()]
    };
    let f = |deg: f64| terms.mean(at(deg));
    let step = 0.5;
    // The grid's angles in parallel (each angle's sum over the faces is taken alone in its fixed
    // order, so the values and the choice, the first lowest, are those of a sequential scan):
    // one large island's turn was the tail of the islands' parallel loop.
    let grid: Vec<f64> = if terms.len() >= PAR_SHEAR_FACES {
        (0..180).into_par_iter().map(|k| f(k as f64 * step)).collect()
    } else {
        (0..180).map(|k| f(k as f64 * step)).collect()
    };
    let (mut best, mut best_f) = (0.0, grid[0]);
    for (k, &v) in grid.iter().enumerate().skip(1) {
        if v < best_f {
            (best, best_f) = (k as f64 * step, v);
        }
    }
    let golden = 0.5 * (5f64.sqrt() - 1.0);
    let (mut a, mut b) = (best - step, best + step);
    for _ in 0..24 {
        let (x1, x2) = (b - golden * (b - a), a + golden * (b - a));
        if f(x1) < f(x2) { b = x2 } else { a = x1 }
    }
    let mid = 0.5 * (a + b);
    let at_mid = f(mid);
    if at_mid < best_f {
        (best, best_f) = (mid, at_mid);
    }
    if best_f < terms.mean(fallback) - TURN_SHEAR {
        // The same axes, turned by the quarter turn that brings the angle nearest to zero.
        let deg = best - 90.0 * (best / 90.0).round();
        at(deg)
    } else {
        fallback
    }
}

/// The turn `b` after `a`, as `(cos, sin)`.
fn compose(a: [f64; 2], b: [f64; 2]) -> [f64; 2] {
    [a[0] * b[0] - a[1] * b[1], a[0] * b[1] + a[1] * b[0]]
}

/// `p` rotated by the angle whose `(cos, sin)` is `rot`.
pub(crate) fn rotated(p: [f64; 2], rot: [f64; 2]) -> [f64; 2] {
    [rot[0] * p[0] - rot[1] * p[1], rot[1] * p[0] + rot[0] * p[1]]
}

/// Points from which [`convex_hull`] sorts in parallel.
const HULL_PARALLEL_POINTS: usize = 4096;

/// Convex hull, counter-clockwise, without collinear points (Andrew's monotone chain). Fewer than
/// three points, or collinear ones, give their extreme points.
pub(crate) fn convex_hull(points: &[[f64; 2]]) -> Vec<[f64; 2]> {
    let mut p = points.to_vec();
    // Points equal under this order are the same bits, so an unstable sort leaves the same
    // sequence; in parallel for a large island (a neck cut's parts, prepared one a trial).
    let by_x_then_y = |a: &[f64; 2], b: &[f64; 2]| a[0].total_cmp(&b[0]).then(a[1].total_cmp(&b[1]));
    if p.len() >= HULL_PARALLEL_POINTS {
        p.par_sort_unstable_by(by_x_then_y);
    } else {
        p.sort_unstable_by(by_x_then_y);
    }
    p.dedup();
    if p.len() < 3 {
        return p;
    }
    let turn =
        |o: [f64; 2], a: [f64; 2], b: [f64; 2]| (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0]);
    let mut hull: Vec<[f64; 2]> = Vec::with_capacity(2 * p.len());
    for pass in 0..2 {
        let start = hull.len();
        let iter: Box<dyn Iterator<Item = &[f64; 2]>> =
            if pass == 0 { Box::new(p.iter()) } else { Box::new(p.iter().rev()) };
        for &q in iter {
            while hull.len() >= start + 2 && turn(hull[hull.len() - 2], hull[hull.len() - 1], q) <= 0.0 {
                hull.pop();
            }
            hull.push(q);
        }
        hull.pop(); // the last point starts the other chain
    }
    hull
}

/// The rotation `(cos, sin)` that makes the minimum-area bounding rectangle of the convex polygon
/// `hull` axis-aligned, the smallest such angle (in `(-45°, 45°]`). The rectangle has a side on a
/// hull edge; each edge is tried and the first of equal areas kept.
pub(crate) fn min_area_rotation(hull: &[[f64; 2]]) -> [f64; 2] {
    if hull.len() < 2 {
        return [1.0, 0.0];
    }
    let m = hull.len();
    let mut best: Option<(f64, f64)> = None; // (area, angle of the edge)
    for j in 0..m {
        let (a, b) = (hull[j], hull[(j + 1) % m]);
        let d = [b[0] - a[0], b[1] - a[1]];
        let len = (d[0] * d[0] + d[1] * d[1]).sqrt();
        if len == 0.0 {
            continue;
        }
        let (u, n) = ([d[0] / len, d[1] / len], [-d[1] / len, d[0] / len]);
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for p in hull {
            let s = [p[0] * u[0] + p[1] * u[1], p[0] * n[0] + p[1] * n[1]];
            for k in 0..2 {
                lo[k] = lo[k].min(s[k]);
                hi[k] = hi[k].max(s[k]);
            }
        }
        let area = (hi[0] - lo[0]) * (hi[1] - lo[1]);
        if best.is_none_or(|(a, _)| area < a * (1.0 - 1e-12)) {
            best = Some((area, d[1].atan2(d[0])));
        }
    }
    let Some((_, angle)) = best else { return [1.0, 0.0] };
    // Rotate by -angle, then by the multiple of 90° that brings the total nearest to zero.
    let quarter = std::f64::consts::FRAC_PI_2;
    let mut turn = -angle;
    turn -= (turn / quarter).round() * quarter;
    if turn <= -quarter / 2.0 {
        turn += quarter;
    }
    [turn.cos(), turn.sin()]
}

/// A successful packing: where each island's rectangle goes.
struct Packing {
    cells: Vec<Placed>,
}

/// The largest atlas scale found at which every island's rectangle fits, and that packing; `None`
/// if they do not fit even at scale 0 (every cell one texel).
fn best_scale(islands: &[Island], res: u32, gutter: u32, rotate: bool) -> Option<(f64, Packing)> {
    let cells = |scale: f64| -> Vec<[u32; 2]> { islands.iter().map(|i| i.cell(scale, res)).collect() };
    let try_cells = |cells: &[[u32; 2]]| -> Option<Packing> {
        let sizes: Vec<[u32; 2]> = cells.iter().map(|c| c.map(|x| x + gutter)).collect();
        pack_rects(&sizes, res, rotate).map(|cells| Packing { cells })
    };
    // A necessary condition, growing with the scale: the rectangles' total area is at most the
    // square's, and each fits its side.
    let may_fit = |scale: f64| {
        let (mut area, side) = (0u64, res as u64);
        cells(scale).iter().all(|c| {
            let [w, h] = c.map(|x| (x + gutter) as u64);
            area += w * h;
            w <= side && h <= side
        }) && area <= side * side
    };
    if !may_fit(0.0) {
        return None;
    }
    // The scale at which the islands' bounding rectangles alone would fill the square or one of
    // them its side; every scale beyond breaks `may_fit`.
    let (mut area, mut longest) = (0.0f64, 0.0f64);
    for i in islands.iter().filter(|i| !i.degenerate) {
        let e = i.extent.map(|x| x * i.growth);
        area += e[0] * e[1];
        longest = longest.max(e[0].max(e[1]));
    }
    if longest == 0.0 {
        return try_cells(&cells(0.0)).map(|p| (0.0, p));
    }
    let mut hi = (1.0 / longest).min(if area > 0.0 { 1.0 / area.sqrt() } else { f64::INFINITY });
    // Tighten it to the largest scale that passes `may_fit` (no packing needed).
    if !may_fit(hi) {
        let mut ok = 0.0;
        for _ in 0..64 {
            let mid = 0.5 * (ok + hi);
            if may_fit(mid) { ok = mid } else { hi = mid }
        }
        hi = ok;
    }
    let mut hi_cells = cells(hi);
    if let Some(p) = try_cells(&hi_cells) {
        return Some((hi, p));
    }
    // Bisection to 1e-6 relative. Cells only change at discrete scales: a midpoint with the cells
    // of a scale known to fit (or not) is not packed again.
    let (mut lo, mut lo_cells, mut packing) = (0.0, cells(0.0), None);
    for _ in 0..64 {
        if hi - lo <= hi * 1e-6 {
            break;
        }
        let mid = 0.5 * (lo + hi);
        let mid_cells = cells(mid);
        if mid_cells == hi_cells {
            hi = mid;
        } else if mid_cells == lo_cells && packing.is_some() {
            lo = mid;
        } else if let Some(p) = try_cells(&mid_cells) {
            (lo, lo_cells, packing) = (mid, mid_cells, Some(p));
        } else {
            (hi, hi_cells) = (mid, mid_cells);
        }
    }
    match packing {
        Some(p) => Some((lo, p)),
        None => try_cells(&lo_cells).map(|p| (lo, p)),
    }
}

/// How the islands were laid out: by their bounding rectangles or by their shapes.
enum Arrangement {
    Rects(Packing),
    Shapes(Vec<ShapePlaced>),
}

/// Up to this many islands their shapes are packed too (`shapes`), and the packing of the
/// larger scale is kept. Beyond, only rectangles: the shape search's cost grows with the islands
/// already placed (measured in BENCHMARKS.md, "Shape packing").
pub const SHAPES_UP_TO: usize = 500;

/// The relative width of the scale interval at which the shape packer's bisection stops. Each
/// trial packs every island up to five times; the last trials of a finer bisection move the
/// efficiency by hundredths of a percent. 1e-3 (an efficiency within 0.2% of the bracket's top):
/// on the 14 Common Shapes atlases 0.5958 → 0.5955 and 17–24% less packing time than 2e-4
/// (BENCHMARKS.md, "A coarser bisection for the shape packer").
pub const SHAPE_SCALE_PRECISION: f64 = 1e-3;

/// The largest atlas scale found, by bisection from `from` (to [`SHAPE_SCALE_PRECISION`]), at which the
/// islands' shapes pack ([`shapes::pack_shapes`]), with that packing; `None` when they do not
/// pack even at `from`. A scale packs when one of five attempts fits every island, tried in
/// turn: the lowest-top rule ([`Rule::LowestTop`]) with the islands by decreasing 3-D area, else
/// by decreasing longest side, else by decreasing bounding-rectangle area (the third order took
/// Common Shapes from 0.4915 to 0.4959), then the corner and square rules ([`Rule::Corner`],
/// [`Rule::Square`]) by decreasing area. Measured on the 14 Common Shapes atlases at 2048²
/// (BENCHMARKS.md, "Three placement rules"): the two added rules took the mean efficiency from
/// 0.582 to 0.601 for 1.4× the packing time; both rules in all three orders reached 0.603 for
/// 2.2× (times before footprints came from the outline, [`shapes::Outline`], which made the
/// whole faster than the one rule had been).
fn best_shapes(
    islands: &[Island],
    res: u32,
    gutter: u32,
    rotate: bool,
    from: f64,
    search: usize,
) -> Option<(f64, Vec<ShapePlaced>)> {
    let orders = ShapeOrders::of(islands);
    let trial = |scale: f64| orders.pack(islands, scale, res, gutter, rotate);
    // The scale, its packing, and which of the attempts made it.
    let (attempt, placed) = trial(from)?;
    let mut best = (from, placed, attempt);
    // Every face area at once cannot exceed the square: the scale at which it would fill it.
    let area: f64 = islands.iter().filter(|i| !i.degenerate).map(|i| i.area_3d).sum();
    if area <= 0.0 {
        return Some((best.0, best.1));
    }
    let mut hi = 1.0 / area.sqrt();
    let mut lo = from;
    while hi - lo > SHAPE_SCALE_PRECISION * hi {
        let mid = 0.5 * (lo + hi);
        match trial(mid) {
            Some((attempt, p)) => {
                lo = mid;
                best = (mid, p, attempt);
            }
            None => hi = mid,
        }
    }
    let (scale, placed, attempt) = best;
    let start = orders.attempts[attempt].clone();
    let (best, order, rule) = search_orders(islands, res, gutter, rotate, (scale, placed), start, search);
    Some(search_places(islands, res, gutter, rotate, best, &order, rule, search))
}

/// The packing `best` of the order search, raised [`PLACE_SEARCH_STEP`] at a time while
/// [`shapes::pack_shapes_searched`] finds a packing of the search's last `order` by its last
/// `rule` at the next scale: first with one departure from the rule's choice, then two, up to
/// [`PLACE_SEARCH`]'s (`SearchLimits::deepen`); all of it within [`PLACE_SEARCH_BUDGET`]
/// footprint placements searched. Nothing without the order search (`search == 0`: the necks
/// pass's trial layouts) or beyond [`SEARCH_UP_TO`] islands. Measured on re-bakes of the 14
/// Common Shapes checkpoints (BENCHMARKS.md, "The large islands' places searched"): packing
/// efficiency 0.6800 → 0.6902, charts unchanged, Editability 0.9676 → 0.9679, the pack phase
/// 0.43 → 0.97 s a mesh.
#[allow(clippy::too_many_arguments)]
fn search_places(
    islands: &[Island],
    res: u32,
    gutter: u32,
    rotate: bool,
    mut best: (f64, Vec<ShapePlaced>),
    order: &[usize],
    rule: Rule,
    search: usize,
) -> (f64, Vec<ShapePlaced>) {
    if !searches(islands, search) {
        return best;
    }
    let mut budget = PLACE_SEARCH_BUDGET;
    while budget > 0 {
        let target = best.0 * (1.0 + PLACE_SEARCH_STEP);
        let fps = footprints_at(islands, target, res, rotate);
        match shapes::pack_shapes_searched(&fps, order, res, gutter, rule, PLACE_SEARCH, &mut budget) {
            Some(placed) => best = (target, placed),
            None => break,
        }
    }
    best
}

/// Whether the searches after the bisection run: with `attempts` asked for and 2 to
/// [`SEARCH_UP_TO`] islands.
fn searches(islands: &[Island], attempts: usize) -> bool {
    attempts > 0 && (2..=SEARCH_UP_TO).contains(&islands.len())
}

/// The islands' footprints at atlas scale `scale` (the shape packings' input).
fn footprints_at(islands: &[Island], scale: f64, res: u32, rotate: bool) -> Vec<Vec<shapes::Footprint>> {
    shapes::footprints(islands, |i: &Island| i.texels_per_unit(scale, res), rotate)
}

/// How far [`search_places`] looks at each scale: the places of the first 6 islands of the
/// order (where the packings at the largest scale fail: the third to seventh island on the
/// Common Shapes atlases), each in up to 6 orientations, at most 3 of them away from the
/// rule's choice.
const PLACE_SEARCH: shapes::SearchLimits =
    shapes::SearchLimits { depth: 6, width: 6, discrepancies: 3, speculate: true, deepen: true };

/// The relative rise of the scale at each step of `search_places`: finer than the order
/// search's [`SEARCH_STEP`], as each step's search is dearer and its gain smaller.
pub const PLACE_SEARCH_STEP: f64 = 0.003;

/// Footprint placements (`best_fit` calls) `search_places` may search in all: on the Common
/// Shapes atlases at 2048², 0.54 s a mesh on average and 1.5 s at most (the teapot) on 2 Zen 5
/// cores when places were searched one at a time, ~0.3 s less on the teapot two at a time
/// (BENCHMARKS.md). The calls counted are those of the sequential search either way, and of
/// its iterations as separate searches: a call the memo of a deepening search
/// (`shapes::SearchLimits::deepen`) spares is counted as if made.
pub const PLACE_SEARCH_BUDGET: usize = 10_000;

/// Packing attempts of the order search (`search_orders`) in `nuvo unwrap`'s final layout.
/// Re-bakes of the 14 Common Shapes checkpoints (BENCHMARKS.md, "An order search after the
/// bisection"): packing efficiency 0.5896 → 0.5991 (the bunny 0.584 → 0.632, the horse 0.470 →
/// 0.489, some meshes unchanged), Editability unchanged, the pack phase 0.66 → 1.06 s a mesh.
pub const ORDER_SEARCH: usize = 24;

/// The relative rise of the scale each attempt of the order search asks for.
pub const SEARCH_STEP: f64 = 0.01;

/// Islands up to which the order search runs. Each attempt places every island, and its cost
/// grows with the islands placed before it; Nuvo's atlases have few (Common Shapes: at most 28),
/// while a marching-cubes mesh's hundreds of floaters gain nothing from an order.
pub const SEARCH_UP_TO: usize = 64;

/// The shape packing `best` (scale, placement) of [`best_shapes`], improved by a search over
/// island orders (for 2 to [`SEARCH_UP_TO`] islands): `attempts` times, the rule and order
/// that packed last (at first, `start`: the attempt of [`best_shapes`] that packed `best`) with
/// two islands at most three places apart swapped (and, one time in four, another placement
/// rule) is packed at [`SEARCH_STEP`] above the current scale; when it fits, it becomes the
/// current packing, rule and order. Why: the bisection stops at the largest scale one of five
/// fixed attempts packs, and a greedy placement's success is sensitive to the order of the
/// large islands in ways no fixed order serves for every mesh. Deterministic: the swaps come
/// from a fixed-seed LCG.
fn search_orders(
    islands: &[Island],
    res: u32,
    gutter: u32,
    rotate: bool,
    best: (f64, Vec<ShapePlaced>),
    start: (Rule, Vec<usize>),
    attempts: usize,
) -> ((f64, Vec<ShapePlaced>), Vec<usize>, Rule) {
    let (mut rule, mut order) = start;
    if !searches(islands, attempts) {
        return (best, order, rule);
    }
    let footprints = |scale: f64| footprints_at(islands, scale, res, rotate);
    let mut best = best;
    let mut state = 0x9e37_79b9_7f4a_7c15u64;
    let mut draw = |n: usize| {
        state = state.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1_442_695_040_888_963_407);
        (state >> 33) as usize % n
    };
    // Each attempt's swap and rule, drawn up front: the draws do not depend on what fits.
    let n = order.len();
    let moves: Vec<(usize, usize, Option<Rule>)> = (0..attempts)
        .map(|_| {
            let i = draw(n);
            let j = (i + 1 + draw(3)).min(n - 1);
            let r = (draw(4) == 0).then(|| [Rule::LowestTop, Rule::Corner, Rule::Square][draw(3)]);
            (i, j, r)
        })
        .collect();
    let mut target = best.0 * (1.0 + SEARCH_STEP);
    // The current order's packing at the target, kept island by island: an attempt places only
    // the islands from its swap on, and none when the current order fails before the swap.
    let mut head = shapes::GreedyHead::new(footprints(target), &order, res, gutter, rule);
    let attempt =
        |order: &[usize], rule: Rule, head: &shapes::GreedyHead, (i, j, r): (usize, usize, Option<Rule>)| {
            let mut candidate = order.to_vec();
            candidate.swap(i, j);
            let r = r.unwrap_or(rule);
            head.pack(&candidate, r).map(|placed| (placed, candidate, r))
        };
    let mut a = 0;
    while a < moves.len() {
        // Two attempts at once: the second from the same packing, as the sequential search
        // makes it when the first does not fit (most do not); when the first fits, the second
        // is made again from the new packing. Same result as one at a time.
        let (first, second) = match moves.get(a + 1) {
            Some(&next) => {
                rayon::join(|| attempt(&order, rule, &head, moves[a]), || attempt(&order, rule, &head, next))
            }
            None => (attempt(&order, rule, &head, moves[a]), None),
        };
        let (taken, fitted) = match (first, second) {
            (Some(fitted), _) => (1, Some(fitted)),
            (None, second) => (2, second),
        };
        if let Some((placed, candidate, r)) = fitted {
            (best, order, rule) = ((target, placed), candidate, r);
            target = best.0 * (1.0 + SEARCH_STEP);
            head = shapes::GreedyHead::new(footprints(target), &order, res, gutter, rule);
        }
        a += taken;
    }
    (best, order, rule)
}

/// The placement rules and island orders [`best_shapes`] tries, in turn (its docs).
struct ShapeOrders {
    attempts: Vec<(Rule, Vec<usize>)>,
}

impl ShapeOrders {
    fn of(islands: &[Island]) -> Self {
        let order = |key: &dyn Fn(&Island) -> f64| {
            let mut o: Vec<usize> = (0..islands.len()).collect();
            let k = |i: usize| if islands[i].degenerate { -1.0 } else { key(&islands[i]) };
            o.sort_by(|&a, &b| k(b).total_cmp(&k(a)).then(a.cmp(&b)));
            o
        };
        let by_area = order(&|i| i.area_3d);
        let by_side = order(&|i| i.growth * i.extent[0].max(i.extent[1]));
        let by_box = order(&|i| i.growth * i.growth * i.extent[0] * i.extent[1]);
        let attempts = vec![
            (Rule::LowestTop, by_area.clone()),
            (Rule::LowestTop, by_side),
            (Rule::LowestTop, by_box),
            (Rule::Corner, by_area.clone()),
            (Rule::Square, by_area),
        ];
        ShapeOrders { attempts }
    }

    /// The islands' shapes packed at `scale` by the first attempt that fits them, with its index.
    fn pack(
        &self,
        islands: &[Island],
        scale: f64,
        res: u32,
        gutter: u32,
        rotate: bool,
    ) -> Option<(usize, Vec<ShapePlaced>)> {
        let fps = footprints_at(islands, scale, res, rotate);
        let attempt = |k: usize| {
            let (rule, order) = &self.attempts[k];
            shapes::pack_shapes(&fps, order, res, gutter, *rule).map(|p| (k, p))
        };
        // Two attempts at once, the first that fits in order kept: the second core, which each
        // island's placement (4–8 orientations) keeps only partly busy, tries the next attempt.
        (0..self.attempts.len()).step_by(2).find_map(|k| {
            if k + 1 < self.attempts.len() {
                let (a, b) = rayon::join(|| attempt(k), || attempt(k + 1));
                a.or(b)
            } else {
                attempt(k)
            }
        })
    }
}

// ---- The rectangle packer -------------------------------------------------------------------

/// Where [`pack_rects`] put a rectangle: its top-left corner in texels (rows from the top) and
/// whether it was turned by 90° (its width and height swapped).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Placed {
    x: u32,
    y: u32,
    turned: bool,
}

/// A sort key of a rectangle's sides.
type OrderKey = fn([u64; 2]) -> (u64, u64);

/// Rectangle orders tried by [`pack_rects`], in turn, as sort keys (larger first, ties by
/// index) of a rectangle's `[longer, shorter]` side when rotations are allowed, else of
/// `[width, height]`: area (then longer side), then height (then width).
const ORDERS: [OrderKey; 2] = [|s| (s[0] * s[1], s[0].max(s[1])), |s| (s[1], s[0])];

/// Up to this many islands the packer is MaxRects, whose cost grows with the square of their
/// number; beyond, a skyline packer, nearly linear but packing less tightly (the bunny's 1,062
/// islands at 1024²: 0.502 of the atlas against 0.531; 4,000 random triangles: 0.32 against
/// 0.36). With MaxRects 1,000 islands take ~0.3 s, 4,000 several seconds; with the skyline 16,000
/// take 1–2 s.
pub const MAXRECTS_UP_TO: usize = 2000;

/// Packs rectangles `sizes` (`[width, height]` in texels) into a `side × side` square with
/// [`maxrects_pack`] (or, for many, [`skyline_pack`]) in each of the [`ORDERS`]: the first that
/// fits, `None` if none does.
fn pack_rects(sizes: &[[u32; 2]], side: u32, rotate: bool) -> Option<Vec<Placed>> {
    let key = |s: [u32; 2]| {
        let s = if rotate { [s[0].max(s[1]), s[0].min(s[1])] } else { s };
        s.map(u64::from)
    };
    ORDERS.iter().find_map(|k| {
        let mut order: Vec<usize> = (0..sizes.len()).collect();
        order.sort_by(|&a, &b| k(key(sizes[b])).cmp(&k(key(sizes[a]))).then(a.cmp(&b)));
        if sizes.len() <= MAXRECTS_UP_TO {
            maxrects_pack(sizes, &order, side, rotate)
        } else {
            skyline_pack(sizes, &order, side, rotate)
        }
    })
}

/// Packs rectangles in the given order with MaxRects, best short side fit (Jylänki 2010): the
/// free space is kept as the list of maximal free rectangles, each rectangle goes into the free
/// one that leaves the least along its shorter leftover side (then the longer, then the first in
/// the list), both orientations tried with `rotate` (ties keep it unturned).
fn maxrects_pack(sizes: &[[u32; 2]], order: &[usize], side: u32, rotate: bool) -> Option<Vec<Placed>> {
    let mut free = vec![Rect { x: 0, y: 0, w: side, h: side }];
    let mut out = vec![Placed { x: 0, y: 0, turned: false }; sizes.len()];
    let mut fresh = Vec::new();
    for &r in order {
        let [w, h] = sizes[r];
        let mut best: Option<((u32, u32), Rect, bool)> = None;
        for f in &free {
            for turned in [false, true] {
                if turned && (!rotate || w == h) {
                    continue;
                }
                let (w, h) = if turned { (h, w) } else { (w, h) };
                if w <= f.w && h <= f.h {
                    let (a, b) = (f.w - w, f.h - h);
                    let score = (a.min(b), a.max(b));
                    if best.is_none_or(|(s, ..)| score < s) {
                        best = Some((score, Rect { x: f.x, y: f.y, w, h }, turned));
                    }
                }
            }
        }
        let (_, placed, turned) = best?;
        out[r] = Placed { x: placed.x, y: placed.y, turned };
        // Split every free rectangle the new one overlaps into the (up to four) maximal
        // rectangles around it, then drop the free rectangles another one contains.
        fresh.clear();
        free.retain(|f| {
            if !f.overlaps(&placed) {
                return true;
            }
            if placed.x > f.x {
                fresh.push(Rect { x: f.x, y: f.y, w: placed.x - f.x, h: f.h });
            }
            if placed.x + placed.w < f.x + f.w {
                fresh.push(Rect {
                    x: placed.x + placed.w,
                    y: f.y,
                    w: f.x + f.w - placed.x - placed.w,
                    h: f.h,
                });
            }
            if placed.y > f.y {
                fresh.push(Rect { x: f.x, y: f.y, w: f.w, h: placed.y - f.y });
            }
            if placed.y + placed.h < f.y + f.h {
                fresh.push(Rect {
                    x: f.x,
                    y: placed.y + placed.h,
                    w: f.w,
                    h: f.y + f.h - placed.y - placed.h,
                });
            }
            false
        });
        // New rectangles contained in another new one (the first of equal ones kept) or in an
        // old one go; old ones contained in a surviving new one go.
        let mut keep = vec![true; fresh.len()];
        for i in 0..fresh.len() {
            keep[i] = !free.iter().any(|f| f.contains(&fresh[i]))
                && !(0..fresh.len()).any(|j| {
                    j != i && keep[j] && fresh[j].contains(&fresh[i]) && (fresh[j] != fresh[i] || j < i)
                });
        }
        let mut k = keep.iter();
        fresh.retain(|_| *k.next().unwrap());
        free.retain(|f| !fresh.iter().any(|n| n.contains(f)));
        free.extend_from_slice(&fresh);
    }
    Some(out)
}

/// An axis-aligned rectangle of texels.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Rect {
    x: u32,
    y: u32,
    w: u32,
    h: u32,
}

impl Rect {
    fn overlaps(&self, o: &Rect) -> bool {
        self.x < o.x + o.w && o.x < self.x + self.w && self.y < o.y + o.h && o.y < self.y + self.h
    }

    fn contains(&self, o: &Rect) -> bool {
        o.x >= self.x && o.y >= self.y && o.x + o.w <= self.x + self.w && o.y + o.h <= self.y + self.h
    }
}

/// One segment of the skyline: `width` texels from `x`, filled from the top of the square down
/// to row `y`.
#[derive(Clone, Copy, Debug)]
struct Segment {
    x: u32,
    y: u32,
    width: u32,
}

/// A skyline placement's far edge, wasted area and `x`: lower is better.
type SkylineScore = (u64, u64, u32);

/// Packs rectangles in the given order with the skyline bottom-left rule (Jylänki 2010): each
/// goes where its far edge (`y + height`, rows from the top) is least, then where it leaves the
/// least area empty under it, then the least `x`; with `rotate` both orientations are tried (ties
/// keep it unturned).
fn skyline_pack(sizes: &[[u32; 2]], order: &[usize], side: u32, rotate: bool) -> Option<Vec<Placed>> {
    let mut sky = vec![Segment { x: 0, y: 0, width: side }];
    let mut out = vec![Placed { x: 0, y: 0, turned: false }; sizes.len()];
    for &r in order {
        let [w, h] = sizes[r];
        // (score, segment, row, turned)
        let mut best: Option<(SkylineScore, usize, u32, bool)> = None;
        for turned in [false, true] {
            if turned && (!rotate || w == h) {
                continue;
            }
            let (w, h) = if turned { (h, w) } else { (w, h) };
            for i in 0..sky.len() {
                let Some((y, waste)) = skyline_fit(&sky, i, w, h, side) else { continue };
                let score = ((y + h) as u64, waste, sky[i].x);
                if best.is_none_or(|(s, ..)| score < s) {
                    best = Some((score, i, y, turned));
                }
            }
        }
        let (_, i, y, turned) = best?;
        let (w, h) = if turned { (h, w) } else { (w, h) };
        let x = sky[i].x;
        out[r] = Placed { x, y, turned };
        skyline_raise(&mut sky, i, x, y + h, w);
    }
    Some(out)
}

/// Whether a `w × h` rectangle with its left edge at segment `i` fits: the row it rests on and
/// the area left empty under it.
fn skyline_fit(sky: &[Segment], i: usize, w: u32, h: u32, side: u32) -> Option<(u32, u64)> {
    let x = sky[i].x;
    if x as u64 + w as u64 > side as u64 {
        return None;
    }
    let end = x + w;
    let mut j = i;
    let mut y = 0;
    while j < sky.len() && sky[j].x < end {
        y = y.max(sky[j].y);
        j += 1;
    }
    if y as u64 + h as u64 > side as u64 {
        return None;
    }
    let waste = sky[i..j].iter().map(|s| (y - s.y) as u64 * ((s.x + s.width).min(end) - s.x) as u64).sum();
    Some((y, waste))
}

/// Raises the skyline to row `y` over `[x, x + w)`, `x` being segment `i`'s start.
fn skyline_raise(sky: &mut Vec<Segment>, i: usize, x: u32, y: u32, w: u32) {
    let end = x + w;
    sky.insert(i, Segment { x, y, width: w });
    let j = i + 1;
    while j < sky.len() && sky[j].x < end {
        let s_end = sky[j].x + sky[j].width;
        if s_end <= end {
            sky.remove(j);
        } else {
            sky[j] = Segment { x: end, y: sky[j].y, width: s_end - end };
            break;
        }
    }
    // Merge the new segment with neighbours at the same row.
    if j < sky.len() && sky[j].y == y {
        sky[i].width += sky[j].width;
        sky.remove(j);
    }
    if i > 0 && sky[i - 1].y == y {
        sky[i - 1].width += sky[i].width;
        sky.remove(i);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Mean |cos(T, B)| by its definition: each metric turned (`G' = R G Rᵀ`), then
    /// `|G'₁₂| / √(G'₁₁ G'₂₂)`.
    fn shear_by_turning(metric: &[[f64; 3]], rot: [f64; 2]) -> f64 {
        let [c, s] = rot;
        let sum: f64 = metric
            .iter()
            .map(|&[g11, g12, g22]| {
                let a = c * c * g11 - 2.0 * c * s * g12 + s * s * g22;
                let b = s * s * g11 + 2.0 * c * s * g12 + c * c * g22;
                let off = c * s * (g11 - g22) + (c * c - s * s) * g12;
                off.abs() / (a * b).sqrt()
            })
            .sum();
        sum / metric.len() as f64
    }

    /// A positive definite metric `[T·T, T·B, B·B]` with random axes' lengths and angle.
    fn random_metric(rng: &mut impl rand::Rng) -> [f64; 3] {
        let (lt, lb) = (rng.random_range(0.1..10.0f64), rng.random_range(0.1..10.0f64));
        let cos = rng.random_range(-0.95..0.95f64);
        [lt * lt, lt * lb * cos, lb * lb]
    }

    #[test]
    fn shear_terms_give_the_turned_metrics_shear() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        for faces in [1usize, 3, 4, 7, 64, 1001] {
            let metric: Vec<[f64; 3]> = (0..faces).map(|_| random_metric(&mut rng)).collect();
            let terms = ShearTerms::of(&metric);
            for _ in 0..50 {
                let a = rng.random_range(0.0..std::f64::consts::TAU);
                let rot = [a.cos(), a.sin()];
                let (fast, slow) = (terms.mean(rot), shear_by_turning(&metric, rot));
                assert!(
                    (fast - slow).abs() <= 1e-12 * slow.max(1.0),
                    "{faces} faces at {a}: {fast} vs {slow}"
                );
            }
        }
        assert_eq!(ShearTerms::of(&[]).mean([1.0, 0.0]), 0.0);
    }

    /// Faces whose texture axes are orthogonal on the surface once turned by a known angle (a
    /// stretch along a direction that is not a texture axis): the least-shear turn finds it
    /// (up to quarter turns, which only swap the axes), and the shear there is nil.
    #[test]
    fn least_shear_turn_undoes_a_known_stretch_direction() {
        for deg in [0.0f64, 10.0, 33.0, 45.0, 71.5] {
            let th = deg.to_radians();
            // G = Rᵀ diag(d1, d2) R: turned by θ the metric is diagonal again.
            let metric: Vec<[f64; 3]> = [(4.0, 1.0), (9.0, 2.0), (1.5, 1.0)]
                .iter()
                .map(|&(d1, d2)| {
                    let (c, s) = (th.cos(), th.sin());
                    [c * c * d1 + s * s * d2, c * s * (d2 - d1), s * s * d1 + c * c * d2]
                })
                .collect();
            let terms = ShearTerms::of(&metric);
            let rot = least_shear_rotation(&terms, [1.0, 0.0]);
            assert!(terms.mean(rot) < 1e-6, "{deg}°: shear {} at {rot:?}", terms.mean(rot));
            let found = rot[1].atan2(rot[0]).to_degrees();
            let off = (found - deg).rem_euclid(90.0);
            assert!(off.min(90.0 - off) < 1e-3, "{deg}°: turned by {found}°");
        }
    }

    #[test]
    fn hull_of_a_square_with_inner_and_edge_points() {
        let p = [[0.0, 0.0], [1.0, 0.0], [0.5, 0.0], [1.0, 1.0], [0.0, 1.0], [0.5, 0.5]];
        assert_eq!(convex_hull(&p), vec![[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]]);
        assert_eq!(convex_hull(&[[1.0, 1.0], [1.0, 1.0]]), vec![[1.0, 1.0]]);
    }

    #[test]
    fn min_area_rotation_undoes_a_rotation_by_the_smallest_angle() {
        for deg in [0.0f64, 10.0, 30.0, 44.0, 60.0, 100.0, -20.0] {
            let (c, s) = (deg.to_radians().cos(), deg.to_radians().sin());
            let rect: Vec<[f64; 2]> = [[0.0, 0.0], [3.0, 0.0], [3.0, 1.0], [0.0, 1.0]]
                .iter()
                .map(|p| rotated(*p, [c, s]))
                .collect();
            let rot = min_area_rotation(&convex_hull(&rect));
            let back: Vec<[f64; 2]> = rect.iter().map(|p| rotated(*p, rot)).collect();
            // Axis-aligned again: every edge is horizontal or vertical.
            for k in 0..4 {
                let (a, b) = (back[k], back[(k + 1) % 4]);
                assert!((a[0] - b[0]).abs() < 1e-9 || (a[1] - b[1]).abs() < 1e-9, "{deg}°: {back:?}");
            }
            let angle = rot[1].atan2(rot[0]).to_degrees();
            assert!(angle > -45.0 - 1e-9 && angle <= 45.0 + 1e-9, "{deg}° turned by {angle}°");
        }
    }

    #[test]
    fn skyline_fills_a_square_with_its_quarters_and_turns_a_strip() {
        let order = [0, 1, 2, 3];
        let p = skyline_pack(&[[5, 5]; 4], &order, 10, false).unwrap();
        let mut corners: Vec<(u32, u32)> = p.iter().map(|q| (q.x, q.y)).collect();
        corners.sort();
        assert_eq!(corners, vec![(0, 0), (0, 5), (5, 0), (5, 5)]);
        assert!(skyline_pack(&[[5, 5]; 5], &[0, 1, 2, 3, 4], 10, true).is_none());
        assert!(skyline_pack(&[[10, 8], [2, 10]], &[0, 1], 10, false).is_none());
        let p = skyline_pack(&[[10, 8], [2, 10]], &[0, 1], 10, true).unwrap();
        assert_eq!((p[0].turned, p[1].turned), (false, true));
    }

    #[test]
    fn maxrects_fills_a_square_exactly_with_its_quarters_and_refuses_too_much() {
        let sizes = [[5, 5], [5, 5], [5, 5], [5, 5]];
        let p = pack_rects(&sizes, 10, false).unwrap();
        let mut corners: Vec<(u32, u32)> = p.iter().map(|q| (q.x, q.y)).collect();
        corners.sort();
        assert_eq!(corners, vec![(0, 0), (0, 5), (5, 0), (5, 5)]);
        assert!(pack_rects(&[[5, 5]; 5], 10, true).is_none());
        // A 10 × 2 strip fits a 10 × 10 square only lying down.
        assert!(pack_rects(&[[2, 10], [10, 8]], 10, false).is_none());
        let p = pack_rects(&[[2, 10], [10, 8]], 10, true).unwrap();
        assert_ne!(p[0].turned, p[1].turned);
    }
}

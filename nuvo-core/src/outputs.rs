//! From trained networks to files a user can use: the baked mesh (OBJ + MTL, GLB), pictures and the
//! paper's metrics, under fixed names scripts can rely on:
//!
//! | file | what |
//! |---|---|
//! | `atlas.obj`, `atlas.mtl` | the mesh with per-corner UVs in the packed atlas, input coordinates |
//! | `atlas.glb` | the same as binary glTF (`texture.png`, else the checkerboard, embedded as its base colour) |
//! | `uv_layout.png` | the baked UV triangles coloured by chart, overlaps in red |
//! | `checker.png` | the checkerboard texture the OBJ's material and the renders use (without `texture.png`) |
//! | `texture.png` | with `output.texture`: the input's colour baked through the new UVs (`nuvo_atlas::texture`) |
//! | `renders/view_{k}.png` | the mesh wearing `texture.png` (else the checkerboard) from several views |
//! | `normal_grids.png` | the learned normal grids `N_i`, packed like the atlas |
//! | `metrics.json` | Boundary, Stretch, Conformal, Editability, the PartUV metric set, UV statistics and the bake report |
//! | `vertex_map.json` | for each vertex of `atlas.glb`, the input vertex it copies (seams split vertices) |
//! | `points_uv.csv` | per-point charts and UVs, when there is no mesh to bake onto |
//!
//! **Appearance** (`output.texture`): the colour of the input (or of `output.texture_from`) is
//! looked up face by face when its file has exactly the faces baked onto (the user's own mesh),
//! else at the nearest surface point or points (`nuvo_geometry::appearance::NearestColour`).
//! Anything that stops a texture (no colour in the file, unreadable images, no mesh) is a warning
//! in [`OutputReport::warnings`]; the atlas is written all the same, with the checkerboard.
//!
//! Baking follows the paper's "(b)" rows: the networks are evaluated at the mesh vertices, every face
//! takes one chart and its corners that chart's UVs (see `nuvo_atlas::bake`).
//!
//! **The user's own mesh.** `atlas.obj` has the input's vertices (positions bit for bit as the file
//! stored them, when the source kept them) in the input's order and its faces in the input's order,
//! with one `vt` per corner; `atlas.glb` splits vertices on seams, and `vertex_map.json` says which
//! input vertex each of its vertices is.

use std::collections::HashSet;
use std::path::{Path, PathBuf};

use nuvo_atlas::AtlasError;
use nuvo_atlas::bake::{BakeOptions, BakeReport, ChartFields, RoundTrip, argmax, bake, chart_uv};
use nuvo_atlas::camera::orbit_views;
use nuvo_atlas::creases::{CreaseReport, crease_charts};
use nuvo_atlas::export::{GlbOptions, glb_vertex_map, write_glb, write_obj};
use nuvo_atlas::injective::{InjectiveOptions, InjectiveReport, make_injective, make_injective_where};
use nuvo_atlas::islands::{IslandPacking, pack_islands};
use nuvo_atlas::join::{JoinOptions, JoinReport, join_small_islands};
use nuvo_atlas::metrics::{EvalOptions, Metrics, evaluate};
use nuvo_atlas::necks::{NeckOptions, NeckReport, cut_necks, judge_cuts};
use nuvo_atlas::pack::AtlasLayout;
use nuvo_atlas::pictures::{
    ChartGrid, MAX_CHECKER_CELLS, chart_grid_image, checkerboard, pack_images, png_bytes, render_textured,
    uv_layout, write_png,
};
use nuvo_atlas::refine::{RefineOptions, RefineReport, refine_islands};
use nuvo_atlas::texture::{SurfaceColour, TextureOptions, TextureReport, bake_texture};
use nuvo_atlas::uvstats::{UvAnalysis, analyse_uv, uv_islands};
use nuvo_geometry::appearance::{Colours, NearestColour, SurfaceColours, load_colours};
use nuvo_geometry::{GeometryError, GeometrySource, Similarity, TriMesh};
use serde::Serialize;

use crate::config::{OutputConfig, Packing};
use crate::trained::{AtlasFields, TrainedAtlas};

/// Output file names.
pub mod names {
    pub const OBJ: &str = "atlas.obj";
    pub const GLB: &str = "atlas.glb";
    pub const LAYOUT: &str = "uv_layout.png";
    pub const CHECKER: &str = "checker.png";
    pub const TEXTURE: &str = "texture.png";
    pub const RENDERS: &str = "renders";
    pub const NORMAL_GRIDS: &str = "normal_grids.png";
    pub const METRICS: &str = "metrics.json";
    pub const POINTS: &str = "points_uv.csv";
    pub const VERTEX_MAP: &str = "vertex_map.json";
}

/// Where each headline number sits in `metrics.json` ([`OutputMetrics`] serialised), as JSON
/// pointers: the readers of finished runs (ablation tables, batch summaries, reports) look them up
/// here, so a field that moves is moved once.
pub mod metric_paths {
    pub const BOUNDARY: &str = "/metrics/image/boundary";
    pub const STRETCH: &str = "/metrics/image/stretch";
    pub const CONFORMAL: &str = "/metrics/image/conformal";
    pub const EDITABILITY: &str = "/metrics/image/editability";
    /// The paper's "UV Eff.".
    pub const UV_EFFICIENCY: &str = "/metrics/uv/utilisation";
    pub const CHARTS: &str = "/metrics/partuv/charts";
    pub const SEAM_LENGTH: &str = "/metrics/partuv/seam_length";
    pub const ANGULAR: &str = "/metrics/partuv/angular_score";
    pub const AREA_WORST_CHART: &str = "/metrics/partuv/area_distortion";
    pub const AREA_OVERALL: &str = "/metrics/partuv/overall_area_distortion";
    pub const PACKING: &str = "/metrics/partuv/packing_efficiency";
    pub const FLIPPED_FACES: &str = "/metrics/uv/flipped_faces";
    pub const OVERLAPPING_FACES: &str = "/metrics/uv/overlapping_faces";
    /// Each face's σ₁/σ₂ (1: square texels), median and 90th percentile over the faces.
    pub const TEXEL_ASPECT_MEDIAN: &str = "/metrics/uv/texel_aspect_median";
    pub const TEXEL_ASPECT_P90: &str = "/metrics/uv/texel_aspect_p90";
    pub const STEPS: &str = "/steps";
}

/// Why outputs could not be written.
#[derive(Debug, thiserror::Error)]
pub enum OutputError {
    #[error(transparent)]
    Atlas(#[from] AtlasError),
    #[error(transparent)]
    Geometry(#[from] GeometryError),
    #[error("cannot write {path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// The geometry to bake onto is not in the frame the atlas was trained in: the file changed
    /// since training, or the config names another one.
    #[error(
        "{geometry}: not the geometry this atlas was trained on (its bounding box is centred at \
         {:?} with scale {}; the trained geometry's at {:?} with scale {}); to bake onto another \
         mesh placed like the trained geometry, set `output.bake_mesh`",
        found.center, found.scale, trained.center, trained.scale
    )]
    OtherGeometry { geometry: String, found: Similarity, trained: Similarity },
    /// Neither a scene nor `output.bake_mesh` to bake onto.
    #[error("nothing to bake onto: no geometry source and no `output.bake_mesh`")]
    NoGeometry,
}

/// Counts from the bake (the full face lists stay in memory only).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct BakeSummary {
    pub faces: usize,
    pub flipped_faces: usize,
    /// Of the flipped faces, those on a crease of the input surface (`nuvo_atlas::uvstats`).
    pub flipped_on_creases: usize,
    pub overlapping_faces: usize,
    pub degenerate_uv_faces: usize,
    /// The side, in texels, of the raster on which the flips and overlaps above were counted:
    /// the atlas's own (`output.resolution`), so a user reads them at the texture's resolution;
    /// `metrics.uv` counts the same atlas at a fixed 1024², as `nuvo eval` counts every tool's,
    /// so the two can differ where islands come within a texel of each other.
    pub raster_resolution: u32,
    pub split_vertices: usize,
    pub corners_outside_chart: usize,
    pub mixed_faces: usize,
    /// Faces the round-trip check moved to another chart (`output.round_trip_tolerance`).
    pub reassigned_faces: usize,
    /// Faces of chart enclaves moved to the chart round them (`output.absorb_enclaves`).
    pub absorbed_faces: usize,
    /// Flipped faces before untangling (`output.untangle`; equal to `flipped_faces` without it).
    pub flipped_before_untangle: usize,
    /// UV vertex moves untangling made.
    pub untangle_moves: usize,
    /// Faces per chart.
    pub faces_per_chart: Vec<usize>,
}

/// What `vertex_map.json` holds.
#[derive(Serialize)]
struct VertexMap {
    about: &'static str,
    glb_to_input: Vec<u32>,
}

/// What refinement and island packing did (`output.refine`, `output.packing`).
#[derive(Clone, Debug, Serialize)]
pub struct LayoutSummary {
    /// The layout written.
    pub packing: Packing,
    /// The refinement's report, when it ran.
    pub refine: Option<RefineReport>,
    /// What making every island injective did (`output.injective`, after the refinement).
    pub injective: Option<InjectiveReport>,
    /// What joining small islands did (`output.join`, after `injective`).
    pub join: Option<JoinReport>,
    /// What charting the surface by its creases did (`output.crease_charts`, after `join`).
    pub creases: Option<CreaseReport>,
    /// What cutting islands at their necks did (`output.cut_necks`, before packing).
    pub necks: Option<NeckReport>,
    /// Islands packed, with `packing = "islands"`.
    pub islands: Option<usize>,
}

/// Refines and packs the baked layout as `opts` asks (both off: the bake as it is).
fn finish_layout(
    mesh: TriMesh,
    opts: &OutputConfig,
    phases: &mut Phases,
) -> Result<(TriMesh, LayoutSummary), OutputError> {
    let mut mesh = mesh;
    let mut summary = LayoutSummary {
        packing: opts.packing,
        refine: None,
        injective: None,
        join: None,
        creases: None,
        necks: None,
        islands: None,
    };
    if opts.refine {
        let refined = refine_islands(&mesh, &RefineOptions::default())?;
        mesh = refined.mesh;
        summary.refine = Some(refined.report);
        phases.done("refine");
    }
    if opts.injective {
        let cones = InjectiveOptions { cut_cones: opts.cut_cones, ..injective_options(opts) };
        let injective = make_injective(&mesh, &cones)?;
        mesh = injective.mesh;
        summary.injective = Some(injective.report);
        phases.done("injective");
    }
    if opts.join {
        let joined = join_small_islands(&mesh, &JoinOptions::default())?;
        mesh = joined.mesh;
        summary.join = Some(joined.report);
        phases.done("join");
    }
    // Crease charts come unpacked, wherever SLIM left them: only the island packer lays them out.
    if opts.injective && opts.crease_charts && opts.packing == Packing::Islands {
        let cones = InjectiveOptions { cut_cones: opts.cut_cones, ..injective_options(opts) };
        let charted = crease_charts(&mesh, &cones)?;
        mesh = charted.mesh;
        summary.creases = Some(charted.report);
        phases.done("creases");
    }
    if opts.packing == Packing::Islands && opts.cut_necks {
        let neck_options = NeckOptions { seam_cost: opts.neck_seam_cost, ..NeckOptions::default() };
        let mut necked = cut_necks(&mesh, &neck_options)?;
        if necked.report.cuts > 0 {
            let mut cut = necked.mesh;
            if opts.injective {
                // A cut frees the parts' boundary where they were joined: SLIM relaxes them from
                // their maps. The islands no cut touched are already converged and keep their UVs.
                let uncut: HashSet<Vec<u32>> = match &mesh.uv {
                    Some(uv) => uv_islands(&mesh, uv).into_iter().collect(),
                    None => HashSet::new(),
                };
                let opts = injective_options(opts);
                cut = make_injective_where(&cut, &opts, |faces| !uncut.contains(faces))?.mesh;
            }
            if judge_cuts(&mesh, &cut, &neck_options, &mut necked.report)? {
                mesh = cut;
            }
        }
        summary.necks = Some(necked.report);
        phases.done("necks");
    }
    if opts.packing == Packing::Islands {
        let packing = IslandPacking {
            resolution: opts.atlas_resolution,
            gutter: opts.gutter,
            rotate: true,
            search: nuvo_atlas::islands::ORDER_SEARCH,
        };
        let packed = pack_islands(&mesh, &packing)?;
        mesh = packed.mesh;
        summary.islands = Some(packed.islands);
        phases.done("pack");
    }
    Ok((mesh, summary))
}

/// Cells per side of `checker.png` for a squares layout of `columns` columns: 8 per chart's
/// square, at most [`MAX_CHECKER_CELLS`] (letters run out): with 10 charts or more (4 columns)
/// the bake used to fail after training with "32 cells is not in 1..=26".
fn checker_cells(columns: u32) -> u32 {
    (8 * columns).clamp(1, MAX_CHECKER_CELLS)
}

/// `make_injective`'s options for `opts`.
fn injective_options(opts: &OutputConfig) -> InjectiveOptions {
    // Split parts lie on each other until packed, so only island packing may split.
    let split = opts.packing == Packing::Islands;
    InjectiveOptions {
        split,
        split_energy: opts.injective_split_energy,
        conformal: opts.injective_conformal,
        orthogonal: opts.injective_orthogonal,
        equiareal: opts.injective_equiareal,
        ..Default::default()
    }
}

/// What `metrics.json` holds.
#[derive(Clone, Debug, Serialize)]
pub struct OutputMetrics {
    /// The paper's metrics of the baked mesh.
    pub metrics: Metrics,
    /// The bake's findings (flips and overlaps counted on the layout written).
    pub bake: BakeSummary,
    /// Refinement and packing after the bake.
    pub layout: LayoutSummary,
    /// Steps trained.
    pub steps: u64,
    /// What `output.texture` baked (absent when no texture was written).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub texture: Option<TextureSummary>,
}

/// What `output.texture` baked into `texture.png`.
#[derive(Clone, Debug, Serialize)]
pub struct TextureSummary {
    /// The file whose colours were baked.
    pub from: PathBuf,
    /// How colours were found: `"same faces"` (the file's own faces and barycentrics),
    /// `"nearest surface point"` (another mesh) or `"nearest points"` (a point cloud).
    pub lookup: &'static str,
    /// Texel counts of the bake.
    #[serde(flatten)]
    pub texels: TextureReport,
}

/// Wall seconds of each phase of a bake, in the order they ran (`evaluate`, `bake`, `refine`, ...).
/// Kept out of `metrics.json`, which stays the same bytes for the same atlas; `nuvo unwrap` writes
/// them to `unwrap.json` and the CLI prints them.
pub type PhaseSeconds = Vec<(&'static str, f64)>;

/// Records [`PhaseSeconds`]: each call to [`Phases::done`] closes the phase that began at the
/// previous call.
struct Phases {
    last: std::time::Instant,
    seconds: PhaseSeconds,
}

impl Phases {
    fn start() -> Self {
        Phases { last: std::time::Instant::now(), seconds: Vec::new() }
    }

    fn done(&mut self, phase: &'static str) {
        let now = std::time::Instant::now();
        self.seconds.push((phase, (now - self.last).as_secs_f64()));
        self.last = now;
    }
}

/// What was written.
#[derive(Clone, Debug)]
pub struct OutputReport {
    pub files: Vec<PathBuf>,
    /// How long each phase took.
    pub phase_seconds: PhaseSeconds,
    /// The baked UVs, per corner of the mesh baked onto (`None` without a mesh).
    pub baked_uv: Option<nuvo_geometry::UvLayer>,
    /// `None` when there was no mesh to bake onto (per-point UVs were written instead).
    pub metrics: Option<OutputMetrics>,
    /// What could not be done and was skipped, each naming the file and the problem (e.g. a
    /// texture image that cannot be read: the atlas is written without that texture).
    pub warnings: Vec<String>,
}

fn io_err(path: &Path) -> impl FnOnce(std::io::Error) -> OutputError + '_ {
    move |source| OutputError::Io { path: path.to_owned(), source }
}

/// Bakes, exports, draws and measures `atlas` into `dir`. The mesh is `output.bake_mesh` when set
/// (in the coordinates of the geometry the atlas was trained on), else `scene`'s own (a mesh
/// file's, or a density grid's marching-cubes mesh), else there is none and per-point UVs of
/// `scene`'s samples are written instead. `scene` is the geometry the atlas was trained on: an
/// error ([`OutputError::OtherGeometry`]) when its frame says otherwise. It is not read when
/// `output.bake_mesh` is set, so may then be `None`.
pub fn write_outputs(
    atlas: &mut TrainedAtlas,
    scene: Option<&dyn GeometrySource>,
    dir: &Path,
    opts: &OutputConfig,
) -> Result<OutputReport, OutputError> {
    std::fs::create_dir_all(dir).map_err(io_err(dir))?;
    // The mesh to bake onto, in the canonical frame, and its vertices as the input stored them.
    if let Some(path) = &opts.bake_mesh {
        let mut m = nuvo_geometry::load_mesh(path)?;
        m.uv = None;
        let input = m.positions.clone();
        m.transform(&atlas.frame());
        let colour_files = [Some(path.as_path()), scene.and_then(|s| s.file())];
        return bake_and_measure(atlas, &m, Some(input), &colour_files, dir, opts);
    }
    let scene = scene.ok_or(OutputError::NoGeometry)?;
    if !same_frame(&scene.to_canonical(), &atlas.frame()) {
        return Err(OutputError::OtherGeometry {
            geometry: scene.describe(),
            found: scene.to_canonical(),
            trained: atlas.frame(),
        });
    }
    match scene.mesh() {
        Some(m) => {
            let mesh = TriMesh { uv: None, ..m.clone() };
            let input = scene.input_positions().map(<[_]>::to_vec);
            bake_and_measure(atlas, &mesh, input, &[scene.file()], dir, opts)
        }
        None => write_point_uvs(atlas, scene, dir, opts),
    }
}

/// Whether two input → canonical maps place the geometry alike: centres within 1e-5 of the
/// canonical extent and scales within 1e-5 relative. Exact equality would make a run unbakeable
/// after a last-bit change in how a reader computes bounding boxes; any real change of the geometry
/// moves them far more.
fn same_frame(a: &Similarity, b: &Similarity) -> bool {
    const TOLERANCE: f32 = 1e-5;
    let close_scale = (a.scale - b.scale).abs() <= TOLERANCE * a.scale.max(b.scale);
    let close_center = a.center.iter().zip(&b.center).all(|(x, y)| (x - y).abs() * a.scale <= TOLERANCE);
    close_scale && close_center
}

/// `colour_files`: where `output.texture` looks for colour when `output.texture_from` is unset,
/// in order (the bake mesh's file, the geometry's file).
fn bake_and_measure(
    atlas: &mut TrainedAtlas,
    mesh: &TriMesh,
    input_positions: Option<Vec<[f32; 3]>>,
    colour_files: &[Option<&Path>],
    dir: &Path,
    opts: &OutputConfig,
) -> Result<OutputReport, OutputError> {
    let mut phases = Phases::start();
    let n = atlas.charts();
    let frame = atlas.frame();
    // The surface networks' pass serves only the round-trip check: half the networks, skipped
    // when the check is off (the unwrap recipe of fragmented inputs, the paper's configs).
    let round_trip_check = opts.round_trip_tolerance > 0.0;
    let fields = if round_trip_check {
        atlas.evaluate_atlas(&mesh.positions)
    } else {
        let (probs, uvs) = atlas.evaluate_charts(&mesh.positions);
        AtlasFields { probs, uvs, round_trip: Vec::new() }
    };
    phases.done("evaluate");
    let layout = AtlasLayout::grid(n, opts.atlas_resolution, opts.gutter)?;
    let round_trip = round_trip_check
        .then(|| RoundTrip { distances: &fields.round_trip, tolerance: opts.round_trip_tolerance });
    let options = BakeOptions { untangle: opts.untangle, absorb_enclaves: opts.absorb_enclaves };
    let baked = bake(
        mesh,
        &ChartFields { probs: &fields.probs, uvs: &fields.uvs, round_trip },
        n,
        &layout,
        &options,
    )?;
    phases.done("bake");
    let (layout_mesh, finished) = finish_layout(baked.mesh, opts, &mut phases)?;
    let baked = nuvo_atlas::bake::Baked { mesh: layout_mesh, ..baked };
    // Refinement and packing move UVs: count flips and overlaps again on what is written.
    let recount = (finished.refine.is_some()
        || finished.injective.is_some()
        || finished.join.is_some()
        || finished.islands.is_some())
    .then(|| analyse_uv(&baked.mesh, Some(&baked.face_chart), opts.atlas_resolution))
    .transpose()?;
    phases.done("recount");
    let mut warnings = Vec::new();
    let texture = if opts.texture {
        let t = bake_appearance(&baked.mesh, colour_files, &frame, opts, &mut warnings)?;
        phases.done("texture");
        t
    } else {
        None
    };
    // The files and the metrics read the finished layout only: written on one side while the
    // metrics render on the other (the writers use one core for a good part of their time).
    let eval =
        EvalOptions { views: opts.eval_views, resolution: opts.eval_resolution, ..EvalOptions::default() };
    let (written, metrics) = rayon::join(
        || write_atlas_files(&baked, texture.as_ref(), input_positions, &frame, atlas, &layout, dir, opts),
        || evaluate(&baked.mesh, &eval),
    );
    let mut files = written?;
    let summary = OutputMetrics {
        metrics: metrics?,
        bake: summarize(&baked.report, recount.as_ref(), &baked.face_chart, n),
        layout: finished,
        steps: atlas.steps(),
        texture: texture.map(|(_, summary)| summary),
    };
    let metrics_path = dir.join(names::METRICS);
    let json = serde_json::to_string_pretty(&summary)
        .map_err(|e| io_err(&metrics_path)(std::io::Error::other(e)))?;
    nuvo_fsio::write_bytes_atomic(&metrics_path, json.as_bytes()).map_err(io_err(&metrics_path))?;
    files.push(metrics_path);
    phases.done("export, pictures, metrics");
    Ok(OutputReport {
        files,
        phase_seconds: phases.seconds,
        baked_uv: baked.mesh.uv,
        metrics: Some(summary),
        warnings,
    })
}

/// How the colour of a point of the mesh being textured is found.
enum ColourLookup<'a> {
    /// The colour file has exactly the mesh's faces: the same face and barycentrics.
    SameFaces(&'a SurfaceColours),
    /// The nearest surface point or points of the colour file (in the mesh's frame).
    Nearest(NearestColour),
}

impl SurfaceColour for ColourLookup<'_> {
    fn colour(&self, face: usize, bary: [f32; 3], point: [f32; 3]) -> [f32; 3] {
        match self {
            ColourLookup::SameFaces(s) => s.colour(face, bary),
            ColourLookup::Nearest(n) => n.colour_at(point),
        }
    }
}

/// Bakes the colour `output.texture` asks for through `mesh`'s UVs (`mesh` in the frame
/// `frame` maps the input into). The file is `output.texture_from`, else the first of
/// `colour_files` that has colour. Whatever prevents a texture is pushed onto `warnings` and gives
/// `None`: the atlas is then written with the checkerboard.
fn bake_appearance(
    mesh: &TriMesh,
    colour_files: &[Option<&Path>],
    frame: &Similarity,
    opts: &OutputConfig,
    warnings: &mut Vec<String>,
) -> Result<Option<(nuvo_atlas::pictures::RgbImage, TextureSummary)>, OutputError> {
    let candidates: Vec<&Path> = match &opts.texture_from {
        Some(p) => vec![p.as_path()],
        None => colour_files.iter().flatten().copied().collect(),
    };
    let mut found = None;
    for path in &candidates {
        match load_colours(path) {
            Ok(loaded) => {
                warnings.extend(loaded.warnings);
                if let Some(colours) = loaded.colours {
                    found = Some((path.to_path_buf(), colours));
                    break;
                }
            }
            Err(e) => warnings.push(format!("output.texture: cannot read the colours: {e}")),
        }
    }
    let Some((from, colours)) = found else {
        let files: Vec<String> = candidates.iter().map(|p| p.display().to_string()).collect();
        warnings.push(if files.is_empty() {
            "output.texture: no file to take colours from (set output.texture_from); no texture.png written"
                .to_owned()
        } else {
            format!(
                "output.texture: {} carries no colour (no vertex or point colours, no texture that could be \
                 read, at most one material colour); no texture.png written",
                files.join(", ")
            )
        });
        return Ok(None);
    };
    let lookup = match &colours {
        Colours::Surface(s) if s.mesh.triangles == mesh.triangles => ColourLookup::SameFaces(s),
        other => ColourLookup::Nearest(NearestColour::new(other, frame)),
    };
    let kind = match (&lookup, &colours) {
        (ColourLookup::SameFaces(_), _) => "same faces",
        (_, Colours::Surface(_)) => "nearest surface point",
        (_, Colours::Points(_)) => "nearest points",
    };
    let texture_opts =
        TextureOptions { resolution: opts.atlas_resolution, supersampling: opts.texture_supersampling };
    let baked = bake_texture(mesh, &lookup, &texture_opts)?;
    Ok(Some((baked.image, TextureSummary { from, lookup: kind, texels: baked.report })))
}

/// Writes the atlas's files into `dir` (the checker, the texture, the OBJ, GLB and vertex map,
/// the layout picture, the renders and the normal grids), returning their paths in that order.
/// Reads the finished layout only, so [`bake_and_measure`] runs it beside the metrics.
#[allow(clippy::too_many_arguments)]
fn write_atlas_files(
    baked: &nuvo_atlas::bake::Baked,
    texture: Option<&(nuvo_atlas::pictures::RgbImage, TextureSummary)>,
    input_positions: Option<Vec<[f32; 3]>>,
    frame: &Similarity,
    atlas: &TrainedAtlas,
    layout: &AtlasLayout,
    dir: &Path,
    opts: &OutputConfig,
) -> Result<Vec<PathBuf>, OutputError> {
    let mut files = Vec::new();
    let path = |name: &str| dir.join(name);
    let side = opts.atlas_resolution.min(2048);
    let checker = checkerboard(side, checker_cells(layout.columns).min(side))?;
    write_png(&path(names::CHECKER), &checker)?;
    files.push(path(names::CHECKER));
    // Encoded once: the file and the GLB's embedded image are the same bytes.
    let texture_png = texture.map(|(image, _)| png_bytes(image)).transpose()?;
    if let Some(bytes) = &texture_png {
        let p = path(names::TEXTURE);
        nuvo_fsio::write_bytes_atomic(&p, bytes).map_err(io_err(&p))?;
        files.push(p);
    }
    let (texture_image, texture_name) = match texture {
        Some((image, _)) => (image, names::TEXTURE),
        None => (&checker, names::CHECKER),
    };
    // Writers get the input's own positions when there are any (bit for bit), else map back.
    let (export, export_frame) = match input_positions {
        Some(positions) if positions.len() == baked.mesh.positions.len() => {
            let m = &baked.mesh;
            (TriMesh { positions, triangles: m.triangles.clone(), uv: m.uv.clone() }, Similarity::IDENTITY)
        }
        _ => (baked.mesh.clone(), *frame),
    };
    write_obj(&path(names::OBJ), &export, &export_frame, Some(Path::new(texture_name)))?;
    files.push(path(names::OBJ));
    files.push(path(names::OBJ).with_extension("mtl"));
    let png = match texture_png {
        Some(bytes) => bytes,
        None => png_bytes(&checker)?,
    };
    write_glb(
        &path(names::GLB),
        &export,
        &export_frame,
        &GlbOptions { normals: true, texture_png: Some(&png) },
    )?;
    files.push(path(names::GLB));
    let map = serde_json::to_string(&VertexMap {
        about: "for each vertex of atlas.glb, the index (0-based) of the input mesh vertex it copies",
        glb_to_input: glb_vertex_map(&export)?,
    })
    .map_err(|e| io_err(&path(names::VERTEX_MAP))(std::io::Error::other(e)))?;
    drop(export);
    nuvo_fsio::write_bytes_atomic(&path(names::VERTEX_MAP), map.as_bytes())
        .map_err(io_err(&path(names::VERTEX_MAP)))?;
    files.push(path(names::VERTEX_MAP));
    write_png(
        &path(names::LAYOUT),
        &uv_layout(&baked.mesh, Some(&baked.face_chart), opts.atlas_resolution.min(2048))?,
    )?;
    files.push(path(names::LAYOUT));
    files.extend(write_renders(&baked.mesh, texture_image, dir, opts)?);
    files.push(write_normal_grids(atlas, layout, dir)?);
    Ok(files)
}

/// The bake's counts; flips, overlaps and degenerate faces from `recount` when refinement or
/// packing changed the layout after the bake.
fn summarize(r: &BakeReport, recount: Option<&UvAnalysis>, face_chart: &[u32], n: usize) -> BakeSummary {
    let mut faces_per_chart = vec![0; n];
    for &c in face_chart {
        faces_per_chart[c as usize] += 1;
    }
    let (flipped, on_creases, overlapping, degenerate, resolution) = match recount {
        Some(a) => (
            a.flipped.len(),
            a.stats.flipped_on_creases,
            a.overlapping.len(),
            a.degenerate_uv.len(),
            a.stats.raster_resolution,
        ),
        None => (
            r.flipped_faces.len(),
            r.stats.flipped_on_creases,
            r.overlapping_faces.len(),
            r.degenerate_uv_faces.len(),
            r.stats.raster_resolution,
        ),
    };
    BakeSummary {
        faces: face_chart.len(),
        flipped_faces: flipped,
        flipped_on_creases: on_creases,
        overlapping_faces: overlapping,
        degenerate_uv_faces: degenerate,
        raster_resolution: resolution,
        split_vertices: r.split_vertices,
        corners_outside_chart: r.corners_outside_chart,
        mixed_faces: r.mixed_faces,
        reassigned_faces: r.reassigned_faces,
        absorbed_faces: r.absorbed_faces,
        flipped_before_untangle: if r.untangle.moves > 0 {
            r.untangle.flipped_before
        } else {
            r.flipped_faces.len()
        },
        untangle_moves: r.untangle.moves,
        faces_per_chart,
    }
}

fn write_renders(
    mesh: &TriMesh,
    checker: &nuvo_atlas::pictures::RgbImage,
    dir: &Path,
    opts: &OutputConfig,
) -> Result<Vec<PathBuf>, OutputError> {
    if opts.renders == 0 {
        return Ok(Vec::new());
    }
    let renders = dir.join(names::RENDERS);
    std::fs::create_dir_all(&renders).map_err(io_err(&renders))?;
    let bounds = mesh.bounds().ok_or_else(|| AtlasError::invalid("mesh", "no vertices"))?;
    let cams = orbit_views(&bounds, opts.renders, 1, opts.render_resolution, opts.render_resolution);
    let mut files = Vec::new();
    for (k, img) in render_textured(mesh, &cams, checker)?.iter().enumerate() {
        let p = renders.join(format!("view_{k}.png"));
        write_png(&p, img)?;
        files.push(p);
    }
    Ok(files)
}

fn write_normal_grids(
    atlas: &TrainedAtlas,
    layout: &AtlasLayout,
    dir: &Path,
) -> Result<PathBuf, OutputError> {
    let res = atlas.model().grid_resolution();
    let params = atlas.params();
    let images = (0..atlas.charts())
        .map(|i| {
            let values = params.value(atlas.model().grid_param(i)).data();
            chart_grid_image(&ChartGrid { width: res, height: res, values })
        })
        .collect::<Result<Vec<_>, _>>()?;
    let p = dir.join(names::NORMAL_GRIDS);
    write_png(&p, &pack_images(layout, &images)?)?;
    Ok(p)
}

/// Without a mesh: charts and atlas UVs of points drawn from the source, as CSV in input coordinates.
fn write_point_uvs(
    atlas: &mut TrainedAtlas,
    scene: &dyn GeometrySource,
    dir: &Path,
    opts: &OutputConfig,
) -> Result<OutputReport, OutputError> {
    const POINTS: usize = 200_000;
    let mut phases = Phases::start();
    let n = atlas.charts();
    let frame = atlas.frame();
    let pts = scene.sample(POINTS, atlas.seed()).positions;
    let (probs, uvs) = atlas.evaluate_charts(&pts);
    let layout = AtlasLayout::grid(n, opts.atlas_resolution, opts.gutter)?;
    let mut csv = String::from("x,y,z,chart,u,v\n");
    for (k, p) in pts.iter().enumerate() {
        let chart = argmax(probs[k * n..(k + 1) * n].iter().copied()) as usize;
        let uv = layout.map(chart, chart_uv(&uvs, n, k as u32, chart));
        let q = frame.invert(*p);
        csv.push_str(&format!("{},{},{},{chart},{},{}\n", q[0], q[1], q[2], uv[0], uv[1]));
    }
    let path = dir.join(names::POINTS);
    nuvo_fsio::write_bytes_atomic(&path, csv.as_bytes()).map_err(io_err(&path))?;
    phases.done("points");
    let warnings = if opts.texture {
        vec![format!(
            "output.texture: {} has no mesh to bake a texture onto (set output.bake_mesh); no texture.png written",
            scene.describe()
        )]
    } else {
        Vec::new()
    };
    Ok(OutputReport {
        files: vec![path],
        phase_seconds: phases.seconds,
        baked_uv: None,
        metrics: None,
        warnings,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_checker_of_any_chart_count_can_be_drawn() {
        for charts in [1u32, 4, 9, 10, 12, 16, 64, 1000] {
            let columns = (charts as f64).sqrt().ceil() as u32;
            let cells = checker_cells(columns);
            assert!(nuvo_atlas::pictures::checkerboard(64, cells).is_ok(), "{charts} charts: {cells} cells");
        }
        assert_eq!((checker_cells(1), checker_cells(3), checker_cells(4)), (8, 24, MAX_CHECKER_CELLS));
    }

    #[test]
    fn frames_match_within_rounding_not_beyond() {
        let a = Similarity { center: [1.0, -2.0, 0.5], scale: 4.0 };
        let nudged = Similarity { center: [1.0 + 1e-7, -2.0, 0.5], scale: 4.0 * (1.0 + 1e-7) };
        assert!(same_frame(&a, &a) && same_frame(&a, &nudged));
        assert!(!same_frame(&a, &Similarity { center: [1.001, -2.0, 0.5], scale: 4.0 }));
        assert!(!same_frame(&a, &Similarity { scale: 4.01, ..a }));
    }
}

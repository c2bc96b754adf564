//! `nuvo unwrap`: from any input file to a resolved experiment config, by rules from measured
//! properties of the input, each decision stated with the numbers behind it.
//!
//! The steps, in the order the CLI takes them:
//! 1. [`input_kind`]: the extension and the content choose the source (`mesh`, `point_cloud`,
//!    `density`);
//! 2. for meshes, [`profile_mesh`] and [`choose_sampling`]: area-uniform samples for a clean
//!    surface, visible ray hits for a fragmented one or one with hidden inner sheets;
//! 3. [`recipe`]: the config text (the measured recipe of `configs/bunny.toml`, with the options
//!    that hurt on fragmented meshes off for them, and injective islands that are never split
//!    on them);
//! 4. [`chart_trials`] and [`choose_charts`]: the chart count, from how well `n` projection charts
//!    can start the surface fold-free;
//! 5. [`fit_steps`]: the step count that fits the time budget on this machine, from timed steps:
//!    the most the run takes, since it stops once the atlas has settled (`training.
//!    stop_when_settled`, `crate::settling`): its charts, or a single chart's map, hold still.
//!
//! The result is an ordinary config: written as `config.toml`, `nuvo train` reproduces the run.

use std::path::{Path, PathBuf};
use std::time::Instant;

use nuvo_geometry::mesh_source::SamplingMode;
use nuvo_geometry::profile::MeshProfile;
use nuvo_geometry::{GeometryError, GeometrySource, TriMesh};
use serde::Serialize;

use crate::batch::surface_samples;
use crate::trainer::{TrainError, Trainer};
use crate::warm_start::{Coverage, Projection, ProjectionPrior};

pub use nuvo_geometry::profile::profile_mesh;

/// What kind of geometry an input file holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum InputKind {
    /// A triangle mesh (`.obj`, `.gltf`, `.glb`, a `.ply` with faces): trained on samples, baked
    /// onto itself.
    Mesh,
    /// Surface points (a `.ply` without faces, `.xyz`, `.txt`, `.pts`): per-point UVs, or a bake
    /// onto a given mesh.
    PointCloud,
    /// A density grid (`.npy`): baked onto its own marching-cubes mesh.
    Density,
}

impl InputKind {
    /// The geometry source that reads this kind.
    pub fn source(self) -> &'static str {
        match self {
            InputKind::Mesh => "mesh",
            InputKind::PointCloud => "point_cloud",
            InputKind::Density => "density",
        }
    }
}

/// Why an input cannot be unwrapped.
#[derive(Debug, thiserror::Error)]
pub enum UnwrapError {
    /// The file itself is the problem (missing, empty, unknown kind).
    #[error("{path}: {message}")]
    Input { path: PathBuf, message: String },
    #[error(transparent)]
    Geometry(#[from] GeometryError),
    #[error(transparent)]
    Train(#[from] TrainError),
}

fn input_error(path: &Path, message: impl Into<String>) -> UnwrapError {
    UnwrapError::Input { path: path.to_owned(), message: message.into() }
}

/// The input extensions `nuvo unwrap` reads, by kind.
pub const MESH_INPUTS: &[&str] = &["obj", "gltf", "glb"];
pub const POINT_INPUTS: &[&str] = &["ply", "xyz", "txt", "pts"];
/// A `.ply` whose header declares faces is a mesh; without faces, a point cloud.
const PLY: &str = "ply";
pub const DENSITY_INPUTS: &[&str] = &["npy"];

/// The kind of `path`, from its extension, after checking that it is a readable, non-empty file.
/// A PLY file is read as points (its faces, if any, are not used; the CLI says so, from
/// `nuvo_geometry::ply::declares_faces`).
pub fn input_kind(path: &Path) -> Result<InputKind, UnwrapError> {
    let meta =
        std::fs::metadata(path).map_err(|e| input_error(path, format!("cannot read the input: {e}")))?;
    if meta.is_dir() {
        return Err(input_error(path, "is a directory; give the mesh, point cloud or density grid file"));
    }
    if meta.len() == 0 {
        return Err(input_error(path, "the file is empty"));
    }
    let ext = path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase).unwrap_or_default();
    let is = |list: &[&str]| list.contains(&ext.as_str());
    if is(MESH_INPUTS) || (ext == PLY && nuvo_geometry::ply::declares_faces(path)) {
        Ok(InputKind::Mesh)
    } else if is(POINT_INPUTS) {
        Ok(InputKind::PointCloud)
    } else if is(DENSITY_INPUTS) {
        Ok(InputKind::Density)
    } else {
        let all: Vec<String> =
            [MESH_INPUTS, POINT_INPUTS, DENSITY_INPUTS].concat().iter().map(|e| format!(".{e}")).collect();
        Err(input_error(
            path,
            format!(
                "unsupported input type `{}`; nuvo unwrap reads {}",
                if ext.is_empty() { "(no extension)".to_owned() } else { format!(".{ext}") },
                all.join(", ")
            ),
        ))
    }
}

/// One choice `nuvo unwrap` made, and why: printed, and written to `unwrap.json`.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Decision {
    /// What was decided (`sampling`, `charts`, `steps`, ...).
    pub what: String,
    /// The choice, as the config spells it.
    pub choice: String,
    /// The rule and the measured numbers behind it.
    pub why: String,
}

impl Decision {
    fn new(what: &str, choice: impl ToString, why: impl Into<String>) -> Self {
        Decision { what: what.to_owned(), choice: choice.to_string(), why: why.into() }
    }
}

/// Visible-surface sampling once this share of the surface is hidden from every outside direction
/// (inner sheets, bubbles). Clean meshes measure under 1% (narrow crevices); the marching-cubes
/// meshes of `../shared/data` over 10% (BENCHMARKS.md, "nuvo unwrap").
pub const HIDDEN_AREA_FOR_VISIBLE: f64 = 0.05;
/// Visible-surface sampling once this many pieces each hold under 0.1% of the area (floaters).
/// Clean meshes have a handful of pieces (a teapot's lid and handle, a character's eyes).
pub const FRAGMENTS_FOR_VISIBLE: usize = 50;

/// The sampling rule for a mesh (module docs): visible ray hits when the profile shows hidden
/// surface or floaters, area-uniform otherwise.
pub fn choose_sampling(p: &MeshProfile) -> (SamplingMode, Decision) {
    let numbers = format!(
        "{} faces, {} pieces ({} fragments under 0.1% of the area, {:.2}% of it; largest piece {:.1}%), \
         {:.1}% of the surface hidden from outside",
        p.faces,
        p.components,
        p.fragments,
        100.0 * p.fragment_area,
        100.0 * p.largest_component_area,
        100.0 * p.hidden_area
    );
    if p.hidden_area >= HIDDEN_AREA_FOR_VISIBLE || p.fragments >= FRAGMENTS_FOR_VISIBLE {
        let why = format!(
            "{numbers}: hidden area ≥ {:.0}% or ≥ {FRAGMENTS_FOR_VISIBLE} fragments, as a marching-cubes mesh of a \
             neural field has, so only what a camera sees is sampled",
            100.0 * HIDDEN_AREA_FOR_VISIBLE
        );
        (SamplingMode::Visible, Decision::new("sampling", "visible", why))
    } else {
        let why = format!(
            "{numbers}: a clean surface (hidden area < {:.0}%, < {FRAGMENTS_FOR_VISIBLE} fragments), so every face is \
             sampled by area",
            100.0 * HIDDEN_AREA_FOR_VISIBLE
        );
        (SamplingMode::Uniform, Decision::new("sampling", "uniform", why))
    }
}

/// The orientation rule: a mesh whose surface points mostly escape through the back of their faces
/// is wound inside out, and its normals are flipped (`geometry.flip_normals`), since the warm start
/// projects each chart onto the side its normals face. Visible sampling orients every normal
/// towards its camera anyway, so only area-uniform sampling needs it.
pub fn choose_orientation(p: &MeshProfile, sampling: SamplingMode) -> Option<Decision> {
    let flip = sampling == SamplingMode::Uniform && p.outward_escapes < 0.5;
    flip.then(|| {
        Decision::new(
            "normals",
            "flipped",
            format!(
                "only {:.0}% of the rays that leave the surface leave through the front of their face: the mesh is \
                 wound inside out",
                100.0 * p.outward_escapes
            ),
        )
    })
}

/// How a recipe treats the input: a clean surface gets the bake's round-trip check and untangling
/// (both measured to help on clean meshes and to hurt on fragmented ones; BENCHMARKS.md "Round-trip
/// check", "Untangling").
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RecipeInput<'a> {
    pub kind: InputKind,
    pub path: &'a Path,
    /// Meshes only.
    pub sampling: SamplingMode,
    /// Meshes only: the mesh is wound inside out ([`choose_orientation`]).
    pub flip_normals: bool,
    pub charts: usize,
    pub steps: u64,
    /// A safety stop: training ends after this many seconds whatever the step count
    /// (`training.time_budget_minutes`).
    pub stop_after_seconds: Option<f64>,
    pub seed: u64,
    /// Density grids only: `[[min], [max]]` of the grid nodes, from a sidecar header.
    pub bounds: Option<[[f32; 3]; 2]>,
    /// Bake the input's colour into `texture.png` (`output.texture`; [`choose_texture`]).
    pub texture: bool,
}

/// The config text of a run (module docs). The recipe is `configs/bunny.toml`'s: small networks, a
/// fast learning rate, the occlusion-aware projection warm start, chart support, the scale-free
/// signed stretch; its weights were measured on the bunny and are checked across the whole
/// benchmark suite (BENCHMARKS.md).
pub fn recipe(r: &RecipeInput) -> String {
    let path = toml::Value::String(r.path.to_string_lossy().into_owned());
    let mut geometry = format!("source = \"{}\"\npath = {path}\n", r.kind.source());
    let clean = match r.kind {
        InputKind::Mesh => {
            let mode = match r.sampling {
                SamplingMode::Uniform => "uniform",
                SamplingMode::Visible => "visible",
            };
            geometry += &format!("sampling = \"{mode}\"\n");
            if r.flip_normals {
                geometry += "flip_normals = true\n";
            }
            r.sampling == SamplingMode::Uniform
        }
        InputKind::PointCloud => true,
        InputKind::Density => {
            if let Some([lo, hi]) = r.bounds {
                geometry += &format!("bounds = [{lo:?}, {hi:?}]\n");
            }
            false
        }
    };
    // Fragmented inputs need more UV samples per step: their charts hold many pieces.
    let batch_uv = if clean { 1024 } else { 2048 };
    // The prior fades over 300 steps (the measured bunny setting), or the first 30% of a short run.
    // Its steps draw half the batch: every chart reads every sample until it fades, so they cost
    // twice the later ones, and half the samples fit a projection as well (Common Shapes: mean
    // Editability 0.9589 -> 0.9600, wall 42.7 -> 32.0 s a mesh; BENCHMARKS.md, "Half batches
    // while the warm start weighs in").
    let warm = (r.steps * 3 / 10).clamp(1, 300);
    let mut bake = String::from("refine = true\npacking = \"islands\"\n");
    if clean {
        bake += "round_trip_tolerance = 0.1\nuntangle = true\n";
    }
    // Every island is made injective and small islands joined. On fragmented inputs (floaters,
    // crumbs) a re-embedded island is split only where SLIM could not flatten it: each split is
    // a seam across a blob that the renders see, while its distortion barely moves the medians,
    // but a disc left squeezed to specks shows (BENCHMARKS.md, "Injective islands on fragmented
    // meshes" and "Splitting the discs SLIM could not flatten").
    bake += "injective = true\njoin = true\n";
    // Specks of one chart inside another become part of it where its map allows: the chart
    // network's argmax is noisy on fragmented inputs (105–184 faces absorbed on each unruly
    // mesh), and no Common Shapes mesh lost (BENCHMARKS.md, "SLIM on islands that touch
    // themselves, chart enclaves").
    bake += "absorb_enclaves = true\n";
    // Islands that waste most of their rectangle are cut across their necks where a trial
    // packing gains in proportion to the seam (Common Shapes: efficiency 0.59 -> 0.68 for 4 more
    // charts a mesh; layouts of thousands of islands, as on marching-cubes meshes, are left
    // alone; BENCHMARKS.md, "More neck cuts").
    bake += "cut_necks = true\n";
    // Every solved disc is cut open from its cone points to its boundary where SLIM then gains
    // (Common Shapes: angular 0.955 -> 0.961, worst-chart area 1.21 -> 1.10, Editability 0.9556
    // -> 0.9572, no mesh lower; the unruly meshes and grid: +0.019 to +0.063, the generated
    // homer 0.769 -> 0.832; BENCHMARKS.md, "Cutting discs open at their cone points").
    bake += "cut_cones = true\n";
    // SLIM keeps each face's texture axes perpendicular on the surface and the face at its
    // island's texel density, the two things the renders and PartUV's scores measure, and lets
    // the stretch left go along the axes (Common Shapes: Editability 0.9594 -> 0.9721, angular
    // 0.955 -> 0.982, worst-chart area 1.148 -> 1.065, no mesh lower; unruly inputs 0.841 ->
    // 0.868; for a texel aspect of 1.05 -> 1.09 on the median face, 1.21 -> 1.43 at the 90th
    // percentile; BENCHMARKS.md, "Texture axes kept perpendicular and faces at their island's
    // density").
    bake += &format!(
        "injective_orthogonal = {:?}\ninjective_equiareal = {:?}\n",
        nuvo_atlas::injective::UNWRAP_ORTHOGONAL,
        nuvo_atlas::injective::UNWRAP_EQUIAREAL
    );
    // A surface of patches meeting at sharp creases (a machined part) is charted by its creases
    // where the renders say that beats the networks' charts: fandisk 0.9794 -> 0.9855 (xatlas
    // 0.9806), the teapot's separate patches 0.9582 -> 0.9689; cheburashka, suzanne and the
    // beetle were judged and keep the networks' charts, the other nine have one region
    // (BENCHMARKS.md, "Charts along the creases").
    bake += "crease_charts = true\n";
    if !clean {
        bake += &format!("injective_split_energy = {:?}\n", nuvo_atlas::injective::FAILED_SLIM_ENERGY);
    }
    if r.texture {
        bake += "texture = true\n";
    }
    // On a clean surface training stops once the chart assignment holds still: the steps after
    // that mostly merge the last small charts, while the baked atlas's scores stay within their
    // step-to-step noise. Fragmented inputs train to their budget: their noisy argmax settles
    // late (15% of the steps saved) and the vase grid lost Editability 0.63 -> 0.58 stopped
    // early (BENCHMARKS.md, "Stopping once the atlas has settled").
    let mut stop = String::new();
    if clean {
        stop += "stop_when_settled = 0.015\n";
    }
    if let Some(s) = r.stop_after_seconds {
        stop += &format!("time_budget_minutes = {}\n", s / 60.0);
    }
    format!(
        "# Written by `nuvo unwrap`; `nuvo train` on this file reproduces the run.\n\
         seed = {seed}\n\n[geometry]\n{geometry}\n\
         [model]\ncharts = {charts}\ndepth = 4\nwidth = 128\n\n\
         [training]\nsteps = {steps}\nbatch_3d = 2048\nbatch_uv = {batch_uv}\nchart_support = 1e-3\n{stop}\n\
         [optimizer]\nlr_mlp = 3e-3\n\n\
         [warm_start]\nsteps = {warm}\nocclusion = true\nbatch_share = 0.5\n\n\
         [losses.cycle_3d]\n[losses.cycle_2d]\n[losses.entropy]\n[losses.surface]\n\
         [losses.cluster]\nweight = 1.5\n[losses.conformal]\nweight = 1.2\n\
         [losses.stretch]\nweight = 2.0\nrelative = true\nsigned = true\narea = \"jacobian\"\n[losses.texture]\n\n\
         [output]\n{bake}",
        seed = r.seed,
        charts = r.charts,
        steps = r.steps,
    )
}

/// Whether to bake the input's colour into a texture (`output.texture`): yes when the file carries
/// colour ([`nuvo_geometry::appearance::load_colours`]) and there is a mesh to bake onto (a
/// point cloud needs `has_bake_mesh`). Returns the choice, the decision to print when the file
/// has colour, and the reader's warnings (images that cannot be read: the atlas is written
/// without them). Errors only where the geometry itself cannot be read.
pub fn choose_texture(
    path: &Path,
    kind: InputKind,
    has_bake_mesh: bool,
) -> Result<(bool, Option<Decision>, Vec<String>), nuvo_geometry::GeometryError> {
    use nuvo_geometry::appearance::{Colours, load_colours};
    let loaded = load_colours(path)?;
    let Some(colours) = &loaded.colours else { return Ok((false, None, loaded.warnings)) };
    let what = match colours {
        Colours::Surface(s) => {
            let textures = s.materials.iter().filter(|m| m.texture.is_some()).count();
            let mut parts = Vec::new();
            if s.vertex_colours.is_some() {
                parts.push("vertex colours".to_owned());
            }
            if textures > 0 {
                parts.push(format!("{textures} texture(s) through its own UVs"));
            }
            if parts.is_empty() {
                parts.push(format!("{} material colours", s.materials.len()));
            }
            parts.join(" and ")
        }
        Colours::Points(p) => format!("colours on its {} points", p.colours.len()),
    };
    let usable = kind != InputKind::PointCloud || has_bake_mesh;
    let decision = Decision {
        what: "texture".into(),
        choice: if usable { "texture.png" } else { "none" }.into(),
        why: if usable {
            format!("the input has {what}: baked through the new UVs")
        } else {
            format!("the input has {what}, but a point cloud has no mesh to bake onto (set output.bake_mesh)")
        },
    };
    Ok((usable, Some(decision), loaded.warnings))
}

/// How well `charts` projection charts start a sample of the surface (see [`Coverage`]).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct ChartTrial {
    pub charts: usize,
    #[serde(flatten)]
    pub coverage: Coverage,
}

/// The chart counts [`choose_charts`] considers. One chart is enough for a surface that one
/// projection sees whole (a relief, a height field): woody and alligator of Common Shapes, where a
/// second chart only added a seam (Editability 0.991 → 0.9999 on woody; BENCHMARKS.md).
pub const CHART_CANDIDATES: std::ops::RangeInclusive<usize> = 1..=8;
/// Samples the chart trials fit and score.
pub const TRIAL_SAMPLES: usize = 20_000;

/// Fits the warm start's occlusion-aware orthographic charts (what training starts from) for each
/// candidate count to one sample of `source`, and measures their [`Coverage`].
pub fn chart_trials(source: &dyn GeometrySource, seed: u64) -> Result<Vec<ChartTrial>, UnwrapError> {
    let sample = surface_samples(source, TRIAL_SAMPLES, seed).map_err(TrainError::from)?;
    Ok(CHART_CANDIDATES
        .map(|n| {
            let prior =
                ProjectionPrior::fit(&sample.points, &sample.normals, n, Projection::Orthographic, 0.3, true);
            ChartTrial { charts: n, coverage: prior.coverage(&sample.points, &sample.normals) }
        })
        .collect())
}

/// A chart count is enough once its charts supervise this share of the surface.
pub const ENOUGH_COVERAGE: f64 = 0.95;
/// ... or once one more chart would add less than this to the share.
pub const COVERAGE_GAIN: f64 = 0.01;

/// The chart-count rule: the fewest charts whose projections start at least [`ENOUGH_COVERAGE`] of
/// the surface fold-free and unoccluded, or past which one more chart gains less than
/// [`COVERAGE_GAIN`]; the most candidates when neither happens. Fewer charts mean shorter seams, and
/// what a projection cannot start fold-free the training must unfold, so coverage is what decides.
pub fn choose_charts(trials: &[ChartTrial]) -> (usize, Decision) {
    let listed: Vec<String> =
        trials.iter().map(|t| format!("{}: {:.1}%", t.charts, 100.0 * t.coverage.supervised)).collect();
    let pick = trials.iter().enumerate().find(|(k, t)| {
        t.coverage.supervised >= ENOUGH_COVERAGE
            || trials
                .get(k + 1)
                .is_some_and(|next| next.coverage.supervised - t.coverage.supervised < COVERAGE_GAIN)
    });
    let n = pick.map_or_else(|| trials.last().map_or(4, |t| t.charts), |(_, t)| t.charts);
    let why = format!(
        "share of the surface that n projection charts start fold-free and unoccluded ({}); the fewest charts \
         reaching {:.0}% or gaining < {:.0} points with one more",
        listed.join(", "),
        100.0 * ENOUGH_COVERAGE,
        100.0 * COVERAGE_GAIN
    );
    (n, Decision::new("charts", n, why))
}

/// Steps timed to estimate the speed of training.
pub const TIMED_STEPS: u64 = 8;
/// Steps after the warm start cost less than the timed ones (chart support prunes the charts a
/// sample does not belong to, and the warm start's own steps draw half batches): the whole run
/// averages this fraction of the fastest timed step. First measured on the suite against the
/// mean timed step before the warm start drew half batches (BENCHMARKS.md, "nuvo unwrap"); with
/// both, fragmented runs averaged 0.72–0.75 of the fastest timed step (homer_unruly 144 ms a
/// step against 200 ms, unruly_bunny 143 against 191; BENCHMARKS.md, "Half batches while the
/// warm start weighs in").
pub const MEAN_STEP_COST: f64 = 0.8;
/// Fewest steps a fitted run gets, whatever the budget: a slow machine or a large input should
/// get a larger `--time-budget` rather than fewer steps.
pub const MIN_STEPS: u64 = 300;
/// Most steps a fitted run gets: the plan of every machine fast enough to train this many
/// steps within the budget, so the budget is only a cap and the same input gives the same
/// config on a fast CPU as on a slower one. The warm start (30% of the plan) and the
/// learning-rate schedule follow the plan; a longer plan made a faster CPU train longer, since
/// its charts settled later. Common Shapes with the plan at 400 against the plans the budget
/// gave on a Zen 1 (300–550 steps for several charts, 1150–2000 for one or two): mean
/// Editability 0.9586 → 0.9579, mean wall 47.2 → 36.0 s a mesh, one-chart meshes unchanged
/// in score at a third of the time (BENCHMARKS.md, "A plan of at most 400 steps"). A run that
/// stops once settled plans it untimed ([`fit_steps`]).
pub const MAX_STEPS: u64 = 400;

/// Times up to [`TIMED_STEPS`] steps of `trainer` (at step 0) one by one, puts it back as it
/// was, and returns the step count that fits `budget_seconds` at the fastest of them (rounded
/// down to a multiple of 50, so timing noise rarely changes it; within
/// [`MIN_STEPS`]`..=`[`MAX_STEPS`]). Timing stops as soon as one step fits the cap: the plan is
/// then [`MAX_STEPS`] whatever the later steps take.
/// The fastest, not the mean: on a shared machine a few steps run 30–80% slow now and then, and
/// the mean of eight moved the plan of one input between 350 and 500 steps from run to run
/// (fastest step: within 14%). The caller builds the run's trainer with it, since the warm
/// start's length follows the step count ([`recipe`]).
///
/// A run that stops once its charts settle (`training.stop_when_settled`, a clean surface) is not
/// timed: it plans [`MAX_STEPS`] whatever the budget, which then stops it only through the run's
/// time limit. Why: such a run trains 150–300 steps of its 400 on Common Shapes, at 0.56–0.67 of
/// the fastest timed step on average (the early steps, before chart support prunes, are the
/// dearest), so [`MEAN_STEP_COST`] priced it high, and a plan cut to 350 or 300 on a slower
/// sitting changed its schedule, its settling and its atlas: the bunny trained 300 steps planned
/// at 350 and 200 planned at 300 or 400, with three different atlases (BENCHMARKS.md, "Clean
/// surfaces plan 400 steps untimed").
pub fn fit_steps(trainer: &mut Trainer, budget_seconds: f64) -> Result<(u64, Decision), UnwrapError> {
    if trainer.settling_threshold().is_some() {
        let why = format!(
            "at most: not timed, the same plan on every machine; training stops sooner once the {}, \
             and a {budget_seconds:.0} s training budget stops it on a slower machine",
            if trainer.config().model.charts == 1 { "chart's map holds still" } else { "charts hold still" }
        );
        return Ok((MAX_STEPS, Decision::new("steps", MAX_STEPS, why)));
    }
    let start = trainer.checkpoint()?;
    // Timed at full batches: a warm start on a share of them costs less than the plan assumes.
    trainer.time_full_batches(true);
    // One untimed step first: it allocates the tape's buffers.
    trainer.step()?;
    let (mut per_step, mut timed) = (f64::INFINITY, 0);
    // Any step's time bounds the fastest from above, so once one step shows that the cap fits,
    // more timing cannot change the plan.
    while timed < TIMED_STEPS && steps_for(budget_seconds, per_step) < MAX_STEPS {
        let t = Instant::now();
        trainer.step()?;
        per_step = per_step.min(t.elapsed().as_secs_f64());
        timed += 1;
    }
    trainer.time_full_batches(false);
    trainer.restore(&start)?;
    let steps = steps_for(budget_seconds, per_step);
    let why = format!(
        "{:.0} ms for the fastest of {timed} steps timed at the start (≈{:.0} ms on average over a \
         run), {budget_seconds:.0} s of training budget, at most {MAX_STEPS} steps on any machine",
        1e3 * per_step,
        1e3 * per_step * MEAN_STEP_COST,
    );
    Ok((steps, Decision::new("steps", steps, why)))
}

/// The step count for a budget and a timed step (see [`fit_steps`]).
pub fn steps_for(budget_seconds: f64, seconds_per_timed_step: f64) -> u64 {
    let raw = budget_seconds / (seconds_per_timed_step * MEAN_STEP_COST).max(1e-6);
    ((raw.min(1e9) as u64) / 50 * 50).clamp(MIN_STEPS, MAX_STEPS)
}

/// Sanity of a loaded mesh for unwrapping beyond what loading checks: it must have area.
pub fn check_mesh(path: &Path, mesh: &TriMesh) -> Result<(), UnwrapError> {
    if !mesh.has_area() {
        return Err(input_error(path, "every face has zero area: there is no surface to unwrap"));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_texture_is_baked_when_the_input_has_colour_and_a_mesh_to_bake_onto() {
        let dir = tempfile::tempdir().unwrap();
        let tri = "f 1 2 3\n";
        let plain = dir.path().join("plain.obj");
        std::fs::write(&plain, format!("v 0 0 0\nv 1 0 0\nv 0 1 0\n{tri}")).unwrap();
        let (on, decision, warnings) = choose_texture(&plain, InputKind::Mesh, false).unwrap();
        assert!(!on && decision.is_none() && warnings.is_empty());
        let coloured = dir.path().join("coloured.obj");
        std::fs::write(&coloured, format!("v 0 0 0 1 0 0\nv 1 0 0 0 1 0\nv 0 1 0 0 0 1\n{tri}")).unwrap();
        let (on, decision, _) = choose_texture(&coloured, InputKind::Mesh, false).unwrap();
        assert!(on);
        assert!(decision.unwrap().why.contains("vertex colours"));
        // A coloured point cloud has no mesh of its own: only with `output.bake_mesh`.
        let cloud = dir.path().join("cloud.xyz");
        std::fs::write(&cloud, "0 0 0 0 0 1 255 0 0\n1 0 0 0 0 1 0 255 0\n0 1 0 0 0 1 0 0 255\n").unwrap();
        let (on, decision, _) = choose_texture(&cloud, InputKind::PointCloud, false).unwrap();
        assert!(!on);
        let d = decision.unwrap();
        assert!(d.choice == "none" && d.why.contains("output.bake_mesh"), "{d:?}");
        assert!(choose_texture(&cloud, InputKind::PointCloud, true).unwrap().0);
        // A missing texture is a warning naming it, not an error, and no texture.
        let mtl = dir.path().join("m.mtl");
        std::fs::write(&mtl, "newmtl m\nmap_Kd gone.png\n").unwrap();
        let textured = dir.path().join("textured.obj");
        let text =
            "mtllib m.mtl\nusemtl m\nv 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nf 1/1 2/2 3/3\n";
        std::fs::write(&textured, text).unwrap();
        let (on, _, warnings) = choose_texture(&textured, InputKind::Mesh, false).unwrap();
        assert!(!on && warnings.iter().any(|w| w.contains("gone.png")), "{warnings:?}");
    }

    fn profile(hidden: f64, fragments: usize) -> MeshProfile {
        MeshProfile {
            vertices: 10,
            faces: 10,
            degenerate_faces: 0,
            components: fragments + 1,
            largest_component_area: 0.9,
            fragments,
            fragment_area: 0.01,
            hidden_area: hidden,
            outward_escapes: 0.9,
        }
    }

    #[test]
    fn sampling_is_visible_for_hidden_surface_or_floaters_only() {
        assert_eq!(choose_sampling(&profile(0.01, 3)).0, SamplingMode::Uniform);
        assert_eq!(choose_sampling(&profile(0.2, 3)).0, SamplingMode::Visible);
        assert_eq!(choose_sampling(&profile(0.0, 500)).0, SamplingMode::Visible);
        let (_, d) = choose_sampling(&profile(0.2, 3));
        assert!(d.why.contains("20.0% of the surface hidden"), "{}", d.why);
    }

    fn trials(shares: &[f64]) -> Vec<ChartTrial> {
        shares
            .iter()
            .enumerate()
            .map(|(k, &s)| ChartTrial {
                charts: k + 1,
                coverage: Coverage { supervised: s, mean_facing: 0.8 },
            })
            .collect()
    }

    #[test]
    fn inside_out_meshes_get_flipped_normals_when_sampled_by_area() {
        let inverted = MeshProfile { outward_escapes: 0.1, ..profile(0.0, 0) };
        assert!(choose_orientation(&inverted, SamplingMode::Uniform).is_some());
        assert!(choose_orientation(&inverted, SamplingMode::Visible).is_none());
        assert!(choose_orientation(&profile(0.0, 0), SamplingMode::Uniform).is_none());
    }

    #[test]
    fn charts_are_the_fewest_that_cover_or_stop_gaining() {
        assert_eq!(choose_charts(&trials(&[0.80, 0.96, 0.99])).0, 2);
        assert_eq!(choose_charts(&trials(&[0.97, 0.99])).0, 1);
        // 0.85 -> 0.855 gains half a point: stop at 2.
        assert_eq!(choose_charts(&trials(&[0.70, 0.85, 0.855, 0.90])).0, 2);
        // Never enough, always gaining: the most.
        assert_eq!(choose_charts(&trials(&[0.5, 0.6, 0.7])).0, 3);
    }

    fn slab(half: [f32; 3]) -> TriMesh {
        nuvo_geometry::testdata::closed_box([0.0; 3], half)
    }

    /// `mesh` as a source sampled by area, as `nuvo unwrap` builds one for a clean mesh.
    fn uniform_source(mesh: TriMesh) -> nuvo_geometry::mesh_source::MeshSource {
        use nuvo_geometry::BuildContext;
        use nuvo_geometry::mesh_source::{MeshOptions, MeshSource};
        let opts = MeshOptions {
            path: "test".into(),
            sampling: SamplingMode::Uniform,
            normals: Default::default(),
            flip_normals: false,
            cameras: None,
        };
        let ctx = BuildContext { base_dir: ".".into() };
        MeshSource::from_mesh("test".into(), mesh, &opts, &ctx).unwrap()
    }

    fn trials_on(mesh: TriMesh) -> Vec<ChartTrial> {
        chart_trials(&uniform_source(mesh), 7).unwrap()
    }

    #[test]
    fn measured_meshes_get_the_sampling_their_profile_calls_for() {
        let outer = slab([1.0, 1.0, 1.0]);
        assert_eq!(choose_sampling(&profile_mesh(&outer, 1)).0, SamplingMode::Uniform);
        // A box inside it: a fifth of the area hidden from every outside direction.
        let nested = nuvo_geometry::testdata::merged(outer, &slab([0.5, 0.5, 0.5]));
        let p = profile_mesh(&nested, 1);
        assert!((p.hidden_area - 0.2).abs() < 0.03, "{p:?}");
        assert_eq!(choose_sampling(&p).0, SamplingMode::Visible);
        // Inside out: flipped normals when sampled by area.
        let mut inverted = slab([1.0, 2.0, 0.5]);
        inverted.triangles.iter_mut().for_each(|t| t.swap(1, 2));
        let p = profile_mesh(&inverted, 1);
        assert!(choose_orientation(&p, SamplingMode::Uniform).is_some(), "{p:?}");
    }

    #[test]
    fn a_sheet_takes_one_chart_and_a_closed_pancake_two() {
        let sheet = TriMesh {
            positions: vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.1], [1.0, 1.0, 0.0], [0.0, 1.0, 0.1]],
            triangles: vec![[0, 1, 2], [0, 2, 3]],
            uv: None,
        };
        let t = trials_on(sheet);
        assert_eq!(t.len(), CHART_CANDIDATES.count());
        assert_eq!(t[0].coverage.supervised, 1.0);
        assert_eq!(choose_charts(&t).0, 1);
        // Top and bottom hold 200 of 204 units of area: one chart sees half, two see 98%.
        let t = trials_on(slab([5.0, 5.0, 0.05]));
        assert!(t[0].coverage.supervised < 0.55, "{t:?}");
        assert!(t[1].coverage.supervised > 0.95, "{t:?}");
        assert_eq!(choose_charts(&t).0, 2);
    }

    /// A tiny trainer on a box sampled by area, with `model` and `training` lines added to its
    /// config: what the step-planning tests time.
    fn box_trainer(model: &str, training: &str) -> Trainer {
        let source = uniform_source(slab([1.0, 0.5, 0.25]));
        let text = format!(
            "[geometry]\nsource = \"mesh\"\npath = \"box.obj\"\n\
             [model]\n{model}depth = 2\nwidth = 8\ngrid_resolution = 4\n\
             [training]\n{training}steps = 10\nbatch_3d = 64\nbatch_uv = 64\n"
        );
        let loaded = crate::config::from_str("box.toml", &text).unwrap();
        let losses = nuvo_losses::LossRegistry::with_builtins();
        Trainer::with_source(&loaded, Box::new(source), &losses).unwrap()
    }

    #[test]
    fn timing_stops_once_one_step_fits_the_cap() {
        let mut trainer = box_trainer("", "");
        // A budget that any step fits 400 times over: the first timed step decides.
        let (steps, d) = fit_steps(&mut trainer, 1e9).unwrap();
        assert_eq!(steps, MAX_STEPS);
        assert!(d.why.contains("fastest of 1 steps"), "{}", d.why);
        // A budget that no step fits: every step is timed, and the floor holds.
        let (steps, d) = fit_steps(&mut trainer, 1e-9).unwrap();
        assert_eq!(steps, MIN_STEPS);
        assert!(d.why.contains(&format!("fastest of {TIMED_STEPS} steps")), "{}", d.why);
        assert_eq!(trainer.step_index(), 0, "the trainer is put back as it was");
    }

    #[test]
    fn a_run_that_stops_once_settled_plans_the_cap_untimed_at_any_budget() {
        let mut trainer = box_trainer("charts = 2\n", "stop_when_settled = 0.015\n");
        let (steps, d) = fit_steps(&mut trainer, 1e-9).unwrap();
        assert_eq!(steps, MAX_STEPS, "a budget no step fits does not cut the plan");
        assert!(d.why.contains("not timed") && d.why.contains("charts hold still"), "{}", d.why);
        assert_eq!(trainer.step_index(), 0, "no step taken");
    }

    #[test]
    fn steps_fill_the_budget_in_fifties_within_bounds() {
        // 30 s at 0.099 s per timed step, 0.0792 s on average: 378 steps, down to 350.
        assert_eq!(steps_for(30.0, 0.099), 350);
        assert_eq!(steps_for(30.0, 0.12), MIN_STEPS);
        // 416 steps fit: capped.
        assert_eq!(steps_for(30.0, 0.09), MAX_STEPS);
        assert_eq!(steps_for(1.0, 0.1), MIN_STEPS);
        assert_eq!(steps_for(1e6, 1e-9), MAX_STEPS);
    }

    #[test]
    fn input_kinds_follow_the_extension_and_bad_files_are_named() {
        let dir = tempfile::tempdir().unwrap();
        let write = |name: &str, text: &str| {
            let p = dir.path().join(name);
            std::fs::write(&p, text).unwrap();
            p
        };
        assert_eq!(input_kind(&write("a.OBJ", "v 0 0 0")).unwrap(), InputKind::Mesh);
        assert_eq!(input_kind(&write("a.glb", "x")).unwrap(), InputKind::Mesh);
        assert_eq!(input_kind(&write("a.xyz", "0 0 0")).unwrap(), InputKind::PointCloud);
        let header =
            "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n";
        assert_eq!(
            input_kind(&write("p.ply", &format!("{header}end_header\n"))).unwrap(),
            InputKind::PointCloud
        );
        let mesh = format!("{header}element face 1\nproperty list uchar int vertex_indices\nend_header\n");
        assert_eq!(input_kind(&write("m.ply", &mesh)).unwrap(), InputKind::Mesh);
        assert_eq!(input_kind(&write("a.npy", "x")).unwrap(), InputKind::Density);
        let e = input_kind(&write("a.stl", "solid")).unwrap_err().to_string();
        assert!(e.contains("a.stl") && e.contains("unsupported input type `.stl`"), "{e}");
        let e = input_kind(&write("b.obj", "")).unwrap_err().to_string();
        assert!(e.contains("b.obj: the file is empty"), "{e}");
        let e = input_kind(&dir.path().join("missing.obj")).unwrap_err().to_string();
        assert!(e.contains("missing.obj: cannot read the input"), "{e}");
    }

    #[test]
    fn the_recipe_is_a_valid_config_and_fits_the_bake_to_fragmented_meshes() {
        let path = Path::new("/data/x.obj");
        let base = RecipeInput {
            kind: InputKind::Mesh,
            path,
            sampling: SamplingMode::Uniform,
            flip_normals: false,
            charts: 5,
            steps: 900,
            stop_after_seconds: Some(90.0),
            seed: 3,
            bounds: None,
            texture: false,
        };
        let clean = crate::config::from_str("clean", &recipe(&base)).unwrap().config;
        assert_eq!((clean.model.charts, clean.training.steps, clean.seed), (5, 900, 3));
        assert!(clean.output.untangle && clean.output.round_trip_tolerance > 0.0 && clean.output.injective);
        assert!(clean.output.join && clean.output.absorb_enclaves && clean.output.cut_necks);
        assert!(clean.output.cut_cones, "discs are cut at their cone points");
        let slim_terms = |o: &crate::config::OutputConfig| (o.injective_orthogonal, o.injective_equiareal);
        let unwrap_terms =
            (nuvo_atlas::injective::UNWRAP_ORTHOGONAL, nuvo_atlas::injective::UNWRAP_EQUIAREAL);
        assert!(unwrap_terms.0 > 0.0 && unwrap_terms.1 > 0.0);
        assert_eq!(slim_terms(&clean.output), unwrap_terms, "axes and area kept");
        assert!(clean.output.crease_charts, "machined parts may be charted by their creases");
        assert_eq!(clean.output.injective_split_energy, nuvo_atlas::injective::SPLIT_ENERGY);
        assert_eq!(clean.training.time_budget_minutes, Some(1.5));
        assert_eq!(clean.training.stop_when_settled, Some(0.015));
        let warm = clean.warm_start.unwrap();
        assert_eq!((warm.steps, warm.batch_share), (270, 0.5));
        let flipped = RecipeInput { flip_normals: true, ..base };
        let c = crate::config::from_str("flipped", &recipe(&flipped)).unwrap().config;
        assert_eq!(c.geometry.options["flip_normals"].as_bool(), Some(true));
        assert!(!clean.geometry.options.contains_key("flip_normals"));
        let unruly = RecipeInput { sampling: SamplingMode::Visible, ..base };
        let c = crate::config::from_str("unruly", &recipe(&unruly)).unwrap().config;
        assert!(!c.output.untangle && c.output.round_trip_tolerance == 0.0);
        assert!(c.output.injective && c.output.join, "injective islands everywhere");
        assert!(c.output.absorb_enclaves);
        assert!(c.output.cut_necks, "necks cut everywhere");
        assert!(c.output.cut_cones, "cone cuts everywhere");
        assert_eq!(slim_terms(&c.output), unwrap_terms, "axes and area kept everywhere");
        assert!(c.output.crease_charts, "crease charts tried everywhere (left alone past 256 regions)");
        assert_eq!(
            c.output.injective_split_energy,
            nuvo_atlas::injective::FAILED_SLIM_ENERGY,
            "only the fragments' discs SLIM could not flatten are split"
        );
        assert!(c.output.refine, "refinement holds everywhere");
        assert_eq!(c.geometry.options["sampling"].as_str(), Some("visible"));
        assert_eq!(c.training.stop_when_settled, None, "fragmented inputs train to their budget");
        let grid = RecipeInput {
            kind: InputKind::Density,
            bounds: Some([[-1.0, -2.0, -1.0], [1.0, 2.0, 1.0]]),
            ..base
        };
        let c = crate::config::from_str("grid", &recipe(&grid)).unwrap().config;
        assert_eq!(c.geometry.source, "density");
        assert!(c.geometry.options["bounds"].to_string().contains("-2.0"));
        assert_eq!(c.training.stop_when_settled, None);
        let cloud = RecipeInput { kind: InputKind::PointCloud, ..base };
        let c = crate::config::from_str("cloud", &recipe(&cloud)).unwrap().config;
        assert_eq!(c.training.stop_when_settled, Some(0.015), "a point cloud is a clean surface");
        assert!(!clean.output.texture, "no texture unless the input has colour");
        let coloured = RecipeInput { texture: true, ..base };
        assert!(crate::config::from_str("coloured", &recipe(&coloured)).unwrap().config.output.texture);
    }
}

//! Experiment configs: the TOML file a researcher writes, plus `--set key=value` overrides, checked
//! with errors that name the file, the line, the key and the valid choices.
//!
//! Loading happens in three stages, each with its own error:
//! 1. the text must be TOML (syntax errors come with toml's line and snippet);
//! 2. overrides are applied to the parsed tree and the tree is deserialised into [`ExperimentConfig`]
//!    (`deny_unknown_fields` everywhere; serde reports the key path, which [`ConfigSource::locate`]
//!    turns back into a line of the file);
//! 3. [`ExperimentConfig::validate`] checks ranges (positive sizes, finite rates, ...).
//!
//! Relative input paths in the file (e.g. `geometry.path`) resolve against the file's folder; those
//! given with `--set` resolve against the working directory. `output.dir` resolves against the
//! working directory.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use nuvo_autodiff::nn::Init;
use nuvo_autodiff::{Activation, MatmulPrecision};
use serde::{Deserialize, Serialize};

/// The whole experiment.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ExperimentConfig {
    /// Seeds initialisation and every random draw; same config + seed = same atlas.
    #[serde(default)]
    pub seed: u64,
    /// The scene.
    pub geometry: GeometryConfig,
    /// The networks.
    #[serde(default)]
    pub model: ModelConfig,
    /// Batch sizes, steps, budget, checkpoints.
    #[serde(default)]
    pub training: TrainingConfig,
    /// Adam and its schedule.
    #[serde(default)]
    pub optimizer: OptimizerConfig,
    /// `[warm_start]`: the optional projection prior of the first steps (off by default; not in
    /// the paper). See [`crate::warm_start`].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub warm_start: Option<crate::warm_start::WarmStartConfig>,
    /// The loss terms, one table each. Absent: the paper's eight at their weights
    /// (`nuvo_losses::builtin::PAPER`), whatever else is registered. Present:
    /// exactly the listed terms (removing an entry, or a weight of 0, is an ablation).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub losses: Option<BTreeMap<String, LossConfig>>,
    /// Where results go.
    #[serde(default)]
    pub output: OutputConfig,
    /// `[ablation]`: the variants `nuvo ablate` runs (ignored by `nuvo train`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ablation: Option<AblationConfig>,
}

/// `[geometry]`: which registered source, and its own options (checked by the source itself).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GeometryConfig {
    /// Registered source name: `mesh`, `point_cloud`, `density`, or a plugin's.
    pub source: String,
    /// Every other key of the table, handed to the source's builder.
    #[serde(flatten)]
    pub options: toml::Table,
}

/// `[model]`: the `2n + 1` networks. Per-network tables override depth, width and encoding degree.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ModelConfig {
    /// Number of charts `n`.
    pub charts: usize,
    /// Fully-connected layers per network (the paper: 8).
    pub depth: usize,
    /// Channels per hidden layer (the paper: 256).
    pub width: usize,
    /// Hidden activation.
    pub activation: Activation,
    /// How the MLPs start: `"torch"` (default; PyTorch's `U(±1/√in)`) or `"he"` (larger initial maps;
    /// see BENCHMARKS.md "Initialisation" for when each measured better).
    pub init: Init,
    /// Overrides for the chart-assignment network `c` (encoding degree 1 by default).
    pub chart: NetworkOverrides,
    /// Overrides for the texture-coordinate networks `t_i` (encoding degree 4 by default).
    pub texture: NetworkOverrides,
    /// Overrides for the surface-coordinate networks `s_i` (encoding degree 4 by default).
    pub surface: NetworkOverrides,
    /// Texels per side of each normal grid `N_i`; default `256·√(2/n)` (the paper's texture budget).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub grid_resolution: Option<usize>,
    /// Initial value of the learned average stretch `σ`.
    pub sigma_init: f32,
    /// Angular frequency (radians per unit of model-frame length) of the lowest positional-encoding
    /// band: networks see `γ(encoding_scale · z)`. π is NeRF's convention; 1 is mip-NeRF's. Lower
    /// values make the networks smoother across the object.
    pub encoding_scale: f32,
}

impl Default for ModelConfig {
    fn default() -> Self {
        ModelConfig {
            charts: 1,
            depth: 8,
            width: 256,
            activation: Activation::Relu,
            init: Init::default(),
            chart: NetworkOverrides::default(),
            texture: NetworkOverrides::default(),
            surface: NetworkOverrides::default(),
            grid_resolution: None,
            sigma_init: 1.0,
            encoding_scale: std::f32::consts::PI,
        }
    }
}

/// Per-network overrides; unset fields fall back to `[model]`'s.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct NetworkOverrides {
    #[serde(skip_serializing_if = "Option::is_none")]
    pub depth: Option<usize>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub width: Option<usize>,
    /// Positional-encoding degree.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub posenc: Option<usize>,
}

/// `[training]`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TrainingConfig {
    /// Optimisation steps; the cosine schedule spans them.
    pub steps: u64,
    /// 3-D surface samples per step `|G|`.
    pub batch_3d: usize,
    /// UV samples per step `|T|`.
    pub batch_uv: usize,
    /// How many of the 3-D samples carry the distortion losses (`conformal`, `stretch`), which each
    /// cost two more texture-network passes per chart; default all of `batch_3d` (the paper). Not
    /// in the paper when smaller: the first `batch_distortion` samples of the (random) batch.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub batch_distortion: Option<usize>,
    /// Chart-support threshold `τ`: the `c(x)`-weighted losses (`cycle_3d`, `texture`, `conformal`,
    /// `stretch`) evaluate chart `i`'s networks only on the samples where `c(x)[i] ≥ τ`, so a term
    /// that would weigh less than `τ` costs no network pass (each skipped term changes its loss by
    /// less than `τ` times its value). 0 (the default, the paper) evaluates every chart on every
    /// sample. Not applied while the warm-start prior is on, when `c` is still soft. Not in the paper.
    pub chart_support: f32,
    /// Stop early after this many minutes of training (results then depend on the machine's speed).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub time_budget_minutes: Option<f64>,
    /// Stop once the atlas has settled: when, at two looks in a row 25 steps apart after the warm
    /// start, at most this share of a fixed sample of surface points changed chart
    /// (`crate::settling`). The atlas a bake makes changes little after that (the layout passes
    /// redo the distortion within each chart), while training on would mostly merge the last
    /// small charts. That holds for bakes with the layout passes (`output.refine`, `injective`,
    /// `packing = "islands"`, as `nuvo unwrap` sets them); without them the networks' own maps
    /// are the atlas and keep improving. `steps` stays the most a run takes. A run of one chart
    /// has nothing to assign: it stops once its map's shape holds still instead
    /// (`crate::trainer::ONE_CHART_SHAPE_SETTLED`). Not in the paper.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub stop_when_settled: Option<f32>,
    /// Arithmetic of the networks' products while training: `"f32"` (the default) or `"bf16"`,
    /// factors rounded to bfloat16 and accumulated in f32 on the AMX tiles of CPUs that have them
    /// (Intel Xeon since Sapphire Rapids) or on AVX-512 BF16 (AMD Zen 4 and later), f32
    /// elsewhere (the run says which when it starts).
    /// Faster; the atlas differs from an f32 run's as another seed's would (BENCHMARKS.md). The
    /// bake always evaluates the networks in f32. Not in the paper.
    pub matmul: MatmulPrecision,
    /// Finite-difference step of the distortion losses, in the model frame (the paper: 1e-2).
    pub epsilon: f32,
    /// Write a checkpoint every this many steps (and at the end).
    pub checkpoint_every: u64,
    /// After this many consecutive steps skipped for NaN/inf, roll back to the last checkpoint.
    pub max_bad_steps: u32,
}

impl Default for TrainingConfig {
    fn default() -> Self {
        TrainingConfig {
            steps: 2000,
            batch_3d: 5000,
            batch_uv: 5000,
            batch_distortion: None,
            chart_support: 0.0,
            time_budget_minutes: None,
            stop_when_settled: None,
            matmul: MatmulPrecision::F32,
            epsilon: 1e-2,
            checkpoint_every: 250,
            max_bad_steps: 20,
        }
    }
}

/// `[optimizer]`: Adam with per-group learning rates (the paper's by default) and cosine decay.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct OptimizerConfig {
    /// Learning rate of every MLP parameter (the paper: 1e-4).
    pub lr_mlp: f32,
    /// Learning rate of σ (the paper: 0.1).
    pub lr_sigma: f32,
    /// Learning rate of the normal grids (the paper: 0.04).
    pub lr_grid: f32,
    pub beta1: f32,
    pub beta2: f32,
    pub eps: f32,
    /// Linear warm-up steps before the cosine decay.
    pub warmup_steps: u64,
    /// The schedule decays every rate to this fraction of its start (the paper: 0).
    pub final_lr_factor: f32,
}

impl Default for OptimizerConfig {
    fn default() -> Self {
        OptimizerConfig {
            lr_mlp: 1e-4,
            lr_sigma: 0.1,
            lr_grid: 0.04,
            beta1: 0.9,
            beta2: 0.999,
            eps: 1e-8,
            warmup_steps: 0,
            final_lr_factor: 0.0,
        }
    }
}

/// `[losses.NAME]`: the weight, plus the loss's own options (checked by the loss).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LossConfig {
    /// Weight of the term; absent means the registry's default (the paper's weight).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub weight: Option<f32>,
    /// Ramp the weight linearly from 0 to `weight` over this many first steps (0 or absent: full
    /// weight from the start). A curriculum knob, not in the paper: e.g. let the cycle losses find a
    /// bijection before the distortion terms start shaping it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub warmup_steps: Option<u64>,
    /// Every other key, handed to the loss's builder.
    #[serde(flatten)]
    pub options: toml::Table,
}

/// `[output]`: where results go and how the atlas is baked, drawn and measured.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct OutputConfig {
    /// Output folder (relative to the working directory).
    pub dir: PathBuf,
    /// Bake, export, draw and measure the atlas after training.
    pub bake: bool,
    /// A mesh to bake onto instead of the geometry source's own (point clouds have none; density
    /// grids have their marching-cubes mesh unless `extract_mesh = false`), in the
    /// input's own coordinates; relative to the config's folder.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub bake_mesh: Option<PathBuf>,
    /// Side of the packed atlas in texels (the charts' grid cells tile it).
    pub atlas_resolution: u32,
    /// Empty texels around each chart in the atlas, so bilinear filtering does not bleed.
    pub gutter: u32,
    /// The bake's round-trip check (not in the paper; `nuvo_atlas::bake` docs): a face whose chart
    /// does not map its corners back to within this distance, as a fraction of the geometry's
    /// longest bounding-box side, moves to a chart that does, if one keeps it the right way round.
    /// Off (0) by default, as the paper bakes by the probabilities alone. At 0.1 it removes most
    /// overlapping faces of the bunny's atlas at no cost to the scores, but on unruly meshes it
    /// cuts the charts up (BENCHMARKS.md, "Round-trip check"). Off, the bake does not run the
    /// surface networks at all (they serve only this check).
    pub round_trip_tolerance: f32,
    /// Untangle the bake (not in the paper; `nuvo_atlas::untangle`): move single UV vertices so that
    /// faces the wrong way round in their chart (fold-overs, mostly tiny triangles on creases of a
    /// scanned surface, where a smooth map of 3-D position cannot help mirroring them) turn back.
    /// The flipped-face count never rises. Off by default, as the paper bakes the map as it is.
    pub untangle: bool,
    /// Absorb chart enclaves in the bake (not in the paper; `nuvo_atlas::enclaves`): a patch of
    /// one chart surrounded by one other, and smaller than the region round it, moves to that chart
    /// where the chart's map has it the right way round. The chart network's argmax is noisy on
    /// marching-cubes meshes, and every speck it leaves is an island with a seam all round it.
    /// Off by default, as the paper bakes by the probabilities alone; on in `nuvo unwrap`.
    pub absorb_enclaves: bool,
    /// Refine the baked islands towards isometry (not in the paper; `nuvo_atlas::refine`): a
    /// local/global ARAP solve per UV island, started from the networks' UVs, kept only where it
    /// adds no flipped face and does not lower the island's angular score. Off by default (the
    /// paper's bake); `nuvo unwrap` turns it on.
    pub refine: bool,
    /// Make every baked island injective (not in the paper; `nuvo_atlas::injective`): no face
    /// flipped, none over another. Folds are mended in place; an island that overlaps itself is
    /// re-embedded as a disc and its distortion lowered (SLIM), or, where that distorts too much,
    /// its overlapping faces are detached into islands of their own (only with `packing =
    /// "islands"`, which places the new islands; with `"squares"` such an island keeps its UVs).
    /// Off by default (the paper's bake); `nuvo unwrap` turns it on for clean meshes.
    pub injective: bool,
    /// With `injective`: the symmetric Dirichlet energy per unit area above which an island
    /// re-embedded as a disc is split into parts instead (`nuvo_atlas::injective::SPLIT_ENERGY`,
    /// 4.5, by default); `inf` never splits a disc. On a marching-cubes mesh most islands are
    /// floaters and crumbs, closed blobs whose every split is a seam in the renders while their
    /// distortion barely moves the scores' medians, so `nuvo unwrap` sets it there to
    /// `nuvo_atlas::injective::FAILED_SLIM_ENERGY` (100): only the discs SLIM could not flatten
    /// are split (BENCHMARKS.md, "Injective islands on fragmented meshes" and "Splitting the
    /// discs SLIM could not flatten").
    pub injective_split_energy: f64,
    /// With `injective`: the weight of the conformal term SLIM minimises with the symmetric
    /// Dirichlet energy (`nuvo_atlas::injective::InjectiveOptions::conformal`): 0 balances angle
    /// and area distortion as the symmetric Dirichlet energy does, a larger weight keeps angles
    /// (PartUV's angular score) at the cost of area.
    pub injective_conformal: f64,
    /// With `injective`: the weight of the shear term SLIM minimises with the symmetric
    /// Dirichlet energy, `cos²` of the angle the texture axes `∂p/∂u` and `∂p/∂v` make on the
    /// surface (`nuvo_atlas::injective::InjectiveOptions::orthogonal`). Unlike the conformal
    /// term it leaves stretch along the texture axes free, so the axes stay perpendicular (what
    /// PartUV's angular score and the paper's Conformal metric measure) at less cost in area.
    /// 0 (off) by default; `nuvo unwrap` and `configs/bunny.toml` set
    /// `nuvo_atlas::injective::UNWRAP_ORTHOGONAL`.
    pub injective_orthogonal: f64,
    /// With `injective`: the weight of the area term SLIM minimises with the symmetric Dirichlet
    /// energy, `(det J − 1)²` (`nuvo_atlas::injective::InjectiveOptions::equiareal`): every face
    /// kept at its island's texel density (what Stretch and the area distortions measure). 0
    /// (off) by default; `nuvo unwrap` and `configs/bunny.toml` set
    /// `nuvo_atlas::injective::UNWRAP_EQUIAREAL`.
    pub injective_equiareal: f64,
    /// With `injective`: cut each solved island open from its cone points (where the surface
    /// gathers an angle deficit that no flat map holds without distortion) to its boundary, and
    /// keep the cuts where SLIM then lowers the island's distortion enough (not in the paper;
    /// `nuvo_atlas::injective`, step 6). Off by default.
    pub cut_cones: bool,
    /// Join small islands into a neighbouring island and smooth the seams (not in the paper;
    /// `nuvo_atlas::join`): an island under 0.2% of the surface grows onto the neighbour it shares
    /// the longest edge with, and a face with two edges on a seam moves across it, wherever the
    /// result stays injective. Runs after `injective`; off by default, on in `nuvo unwrap`
    /// wherever `injective` is.
    pub join: bool,
    /// With `injective` and `packing = "islands"`: chart the surface by its sharp creases (normals more than 60° apart;
    /// regions under 2% of the area join a neighbour), make those charts injective as the
    /// networks' islands were, and keep them instead of the networks' layout where the
    /// Editability estimated from renders other than the evaluation's is higher, both packed
    /// (not in the paper; `nuvo_atlas::creases`): a machined part's patches flatten to
    /// isometries. Runs after `join`; off by default, on in `nuvo unwrap`.
    pub crease_charts: bool,
    /// With `packing = "islands"`: cut islands across their necks where the atlas then packs
    /// tighter (not in the paper; `nuvo_atlas::necks`): cuts are tried greedily on the islands
    /// that waste most of their bounding rectangle and kept only when a trial packing gains in
    /// proportion to the seam's length; with `injective`, SLIM then relaxes the parts from their
    /// maps. Off by default, on in `nuvo unwrap` (Common Shapes: packing efficiency 0.59 -> 0.68,
    /// charts 12.4 -> 16.4, Editability 0.9721 -> 0.9675, BENCHMARKS.md "More neck cuts").
    pub cut_necks: bool,
    /// With `cut_necks`: how much packing a seam must buy, the least relative rise of the packing
    /// efficiency per unit of the cut's 3-D length over the square root of the surface's area
    /// (`nuvo_atlas::necks::SEAM_COST`, 0.0625, by default; the pass's cautious second path asks
    /// twice this, `nuvo_atlas::necks::CAUTIOUS_PRICE`): larger keeps fewer, shorter seams. On
    /// Common Shapes, one path at 0.25: packing 0.641 with 13.7 charts, Editability 0.9695
    /// (BENCHMARKS.md, "More neck cuts"); the two paths at 0.0625: 0.704 with 18.2 charts, where
    /// the earlier default, one path at 0.125, gave 0.690 with 17.0 (BENCHMARKS.md, "Two paths
    /// for the necks pass").
    pub neck_seam_cost: f64,
    /// How the atlas is laid out: `"squares"` (default, the paper's: one square cell per chart) or
    /// `"islands"` (not in the paper; `nuvo_atlas::islands`: every UV island packed on its own at
    /// one texel density for the whole atlas, rotated to fit, with `gutter` texels between islands).
    pub packing: Packing,
    /// Views of the metrics (the paper's protocol: random views on a sphere).
    pub eval_views: usize,
    /// Side of each metrics view in pixels.
    pub eval_resolution: u32,
    /// Checkerboard renders written to `renders/`.
    pub renders: usize,
    /// Side of each render in pixels.
    pub render_resolution: u32,
    /// Carry the input's appearance over (not in the paper; `nuvo_atlas::texture`): bake its
    /// colour (vertex colours, its own textures through its own UVs, coloured points) into
    /// `texture.png` at `atlas_resolution` through the new UVs, and make it the texture of
    /// `atlas.obj`/`atlas.glb` and the renders (the checkerboard stays in `checker.png`). The
    /// colour comes from `texture_from` when set, else from `bake_mesh`, else from the geometry's
    /// own file. Off by default; `nuvo unwrap` turns it on when the input has colour. Input
    /// without colour, or an image that cannot be read, is a warning and the atlas is written
    /// without a texture.
    pub texture: bool,
    /// With `texture`: the file whose colours to bake (a mesh with vertex colours or textures, or
    /// a coloured point cloud, placed like the trained geometry), e.g. a high-resolution scan;
    /// relative to the config's folder. Its colour is looked up at the nearest surface point
    /// (nearest points, for a point cloud) unless it has exactly the faces baked onto.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub texture_from: Option<PathBuf>,
    /// With `texture`: sub-texel points per texel side (2: four a texel), against aliasing.
    pub texture_supersampling: u32,
}

impl Default for OutputConfig {
    fn default() -> Self {
        OutputConfig {
            dir: PathBuf::from("runs/nuvo"),
            bake: true,
            bake_mesh: None,
            atlas_resolution: 2048,
            gutter: 4,
            round_trip_tolerance: 0.0,
            untangle: false,
            absorb_enclaves: false,
            refine: false,
            injective: false,
            injective_split_energy: nuvo_atlas::injective::SPLIT_ENERGY,
            injective_conformal: 0.0,
            injective_orthogonal: 0.0,
            injective_equiareal: 0.0,
            join: false,
            crease_charts: false,
            cut_necks: false,
            neck_seam_cost: nuvo_atlas::necks::SEAM_COST,
            cut_cones: false,
            packing: Packing::Squares,
            eval_views: 16,
            eval_resolution: 800,
            renders: 4,
            render_resolution: 512,
            texture: false,
            texture_from: None,
            texture_supersampling: 2,
        }
    }
}

/// How the baked atlas is laid out (`output.packing`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Packing {
    /// One square cell of a grid per chart (the paper's layout).
    #[default]
    Squares,
    /// Each UV island packed on its own at one texel density (`nuvo_atlas::islands`).
    Islands,
}

/// `[ablation]`: which variants `nuvo ablate` runs besides the base config.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AblationConfig {
    /// Run the base config as the first row (default true).
    #[serde(default = "default_true")]
    pub base: bool,
    /// Losses removed one at a time, a `w/o NAME` variant each. Absent: every loss of the base
    /// config; empty: none.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub remove_each: Option<Vec<String>>,
    /// Further named variants, run in the order written.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub variants: Vec<VariantConfig>,
}

impl Default for AblationConfig {
    fn default() -> Self {
        AblationConfig { base: true, remove_each: None, variants: Vec::new() }
    }
}

fn default_true() -> bool {
    true
}

/// `[[ablation.variants]]`: a named change of the base config.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct VariantConfig {
    /// Row label in the table (and, slugged, the run folder's name).
    pub name: String,
    /// Losses to drop from the base config.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub remove: Vec<String>,
    /// `KEY=VALUE` overrides, as with `--set`.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub set: Vec<String>,
}

/// A config that failed to load, with where and why.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    /// The resolved config could not be written as TOML (a value TOML cannot hold).
    #[error("cannot write the resolved config as TOML: {0}")]
    Serialize(String),
    #[error("cannot read config {path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// Not TOML; toml's message carries the line and a snippet.
    #[error("{path} is not valid TOML: {message}")]
    Syntax { path: PathBuf, message: String },
    /// A key is unknown, mistyped or out of range.
    #[error("{location}: {message}")]
    Invalid { location: String, message: String },
    /// A `--set` argument is malformed.
    #[error("--set {arg}: {message}")]
    Override { arg: String, message: String },
}

/// Where a config came from, for locating keys in error messages and resolving relative paths.
#[derive(Clone, Debug)]
pub struct ConfigSource {
    /// The file.
    pub path: PathBuf,
    text: String,
    /// Dotted keys set with `--set`.
    overridden: BTreeSet<String>,
}

impl ConfigSource {
    /// A source for text that did not come from a file (tests, programmatic configs).
    pub fn in_memory(name: &str, text: &str) -> Self {
        ConfigSource { path: PathBuf::from(name), text: text.to_owned(), overridden: BTreeSet::new() }
    }

    /// Human-readable location of a dotted key: `file line N, key \`a.b\``, or a note that it was set
    /// on the command line.
    pub fn locate(&self, key: &str) -> String {
        let file = self.path.display();
        if key.is_empty() {
            return file.to_string();
        }
        if self.overridden.iter().any(|o| key == o || key.starts_with(&format!("{o}."))) {
            return format!("{file}, key `{key}` (set with --set)");
        }
        match key_line(&self.text, key) {
            Some(line) => format!("{file} line {line}, key `{key}`"),
            None => format!("{file}, key `{key}`"),
        }
    }

    /// Folder that relative paths written in the file resolve against.
    pub fn base_dir(&self) -> PathBuf {
        self.path.parent().map(Path::to_path_buf).unwrap_or_default()
    }

    /// Whether `key` was set on the command line.
    pub fn is_overridden(&self, key: &str) -> bool {
        self.overridden.contains(key)
    }

    /// A [`ConfigError::Invalid`] for `key`.
    pub fn invalid(&self, key: &str, message: impl Into<String>) -> ConfigError {
        ConfigError::Invalid { location: self.locate(key), message: message.into() }
    }

    /// Turns a serde message from deserialising the table at `prefix` (e.g. `geometry`, or `""` for
    /// the whole document) into an error located at the offending key.
    pub fn serde_error(&self, prefix: &str, message: &str) -> ConfigError {
        let key = offending_key(prefix, message);
        let text = message.split("\nin `").next().unwrap_or(message).trim();
        self.invalid(&key, text.to_owned())
    }
}

/// A loaded, validated config and where it came from.
#[derive(Clone, Debug)]
pub struct LoadedConfig {
    pub config: ExperimentConfig,
    pub source: ConfigSource,
}

/// Reads `path`, applies `overrides` (`key.path=value`, the value in TOML syntax or else a bare
/// string) and validates the result.
pub fn load(path: &Path, overrides: &[String]) -> Result<LoadedConfig, ConfigError> {
    load_edited(path, overrides, |_, _| Ok(()))
}

/// [`load`], with `edit` changing the parsed tree after the overrides and before it is checked (the
/// ablation runner removes loss entries this way). `edit` gets the tree and the source, for errors.
pub fn load_edited(
    path: &Path,
    overrides: &[String],
    edit: impl FnOnce(&mut toml::Table, &ConfigSource) -> Result<(), ConfigError>,
) -> Result<LoadedConfig, ConfigError> {
    if path.is_dir() {
        return Err(ConfigError::Io {
            path: path.to_owned(),
            source: std::io::Error::other("is a directory, not a config file"),
        });
    }
    let text =
        std::fs::read_to_string(path).map_err(|source| ConfigError::Io { path: path.to_owned(), source })?;
    let source = ConfigSource { path: path.to_owned(), text, overridden: BTreeSet::new() };
    let cwd = std::env::current_dir().unwrap_or_default();
    let (mut config, source) = resolve(source, overrides, &cwd, edit)?;
    config.absolutize_paths(&cwd.join(source.base_dir()));
    Ok(LoadedConfig { config, source })
}

/// Parses a config from a string (no overrides).
pub fn from_str(name: &str, text: &str) -> Result<LoadedConfig, ConfigError> {
    from_str_with_overrides(name, text, &[])
}

/// Parses a config from a string and applies `overrides` as [`load`] does (`nuvo bake --set` on the
/// config stored in a checkpoint).
pub fn from_str_with_overrides(
    name: &str,
    text: &str,
    overrides: &[String],
) -> Result<LoadedConfig, ConfigError> {
    let cwd = std::env::current_dir().unwrap_or_default();
    let (config, source) = resolve(ConfigSource::in_memory(name, text), overrides, &cwd, |_, _| Ok(()))?;
    Ok(LoadedConfig { config, source })
}

/// The shared path of [`load_edited`] and [`from_str_with_overrides`]: parses `source`'s text,
/// applies `overrides` (recording them in the source), then `edit`, and deserialises and validates
/// the result.
fn resolve(
    mut source: ConfigSource,
    overrides: &[String],
    cwd: &Path,
    edit: impl FnOnce(&mut toml::Table, &ConfigSource) -> Result<(), ConfigError>,
) -> Result<(ExperimentConfig, ConfigSource), ConfigError> {
    let mut tree: toml::Table = toml::from_str(&source.text).map_err(|e| ConfigError::Syntax {
        path: source.path.clone(),
        message: e.to_string().trim().to_owned(),
    })?;
    for arg in overrides {
        let key = apply_override(&mut tree, arg, cwd)?;
        source.overridden.insert(key);
    }
    edit(&mut tree, &source)?;
    let config = ExperimentConfig::deserialize(toml::Value::Table(tree))
        .map_err(|e| source.serde_error("", &e.to_string()))?;
    config.validate(&source)?;
    Ok((config, source))
}

/// Applies one `key.path=value` override; returns the dotted key. Paths set this way that name
/// input files (`geometry.path`) are made absolute against `cwd`, since the user typed them relative
/// to where they stand.
fn apply_override(tree: &mut toml::Table, arg: &str, cwd: &Path) -> Result<String, ConfigError> {
    let err = |m: &str| ConfigError::Override { arg: arg.to_owned(), message: m.to_owned() };
    let (key, raw) = arg.split_once('=').ok_or_else(|| err("expected KEY=VALUE, e.g. training.steps=200"))?;
    let key = key.trim();
    let parts: Vec<&str> = key.split('.').collect();
    if parts.iter().any(|p| p.is_empty()) {
        return Err(err("the key has an empty segment"));
    }
    let mut value = parse_override_value(raw.trim());
    if key == "geometry.path"
        && let toml::Value::String(p) = &value
        && Path::new(p).is_relative()
    {
        value = toml::Value::String(cwd.join(p).to_string_lossy().into_owned());
    }
    let (last, parents) = parts.split_last().expect("split yields at least one part");
    let mut table = tree;
    for (depth, p) in parents.iter().enumerate() {
        let entry = table.entry(p.to_string()).or_insert_with(|| toml::Value::Table(toml::Table::new()));
        table = entry
            .as_table_mut()
            .ok_or_else(|| err(&format!("`{}` is not a table", parts[..=depth].join("."))))?;
    }
    table.insert(last.to_string(), value);
    Ok(key.to_owned())
}

/// A TOML value if `raw` is one (`200`, `1e-3`, `true`, `"x"`, `[1, 2]`), else the bare string.
fn parse_override_value(raw: &str) -> toml::Value {
    toml::from_str::<toml::Table>(&format!("v = {raw}"))
        .ok()
        .and_then(|mut t| t.remove("v"))
        .unwrap_or_else(|| toml::Value::String(raw.to_owned()))
}

/// The dotted key a serde message is about: `in \`a.b\`` gives the path; an unknown field adds its
/// name. `prefix` is the path of the table that was deserialised.
fn offending_key(prefix: &str, message: &str) -> String {
    let path = message.rsplit_once("\nin `").map(|(_, p)| p.trim_end_matches('`').trim_end_matches("`\n"));
    let unknown = message.strip_prefix("unknown field `").and_then(|r| r.split('`').next());
    let mut parts: Vec<&str> = Vec::new();
    if !prefix.is_empty() {
        parts.push(prefix);
    }
    if let Some(p) = path {
        parts.push(p.trim_end_matches('`'));
    }
    if let Some(u) = unknown {
        parts.push(u);
    }
    parts.join(".")
}

/// 1-based line of the dotted `key` in `text`, if it is written there.
fn key_line(text: &str, key: &str) -> Option<usize> {
    let doc = toml_edit::Document::parse(text).ok()?;
    let mut item = doc.as_item();
    let mut span = None;
    for part in key.split('.') {
        let (k, v) = match item {
            toml_edit::Item::Table(t) => t.get_key_value(part)?,
            toml_edit::Item::Value(toml_edit::Value::InlineTable(t)) => t.get_key_value(part)?,
            _ => return None,
        };
        span = k.span().or(span);
        item = v;
    }
    span.map(|s| text[..s.start].matches('\n').count() + 1)
}

impl ModelConfig {
    /// Depth, width and encoding degree of the chart network.
    pub fn chart_shape(&self) -> (usize, usize, usize) {
        self.resolve(&self.chart, 1)
    }

    /// Depth, width and encoding degree of the texture networks.
    pub fn texture_shape(&self) -> (usize, usize, usize) {
        self.resolve(&self.texture, 4)
    }

    /// Depth, width and encoding degree of the surface networks.
    pub fn surface_shape(&self) -> (usize, usize, usize) {
        self.resolve(&self.surface, 4)
    }

    fn resolve(&self, o: &NetworkOverrides, posenc: usize) -> (usize, usize, usize) {
        (o.depth.unwrap_or(self.depth), o.width.unwrap_or(self.width), o.posenc.unwrap_or(posenc))
    }

    /// Texels per side of each normal grid.
    pub fn grid_resolution(&self) -> usize {
        self.grid_resolution
            .unwrap_or_else(|| (256.0 * (2.0 / self.charts.max(1) as f64).sqrt()).round() as usize)
    }
}

impl ExperimentConfig {
    /// The resolved config as TOML, as runs save it (`config.toml`, the checkpoint).
    pub fn to_toml(&self) -> Result<String, ConfigError> {
        toml::to_string(self).map_err(|e| ConfigError::Serialize(e.to_string()))
    }

    /// Makes the input paths written in the file absolute (`base` is the config's folder): every
    /// `path` or `file` key inside `[geometry]` (at any depth), each `losses.NAME.plugin`, and
    /// `output.bake_mesh` and `output.texture_from`. The resolved
    /// config saved with a run then works from any working directory (for `nuvo bake`, `--resume`).
    pub fn absolutize_paths(&mut self, base: &Path) {
        fn visit(t: &mut toml::Table, base: &Path) {
            for (k, v) in t.iter_mut() {
                match v {
                    toml::Value::String(p)
                        if (k == "path" || k == "file") && Path::new(p.as_str()).is_relative() =>
                    {
                        *p = base.join(&*p).to_string_lossy().into_owned();
                    }
                    toml::Value::Table(inner) => visit(inner, base),
                    _ => {}
                }
            }
        }
        visit(&mut self.geometry.options, base);
        for loss in self.losses.iter_mut().flat_map(|l| l.values_mut()) {
            if let Some(toml::Value::String(p)) = loss.options.get_mut("plugin")
                && Path::new(p.as_str()).is_relative()
            {
                *p = base.join(&*p).to_string_lossy().into_owned();
            }
        }
        for m in [&mut self.output.bake_mesh, &mut self.output.texture_from] {
            if let Some(m) = m.as_mut().filter(|m| m.is_relative()) {
                *m = base.join(&*m);
            }
        }
    }

    /// Range checks that serde's types cannot express, section by section.
    pub fn validate(&self, src: &ConfigSource) -> Result<(), ConfigError> {
        self.model.validate(src)?;
        self.training.validate(src)?;
        self.optimizer.validate(src)?;
        if let Some(w) = &self.warm_start {
            w.validate(self.model.charts, src)?;
        }
        self.output.validate(src)?;
        for (name, l) in self.losses.iter().flatten() {
            if let Some(w) = l.weight {
                non_negative(&format!("losses.{name}.weight"), w, "must be a non-negative number", src)?;
            }
        }
        Ok(())
    }
}

impl ModelConfig {
    fn validate(&self, src: &ConfigSource) -> Result<(), ConfigError> {
        let m = self;
        positive("model.charts", m.charts, src)?;
        if m.charts > 256 {
            return Err(
                src.invalid("model.charts", format!("{} charts is more than the supported 256", m.charts))
            );
        }
        positive("model.depth", m.depth, src)?;
        positive("model.width", m.width, src)?;
        for (name, ov) in [("chart", &m.chart), ("texture", &m.texture), ("surface", &m.surface)] {
            positive(&format!("model.{name}.depth"), ov.depth.unwrap_or(1), src)?;
            positive(&format!("model.{name}.width"), ov.width.unwrap_or(1), src)?;
            if ov.posenc.is_some_and(|p| p > 16) {
                return Err(
                    src.invalid(&format!("model.{name}.posenc"), "degrees above 16 overflow f32 frequencies")
                );
            }
        }
        if m.grid_resolution.is_some_and(|r| !(2..=4096).contains(&r)) {
            return Err(src.invalid("model.grid_resolution", "must be between 2 and 4096"));
        }
        finite("model.sigma_init", m.sigma_init, src)?;
        if !(m.encoding_scale.is_finite() && m.encoding_scale > 0.0) {
            return Err(src.invalid("model.encoding_scale", "must be a positive number"));
        }
        Ok(())
    }
}

impl TrainingConfig {
    fn validate(&self, src: &ConfigSource) -> Result<(), ConfigError> {
        let t = self;
        positive("training.batch_3d", t.batch_3d, src)?;
        positive("training.batch_uv", t.batch_uv, src)?;
        if let Some(k) = t.batch_distortion {
            positive("training.batch_distortion", k, src)?;
            if k > t.batch_3d {
                return Err(src.invalid(
                    "training.batch_distortion",
                    format!("{k} is more than the {} samples of training.batch_3d", t.batch_3d),
                ));
            }
        }
        if !(0.0..1.0).contains(&t.chart_support) {
            return Err(src.invalid("training.chart_support", "must be at least 0 and below 1"));
        }
        if t.steps == 0 {
            return Err(src.invalid("training.steps", "must be at least 1"));
        }
        if !(t.epsilon.is_finite() && t.epsilon > 0.0) {
            return Err(src.invalid("training.epsilon", "must be a positive number"));
        }
        if t.time_budget_minutes.is_some_and(|b| !(b.is_finite() && b > 0.0)) {
            return Err(src.invalid("training.time_budget_minutes", "must be a positive number of minutes"));
        }
        if t.stop_when_settled.is_some_and(|s| !(s.is_finite() && (0.0..1.0).contains(&s))) {
            return Err(src.invalid("training.stop_when_settled", "must be a share of points in [0, 1)"));
        }
        if t.checkpoint_every == 0 {
            return Err(src.invalid("training.checkpoint_every", "must be at least 1"));
        }
        Ok(())
    }
}

impl OptimizerConfig {
    fn validate(&self, src: &ConfigSource) -> Result<(), ConfigError> {
        let o = self;
        for (key, v) in [
            ("optimizer.lr_mlp", o.lr_mlp),
            ("optimizer.lr_sigma", o.lr_sigma),
            ("optimizer.lr_grid", o.lr_grid),
        ] {
            non_negative(key, v, "must be a non-negative number", src)?;
        }
        for (key, v) in [("optimizer.beta1", o.beta1), ("optimizer.beta2", o.beta2)] {
            if !(0.0..1.0).contains(&v) {
                return Err(src.invalid(key, "must be in [0, 1)"));
            }
        }
        if !(o.eps.is_finite() && o.eps > 0.0) {
            return Err(src.invalid("optimizer.eps", "must be a positive number"));
        }
        if !(0.0..=1.0).contains(&o.final_lr_factor) {
            return Err(src.invalid("optimizer.final_lr_factor", "must be in [0, 1]"));
        }
        Ok(())
    }
}

impl OutputConfig {
    fn validate(&self, src: &ConfigSource) -> Result<(), ConfigError> {
        let out = self;
        if !(16..=16384).contains(&out.atlas_resolution) {
            return Err(src.invalid("output.atlas_resolution", "must be between 16 and 16384 texels"));
        }
        non_negative(
            "output.round_trip_tolerance",
            out.round_trip_tolerance,
            "must be 0 (off) or a positive fraction",
            src,
        )?;
        if out.injective_split_energy.is_nan() || out.injective_split_energy <= 0.0 {
            return Err(src.invalid(
                "output.injective_split_energy",
                "must be a positive energy per unit area (4 is an isometry) or inf (never split)",
            ));
        }
        for (key, weight) in [
            ("output.injective_conformal", out.injective_conformal),
            ("output.injective_orthogonal", out.injective_orthogonal),
            ("output.injective_equiareal", out.injective_equiareal),
        ] {
            non_negative(key, weight, "must be 0 (off) or a positive weight", src)?;
        }
        non_negative(
            "output.neck_seam_cost",
            out.neck_seam_cost,
            "must be 0 (a cut need only gain packing) or a positive cost per unit of seam",
            src,
        )?;
        if out.gutter.saturating_mul(4) >= out.atlas_resolution {
            return Err(
                src.invalid("output.gutter", "leaves no room for the charts at this atlas resolution")
            );
        }
        if out.eval_views == 0 || !(16..=8192).contains(&out.eval_resolution) {
            return Err(
                src.invalid("output.eval_views", "needs at least one view of 16 to 8192 pixels a side")
            );
        }
        if !(16..=8192).contains(&out.render_resolution) {
            return Err(src.invalid("output.render_resolution", "must be between 16 and 8192 pixels"));
        }
        if !(1..=nuvo_atlas::texture::MAX_SUPERSAMPLING).contains(&out.texture_supersampling) {
            return Err(src.invalid(
                "output.texture_supersampling",
                format!(
                    "must be between 1 and {} points per texel side",
                    nuvo_atlas::texture::MAX_SUPERSAMPLING
                ),
            ));
        }
        Ok(())
    }
}

/// `Err` naming `key` unless `v ≥ 1`.
fn positive(key: &str, v: usize, src: &ConfigSource) -> Result<(), ConfigError> {
    if v == 0 { Err(src.invalid(key, "must be at least 1")) } else { Ok(()) }
}

/// `Err` naming `key` with `message` unless `v` is finite and `≥ 0`.
fn non_negative(key: &str, v: impl Into<f64>, message: &str, src: &ConfigSource) -> Result<(), ConfigError> {
    let v = v.into();
    if v.is_finite() && v >= 0.0 { Ok(()) } else { Err(src.invalid(key, message)) }
}

fn finite(key: &str, v: f32, src: &ConfigSource) -> Result<(), ConfigError> {
    if v.is_finite() { Ok(()) } else { Err(src.invalid(key, "must be a finite number")) }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MINIMAL: &str = "[geometry]\nsource = \"mesh\"\npath = \"bunny.obj\"\n";

    #[test]
    fn minimal_config_gets_paper_defaults() {
        let c = from_str("c.toml", MINIMAL).unwrap().config;
        assert_eq!(c.model.charts, 1);
        assert_eq!((c.model.depth, c.model.width), (8, 256));
        assert_eq!(c.model.texture_shape(), (8, 256, 4));
        assert_eq!(c.model.chart_shape(), (8, 256, 1));
        assert_eq!(c.optimizer.lr_sigma, 0.1);
        assert_eq!(c.geometry.options["path"].as_str(), Some("bunny.obj"));
        assert!(c.losses.is_none());
    }

    #[test]
    fn grid_resolution_follows_the_texture_budget() {
        let mut m = ModelConfig { charts: 1, ..ModelConfig::default() };
        assert_eq!(m.grid_resolution(), 362);
        m.charts = 8;
        assert_eq!(m.grid_resolution(), 128);
    }

    #[test]
    fn typo_names_key_line_and_valid_keys() {
        let text = format!("{MINIMAL}\n[model]\ncharts = 2\ndepht = 3\n");
        let e = from_str("c.toml", &text).unwrap_err().to_string();
        assert!(e.contains("line 7"), "{e}");
        assert!(e.contains("model.depht"), "{e}");
        assert!(e.contains("`depth`") && e.contains("`width`"), "{e}");
    }

    #[test]
    fn wrong_type_and_negative_size_name_the_key() {
        let e =
            from_str("c.toml", &format!("{MINIMAL}[training]\nsteps = \"many\"\n")).unwrap_err().to_string();
        assert!(e.contains("training.steps") && e.contains("line 5"), "{e}");
        let e = from_str("c.toml", &format!("{MINIMAL}[training]\nbatch_3d = -5\n")).unwrap_err().to_string();
        assert!(e.contains("training.batch_3d"), "{e}");
        let e = from_str("c.toml", &format!("{MINIMAL}[training]\nbatch_3d = 0\n")).unwrap_err().to_string();
        assert!(e.contains("training.batch_3d") && e.contains("at least 1"), "{e}");
        let e = from_str("c.toml", &format!("{MINIMAL}[training]\nbatch_3d = 64\nbatch_distortion = 65\n"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("training.batch_distortion") && e.contains("training.batch_3d"), "{e}");
        let e = from_str("c.toml", &format!("{MINIMAL}[training]\nbatch_distortion = 0\n"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("training.batch_distortion") && e.contains("at least 1"), "{e}");
        for bad in ["1.0", "-1e-4", "nan"] {
            let e = from_str("c.toml", &format!("{MINIMAL}[training]\nchart_support = {bad}\n"))
                .unwrap_err()
                .to_string();
            assert!(e.contains("training.chart_support") && e.contains("below 1"), "{bad}: {e}");
        }
        assert!(from_str("c.toml", &format!("{MINIMAL}[training]\nchart_support = 1e-4\n")).is_ok());
        for bad in ["1.0", "-0.01", "nan"] {
            let e = from_str("c.toml", &format!("{MINIMAL}[training]\nstop_when_settled = {bad}\n"))
                .unwrap_err()
                .to_string();
            assert!(e.contains("training.stop_when_settled") && e.contains("[0, 1)"), "{bad}: {e}");
        }
        let c = from_str("c.toml", &format!("{MINIMAL}[training]\nstop_when_settled = 0.015\n")).unwrap();
        assert_eq!(c.config.training.stop_when_settled, Some(0.015));
        assert_eq!(from_str("c.toml", MINIMAL).unwrap().config.training.matmul, MatmulPrecision::F32);
        let c = from_str("c.toml", &format!("{MINIMAL}[training]\nmatmul = \"bf16\"\n")).unwrap();
        assert_eq!(c.config.training.matmul, MatmulPrecision::Bf16);
        let e =
            from_str("c.toml", &format!("{MINIMAL}[training]\nmatmul = \"f16\"\n")).unwrap_err().to_string();
        assert!(e.contains("training.matmul") && e.contains("bf16"), "{e}");
    }

    #[test]
    fn packing_and_refinement_default_to_the_papers_bake_and_name_a_typo() {
        let c = from_str("c.toml", MINIMAL).unwrap().config;
        assert_eq!((c.output.packing, c.output.refine, c.output.injective), (Packing::Squares, false, false));
        let c = from_str("c.toml", &format!("{MINIMAL}[output]\npacking = \"islands\"\nrefine = true\n"))
            .unwrap();
        assert_eq!((c.config.output.packing, c.config.output.refine), (Packing::Islands, true));
        let e = from_str("c.toml", &format!("{MINIMAL}[output]\npacking = \"island\"\n"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("packing") && e.contains("islands"), "{e}");
    }

    #[test]
    fn injective_split_energy_defaults_to_the_atlas_threshold_takes_inf_and_is_checked() {
        let out = |extra: &str| from_str("c.toml", &format!("{MINIMAL}[output]\n{extra}"));
        assert_eq!(out("").unwrap().config.output.injective_split_energy, 4.5);
        let c = out("injective_split_energy = inf\n").unwrap().config;
        assert_eq!(c.output.injective_split_energy, f64::INFINITY);
        // It survives the resolved config that `nuvo unwrap` writes and `nuvo train` reads.
        let text = toml::to_string(&c).unwrap();
        assert_eq!(
            from_str("again.toml", &text).unwrap().config.output.injective_split_energy,
            f64::INFINITY
        );
        for bad in ["0.0", "-1.0", "nan"] {
            let e = out(&format!("injective_split_energy = {bad}\n")).unwrap_err();
            assert!(e.to_string().contains("output.injective_split_energy"), "{bad}: {e}");
        }
    }

    #[test]
    fn slim_term_weights_are_off_by_default_and_checked() {
        let out = |extra: &str| from_str("c.toml", &format!("{MINIMAL}[output]\n{extra}"));
        let weights =
            |o: &OutputConfig| [o.injective_conformal, o.injective_orthogonal, o.injective_equiareal];
        assert_eq!(weights(&out("").unwrap().config.output), [0.0; 3]);
        for (k, key) in
            ["injective_conformal", "injective_orthogonal", "injective_equiareal"].iter().enumerate()
        {
            let mut want = [0.0; 3];
            want[k] = 2.0;
            assert_eq!(weights(&out(&format!("{key} = 2.0\n")).unwrap().config.output), want, "{key}");
            for bad in ["-1.0", "nan", "inf"] {
                let e = out(&format!("{key} = {bad}\n")).unwrap_err();
                assert!(e.to_string().contains(&format!("output.{key}")), "{key} = {bad}: {e}");
            }
        }
    }

    #[test]
    fn the_neck_seam_cost_defaults_to_the_atlas_crates_and_is_checked() {
        let out = |extra: &str| from_str("c.toml", &format!("{MINIMAL}[output]\n{extra}"));
        assert_eq!(out("").unwrap().config.output.neck_seam_cost, nuvo_atlas::necks::SEAM_COST);
        assert_eq!(out("neck_seam_cost = 0.5\n").unwrap().config.output.neck_seam_cost, 0.5);
        for bad in ["-1.0", "nan", "inf"] {
            let e = out(&format!("neck_seam_cost = {bad}\n")).unwrap_err();
            assert!(e.to_string().contains("output.neck_seam_cost"), "{bad}: {e}");
        }
    }

    #[test]
    fn round_trip_tolerance_is_off_by_default_and_checked() {
        assert_eq!(from_str("c.toml", MINIMAL).unwrap().config.output.round_trip_tolerance, 0.0);
        let e = from_str("c.toml", &format!("{MINIMAL}[output]\nround_trip_tolerance = -0.1\n")).unwrap_err();
        assert!(e.to_string().contains("output.round_trip_tolerance"), "{e}");
        let sets = ["output.round_trip_tolerance=0.1".to_owned()];
        let c = from_str_with_overrides("c.toml", MINIMAL, &sets).unwrap();
        assert_eq!(c.config.output.round_trip_tolerance, 0.1);
        assert!(c.source.is_overridden("output.round_trip_tolerance"));
    }

    #[test]
    fn cut_necks_is_off_by_default_and_a_boolean() {
        assert!(!from_str("c.toml", MINIMAL).unwrap().config.output.cut_necks);
        assert!(!from_str("c.toml", MINIMAL).unwrap().config.output.cut_cones);
        let cones = from_str("c.toml", &format!("{MINIMAL}[output]\ncut_cones = true\n")).unwrap();
        assert!(cones.config.output.cut_cones);
        let on = from_str("c.toml", &format!("{MINIMAL}[output]\ncut_necks = true\n")).unwrap();
        assert!(on.config.output.cut_necks);
        let e = from_str("c.toml", &format!("{MINIMAL}[output]\ncut_necks = 1\n")).unwrap_err().to_string();
        assert!(e.contains("cut_necks"), "{e}");
    }

    #[test]
    fn absorb_enclaves_is_off_by_default_and_a_boolean() {
        assert!(!from_str("c.toml", MINIMAL).unwrap().config.output.absorb_enclaves);
        let on = from_str("c.toml", &format!("{MINIMAL}[output]\nabsorb_enclaves = true\n")).unwrap();
        assert!(on.config.output.absorb_enclaves);
        let e = from_str("c.toml", &format!("{MINIMAL}[output]\nabsorb_enclaves = \"yes\"\n"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("absorb_enclaves"), "{e}");
    }

    #[test]
    fn untangle_is_off_by_default_and_a_boolean() {
        assert!(!from_str("c.toml", MINIMAL).unwrap().config.output.untangle);
        assert!(
            from_str("c.toml", &format!("{MINIMAL}[output]\nuntangle = true\n"))
                .unwrap()
                .config
                .output
                .untangle
        );
        let e = from_str("c.toml", &format!("{MINIMAL}[output]\nuntangle = 1\n")).unwrap_err().to_string();
        assert!(e.contains("untangle"), "{e}");
    }

    #[test]
    fn syntax_errors_point_at_the_line() {
        let e = from_str("c.toml", "[geometry\nsource = 1").unwrap_err().to_string();
        assert!(e.contains("line 1") && e.contains("not valid TOML"), "{e}");
    }

    #[test]
    fn overrides_set_values_and_are_reported_as_such() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("c.toml");
        std::fs::write(&p, MINIMAL).unwrap();
        let sets = [
            "training.steps=200".to_owned(),
            "model.texture.depth=3".to_owned(),
            "output.dir=runs/x".to_owned(),
        ];
        let c = load(&p, &sets).unwrap();
        assert_eq!(c.config.training.steps, 200);
        assert_eq!(c.config.model.texture_shape().0, 3);
        assert_eq!(c.config.output.dir, PathBuf::from("runs/x"));
        let e = load(&p, &["training.steps=-1".to_owned()]).unwrap_err().to_string();
        assert!(e.contains("set with --set"), "{e}");
        let e = load(&p, &["training.stesp=5".to_owned()]).unwrap_err().to_string();
        assert!(e.contains("stesp") && e.contains("`steps`"), "{e}");
        let e = load(&p, &["noequals".to_owned()]).unwrap_err().to_string();
        assert!(e.contains("KEY=VALUE"), "{e}");
    }

    #[test]
    fn override_paths_resolve_against_the_working_directory() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("c.toml");
        std::fs::write(&p, MINIMAL).unwrap();
        let c = load(&p, &["geometry.path=other.obj".to_owned()]).unwrap();
        let got = PathBuf::from(c.config.geometry.options["path"].as_str().unwrap());
        assert_eq!(got, std::env::current_dir().unwrap().join("other.obj"));
        // Paths written in the file resolve against the file's folder, and become absolute.
        let c = load(&p, &[]).unwrap();
        let got = PathBuf::from(c.config.geometry.options["path"].as_str().unwrap());
        assert_eq!(got, dir.path().join("bunny.obj"));
    }

    #[test]
    fn missing_file_and_directory_are_clear_errors() {
        let e = load(Path::new("/nonexistent/c.toml"), &[]).unwrap_err().to_string();
        assert!(e.contains("/nonexistent/c.toml"), "{e}");
        let dir = tempfile::tempdir().unwrap();
        let e = load(dir.path(), &[]).unwrap_err().to_string();
        assert!(e.contains("directory"), "{e}");
    }

    #[test]
    fn resolved_config_round_trips_through_toml() {
        let c =
            from_str("c.toml", &format!("{MINIMAL}[losses.stretch]\nweight = 0.2\narea = \"jacobian\"\n"))
                .unwrap()
                .config;
        let text = toml::to_string(&c).unwrap();
        let back = from_str("r.toml", &text).unwrap().config;
        assert_eq!(c, back);
    }
}

//! The trainer: one optimisation step at a time, deterministic for a config and seed.
//!
//! A step draws its batch from `(seed, step)`, records every enabled loss on the tape through one
//! shared [`StepContext`], sums the weighted terms, runs backward once and takes an Adam step. A term
//! or gradient that is NaN or infinite skips the step (parameters untouched) and the outcome names the
//! term responsible; the run loop ([`crate::run()`]) rolls back after too many skipped steps.

use std::collections::BTreeMap;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

use nuvo_autodiff::optim::{Adam, AdamConfig, CosineSchedule};
use nuvo_autodiff::{ParamStore, Shape, Tape, Var};
use nuvo_geometry::{BuildContext, GeometryError, GeometrySource, SourceRegistry};
use nuvo_losses::{Loss, LossError, LossRegistry, Networks, Reads, StepContext};

use crate::batch::{BatchSizes, ShortBatch, StepBatch};
use crate::checkpoint::{AdamState, Checkpoint, CheckpointError};
use crate::config::{ConfigError, ExperimentConfig, LoadedConfig};
use crate::model::{NuvoModel, groups};
use crate::seeds::{Stream, derive};
use crate::settling::{Movement, Snapshot, movement};
use crate::trained::{CheckpointMismatch, TrainedAtlas, checkpoint_params, fields_at};
use crate::warm_start::ProjectionPrior;

/// Anything that stops training.
#[derive(Debug, thiserror::Error)]
pub enum TrainError {
    #[error(transparent)]
    Config(#[from] ConfigError),
    #[error(transparent)]
    Geometry(#[from] GeometryError),
    /// The config's geometry could not be loaded; `config` locates the key that named it.
    #[error("{config}: {source}")]
    Source {
        config: String,
        #[source]
        source: GeometryError,
    },
    #[error(transparent)]
    Loss(#[from] LossError),
    #[error(transparent)]
    Checkpoint(#[from] CheckpointError),
    #[error(transparent)]
    Batch(#[from] ShortBatch),
    #[error("cannot write {path}: {source}")]
    Io {
        path: std::path::PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("cannot read {path}: {source}")]
    Read {
        path: std::path::PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{0}")]
    Resume(String),
    #[error(transparent)]
    Mismatch(#[from] CheckpointMismatch),
    #[error("training diverged: {0}")]
    Diverged(String),
}

/// One weighted term of the objective: a `[losses.NAME]` loss, or the `[warm_start]` prior.
pub struct Term {
    /// The `[losses.NAME]` key ([`WARM_START_TERM`] for the prior).
    pub name: String,
    /// Its weight (> 0 for `[losses]` terms, whose zero weight leaves them out; the prior is built
    /// with whatever `warm_start.weight` says).
    pub weight: f32,
    /// How the weight changes over the run.
    pub schedule: WeightSchedule,
    /// Whether chart support (`training.chart_support`) waits while this term weighs in: true for
    /// the warm-start prior, which reads every chart on every sample (so pruning the other terms to
    /// the charts' supports would only add passes) while its chart probabilities are still soft.
    pub suspends_chart_support: bool,
    loss: Box<dyn Loss>,
}

/// How a term's weight `w` changes over the run.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum WeightSchedule {
    /// `w` throughout.
    Constant,
    /// `w · min(1, (step + 1) / steps)`: up from `w / steps` to `w` (`[losses.NAME] warmup_steps`).
    RampUp { steps: u64 },
    /// `w · (1 − step / steps)`, 0 from `steps` on: down to nothing, after which the term has
    /// ended and is not recorded (the `[warm_start]` prior).
    FadeOut { steps: u64 },
}

impl Term {
    /// The weight at 0-based `step`.
    pub fn weight_at(&self, step: u64) -> f32 {
        match self.schedule {
            WeightSchedule::RampUp { steps } if step < steps => {
                self.weight * (step + 1) as f32 / steps as f32
            }
            WeightSchedule::Constant | WeightSchedule::RampUp { .. } => self.weight,
            WeightSchedule::FadeOut { steps } if step < steps => {
                self.weight * (1.0 - step as f32 / steps as f32)
            }
            WeightSchedule::FadeOut { .. } => 0.0,
        }
    }

    /// Whether the term is a prior still fading out at `step` (it holds the charts in place
    /// until then).
    pub fn is_fading(&self, step: u64) -> bool {
        matches!(self.schedule, WeightSchedule::FadeOut { steps } if step < steps)
    }
}

/// What one step did.
#[derive(Clone, Debug, PartialEq)]
pub struct StepOutcome {
    /// The step's index (0-based).
    pub step: u64,
    /// The weighted sum of the terms.
    pub total: f32,
    /// Each term's unweighted value, in config order.
    pub terms: Vec<(String, f32)>,
    /// The schedule's learning-rate factor used (including any rollback scale).
    pub lr_factor: f32,
    /// `σ` after the step.
    pub sigma: f32,
    /// Why the step was skipped, if it was.
    pub skipped: Option<String>,
    /// How much the atlas moved since the settling probe's last look, when it looked after this
    /// step (`training.stop_when_settled`).
    pub moved: Option<Movement>,
}

/// The model, its parameters and optimiser, the scene, and the losses.
pub struct Trainer {
    config: ExperimentConfig,
    source: Box<dyn GeometrySource>,
    model: NuvoModel,
    tape: Tape,
    adam: Adam,
    schedule: CosineSchedule,
    terms: Vec<Term>,
    step: u64,
    lr_scale: f32,
    batch: StepBatch,
    /// The settling probe's points (drawn on first use).
    probe_points: Vec<[f32; 3]>,
    /// The probe's last look (`training.stop_when_settled`).
    last_look: Option<Snapshot>,
    /// Looks in a row at which the atlas had settled.
    settled_looks: u32,
    /// Draw full batches even while `warm_start.batch_share` applies (`Trainer::time_full_batches`).
    full_batches: bool,
}

/// Steps between two looks of the settling probe; `checkpoint_every` being a multiple of it (the
/// default 250 is) lets a resumed run stop at the same step as an uninterrupted one.
pub const LOOK_EVERY: u64 = 25;
/// Settled looks in a row that stop a run (one alone can be a lull).
const SETTLED_LOOKS: u32 = 2;
/// A run of one chart has settled when, between two looks, its map's shape changed by at most
/// this ([`Movement::shape_change`]: the root of the share of the UV spread that no similarity of
/// the last look's UVs explains). Its map keeps improving long after the charts of a run of
/// several would have held still: stopped at the point they settle, a relief's single chart
/// packed at 0.40 instead of 0.60 and woody's angular score fell from 1.000 to 0.983. The shape
/// change falls from ~0.3 in the warm start to ~0.005 a few hundred steps after it and then
/// creeps down; at 0.003 woody stopped at step ~950 of 1950 and the alligator at ~600 of 1900,
/// their baked Editability 0.9900 and 0.9904 against 0.9901 and 0.9909 trained to the end
/// (BENCHMARKS.md, "One chart settles by its map's shape"). Measured again at 400 planned steps
/// (stop 65): the shape change follows the learning rate's decay and reaches 0.003 only near
/// the schedule's end; the alligator's and woody's atlases score the same after 20 steps as
/// after 400 (the bake re-embeds their single island), but other meshes forced to one chart do
/// not, so the rule stays (BENCHMARKS.md, "An island's orientations stop each other's search").
pub const ONE_CHART_SHAPE_SETTLED: f32 = 0.003;

/// The name the warm-start prior's value is logged under.
pub const WARM_START_TERM: &str = "warm_start";

impl Trainer {
    /// Builds everything a config describes: the geometry source and losses come from the
    /// registries, so applications can register their own before calling this.
    pub fn new(
        loaded: &LoadedConfig,
        sources: &SourceRegistry,
        losses: &LossRegistry,
    ) -> Result<Self, TrainError> {
        let source = build_source(loaded, sources)?;
        Self::with_source(loaded, source, losses)
    }

    /// [`Trainer::new`] with the geometry source already built (from `loaded`'s `[geometry]` table):
    /// `nuvo unwrap` measures a source before it trains on it and need not load the input twice.
    pub fn with_source(
        loaded: &LoadedConfig,
        source: Box<dyn GeometrySource>,
        losses: &LossRegistry,
    ) -> Result<Self, TrainError> {
        let config = loaded.config.clone();
        let mut terms = build_terms(&config, loaded, losses)?;
        if let Some(term) = warm_start_term(&config, &*source)? {
            // Last, where the prior has always been added to the sum.
            terms.push(term);
        }
        let mut params = ParamStore::new();
        let model = NuvoModel::new(&config.model, &mut params, derive(config.seed, 0, Stream::Init));
        let o = &config.optimizer;
        let lrs = BTreeMap::from([
            (groups::MLP.to_owned(), o.lr_mlp),
            (groups::SIGMA.to_owned(), o.lr_sigma),
            (groups::GRID.to_owned(), o.lr_grid),
        ]);
        let adam = Adam::new(&params, AdamConfig { beta1: o.beta1, beta2: o.beta2, eps: o.eps }, &lrs)
            .expect("the model only uses the three configured groups");
        let schedule = CosineSchedule {
            total_steps: config.training.steps,
            warmup_steps: o.warmup_steps,
            final_factor: o.final_lr_factor,
        };
        let mut tape = Tape::new(params);
        tape.set_matmul_precision(config.training.matmul);
        Ok(Trainer {
            config,
            source,
            model,
            tape,
            adam,
            schedule,
            terms,
            step: 0,
            lr_scale: 1.0,
            batch: StepBatch::default(),
            probe_points: Vec::new(),
            last_look: None,
            settled_looks: 0,
            full_batches: false,
        })
    }

    /// The arithmetic the networks' products train in on this machine: `training.matmul`, or f32
    /// where the CPU cannot run bf16 ([`nuvo_autodiff::MatmulPrecision::effective`]).
    pub fn matmul_precision(&self) -> nuvo_autodiff::MatmulPrecision {
        self.tape.matmul_precision()
    }

    /// The config being trained.
    pub fn config(&self) -> &ExperimentConfig {
        &self.config
    }

    /// The scene.
    pub fn source(&self) -> &dyn GeometrySource {
        &*self.source
    }

    /// The networks' handles.
    pub fn model(&self) -> &NuvoModel {
        &self.model
    }

    /// The parameters.
    pub fn params(&self) -> &ParamStore {
        self.tape.params()
    }

    /// The enabled terms, in the order they are summed (the `[warm_start]` prior last).
    pub fn terms(&self) -> &[Term] {
        &self.terms
    }

    /// Steps completed so far.
    pub fn step_index(&self) -> u64 {
        self.step
    }

    /// Steps the schedule spans.
    pub fn total_steps(&self) -> u64 {
        self.config.training.steps
    }

    /// The geometry source, taking the trainer apart: `nuvo unwrap` times a few steps with one
    /// trainer, then builds the run's trainer on the same source with the step count that fits.
    pub fn into_source(self) -> Box<dyn GeometrySource> {
        self.source
    }

    /// The learning-rate multiplier left by NaN rollbacks (1 normally).
    pub fn lr_scale(&self) -> f32 {
        self.lr_scale
    }

    /// Halves every learning rate from now on (after a rollback).
    pub fn halve_learning_rates(&mut self) {
        self.lr_scale *= 0.5;
    }

    /// The batch the last step drew.
    pub fn batch(&self) -> &StepBatch {
        &self.batch
    }

    /// Whether steps draw full batches even while `warm_start.batch_share` would shrink them:
    /// `nuvo unwrap` times its first steps this way, so its step plan rests on the cost of a
    /// full step (what `MEAN_STEP_COST` was measured against) and not on a warm-start step's.
    pub fn time_full_batches(&mut self, on: bool) {
        self.full_batches = on;
    }

    /// Runs one optimisation step.
    ///
    /// The step runs on a rayon worker thread: the engine's parallel kernels then fork and join
    /// inside the pool instead of each handing its work over from the calling thread and sleeping
    /// until it is done (a futex round trip per kernel, measured at several percent of a small step).
    /// While it runs, the pool's other threads stay awake on its jobs (`keep_busy`).
    pub fn step(&mut self) -> Result<StepOutcome, TrainError> {
        let done = AtomicBool::new(false);
        rayon::scope(|scope| {
            let _stepping = Stepping::enter();
            if STEPPING.load(Ordering::SeqCst) == 1 {
                let (done, stepper) = (&done, rayon::current_thread_index());
                for _ in 1..rayon::current_num_threads() {
                    scope.spawn(move |_| keep_busy(done, stepper));
                }
            }
            let outcome = self.step_on_worker();
            done.store(true, Ordering::Release);
            outcome
        })
    }

    fn step_on_worker(&mut self) -> Result<StepOutcome, TrainError> {
        let mut sizes = BatchSizes::of(&self.config.training);
        if let Some(ws) = &self.config.warm_start
            && !self.full_batches
            && self.chart_support_suspended(self.step)
        {
            sizes = sizes.share(ws.batch_share);
        }
        self.batch = StepBatch::draw(&*self.source, sizes, self.config.seed, self.step)?;
        let lr_factor = self.schedule.factor(self.step) * self.lr_scale;
        let mut outcome = StepOutcome {
            step: self.step,
            total: f32::NAN,
            terms: Vec::with_capacity(self.terms.len()),
            lr_factor,
            sigma: f32::NAN,
            skipped: None,
            moved: None,
        };
        let total = self.record(None, &mut outcome.terms)?;
        outcome.total = self.tape.scalar(total);
        if let Some((name, v)) = outcome.terms.iter().find(|(_, v)| !v.is_finite()) {
            outcome.skipped = Some(format!("loss `{name}` is {v}"));
        } else {
            self.tape.backward(total);
            if grads_finite(self.tape.params()) {
                self.adam.step(self.tape.params_mut(), lr_factor);
            } else {
                outcome.skipped =
                    Some(format!("the gradient of {} is not finite", self.diagnose_gradient()?));
            }
        }
        outcome.sigma = self.tape.params().value(self.model.sigma_param()).data()[0];
        self.step += 1;
        outcome.moved = self.look_if_due();
        Ok(outcome)
    }

    /// With `training.stop_when_settled`, every [`LOOK_EVERY`] steps: what the networks say at the
    /// probe points, how much that moved since the last look, and whether it counts as settled
    /// (only once the warm-start prior has faded: until then it holds the charts in place).
    fn look_if_due(&mut self) -> Option<Movement> {
        let threshold = self.settling_threshold()?;
        if !self.step.is_multiple_of(LOOK_EVERY) {
            return None;
        }
        let now = self.probe();
        let moved = self.last_look.as_ref().map(|before| movement(before, &now));
        self.last_look = Some(now);
        let prior_faded = !self.terms.iter().any(|t| t.is_fading(self.step));
        let holds = |m: &Movement| match self.model.charts() {
            1 => m.shape_change <= ONE_CHART_SHAPE_SETTLED,
            _ => m.charts_changed <= threshold,
        };
        match moved {
            Some(m) if prior_faded && holds(&m) => self.settled_looks += 1,
            _ => self.settled_looks = 0,
        }
        moved
    }

    /// `training.stop_when_settled`, when it applies. A run of several charts has settled when
    /// at most this share of the probe points changed chart between looks; a run of one chart
    /// has no assignment to settle, and has settled when its map's shape holds still
    /// ([`ONE_CHART_SHAPE_SETTLED`]).
    pub fn settling_threshold(&self) -> Option<f32> {
        self.config.training.stop_when_settled
    }

    /// Whether the atlas has settled (`training.stop_when_settled`): the run can stop.
    pub fn settled(&self) -> bool {
        self.settled_looks >= SETTLED_LOOKS
    }

    /// Records the weighted sum of the terms (or of term `only`) on a fresh tape; pushes each
    /// term's unweighted value into `values`.
    fn record(&mut self, only: Option<usize>, values: &mut Vec<(String, f32)>) -> Result<Var, TrainError> {
        self.tape.reset();
        self.tape.params_mut().zero_grads();
        let training = &self.config.training;
        let data = self.batch.data(training.epsilon, self.chart_support_at(self.step));
        let step = self.step;
        let evaluated = |k: usize, term: &Term| only.is_none_or(|o| o == k) && term.weight_at(step) > 0.0;
        let reads = (self.terms.iter().enumerate())
            .filter(|&(k, term)| evaluated(k, term))
            .fold(Reads::NOTHING, |r, (_, term)| r.union(term.loss.reads()));
        let mut ctx = StepContext::new(&mut self.tape, &self.model, data).reading(reads);
        let mut total: Option<Var> = None;
        for (k, term) in self.terms.iter().enumerate() {
            if !evaluated(k, term) {
                continue;
            }
            let weight = term.weight_at(self.step);
            let v = term.loss.evaluate(&mut ctx)?;
            values.push((term.name.clone(), ctx.tape.scalar(v)));
            total = Some(add_weighted(ctx.tape, total, v, weight));
        }
        Ok(total.unwrap_or_else(|| ctx.tape.constant(Shape::SCALAR, 0.0)))
    }

    /// `training.chart_support` at `step`: 0 while a term flagged
    /// [`Term::suspends_chart_support`] (the warm-start prior) weighs in.
    fn chart_support_at(&self, step: u64) -> f32 {
        if self.chart_support_suspended(step) { 0.0 } else { self.config.training.chart_support }
    }

    /// Whether a term flagged [`Term::suspends_chart_support`] (the warm-start prior) weighs in
    /// at `step`.
    fn chart_support_suspended(&self, step: u64) -> bool {
        self.terms.iter().any(|t| t.suspends_chart_support && t.weight_at(step) > 0.0)
    }

    /// Which term's gradient is not finite: re-records the step one term at a time. Only runs after a
    /// failure, so its cost does not matter.
    fn diagnose_gradient(&mut self) -> Result<String, TrainError> {
        let mut culprit = "the total loss".to_owned();
        for k in 0..self.terms.len() {
            let mut ignored = Vec::new();
            let v = self.record(Some(k), &mut ignored)?;
            self.tape.backward(v);
            if !grads_finite(self.tape.params()) {
                culprit = format!("loss `{}`", self.terms[k].name);
                break;
            }
        }
        self.tape.params_mut().zero_grads();
        Ok(culprit)
    }

    /// The atlas as trained so far: the model and a copy of its parameters, in the source's frame.
    pub fn atlas(&self) -> TrainedAtlas {
        let params = self.tape.params().clone();
        TrainedAtlas::new(self.model.clone(), params, self.source.to_canonical(), self.step, self.config.seed)
    }

    /// What the networks say now at the settling probe's points (`crate::settling`): a fixed
    /// sample of the surface, drawn on the first call from the run's seed.
    pub fn probe(&mut self) -> Snapshot {
        /// Enough points that a chart of 1% of the surface holds ~40 of them.
        const PROBE_POINTS: usize = 4096;
        if self.probe_points.is_empty() {
            let seed = derive(self.config.seed, 0, Stream::Probe);
            self.probe_points = self.source.sample(PROBE_POINTS, seed).positions;
        }
        let fields = fields_at(&self.model, &mut self.tape, &self.probe_points, false);
        Snapshot::from_fields(&fields.probs, &fields.uvs, self.model.charts())
    }

    /// A checkpoint of the current state. Its config describes the experiment, not where or how
    /// long it ran: `output.dir` and the time budget are left at their defaults, so the same
    /// experiment gives the same checkpoint bytes wherever it is written.
    pub fn checkpoint(&self) -> Result<Checkpoint, TrainError> {
        let p = self.tape.params();
        let (m, v) = self.adam.moments();
        let mut config = self.config.clone();
        config.output.dir = crate::config::OutputConfig::default().dir;
        config.training.time_budget_minutes = None;
        Ok(Checkpoint {
            step: self.step,
            lr_scale: self.lr_scale,
            config_toml: config.to_toml()?,
            to_canonical: self.source.to_canonical(),
            params: p.ids().map(|id| (p.info(id).name.clone(), p.value(id).clone())).collect(),
            adam: AdamState { steps: self.adam.steps(), m: m.to_vec(), v: v.to_vec() },
            settled_looks: self.settled_looks,
        })
    }

    /// Continues from a checkpoint of this same experiment. Fails, changing nothing, if the
    /// checkpoint's parameters do not match this model's names and shapes.
    pub fn restore(&mut self, ckpt: &Checkpoint) -> Result<(), TrainError> {
        let ids = checkpoint_params(self.tape.params(), ckpt)?;
        let count = self.tape.params().len();
        let (mut m, mut v) = (vec![Vec::new(); count], vec![Vec::new(); count]);
        for (k, &id) in ids.iter().enumerate() {
            m[id.index()] = ckpt.adam.m[k].clone();
            v[id.index()] = ckpt.adam.v[k].clone();
        }
        self.adam.restore(ckpt.adam.steps, m, v).map_err(CheckpointMismatch)?;
        for (&id, (_, t)) in ids.iter().zip(&ckpt.params) {
            *self.tape.params_mut().value_mut(id) = t.clone();
        }
        self.step = ckpt.step;
        self.lr_scale = ckpt.lr_scale;
        // The look the run took at this step, taken again (the same parameters give the same
        // look); between looks, and at step 0 where a run has not looked yet, the next look has
        // nothing to compare with and cannot count.
        self.settled_looks = ckpt.settled_looks;
        let looked_here = self.step > 0 && self.step.is_multiple_of(LOOK_EVERY);
        self.last_look = (self.settling_threshold().is_some() && looked_here).then(|| self.probe());
        Ok(())
    }
}

/// The geometry source `loaded`'s `[geometry]` table names, built from `sources`, with errors that
/// locate the config key.
pub fn build_source(
    loaded: &LoadedConfig,
    sources: &SourceRegistry,
) -> Result<Box<dyn GeometrySource>, TrainError> {
    let config = &loaded.config;
    let src = &loaded.source;
    let ctx = BuildContext { base_dir: src.base_dir() };
    let built =
        sources.build(&config.geometry.source, &config.geometry.options, &ctx).map_err(|e| match e {
            GeometryError::Options { message, .. } => {
                TrainError::Config(src.serde_error("geometry", &message))
            }
            GeometryError::UnknownSource { .. } => {
                TrainError::Config(src.invalid("geometry.source", e.to_string()))
            }
            other => {
                let key =
                    if config.geometry.options.contains_key("path") { "geometry.path" } else { "geometry" };
                TrainError::Source { config: src.locate(key), source: other }
            }
        })?;
    Ok(built)
}

/// The `[warm_start]` prior as a term, when enabled: fitted to a sample of the scene drawn from
/// the run's own seed (so a resumed run fits the same one), its weight fading out.
fn warm_start_term(
    config: &ExperimentConfig,
    source: &dyn GeometrySource,
) -> Result<Option<Term>, TrainError> {
    let Some(cfg) = &config.warm_start else { return Ok(None) };
    let Some(prior) = ProjectionPrior::for_run(config, source)? else { return Ok(None) };
    Ok(Some(Term {
        name: WARM_START_TERM.to_owned(),
        weight: cfg.weight,
        schedule: WeightSchedule::FadeOut { steps: cfg.steps },
        suspends_chart_support: true,
        loss: Box::new(prior),
    }))
}

/// `total + weight · v` on the tape (`weight · v` when there is no total yet).
fn add_weighted(tape: &mut Tape, total: Option<Var>, v: Var, weight: f32) -> Var {
    let w = tape.scale(v, weight);
    match total {
        None => w,
        Some(t) => tape.add(t, w),
    }
}

fn grads_finite(p: &ParamStore) -> bool {
    p.ids().all(|id| p.grad(id).data().iter().all(|g| g.is_finite()))
}

/// The enabled terms, in config order (the paper's eight at their weights when `[losses]` is absent).
fn build_terms(
    config: &ExperimentConfig,
    loaded: &LoadedConfig,
    registry: &LossRegistry,
) -> Result<Vec<Term>, TrainError> {
    let src = &loaded.source;
    type Listed = (String, Option<f32>, Option<u64>, toml::Table);
    let listed: Vec<Listed> = match &config.losses {
        None => nuvo_losses::builtin::PAPER
            .iter()
            .map(|&n| (n.to_owned(), None, None, toml::Table::new()))
            .collect(),
        Some(map) => {
            map.iter().map(|(k, l)| (k.clone(), l.weight, l.warmup_steps, l.options.clone())).collect()
        }
    };
    let mut terms = Vec::new();
    for (name, weight, warmup_steps, mut options) in listed {
        let key = format!("losses.{name}");
        // `plugin = "path"`: a run-time loss plugin (nuvo-plugin-host); the path is relative to the
        // config file, or to the working directory when set with --set.
        let (loss, default_weight) = if let Some(plugin) = options.remove("plugin") {
            let at = format!("{key}.plugin");
            let path = plugin.as_str().ok_or_else(|| {
                src.invalid(&at, "must be a string: the path of the plugin's shared library")
            })?;
            let base = if src.is_overridden(&at) {
                std::env::current_dir().unwrap_or_default()
            } else {
                src.base_dir()
            };
            let (loss, info) =
                nuvo_plugin_host::load_loss_plugin(&base.join(path), &options).map_err(|e| match e {
                    nuvo_plugin_host::PluginError::Options { message, .. } => src.serde_error(&key, &message),
                    other => src.invalid(&at, other.to_string()),
                })?;
            (loss, info.default_weight)
        } else {
            let info = registry.info(&name).ok_or_else(|| {
                src.invalid(&key, format!("unknown loss `{name}`; known losses: {}", registry.names()))
            })?;
            let loss = registry.build(&name, &options).map_err(|e| match e {
                LossError::Options { message, .. } => src.serde_error(&key, &message),
                other => src.invalid(&key, other.to_string()),
            })?;
            (loss, info.default_weight)
        };
        let weight = weight.unwrap_or(default_weight);
        if weight > 0.0 {
            let schedule = match warmup_steps.unwrap_or(0) {
                0 => WeightSchedule::Constant,
                steps => WeightSchedule::RampUp { steps },
            };
            terms.push(Term { name, weight, schedule, suspends_chart_support: false, loss });
        }
    }
    Ok(terms)
}

/// Steps running in this process now (tests, or a library user, may step several trainers on one
/// pool at once).
static STEPPING: AtomicUsize = AtomicUsize::new(0);

/// One step counted in [`STEPPING`] while it lives (also when the step fails or panics).
struct Stepping;

impl Stepping {
    fn enter() -> Stepping {
        STEPPING.fetch_add(1, Ordering::SeqCst);
        Stepping
    }
}

impl Drop for Stepping {
    fn drop(&mut self) {
        STEPPING.fetch_sub(1, Ordering::SeqCst);
    }
}

/// Run on the pool's other threads while a step runs alone (spawned by [`Trainer::step`] before
/// any of the step's own jobs): runs the pool's jobs as they come and spins between them instead
/// of going to sleep, until the step is `done` or another step starts.
///
/// Why: a step is a few hundred parallel kernels of 0.1–1 ms, with the step's sequential work in
/// between; an idle rayon thread falls asleep within tens of microseconds, and waking it again
/// for the next kernel costs more than that (on the 2-core VMs of BENCHMARKS.md, "A second thread
/// kept awake through the step"). Kept awake, steps of the README job's training ran 2–6%
/// faster, each step A/B against the next in the same runs, with the same bits. The thread burns
/// its core while it waits, as OpenMP's active wait policy does; between steps it sleeps.
///
/// Safe from deadlock because such a job blocks its thread only on the step's own progress: it is
/// spawned before the step pushes any job, so a thread that steals it (oldest first) holds none of
/// the step's jobs beneath it, and on the step's own thread it returns at once; and because with
/// a second step running (two trainers sharing the pool, each thread could end up spinning for the
/// other's step above that step's frames) it returns too.
fn keep_busy(done: &AtomicBool, stepper: Option<usize>) {
    if rayon::current_thread_index() == stepper {
        return;
    }
    while !done.load(Ordering::Acquire) && STEPPING.load(Ordering::SeqCst) == 1 {
        if rayon::yield_now() != Some(rayon::Yield::Executed) {
            std::hint::spin_loop();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    struct Zero;
    impl Loss for Zero {
        fn evaluate(&self, ctx: &mut StepContext<'_>) -> Result<Var, LossError> {
            Ok(ctx.tape.constant(Shape::SCALAR, 0.0))
        }
    }

    fn term(weight: f32, schedule: WeightSchedule) -> Term {
        Term { name: "t".into(), weight, schedule, suspends_chart_support: false, loss: Box::new(Zero) }
    }

    #[test]
    fn weights_ramp_up_and_fade_out_linearly() {
        let weights = |t: &Term| (0..6).map(|s| t.weight_at(s)).collect::<Vec<f32>>();
        assert_eq!(
            weights(&term(10.0, WeightSchedule::RampUp { steps: 4 })),
            [2.5, 5.0, 7.5, 10.0, 10.0, 10.0]
        );
        assert_eq!(weights(&term(10.0, WeightSchedule::Constant)), [10.0; 6]);
        let prior = term(8.0, WeightSchedule::FadeOut { steps: 4 });
        assert_eq!(weights(&prior), [8.0, 6.0, 4.0, 2.0, 0.0, 0.0]);
        assert_eq!(
            (0..6).map(|s| prior.is_fading(s)).collect::<Vec<_>>(),
            [true, true, true, true, false, false]
        );
        assert!(!term(1.0, WeightSchedule::RampUp { steps: 4 }).is_fading(0));
        assert!(!term(1.0, WeightSchedule::Constant).is_fading(0));
    }
}

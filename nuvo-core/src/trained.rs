//! A trained atlas: the networks, their parameters and the frame they were trained in. What
//! evaluation, baking and export need, and nothing of training: no geometry sampler, losses,
//! plugins, warm-start fit or optimiser. [`crate::outputs`] takes one, so `nuvo bake` builds it
//! straight from a checkpoint ([`TrainedAtlas::from_checkpoint`]) and bakes even when a loss plugin
//! the run trained with is no longer on disk; a trainer hands out its current one
//! ([`crate::Trainer::atlas`]).

use nuvo_autodiff::{ParamId, ParamStore, Shape, Tape, Var};
use nuvo_geometry::Similarity;
use nuvo_losses::Networks;

use crate::checkpoint::Checkpoint;
use crate::config::ExperimentConfig;
use crate::model::{MODEL_FRAME_SCALE, NuvoModel};

/// The trained networks evaluated at `V` points (`n` charts, row-major), what baking needs.
#[derive(Clone, Debug, PartialEq)]
pub struct AtlasFields {
    /// Chart probabilities `c(x)`, `V×n`.
    pub probs: Vec<f32>,
    /// Every chart's texture coordinates `t_i(x)`, `V×n×2`.
    pub uvs: Vec<f32>,
    /// `|s_i(t_i(x)) − x|` per point and chart (`V×n`) in the model frame, where the geometry's
    /// longest bounding-box side is 1: small where chart `i`'s map is faithful at `x`.
    pub round_trip: Vec<f32>,
}

/// A checkpoint whose parameters are not those of the model its config describes.
#[derive(Debug, thiserror::Error)]
#[error("the checkpoint does not fit this model: {0}")]
pub struct CheckpointMismatch(pub String);

/// The networks of an atlas with their parameters, the input → canonical frame of the geometry
/// they were trained on, and where the run was.
pub struct TrainedAtlas {
    model: NuvoModel,
    /// Holds the parameters; evaluation records on it.
    tape: Tape,
    frame: Similarity,
    steps: u64,
    seed: u64,
}

impl TrainedAtlas {
    /// The atlas of a trainer's model and parameters (copied) at `steps` steps.
    pub(crate) fn new(
        model: NuvoModel,
        params: ParamStore,
        frame: Similarity,
        steps: u64,
        seed: u64,
    ) -> Self {
        TrainedAtlas { model, tape: Tape::new(params), frame, steps, seed }
    }

    /// The atlas a checkpoint holds, with the model `config` describes (the config stored in the
    /// checkpoint, perhaps with output overrides): its frame is the checkpoint's `to_canonical`.
    pub fn from_checkpoint(ckpt: &Checkpoint, config: &ExperimentConfig) -> Result<Self, CheckpointMismatch> {
        let mut params = ParamStore::new();
        // The initial values are overwritten below; the seed only makes them deterministic.
        let model = NuvoModel::new(&config.model, &mut params, 0);
        for (id, (_, value)) in checkpoint_params(&params, ckpt)?.into_iter().zip(&ckpt.params) {
            *params.value_mut(id) = value.clone();
        }
        Ok(TrainedAtlas::new(model, params, ckpt.to_canonical, ckpt.step, config.seed))
    }

    /// The networks' handles.
    pub fn model(&self) -> &NuvoModel {
        &self.model
    }

    /// The parameters.
    pub fn params(&self) -> &ParamStore {
        self.tape.params()
    }

    /// Number of charts.
    pub fn charts(&self) -> usize {
        self.model.charts()
    }

    /// The input → canonical map of the geometry the networks were trained on.
    pub fn frame(&self) -> Similarity {
        self.frame
    }

    /// Steps trained.
    pub fn steps(&self) -> u64 {
        self.steps
    }

    /// The run's seed (points drawn at bake time are drawn with it).
    pub fn seed(&self) -> u64 {
        self.seed
    }

    /// The networks' fields at points given in the canonical frame (see [`AtlasFields`]).
    pub fn evaluate_atlas(&mut self, canonical: &[[f32; 3]]) -> AtlasFields {
        fields_at(&self.model, &mut self.tape, canonical, true)
    }

    /// [`AtlasFields::probs`] and [`AtlasFields::uvs`] alone: what a reader of charts and UVs needs,
    /// without the surface networks' pass the round trip costs.
    pub fn evaluate_charts(&mut self, canonical: &[[f32; 3]]) -> (Vec<f32>, Vec<f32>) {
        let AtlasFields { probs, uvs, .. } = fields_at(&self.model, &mut self.tape, canonical, false);
        (probs, uvs)
    }
}

/// For each of `ckpt`'s parameters, in its order, the model's parameter of the same name, checked
/// to have the same shape; an error unless the two hold exactly the same parameters.
pub(crate) fn checkpoint_params(
    params: &ParamStore,
    ckpt: &Checkpoint,
) -> Result<Vec<ParamId>, CheckpointMismatch> {
    if ckpt.params.len() != params.len() {
        return Err(CheckpointMismatch(format!(
            "{} parameters saved, {} in the model",
            ckpt.params.len(),
            params.len()
        )));
    }
    ckpt.params
        .iter()
        .map(|(name, t)| {
            let id =
                params.find(name).ok_or_else(|| CheckpointMismatch(format!("unknown parameter `{name}`")))?;
            if params.value(id).shape() != t.shape() {
                return Err(CheckpointMismatch(format!(
                    "`{name}` is {} in the checkpoint, {} in the model",
                    t.shape(),
                    params.value(id).shape()
                )));
            }
            Ok(id)
        })
        .collect()
}

/// The fields of `model` at `canonical` points, evaluated on `tape` in chunks, one network pass at
/// a time, so memory stays bounded on huge meshes; `round_trip` empty unless `with_round_trip`.
/// The trainer's settling probe and [`TrainedAtlas`] both evaluate through this.
pub(crate) fn fields_at(
    model: &NuvoModel,
    tape: &mut Tape,
    canonical: &[[f32; 3]],
    with_round_trip: bool,
) -> AtlasFields {
    const CHUNK: usize = 16384;
    let n = model.charts();
    let mut probs = Vec::with_capacity(canonical.len() * n);
    let mut uvs = vec![0.0f32; canonical.len() * n * 2];
    let mut round_trip = vec![0.0f32; if with_round_trip { canonical.len() * n } else { 0 }];
    for (c, chunk) in canonical.chunks(CHUNK).enumerate() {
        let x = fresh_model_frame_input(tape, chunk);
        let logits = model.chart_logits(tape, x);
        let p = tape.softmax(logits);
        probs.extend_from_slice(tape.value(p));
        for i in 0..n {
            let x = fresh_model_frame_input(tape, chunk);
            let t = model.texture(tape, i, x);
            for (k, uv) in tape.value(t).chunks_exact(2).enumerate() {
                let at = (c * CHUNK + k) * n + i;
                uvs[2 * at..2 * at + 2].copy_from_slice(uv);
            }
            if with_round_trip {
                let back = model.surface(tape, i, t);
                let rows = tape.value(back).chunks_exact(3).zip(tape.value(x).chunks_exact(3));
                for (k, (s, x)) in rows.enumerate() {
                    let at = (c * CHUNK + k) * n + i;
                    round_trip[at] = s.iter().zip(x).map(|(a, b)| (a - b) * (a - b)).sum::<f32>().sqrt();
                }
            }
        }
    }
    tape.reset();
    AtlasFields { probs, uvs, round_trip }
}

/// Clears the tape and records `canonical` points, scaled into the model frame, as its input.
fn fresh_model_frame_input(tape: &mut Tape, canonical: &[[f32; 3]]) -> Var {
    tape.reset();
    tape.input_with(Shape::new(canonical.len(), 3), |d| {
        for (row, p) in d.chunks_exact_mut(3).zip(canonical) {
            row.iter_mut().zip(p).for_each(|(r, &v)| *r = v * MODEL_FRAME_SCALE);
        }
    })
}

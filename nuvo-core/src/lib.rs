//! `nuvo-core`: the Nuvo model, experiment configs, the trainer and training runs.
//!
//! - [`config`]: the TOML experiment config with `--set` overrides and located errors;
//! - [`model`]: the `2n + 1` networks, `σ` and the normal grids;
//! - [`trainer`]: one deterministic optimisation step at a time;
//! - [`trained`]: a trained atlas (networks, parameters, frame), from a trainer or a checkpoint, which
//!   evaluation, baking and export take;
//! - [`mod@run`]: the output folder, checkpoints, log, resume, budget and NaN rollback;
//! - [`checkpoint`]: the safetensors checkpoint format;
//! - [`ablation`]: sweeps of config variants and the paper's ablation table;
//! - [`manifest`] and [`batch_record`]: `nuvo batch`'s items and shards, and what each item leaves
//!   behind (its record, the summary table);
//! - [`warm_start`]: the optional projection prior that starts charts as fold-free projections.
//!
//! Geometry sources and losses come from registries ([`nuvo_geometry::SourceRegistry`],
//! [`nuvo_losses::LossRegistry`]), so an application can add its own before building a [`Trainer`].

pub mod ablation;
pub mod batch;
pub mod batch_record;
pub mod checkpoint;
pub mod config;
pub mod manifest;
pub mod model;
pub mod outputs;
pub mod run;
pub mod seeds;
pub mod settling;
pub mod trained;
pub mod trainer;
pub mod unwrap;
pub mod warm_start;

pub use checkpoint::{Checkpoint, CheckpointError};
pub use config::{ConfigError, ExperimentConfig, LoadedConfig};
pub use model::NuvoModel;
pub use run::{Observer, RunOptions, RunSummary, run};
pub use trained::{AtlasFields, TrainedAtlas};
pub use trainer::{StepOutcome, TrainError, Trainer};

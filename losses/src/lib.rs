//! `nuvo-losses`: the terms of Nuvo's objective as named, weighted plugins.
//!
//! A loss implements [`Loss`]: given the per-step [`StepContext`] (the batch and every network output,
//! computed once and shared), it records its value on the tape. A loss that configs name implements
//! [`RegisteredLoss`] too (its [`LossInfo`] and a constructor from its options table, the shape of a
//! run-time plugin) and is added with [`LossRegistry::add`]; the registry maps the names used in
//! `[losses.NAME]` config tables to constructors. [`builtin`] holds the paper's eight
//! ([`builtin::PAPER`], what a config without `[losses]` trains):
//!
//! | name | paper | default weight |
//! |---|---|---|
//! | `cycle_3d` | L_{3→2→3} | 1 |
//! | `cycle_2d` | L_{2→3→2} | 1 |
//! | `entropy` | L_entropy | 0.04 |
//! | `surface` | L_surface (symmetric Chamfer, kd-tree nearest neighbours) | 10 |
//! | `cluster` | L_cluster | 0.5 |
//! | `conformal` | L_conformal | 0.4 |
//! | `stretch` | L_stretch | 0.1 |
//! | `texture` | L_texture | 0.1 |
//!
//! Models plug in through the [`Networks`] trait, so this crate never evaluates a model itself.

pub mod builtin;
pub mod context;
pub mod loss;
pub mod networks;
pub mod registry;
#[cfg(test)]
mod testing;

pub use context::{ChartRows, Reads, Samples, StepContext, StepData};
pub use loss::{Loss, LossError, chart_weighted_mean, squared_distance};
pub use networks::Networks;
pub use registry::{LossInfo, LossRegistry, OptionDoc, RegisteredLoss, no_options, parse_options};

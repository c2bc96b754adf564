//! `nuvo-plugin-api`: the only dependency a run-time loss plugin for nuvo needs.
//!
//! A loss plugin is a separate crate built as a `cdylib`. A config names it by path and nuvo loads it
//! when training starts:
//!
//! ```toml
//! [losses.isometric]
//! plugin = "plugins/target/release/libmy_loss.so"   # relative to the config file
//! weight = 0.01
//! floor = 1e-3                                      # the plugin's own options
//! ```
//!
//! Write one in three steps (the full walk-through is `plugins/README.md`):
//!
//! 1. implement [`LossPlugin`]: declare the per-step [`Quantity`]s you read, parse your options in
//!    [`LossPlugin::new`], and in [`LossPlugin::evaluate`] return the value and fill the gradient of
//!    every differentiable quantity you read ([`Gradients::take`]);
//! 2. call [`export_loss_plugin!`] once;
//! 3. unit-test it with [`testing::TestPlugin::check_gradients`].
//!
//! # Layers
//!
//! - [`abi`]: the versioned `#[repr(C)]` contract (descriptor, inputs, outputs, statuses, ownership,
//!   threading). It is the only thing that crosses the library boundary.
//! - The safe layer ([`LossPlugin`], [`Inputs`], [`Gradients`], [`Matrix`], [`export_loss_plugin!`]):
//!   no `unsafe` in plugin code; every call is wrapped in `catch_unwind`, so a panic becomes an error
//!   reported to nuvo instead of unwinding across the C boundary.
//! - [`testing`]: drives a plugin through the same C entry points in-process, for unit tests.

#![warn(missing_docs)]

pub mod abi;
pub mod export;
mod matrix;
mod plugin;
mod quantity;
pub mod testing;

pub use abi::{ABI_VERSION, OptionDoc};
pub use matrix::{Matrix, MatrixMut};
pub use plugin::{Gradients, Inputs, LossPlugin};
pub use quantity::{Dims, Quantities, Quantity};

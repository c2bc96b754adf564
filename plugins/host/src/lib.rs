//! `nuvo-plugin-host`: loads run-time loss plugins (shared libraries built with `nuvo-plugin-api`)
//! and turns them into [`nuvo_losses::Loss`]es the trainer weights and sums like built-in ones.
//!
//! The boundary is checked, in this order, each failure naming the path and the cause
//! ([`PluginError`]): the path is an existing regular file; the system loader accepts it (opened with
//! every symbol resolved now, privately); it exports `nuvo_loss_plugin`; the descriptor's ABI version
//! (read before anything else) is supported; the rest of the descriptor is well formed (bounded UTF-8
//! strings, known quantities and flags, all functions present, panics caught); the plugin accepts its
//! options. At each step, the plugin's status, its gradient buffers (pointers, shapes, guard words)
//! and the finiteness of its gradients are checked before anything reaches the tape (see
//! [`PluginLoss`] for what happens on failure).
//!
//! Libraries are never unloaded: each validated plugin is leaked into a process-lifetime record, so
//! every loss built from it and every function pointer copied from it stays valid; the same file (by
//! canonical path) is opened once. Calls into one library are serialised (the ABI's threading rule).
//! Messages after loading name the plugin by its canonical path.

#![warn(missing_docs)]

mod buffers;
mod descriptor;
mod error;
mod gather;
mod library;
mod loss;

use std::path::Path;

use nuvo_losses::Loss;

pub use descriptor::{PluginInfo, PluginOption};
pub use error::PluginError;
pub use loss::PluginLoss;
pub use nuvo_plugin_api::{Quantities, Quantity};

/// Loads the plugin at `path` and creates a loss from `options` (the `[losses.NAME]` table without
/// its `plugin` and `weight` keys, handed to the plugin as TOML text). Loading the same file again
/// reuses the loaded library.
pub fn load_loss_plugin(
    path: &Path,
    options: &toml::Table,
) -> Result<(Box<dyn Loss>, PluginInfo), PluginError> {
    let plugin = library::load(path)?;
    let loss = PluginLoss::create(plugin, options)?;
    Ok((Box::new(loss), plugin.info.clone()))
}

/// What the plugin at `path` says about itself, without creating a loss (for `nuvo losses`).
pub fn describe_plugin(path: &Path) -> Result<PluginInfo, PluginError> {
    Ok(library::load(path)?.info.clone())
}

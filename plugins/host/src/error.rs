//! Why a plugin could not be loaded or instantiated. Every variant names the library's path.

use std::path::PathBuf;

use nuvo_plugin_api::abi::{ABI_VERSION, ENTRY_SYMBOL, MIN_SUPPORTED_ABI_VERSION};

/// A plugin that failed to load or to build. Evaluation failures are [`nuvo_losses::LossError`]s
/// instead, since they happen inside a training step. `path` is the path as given until the library
/// is open, its canonical path after.
#[derive(Debug, thiserror::Error)]
pub enum PluginError {
    /// Nothing at the path.
    #[error("loss plugin {}: no such file", path.display())]
    NotFound {
        /// The library's path.
        path: PathBuf,
    },
    /// The path exists but could not be inspected.
    #[error("loss plugin {}: cannot read it: {source}", path.display())]
    Unreadable {
        /// The library's path.
        path: PathBuf,
        /// The system's reason.
        #[source]
        source: std::io::Error,
    },
    /// A directory or other non-file.
    #[error(
        "loss plugin {}: is a directory or special file, not a shared library (point at the file cargo \
         builds, e.g. target/release/{}NAME{})",
        path.display(),
        std::env::consts::DLL_PREFIX,
        std::env::consts::DLL_SUFFIX
    )]
    NotAFile {
        /// The library's path.
        path: PathBuf,
    },
    /// The system loader refused the file.
    #[error("loss plugin {}: not a shared library this system can load: {message}", path.display())]
    NotALibrary {
        /// The library's path.
        path: PathBuf,
        /// The loader's message.
        message: String,
    },
    /// A library, but not a nuvo plugin.
    #[error(
        "loss plugin {}: the library does not export `{ENTRY_SYMBOL}` ({message}); a loss plugin is a \
         cdylib crate that implements nuvo_plugin_api::LossPlugin and calls \
         `nuvo_plugin_api::export_loss_plugin!(YourLoss)`",
        path.display()
    )]
    MissingEntry {
        /// The library's path.
        path: PathBuf,
        /// The loader's message.
        message: String,
    },
    /// Built against an ABI version this nuvo does not speak.
    #[error(
        "loss plugin {}: built against plugin ABI version {found}, but this nuvo supports versions \
         {MIN_SUPPORTED_ABI_VERSION} to {ABI_VERSION}; rebuild the plugin (cargo build --release) \
         against the nuvo-plugin-api of this nuvo (ABI {ABI_VERSION})",
        path.display()
    )]
    AbiVersion {
        /// The library's path.
        path: PathBuf,
        /// The version in its descriptor.
        found: u32,
    },
    /// The descriptor breaks the ABI (bad strings, unknown quantities or flags, null functions, ...).
    #[error("loss plugin {}: invalid descriptor: {message}", path.display())]
    Descriptor {
        /// The library's path.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// The plugin rejected its options.
    #[error("loss plugin {}: {message}", path.display())]
    Options {
        /// The library's path.
        path: PathBuf,
        /// The plugin's message, often in serde's wording (`unknown field ...`), which config loaders
        /// can locate.
        message: String,
    },
    /// Creating the instance failed for another reason (an error status, a panic).
    #[error("loss plugin {}: could not create the loss: {message}", path.display())]
    Create {
        /// The library's path.
        path: PathBuf,
        /// Why.
        message: String,
    },
}

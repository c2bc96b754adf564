//! Why a plugin could not be loaded or instantiated. Every variant names the library's path.

use std::path::PathBuf;

use nuvo_plugin_api::abi::{ABI_VERSION, ENTRY_SYMBOL, MIN_SUPPORTED_ABI_VERSION};

/// A plugin that failed to load or to build. Evaluation failures are [`nuvo_losses::LossError`]s
/// instead, since they happen inside a training step.
#[derive(Debug, thiserror::Error)]
pub enum PluginError {
    /// Nothing at the path.
    #[error("loss plugin {}: no such file", path.display())]
    NotFound { path: PathBuf },
    /// The path exists but could not be inspected.
    #[error("loss plugin {}: cannot read it: {source}", path.display())]
    Unreadable {
        path: PathBuf,
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
    NotAFile { path: PathBuf },
    /// The system loader refused the file.
    #[error("loss plugin {}: not a shared library this system can load: {message}", path.display())]
    NotALibrary { path: PathBuf, message: String },
    /// A library, but not a nuvo plugin.
    #[error(
        "loss plugin {}: the library does not export `{ENTRY_SYMBOL}` ({message}); a loss plugin is a \
         cdylib crate that implements nuvo_plugin_api::LossPlugin and calls \
         `nuvo_plugin_api::export_loss_plugin!(YourLoss)`",
        path.display()
    )]
    MissingEntry { path: PathBuf, message: String },
    /// Built against an ABI version this nuvo does not speak.
    #[error(
        "loss plugin {}: built against plugin ABI version {found}, but this nuvo supports versions \
         {MIN_SUPPORTED_ABI_VERSION} to {ABI_VERSION}; rebuild the plugin (cargo build --release) \
         against the nuvo-plugin-api of this nuvo (ABI {ABI_VERSION})",
        path.display()
    )]
    AbiVersion { path: PathBuf, found: u32 },
    /// The descriptor breaks the ABI (bad strings, unknown quantities or flags, null functions, ...).
    #[error("loss plugin {}: invalid descriptor: {message}", path.display())]
    Descriptor { path: PathBuf, message: String },
    /// The plugin rejected its options (the message is the plugin's, often serde's wording).
    #[error("loss plugin {}: {message}", path.display())]
    Options { path: PathBuf, message: String },
    /// Creating the instance failed for another reason (an error status, a panic).
    #[error("loss plugin {}: could not create the loss: {message}", path.display())]
    Create { path: PathBuf, message: String },
}

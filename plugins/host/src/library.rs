//! Opening plugin libraries: file checks, the system loader, the entry symbol, and a process-wide
//! table of loaded plugins.
//!
//! Lifetime rule: a library, once opened, is never unloaded. Each validated plugin is leaked into a
//! `&'static` record, so every loss built from it, and every function pointer copied from its
//! descriptor, stays valid for the rest of the process; libraries refused after opening are leaked too
//! (their initialisers have run, and unloading code we know nothing about is riskier than keeping it).
//! This also sidesteps unloading hazards of Rust libraries (thread-local destructors, `atexit`
//! handlers). The cost, a few KiB per plugin file, is paid once per process: the same file (by
//! canonical path) is opened once and shared.

use std::path::{Path, PathBuf};
use std::sync::{Mutex, MutexGuard, PoisonError};

use nuvo_plugin_api::abi::{ENTRY_SYMBOL, EntryFn};

use crate::descriptor::{self, Functions, PluginInfo};
use crate::error::PluginError;

/// A loaded, validated plugin library. Lives until the process exits.
#[derive(Debug)]
pub(crate) struct LoadedPlugin {
    /// What it says about itself (`info.path` is the canonical path).
    pub info: PluginInfo,
    /// Its entry points.
    pub functions: Functions,
    /// Held during every call into the library: the ABI promises plugins one call at a time.
    calls: Mutex<()>,
}

impl LoadedPlugin {
    /// Serialises a call into the library.
    pub fn lock_calls(&self) -> MutexGuard<'_, ()> {
        self.calls.lock().unwrap_or_else(PoisonError::into_inner)
    }
}

/// Every plugin loaded so far.
static LOADED: Mutex<Vec<&'static LoadedPlugin>> = Mutex::new(Vec::new());

/// Loads (or finds already loaded) the plugin library at `path` and validates its descriptor.
pub(crate) fn load(path: &Path) -> Result<&'static LoadedPlugin, PluginError> {
    let canonical = check_file(path)?;
    let mut loaded = LOADED.lock().unwrap_or_else(PoisonError::into_inner);
    if let Some(plugin) = loaded.iter().find(|p| p.info.path == canonical) {
        return Ok(plugin);
    }
    let library = open(&canonical)
        .map_err(|e| PluginError::NotALibrary { path: path.to_owned(), message: e.to_string() })?;
    // Never unloaded (see the module docs).
    let library: &'static libloading::Library = Box::leak(Box::new(library));
    // SAFETY: `EntryFn` is the type the ABI gives `nuvo_loss_plugin`; a library exporting a different
    // thing under that name breaks the ABI, which we cannot detect.
    let entry = unsafe { library.get::<EntryFn>(ENTRY_SYMBOL.as_bytes()) }
        .map_err(|e| PluginError::MissingEntry { path: path.to_owned(), message: e.to_string() })?;
    // SAFETY: the entry function takes nothing and only returns a pointer (ABI contract).
    let ptr = unsafe { entry() };
    // SAFETY: the library stays loaded forever, so whatever the descriptor points at stays valid; the
    // ABI guarantees it is readable as `read` requires.
    let (info, functions) = unsafe { descriptor::read(ptr, &canonical) }?;
    let plugin = Box::leak(Box::new(LoadedPlugin { info, functions, calls: Mutex::new(()) }));
    loaded.push(plugin);
    Ok(plugin)
}

/// The canonical path of `path` if it is a regular file, else a precise error.
fn check_file(path: &Path) -> Result<PathBuf, PluginError> {
    let meta = std::fs::metadata(path).map_err(|source| match source.kind() {
        std::io::ErrorKind::NotFound => PluginError::NotFound { path: path.to_owned() },
        _ => PluginError::Unreadable { path: path.to_owned(), source },
    })?;
    if !meta.is_file() {
        return Err(PluginError::NotAFile { path: path.to_owned() });
    }
    path.canonicalize().map_err(|source| PluginError::Unreadable { path: path.to_owned(), source })
}

/// Opens a library with all symbols resolved now (`RTLD_NOW`), so a missing dependency or symbol
/// fails here with the loader's message instead of aborting mid-training, and kept private
/// (`RTLD_LOCAL`), so plugins cannot clash with each other or with nuvo.
fn open(path: &Path) -> Result<libloading::Library, libloading::Error> {
    #[cfg(unix)]
    {
        use libloading::os::unix::{Library, RTLD_LOCAL, RTLD_NOW};
        // SAFETY: opening a library runs its initialisers; a plugin is trusted code (it runs with
        // nuvo's privileges anyway). The path is absolute, so no search path is involved.
        unsafe { Library::open(Some(path), RTLD_NOW | RTLD_LOCAL) }.map(Into::into)
    }
    #[cfg(not(unix))]
    {
        // SAFETY: as above.
        unsafe { libloading::Library::new(path) }
    }
}

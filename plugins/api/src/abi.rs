//! The C ABI between nuvo and a loss plugin: the only thing that crosses the library boundary.
//!
//! Everything here is `#[repr(C)]` and made of fixed-size integers, `f32`, `usize` (`size_t`), raw
//! pointers and *nullable* function pointers. No Rust-ABI type (`String`, `Vec`, trait objects,
//! `Result`) crosses, so a plugin may be built by any Rust compiler, or written in C against the layout
//! documented here, and the host never depends on how the plugin's compiler lays out Rust types.
//!
//! # Entry point
//!
//! A plugin library exports one symbol, [`ENTRY_SYMBOL`] (`nuvo_loss_plugin`), an
//! `extern "C" fn() -> *const PluginDescriptor` ([`EntryFn`]). The descriptor it points to, and every
//! string and array the descriptor points to, must live as long as the library is loaded. Calling the
//! entry function must have no side effects; the host may call it more than once.
//!
//! # Versioning rule
//!
//! [`PluginDescriptor::abi_version`] is the first field of the descriptor in *every* version, and the
//! host reads nothing else before checking it against `MIN_SUPPORTED_ABI_VERSION..=ABI_VERSION`.
//! [`ABI_VERSION`] is bumped whenever a plugin and a host built against different versions could
//! misread each other: a field, status, slot, flag or function signature is added, removed or changes
//! meaning. [`MIN_SUPPORTED_ABI_VERSION`] is raised only when the host can no longer serve old plugins;
//! purely additive changes (a new quantity in a reserved slot, a new flag) keep it, because an old
//! plugin never asks for what it does not know. The range is checked the way tree-sitter checks
//! grammar versions: a plugin outside it is refused with both versions named, before any of its
//! functions is called.
//!
//! # Memory ownership
//!
//! - The descriptor, its strings and its option table belong to the plugin and are static.
//! - Option text, inputs and gradient buffers belong to the host and are valid only during the call
//!   they are passed to. Inputs are read-only. Each gradient buffer is zero-filled by the host, has
//!   exactly the shape of its input, does not overlap any other buffer, and the plugin writes only
//!   inside it. The plugin must not change the pointers or shapes in [`RawOutputs`].
//! - An instance (the `void *` from `create`) belongs to the plugin; the host passes it back to
//!   `evaluate` and frees it with `destroy`, exactly once, after its last use.
//! - An error message ([`PluginString`]) is allocated by the plugin; the host copies it and hands it
//!   back to the plugin's `free_string`, exactly once. Hosts use [`take_plugin_string`].
//!
//! # Threading
//!
//! nuvo never calls into one loaded library from two threads at once (create, evaluate and destroy
//! of all its instances are serialised), but consecutive calls may come from different threads. So
//! instances must be movable between threads (`Send`), and need not be `Sync`.
//!
//! # Errors and panics
//!
//! Every function reports failure through its [`Status`] and an optional message, never by unwinding
//! or aborting: a plugin sets [`FLAG_CATCHES_PANICS`] to promise this, and the host refuses plugins
//! that do not. The safe layer ([`crate::export_loss_plugin!`]) catches panics with `catch_unwind`,
//! which needs the plugin built with `panic = "unwind"` (Rust's default); built with `panic = "abort"`,
//! it does not set the flag.

use std::ffi::c_void;

/// The ABI version this crate describes and the host speaks.
pub const ABI_VERSION: u32 = 1;

/// The oldest plugin ABI version a host built from this crate still serves.
pub const MIN_SUPPORTED_ABI_VERSION: u32 = 1;

/// The name of the exported entry function (no trailing NUL).
pub const ENTRY_SYMBOL: &str = "nuvo_loss_plugin";

/// Number of quantity slots in [`RawInputs`] and [`RawOutputs`]. Quantity `k` (see
/// [`crate::Quantity`]) uses slot `k` and bit `1 << k` of [`PluginDescriptor::reads`]; slots without a
/// quantity are reserved for later versions and always empty.
pub const SLOTS: usize = 16;

/// Flag: every entry function reports failure through its status and never unwinds or aborts.
/// Required by the host.
pub const FLAG_CATCHES_PANICS: u32 = 1;

/// Every flag this version defines; other bits must be zero.
pub const KNOWN_FLAGS: u32 = FLAG_CATCHES_PANICS;

/// The result of `create` and `evaluate`.
pub type Status = i32;
/// Success.
pub const STATUS_OK: Status = 0;
/// Failure; the message says why.
pub const STATUS_ERROR: Status = 1;
/// `create` rejected the options; the message says which key and why (serde's wording, such as
/// "unknown field \`x\`, expected \`y\`", lets the host point at the line of the config).
pub const STATUS_BAD_OPTIONS: Status = 2;
/// The plugin panicked; the message is the panic's. The host does not call that instance again.
pub const STATUS_PANIC: Status = 3;

/// A borrowed UTF-8 string: `len` bytes at `ptr`, not NUL-terminated. `ptr` may be null only when
/// `len` is 0.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct PluginStr {
    /// The first byte.
    pub ptr: *const u8,
    /// Length in bytes.
    pub len: usize,
}

impl PluginStr {
    /// Points at a static string.
    pub const fn from_static(s: &'static str) -> Self {
        PluginStr { ptr: s.as_ptr(), len: s.len() }
    }
}

/// A UTF-8 message allocated by the plugin, freed by the plugin's `free_string`. Null `ptr` means no
/// message.
#[repr(C)]
#[derive(Debug)]
pub struct PluginString {
    /// The first byte, or null.
    pub ptr: *mut u8,
    /// Length in bytes.
    pub len: usize,
}

impl PluginString {
    /// No message.
    pub const fn null() -> Self {
        PluginString { ptr: std::ptr::null_mut(), len: 0 }
    }
}

/// One documented option of a plugin, shown by `nuvo losses`. Build it with [`OptionDoc::new`].
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct OptionDoc {
    /// The key in the `[losses.NAME]` table.
    pub name: PluginStr,
    /// Its default, in TOML syntax.
    pub default: PluginStr,
    /// What it does.
    pub doc: PluginStr,
}

impl OptionDoc {
    /// Documents option `name`, with its default in TOML syntax.
    pub const fn new(name: &'static str, default: &'static str, doc: &'static str) -> Self {
        OptionDoc {
            name: PluginStr::from_static(name),
            default: PluginStr::from_static(default),
            doc: PluginStr::from_static(doc),
        }
    }
}

// SAFETY: an `OptionDoc` only points at immutable static strings (see the module's ownership rules),
// so sharing it between threads cannot race.
unsafe impl Sync for OptionDoc {}

/// A read-only row-major `rows × cols` matrix of `f32`. `data` is null exactly when the quantity was
/// not requested (then `rows` and `cols` are 0).
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct RawMatrix {
    /// The first element.
    pub data: *const f32,
    /// Rows.
    pub rows: usize,
    /// Columns.
    pub cols: usize,
}

/// A writable row-major `rows × cols` matrix of `f32` (a gradient buffer).
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RawMatrixMut {
    /// The first element.
    pub data: *mut f32,
    /// Rows.
    pub rows: usize,
    /// Columns.
    pub cols: usize,
}

impl RawMatrix {
    /// The empty slot.
    pub const EMPTY: RawMatrix = RawMatrix { data: std::ptr::null(), rows: 0, cols: 0 };
}

impl RawMatrixMut {
    /// The empty slot.
    pub const EMPTY: RawMatrixMut = RawMatrixMut { data: std::ptr::null_mut(), rows: 0, cols: 0 };
}

/// What `evaluate` reads: the step's sizes and, in slot `k`, quantity `k` if the plugin declared it.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct RawInputs {
    /// Number of charts `n` (at least 1).
    pub charts: usize,
    /// 3-D samples in the batch, `B`.
    pub batch_3d: usize,
    /// UV samples in the batch, `T`.
    pub batch_uv: usize,
    /// The finite-difference step `ε` of the UV differentials.
    pub epsilon: f32,
    /// One matrix per slot; see [`crate::Quantity`] for shapes and layouts.
    pub quantities: [RawMatrix; SLOTS],
}

/// What `evaluate` writes: the loss's value and, in slot `k`, the gradient of the value with respect
/// to quantity `k` (same shape), for every declared differentiable quantity. Other slots are empty.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct RawOutputs {
    /// The unweighted value of the loss.
    pub value: f32,
    /// Host-allocated, zero-filled gradient buffers.
    pub gradients: [RawMatrixMut; SLOTS],
}

/// The entry function's type.
pub type EntryFn = unsafe extern "C" fn() -> *const PluginDescriptor;

/// `create(options, options_len, instance_out, error_out)`: builds an instance from the TOML text of
/// the `[losses.NAME]` table without its `plugin` and `weight` keys (UTF-8, `options_len` bytes, not
/// NUL-terminated). On [`STATUS_OK`] writes the instance to `*instance_out`; otherwise may write a
/// message to `*error_out`.
pub type CreateFn = unsafe extern "C" fn(
    options: *const u8,
    options_len: usize,
    instance_out: *mut *mut c_void,
    error_out: *mut PluginString,
) -> Status;

/// `evaluate(instance, inputs, outputs, error_out)`: computes the loss for one step. On
/// [`STATUS_OK`] has written `outputs.value` and the gradient buffers; otherwise may write a message to
/// `*error_out`.
pub type EvaluateFn = unsafe extern "C" fn(
    instance: *mut c_void,
    inputs: *const RawInputs,
    outputs: *mut RawOutputs,
    error_out: *mut PluginString,
) -> Status;

/// `destroy(instance)`: frees an instance from `create`. Must not fail.
pub type DestroyFn = unsafe extern "C" fn(instance: *mut c_void);

/// `free_string(message)`: frees a message the plugin wrote to an `error_out`.
pub type FreeStringFn = unsafe extern "C" fn(message: PluginString);

/// Everything the host knows about a plugin. Layout of version 1 (offsets on 64-bit targets):
///
/// | offset | field | C type |
/// |---|---|---|
/// | 0 | `abi_version` | `uint32_t` |
/// | 4 | `descriptor_size` | `uint32_t` |
/// | 8 | `flags` | `uint32_t` |
/// | 12 | `reads` | `uint32_t` |
/// | 16 | `default_weight` | `float` |
/// | 24 | `name` | `{const uint8_t *ptr; size_t len;}` |
/// | 40 | `description` | same |
/// | 56 | `options` | `const OptionDoc *` (3 strings each) |
/// | 64 | `options_len` | `size_t` |
/// | 72 | `create`, `evaluate`, `destroy`, `free_string` | function pointers |
#[repr(C)]
#[derive(Debug)]
pub struct PluginDescriptor {
    /// The ABI version the plugin was built against: [`ABI_VERSION`] of its `nuvo-plugin-api`. Always
    /// the first field.
    pub abi_version: u32,
    /// `size_of::<PluginDescriptor>()` as the plugin saw it: catches hand-written descriptors with a
    /// wrong layout.
    pub descriptor_size: u32,
    /// [`FLAG_CATCHES_PANICS`] and future flags.
    pub flags: u32,
    /// The quantities `evaluate` reads: bit `1 << k` for quantity `k`.
    pub reads: u32,
    /// The weight used when the config gives none.
    pub default_weight: f32,
    /// Short name (an identifier, 1 to 64 bytes), e.g. `symmetric_dirichlet`.
    pub name: PluginStr,
    /// What the loss computes, in one paragraph.
    pub description: PluginStr,
    /// `options_len` documented options.
    pub options: *const OptionDoc,
    /// Number of documented options.
    pub options_len: usize,
    /// Builds an instance.
    pub create: Option<CreateFn>,
    /// Evaluates an instance on one step.
    pub evaluate: Option<EvaluateFn>,
    /// Frees an instance.
    pub destroy: Option<DestroyFn>,
    /// Frees an error message.
    pub free_string: Option<FreeStringFn>,
}

// SAFETY: a descriptor is immutable and only points at static data (see the module's ownership
// rules), so a `static` one may be read from any thread.
unsafe impl Sync for PluginDescriptor {}

/// Copies a plugin's message into a `String` (invalid UTF-8 replaced, at most `max_len` bytes kept)
/// and hands it back to the plugin's `free`. `None` when the plugin wrote no message.
///
/// # Safety
/// `message` must be null or have been written by the plugin whose `free` this is, and not been freed;
/// after this call it must not be used again.
pub unsafe fn take_plugin_string(
    message: PluginString,
    free: FreeStringFn,
    max_len: usize,
) -> Option<String> {
    if message.ptr.is_null() {
        return None;
    }
    // SAFETY: the caller guarantees `message` came from the plugin, which promises `len` readable bytes
    // at `ptr` until it is freed below.
    let bytes = unsafe { std::slice::from_raw_parts(message.ptr, message.len) };
    let mut text = String::from_utf8_lossy(&bytes[..bytes.len().min(max_len)]).into_owned();
    if bytes.len() > max_len {
        text.push_str("… (truncated)");
    }
    // SAFETY: returned exactly once to the plugin that allocated it, as the caller guarantees.
    unsafe { free(message) };
    Some(text)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_version_field_comes_first_and_the_layout_is_the_documented_one() {
        assert_eq!(std::mem::offset_of!(PluginDescriptor, abi_version), 0);
        if cfg!(target_pointer_width = "64") {
            assert_eq!(std::mem::offset_of!(PluginDescriptor, default_weight), 16);
            assert_eq!(std::mem::offset_of!(PluginDescriptor, name), 24);
            assert_eq!(std::mem::offset_of!(PluginDescriptor, description), 40);
            assert_eq!(std::mem::offset_of!(PluginDescriptor, options), 56);
            assert_eq!(std::mem::offset_of!(PluginDescriptor, options_len), 64);
            assert_eq!(std::mem::offset_of!(PluginDescriptor, create), 72);
            assert_eq!(std::mem::size_of::<PluginDescriptor>(), 104);
        }
        // Nullable function pointers are plain pointers.
        assert_eq!(std::mem::size_of::<Option<CreateFn>>(), std::mem::size_of::<usize>());
    }
}

//! Reading a plugin's descriptor: the version first, then everything else, checked and copied into
//! owned Rust values so nothing downstream touches the plugin's raw data again.

use std::fmt;
use std::path::{Path, PathBuf};

use nuvo_plugin_api::Quantities;
use nuvo_plugin_api::abi::{
    ABI_VERSION, CreateFn, DestroyFn, EvaluateFn, FLAG_CATCHES_PANICS, FreeStringFn, KNOWN_FLAGS,
    MIN_SUPPORTED_ABI_VERSION, OptionDoc, PluginDescriptor, PluginStr,
};
use nuvo_plugin_api::export::is_identifier;

use crate::error::PluginError;

/// Longest description accepted, in bytes.
const MAX_DESCRIPTION: usize = 4096;
/// Most options a plugin may document.
const MAX_OPTIONS: usize = 64;
/// Longest option name or default, in bytes.
const MAX_SHORT: usize = 256;

/// What a plugin says about itself (for `nuvo losses`, error messages and default weights).
#[derive(Clone, Debug, PartialEq)]
pub struct PluginInfo {
    /// The library's canonical path.
    pub path: PathBuf,
    /// The ABI version it was built against.
    pub abi_version: u32,
    /// Its identifier.
    pub name: String,
    /// What it computes.
    pub description: String,
    /// The weight used when the config gives none.
    pub default_weight: f32,
    /// Its documented options.
    pub options: Vec<PluginOption>,
    /// The per-step quantities it reads.
    pub reads: Quantities,
}

/// One documented option of a plugin.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct PluginOption {
    /// The key.
    pub name: String,
    /// Its default, in TOML syntax.
    pub default: String,
    /// What it does.
    pub doc: String,
}

/// The plugin's entry points, all present (checked).
#[derive(Clone, Copy)]
pub(crate) struct Functions {
    pub create: CreateFn,
    pub evaluate: EvaluateFn,
    pub destroy: DestroyFn,
    pub free_string: FreeStringFn,
}

impl fmt::Debug for Functions {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("Functions { .. }")
    }
}

/// Reads and checks the descriptor at `ptr`, returned by the entry function of the library at
/// `path`. The ABI version is read first, and nothing else unless it is supported.
///
/// # Safety
/// `ptr` must be null or point at memory that stays valid for the process: at least a readable
/// `u32`, and, if that version is supported, a [`PluginDescriptor`] of this layout whose strings and
/// option table are readable for their stated lengths (what every plugin built with
/// `nuvo-plugin-api` provides). The checks here catch mistakes, not malice: a plugin runs with nuvo's
/// privileges anyway.
pub(crate) unsafe fn read(
    ptr: *const PluginDescriptor,
    path: &Path,
) -> Result<(PluginInfo, Functions), PluginError> {
    let invalid = |message: String| PluginError::Descriptor { path: path.to_owned(), message };
    if ptr.is_null() {
        return Err(invalid("the entry function returned a null descriptor".into()));
    }
    if !ptr.cast::<u32>().is_aligned() {
        return Err(invalid("the descriptor is not aligned".into()));
    }
    // SAFETY: non-null and aligned; the caller guarantees at least a readable `u32`, which every ABI
    // version puts first.
    let found = unsafe { ptr.cast::<u32>().read() };
    if !(MIN_SUPPORTED_ABI_VERSION..=ABI_VERSION).contains(&found) {
        return Err(PluginError::AbiVersion { path: path.to_owned(), found });
    }
    if !ptr.is_aligned() {
        return Err(invalid("the descriptor is not aligned".into()));
    }
    // SAFETY: the version is one whose layout is `PluginDescriptor`, and the caller guarantees the
    // whole descriptor is readable for the process's lifetime.
    let d = unsafe { &*ptr };
    // SAFETY: forwarded from the caller: the strings and options table are readable as stated.
    let (info, functions) = unsafe { check(d, path) }.map_err(invalid)?;
    Ok((info, functions))
}

/// Every check after the version, as messages.
///
/// # Safety
/// As for [`read`].
unsafe fn check(d: &PluginDescriptor, path: &Path) -> Result<(PluginInfo, Functions), String> {
    let size = size_of::<PluginDescriptor>();
    if d.descriptor_size as usize != size {
        return Err(format!(
            "it is {} bytes long, but ABI {} descriptors are {size}",
            d.descriptor_size, d.abi_version
        ));
    }
    if d.flags & !KNOWN_FLAGS != 0 {
        return Err(format!("unknown flags {:#x}", d.flags & !KNOWN_FLAGS));
    }
    if d.flags & FLAG_CATCHES_PANICS == 0 {
        return Err("the plugin does not promise to catch its panics (it was probably built with \
                    panic = \"abort\", so a panic would abort training); build it with panic = \"unwind\", \
                    Rust's default"
            .into());
    }
    let reads = Quantities::from_bits(d.reads)
        .map_err(|bits| format!("it reads quantities this nuvo does not know (bits {bits:#x})"))?;
    if !(d.default_weight.is_finite() && d.default_weight >= 0.0) {
        return Err(format!("the default weight {} is not a non-negative number", d.default_weight));
    }
    // SAFETY (all `text` calls): forwarded from the caller.
    let name = unsafe { text(d.name, "the name", 64) }?;
    if !is_identifier(&name) {
        return Err(format!("the name {name:?} is not 1 to 64 bytes of a-z, 0-9 and _"));
    }
    let description = unsafe { text(d.description, "the description", MAX_DESCRIPTION) }?;
    // SAFETY: forwarded from the caller.
    let options = unsafe { options(d) }?;
    let missing = |f: &str| format!("it has no `{f}` function");
    let functions = Functions {
        create: d.create.ok_or_else(|| missing("create"))?,
        evaluate: d.evaluate.ok_or_else(|| missing("evaluate"))?,
        destroy: d.destroy.ok_or_else(|| missing("destroy"))?,
        free_string: d.free_string.ok_or_else(|| missing("free_string"))?,
    };
    let info = PluginInfo {
        path: path.to_owned(),
        abi_version: d.abi_version,
        name,
        description,
        default_weight: d.default_weight,
        options,
        reads,
    };
    Ok((info, functions))
}

/// The option table, copied.
///
/// # Safety
/// `d.options` must point at `d.options_len` readable [`OptionDoc`]s (checked against null and a
/// bound here), each with readable strings.
unsafe fn options(d: &PluginDescriptor) -> Result<Vec<PluginOption>, String> {
    if d.options_len > MAX_OPTIONS {
        return Err(format!("it documents {} options, more than {MAX_OPTIONS}", d.options_len));
    }
    if d.options_len == 0 {
        return Ok(Vec::new());
    }
    if d.options.is_null() || !d.options.is_aligned() {
        return Err("the option table is null or misaligned".into());
    }
    // SAFETY: non-null, aligned, and `options_len` (bounded) entries by the caller's guarantee.
    let docs: &[OptionDoc] = unsafe { std::slice::from_raw_parts(d.options, d.options_len) };
    docs.iter()
        .enumerate()
        .map(|(k, o)| {
            // SAFETY (all three): the caller guarantees each entry's strings are readable.
            let name = unsafe { text(o.name, &format!("the name of option {k}"), MAX_SHORT) }?;
            if name.is_empty() {
                return Err(format!("option {k} has an empty name"));
            }
            let default = unsafe { text(o.default, &format!("the default of option `{name}`"), MAX_SHORT) }?;
            let doc = unsafe { text(o.doc, &format!("the doc of option `{name}`"), MAX_DESCRIPTION) }?;
            Ok(PluginOption { name, default, doc })
        })
        .collect()
}

/// A descriptor string, checked for length and UTF-8, copied.
///
/// # Safety
/// `s.ptr` must be readable for `s.len` bytes when `s.len` is at most `max` and non-zero.
unsafe fn text(s: PluginStr, what: &str, max: usize) -> Result<String, String> {
    if s.len > max {
        return Err(format!("{what} is {} bytes long, more than {max}", s.len));
    }
    if s.len == 0 {
        return Ok(String::new());
    }
    if s.ptr.is_null() {
        return Err(format!("{what} is a null pointer with length {}", s.len));
    }
    // SAFETY: non-null, bounded, readable for `len` bytes by the caller's guarantee.
    let bytes = unsafe { std::slice::from_raw_parts(s.ptr, s.len) };
    std::str::from_utf8(bytes).map(str::to_owned).map_err(|e| format!("{what} is not UTF-8 ({e})"))
}

#[cfg(test)]
mod tests {
    use super::*;
    use nuvo_plugin_api::export::descriptor;
    use nuvo_plugin_api::{Gradients, Inputs, LossPlugin, Quantity};

    struct Probe;

    impl LossPlugin for Probe {
        const NAME: &'static str = "probe";
        const DESCRIPTION: &'static str = "a test plugin";
        const DEFAULT_WEIGHT: f32 = 0.5;
        const OPTIONS: &'static [OptionDoc] = &[OptionDoc::new("k", "1", "a knob")];
        const READS: Quantities = Quantities::of(&[Quantity::Tex, Quantity::Sigma]);
        fn new(_: &str) -> Result<Self, String> {
            Ok(Probe)
        }
        fn evaluate(&mut self, _: &Inputs<'_>, _: &mut Gradients<'_>) -> Result<f32, String> {
            Ok(0.0)
        }
    }

    fn read_one(d: &PluginDescriptor) -> Result<PluginInfo, String> {
        // SAFETY: `d` is a live descriptor whose strings are static.
        unsafe { read(d, Path::new("/p/libprobe.so")) }.map(|(i, _)| i).map_err(|e| e.to_string())
    }

    #[test]
    fn a_descriptor_from_the_safe_layer_reads_back_whole() {
        let info = read_one(&descriptor::<Probe>()).unwrap();
        assert_eq!(info.name, "probe");
        assert_eq!(info.abi_version, ABI_VERSION);
        assert_eq!(info.default_weight, 0.5);
        assert_eq!(info.reads, Probe::READS);
        assert_eq!(
            info.options,
            vec![PluginOption { name: "k".into(), default: "1".into(), doc: "a knob".into() }]
        );
    }

    #[test]
    fn only_the_version_is_read_from_an_unsupported_descriptor() {
        // A "descriptor" that is nothing but a version: reading any further would be out of bounds.
        #[repr(C, align(8))]
        struct Future(u32);
        let future = Future(999);
        let e = unsafe { read(std::ptr::from_ref(&future).cast(), Path::new("/p/libnew.so")) }.unwrap_err();
        let msg = e.to_string();
        assert!(matches!(e, PluginError::AbiVersion { found: 999, .. }), "{msg}");
        assert!(msg.contains("/p/libnew.so") && msg.contains("999") && msg.contains("rebuild"), "{msg}");
        let e = unsafe { read(std::ptr::null(), Path::new("/p/x.so")) }.unwrap_err();
        assert!(e.to_string().contains("null descriptor"));
    }

    #[test]
    fn each_broken_field_is_named() {
        let bad_utf8: &'static [u8] = b"caf\xe9";
        type Breakage = Box<dyn Fn(&mut PluginDescriptor)>;
        let cases: Vec<(Breakage, &str)> = vec![
            (Box::new(|d| d.descriptor_size = 8), "bytes long"),
            (Box::new(|d| d.flags = 0), "panic = \"abort\""),
            (Box::new(|d| d.flags |= 1 << 7), "unknown flags 0x80"),
            (Box::new(|d| d.reads |= 1 << 13), "bits 0x2000"),
            (Box::new(|d| d.default_weight = f32::NAN), "default weight"),
            (Box::new(|d| d.name = PluginStr::from_static("Has Caps")), "\"Has Caps\""),
            (
                Box::new(|d| d.name = PluginStr { ptr: std::ptr::null(), len: 3 }),
                "the name is a null pointer",
            ),
            (Box::new(move |d| d.description = PluginStr { ptr: bad_utf8.as_ptr(), len: 4 }), "not UTF-8"),
            (Box::new(|d| d.description.len = 1 << 40), "more than 4096"),
            (Box::new(|d| d.options_len = 1000), "1000 options"),
            (Box::new(|d| d.options = std::ptr::null()), "option table is null"),
            (Box::new(|d| d.evaluate = None), "no `evaluate` function"),
        ];
        for (break_it, expected) in cases {
            let mut d = descriptor::<Probe>();
            break_it(&mut d);
            let e = read_one(&d).unwrap_err();
            assert!(e.contains(expected) && e.contains("/p/libprobe.so"), "expected {expected:?} in {e}");
        }
    }
}

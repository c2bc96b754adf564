//! Loading plugins: every bad file gets a clear error naming the path and the cause; good plugins
//! describe themselves.

use std::path::Path;

use nuvo_plugin_api::{ABI_VERSION, Quantities, Quantity};
use nuvo_plugin_host::{PluginError, describe_plugin, load_loss_plugin};
use nuvo_plugin_tests::plugins;

fn options(text: &str) -> toml::Table {
    toml::from_str(text).unwrap()
}

/// The error of loading `path` with `opts`, checked to name the path.
fn load_error(path: &Path, opts: &str) -> PluginError {
    let e = load_loss_plugin(path, &options(opts)).err().expect("the plugin should be refused");
    let shown = e.to_string();
    let name = path.file_name().unwrap().to_string_lossy();
    assert!(shown.contains(&*name), "the error does not name {}: {shown}", path.display());
    e
}

#[test]
fn a_missing_file_a_directory_and_a_text_file_are_refused_for_what_they_are() {
    let dir = tempfile::tempdir().unwrap();
    let e = load_error(&dir.path().join("libnothing.so"), "");
    assert!(matches!(e, PluginError::NotFound { .. }) && e.to_string().contains("no such file"), "{e}");

    let folder = dir.path().join("libfolder.so");
    std::fs::create_dir(&folder).unwrap();
    let e = load_error(&folder, "");
    assert!(matches!(e, PluginError::NotAFile { .. }) && e.to_string().contains("directory"), "{e}");

    let text = dir.path().join("libnotes.so");
    std::fs::write(&text, "these are my notes, not a library\n").unwrap();
    let e = load_error(&text, "");
    assert!(matches!(e, PluginError::NotALibrary { .. }), "{e}");
    assert!(e.to_string().contains("not a shared library this system can load"), "{e}");
}

#[test]
fn a_library_without_the_entry_symbol_says_what_is_expected() {
    let e = load_error(plugins().path("no_entry"), "");
    assert!(matches!(e, PluginError::MissingEntry { .. }), "{e}");
    let msg = e.to_string();
    assert!(msg.contains("`nuvo_loss_plugin`") && msg.contains("export_loss_plugin!"), "{msg}");
}

#[test]
fn a_plugin_from_another_abi_version_is_refused_with_both_versions_and_the_fix() {
    let e = load_error(plugins().path("future_abi"), "");
    assert!(matches!(e, PluginError::AbiVersion { found: 999, .. }), "{e}");
    let msg = e.to_string();
    assert!(msg.contains("version 999") && msg.contains(&format!("to {ABI_VERSION}")), "{msg}");
    assert!(msg.contains("rebuild the plugin"), "{msg}");
    // Refusing it changed nothing: describing it fails the same way.
    assert!(matches!(describe_plugin(plugins().path("future_abi")), Err(PluginError::AbiVersion { .. })));
}

#[test]
fn the_example_describes_itself() {
    let info = describe_plugin(plugins().path("symmetric_dirichlet")).unwrap();
    assert_eq!(info.name, "symmetric_dirichlet");
    assert_eq!(info.abi_version, ABI_VERSION);
    assert_eq!(info.reads, Quantities::of(&[Quantity::ChartProbs, Quantity::UvDifferentials]));
    assert_eq!(info.default_weight, 0.01);
    let names: Vec<&str> = info.options.iter().map(|o| o.name.as_str()).collect();
    assert_eq!(names, ["scale", "floor"]);
    assert!(info.path.is_absolute() && info.description.contains("Dirichlet"));
    // Loading again reuses the library and gives the same answer.
    assert_eq!(describe_plugin(plugins().path("symmetric_dirichlet")).unwrap(), info);
}

#[test]
fn options_go_to_the_plugin_and_its_refusals_come_back() {
    let lib = plugins().path("symmetric_dirichlet");
    let (_, info) = load_loss_plugin(lib, &options("scale = 0.5\nfloor = 0.0")).unwrap();
    assert_eq!(info.name, "symmetric_dirichlet");
    let e = load_error(lib, "flor = 1e-3");
    assert!(
        matches!(&e, PluginError::Options { message, .. }
        if message == "unknown field `flor`, expected `scale` or `floor`"),
        "{e}"
    );
    let e = load_error(lib, "scale = -2.0");
    assert!(e.to_string().contains("`scale` must be a positive number"), "{e}");
}

#[test]
fn a_panic_while_creating_is_an_error_not_a_crash() {
    let e = load_error(plugins().path("misbehaving"), "mode = \"panic_in_new\"");
    assert!(matches!(e, PluginError::Create { .. }), "{e}");
    assert!(e.to_string().contains("panicked: misbehaving: panic in new, as asked"), "{e}");
}

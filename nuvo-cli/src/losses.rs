//! `nuvo losses`: the built-in losses and any loss plugins given with `--plugin`, with their default
//! weights, options and (for plugins) the quantities they read and the config lines that use them.

use std::fmt::Write;
use std::path::{Path, PathBuf};

use nuvo_losses::{LossInfo, LossRegistry};
use nuvo_plugin_host::{PluginInfo, describe_plugin};

/// Arguments of `nuvo losses`.
#[derive(clap::Args, Debug)]
pub struct LossesArgs {
    /// A loss plugin (shared library built with nuvo-plugin-api) to load and describe; repeatable.
    #[arg(long = "plugin", value_name = "PATH")]
    pub plugins: Vec<PathBuf>,
}

/// Runs `nuvo losses`: loads every plugin first (a bad one is an error naming its path), then prints.
pub fn run(args: &LossesArgs) -> anyhow::Result<()> {
    let plugins = args.plugins.iter().map(|p| describe_plugin(p)).collect::<Result<Vec<_>, _>>()?;
    print!("{}", listing(&LossRegistry::with_builtins(), &plugins));
    Ok(())
}

/// The whole listing.
fn listing(registry: &LossRegistry, plugins: &[PluginInfo]) -> String {
    let mut out = String::from(
        "Built-in losses (a [losses.NAME] table in a config enables one; every table also takes\n\
         `weight` and `warmup_steps`, which ramps the weight in linearly over the first steps):\n",
    );
    for info in registry.list() {
        builtin(&mut out, info);
    }
    for info in plugins {
        plugin(&mut out, info);
    }
    if plugins.is_empty() {
        out.push_str("\nLoss plugins: pass --plugin PATH to describe one (see plugins/README.md).\n");
    }
    out
}

/// One built-in loss.
fn builtin(out: &mut String, info: &LossInfo) {
    heading(out, info.name, info.default_weight, info.summary);
    options(out, info.options.iter().map(|o| (o.name, o.default, o.doc)));
}

/// One plugin: its descriptor, and the config lines that use it.
fn plugin(out: &mut String, info: &PluginInfo) {
    let _ = writeln!(out, "\nPlugin {} (plugin ABI {}):", info.path.display(), info.abi_version);
    heading(out, &info.name, info.default_weight, &info.description);
    let _ = writeln!(out, "      reads: {}", info.reads);
    options(out, info.options.iter().map(|o| (o.name.as_str(), o.default.as_str(), o.doc.as_str())));
    let _ = writeln!(out, "      use: [losses.{}]\n           plugin = {}", info.name, toml_path(&info.path));
}

fn heading(out: &mut String, name: &str, weight: f32, summary: &str) {
    let _ = writeln!(out, "\n  {name:<20} default weight {weight}\n      {summary}");
}

fn options<'a>(out: &mut String, options: impl Iterator<Item = (&'a str, &'a str, &'a str)>) {
    let mut any = false;
    for (name, default, doc) in options {
        if !any {
            out.push_str("      options:\n");
            any = true;
        }
        let _ = writeln!(out, "        {name} = {default}\n            {doc}");
    }
    if !any {
        out.push_str("      options: none besides weight\n");
    }
}

/// `path` as a TOML string: a literal string when it can be one, else Rust's escaping (which agrees
/// with TOML's for the characters paths contain).
fn toml_path(path: &Path) -> String {
    let s = path.to_string_lossy();
    if s.contains('\'') || s.chars().any(char::is_control) { format!("{s:?}") } else { format!("'{s}'") }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nuvo_plugin_host::{PluginOption, Quantities, Quantity};

    #[test]
    fn built_ins_are_listed_with_weights_and_options() {
        let text = listing(&LossRegistry::with_builtins(), &[]);
        for name in
            ["cycle_3d", "cycle_2d", "entropy", "surface", "cluster", "conformal", "stretch", "texture"]
        {
            assert!(text.contains(&format!("\n  {name} ")), "{name} missing:\n{text}");
        }
        assert!(text.contains("area = \"paper\""), "{text}");
        assert!(text.contains("default weight 0.04"), "{text}");
        assert!(text.contains("--plugin PATH"), "{text}");
    }

    #[test]
    fn plugins_show_what_they_read_and_how_to_use_them() {
        let info = PluginInfo {
            path: PathBuf::from("/opt/plugins/libiso.so"),
            abi_version: 1,
            name: "iso".into(),
            description: "isometric distortion".into(),
            default_weight: 0.01,
            options: vec![PluginOption {
                name: "floor".into(),
                default: "0.1".into(),
                doc: "det floor".into(),
            }],
            reads: Quantities::of(&[Quantity::ChartProbs]),
        };
        let text = listing(&LossRegistry::new(), &[info]);
        assert!(text.contains("Plugin /opt/plugins/libiso.so (plugin ABI 1):"), "{text}");
        assert!(text.contains("reads: chart_probs") && text.contains("floor = 0.1"), "{text}");
        assert!(text.contains("[losses.iso]\n           plugin = '/opt/plugins/libiso.so'"), "{text}");
        assert!(!text.contains("--plugin PATH"));
    }
}

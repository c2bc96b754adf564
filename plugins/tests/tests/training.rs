//! Training with plugin losses: the example trains and changes the result; plugin configs are checked
//! with located errors; misbehaving plugins fail the step with a clear error and never take the
//! trainer down.

use std::path::Path;

use nuvo_core::config::{self, LoadedConfig};
use nuvo_core::run::{RunOptions, Silent, files, run};
use nuvo_core::{TrainError, Trainer};
use nuvo_losses::LossRegistry;
use nuvo_plugin_tests::{SMALL, plugins, sources, toml_string};

fn small(extra: &str) -> LoadedConfig {
    config::from_str("small.toml", &format!("{SMALL}{extra}")).unwrap()
}

fn trainer(cfg: &LoadedConfig) -> Result<Trainer, TrainError> {
    Trainer::new(cfg, &sources(), &LossRegistry::with_builtins())
}

fn param_values(t: &Trainer) -> Vec<f32> {
    let p = t.params();
    p.ids().flat_map(|id| p.value(id).data().to_vec()).collect()
}

/// A `[losses.NAME]` table loading the library `lib` with extra lines.
fn plugin_table(name: &str, lib: &Path, extra: &str) -> String {
    format!("[losses.{name}]\nplugin = {}\n{extra}", toml_string(lib))
}

const BASE: &str = "[losses.cycle_3d]\n[losses.surface]\n";

#[test]
fn the_example_plugin_trains_appears_in_the_log_and_changes_the_result() {
    let dir = tempfile::tempdir().unwrap();
    // The config sits in a folder with a copy of the library, named relative to the config.
    let folder = dir.path().join("experiment");
    std::fs::create_dir_all(folder.join("plugins")).unwrap();
    let lib = plugins().path("symmetric_dirichlet");
    let copy = folder.join("plugins").join(lib.file_name().unwrap());
    std::fs::copy(lib, &copy).unwrap();
    let table = format!(
        "[losses.isometric]\nplugin = \"plugins/{}\"\nweight = 0.05\n",
        copy.file_name().unwrap().to_string_lossy()
    );
    let config_path = folder.join("nuvo.toml");
    std::fs::write(&config_path, format!("{SMALL}{BASE}{table}")).unwrap();
    let cfg = config::load(&config_path, &["training.steps=12".into()]).unwrap();
    let mut with = trainer(&cfg).unwrap();
    let names: Vec<&str> = with.terms().iter().map(|t| t.name.as_str()).collect();
    assert_eq!(names, ["cycle_3d", "isometric", "surface"]);
    let out = dir.path().join("run");
    let summary = run(&mut with, &RunOptions { out_dir: out.clone(), resume: false }, &mut Silent).unwrap();
    assert_eq!((summary.steps, summary.skipped), (12, 0));

    let log = std::fs::read_to_string(out.join(files::LOG)).unwrap();
    assert_eq!(log.lines().count(), 12);
    for line in log.lines() {
        let line: serde_json::Value = serde_json::from_str(line).unwrap();
        let e = line["terms"]["isometric"].as_f64().expect("the plugin's term is logged every step");
        // E ≥ 4 per sample and chart (up to 2·floor² = 0.02 with the default floor), and c(x) sums to 1.
        assert!(e >= 3.97 && e.is_finite(), "symmetric Dirichlet energy {e}");
    }

    let mut without = trainer(&config::from_str("c.toml", &format!("{SMALL}{BASE}")).unwrap()).unwrap();
    for _ in 0..12 {
        without.step().unwrap();
    }
    assert_ne!(param_values(&with), param_values(&without), "the plugin term changed nothing");
}

#[test]
fn training_on_the_plugin_term_alone_lowers_it() {
    // The plugin's gradient reaches the networks through the tape with the right sign. A floor of 1
    // smooths the barrier, so the random initialisation's fold lines do not dominate (see the example).
    let table = plugin_table(
        "isometric",
        plugins().path("symmetric_dirichlet"),
        "weight = 1.0\nscale = 0.5\nfloor = 1.0\n",
    );
    let mut t = trainer(&small(&table)).unwrap();
    let first = t.step().unwrap().total;
    let mut last = first;
    for _ in 0..30 {
        last = t.step().unwrap().total;
    }
    assert!(last < 0.9 * first, "symmetric Dirichlet went from {first} to {last}");
}

#[test]
fn plugin_config_mistakes_name_the_key_and_line() {
    let missing = small(&format!("{BASE}[losses.iso]\nweight = 0.1\nplugin = \"nowhere/libiso.so\"\n"));
    let e = trainer(&missing).err().unwrap().to_string();
    assert!(
        e.contains("losses.iso.plugin") && e.contains("line 21") && e.contains("nowhere/libiso.so"),
        "{e}"
    );
    assert!(e.contains("no such file"), "{e}");

    let not_a_string = small("[losses.iso]\nplugin = 3\n");
    let e = trainer(&not_a_string).err().unwrap().to_string();
    assert!(e.contains("losses.iso.plugin") && e.contains("must be a string"), "{e}");

    let lib = plugins().path("symmetric_dirichlet");
    let bad_option = small(&format!("{BASE}{}", plugin_table("iso", lib, "weight = 0.1\nflor = 1e-3\n")));
    let e = trainer(&bad_option).err().unwrap().to_string();
    assert!(e.contains("losses.iso.flor") && e.contains("line 22") && e.contains("`floor`"), "{e}");

    // Without `weight`, the plugin's own default applies.
    let t = trainer(&small(&plugin_table("iso", lib, ""))).unwrap();
    assert_eq!(t.terms()[0].weight, 0.01);
}

/// A trainer whose only term is the `misbehaving` fixture in `mode`, plus cycle_3d.
fn misbehaving(mode: &str) -> Trainer {
    let table = plugin_table("bad", plugins().path("misbehaving"), &format!("mode = \"{mode}\"\n"));
    trainer(&small(&format!("[losses.cycle_3d]\n{table}"))).unwrap()
}

/// The error of the next step, checked to name the plugin's library.
fn step_error(t: &mut Trainer, library: &str) -> String {
    let e = t.step().expect_err("the step should fail").to_string();
    assert!(e.contains(library), "the error does not name {library}: {e}");
    e
}

#[test]
fn a_plugin_that_panics_fails_the_step_and_is_never_called_again() {
    let mut t = misbehaving("panic");
    let before = param_values(&t);
    let e = step_error(&mut t, "libmisbehaving");
    assert!(e.contains("panicked: misbehaving: panic in evaluate, as asked"), "{e}");
    let e = step_error(&mut t, "libmisbehaving");
    assert!(e.contains("not called again after it panicked"), "{e}");
    assert_eq!(param_values(&t), before, "a failed step changed the parameters");
}

#[test]
fn a_plugin_error_fails_that_step_only() {
    let mut t = misbehaving("error_once");
    let e = step_error(&mut t, "libmisbehaving");
    assert!(e.contains("loss `misbehaving` failed") && e.contains("failing the first call, as asked"), "{e}");
    let o = t.step().unwrap();
    assert!(o.skipped.is_none() && o.terms.iter().any(|(n, v)| n == "bad" && v.is_finite()), "{o:?}");
}

#[test]
fn a_nan_value_skips_the_step_like_any_loss_and_a_nan_gradient_is_an_error() {
    let mut t = misbehaving("nan_value");
    let before = param_values(&t);
    let o = t.step().unwrap();
    assert_eq!(o.skipped.as_deref(), Some("loss `bad` is NaN"));
    assert_eq!(param_values(&t), before);

    let mut t = misbehaving("nan_gradient");
    let e = step_error(&mut t, "libmisbehaving");
    assert!(
        e.contains("gradient with respect to `tex` is NaN at row 257 (chart 1, sample 1), column 1"),
        "{e}"
    );
}

#[test]
fn raw_abi_breaches_of_the_output_contract_are_caught() {
    let lib = plugins().path("raw_abi");
    let cases = [
        ("overrun", "wrote past the end of the gradient buffer of `tex` (512×2 values)"),
        ("retarget", "changed the pointer or shape of the gradient buffer of `tex`"),
        ("unknown_status", "unknown status 42"),
        ("silent_error", "no message"),
    ];
    for (mode, expected) in cases {
        let table = plugin_table("raw", lib, &format!("mode = \"{mode}\"\n"));
        let mut t = trainer(&small(&table)).unwrap();
        let e = step_error(&mut t, "libraw_abi");
        assert!(e.contains(expected), "{mode}: {e}");
    }
    let mut t = trainer(&small(&plugin_table("raw", lib, "mode = \"ok\"\n"))).unwrap();
    assert_eq!(t.step().unwrap().terms, vec![("raw".to_owned(), 1.0)]);
}

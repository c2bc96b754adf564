//! Every config shipped in `configs/` loads, builds its geometry and losses, trains two steps, and
//! bakes, exports and measures the result (with the pictures and metrics shrunk so this stays
//! quick). Configs that read `../shared/data/` need the test data beside the clone, as in CI.

use std::path::{Path, PathBuf};

use nuvo_core::ablation;
use nuvo_core::outputs::write_outputs;
use nuvo_core::run::{RunOptions, Silent, run};
use nuvo_core::{Trainer, config};
use nuvo_geometry::SourceRegistry;
use nuvo_losses::LossRegistry;

fn configs_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../configs")
}

fn all_configs(dir: &Path, out: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).unwrap() {
        let p = entry.unwrap().path();
        if p.is_dir() {
            all_configs(&p, out);
        } else if p.extension().is_some_and(|e| e == "toml") {
            out.push(p);
        }
    }
    out.sort();
}

/// Overrides that keep a config's geometry, model and losses but make the run short.
const QUICK: &[&str] = &[
    "training.steps=2",
    "output.eval_views=1",
    "output.eval_resolution=64",
    "output.renders=1",
    "output.render_resolution=32",
    "output.atlas_resolution=256",
];

fn train_two_steps(path: &Path, extra: &[String], out: &Path) -> Result<(), String> {
    let overrides: Vec<String> = QUICK.iter().map(|s| s.to_string()).chain(extra.iter().cloned()).collect();
    let loaded = config::load(path, &overrides).map_err(|e| e.to_string())?;
    let mut trainer = Trainer::new(&loaded, &SourceRegistry::with_builtins(), &LossRegistry::with_builtins())
        .map_err(|e| e.to_string())?;
    run(&mut trainer, &RunOptions { out_dir: out.to_owned(), resume: false }, &mut Silent)
        .map_err(|e| e.to_string())?;
    let report = write_outputs(&mut trainer.atlas(), Some(trainer.source()), out, &loaded.config.output)
        .map_err(|e| e.to_string())?;
    let metrics = report.metrics.ok_or("no metrics: the config has no mesh to bake onto")?;
    let i = &metrics.metrics.image;
    for (name, v) in [("boundary", i.boundary), ("stretch", i.stretch), ("conformal", i.conformal)] {
        if !(0.0..=1.0).contains(&v) {
            return Err(format!("{name} = {v}"));
        }
    }
    Ok(())
}

#[test]
fn every_shipped_config_trains_bakes_and_measures() {
    let mut configs = Vec::new();
    all_configs(&configs_dir(), &mut configs);
    assert!(configs.len() >= 8, "{configs:?}");
    let tmp = tempfile::tempdir().unwrap();
    let mut failures = Vec::new();
    for (k, path) in configs.iter().enumerate() {
        let out = tmp.path().join(format!("run{k}"));
        // Paper-sized configs keep their networks but train on smaller batches here.
        let extra: Vec<String> = if path.components().any(|c| c.as_os_str() == "paper") {
            vec!["training.batch_3d=512".into(), "training.batch_uv=512".into()]
        } else {
            Vec::new()
        };
        let started = std::time::Instant::now();
        let result = train_two_steps(path, &extra, &out);
        eprintln!("{}: {:?} ({:.1} s)", path.display(), result, started.elapsed().as_secs_f64());
        if let Err(e) = result {
            failures.push(format!("{}: {e}", path.display()));
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

#[test]
fn every_ablation_variant_of_the_shipped_sweeps_loads() {
    let dir = configs_dir().join("ablations");
    let mut configs = Vec::new();
    all_configs(&dir, &mut configs);
    assert!(!configs.is_empty());
    for path in configs {
        let base = config::load(&path, &[]).unwrap();
        let variants = ablation::plan(&base);
        assert!(variants.len() >= 2, "{}", path.display());
        for v in &variants {
            let loaded = ablation::load_variant(&path, &[], v)
                .unwrap_or_else(|e| panic!("{} variant {}: {e}", path.display(), v.name));
            let names: Vec<&String> = loaded.config.losses.iter().flat_map(|l| l.keys()).collect();
            for removed in &v.remove {
                assert!(!names.contains(&removed), "{} still has {removed}", v.name);
            }
        }
    }
}

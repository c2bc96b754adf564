//! Helpers shared by the CLI's end-to-end tests: the binary, the repo, a tiny experiment config.
#![allow(dead_code)] // each test file uses its own subset

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

pub fn nuvo() -> Command {
    Command::new(env!("CARGO_BIN_EXE_nuvo"))
}

pub fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).parent().unwrap().to_path_buf()
}

/// The `[model]` table of the smallest networks the end-to-end tests train: two charts of 2×16 MLPs,
/// 8² normal grids. Fast enough for a few steps of any source.
pub const SMALLEST_MODEL: &str = "[model]\ncharts = 2\ndepth = 2\nwidth = 16\ngrid_resolution = 8\n";

/// `--set` values that make one `nuvo unwrap` take seconds; everything else is what it chooses
/// (the unwrap and batch tests).
pub const FAST_UNWRAP: &[&str] = &[
    "training.steps=12",
    "training.batch_3d=256",
    "training.batch_uv=256",
    "model.depth=2",
    "model.width=16",
    "model.grid_resolution=8",
    "warm_start.samples=2000",
    "output.atlas_resolution=256",
    "output.eval_views=2",
    "output.eval_resolution=64",
    "output.renders=1",
    "output.render_resolution=64",
];

/// A small experiment on the bundled bunny, written into `dir`.
pub fn tiny_config(dir: &Path, steps: u64, checkpoint_every: u64) -> PathBuf {
    tiny_config_for(dir, &repo().join("assets/stanford-bunny.obj"), steps, checkpoint_every)
}

/// A small experiment on the mesh at `bunny`, written into `dir`.
pub fn tiny_config_for(dir: &Path, bunny: &Path, steps: u64, checkpoint_every: u64) -> PathBuf {
    let text = format!(
        r#"seed = 3
[geometry]
source = "mesh"
path = {bunny:?}
[model]
charts = 2
depth = 3
width = 24
grid_resolution = 16
[training]
steps = {steps}
batch_3d = 256
batch_uv = 256
checkpoint_every = {checkpoint_every}
[optimizer]
lr_mlp = 2e-3
[output]
dir = "unused"
atlas_resolution = 256
eval_views = 2
eval_resolution = 96
renders = 1
render_resolution = 96
"#
    );
    let p = dir.join("tiny.toml");
    std::fs::write(&p, text).unwrap();
    p
}

/// `nuvo train CFG --out OUT --no-bake`, run to completion: a run folder without the atlas outputs.
pub fn train_unbaked(cfg: &Path, out: &Path) -> Output {
    run(nuvo().arg("train").arg(cfg).arg("--out").arg(out).arg("--no-bake"))
}

pub fn run(cmd: &mut Command) -> Output {
    let out = cmd.output().expect("nuvo runs");
    if !out.status.success() {
        eprintln!(
            "stdout:\n{}\nstderr:\n{}",
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        );
    }
    out
}

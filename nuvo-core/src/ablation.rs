//! Ablation sweeps: the base config, one variant per removed loss, and any named variants (other
//! chart counts, weights, ...), each trained, baked and measured into its own folder, then summarised
//! in the paper's ablation table (Boundary, Stretch, Conformal, UV efficiency, average).
//!
//! The sweep is described by the config's optional `[ablation]` table:
//!
//! ```toml
//! [ablation]
//! remove_each = ["cycle_3d", "texture"]     # one "w/o NAME" variant each; absent: every loss
//! [[ablation.variants]]
//! name = "w/o distortion"
//! remove = ["conformal", "stretch"]         # losses to drop
//! [[ablation.variants]]
//! name = "n=1"
//! set = ["model.charts=1"]                  # `--set` overrides
//! ```
//!
//! Variants are built from the config *file* (plus the command line's overrides) by editing the TOML
//! tree, so each one is checked exactly like a config a user wrote, and its run folder holds an
//! ordinary resolved config that `nuvo train --resume` or `nuvo bake` understands.

use std::path::{Path, PathBuf};

use nuvo_geometry::SourceRegistry;
use nuvo_losses::LossRegistry;
use nuvo_losses::builtin::PAPER;
use serde::{Deserialize, Serialize};

use crate::config::{self, ConfigError, ConfigSource, LoadedConfig};
use crate::outputs::{OutputError, OutputMetrics, write_outputs};
use crate::run::{Observer, RunOptions, run};
use crate::trainer::{TrainError, Trainer};

/// One planned run of a sweep.
#[derive(Clone, Debug, PartialEq)]
pub struct Variant {
    /// Row label.
    pub name: String,
    /// Folder name inside the sweep's output folder; unique within the sweep.
    pub dir_name: String,
    /// Losses removed from the base config.
    pub remove: Vec<String>,
    /// Overrides applied after the command line's.
    pub set: Vec<String>,
}

/// The runs of a sweep, in order: the base (unless disabled), one per removed loss, then the named
/// variants. `base` is the loaded base config (without a `[losses]` table it trains the paper's
/// eight, `nuvo_losses::builtin::PAPER`).
pub fn plan(base: &LoadedConfig) -> Vec<Variant> {
    let spec = base.config.ablation.clone().unwrap_or_default();
    let mut named: Vec<(String, Vec<String>, Vec<String>)> = Vec::new();
    if spec.base {
        named.push(("base".to_owned(), Vec::new(), Vec::new()));
    }
    let removable = spec.remove_each.unwrap_or_else(|| base_losses(base));
    for loss in removable {
        named.push((format!("w/o {loss}"), vec![loss], Vec::new()));
    }
    for v in spec.variants {
        named.push((v.name, v.remove, v.set));
    }
    let mut taken: Vec<String> = Vec::new();
    named
        .into_iter()
        .map(|(name, remove, set)| {
            let dir_name = unique_slug(&name, &taken);
            taken.push(dir_name.clone());
            Variant { name, dir_name, remove, set }
        })
        .collect()
}

/// Names of the losses the base config trains with.
fn base_losses(base: &LoadedConfig) -> Vec<String> {
    match &base.config.losses {
        Some(map) => map.keys().cloned().collect(),
        None => PAPER.iter().map(|&n| n.to_owned()).collect(),
    }
}

/// A folder name for `name`: lowercase ASCII letters, digits, `-` and `_` (`w/o cycle_3d` →
/// `wo_cycle_3d`), suffixed `_2`, `_3`, ... when already taken.
fn unique_slug(name: &str, taken: &[String]) -> String {
    let mut slug = String::new();
    for ch in name.chars() {
        match ch {
            c if c.is_ascii_alphanumeric() || c == '-' || c == '_' => slug.push(c.to_ascii_lowercase()),
            '=' | '.' => slug.push('-'),
            '/' => {}
            _ if !slug.ends_with('_') && !slug.is_empty() => slug.push('_'),
            _ => {}
        }
    }
    let slug = slug.trim_matches('_').to_owned();
    let slug = if slug.is_empty() { "variant".to_owned() } else { slug };
    let mut candidate = slug.clone();
    let mut k = 2;
    while taken.contains(&candidate) {
        candidate = format!("{slug}_{k}");
        k += 1;
    }
    candidate
}

/// Loads the config file at `path` as `variant` sees it: the command line's `overrides`, then the
/// variant's own, then its losses removed and the `[ablation]` table dropped. A file without a
/// `[losses]` table gets the paper's eight listed first, at their paper weights.
pub fn load_variant(
    path: &Path,
    overrides: &[String],
    variant: &Variant,
) -> Result<LoadedConfig, ConfigError> {
    let all: Vec<String> = overrides.iter().chain(&variant.set).cloned().collect();
    config::load_edited(path, &all, |tree, src| {
        tree.remove("ablation");
        remove_losses(tree, &variant.remove, src)
    })
}

fn remove_losses(tree: &mut toml::Table, remove: &[String], src: &ConfigSource) -> Result<(), ConfigError> {
    if remove.is_empty() {
        return Ok(());
    }
    let losses = tree.entry("losses").or_insert_with(|| {
        let defaults = PAPER.iter().map(|&n| (n.to_owned(), toml::Value::Table(toml::Table::new())));
        toml::Value::Table(defaults.collect())
    });
    let Some(losses) = losses.as_table_mut() else {
        return Err(src.invalid("losses", "must be a table of loss tables"));
    };
    for name in remove {
        if losses.remove(name).is_none() {
            let known: Vec<&str> = losses.keys().map(String::as_str).collect();
            return Err(src.invalid(
                "ablation",
                format!("cannot remove loss `{name}`: the base config has {}", known.join(", ")),
            ));
        }
    }
    Ok(())
}

/// The table's numbers for one run.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Scores {
    pub boundary: f64,
    pub stretch: f64,
    pub conformal: f64,
    /// Fraction of the atlas covered by the baked UV triangles (the paper's "UV Eff.").
    pub uv_efficiency: f64,
    pub editability: f64,
    /// Steps trained.
    pub steps: u64,
}

impl Scores {
    /// The paper's "Avg.": the mean of Boundary, Stretch, Conformal and UV efficiency.
    pub fn average(&self) -> f64 {
        (self.boundary + self.stretch + self.conformal + self.uv_efficiency) / 4.0
    }

    /// The numbers of a run's `metrics.json` contents.
    pub fn from_metrics(m: &OutputMetrics) -> Self {
        let i = &m.metrics.image;
        Scores {
            boundary: i.boundary,
            stretch: i.stretch,
            conformal: i.conformal,
            uv_efficiency: m.metrics.uv.utilisation,
            editability: i.editability,
            steps: m.steps,
        }
    }

    /// Reads the numbers back from a finished run's `metrics.json` (for resuming a sweep); `None`
    /// when the file is missing or not a complete metrics file.
    pub fn read(path: &Path) -> Option<Self> {
        use crate::outputs::metric_paths as at;
        let v: serde_json::Value = serde_json::from_slice(&std::fs::read(path).ok()?).ok()?;
        let number = |pointer: &str| v.pointer(pointer)?.as_f64();
        Some(Scores {
            boundary: number(at::BOUNDARY)?,
            stretch: number(at::STRETCH)?,
            conformal: number(at::CONFORMAL)?,
            uv_efficiency: number(at::UV_EFFICIENCY)?,
            editability: number(at::EDITABILITY)?,
            steps: v.pointer(at::STEPS)?.as_u64()?,
        })
    }
}

/// A variant's numbers when its run in `dir` has trained all of its `planned` steps, else why
/// not: what a resumed sweep reuses and what `nuvo ablate --collect` tables.
pub fn finished_scores(dir: &Path, planned: u64) -> Result<Scores, String> {
    match Scores::read(&dir.join(crate::outputs::names::METRICS)) {
        Some(s) if s.steps >= planned => Ok(s),
        Some(s) => Err(format!("unfinished: {} of {planned} steps", s.steps)),
        None => Err(format!("not run yet (no metrics.json in {})", dir.display())),
    }
}

/// Why a variant produced no numbers.
#[derive(Debug, thiserror::Error)]
pub enum VariantError {
    #[error(transparent)]
    Config(#[from] ConfigError),
    #[error(transparent)]
    Train(#[from] TrainError),
    #[error(transparent)]
    Output(#[from] OutputError),
    #[error(
        "the geometry has no mesh to measure (set output.bake_mesh, or keep a density grid's extract_mesh on)"
    )]
    NoMesh,
}

/// Trains, bakes and measures one loaded variant into `dir`. With `resume`, a folder whose
/// `metrics.json` already holds complete numbers for the configured steps is not run again, and a
/// partial run continues from its checkpoint.
pub fn run_variant(
    loaded: &LoadedConfig,
    dir: &Path,
    resume: bool,
    registries: (&SourceRegistry, &LossRegistry),
    observer: &mut dyn Observer,
) -> Result<Scores, VariantError> {
    if resume && let Ok(done) = finished_scores(dir, loaded.config.training.steps) {
        observer.note(&format!("{} already finished; reusing its metrics", dir.display()));
        return Ok(done);
    }
    let mut trainer = Trainer::new(loaded, registries.0, registries.1)?;
    let resume = resume && dir.join(crate::run::files::CHECKPOINT).exists();
    run(&mut trainer, &RunOptions { out_dir: dir.to_owned(), resume }, observer)?;
    let report = write_outputs(&mut trainer.atlas(), Some(trainer.source()), dir, &loaded.config.output)?;
    report.metrics.as_ref().map(Scores::from_metrics).ok_or(VariantError::NoMesh)
}

/// One row of the table: a variant and its numbers or the reason it has none.
#[derive(Clone, Debug)]
pub struct Row {
    pub name: String,
    pub dir: PathBuf,
    pub result: Result<Scores, String>,
    /// Training seconds of the variant: its run log's `seconds`, over every session that trained
    /// it (so a resumed sweep reports whole runs), or the wall time spent on it when it has no log.
    pub seconds: f64,
}

/// The paper's ablation table as Markdown; the best average is bold, failed variants say why.
pub fn markdown_table(rows: &[Row]) -> String {
    let best = rows
        .iter()
        .filter_map(|r| r.result.as_ref().ok().map(Scores::average))
        .fold(f64::NEG_INFINITY, f64::max);
    let mut out = String::from(
        "| Variant | Bound. | Stretch | Conf. | UV Eff. | Avg. | Editability | Steps | Time (s) |\n\
         |---|---|---|---|---|---|---|---|---|\n",
    );
    for r in rows {
        let name = r.name.replace('|', "\\|");
        match &r.result {
            Ok(s) => {
                let avg = s.average();
                let avg = if avg == best { format!("**{avg:.3}**") } else { format!("{avg:.3}") };
                out += &format!(
                    "| {name} | {:.3} | {:.3} | {:.3} | {:.3} | {avg} | {:.3} | {} | {:.0} |\n",
                    s.boundary, s.stretch, s.conformal, s.uv_efficiency, s.editability, s.steps, r.seconds
                );
            }
            Err(e) => {
                let e = e.replace('|', "\\|").replace('\n', " ");
                out += &format!("| {name} | failed: {e} | | | | | | | {:.0} |\n", r.seconds);
            }
        }
    }
    out
}

/// The same table as CSV (six decimals; one header line; `status` is `ok` or `failed`, `error` says why).
pub fn csv_table(rows: &[Row]) -> String {
    let mut out = String::from(
        "variant,dir,boundary,stretch,conformal,uv_efficiency,average,editability,steps,seconds,status,error\n",
    );
    for r in rows {
        let dir = r.dir.display().to_string();
        let line = match &r.result {
            Ok(s) => format!(
                "{},{},{:.6},{:.6},{:.6},{:.6},{:.6},{:.6},{},{:.1},ok,",
                csv_field(&r.name),
                csv_field(&dir),
                s.boundary,
                s.stretch,
                s.conformal,
                s.uv_efficiency,
                s.average(),
                s.editability,
                s.steps,
                r.seconds
            ),
            Err(e) => {
                format!(
                    "{},{},,,,,,,,{:.1},failed,{}",
                    csv_field(&r.name),
                    csv_field(&dir),
                    r.seconds,
                    csv_field(e)
                )
            }
        };
        out += &line;
        out.push('\n');
    }
    out
}

/// RFC 4180 quoting where needed.
pub(crate) fn csv_field(s: &str) -> String {
    if s.contains([',', '"', '\n', '\r']) { format!("\"{}\"", s.replace('"', "\"\"")) } else { s.to_owned() }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn loaded(text: &str) -> LoadedConfig {
        config::from_str("t.toml", text).unwrap()
    }

    const GEOMETRY: &str = "[geometry]\nsource = \"mesh\"\npath = \"x.obj\"\n";

    #[test]
    fn default_plan_is_base_plus_every_builtin_loss() {
        let p = plan(&loaded(GEOMETRY));
        assert_eq!(p[0].name, "base");
        let names: Vec<&str> = p[1..].iter().map(|v| v.remove[0].as_str()).collect();
        let builtins: Vec<&str> = PAPER.to_vec();
        assert_eq!(names, builtins);
        assert_eq!(p[1].dir_name, format!("wo_{}", builtins[0]));
    }

    #[test]
    fn plan_follows_the_ablation_table() {
        let text = format!(
            "{GEOMETRY}[losses.cycle_3d]\n[losses.texture]\n[ablation]\nbase = false\nremove_each = [\"texture\"]\n\
             [[ablation.variants]]\nname = \"n=1\"\nset = [\"model.charts=1\"]\n\
             [[ablation.variants]]\nname = \"n=1\"\nremove = [\"cycle_3d\"]\n"
        );
        let p = plan(&loaded(&text));
        let got: Vec<(&str, &str)> = p.iter().map(|v| (v.name.as_str(), v.dir_name.as_str())).collect();
        assert_eq!(got, [("w/o texture", "wo_texture"), ("n=1", "n-1"), ("n=1", "n-1_2")]);
        assert_eq!(p[1].set, ["model.charts=1"]);
    }

    #[test]
    fn variants_remove_losses_and_apply_overrides() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("a.toml");
        std::fs::write(&path, format!("{GEOMETRY}[ablation]\nremove_each = []\n")).unwrap();
        let v = Variant {
            name: "x".into(),
            dir_name: "x".into(),
            remove: vec!["texture".into(), "entropy".into()],
            set: vec!["model.charts=3".into()],
        };
        let l = load_variant(&path, &["training.steps=7".into()], &v).unwrap();
        let losses: Vec<&String> = l.config.losses.as_ref().unwrap().keys().collect();
        let expected: Vec<String> =
            PAPER.iter().map(|&n| n.to_owned()).filter(|n| n != "texture" && n != "entropy").collect();
        assert_eq!(losses, expected.iter().collect::<Vec<_>>());
        assert_eq!((l.config.model.charts, l.config.training.steps), (3, 7));
        assert!(l.config.ablation.is_none(), "variants do not carry the sweep");
    }

    #[test]
    fn removing_a_loss_the_base_lacks_names_the_ones_it_has() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("a.toml");
        std::fs::write(&path, format!("{GEOMETRY}[losses.cycle_3d]\n[losses.surface]\n")).unwrap();
        let v =
            Variant { name: "x".into(), dir_name: "x".into(), remove: vec!["textur".into()], set: vec![] };
        let e = load_variant(&path, &[], &v).unwrap_err().to_string();
        assert!(e.contains("`textur`") && e.contains("cycle_3d, surface"), "{e}");
    }

    fn scores(b: f64) -> Scores {
        Scores { boundary: b, stretch: 0.5, conformal: 0.5, uv_efficiency: 0.5, editability: 0.25, steps: 10 }
    }

    #[test]
    fn tables_mark_the_best_average_and_report_failures() {
        let rows = vec![
            Row { name: "base".into(), dir: "r/base".into(), result: Ok(scores(1.0)), seconds: 3.0 },
            Row { name: "w/o a".into(), dir: "r/wo_a".into(), result: Ok(scores(0.5)), seconds: 2.0 },
            Row {
                name: "bad, one".into(),
                dir: "r/bad".into(),
                result: Err("no \"x\" | y".into()),
                seconds: 0.0,
            },
        ];
        let md = markdown_table(&rows);
        assert!(md.contains("| base | 1.000 | 0.500 | 0.500 | 0.500 | **0.625** | 0.250 | 10 | 3 |"), "{md}");
        assert!(md.contains("| w/o a | 0.500 | 0.500 | 0.500 | 0.500 | 0.500 |"), "{md}");
        assert!(md.contains("failed: no \"x\" \\| y"), "{md}");
        let csv = csv_table(&rows);
        let lines: Vec<&str> = csv.lines().collect();
        assert_eq!(lines.len(), 4);
        assert!(
            lines[1]
                .starts_with("base,r/base,1.000000,0.500000,0.500000,0.500000,0.625000,0.250000,10,3.0,ok,"),
            "{csv}"
        );
        assert_eq!(lines[3], "\"bad, one\",r/bad,,,,,,,,0.0,failed,\"no \"\"x\"\" | y\"");
    }

    #[test]
    fn scores_read_back_from_a_metrics_file() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("metrics.json");
        std::fs::write(
            &p,
            r#"{"metrics":{"image":{"boundary":0.9,"stretch":0.8,"conformal":0.7,"editability":0.675},
               "uv":{"utilisation":0.6}},"steps":12}"#,
        )
        .unwrap();
        let s = Scores::read(&p).unwrap();
        assert_eq!(
            s,
            Scores {
                boundary: 0.9,
                stretch: 0.8,
                conformal: 0.7,
                uv_efficiency: 0.6,
                editability: 0.675,
                steps: 12
            }
        );
        std::fs::write(&p, "{\"metrics\":{}}").unwrap();
        assert_eq!(Scores::read(&p), None);
    }
}

//! Reading a run folder as it is: finished, still training, trained without a bake, or written by
//! an older version that lacked some files or metrics.
//!
//! Only a folder that holds none of a run's files is an error. A file that is missing leaves its
//! part of the page out. A file that cannot be read or parsed becomes a warning on the page and on
//! the command line, and never stops the report.

use std::path::{Path, PathBuf};

use rayon::prelude::*;

use nuvo_core::outputs::names;
use nuvo_core::run::files;

use crate::ReportError;
use crate::config_diff::{self, Flat};
use crate::log::TrainingLog;

/// `nuvo unwrap`'s record of its decisions, shown when a run has one.
pub const UNWRAP_JSON: &str = "unwrap.json";

/// The longest side a picture is shown at. Larger ones (a 2048² UV layout is 4–5 MB) are
/// scaled down for the page, so that a sweep of ten runs stays a page a browser opens quickly;
/// the caption says so, and the file itself is beside the report.
pub const PICTURE_SIDE: u32 = 1024;

/// A picture of a run, as PNG bytes.
#[derive(Clone, Debug)]
pub struct Picture {
    /// Its path inside the run folder, shown as its caption.
    pub name: String,
    pub png: Vec<u8>,
    /// The file's own size when the page shows it scaled down to [`PICTURE_SIDE`].
    pub scaled_from: Option<(u32, u32)>,
}

impl Picture {
    /// `png` as the page shows it (module docs); a PNG that cannot be decoded is an error message.
    fn new(name: String, png: Vec<u8>) -> Result<Picture, String> {
        let (w, h) = image::ImageReader::with_format(std::io::Cursor::new(&png), image::ImageFormat::Png)
            .into_dimensions()
            .map_err(|e| e.to_string())?;
        if w.max(h) <= PICTURE_SIDE {
            return Ok(Picture { name, png, scaled_from: None });
        }
        let img =
            image::load_from_memory_with_format(&png, image::ImageFormat::Png).map_err(|e| e.to_string())?;
        let small = img.resize(PICTURE_SIDE, PICTURE_SIDE, image::imageops::FilterType::Triangle);
        let mut out = Vec::new();
        small
            .write_to(&mut std::io::Cursor::new(&mut out), image::ImageFormat::Png)
            .map_err(|e| e.to_string())?;
        Ok(Picture { name, png: out, scaled_from: Some((w, h)) })
    }
}

/// What a run folder holds.
#[derive(Clone, Debug)]
pub struct Run {
    pub dir: PathBuf,
    /// The run's name on the page (its folder's name, or its path where names repeat).
    pub label: String,
    /// The resolved config's text and its leaves.
    pub config_text: Option<String>,
    pub config: Option<Flat>,
    pub log: TrainingLog,
    pub metrics: Option<serde_json::Value>,
    /// The steps the config plans (`training.steps`), to say how far a running run is.
    pub planned_steps: Option<u64>,
    pub pictures: Vec<Picture>,
    /// `atlas.glb`, for the 3-D view.
    pub glb: Option<Vec<u8>>,
    pub unwrap_json: Option<String>,
    pub warnings: Vec<String>,
}

/// Whether `dir` holds any file that only a run folder holds.
pub fn is_run_folder(dir: &Path) -> bool {
    [files::CONFIG, files::LOG, names::METRICS].iter().any(|f| dir.join(f).is_file())
}

/// The run folders of `inputs`: each is a run folder or a sweep (a folder of run folders, taken
/// in name order).
pub fn run_folders(inputs: &[PathBuf]) -> Result<Vec<PathBuf>, ReportError> {
    let mut out = Vec::new();
    for input in inputs {
        if !input.is_dir() {
            let message = if input.exists() { "not a folder" } else { "no such folder" };
            return Err(ReportError::Input { path: input.clone(), message: message.into() });
        }
        if is_run_folder(input) {
            out.push(input.clone());
            continue;
        }
        let entries =
            std::fs::read_dir(input).map_err(|source| ReportError::Read { path: input.clone(), source })?;
        let mut runs: Vec<PathBuf> =
            entries.filter_map(|e| Some(e.ok()?.path())).filter(|p| p.is_dir() && is_run_folder(p)).collect();
        if runs.is_empty() {
            return Err(ReportError::Input {
                path: input.clone(),
                message: format!(
                    "neither a run folder (it has no {}, {} or {}) nor a sweep of run folders",
                    files::CONFIG,
                    files::LOG,
                    names::METRICS
                ),
            });
        }
        runs.sort();
        out.extend(runs);
    }
    Ok(out)
}

impl Run {
    /// Reads what `dir` holds (module docs); `label` names it on the page.
    pub fn read(dir: &Path, label: String) -> Self {
        let mut warnings = Vec::new();
        let mut text = |name: &str| -> Option<String> {
            let path = dir.join(name);
            match std::fs::read(&path) {
                Ok(bytes) => Some(String::from_utf8_lossy(&bytes).into_owned()),
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => None,
                Err(e) => {
                    warnings.push(format!("cannot read {}: {e}", path.display()));
                    None
                }
            }
        };
        let config_text = text(files::CONFIG);
        let log_text = text(files::LOG);
        let metrics_text = text(names::METRICS);
        let unwrap_json = text(UNWRAP_JSON);

        let config = config_text.as_deref().and_then(|t| match config_diff::flatten(t) {
            Ok(flat) => Some(flat),
            Err(e) => {
                warnings.push(format!("{}: not a TOML config: {e}", dir.join(files::CONFIG).display()));
                None
            }
        });
        let planned_steps = config.as_ref().and_then(|c| c.get("training.steps")?.parse().ok());
        let log = TrainingLog::parse(log_text.as_deref().unwrap_or(""));
        let metrics = metrics_text.as_deref().and_then(|t| match serde_json::from_str(t) {
            Ok(v) => Some(v),
            Err(e) => {
                warnings.push(format!("{}: not JSON: {e}", dir.join(names::METRICS).display()));
                None
            }
        });
        let mut pictures = Vec::new();
        let mut names_of_pictures = vec![names::LAYOUT.to_owned(), names::CHECKER.to_owned()];
        names_of_pictures.push(names::TEXTURE.to_owned());
        names_of_pictures.extend(render_names(&dir.join(names::RENDERS)));
        names_of_pictures.push(names::NORMAL_GRIDS.to_owned());
        // Decoded and scaled down in parallel (the UV layout and the normal grids, 2048² each,
        // were most of the time `nuvo train` spent on its report, on one core), kept in order.
        let read: Vec<(String, PathBuf, std::io::Result<Vec<u8>>)> = names_of_pictures
            .into_iter()
            .map(|name| {
                let path = dir.join(&name);
                let bytes = std::fs::read(&path);
                (name, path, bytes)
            })
            .collect();
        let decoded: Vec<Result<Picture, String>> = read
            .into_par_iter()
            .filter_map(|(name, path, bytes)| match bytes {
                Ok(png) => Some(
                    Picture::new(name, png)
                        .map_err(|e| format!("{}: not a PNG picture ({e}); left out", path.display())),
                ),
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => None,
                Err(e) => Some(Err(format!("cannot read {}: {e}", path.display()))),
            })
            .collect();
        for picture in decoded {
            match picture {
                Ok(p) => pictures.push(p),
                Err(warning) => warnings.push(warning),
            }
        }
        let glb_path = dir.join(names::GLB);
        let glb = match std::fs::read(&glb_path) {
            Ok(b) if b.starts_with(b"glTF") => Some(b),
            Ok(_) => {
                warnings.push(format!("{}: not a binary glTF file; no 3-D view", glb_path.display()));
                None
            }
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => None,
            Err(e) => {
                warnings.push(format!("cannot read {}: {e}", glb_path.display()));
                None
            }
        };
        Run {
            dir: dir.to_path_buf(),
            label,
            config_text,
            config,
            log,
            metrics,
            planned_steps,
            pictures,
            glb,
            unwrap_json,
            warnings,
        }
    }

    /// One line on where the run stands: finished (it has metrics), or how far its log goes.
    pub fn status(&self) -> String {
        let seconds = self.log.seconds;
        let seconds = if seconds < 10.0 { format!("{seconds:.1}") } else { format!("{seconds:.0}") };
        let trained = match (self.log.last_step, self.planned_steps) {
            (Some(s), Some(p)) => format!("step {} of {p} logged, {seconds} s of training", s + 1),
            (Some(s), None) => format!("step {} logged, {seconds} s of training", s + 1),
            (None, _) => "no training logged".to_owned(),
        };
        match &self.metrics {
            Some(_) => format!("finished: {trained}"),
            None => format!("no metrics yet (still training, or trained without a bake): {trained}"),
        }
    }
}

/// The renders' names (`renders/view_*.png`), in name order.
fn render_names(dir: &Path) -> Vec<String> {
    let Ok(entries) = std::fs::read_dir(dir) else { return Vec::new() };
    let mut names: Vec<String> = entries
        .filter_map(|e| e.ok()?.file_name().into_string().ok())
        .filter(|n| n.ends_with(".png"))
        .map(|n| format!("{}/{n}", names::RENDERS))
        .collect();
    names.sort();
    names
}

/// Reads every run; labels are folder names, or the paths as given where two names are equal.
pub fn read_runs(dirs: &[PathBuf]) -> Vec<Run> {
    let name =
        |d: &PathBuf| d.file_name().map_or_else(|| d.display().to_string(), |n| n.to_string_lossy().into());
    let names: Vec<String> = dirs.iter().map(name).collect();
    dirs.iter()
        .zip(&names)
        .map(|(dir, n)| {
            let unique = names.iter().filter(|m| *m == n).count() == 1;
            Run::read(dir, if unique { n.clone() } else { dir.display().to_string() })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_running_run_has_its_config_and_curves_but_no_metrics() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("config.toml"), "[training]\nsteps = 100\n").unwrap();
        std::fs::write(dir.path().join("log.jsonl"), "{\"step\":0,\"total\":1.0,\"seconds\":0.5}\n{\"st")
            .unwrap();
        let run = Run::read(dir.path(), "r".into());
        assert_eq!(run.planned_steps, Some(100));
        assert!(run.metrics.is_none() && run.glb.is_none() && run.pictures.is_empty());
        assert!(run.warnings.is_empty(), "{:?}", run.warnings);
        assert_eq!(
            run.status(),
            "no metrics yet (still training, or trained without a bake): step 1 of 100 logged, 0.5 s of training"
        );
    }

    #[test]
    fn broken_files_are_warnings_and_pictures_come_in_page_order() {
        let dir = tempfile::tempdir().unwrap();
        let mut png = Vec::new();
        image::RgbImage::new(4, 3)
            .write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
            .unwrap();
        std::fs::write(dir.path().join("metrics.json"), "{ not json").unwrap();
        std::fs::write(dir.path().join("atlas.glb"), "not a glb").unwrap();
        std::fs::create_dir(dir.path().join("renders")).unwrap();
        for name in ["renders/view_1.png", "renders/view_0.png", "uv_layout.png", "normal_grids.png"] {
            std::fs::write(dir.path().join(name), &png).unwrap();
        }
        std::fs::write(dir.path().join("checker.png"), "jpeg?").unwrap();
        let run = Run::read(dir.path(), "r".into());
        let names: Vec<&str> = run.pictures.iter().map(|p| p.name.as_str()).collect();
        assert_eq!(names, ["uv_layout.png", "renders/view_0.png", "renders/view_1.png", "normal_grids.png"]);
        assert_eq!(run.warnings.len(), 3, "{:?}", run.warnings);
        assert!(run.warnings.iter().any(|w| w.contains("metrics.json") && w.contains("not JSON")));
        assert!(run.warnings.iter().any(|w| w.contains("checker.png")));
        assert!(run.warnings.iter().any(|w| w.contains("atlas.glb")));
    }

    #[test]
    fn large_pictures_are_shown_scaled_down_and_small_ones_as_they_are() {
        let encode = |w, h| {
            let mut png = Vec::new();
            image::RgbImage::from_fn(w, h, |x, y| image::Rgb([x as u8, y as u8, 7]))
                .write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
                .unwrap();
            png
        };
        let big = Picture::new("uv_layout.png".into(), encode(2048, 1536)).unwrap();
        assert_eq!(big.scaled_from, Some((2048, 1536)));
        let shown = image::load_from_memory(&big.png).unwrap();
        assert_eq!((shown.width(), shown.height()), (1024, 768));
        let small = encode(300, 200);
        let same = Picture::new("a.png".into(), small.clone()).unwrap();
        assert_eq!((same.png, same.scaled_from), (small, None));
        assert!(Picture::new("x.png".into(), b"\x89PNG\r\n\x1a\ncut".to_vec()).is_err());
    }

    #[test]
    fn sweeps_expand_to_their_runs_and_other_folders_are_refused_by_name() {
        let sweep = tempfile::tempdir().unwrap();
        for name in ["no_chamfer", "base"] {
            std::fs::create_dir(sweep.path().join(name)).unwrap();
            std::fs::write(sweep.path().join(name).join("log.jsonl"), "").unwrap();
        }
        std::fs::create_dir(sweep.path().join("not_a_run")).unwrap();
        let runs = run_folders(&[sweep.path().to_path_buf()]).unwrap();
        assert_eq!(runs, [sweep.path().join("base"), sweep.path().join("no_chamfer")]);
        let empty = sweep.path().join("not_a_run");
        let e = run_folders(std::slice::from_ref(&empty)).unwrap_err().to_string();
        assert!(e.contains("not_a_run") && e.contains("neither a run folder"), "{e}");
        let e = run_folders(&[sweep.path().join("gone")]).unwrap_err().to_string();
        assert!(e.contains("gone") && e.contains("no such folder"), "{e}");
    }

    #[test]
    fn repeated_folder_names_are_labelled_by_path() {
        let a = tempfile::tempdir().unwrap();
        let b = tempfile::tempdir().unwrap();
        let dirs = [a.path().join("run"), b.path().join("run"), a.path().join("other")];
        let labels: Vec<String> = read_runs(&dirs).into_iter().map(|r| r.label).collect();
        assert_eq!(labels[0], dirs[0].display().to_string());
        assert_eq!(labels[1], dirs[1].display().to_string());
        assert_eq!(labels[2], "other");
    }
}

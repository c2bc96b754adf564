//! What a batch runs and which part of it one machine takes: the items of a manifest, and the
//! shard a scheduler's array task owns.
//!
//! A manifest is one of three formats, chosen by its extension:
//! - **text**: one input per line; `#` starts a comment; blank lines are ignored;
//! - **`.csv`**: a header naming `input` and optionally `name` and `set` (KEY=VALUE overrides
//!   separated by `;`);
//! - **`.toml`**: an optional top-level `set = [...]` for every item, then `[[item]]` tables with
//!   `input` and an optional `name` and `set`.
//!
//! Relative inputs are relative to the manifest's folder, so a manifest and its meshes move
//! together. Names are folder names: given, or the input's file stem; a repeated name gets `-2`,
//! `-3`, ... in manifest order. An item's index is its place in the manifest, so every shard of
//! an array computes the same items, names and owners from the same file.
//!
//! **Sharding.** Item `i` belongs to shard `i mod N`. The shard comes from `--shard I/N`, else from
//! Slurm's `SLURM_ARRAY_TASK_ID` (less `SLURM_ARRAY_TASK_MIN`, as arrays may start anywhere) and
//! `SLURM_ARRAY_TASK_COUNT`, else from Kubernetes' `JOB_COMPLETION_INDEX` with `--shards N`.
//! Without any of them, the whole manifest is one shard.

use std::path::{Path, PathBuf};

/// Why a manifest or a shard cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum ManifestError {
    #[error("cannot read the manifest {path}: {source}")]
    Read {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// A line or item that is not an item; `line` is 1-based (0 when the format has no lines).
    #[error("{path}{}: {message}", if *line > 0 { format!(" line {line}") } else { String::new() })]
    Item { path: PathBuf, line: usize, message: String },
    #[error("{path}: the manifest lists no items")]
    Empty { path: PathBuf },
    #[error("{0}")]
    Shard(String),
}

/// One thing to unwrap.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Item {
    /// Its place in the manifest (0-based): which shard owns it.
    pub index: usize,
    /// Its output folder's name, unique in the manifest.
    pub name: String,
    pub input: PathBuf,
    /// `--set` overrides for this item (after the batch's own).
    pub set: Vec<String>,
}

/// The items of a manifest, in order.
pub fn load(path: &Path) -> Result<Vec<Item>, ManifestError> {
    let text =
        std::fs::read_to_string(path).map_err(|source| ManifestError::Read { path: path.into(), source })?;
    let ext = path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase);
    let raw = match ext.as_deref() {
        Some("toml") => parse_toml(&text, path)?,
        Some("csv") => parse_csv(&text, path)?,
        _ => parse_lines(&text),
    };
    if raw.is_empty() {
        return Err(ManifestError::Empty { path: path.into() });
    }
    let base = path.parent().unwrap_or(Path::new(""));
    let mut taken: Vec<String> = Vec::new();
    let mut items = Vec::with_capacity(raw.len());
    for (index, r) in raw.into_iter().enumerate() {
        let input = if r.input.is_absolute() { r.input.clone() } else { base.join(&r.input) };
        let wanted = match &r.name {
            Some(n) => {
                check_name(n).map_err(|message| ManifestError::Item {
                    path: path.into(),
                    line: r.line,
                    message,
                })?;
                n.clone()
            }
            None => folder_name(&r.input),
        };
        let name = unique(&wanted, &taken);
        taken.push(name.clone());
        items.push(Item { index, name, input, set: r.set });
    }
    Ok(items)
}

/// An item as read, before names are made unique.
struct RawItem {
    line: usize,
    input: PathBuf,
    name: Option<String>,
    set: Vec<String>,
}

fn parse_lines(text: &str) -> Vec<RawItem> {
    text.lines()
        .enumerate()
        .filter_map(|(k, l)| {
            let l = l.split('#').next().unwrap_or("").trim();
            (!l.is_empty()).then(|| RawItem { line: k + 1, input: l.into(), name: None, set: Vec::new() })
        })
        .collect()
}

fn parse_csv(text: &str, path: &Path) -> Result<Vec<RawItem>, ManifestError> {
    let err = |line: usize, message: String| ManifestError::Item { path: path.into(), line, message };
    let mut lines = text.lines().enumerate().filter(|(_, l)| !l.trim().is_empty());
    let Some((_, header)) = lines.next() else { return Ok(Vec::new()) };
    let columns: Vec<String> =
        csv_fields(header).map_err(|m| err(1, m))?.iter().map(|c| c.trim().to_ascii_lowercase()).collect();
    let column = |name: &str| columns.iter().position(|c| c == name);
    let input_at = column("input").ok_or_else(|| {
        err(1, format!("the header names no `input` column (it has: {})", columns.join(", ")))
    })?;
    if let Some(other) = columns.iter().find(|c| !["input", "name", "set"].contains(&c.as_str())) {
        return Err(err(1, format!("unknown column `{other}`; the columns are input, name and set")));
    }
    let (name_at, set_at) = (column("name"), column("set"));
    let mut out = Vec::new();
    for (k, l) in lines {
        let fields = csv_fields(l).map_err(|m| err(k + 1, m))?;
        if fields.len() > columns.len() {
            return Err(err(
                k + 1,
                format!("{} fields where the header has {}", fields.len(), columns.len()),
            ));
        }
        let field =
            |at: Option<usize>| at.and_then(|i| fields.get(i)).map(|f| f.trim()).filter(|f| !f.is_empty());
        let input = field(Some(input_at)).ok_or_else(|| err(k + 1, "no input".into()))?;
        let set = field(set_at)
            .map(|s| s.split(';').map(str::trim).filter(|s| !s.is_empty()).map(String::from).collect());
        out.push(RawItem {
            line: k + 1,
            input: input.into(),
            name: field(name_at).map(String::from),
            set: set.unwrap_or_default(),
        });
    }
    Ok(out)
}

/// The fields of one CSV line (RFC 4180 quotes; no line breaks inside fields).
fn csv_fields(line: &str) -> Result<Vec<String>, String> {
    let mut fields = vec![String::new()];
    let mut chars = line.chars().peekable();
    let mut quoted = false;
    while let Some(c) = chars.next() {
        match (c, quoted) {
            ('"', false) if fields.last().is_some_and(String::is_empty) => quoted = true,
            ('"', true) if chars.peek() == Some(&'"') => {
                chars.next();
                fields.last_mut().unwrap().push('"');
            }
            ('"', true) => quoted = false,
            (',', false) => fields.push(String::new()),
            (c, _) => fields.last_mut().unwrap().push(c),
        }
    }
    if quoted { Err("a quote is not closed".into()) } else { Ok(fields) }
}

fn parse_toml(text: &str, path: &Path) -> Result<Vec<RawItem>, ManifestError> {
    #[derive(serde::Deserialize)]
    #[serde(deny_unknown_fields)]
    struct File {
        #[serde(default)]
        set: Vec<String>,
        #[serde(default)]
        item: Vec<TomlItem>,
    }
    #[derive(serde::Deserialize)]
    #[serde(deny_unknown_fields)]
    struct TomlItem {
        input: PathBuf,
        name: Option<String>,
        #[serde(default)]
        set: Vec<String>,
    }
    let file: File = toml::from_str(text).map_err(|e| {
        let line = e.span().map_or(0, |s| text[..s.start].matches('\n').count() + 1);
        ManifestError::Item { path: path.into(), line, message: e.message().to_owned() }
    })?;
    Ok(file
        .item
        .into_iter()
        .map(|i| RawItem {
            line: 0,
            input: i.input,
            name: i.name,
            set: file.set.iter().cloned().chain(i.set).collect(),
        })
        .collect())
}

/// A given name must be one folder name.
fn check_name(name: &str) -> Result<(), String> {
    let bad = name.is_empty() || name == "." || name == ".." || name.contains(['/', '\\', '\0']);
    if bad { Err(format!("`{name}` is not a folder name")) } else { Ok(()) }
}

/// The input's file stem, as a folder name.
fn folder_name(input: &Path) -> String {
    let stem = input.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    if check_name(&stem).is_ok() { stem } else { "item".into() }
}

fn unique(wanted: &str, taken: &[String]) -> String {
    if !taken.iter().any(|t| t == wanted) {
        return wanted.to_owned();
    }
    (2..).map(|k| format!("{wanted}-{k}")).find(|n| !taken.contains(n)).unwrap_or_default()
}

/// One machine's part of an array: items `i` with `i mod count == index`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Shard {
    pub index: usize,
    pub count: usize,
}

/// Where a shard came from, for the log line that states it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ShardSource {
    Flag,
    Slurm,
    Kubernetes,
    Whole,
}

impl Shard {
    /// The whole manifest.
    pub const WHOLE: Shard = Shard { index: 0, count: 1 };

    /// Whether the item at `index` of the manifest is this shard's.
    pub fn owns(&self, index: usize) -> bool {
        index % self.count == self.index
    }

    /// `I/N`, as `--shard` takes it.
    pub fn parse(s: &str) -> Result<Shard, ManifestError> {
        let bad = || ManifestError::Shard(format!("--shard {s}: expected I/N with 0 <= I < N, e.g. 0/4"));
        let (i, n) = s.split_once('/').ok_or_else(bad)?;
        let (index, count) = (i.trim().parse().map_err(|_| bad())?, n.trim().parse().map_err(|_| bad())?);
        Shard::new(index, count).ok_or_else(bad)
    }

    fn new(index: usize, count: usize) -> Option<Shard> {
        (count > 0 && index < count).then_some(Shard { index, count })
    }

    /// The shard from the flags or the scheduler's environment (module docs); `var` reads one
    /// environment variable.
    pub fn resolve(
        flag: Option<&str>,
        shards: Option<usize>,
        var: impl Fn(&str) -> Option<String>,
    ) -> Result<(Shard, ShardSource), ManifestError> {
        if let Some(f) = flag {
            return Ok((Shard::parse(f)?, ShardSource::Flag));
        }
        let number = |name: &str| -> Result<Option<usize>, ManifestError> {
            var(name)
                .map(|v| {
                    v.trim()
                        .parse()
                        .map_err(|_| ManifestError::Shard(format!("{name}={v} is not a whole number")))
                })
                .transpose()
        };
        if let Some(id) = number("SLURM_ARRAY_TASK_ID")? {
            let count = number("SLURM_ARRAY_TASK_COUNT")?.ok_or_else(|| {
                ManifestError::Shard("SLURM_ARRAY_TASK_ID is set but SLURM_ARRAY_TASK_COUNT is not".into())
            })?;
            let min = number("SLURM_ARRAY_TASK_MIN")?.unwrap_or(0);
            let shard = id.checked_sub(min).and_then(|i| Shard::new(i, count)).ok_or_else(|| {
                ManifestError::Shard(format!(
                    "SLURM_ARRAY_TASK_ID={id} (less SLURM_ARRAY_TASK_MIN={min}) is not below \
                     SLURM_ARRAY_TASK_COUNT={count}: submit the array as --array=0-{}",
                    count.saturating_sub(1)
                ))
            })?;
            return Ok((shard, ShardSource::Slurm));
        }
        if let Some(index) = number("JOB_COMPLETION_INDEX")? {
            let count = shards.ok_or_else(|| {
                ManifestError::Shard(
                    "JOB_COMPLETION_INDEX is set (a Kubernetes indexed job): give the job's completions as --shards N"
                        .into(),
                )
            })?;
            let shard = Shard::new(index, count).ok_or_else(|| {
                ManifestError::Shard(format!("JOB_COMPLETION_INDEX={index} is not below --shards {count}"))
            })?;
            return Ok((shard, ShardSource::Kubernetes));
        }
        match shards {
            Some(n) if n > 1 => Err(ManifestError::Shard(format!(
                "--shards {n} without a shard index: pass --shard I/{n}, or run under a Slurm array or a \
                 Kubernetes indexed job"
            ))),
            _ => Ok((Shard::WHOLE, ShardSource::Whole)),
        }
    }
}

impl std::fmt::Display for Shard {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}/{}", self.index, self.count)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
        let p = dir.join(name);
        std::fs::write(&p, text).unwrap();
        p
    }

    #[test]
    fn a_text_manifest_is_one_input_a_line_relative_to_itself_with_unique_names() {
        let dir = tempfile::tempdir().unwrap();
        let m =
            write(dir.path(), "list.txt", "# scans\nmeshes/cow.obj\n\n/abs/cow.glb  # again\nhorse.ply\n");
        let items = load(&m).unwrap();
        let names: Vec<&str> = items.iter().map(|i| i.name.as_str()).collect();
        assert_eq!(names, ["cow", "cow-2", "horse"]);
        assert_eq!(items[0].input, dir.path().join("meshes/cow.obj"));
        assert_eq!(items[1].input, Path::new("/abs/cow.glb"));
        assert_eq!(items.iter().map(|i| i.index).collect::<Vec<_>>(), [0, 1, 2]);
        assert!(items.iter().all(|i| i.set.is_empty()));
    }

    #[test]
    fn csv_and_toml_manifests_carry_names_and_overrides() {
        let dir = tempfile::tempdir().unwrap();
        let csv = write(
            dir.path(),
            "m.csv",
            "input,name,set\na.obj,,\n\"b,c.obj\",bee,training.steps=5; model.charts=2\nd.obj,bee,\n",
        );
        let items = load(&csv).unwrap();
        assert_eq!(items[0].name, "a");
        assert_eq!(
            (items[1].name.as_str(), items[1].input.file_name().unwrap()),
            ("bee", "b,c.obj".as_ref())
        );
        assert_eq!(items[1].set, ["training.steps=5", "model.charts=2"]);
        assert_eq!(items[2].name, "bee-2");

        let toml = write(
            dir.path(),
            "m.toml",
            "set = [\"output.renders=0\"]\n[[item]]\ninput = \"x.obj\"\nset = [\"seed=2\"]\n[[item]]\ninput = \"y.obj\"\nname = \"why\"\n",
        );
        let items = load(&toml).unwrap();
        assert_eq!(items[0].set, ["output.renders=0", "seed=2"]);
        assert_eq!(
            (items[1].name.as_str(), &items[1].set[..]),
            ("why", &["output.renders=0".to_owned()][..])
        );
    }

    #[test]
    fn bad_manifests_name_the_file_and_line() {
        let dir = tempfile::tempdir().unwrap();
        let e = |name: &str, text: &str| load(&write(dir.path(), name, text)).unwrap_err().to_string();
        assert!(e("empty.txt", "# nothing\n").contains("lists no items"));
        let m = e("cols.csv", "path,name\na.obj,x\n");
        assert!(m.contains("cols.csv line 1") && m.contains("no `input` column"), "{m}");
        let m = e("name.csv", "input,name\na.obj,x\nb.obj,../up\n");
        assert!(m.contains("name.csv line 3") && m.contains("not a folder name"), "{m}");
        let m = e("quote.csv", "input\n\"a.obj\n");
        assert!(m.contains("line 2") && m.contains("quote"), "{m}");
        let m = e("typo.toml", "[[item]]\ninput = \"a.obj\"\nnmae = \"x\"\n");
        assert!(m.contains("typo.toml line 3") && m.contains("nmae"), "{m}");
        let m = load(&dir.path().join("gone.txt")).unwrap_err().to_string();
        assert!(m.contains("gone.txt"), "{m}");
    }

    fn env<'a>(vars: &'a [(&'a str, &'a str)]) -> impl Fn(&str) -> Option<String> + 'a {
        move |k| vars.iter().find(|(n, _)| *n == k).map(|(_, v)| v.to_string())
    }

    #[test]
    fn shards_come_from_the_flag_then_slurm_then_kubernetes() {
        let slurm =
            [("SLURM_ARRAY_TASK_ID", "7"), ("SLURM_ARRAY_TASK_COUNT", "3"), ("SLURM_ARRAY_TASK_MIN", "5")];
        assert_eq!(
            Shard::resolve(Some("1/4"), None, env(&slurm)).unwrap(),
            (Shard { index: 1, count: 4 }, ShardSource::Flag)
        );
        assert_eq!(
            Shard::resolve(None, None, env(&slurm)).unwrap(),
            (Shard { index: 2, count: 3 }, ShardSource::Slurm)
        );
        let k8s = [("JOB_COMPLETION_INDEX", "4")];
        assert_eq!(
            Shard::resolve(None, Some(5), env(&k8s)).unwrap(),
            (Shard { index: 4, count: 5 }, ShardSource::Kubernetes)
        );
        assert!(Shard::resolve(None, None, env(&k8s)).unwrap_err().to_string().contains("--shards N"));
        assert!(
            Shard::resolve(None, Some(4), env(&k8s))
                .unwrap_err()
                .to_string()
                .contains("not below --shards 4")
        );
        assert_eq!(Shard::resolve(None, None, env(&[])).unwrap(), (Shard::WHOLE, ShardSource::Whole));
        assert!(Shard::resolve(None, Some(3), env(&[])).is_err(), "--shards alone names no shard");
        let bad = [("SLURM_ARRAY_TASK_ID", "3"), ("SLURM_ARRAY_TASK_COUNT", "3")];
        assert!(Shard::resolve(None, None, env(&bad)).unwrap_err().to_string().contains("--array=0-2"));
        for s in ["3/3", "1", "a/2", "0/0"] {
            assert!(Shard::parse(s).is_err(), "{s}");
        }
    }

    #[test]
    fn every_item_belongs_to_exactly_one_shard() {
        let n = 3;
        for i in 0..20 {
            let owners = (0..n).filter(|&k| Shard { index: k, count: n }.owns(i)).count();
            assert_eq!(owners, 1);
        }
        assert!(Shard::WHOLE.owns(17));
    }
}

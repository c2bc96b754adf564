//! What a batch leaves behind: a record in each item's folder, and the table of every item.
//!
//! Invariants:
//! - `batch.json` ([`RECORD`]) is written last, atomically, once the item has ended. Its absence
//!   means the item never ended: it is running, or it was killed. An item is complete exactly when
//!   its record says [`Status::Done`]. A rerun skips those items and redoes every other item
//!   from scratch.
//! - `batch_items.json` ([`ITEMS`]) in the batch folder lists the manifest's items. Every shard
//!   writes the same bytes, atomically, so concurrent shards agree. It lets the summary list items
//!   that no shard has started.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::ablation::csv_field;
use crate::manifest::Item;
use crate::outputs::{metric_paths, names};

/// The record of an ended item, in its folder.
pub const RECORD: &str = "batch.json";
/// The item's `nuvo unwrap` output (stdout and stderr), in its folder.
pub const ITEM_LOG: &str = "batch.log";
/// The manifest's items, in the batch folder.
pub const ITEMS: &str = "batch_items.json";
/// The summary tables, in the batch folder.
pub const SUMMARY_MD: &str = "summary.md";
pub const SUMMARY_CSV: &str = "summary.csv";

/// How an item ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum Status {
    #[serde(rename = "done")]
    Done,
    #[serde(rename = "failed")]
    Failed,
    #[serde(rename = "timed out")]
    TimedOut,
}

impl Status {
    /// The word `batch.json` and the summary use for it (the serde names above).
    pub fn as_str(self) -> &'static str {
        match self {
            Status::Done => "done",
            Status::Failed => "failed",
            Status::TimedOut => "timed out",
        }
    }
}

/// `batch.json`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Record {
    pub status: Status,
    pub input: PathBuf,
    /// Every `--set` the item ran with (the batch's, then the manifest's).
    pub set: Vec<String>,
    /// The shard that ran it (`I/N`) and on which host.
    pub shard: String,
    pub host: String,
    /// Wall seconds from start to end.
    pub seconds: f64,
    /// Why it did not finish (the last error line of its log, or the time limit).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
}

impl Record {
    /// The record in `item_dir`, if the item ended and its record can be read.
    pub fn read(item_dir: &Path) -> Option<Record> {
        serde_json::from_slice(&std::fs::read(item_dir.join(RECORD)).ok()?).ok()
    }
}

/// Whether the item in `item_dir` is complete.
pub fn is_done(item_dir: &Path) -> bool {
    Record::read(item_dir).is_some_and(|r| r.status == Status::Done)
}

/// `batch_items.json`: the items' names and inputs, in manifest order.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ListedItem {
    pub name: String,
    pub input: PathBuf,
}

/// The bytes of `batch_items.json` for `items` (the same for every shard).
pub fn items_json(items: &[Item]) -> String {
    let listed: Vec<ListedItem> =
        items.iter().map(|i| ListedItem { name: i.name.clone(), input: i.input.clone() }).collect();
    serde_json::to_string_pretty(&listed).unwrap_or_default()
}

/// The items of the batch in `dir`: its `batch_items.json`, or, for a folder without one, the
/// sub-folders that hold a record (in name order).
pub fn listed_items(dir: &Path) -> Vec<ListedItem> {
    if let Some(listed) = std::fs::read(dir.join(ITEMS)).ok().and_then(|b| serde_json::from_slice(&b).ok()) {
        return listed;
    }
    let mut found: Vec<ListedItem> = std::fs::read_dir(dir)
        .into_iter()
        .flatten()
        .filter_map(|e| {
            let path = e.ok()?.path();
            let record = Record::read(&path)?;
            Some(ListedItem { name: path.file_name()?.to_string_lossy().into_owned(), input: record.input })
        })
        .collect();
    found.sort_by(|a, b| a.name.cmp(&b.name));
    found
}

/// One row of the summary.
#[derive(Clone, Debug, PartialEq)]
pub struct Row {
    pub name: String,
    pub input: PathBuf,
    /// `done`, `failed`, `timed out`, `running or killed` (a folder, no record) or `not started`.
    pub status: String,
    pub seconds: Option<f64>,
    pub error: Option<String>,
    /// Editability, angular score, charts, packing efficiency, flipped and overlapping faces.
    pub metrics: [Option<f64>; 6],
}

/// The metric columns of [`Row::metrics`]: header and JSON pointer into `metrics.json`.
pub const METRIC_COLUMNS: [(&str, &str); 6] = [
    ("editability", metric_paths::EDITABILITY),
    ("angular", metric_paths::ANGULAR),
    ("charts", metric_paths::CHARTS),
    ("packing", metric_paths::PACKING),
    ("flipped_faces", metric_paths::FLIPPED_FACES),
    ("overlapping_faces", metric_paths::OVERLAPPING_FACES),
];

/// The rows of the batch in `dir`, one per listed item.
pub fn summarise(dir: &Path) -> Vec<Row> {
    listed_items(dir)
        .into_iter()
        .map(|item| {
            let item_dir = dir.join(&item.name);
            let record = Record::read(&item_dir);
            let status = match &record {
                Some(r) => r.status.as_str().to_owned(),
                None if item_dir.is_dir() => "running or killed".into(),
                None => "not started".into(),
            };
            let metrics: Option<serde_json::Value> = std::fs::read(item_dir.join(names::METRICS))
                .ok()
                .and_then(|b| serde_json::from_slice(&b).ok());
            let metric = |pointer: &str| metrics.as_ref()?.pointer(pointer)?.as_f64();
            Row {
                name: item.name,
                input: item.input,
                status,
                seconds: record.as_ref().map(|r| r.seconds),
                error: record.and_then(|r| r.error),
                metrics: METRIC_COLUMNS.map(|(_, p)| metric(p)),
            }
        })
        .collect()
}

/// The summary as Markdown: a count per status, then the table.
pub fn markdown(rows: &[Row]) -> String {
    let mut counts: Vec<(&str, usize)> = Vec::new();
    for r in rows {
        match counts.iter_mut().find(|(s, _)| *s == r.status) {
            Some((_, n)) => *n += 1,
            None => counts.push((&r.status, 1)),
        }
    }
    let counts: Vec<String> = counts.iter().map(|(s, n)| format!("{n} {s}")).collect();
    let mut out = format!("{} items: {}\n\n| item | status | seconds |", rows.len(), counts.join(", "));
    for (h, _) in METRIC_COLUMNS {
        out += &format!(" {} |", h.replace('_', " "));
    }
    out += " error |\n|---|---|---|";
    out += &"---|".repeat(METRIC_COLUMNS.len() + 1);
    out.push('\n');
    for r in rows {
        let seconds = r.seconds.map_or(String::new(), |s| format!("{s:.1}"));
        out += &format!("| {} | {} | {seconds} |", r.name.replace('|', "\\|"), r.status);
        for (m, (h, _)) in r.metrics.iter().zip(METRIC_COLUMNS) {
            out += &match m {
                Some(v) if h.ends_with("faces") || h == "charts" => format!(" {v:.0} |"),
                Some(v) => format!(" {v:.4} |"),
                None => " |".into(),
            };
        }
        match &r.error {
            Some(e) => out += &format!(" {} |\n", e.replace('|', "\\|").replace('\n', " ")),
            None => out += " |\n",
        }
    }
    out
}

/// The summary as CSV (one header line; empty fields where there is no number).
pub fn csv(rows: &[Row]) -> String {
    let mut out = String::from("item,input,status,seconds");
    for (h, _) in METRIC_COLUMNS {
        out += &format!(",{h}");
    }
    out += ",error\n";
    for r in rows {
        out += &format!(
            "{},{},{},{}",
            csv_field(&r.name),
            csv_field(&r.input.display().to_string()),
            csv_field(&r.status),
            r.seconds.map_or(String::new(), |s| format!("{s:.1}"))
        );
        for m in &r.metrics {
            out += &format!(",{}", m.map_or(String::new(), |v| format!("{v}")));
        }
        out += &format!(",{}\n", csv_field(r.error.as_deref().unwrap_or("")));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn record(status: Status, error: Option<&str>) -> Record {
        Record {
            status,
            input: "in.obj".into(),
            set: vec![],
            shard: "0/1".into(),
            host: "h".into(),
            seconds: 2.5,
            error: error.map(String::from),
        }
    }

    #[test]
    fn every_listed_item_gets_a_row_with_its_status_and_numbers() {
        let dir = tempfile::tempdir().unwrap();
        let items: Vec<Item> = ["done", "broken", "killed", "waiting"]
            .iter()
            .enumerate()
            .map(|(index, n)| Item {
                index,
                name: n.to_string(),
                input: format!("{n}.obj").into(),
                set: vec![],
            })
            .collect();
        std::fs::write(dir.path().join(ITEMS), items_json(&items)).unwrap();
        for (name, r) in [
            ("done", Some(record(Status::Done, None))),
            ("broken", Some(record(Status::Failed, Some("bad | mesh")))),
            ("killed", None),
        ] {
            let d = dir.path().join(name);
            std::fs::create_dir(&d).unwrap();
            if let Some(r) = r {
                std::fs::write(d.join(RECORD), serde_json::to_string(&r).unwrap()).unwrap();
            }
        }
        std::fs::write(
            dir.path().join("done").join(names::METRICS),
            r#"{"metrics":{"image":{"editability":0.95},"partuv":{"charts":7,"angular_score":0.96},"uv":{"flipped_faces":0}}}"#,
        )
        .unwrap();
        assert!(is_done(&dir.path().join("done")) && !is_done(&dir.path().join("broken")));
        let rows = summarise(dir.path());
        let status: Vec<&str> = rows.iter().map(|r| r.status.as_str()).collect();
        assert_eq!(status, ["done", "failed", "running or killed", "not started"]);
        assert_eq!(rows[0].metrics, [Some(0.95), Some(0.96), Some(7.0), None, Some(0.0), None]);
        let md = markdown(&rows);
        assert!(md.starts_with("4 items: 1 done, 1 failed, 1 running or killed, 1 not started\n"), "{md}");
        assert!(md.contains("| done | done | 2.5 | 0.9500 | 0.9600 | 7 | | 0 | | |"), "{md}");
        assert!(md.contains("bad \\| mesh"), "{md}");
        let csv = csv(&rows);
        assert_eq!(csv.lines().count(), 5);
        assert_eq!(csv.lines().nth(1).unwrap(), "done,done.obj,done,2.5,0.95,0.96,7,,0,,");
    }

    #[test]
    fn a_status_reads_as_its_serde_name() {
        for s in [Status::Done, Status::Failed, Status::TimedOut] {
            assert_eq!(serde_json::to_value(s).unwrap(), s.as_str());
        }
    }

    #[test]
    fn without_a_list_the_items_are_the_folders_with_a_record() {
        let dir = tempfile::tempdir().unwrap();
        for name in ["b", "a", "no_record"] {
            std::fs::create_dir(dir.path().join(name)).unwrap();
        }
        for name in ["b", "a"] {
            std::fs::write(
                dir.path().join(name).join(RECORD),
                serde_json::to_string(&record(Status::Done, None)).unwrap(),
            )
            .unwrap();
        }
        let names: Vec<String> = listed_items(dir.path()).into_iter().map(|i| i.name).collect();
        assert_eq!(names, ["a", "b"]);
    }
}

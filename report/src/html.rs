//! The page: one self-contained HTML file. Every picture, plot, model and script is inside it, so
//! it opens from disk with no network and no server.
//!
//! Sections, top to bottom: warnings, the metrics table (sortable by clicking a header), the config
//! differences, the loss curves (against step or training seconds, switched without script), and
//! the runs side by side. Each run shows its 3-D view of `atlas.glb` (rotate by dragging, zoom with
//! the wheel), its pictures, and its metrics, decisions and config in full, with the lines that
//! differ from another run's marked.

use std::collections::BTreeSet;
use std::fmt::Write as _;

use crate::ReportError;
use crate::config_diff;
use crate::curves::{self, Line, colour_css};
use crate::log::TOTAL;
use crate::metrics::{COLUMNS, best, value};
use crate::run::Run;

/// The vendored viewer (`report/vendor/model-viewer/README.md`), without its source-map line.
const MODEL_VIEWER: &str = include_str!("../vendor/model-viewer/model-viewer-umd.min.js");

/// The viewer's script, without the `//# sourceMappingURL` line that would make a browser's
/// developer tools ask for a file the report does not carry.
fn model_viewer_script() -> &'static str {
    let s = MODEL_VIEWER.trim_end();
    match s.rfind('\n') {
        Some(i) if s[i + 1..].starts_with("//# sourceMappingURL=") => &s[..i],
        _ => s,
    }
}

const STYLE: &str = r#"
body { font: 14px/1.45 system-ui, sans-serif; margin: 0 24px 48px; color: #222; }
h1 { font-size: 22px; margin: 18px 0 4px; }
h2 { font-size: 18px; margin: 28px 0 8px; border-bottom: 1px solid #ddd; padding-bottom: 4px; }
h3 { font-size: 16px; margin: 4px 0; }
table { border-collapse: collapse; font-variant-numeric: tabular-nums; }
th, td { border: 1px solid #ddd; padding: 3px 8px; text-align: right; white-space: nowrap; }
th { background: #f4f4f4; cursor: pointer; user-select: none; }
th.group { cursor: default; text-align: center; }
td.name, th.name { text-align: left; }
td.best { font-weight: bold; background: #e8f4e8; }
td.text { text-align: left; white-space: pre-wrap; font-family: ui-monospace, monospace; font-size: 12px; }
.swatch { display: inline-block; width: 12px; height: 12px; border-radius: 2px; margin-right: 6px; vertical-align: -1px; }
.scroll { overflow-x: auto; }
.warnings { background: #fff4e0; border: 1px solid #f0c060; padding: 6px 12px; }
.plots { display: flex; flex-wrap: wrap; gap: 8px; }
.plots svg { border: 1px solid #eee; }
#axis-seconds:checked ~ .by-step, #axis-step:checked ~ .by-seconds { display: none; }
.runs { display: grid; grid-auto-flow: column; grid-auto-columns: minmax(420px, 1fr); gap: 16px; overflow-x: auto; }
.run { border: 1px solid #ddd; border-radius: 6px; padding: 10px; min-width: 0; }
.run .path { color: #666; font-size: 12px; word-break: break-all; }
model-viewer { width: 100%; height: 380px; background: #f7f7f7; border-radius: 4px; }
.pictures { display: flex; flex-wrap: wrap; gap: 8px; margin-top: 8px; }
figure { margin: 0; }
figure img { max-width: 100%; width: 200px; image-rendering: auto; border: 1px solid #eee; }
figure.wide img { width: 100%; max-width: 520px; }
figcaption { font-size: 12px; color: #555; max-width: 200px; }
figure.wide figcaption { max-width: 520px; }
pre { background: #f7f7f7; padding: 8px; overflow-x: auto; font-size: 12px; max-height: 480px; }
pre mark { background: #ffe58a; }
details { margin-top: 8px; }
summary { cursor: pointer; }
"#;

/// Click a header of a `table.sortable` to sort its rows by that column (numbers as numbers, a
/// dash last); click again to reverse.
const SORT_SCRIPT: &str = r#"
for (const table of document.querySelectorAll('table.sortable')) {
  const head = table.tHead.rows[table.tHead.rows.length - 1];
  for (const th of head.cells) {
    th.addEventListener('click', () => {
      const k = th.cellIndex, body = table.tBodies[0];
      const up = th.dataset.order !== 'up';
      for (const other of head.cells) delete other.dataset.order;
      th.dataset.order = up ? 'up' : 'down';
      const key = row => { const t = row.cells[k].dataset.value ?? row.cells[k].textContent; const n = parseFloat(t); return isNaN(n) ? t : n; };
      const rows = [...body.rows].sort((a, b) => {
        const x = key(a), y = key(b);
        if (x === y) return 0;
        if (x === '\u2014') return 1; if (y === '\u2014') return -1;
        return (typeof x === 'number' && typeof y === 'number' ? x - y : String(x).localeCompare(String(y))) * (up ? 1 : -1);
      });
      body.append(...rows);
    });
  }
}
"#;

/// The whole page for `runs` (at least one).
pub fn page(runs: &[Run]) -> Result<String, ReportError> {
    let mut h = String::with_capacity(1 << 20);
    let labels: Vec<&str> = runs.iter().map(|r| r.label.as_str()).collect();
    let title = format!("nuvo report: {}", labels.join(", "));
    let _ = write!(
        h,
        "<!doctype html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n<title>{}</title>\n<style>{STYLE}</style>\n</head>\n<body>\n",
        escape(&title)
    );
    let _ = write!(
        h,
        "<h1>nuvo report</h1>\n<p>{} run{}, written by nuvo {}. Everything is inside this file; it needs no network.</p>\n",
        runs.len(),
        if runs.len() == 1 { "" } else { "s" },
        env!("CARGO_PKG_VERSION")
    );
    warnings(&mut h, runs);
    metrics_table(&mut h, runs);
    let differing = config_differences(&mut h, runs);
    loss_curves(&mut h, runs)?;
    h.push_str("<h2 id=\"runs\">Runs</h2>\n<div class=\"runs\">\n");
    for (k, run) in runs.iter().enumerate() {
        run_column(&mut h, k, run, &differing);
    }
    h.push_str("</div>\n");
    let _ = writeln!(h, "<script>{SORT_SCRIPT}</script>");
    if runs.iter().any(|r| r.glb.is_some()) {
        let _ = write!(h, "<script>\n{}\n</script>\n", model_viewer_script());
    }
    h.push_str("</body>\n</html>\n");
    Ok(h)
}

fn swatch(k: usize) -> String {
    format!("<span class=\"swatch\" style=\"background:{}\"></span>", colour_css(k))
}

fn warnings(h: &mut String, runs: &[Run]) {
    let all: Vec<String> =
        runs.iter().flat_map(|r| r.warnings.iter().map(move |w| format!("{}: {w}", r.label))).collect();
    if all.is_empty() {
        return;
    }
    h.push_str("<div class=\"warnings\" id=\"warnings\"><b>Warnings</b><ul>\n");
    for w in all {
        let _ = writeln!(h, "<li>{}</li>", escape(&w));
    }
    h.push_str("</ul></div>\n");
}

fn metrics_table(h: &mut String, runs: &[Run]) {
    h.push_str("<h2 id=\"metrics\">Metrics</h2>\n<div class=\"scroll\"><table class=\"sortable\" id=\"metrics-table\">\n<thead>\n<tr><th class=\"group\"></th>");
    let mut groups: Vec<(&str, usize)> = Vec::new();
    for c in &COLUMNS {
        match groups.last_mut() {
            Some((g, n)) if *g == c.group => *n += 1,
            _ => groups.push((c.group, 1)),
        }
    }
    for (g, n) in groups {
        let _ = write!(h, "<th class=\"group\" colspan=\"{n}\">{}</th>", escape(g));
    }
    h.push_str("<th class=\"group\"></th><th class=\"group\"></th></tr>\n<tr><th class=\"name\">run</th>");
    for c in &COLUMNS {
        let arrow = match c.better {
            crate::metrics::Better::Higher => "\u{2191}",
            crate::metrics::Better::Lower => "\u{2193}",
        };
        let _ = write!(h, "<th>{} {arrow}</th>", escape(c.label));
    }
    h.push_str("<th>training s</th><th class=\"name\">status</th></tr>\n</thead>\n<tbody>\n");
    let columns: Vec<Vec<Option<f64>>> =
        COLUMNS.iter().map(|c| runs.iter().map(|r| value(r.metrics.as_ref(), c)).collect()).collect();
    let bests: Vec<Option<usize>> = COLUMNS.iter().zip(&columns).map(|(c, v)| best(v, c.better)).collect();
    for (k, run) in runs.iter().enumerate() {
        let _ = write!(h, "<tr><td class=\"name\">{}{}</td>", swatch(k), escape(&run.label));
        for ((c, values), b) in COLUMNS.iter().zip(&columns).zip(&bests) {
            let class = if *b == Some(k) { " class=\"best\"" } else { "" };
            match values[k] {
                Some(v) => {
                    let _ = write!(h, "<td{class} data-value=\"{v}\">{v:.*}</td>", c.decimals);
                }
                None => h.push_str("<td>\u{2014}</td>"),
            }
        }
        let status = run.status();
        let _ = writeln!(
            h,
            "<td data-value=\"{s}\">{s:.1}</td><td class=\"name\">{}</td></tr>",
            escape(status.split(':').next().unwrap_or("")),
            s = run.log.seconds
        );
    }
    h.push_str("</tbody>\n</table></div>\n");
    if runs.len() > 1 {
        h.push_str("<p>Click a header to sort. The best run of each column is in bold.</p>\n");
    }
}

/// Writes the differences table; returns the keys that differ (the runs' config texts mark them).
fn config_differences(h: &mut String, runs: &[Run]) -> BTreeSet<String> {
    h.push_str("<h2 id=\"config\">Config differences</h2>\n");
    let with_config: Vec<(usize, &Run)> =
        runs.iter().enumerate().filter(|(_, r)| r.config.is_some()).collect();
    if with_config.len() < 2 {
        h.push_str("<p>Fewer than two runs with a config: nothing to compare. Each run's config is under it below.</p>\n");
        return BTreeSet::new();
    }
    let flats: Vec<config_diff::Flat> =
        with_config.iter().map(|(_, r)| r.config.clone().unwrap_or_default()).collect();
    let diff = config_diff::differences(&flats);
    if diff.is_empty() {
        h.push_str("<p>The configs are the same.</p>\n");
        return BTreeSet::new();
    }
    h.push_str("<div class=\"scroll\"><table id=\"config-table\">\n<thead><tr><th class=\"name\">key</th>");
    for (k, r) in &with_config {
        let _ = write!(h, "<th class=\"name\">{}{}</th>", swatch(*k), escape(&r.label));
    }
    h.push_str("</tr></thead>\n<tbody>\n");
    for (key, values) in &diff {
        let _ = write!(h, "<tr><td class=\"name\"><code>{}</code></td>", escape(key));
        for v in values {
            let _ = write!(h, "<td class=\"text\">{}</td>", v.as_deref().map_or("\u{2014}".into(), escape));
        }
        h.push_str("</tr>\n");
    }
    h.push_str("</tbody>\n</table></div>\n");
    diff.into_iter().map(|(k, _)| k).collect()
}

fn loss_curves(h: &mut String, runs: &[Run]) -> Result<(), ReportError> {
    h.push_str("<h2 id=\"curves\">Loss curves</h2>\n");
    let mut names: Vec<&str> = Vec::new();
    for run in runs {
        for n in run.log.names() {
            if !names.contains(&n) {
                names.push(n);
            }
        }
    }
    if let Some(i) = names.iter().position(|&n| n == TOTAL) {
        names.remove(i);
        names.insert(0, TOTAL);
    }
    if names.is_empty() {
        h.push_str("<p>No training logged yet.</p>\n");
        return Ok(());
    }
    h.push_str(
        "<div><input type=\"radio\" name=\"axis\" id=\"axis-step\" checked> <label for=\"axis-step\">against step</label> \
         <input type=\"radio\" name=\"axis\" id=\"axis-seconds\"> <label for=\"axis-seconds\">against training seconds</label>\n",
    );
    if runs.len() > 1 {
        h.push_str("<p>");
        for (k, r) in runs.iter().enumerate() {
            let _ = write!(h, "{}{} &nbsp; ", swatch(k), escape(&r.label));
        }
        h.push_str("</p>\n");
    }
    for (class, x_label) in [("by-step", "step"), ("by-seconds", "training seconds")] {
        let _ = writeln!(h, "<div class=\"plots {class}\">");
        for name in &names {
            let lines: Vec<Line> = runs
                .iter()
                .enumerate()
                .filter_map(|(k, r)| {
                    let c = r.log.curves.get(*name)?;
                    let points = if class == "by-step" { &c.by_step } else { &c.by_seconds };
                    Some(Line { run: k, points })
                })
                .collect();
            if let Some(svg) = curves::panel(name, x_label, &lines)? {
                let _ = writeln!(
                    h,
                    "{}",
                    svg.replacen(
                        "<svg ",
                        &format!("<svg class=\"plot\" data-curve=\"{}\" ", escape(name)),
                        1
                    )
                );
            }
        }
        h.push_str("</div>\n");
    }
    h.push_str("</div>\n");
    Ok(())
}

fn run_column(h: &mut String, k: usize, run: &Run, differing: &BTreeSet<String>) {
    let _ = write!(
        h,
        "<article class=\"run\" data-run=\"{k}\">\n<h3>{}{}</h3>\n<div class=\"path\">{}</div>\n<p>{}</p>\n",
        swatch(k),
        escape(&run.label),
        escape(&run.dir.display().to_string()),
        escape(&run.status())
    );
    if let Some(glb) = &run.glb {
        let _ = write!(
            h,
            "<model-viewer class=\"viewer\" src=\"data:model/gltf-binary;base64,{}\" camera-controls \
             interaction-prompt=\"none\" shadow-intensity=\"0\" exposure=\"1\" alt=\"{} wearing its atlas\"></model-viewer>\n\
             <div class=\"path\">Drag to turn, scroll to zoom.</div>\n",
            base64::encode(glb),
            escape(&run.label)
        );
    } else {
        h.push_str("<p>No <code>atlas.glb</code> (yet): no 3-D view.</p>\n");
    }
    if !run.pictures.is_empty() {
        h.push_str("<div class=\"pictures\">\n");
        for p in &run.pictures {
            let wide = if p.name.starts_with("normal_grids") { " class=\"wide\"" } else { "" };
            let scaled = p
                .scaled_from
                .map_or(String::new(), |(w, h)| format!(" (shown smaller; the file is {w}×{h})"));
            let _ = writeln!(
                h,
                "<figure{wide}><img class=\"picture\" alt=\"{n}\" src=\"data:image/png;base64,{}\"><figcaption>{n}{scaled}</figcaption></figure>",
                base64::encode(&p.png),
                n = escape(&p.name)
            );
        }
        h.push_str("</div>\n");
    }
    if let Some(m) = &run.metrics {
        let pretty = serde_json::to_string_pretty(m).unwrap_or_default();
        let _ =
            writeln!(h, "<details><summary>metrics.json</summary><pre>{}</pre></details>", escape(&pretty));
    }
    if let Some(u) = &run.unwrap_json {
        let _ = writeln!(
            h,
            "<details><summary>unwrap.json (the decisions of <code>nuvo unwrap</code>)</summary><pre>{}</pre></details>",
            escape(u)
        );
    }
    if let Some(text) = &run.config_text {
        let _ = writeln!(
            h,
            "<details{}><summary>config.toml{}</summary><pre class=\"config\">{}</pre></details>",
            if differing.is_empty() { "" } else { " open" },
            if differing.is_empty() { "" } else { " (lines that differ between runs marked)" },
            marked_config(text, differing)
        );
    }
    h.push_str("</article>\n");
}

/// The config text, escaped, with each line that sets a differing key (or a table of them, for an
/// inline table) in `<mark>`.
fn marked_config(text: &str, differing: &BTreeSet<String>) -> String {
    let mut out = String::with_capacity(text.len() + 64);
    let mut table = String::new();
    for line in text.lines() {
        let trimmed = line.trim();
        let mut mark = false;
        if trimmed.starts_with('[') && !trimmed.starts_with("[[") {
            table = trimmed.trim_start_matches('[').split(']').next().unwrap_or("").trim().to_owned();
        } else if let Some((key, _)) = trimmed.split_once('=')
            && !trimmed.starts_with('#')
        {
            let key = key.trim();
            let full = if table.is_empty() { key.to_owned() } else { format!("{table}.{key}") };
            let prefix = format!("{full}.");
            mark = differing.iter().any(|d| *d == full || d.starts_with(&prefix));
        }
        if mark {
            let _ = writeln!(out, "<mark>{}</mark>", escape(line));
        } else {
            let _ = writeln!(out, "{}", escape(line));
        }
    }
    out
}

/// Text for HTML content and attribute values.
pub fn escape(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&#39;"),
            c => out.push(c),
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_embedded_viewer_cannot_end_its_script_early_and_has_no_map_line() {
        let s = model_viewer_script();
        assert!(s.len() > 500_000, "the whole viewer is embedded");
        // `<!--` (in a template) is harmless in a script element unless a `<script` follows it.
        assert!(!s.contains("</script") && !s.contains("<script"));
        assert!(!s.contains("sourceMappingURL"));
        assert!(s.contains("customElements.define(\"model-viewer\""));
    }

    #[test]
    fn differing_lines_are_marked_in_their_tables() {
        let text = "seed = 3\n[model]\ncharts = 4\nwidth = 128\n[losses]\nchamfer = { weight = 1.0 }\n# charts = 9\n";
        let differing: BTreeSet<String> =
            ["model.charts".to_owned(), "losses.chamfer.weight".to_owned()].into();
        let marked = marked_config(text, &differing);
        assert_eq!(
            marked,
            "seed = 3\n[model]\n<mark>charts = 4</mark>\nwidth = 128\n[losses]\n<mark>chamfer = { weight = 1.0 }</mark>\n# charts = 9\n"
        );
    }

    #[test]
    fn escaping_covers_markup_and_quotes() {
        assert_eq!(escape("<a href=\"x\">&'</a>"), "&lt;a href=&quot;x&quot;&gt;&amp;&#39;&lt;/a&gt;");
    }
}

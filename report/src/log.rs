//! A run's `log.jsonl` as curves: the objective's total and every term, against step and against
//! training seconds.
//!
//! The log is read as it is, while a run may still be appending to it: a line that does not parse
//! (the half-written last line of a running run, or damage) is skipped and counted, never an error.
//! Steps skipped for a non-finite loss and non-finite values leave a gap in their curve only.

use std::collections::BTreeMap;

use nuvo_core::run::cumulative_seconds;

/// The name of the objective's total among a log's curves (a term cannot take it: terms are
/// logged under `terms`).
pub const TOTAL: &str = "total";

/// One curve: `(step, value)` and `(seconds, value)` of the same log lines.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Curve {
    pub by_step: Vec<(f64, f64)>,
    pub by_seconds: Vec<(f64, f64)>,
}

/// What a log holds, in the order its lines were written.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TrainingLog {
    /// [`TOTAL`] and every term, by name.
    pub curves: BTreeMap<String, Curve>,
    /// The last step logged (`None` for an empty log).
    pub last_step: Option<u64>,
    /// Training seconds at the last line, over every session of a resumed run.
    pub seconds: f64,
    /// Lines that were not a log entry (a running run's half-written last line).
    pub unreadable_lines: usize,
}

impl TrainingLog {
    /// Reads a log's text; never fails (module docs).
    pub fn parse(text: &str) -> Self {
        let mut entries = Vec::new();
        let mut unreadable_lines = 0;
        for line in text.lines().filter(|l| !l.trim().is_empty()) {
            match serde_json::from_str::<serde_json::Value>(line) {
                Ok(v) if v.get("step").and_then(serde_json::Value::as_u64).is_some() => entries.push(v),
                _ => unreadable_lines += 1,
            }
        }
        let seconds = cumulative_seconds(
            entries.iter().map(|e| e.get("seconds").and_then(serde_json::Value::as_f64).unwrap_or(0.0)),
        );
        let mut curves: BTreeMap<String, Curve> = BTreeMap::new();
        for (entry, &t) in entries.iter().zip(&seconds) {
            let step = entry["step"].as_u64().unwrap_or(0) as f64;
            // `skipped` says why a step was skipped; it is null (or absent, or false) when it was not.
            let skipped =
                entry.get("skipped").is_some_and(|s| !s.is_null() && *s != serde_json::Value::Bool(false));
            if skipped {
                continue;
            }
            let total = entry.get(TOTAL).map(|v| (TOTAL, v));
            let terms = entry.get("terms").and_then(serde_json::Value::as_object);
            let values = total.into_iter().chain(terms.into_iter().flatten().map(|(k, v)| (k.as_str(), v)));
            for (name, value) in values {
                if let Some(y) = value.as_f64().filter(|y| y.is_finite()) {
                    let curve = curves.entry(name.to_owned()).or_default();
                    curve.by_step.push((step, y));
                    curve.by_seconds.push((t, y));
                }
            }
        }
        TrainingLog {
            curves,
            last_step: entries.last().and_then(|e| e["step"].as_u64()),
            seconds: seconds.last().copied().unwrap_or(0.0),
            unreadable_lines,
        }
    }

    /// The curves' names, [`TOTAL`] first, then the terms by name.
    pub fn names(&self) -> impl Iterator<Item = &str> {
        let total = self.curves.contains_key(TOTAL).then_some(TOTAL);
        total.into_iter().chain(self.curves.keys().map(String::as_str).filter(|&k| k != TOTAL))
    }
}

/// At most about `2 * buckets` points of `points` (sorted by x), keeping each bucket's lowest and
/// highest value in their order, so that spikes and the envelope survive the thinning. Curves of
/// long runs would otherwise put tens of thousands of points into every SVG.
pub fn thin(points: &[(f64, f64)], buckets: usize) -> Vec<(f64, f64)> {
    if points.len() <= 2 * buckets.max(1) {
        return points.to_vec();
    }
    let per_bucket = points.len().div_ceil(buckets);
    let mut out = Vec::with_capacity(2 * buckets + 1);
    for chunk in points.chunks(per_bucket) {
        let lowest = chunk.iter().enumerate().min_by(|a, b| a.1.1.total_cmp(&b.1.1)).map(|(i, _)| i);
        let highest = chunk.iter().enumerate().max_by(|a, b| a.1.1.total_cmp(&b.1.1)).map(|(i, _)| i);
        let (Some(lo), Some(hi)) = (lowest, highest) else { continue };
        let (first, second) = if lo <= hi { (lo, hi) } else { (hi, lo) };
        out.push(chunk[first]);
        if second != first {
            out.push(chunk[second]);
        }
    }
    if out.last() != points.last() {
        out.extend(points.last());
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    const LOG: &str = r#"{"step":0,"total":3.0,"terms":{"chamfer":2.0,"cluster":1.0},"seconds":0.5,"skipped":false}
{"step":1,"total":2.0,"terms":{"chamfer":1.5,"cluster":0.5},"seconds":1.0,"skipped":null}
{"step":2,"total":5.0,"terms":{"chamfer":5.0},"seconds":1.5,"skipped":"non-finite loss"}
{"step":3,"total":1.0,"terms":{"chamfer":0.75,"cluster":null},"seconds":2.0,"skipped":null}
{"step":4,"total":0.9,"ter"#;

    #[test]
    fn curves_of_a_running_runs_log_skip_bad_steps_and_the_half_written_line() {
        let log = TrainingLog::parse(LOG);
        assert_eq!(log.names().collect::<Vec<_>>(), ["total", "chamfer", "cluster"]);
        assert_eq!(log.curves["total"].by_step, [(0.0, 3.0), (1.0, 2.0), (3.0, 1.0)]);
        assert_eq!(log.curves["chamfer"].by_seconds, [(0.5, 2.0), (1.0, 1.5), (2.0, 0.75)]);
        assert_eq!(log.curves["cluster"].by_step, [(0.0, 1.0), (1.0, 0.5)], "a null value is a gap");
        assert_eq!(log.last_step, Some(3));
        assert_eq!(log.seconds, 2.0);
        assert_eq!(log.unreadable_lines, 1);
    }

    #[test]
    fn an_old_resumed_log_counts_seconds_across_its_sessions() {
        let text = "{\"step\":0,\"total\":1,\"seconds\":1.0}\n{\"step\":1,\"total\":1,\"seconds\":2.0}\n\
                    {\"step\":2,\"total\":1,\"seconds\":0.5}\n";
        let log = TrainingLog::parse(text);
        assert_eq!(log.curves["total"].by_seconds.iter().map(|p| p.0).collect::<Vec<_>>(), [1.0, 2.0, 2.5]);
        assert_eq!(log.seconds, 2.5);
    }

    #[test]
    fn an_empty_log_has_no_curves() {
        let log = TrainingLog::parse("");
        assert!(log.curves.is_empty());
        assert_eq!((log.last_step, log.seconds, log.unreadable_lines), (None, 0.0, 0));
    }

    #[test]
    fn thinning_keeps_each_buckets_extremes_and_the_ends() {
        let points: Vec<(f64, f64)> =
            (0..1000).map(|i| (i as f64, if i == 537 { 100.0 } else { 1.0 })).collect();
        let thinned = thin(&points, 50);
        assert!(thinned.len() <= 101, "{}", thinned.len());
        assert!(thinned.contains(&(537.0, 100.0)), "the spike survives");
        assert_eq!(thinned.first(), points.first());
        assert_eq!(thinned.last(), points.last());
        assert!(thinned.windows(2).all(|w| w[0].0 < w[1].0), "still sorted by x");
        assert_eq!(thin(&points[..10], 50), &points[..10]);
    }
}

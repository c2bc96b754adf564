//! The numbers a report puts side by side, read from `metrics.json` by path so that old run
//! folders, which lack the newer numbers, show a dash where a number is missing and nothing else.

use nuvo_core::outputs::metric_paths::*;

/// Which way a metric is better; the comparison table marks the best run of each column.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Better {
    Higher,
    Lower,
}

/// One column of the metrics table.
#[derive(Clone, Copy, Debug)]
pub struct Column {
    pub group: &'static str,
    pub label: &'static str,
    /// JSON pointer into `metrics.json` (`nuvo_core::outputs::metric_paths`).
    pub pointer: &'static str,
    pub better: Better,
    /// Decimals shown (0 for counts).
    pub decimals: usize,
}

const fn column(
    group: &'static str,
    label: &'static str,
    pointer: &'static str,
    better: Better,
    decimals: usize,
) -> Column {
    Column { group, label, pointer, better, decimals }
}

/// The paper's metrics (Table 1), PartUV's set (`../shared/data/benchmark/README.md`), and the
/// atlas's health.
pub const COLUMNS: [Column; 16] = [
    column("paper", "Boundary", BOUNDARY, Better::Higher, 4),
    column("paper", "Stretch", STRETCH, Better::Higher, 4),
    column("paper", "Conformal", CONFORMAL, Better::Higher, 4),
    column("paper", "UV Eff.", UV_EFFICIENCY, Better::Higher, 4),
    column("paper", "Editability", EDITABILITY, Better::Higher, 4),
    column("PartUV", "charts", CHARTS, Better::Lower, 0),
    column("PartUV", "seam length", SEAM_LENGTH, Better::Lower, 2),
    column("PartUV", "angular", ANGULAR, Better::Higher, 4),
    column("PartUV", "area (worst chart)", AREA_WORST_CHART, Better::Lower, 3),
    column("PartUV", "area (overall)", AREA_OVERALL, Better::Lower, 3),
    column("PartUV", "packing", PACKING, Better::Higher, 3),
    column("atlas", "flipped faces", FLIPPED_FACES, Better::Lower, 0),
    column("atlas", "overlapping faces", OVERLAPPING_FACES, Better::Lower, 0),
    column("atlas", "texel aspect (median)", TEXEL_ASPECT_MEDIAN, Better::Lower, 3),
    column("atlas", "texel aspect (p90)", TEXEL_ASPECT_P90, Better::Lower, 3),
    column("atlas", "steps", STEPS, Better::Lower, 0),
];

/// The column's number in a run's metrics, if it has one.
pub fn value(metrics: Option<&serde_json::Value>, column: &Column) -> Option<f64> {
    metrics?.pointer(column.pointer)?.as_f64().filter(|v| v.is_finite())
}

/// The index of the best run of a column among `values` (`None` when fewer than two runs have a
/// number, or when they all tie: there is nothing to mark).
pub fn best(values: &[Option<f64>], better: Better) -> Option<usize> {
    let present: Vec<(usize, f64)> =
        values.iter().enumerate().filter_map(|(i, v)| Some((i, (*v)?))).collect();
    if present.len() < 2 || present.iter().all(|p| p.1 == present[0].1) {
        return None;
    }
    let pick = |a: &(usize, f64), b: &(usize, f64)| match better {
        Better::Higher => a.1.total_cmp(&b.1),
        Better::Lower => b.1.total_cmp(&a.1),
    };
    // Ties go to the first run with the best value.
    present.iter().rev().max_by(|a, b| pick(a, b)).map(|p| p.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers_come_from_their_paths_and_missing_ones_are_none() {
        let m = serde_json::json!({
            "metrics": {"image": {"editability": 0.95}, "partuv": {"charts": 12}, "uv": {"texel_aspect_p90": 1.4}},
            "steps": 300
        });
        let get = |label: &str| value(Some(&m), COLUMNS.iter().find(|c| c.label == label).unwrap());
        assert_eq!(get("Editability"), Some(0.95));
        assert_eq!(get("charts"), Some(12.0));
        assert_eq!(get("steps"), Some(300.0));
        assert_eq!(get("angular"), None, "an old run has no PartUV angular score");
        assert_eq!(get("texel aspect (p90)"), Some(1.4));
        assert_eq!(get("texel aspect (median)"), None);
        assert_eq!(value(None, &COLUMNS[0]), None);
    }

    #[test]
    fn the_best_run_follows_the_direction_and_needs_two_numbers() {
        assert_eq!(best(&[Some(0.9), None, Some(0.95), Some(0.95)], Better::Higher), Some(2));
        assert_eq!(best(&[Some(12.0), Some(9.0), Some(30.0)], Better::Lower), Some(1));
        assert_eq!(best(&[Some(1.0), None], Better::Lower), None);
        assert_eq!(best(&[Some(1.0), Some(1.0)], Better::Lower), None);
    }
}

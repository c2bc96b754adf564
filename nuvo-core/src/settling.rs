//! Whether the atlas has settled: how much the chart assignment and the shape of each chart's
//! texture map changed between two looks at a fixed set of probe points.
//!
//! Why not the loss: with a constant learning rate the objective keeps falling slowly for
//! thousands of steps (the distortion terms most of all), while the atlas a bake makes from the
//! networks stops changing much earlier, because the layout passes after the bake (refinement,
//! injectivity, packing) redo the within-chart distortion anyway. What training alone decides is
//! which chart each part of the surface goes to and roughly how each chart lies in its square;
//! those two are what a [`Snapshot`] records.
//!
//! A chart's UVs are compared up to a similarity (a chart that only turns or drifts in its square
//! has not changed: packing places it anew), so [`Movement::shape_change`] is the share of a
//! chart's UV spread that no rotation, scale and translation of the old UVs explains.

use nalgebra::Vector2;
use nuvo_atlas::bake::{argmax, chart_uv};

/// What the networks say at the probe points: each point's chart (the most probable) and its UV
/// in that chart.
#[derive(Clone, Debug, PartialEq)]
pub struct Snapshot {
    /// The chart of each probe point.
    pub charts: Vec<u32>,
    /// The UV of each probe point in its chart.
    pub uvs: Vec<[f32; 2]>,
}

impl Snapshot {
    /// A snapshot from the networks' fields at the probe points (`n` charts; `probs` is `P×n`,
    /// `uvs` is `P×n×2`, as in `AtlasFields`).
    pub fn from_fields(probs: &[f32], uvs: &[f32], n: usize) -> Self {
        let points = probs.len() / n.max(1);
        let mut snapshot = Snapshot { charts: Vec::with_capacity(points), uvs: Vec::with_capacity(points) };
        for (k, row) in probs.chunks_exact(n).enumerate() {
            let chart = argmax(row.iter().copied());
            snapshot.charts.push(chart);
            snapshot.uvs.push(chart_uv(uvs, n, k as u32, chart as usize));
        }
        snapshot
    }
}

/// How much the atlas moved between two snapshots of the same probe points.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct Movement {
    /// Share of the probe points whose chart changed.
    pub charts_changed: f32,
    /// Over the points that kept their chart, the root of the share of each chart's UV variance
    /// that the best similarity of its old UVs leaves unexplained, weighted by the chart's points
    /// (0: every chart only moved rigidly or scaled in its square).
    pub shape_change: f32,
}

/// The movement from `before` to `after` (snapshots of the same probe points).
pub fn movement(before: &Snapshot, after: &Snapshot) -> Movement {
    assert_eq!(before.charts.len(), after.charts.len(), "snapshots of different probe sets");
    let points = before.charts.len();
    if points == 0 {
        return Movement { charts_changed: 0.0, shape_change: 0.0 };
    }
    let charts = before.charts.iter().chain(&after.charts).map(|&c| c as usize + 1).max().unwrap_or(0);
    let mut kept: Vec<Vec<(Vector2<f64>, Vector2<f64>)>> = vec![Vec::new(); charts];
    let mut changed = 0usize;
    let point = |p: [f32; 2]| Vector2::new(f64::from(p[0]), f64::from(p[1]));
    for k in 0..points {
        if before.charts[k] == after.charts[k] {
            kept[before.charts[k] as usize].push((point(before.uvs[k]), point(after.uvs[k])));
        } else {
            changed += 1;
        }
    }
    let (mut residual, mut weight) = (0.0, 0.0);
    for pairs in kept.iter().filter(|p| p.len() >= 3) {
        residual += pairs.len() as f64 * unexplained_share(pairs);
        weight += pairs.len() as f64;
    }
    Movement {
        charts_changed: changed as f32 / points as f32,
        shape_change: if weight > 0.0 { (residual / weight).sqrt() as f32 } else { 0.0 },
    }
}

/// `min over similarities S of Σ|b − S(a)|² / Σ|b − mean b|²`: 2-D Procrustes with scaling, in
/// complex numbers (centred `a`, `b`: the best `S` multiplies by `z = Σ conj(a)·b / Σ|a|²`, which
/// leaves `Σ|b|² − |Σ conj(a)·b|² / Σ|a|²`). 0 when `b` is a similar copy of `a`; 1 when nothing
/// of `b`'s spread follows `a`; 0 when `b` has no spread.
fn unexplained_share(pairs: &[(Vector2<f64>, Vector2<f64>)]) -> f64 {
    let n = pairs.len() as f64;
    let mean_a = pairs.iter().map(|p| p.0).sum::<Vector2<f64>>() / n;
    let mean_b = pairs.iter().map(|p| p.1).sum::<Vector2<f64>>() / n;
    let (mut aa, mut bb, mut re, mut im) = (0.0, 0.0, 0.0, 0.0);
    for (a, b) in pairs {
        let (a, b) = (a - mean_a, b - mean_b);
        aa += a.norm_squared();
        bb += b.norm_squared();
        // conj(a)·b = a·b + i (a × b)
        re += a.dot(&b);
        im += a.perp(&b);
    }
    if bb <= f64::MIN_POSITIVE {
        return 0.0;
    }
    let explained = if aa > f64::MIN_POSITIVE { (re * re + im * im) / aa } else { 0.0 };
    ((bb - explained) / bb).clamp(0.0, 1.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn snapshot(charts: &[u32], uvs: &[[f32; 2]]) -> Snapshot {
        Snapshot { charts: charts.to_vec(), uvs: uvs.to_vec() }
    }

    fn ring(k: usize) -> Vec<[f32; 2]> {
        (0..k)
            .map(|i| {
                let a = i as f32 * 0.7 + 0.1 * (i * i % 5) as f32;
                [0.5 + 0.3 * a.cos() * (1.0 + 0.1 * i as f32), 0.5 + 0.2 * a.sin()]
            })
            .collect()
    }

    #[test]
    fn picks_the_most_probable_chart_and_its_uv() {
        // Two points, two charts: point 0 in chart 1, point 1 in chart 0.
        let probs = [0.2, 0.8, 0.6, 0.4];
        let uvs = [0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8];
        let s = Snapshot::from_fields(&probs, &uvs, 2);
        assert_eq!(s.charts, vec![1, 0]);
        assert_eq!(s.uvs, vec![[0.3, 0.4], [0.5, 0.6]]);
    }

    #[test]
    fn a_turned_scaled_and_shifted_chart_has_not_changed() {
        let a = ring(40);
        let (c, s) = (0.6f32.cos(), 0.6f32.sin());
        let b: Vec<[f32; 2]> = a
            .iter()
            .map(|p| [0.1 + 0.7 * (c * p[0] - s * p[1]), 0.2 + 0.7 * (s * p[0] + c * p[1])])
            .collect();
        let m = movement(&snapshot(&[0; 40], &a), &snapshot(&[0; 40], &b));
        assert_eq!(m.charts_changed, 0.0);
        assert!(m.shape_change < 1e-3, "{m:?}");
    }

    #[test]
    fn a_mirrored_or_sheared_chart_has_changed() {
        let a = ring(40);
        let mirrored: Vec<[f32; 2]> = a.iter().map(|p| [1.0 - p[0], p[1]]).collect();
        let m = movement(&snapshot(&[0; 40], &a), &snapshot(&[0; 40], &mirrored));
        assert!(m.shape_change > 0.3, "{m:?}");
        // A shear by 0.1 of a roughly round spread: a small but clear change.
        let sheared: Vec<[f32; 2]> = a.iter().map(|p| [p[0] + 0.1 * p[1], p[1]]).collect();
        let m = movement(&snapshot(&[0; 40], &a), &snapshot(&[0; 40], &sheared));
        assert!(m.shape_change > 0.01 && m.shape_change < 0.2, "{m:?}");
    }

    #[test]
    fn counts_points_that_changed_chart() {
        let a = ring(8);
        let m = movement(&snapshot(&[0, 0, 0, 0, 1, 1, 1, 1], &a), &snapshot(&[0, 0, 0, 1, 1, 1, 1, 1], &a));
        assert_eq!(m.charts_changed, 0.125);
        assert!(m.shape_change < 1e-6);
    }
}

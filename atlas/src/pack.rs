//! Packing Nuvo's `n` square charts (each its own `[0,1]²`) into one atlas `[0,1]²`.
//!
//! All charts are equal squares, so a near-square grid of `columns = ceil(sqrt(n))` by
//! `rows = ceil(n / columns)` cells is optimal among grid layouts and needs no general packer.
//! Chart `i` sits in column `i % columns`, row `i / columns`, rows counted from the **top** of the
//! atlas image (largest `v`), so chart 0 is top-left in a picture.
//!
//! **Gutter.** For an atlas of `resolution²` texels, every cell is `floor(resolution / columns)`
//! texels wide and its chart square is inset by `gutter` texels on each side, with its edges on
//! texel boundaries. Neighbouring charts are thus `2·gutter` texels apart: bilinear filtering at a
//! chart's edge reads at most one texel beyond it, so `gutter ≥ 1` keeps charts from bleeding into
//! each other (mip level `k` needs `gutter ≥ 2^k`). Gutter texels should be filled by dilating the
//! chart's edge texels ([`crate::pictures::pack_images`] does).

use serde::Serialize;

use crate::error::AtlasError;

/// Where one chart lands: `atlas_uv = offset + scale · chart_uv`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct ChartPlacement {
    /// Side of the chart square in atlas UV units.
    pub scale: f32,
    /// Atlas UV of the chart's `(0, 0)` corner.
    pub offset: [f32; 2],
    /// The chart square in atlas texels: left column, top row (row 0 at `v = 1`), side.
    pub texels: [u32; 3],
}

/// A packing of `charts.len()` square charts into the atlas square. Invariants: every chart square
/// lies inside `[0,1]²`, squares are disjoint and at least `2·gutter` texels apart.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct AtlasLayout {
    /// Atlas side in texels.
    pub resolution: u32,
    /// Texels kept free around every chart square.
    pub gutter: u32,
    /// Grid columns.
    pub columns: u32,
    /// Grid rows (used ones).
    pub rows: u32,
    /// Where each chart goes, by chart index.
    pub charts: Vec<ChartPlacement>,
}

impl AtlasLayout {
    /// The grid packing of `n_charts` charts for a `resolution²` atlas with `gutter` texels around
    /// every chart (module docs). Errors if `n_charts == 0` or the gutter leaves no texel for a chart.
    pub fn grid(n_charts: usize, resolution: u32, gutter: u32) -> Result<Self, AtlasError> {
        if n_charts == 0 || n_charts > 1 << 16 {
            return Err(AtlasError::invalid(
                "atlas layout",
                format!("{n_charts} charts is not in 1..=65536"),
            ));
        }
        let columns = (n_charts as f64).sqrt().ceil() as u32;
        let rows = (n_charts as u32).div_ceil(columns);
        let cell = resolution / columns;
        let side = cell.saturating_sub(2 * gutter);
        if side == 0 {
            return Err(AtlasError::invalid(
                "atlas layout",
                format!(
                    "a {resolution}² atlas has {cell}-texel cells for {n_charts} charts: no room for a \
                     {gutter}-texel gutter on each side; raise the resolution or lower the gutter"
                ),
            ));
        }
        let r = resolution as f32;
        let charts = (0..n_charts as u32)
            .map(|i| {
                let (x0, y0) = ((i % columns) * cell + gutter, (i / columns) * cell + gutter);
                ChartPlacement {
                    scale: side as f32 / r,
                    offset: [x0 as f32 / r, 1.0 - (y0 + side) as f32 / r],
                    texels: [x0, y0, side],
                }
            })
            .collect();
        Ok(AtlasLayout { resolution, gutter, columns, rows, charts })
    }

    /// Chart `chart`'s UV `uv` in the atlas. Panics if `chart` is out of range (a caller bug).
    pub fn map(&self, chart: usize, uv: [f32; 2]) -> [f32; 2] {
        let p = &self.charts[chart];
        [p.offset[0] + p.scale * uv[0], p.offset[1] + p.scale * uv[1]]
    }

    /// Chart `chart`'s square in the atlas as `[lo, hi]`: the images of its `[0,1]²` corners under
    /// [`AtlasLayout::map`], so a mapped UV inside the chart square is inside these bounds exactly.
    pub fn chart_bounds(&self, chart: usize) -> [[f32; 2]; 2] {
        [self.map(chart, [0.0, 0.0]), self.map(chart, [1.0, 1.0])]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grid_is_near_square_inside_the_unit_square_and_gutters_are_kept() {
        for n in 1..=20usize {
            let l = AtlasLayout::grid(n, 1024, 4).unwrap();
            assert!(
                l.columns >= l.rows && l.columns * l.rows >= n as u32 && (l.columns - 1) * l.rows < n as u32
            );
            for (i, p) in l.charts.iter().enumerate() {
                for c in [[0.0, 0.0], [1.0, 1.0]] {
                    let q = l.map(i, c);
                    assert!(q.iter().all(|x| (0.0..=1.0).contains(x)), "chart {i} leaves the atlas: {q:?}");
                }
                for (j, o) in l.charts.iter().enumerate().filter(|&(j, _)| j != i) {
                    let gap_x = (p.texels[0] as i64 - o.texels[0] as i64).abs() - p.texels[2] as i64;
                    let gap_y = (p.texels[1] as i64 - o.texels[1] as i64).abs() - p.texels[2] as i64;
                    assert!(gap_x.max(gap_y) >= 8, "charts {i} and {j} are closer than two gutters");
                }
            }
        }
    }

    #[test]
    fn chart_squares_sit_on_texel_boundaries_with_chart_zero_top_left() {
        let l = AtlasLayout::grid(4, 256, 2).unwrap();
        assert_eq!((l.columns, l.rows), (2, 2));
        assert_eq!(l.charts[0].texels, [2, 2, 124]);
        // chart 0's (0, 1) corner is texel corner (2, 2) from the top-left.
        assert_eq!(l.map(0, [0.0, 1.0]), [2.0 / 256.0, 1.0 - 2.0 / 256.0]);
        assert_eq!(l.map(3, [1.0, 0.0]), [254.0 / 256.0, 2.0 / 256.0]);
    }

    #[test]
    fn impossible_layouts_are_errors() {
        assert!(AtlasLayout::grid(0, 1024, 2).is_err());
        assert!(AtlasLayout::grid(16, 16, 2).is_err());
        assert!(AtlasLayout::grid(16, 17, 1).is_ok());
    }
}

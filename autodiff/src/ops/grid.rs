//! Bilinear lookup in a square 2-D grid of feature vectors (Nuvo's per-chart normal grids `N_i`).

use super::Op;
use crate::kernels;
use crate::shape::Shape;
use crate::tape::{GradSink, Reader, Tape, Var};

/// The four texels around a UV point and the bilinear weights.
///
/// Convention (like `align_corners = true`): `u = 0` is the centre of texel column 0 and `u = 1` the
/// centre of column `res − 1`; `u` indexes columns (x) and `v` rows (y). Outside `[0, 1]` the lookup
/// clamps, and the gradient with respect to that coordinate is zero.
struct Footprint {
    x0: usize,
    y0: usize,
    x1: usize,
    y1: usize,
    fx: f32,
    fy: f32,
    /// d(texel coordinate)/d(uv), zero where clamped.
    dpx: f32,
    dpy: f32,
}

fn footprint(u: f32, v: f32, res: usize) -> Footprint {
    let span = (res - 1) as f32;
    let axis = |t: f32| -> (usize, usize, f32, f32) {
        if res == 1 {
            return (0, 0, 0.0, 0.0);
        }
        let inside = (0.0..=1.0).contains(&t);
        let p = t.clamp(0.0, 1.0) * span;
        let i0 = (p.floor() as usize).min(res - 2);
        (i0, i0 + 1, p - i0 as f32, if inside { span } else { 0.0 })
    };
    let (x0, x1, fx, dpx) = axis(u);
    let (y0, y1, fy, dpy) = axis(v);
    Footprint { x0, y0, x1, y1, fx, fy, dpx, dpy }
}

impl Tape {
    /// Bilinear lookup of `uv` (`B×2`, in `[0,1]²`) in `grid` (`res²×C`, texel `(x, y)` at row
    /// `y·res + x`). Returns `B×C`. Differentiable in both the grid values and the coordinates.
    pub fn grid_sample(&mut self, grid: Var, uv: Var, res: usize) -> Var {
        let (sg, su) = (self.shape(grid), self.shape(uv));
        assert!(res >= 1 && sg.rows == res * res, "grid_sample: a {sg} grid is not {res}×{res} texels");
        assert_eq!(su.cols, 2, "grid_sample: uv must be B×2, got {su}");
        let c = sg.cols;
        let shape = Shape::new(su.rows, c);
        let mut out = self.alloc(shape);
        let (gv, uvv) = (self.value(grid), self.value(uv));
        kernels::for_each_row(out.as_mut_slice(), c, |b, o| {
            let f = footprint(uvv[2 * b], uvv[2 * b + 1], res);
            let t = |x: usize, y: usize| &gv[(y * res + x) * c..(y * res + x + 1) * c];
            let (t00, t10, t01, t11) = (t(f.x0, f.y0), t(f.x1, f.y0), t(f.x0, f.y1), t(f.x1, f.y1));
            for k in 0..c {
                let top = t00[k] + f.fx * (t10[k] - t00[k]);
                let bottom = t01[k] + f.fx * (t11[k] - t01[k]);
                o[k] = top + f.fy * (bottom - top);
            }
        });
        self.push(Op::GridSample { grid, uv, res }, shape, out, &[grid, uv])
    }
}

pub(crate) fn backward(r: &Reader<'_>, s: &mut GradSink<'_>, g: &[f32], grid: Var, uv: Var, res: usize) {
    let c = r.shape(grid).cols;
    let (gv, uvv) = (r.value(grid), r.value(uv));
    if s.needs(uv) {
        let (dst, fresh) = s.slot(uv);
        kernels::for_each_row(dst, 2, |b, d| {
            let f = footprint(uvv[2 * b], uvv[2 * b + 1], res);
            let t = |x: usize, y: usize| &gv[(y * res + x) * c..(y * res + x + 1) * c];
            let (t00, t10, t01, t11) = (t(f.x0, f.y0), t(f.x1, f.y0), t(f.x0, f.y1), t(f.x1, f.y1));
            let (mut du, mut dv) = (0.0, 0.0);
            for k in 0..c {
                let gk = g[b * c + k];
                du += gk * ((1.0 - f.fy) * (t10[k] - t00[k]) + f.fy * (t11[k] - t01[k]));
                dv += gk * ((1.0 - f.fx) * (t01[k] - t00[k]) + f.fx * (t11[k] - t10[k]));
            }
            let (du, dv) = (du * f.dpx, dv * f.dpy);
            if fresh {
                d[0] = du;
                d[1] = dv;
            } else {
                d[0] += du;
                d[1] += dv;
            }
        });
    }
    if s.needs(grid) {
        // Scatter into four texels per sample, sequentially so the summation order is fixed.
        let dst = s.slot_zeroed(grid);
        let rows = g.len() / c.max(1);
        for b in 0..rows {
            let f = footprint(uvv[2 * b], uvv[2 * b + 1], res);
            let corners = [
                (f.x0, f.y0, (1.0 - f.fx) * (1.0 - f.fy)),
                (f.x1, f.y0, f.fx * (1.0 - f.fy)),
                (f.x0, f.y1, (1.0 - f.fx) * f.fy),
                (f.x1, f.y1, f.fx * f.fy),
            ];
            for (x, y, w) in corners {
                let t = (y * res + x) * c;
                for k in 0..c {
                    dst[t + k] += w * g[b * c + k];
                }
            }
        }
    }
}

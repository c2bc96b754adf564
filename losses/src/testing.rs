//! Test support: tiny affine "networks" whose losses can be computed by hand, and a finite-difference
//! gradient check of any loss with respect to every network parameter.

use std::cell::Cell;

use nuvo_autodiff::gradcheck::{GradCheck, check_gradients};
use nuvo_autodiff::{Activation, Tape, Tensor, Var};

use crate::context::{Reads, StepContext, StepData};
use crate::loss::Loss;
use crate::networks::Networks;

/// Affine maps recorded on the tape: logits `x·C + c`, `t_i(x) = x·A_i + a_i`, `s_i(u) = u·B_i + b_i`.
struct AffineNets {
    chart: (Var, Var),
    tex: Vec<(Var, Var)>,
    surf: Vec<(Var, Var)>,
    sigma: Var,
    grids: Vec<Var>,
    grid_res: usize,
}

impl Networks for AffineNets {
    fn charts(&self) -> usize {
        self.tex.len()
    }
    fn chart_logits(&self, tape: &mut Tape, x: Var) -> Var {
        tape.linear(x, self.chart.0, Some(self.chart.1), Activation::Identity)
    }
    fn texture(&self, tape: &mut Tape, i: usize, x: Var) -> Var {
        tape.linear(x, self.tex[i].0, Some(self.tex[i].1), Activation::Identity)
    }
    fn surface(&self, tape: &mut Tape, i: usize, uv: Var) -> Var {
        tape.linear(uv, self.surf[i].0, Some(self.surf[i].1), Activation::Identity)
    }
    fn sigma(&self, _tape: &mut Tape) -> Var {
        self.sigma
    }
    fn normal_grid(&self, _tape: &mut Tape, i: usize) -> (Var, usize) {
        (self.grids[i], self.grid_res)
    }
}

/// How many times each kind of network ran while a step was recorded.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Evaluations {
    pub chart: usize,
    pub texture: usize,
    pub surface: usize,
}

/// `nets`, counting their evaluations.
struct Counted<N> {
    nets: N,
    counts: Cell<Evaluations>,
}

impl<N: Networks> Counted<N> {
    fn count(&self, f: impl FnOnce(&mut Evaluations)) {
        let mut c = self.counts.get();
        f(&mut c);
        self.counts.set(c);
    }
}

impl<N: Networks> Networks for Counted<N> {
    fn charts(&self) -> usize {
        self.nets.charts()
    }
    fn chart_logits(&self, tape: &mut Tape, x: Var) -> Var {
        self.count(|c| c.chart += 1);
        self.nets.chart_logits(tape, x)
    }
    fn texture(&self, tape: &mut Tape, i: usize, x: Var) -> Var {
        self.count(|c| c.texture += 1);
        self.nets.texture(tape, i, x)
    }
    fn surface(&self, tape: &mut Tape, i: usize, uv: Var) -> Var {
        self.count(|c| c.surface += 1);
        self.nets.surface(tape, i, uv)
    }
    fn sigma(&self, tape: &mut Tape) -> Var {
        self.nets.sigma(tape)
    }
    fn normal_grid(&self, tape: &mut Tape, i: usize) -> (Var, usize) {
        self.nets.normal_grid(tape, i)
    }
}

/// Orthonormal tangents `(p, n × p)` for each normal.
fn tangents(normals: &[[f32; 3]]) -> (Vec<[f32; 3]>, Vec<[f32; 3]>) {
    normals
        .iter()
        .map(|n| {
            let a = if n[0].abs() < 0.9 { [1.0, 0.0, 0.0] } else { [0.0, 1.0, 0.0] };
            let d = a[0] * n[0] + a[1] * n[1] + a[2] * n[2];
            let p: [f32; 3] = std::array::from_fn(|k| a[k] - d * n[k]);
            let l = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
            let p = p.map(|v| v / l);
            let q = [n[1] * p[2] - n[2] * p[1], n[2] * p[0] - n[0] * p[2], n[0] * p[1] - n[1] * p[0]];
            (p, q)
        })
        .unzip()
}

/// A batch plus network parameters. Defaults: one chart, `t(x) = (x, y)`, `s(u) = (u, v, 0)`, normals
/// `+z`, one UV point, σ = 1, a 2×2 zero normal grid, ε = 1e-2.
#[derive(Clone)]
pub(crate) struct Scene {
    points: Vec<[f32; 3]>,
    normals: Vec<[f32; 3]>,
    uv: Vec<[f32; 2]>,
    epsilon: f32,
    /// Row-major parameter tensors in the order `AffineNets` reads them (see `nets`).
    chart_w: Tensor,
    chart_b: Tensor,
    tex: Vec<(Tensor, Tensor)>,
    surf: Vec<(Tensor, Tensor)>,
    sigma: Tensor,
    grids: Vec<Tensor>,
    grid_res: usize,
    /// Tangent frames for the first this many samples only (the distortion samples); all if `None`.
    distortion_samples: Option<usize>,
    /// `StepData::chart_support`.
    chart_support: f32,
}

impl Scene {
    /// One chart on the z = 0 plane: t and s are the plane's own coordinates.
    pub fn plane_points(points: &[[f32; 3]]) -> Self {
        Scene {
            points: points.to_vec(),
            normals: vec![[0.0, 0.0, 1.0]; points.len()],
            uv: vec![[0.25, 0.5]],
            epsilon: 1e-2,
            chart_w: Tensor::zeros(3, 1),
            chart_b: Tensor::zeros(1, 1),
            tex: vec![(Tensor::from_vec(3, 2, vec![1.0, 0.0, 0.0, 1.0, 0.0, 0.0]), Tensor::zeros(1, 2))],
            surf: vec![(Tensor::from_vec(2, 3, vec![1.0, 0.0, 0.0, 0.0, 1.0, 0.0]), Tensor::zeros(1, 3))],
            sigma: Tensor::scalar(1.0),
            grids: vec![Tensor::zeros(4, 3)],
            grid_res: 2,
            distortion_samples: None,
            chart_support: 0.0,
        }
    }

    /// Two charts with constant probabilities (¼, ¾); chart 1 is chart 0 with `s` lifted by `dz`.
    pub fn with_two_charts_shifted_z(mut self, dz: f32) -> Self {
        self.chart_w = Tensor::zeros(3, 2);
        self.chart_b = Tensor::from_vec(1, 2, vec![0.0, 3.0f32.ln()]);
        self.tex.push(self.tex[0].clone());
        let (w, _) = self.surf[0].clone();
        self.surf.push((w, Tensor::from_vec(1, 3, vec![0.0, 0.0, dz])));
        self.grids.push(self.grids[0].clone());
        self
    }

    pub fn with_uv(mut self, uv: &[[f32; 2]]) -> Self {
        self.uv = uv.to_vec();
        self
    }

    pub fn with_normals(mut self, normals: &[[f32; 3]]) -> Self {
        self.normals = normals.to_vec();
        self
    }

    /// Every chart's `t` scales x: `t(x) = (k·x, y)`.
    pub fn with_texture_scale(mut self, k: f32) -> Self {
        for (w, _) in &mut self.tex {
            w.data_mut()[0] = k;
        }
        self
    }

    /// Every chart's `t` shears: `t(x) = (x + k·y, y)`.
    pub fn with_texture_shear(mut self, k: f32) -> Self {
        for (w, _) in &mut self.tex {
            w.data_mut()[2] = k;
        }
        self
    }

    pub fn with_sigma(mut self, s: f32) -> Self {
        self.sigma = Tensor::scalar(s);
        self
    }

    pub fn with_constant_grid(mut self, value: [f32; 3]) -> Self {
        for g in &mut self.grids {
            for row in g.data_mut().chunks_exact_mut(3) {
                row.copy_from_slice(&value);
            }
        }
        self
    }

    /// Only the first `k` samples carry tangent frames, so the distortion losses read those alone.
    pub fn with_distortion_samples(mut self, k: usize) -> Self {
        self.distortion_samples = Some(k);
        self
    }

    /// Evaluate the `c(x)`-weighted losses only where `c(x)[i] ≥ tau` (see `StepData`).
    pub fn with_chart_support(mut self, tau: f32) -> Self {
        self.chart_support = tau;
        self
    }

    /// Chart 1's logit minus chart 0's becomes `slope·x + bias` (x the first coordinate), so the
    /// chart probabilities vary across the samples. Needs two charts.
    pub fn with_chart_logits_along_x(mut self, slope: f32, bias: f32) -> Self {
        assert_eq!(self.tex.len(), 2, "with_chart_logits_along_x needs two charts");
        self.chart_w = Tensor::from_vec(3, 2, vec![0.0, slope, 0.0, 0.0, 0.0, 0.0]);
        self.chart_b = Tensor::from_vec(1, 2, vec![0.0, bias]);
        self
    }

    pub fn epsilon(&self) -> f32 {
        self.epsilon
    }

    /// Every parameter tensor, in the order [`Scene::nets`] consumes them.
    fn params(&self) -> Vec<Tensor> {
        let mut p = vec![self.chart_w.clone(), self.chart_b.clone()];
        for (w, b) in self.tex.iter().chain(&self.surf) {
            p.push(w.clone());
            p.push(b.clone());
        }
        p.push(self.sigma.clone());
        p.extend(self.grids.iter().cloned());
        p
    }

    fn nets(&self, v: &[Var]) -> AffineNets {
        let n = self.tex.len();
        let pair = |k: usize| (v[k], v[k + 1]);
        AffineNets {
            chart: pair(0),
            tex: (0..n).map(|i| pair(2 + 2 * i)).collect(),
            surf: (0..n).map(|i| pair(2 + 2 * n + 2 * i)).collect(),
            sigma: v[2 + 4 * n],
            grids: v[3 + 4 * n..].to_vec(),
            grid_res: self.grid_res,
        }
    }

    /// Records `loss` with the parameters `v` and returns its Var.
    fn record(&self, tape: &mut Tape, v: &[Var], loss: &dyn Loss) -> Var {
        let nets = self.nets(v);
        self.with_context(tape, &nets, Some(Reads::NOTHING), |ctx| {
            loss.evaluate(ctx).expect("built-in losses do not fail on a valid scene")
        })
    }

    /// The sum of `losses` and its gradient with respect to every parameter, recorded on a context
    /// told `reads` (`None`: a context that never stacks evaluations), and how often each network
    /// ran.
    pub fn total_and_gradients(
        &self,
        losses: &[Box<dyn Loss>],
        reads: Option<Reads>,
    ) -> (f32, Vec<Vec<f32>>, Evaluations) {
        let mut tape = Tape::default();
        let params = self.params();
        let leaves: Vec<Var> = params.iter().map(|t| tape.leaf(t)).collect();
        let nets = Counted { nets: self.nets(&leaves), counts: Default::default() };
        let total = self.with_context(&mut tape, &nets, reads, |ctx| {
            let terms: Vec<Var> =
                losses.iter().map(|l| l.evaluate(ctx).expect("built-in losses do not fail")).collect();
            terms.into_iter().reduce(|a, b| ctx.tape.add(a, b)).expect("at least one loss")
        });
        tape.backward(total);
        let grads = (leaves.iter().zip(&params))
            .map(|(&l, t)| tape.grad(l).map(<[f32]>::to_vec).unwrap_or_else(|| vec![0.0; t.data().len()]))
            .collect();
        (tape.scalar(total), grads, nets.counts.get())
    }

    /// Runs `f` on a context of this scene's step data over `nets`.
    fn with_context<R>(
        &self,
        tape: &mut Tape,
        nets: &dyn Networks,
        reads: Option<Reads>,
        f: impl FnOnce(&mut StepContext<'_>) -> R,
    ) -> R {
        let k = self.distortion_samples.unwrap_or(self.normals.len());
        let (p, q) = tangents(&self.normals[..k]);
        let data = StepData {
            points: &self.points,
            normals: &self.normals,
            uv: &self.uv,
            tangents_p: &p,
            tangents_q: &q,
            epsilon: self.epsilon,
            chart_support: self.chart_support,
        };
        let ctx = StepContext::new(tape, nets, data);
        let mut ctx = match reads {
            Some(reads) => ctx.reading(reads),
            None => ctx.never_stacking(),
        };
        f(&mut ctx)
    }

    /// The loss value.
    pub fn evaluate(&self, loss: &dyn Loss) -> f32 {
        let mut tape = Tape::default();
        let v: Vec<Var> = self.params().iter().map(|t| tape.input(t)).collect();
        let out = self.record(&mut tape, &v, loss);
        tape.scalar(out)
    }

    /// A generic two-chart scene, off any plane, with every parameter non-trivial and texture
    /// coordinates strictly inside grid cells (so the bilinear lookup is smooth).
    pub fn generic() -> Self {
        let normals: Vec<[f32; 3]> =
            [[0.1f32, -0.2, 1.0], [-0.3, 0.1, 1.0], [0.2, 0.3, 1.0], [0.0, -0.1, 1.0]]
                .iter()
                .map(|n| {
                    let l = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
                    n.map(|v| v / l)
                })
                .collect();
        Scene {
            points: vec![[0.11, 0.23, 0.05], [0.62, 0.41, -0.03], [0.37, 0.78, 0.02], [0.83, 0.15, 0.04]],
            normals,
            uv: vec![[0.2, 0.3], [0.7, 0.6], [0.45, 0.85]],
            epsilon: 1e-2,
            chart_w: Tensor::from_vec(3, 2, vec![0.3, -0.2, 0.1, 0.4, -0.5, 0.2]),
            chart_b: Tensor::from_vec(1, 2, vec![0.1, -0.1]),
            tex: vec![
                (
                    Tensor::from_vec(3, 2, vec![0.7, 0.1, 0.05, 0.8, 0.2, -0.1]),
                    Tensor::from_vec(1, 2, vec![0.05, 0.04]),
                ),
                (
                    Tensor::from_vec(3, 2, vec![0.8, -0.1, 0.1, 0.6, -0.2, 0.3]),
                    Tensor::from_vec(1, 2, vec![0.03, 0.12]),
                ),
            ],
            surf: vec![
                (
                    Tensor::from_vec(2, 3, vec![1.0, 0.1, 0.05, 0.05, 0.9, -0.1]),
                    Tensor::from_vec(1, 3, vec![0.02, 0.01, 0.03]),
                ),
                (
                    Tensor::from_vec(2, 3, vec![0.8, -0.2, 0.1, 0.1, 1.1, 0.05]),
                    Tensor::from_vec(1, 3, vec![0.1, -0.05, 0.0]),
                ),
            ],
            sigma: Tensor::scalar(0.3),
            grids: (0..2)
                .map(|g| {
                    Tensor::from_vec(
                        16,
                        3,
                        (0..48).map(|i| (((i * 7 + g * 5) % 11) as f32 - 5.0) / 6.0).collect(),
                    )
                })
                .collect(),
            grid_res: 4,
            distortion_samples: None,
            chart_support: 0.0,
        }
    }
}

/// Checks `loss`'s gradient with respect to every network parameter of [`Scene::generic`] against
/// finite differences.
pub(crate) fn check_loss_gradient(loss: &dyn Loss) {
    check_loss_gradient_on(&Scene::generic(), loss);
}

/// [`check_loss_gradient`] on a variant of [`Scene::generic`] (same points and networks).
pub(crate) fn check_loss_gradient_on(scene: &Scene, loss: &dyn Loss) {
    // The texture coordinates must sit strictly inside grid cells for the check to be meaningful.
    let tex = |i: usize, x: &[f32; 3]| -> [f32; 2] {
        let (w, b) = &scene.tex[i];
        std::array::from_fn(|c| (0..3).map(|k| x[k] * w.get(k, c)).sum::<f32>() + b.get(0, c))
    };
    for i in 0..2 {
        for x in &scene.points {
            for c in tex(i, x) {
                let cell = c * (scene.grid_res - 1) as f32;
                assert!(c > 0.0 && c < 1.0 && (cell - cell.round()).abs() > 0.02, "bad test scene: uv {c}");
            }
        }
    }
    let params = scene.params();
    check_gradients(|t, v| scene.record(t, v, loss), &params, GradCheck::default())
        .unwrap_or_else(|e| panic!("gradient check failed: {e}"));
}

//! The per-step context: the batch, and every network output a loss may read, computed once.
//!
//! Losses ask for quantities (`c(x)`, `t_i(x)`, `s_i(u)`, …) through getters. The first request
//! records the evaluation on the tape and caches the [`Var`]; later requests, from the same or another
//! loss, get the cached one. So however many losses read `t_i(x)`, each network runs once per input.
//!
//! The `support_*` getters serve the losses whose per-chart terms are weighted by `c(x)[i]`: they
//! evaluate chart `i` only on its *support*, the samples where `c(x)[i] ≥ τ`
//! (`training.chart_support`). Once the charts have settled, most samples belong to one or two of
//! them, so this skips most of the per-chart passes over the 3-D samples while changing each loss
//! by less than `τ` times its size. With `τ = 0` they return exactly what the plain getters do.

use nuvo_autodiff::{Shape, Tape, Var};

use crate::networks::Networks;

/// The raw data of one step. Invariant: `points` and `normals` have the same length `B`;
/// `tangents_p` and `tangents_q` have the same length `k ≤ B` and `(tangents_p[j], tangents_q[j],
/// normals[j])` is an orthonormal frame: the first `k` samples are the ones the distortion losses
/// read (all of them unless `training.batch_distortion` says otherwise).
#[derive(Clone, Copy, Debug)]
pub struct StepData<'a> {
    /// Surface samples `x` in the model frame.
    pub points: &'a [[f32; 3]],
    /// Unit normals at the samples.
    pub normals: &'a [[f32; 3]],
    /// Random UV points `u`, uniform in `[0, 1]²`, shared by every chart.
    pub uv: &'a [[f32; 2]],
    /// First random unit tangent `p` at each sample.
    pub tangents_p: &'a [[f32; 3]],
    /// Second unit tangent `q = n × p`.
    pub tangents_q: &'a [[f32; 3]],
    /// Finite-difference step `ε` of the distortion losses (the paper uses 1e-2).
    pub epsilon: f32,
    /// The chart-support threshold `τ` of the `support_*` getters (`training.chart_support`): chart
    /// `i` is evaluated on the samples where `c(x)[i] ≥ τ`. 0 evaluates every chart everywhere.
    pub chart_support: f32,
}

/// The 3-D samples a chart is evaluated on by the `support_*` getters: those where its probability
/// reaches the threshold. Invariant: `rows` is strictly increasing and non-empty, so the distortion
/// samples among them (indices below `k`) are its first `distortion` entries.
#[derive(Clone, Debug)]
struct Support {
    rows: Vec<u32>,
    distortion: usize,
}

#[derive(Default)]
struct Cache {
    x: Option<Var>,
    normals: Option<Var>,
    uv: Option<Var>,
    offsets: Option<(Var, Var)>,
    chart_logits: Option<Var>,
    chart_probs: Option<Var>,
    tex: Vec<Option<Var>>,
    tex_offsets: Vec<Option<(Var, Var)>>,
    differentials: Vec<Option<(Var, Var)>>,
    cycle_points: Vec<Option<Var>>,
    surface_points: Vec<Option<Var>>,
    cycle_uv: Vec<Option<Var>>,
    all_surface_points: Option<Var>,
    chart_log_probs_at_surface: Option<Var>,
    sigma: Option<Var>,
    grids: Vec<Option<(Var, usize)>>,
    /// Per chart: `None` when the chart is evaluated on every sample (no pruning).
    support: Vec<Option<Option<Support>>>,
    support_tex: Vec<Option<Var>>,
    support_differentials: Vec<Option<(Var, Var)>>,
    support_cycle_points: Vec<Option<Var>>,
}

/// Which 3-D samples a per-chart column of a loss covers (see [`crate::chart_weighted_mean`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Samples {
    /// Every sample of the batch.
    All,
    /// The chart's support ([`StepContext::support_tex`] and the other `support_*` getters).
    Support,
    /// The distortion samples in the chart's support ([`StepContext::support_uv_differentials`]).
    DistortionSupport,
}

/// Shared forward results of one step. See the module docs.
pub struct StepContext<'a> {
    /// The tape the step records on. Losses record their own arithmetic here.
    pub tape: &'a mut Tape,
    nets: &'a dyn Networks,
    data: StepData<'a>,
    cache: Cache,
}

macro_rules! cached {
    ($self:ident . $field:ident, $compute:expr) => {{
        if let Some(v) = $self.cache.$field {
            return v;
        }
        let v = $compute;
        $self.cache.$field = Some(v);
        v
    }};
    ($self:ident . $field:ident [$i:expr], $compute:expr) => {{
        if let Some(v) = $self.cache.$field[$i] {
            return v;
        }
        let v = $compute;
        $self.cache.$field[$i] = Some(v);
        v
    }};
}

fn rows3(tape: &mut Tape, rows: &[[f32; 3]]) -> Var {
    tape.input_with(Shape::new(rows.len(), 3), |d| d.copy_from_slice(rows.as_flattened()))
}

impl<'a> StepContext<'a> {
    /// A context for one step.
    pub fn new(tape: &'a mut Tape, nets: &'a dyn Networks, data: StepData<'a>) -> Self {
        let n = nets.charts();
        let cache = Cache {
            tex: vec![None; n],
            tex_offsets: vec![None; n],
            differentials: vec![None; n],
            cycle_points: vec![None; n],
            surface_points: vec![None; n],
            cycle_uv: vec![None; n],
            grids: vec![None; n],
            support: vec![None; n],
            support_tex: vec![None; n],
            support_differentials: vec![None; n],
            support_cycle_points: vec![None; n],
            ..Cache::default()
        };
        StepContext { tape, nets, data, cache }
    }

    /// Number of charts.
    pub fn charts(&self) -> usize {
        self.nets.charts()
    }

    /// The raw step data.
    pub fn data(&self) -> &StepData<'a> {
        &self.data
    }

    /// Number of 3-D samples `|G|`.
    pub fn batch_3d(&self) -> usize {
        self.data.points.len()
    }

    /// Number of UV samples `|T|`.
    pub fn batch_uv(&self) -> usize {
        self.data.uv.len()
    }

    /// The samples `x` (`B×3`, constant).
    pub fn x(&mut self) -> Var {
        cached!(self.x, rows3(self.tape, self.data.points))
    }

    /// Their normals `n(x)` (`B×3`, constant).
    pub fn normals(&mut self) -> Var {
        cached!(self.normals, rows3(self.tape, self.data.normals))
    }

    /// The UV samples `u` (`|T|×2`, constant).
    pub fn uv(&mut self) -> Var {
        cached!(
            self.uv,
            self.tape.input_with(Shape::new(self.data.uv.len(), 2), |d| d
                .copy_from_slice(self.data.uv.as_flattened()))
        )
    }

    /// `c(x)` as logits (`B×n`).
    pub fn chart_logits(&mut self) -> Var {
        cached!(self.chart_logits, {
            let x = self.x();
            self.nets.chart_logits(self.tape, x)
        })
    }

    /// `c(x)`, the chart probabilities (`B×n`, rows sum to 1).
    pub fn chart_probs(&mut self) -> Var {
        cached!(self.chart_probs, {
            let l = self.chart_logits();
            self.tape.softmax(l)
        })
    }

    /// `t_i(x)` (`B×2`).
    pub fn tex(&mut self, i: usize) -> Var {
        cached!(self.tex[i], {
            let x = self.x();
            self.nets.texture(self.tape, i, x)
        })
    }

    /// The offset points `(x + εp, x + εq)` of the distortion samples (constants, `k×3`).
    fn offsets(&mut self) -> (Var, Var) {
        cached!(self.offsets, {
            let d = self.data;
            let shifted = |t: &[[f32; 3]]| -> Vec<[f32; 3]> {
                d.points
                    .iter()
                    .zip(t)
                    .map(|(x, t)| std::array::from_fn(|k| x[k] + d.epsilon * t[k]))
                    .collect()
            };
            let (p, q) = (shifted(d.tangents_p), shifted(d.tangents_q));
            (rows3(self.tape, &p), rows3(self.tape, &q))
        })
    }

    /// `(t_i(x + εp), t_i(x + εq))` for the distortion samples.
    pub fn tex_at_offsets(&mut self, i: usize) -> (Var, Var) {
        cached!(self.tex_offsets[i], {
            let (xp, xq) = self.offsets();
            (self.nets.texture(self.tape, i, xp), self.nets.texture(self.tape, i, xq))
        })
    }

    /// Number of distortion samples `k`: the first `k` of the 3-D samples (see [`StepData`]).
    pub fn batch_distortion(&self) -> usize {
        self.data.tangents_p.len()
    }

    /// The paper's UV vectors `D t_i(εp) ≈ t_i(x + εp) − t_i(x)` and `D t_i(εq)` (`k×2` each, for
    /// the first [`Self::batch_distortion`] samples): the finite-difference images of the tangent
    /// vectors `εp` and `εq` (not divided by `ε`).
    pub fn uv_differentials(&mut self, i: usize) -> (Var, Var) {
        cached!(self.differentials[i], {
            let k = self.batch_distortion();
            let t = self.tex(i);
            let t = if k < self.batch_3d() { self.tape.slice_rows(t, 0, k) } else { t };
            let (tp, tq) = self.tex_at_offsets(i);
            (self.tape.sub(tp, t), self.tape.sub(tq, t))
        })
    }

    /// `s_i(t_i(x))`, the 3→2→3 round trip (`B×3`).
    pub fn cycle_points(&mut self, i: usize) -> Var {
        cached!(self.cycle_points[i], {
            let t = self.tex(i);
            self.nets.surface(self.tape, i, t)
        })
    }

    /// `s_i(u)` (`|T|×3`).
    pub fn surface_points(&mut self, i: usize) -> Var {
        cached!(self.surface_points[i], {
            let u = self.uv();
            self.nets.surface(self.tape, i, u)
        })
    }

    /// `⋃_i s_i(T)`: every chart's surface points stacked, chart 0 first (`n|T|×3`).
    pub fn all_surface_points(&mut self) -> Var {
        cached!(self.all_surface_points, {
            let parts: Vec<Var> = (0..self.charts()).map(|i| self.surface_points(i)).collect();
            if parts.len() == 1 { parts[0] } else { self.tape.concat_rows(&parts) }
        })
    }

    /// `t_i(s_i(u))`, the 2→3→2 round trip (`|T|×2`).
    pub fn cycle_uv(&mut self, i: usize) -> Var {
        cached!(self.cycle_uv[i], {
            let s = self.surface_points(i);
            self.nets.texture(self.tape, i, s)
        })
    }

    /// `log c(s_i(u))` for every chart's surface points, stacked like [`Self::all_surface_points`]
    /// (`n|T|×n`). One chart-network evaluation covers all charts.
    pub fn chart_log_probs_at_surface_points(&mut self) -> Var {
        cached!(self.chart_log_probs_at_surface, {
            let s = self.all_surface_points();
            let l = self.nets.chart_logits(self.tape, s);
            self.tape.log_softmax(l)
        })
    }

    /// Chart `i`'s support: the samples where `c(x)[i] ≥ τ` (`StepData::chart_support`), or `None`
    /// when that is every sample (or `τ = 0`). A chart that reaches `τ` on none of the distortion
    /// samples keeps its most probable one, so no evaluation is ever empty.
    fn support(&mut self, i: usize) -> Option<&Support> {
        if self.cache.support[i].is_none() {
            let computed = self.compute_support(i);
            self.cache.support[i] = Some(computed);
        }
        self.cache.support[i].as_ref().and_then(Option::as_ref)
    }

    /// The rows of `v` that `samples` names for chart `i` (`v` covers the batch, or the `k`
    /// distortion samples for [`Samples::DistortionSupport`]), gathered; `v` itself when that is
    /// all of them. Reads the cached support in place (no copy of its rows).
    fn rows_of(&mut self, i: usize, v: Var, samples: Samples) -> Var {
        if samples == Samples::All || self.support(i).is_none() {
            return v;
        }
        let support = self.cache.support[i].as_ref().and_then(Option::as_ref).expect("computed above");
        let rows = match samples {
            Samples::DistortionSupport => &support.rows[..support.distortion],
            _ => &support.rows[..],
        };
        self.tape.gather_rows(v, rows)
    }

    fn compute_support(&mut self, i: usize) -> Option<Support> {
        let tau = self.data.chart_support;
        if tau <= 0.0 {
            return None;
        }
        let (n, k) = (self.charts(), self.batch_distortion());
        let c = self.chart_probs();
        let column: Vec<f32> = self.tape.value(c).iter().skip(i).step_by(n).copied().collect();
        let mut rows: Vec<u32> = (0..column.len() as u32).filter(|&r| column[r as usize] >= tau).collect();
        if rows.len() == column.len() {
            return None;
        }
        let mut distortion = rows.partition_point(|&r| (r as usize) < k);
        if distortion == 0 {
            let best = (0..k).fold(0, |b, r| if column[r] > column[b] { r } else { b });
            rows.insert(0, best as u32);
            distortion = 1;
        }
        Some(Support { rows, distortion })
    }

    /// The rows of `v` (a `B×k` quantity of the 3-D samples) on chart `i`'s support, in the order of
    /// [`Self::support_tex`]; `v` itself when the support is every sample.
    pub fn on_support(&mut self, i: usize, v: Var) -> Var {
        self.rows_of(i, v, Samples::Support)
    }

    /// Chart `i`'s probabilities `c(x)[i]` on the samples `samples` covers (a column).
    pub fn chart_probs_on(&mut self, i: usize, samples: Samples) -> Var {
        let c = self.chart_probs();
        let column = self.tape.slice_cols(c, i, 1);
        match samples {
            Samples::DistortionSupport if self.support(i).is_none() => {
                let k = self.batch_distortion();
                self.tape.slice_rows(column, 0, k)
            }
            _ => self.rows_of(i, column, samples),
        }
    }

    /// Whether any chart is evaluated on fewer than every sample this step.
    pub fn is_pruned(&mut self) -> bool {
        (0..self.charts()).any(|i| self.support(i).is_some())
    }

    /// `t_i(x)` on chart `i`'s support: [`Self::tex`] when that is every sample. The losses whose
    /// terms are weighted by `c(x)[i]` read this, so a term weighing less than `τ` costs nothing.
    pub fn support_tex(&mut self, i: usize) -> Var {
        if self.support(i).is_none() {
            return self.tex(i);
        }
        cached!(self.support_tex[i], {
            let x = self.x();
            let x = self.on_support(i, x);
            self.nets.texture(self.tape, i, x)
        })
    }

    /// [`Self::uv_differentials`] on the distortion samples of chart `i`'s support.
    pub fn support_uv_differentials(&mut self, i: usize) -> (Var, Var) {
        if self.support(i).is_none() {
            return self.uv_differentials(i);
        }
        cached!(self.support_differentials[i], {
            let t = self.support_tex(i);
            let (xp, xq) = self.offsets();
            let xp = self.rows_of(i, xp, Samples::DistortionSupport);
            let xq = self.rows_of(i, xq, Samples::DistortionSupport);
            let t = self.tape.slice_rows(t, 0, self.tape.shape(xp).rows);
            let (tp, tq) = (self.nets.texture(self.tape, i, xp), self.nets.texture(self.tape, i, xq));
            (self.tape.sub(tp, t), self.tape.sub(tq, t))
        })
    }

    /// [`Self::cycle_points`] on chart `i`'s support.
    pub fn support_cycle_points(&mut self, i: usize) -> Var {
        if self.support(i).is_none() {
            return self.cycle_points(i);
        }
        cached!(self.support_cycle_points[i], {
            let t = self.support_tex(i);
            self.nets.surface(self.tape, i, t)
        })
    }

    /// The learned average stretch `σ`.
    pub fn sigma(&mut self) -> Var {
        cached!(self.sigma, self.nets.sigma(self.tape))
    }

    /// The normal grid `N_i` and its resolution.
    pub fn normal_grid(&mut self, i: usize) -> (Var, usize) {
        cached!(self.grids[i], self.nets.normal_grid(self.tape, i))
    }
}

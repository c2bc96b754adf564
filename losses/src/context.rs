//! The per-step context: the batch, and every network output a loss may read, computed once.
//!
//! Losses ask for quantities (`c(x)`, `t_i(x)`, `s_i(u)`, …) through getters. The first request
//! records the evaluation on the tape and caches the [`Var`]; later requests, from the same or another
//! loss, get the cached one. So however many losses read `t_i(x)`, each network runs once per input.
//!
//! A per-chart quantity of the 3-D samples is asked for with a [`ChartRows`]: chart `i` on a set of
//! [`Samples`]. The same handle gives the probabilities `c(x)[i]` on those rows
//! ([`StepContext::chart_weights`]) and pairs each term with them in [`crate::chart_weighted_mean`],
//! which checks that every term has as many rows as its handle names (a term of the support
//! labelled as every sample fails there as soon as anything is pruned). [`Samples::Support`] serves the losses
//! whose per-chart terms are weighted by `c(x)[i]`: chart `i` is evaluated only on its *support*,
//! the samples where `c(x)[i] ≥ τ` (`training.chart_support`). Once the charts have settled, most
//! samples belong to one or two of them, so this skips most of the per-chart passes over the 3-D
//! samples while changing each loss by less than `τ` times its size. With `τ = 0` the support is
//! every sample, and a term is exactly what [`Samples::All`] gives.

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
    /// The chart-support threshold `τ` of [`Samples::Support`] (`training.chart_support`): chart
    /// `i` is evaluated on the samples where `c(x)[i] ≥ τ`. 0 evaluates every chart everywhere.
    pub chart_support: f32,
}

/// The 3-D samples of [`Samples::Support`] for one chart: those where its probability
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

/// Which of a step's 3-D samples a per-chart quantity covers.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Samples {
    /// Every sample of the batch (`B` rows).
    All,
    /// The chart's support: the samples where `c(x)[i] ≥ τ` (`StepData::chart_support`); every
    /// sample when `τ = 0` or when the chart reaches `τ` everywhere.
    Support,
    /// The distortion samples: the first `k` of the batch (see [`StepData`]).
    Distortion,
    /// The distortion samples in the chart's support.
    DistortionSupport,
}

impl Samples {
    /// Whether these are distortion samples, which the UV differentials are defined on.
    pub fn is_distortion(self) -> bool {
        matches!(self, Samples::Distortion | Samples::DistortionSupport)
    }

    /// Whether these are the chart's support (or its distortion samples).
    fn is_support(self) -> bool {
        matches!(self, Samples::Support | Samples::DistortionSupport)
    }
}

/// Chart `i` on a set of [`Samples`]: what the per-chart getters of [`StepContext`] take, and what
/// [`crate::chart_weighted_mean`] pairs each term with, so a term and the probabilities `c(x)[i]` that
/// weigh it always cover the same rows. A plain value: it records nothing until a getter uses it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ChartRows {
    /// The chart `i`.
    pub chart: usize,
    /// Which samples.
    pub samples: Samples,
}

impl ChartRows {
    /// Chart `chart` on `samples`.
    pub fn new(chart: usize, samples: Samples) -> Self {
        ChartRows { chart, samples }
    }
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

    /// `t_i(x)` on the rows `r` names (`rows×2`).
    pub fn tex(&mut self, r: ChartRows) -> Var {
        let t = if r.samples.is_support() { self.support_tex(r.chart) } else { self.tex_everywhere(r.chart) };
        self.first_distortion_rows(r, t)
    }

    /// `t_i(x)` on every sample.
    fn tex_everywhere(&mut self, i: usize) -> Var {
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

    /// `(t_i(x + εp), t_i(x + εq))` for every distortion sample.
    fn tex_at_offsets(&mut self, i: usize) -> (Var, Var) {
        cached!(self.tex_offsets[i], {
            let (xp, xq) = self.offsets();
            (self.nets.texture(self.tape, i, xp), self.nets.texture(self.tape, i, xq))
        })
    }

    /// Number of distortion samples `k`: the first `k` of the 3-D samples (see [`StepData`]).
    pub fn batch_distortion(&self) -> usize {
        self.data.tangents_p.len()
    }

    /// The paper's UV vectors `D t_i(εp) ≈ t_i(x + εp) − t_i(x)` and `D t_i(εq)` (`rows×2` each) on
    /// the distortion samples `r` names: the finite-difference images of the tangent vectors `εp`
    /// and `εq` (not divided by `ε`).
    ///
    /// # Panics
    /// When `r` names other than distortion samples (a programming error: the tangents exist only
    /// there).
    pub fn uv_differentials(&mut self, r: ChartRows) -> (Var, Var) {
        match r.samples {
            Samples::Distortion => self.uv_differentials_everywhere(r.chart),
            Samples::DistortionSupport => self.support_uv_differentials(r.chart),
            other => panic!("UV differentials exist on the distortion samples only, not {other:?}"),
        }
    }

    /// [`Self::uv_differentials`] on every distortion sample.
    fn uv_differentials_everywhere(&mut self, i: usize) -> (Var, Var) {
        cached!(self.differentials[i], {
            let k = self.batch_distortion();
            let t = self.tex_everywhere(i);
            let t = if k < self.batch_3d() { self.tape.slice_rows(t, 0, k) } else { t };
            let (tp, tq) = self.tex_at_offsets(i);
            (self.tape.sub(tp, t), self.tape.sub(tq, t))
        })
    }

    /// `s_i(t_i(x))`, the 3→2→3 round trip, on the rows `r` names (`rows×3`).
    pub fn cycle_points(&mut self, r: ChartRows) -> Var {
        let s = if r.samples.is_support() {
            self.support_cycle_points(r.chart)
        } else {
            self.cycle_points_everywhere(r.chart)
        };
        self.first_distortion_rows(r, s)
    }

    /// `s_i(t_i(x))` on every sample.
    fn cycle_points_everywhere(&mut self, i: usize) -> Var {
        cached!(self.cycle_points[i], {
            let t = self.tex_everywhere(i);
            self.nets.surface(self.tape, i, t)
        })
    }

    /// `v`, a quantity of the rows of `r`'s chart on all its samples or on its support, cut to its
    /// distortion samples when `r` names those (they come first).
    fn first_distortion_rows(&mut self, r: ChartRows, v: Var) -> Var {
        if !r.samples.is_distortion() {
            return v;
        }
        let rows = self.row_count(r);
        if self.tape.shape(v).rows == rows { v } else { self.tape.slice_rows(v, 0, rows) }
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

    /// How many rows the quantities of `r` have.
    pub fn row_count(&mut self, r: ChartRows) -> usize {
        let (b, k) = (self.batch_3d(), self.batch_distortion());
        let support = if r.samples.is_support() { self.support(r.chart) } else { None };
        match (r.samples, support) {
            (Samples::Support, Some(s)) => s.rows.len(),
            (Samples::DistortionSupport, Some(s)) => s.distortion,
            (Samples::Distortion | Samples::DistortionSupport, _) => k,
            (Samples::All | Samples::Support, _) => b,
        }
    }

    /// The rows of `v` that `r` names, gathered: `v` is a quantity of every sample (`B` rows) or,
    /// for distortion samples, of every distortion sample (`k` rows); `v` itself when `r` names all
    /// of its rows.
    pub fn select(&mut self, r: ChartRows, v: Var) -> Var {
        if !r.samples.is_support() || self.support(r.chart).is_none() {
            return self.first_distortion_rows(r, v);
        }
        let support = self.cache.support[r.chart].as_ref().and_then(Option::as_ref).expect("computed above");
        let rows = match r.samples {
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

    /// Chart `i`'s probabilities `c(x)[i]` on the rows `r` names (a column): the weights of its
    /// terms.
    pub fn chart_weights(&mut self, r: ChartRows) -> Var {
        let c = self.chart_probs();
        let column = self.tape.slice_cols(c, r.chart, 1);
        self.select(r, column)
    }

    /// Whether any chart is evaluated on fewer than every sample this step.
    pub fn is_pruned(&mut self) -> bool {
        (0..self.charts()).any(|i| self.support(i).is_some())
    }

    /// `t_i(x)` on chart `i`'s support: every sample when that is all of them. The losses whose
    /// terms are weighted by `c(x)[i]` read this, so a term weighing less than `τ` costs nothing.
    fn support_tex(&mut self, i: usize) -> Var {
        if self.support(i).is_none() {
            return self.tex_everywhere(i);
        }
        cached!(self.support_tex[i], {
            let x = self.x();
            let x = self.select(ChartRows::new(i, Samples::Support), x);
            self.nets.texture(self.tape, i, x)
        })
    }

    /// The UV differentials on the distortion samples of chart `i`'s support.
    fn support_uv_differentials(&mut self, i: usize) -> (Var, Var) {
        if self.support(i).is_none() {
            return self.uv_differentials_everywhere(i);
        }
        cached!(self.support_differentials[i], {
            let t = self.support_tex(i);
            let (xp, xq) = self.offsets();
            let rows = ChartRows::new(i, Samples::DistortionSupport);
            let xp = self.select(rows, xp);
            let xq = self.select(rows, xq);
            let t = self.tape.slice_rows(t, 0, self.tape.shape(xp).rows);
            let (tp, tq) = (self.nets.texture(self.tape, i, xp), self.nets.texture(self.tape, i, xq));
            (self.tape.sub(tp, t), self.tape.sub(tq, t))
        })
    }

    /// `s_i(t_i(x))` on chart `i`'s support.
    fn support_cycle_points(&mut self, i: usize) -> Var {
        if self.support(i).is_none() {
            return self.cycle_points_everywhere(i);
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

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
//!
//! **Evaluations stacked.** One network's evaluations of one step on inputs that do not depend on
//! each other are recorded as one evaluation of the inputs stacked (`concat_rows`) and sliced back:
//! chart `i`'s texture network on its rows (its support, or every sample) together with the
//! distortion samples' offsets `x + εp` and `x + εq`, and its surface network on `t_i` of its rows
//! together with the UV samples `u`. With the paper's losses a step then runs each texture network
//! twice (the second time on `s_i(u)`, which depends on the first) and each surface network once,
//! instead of four times and twice: fewer and larger GEMMs for the two cores to share (BENCHMARKS.md,
//! "One evaluation per network and input layer"). Each row is the same function of the same input
//! either way; only the rounding of the weight gradients' sums over rows differs. What is stacked
//! follows from the [`Reads`] the step's losses declare and the order they ask in, both fixed by the
//! config and the step, so a step's tape stays a function of them (determinism, resume). A quantity
//! asked for but not declared is evaluated on its own as it is asked for.

use nuvo_autodiff::{Shape, Tape, Var};

use crate::networks::Networks;

/// What a step's losses read of the context ([`crate::Loss::reads`]), so that the context can stack
/// one network's evaluations (module docs, "Evaluations stacked"). Declaring less than a loss reads
/// costs speed, never correctness; declaring more records evaluations nothing reads.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Reads {
    /// The UV differentials ([`StepContext::uv_differentials`]).
    pub uv_differentials: bool,
    /// The 3→2→3 round trip `s_i(t_i(x))` ([`StepContext::cycle_points`]).
    pub cycle_points: bool,
    /// The surface points `s_i(u)` ([`StepContext::surface_points`] and what is built on them:
    /// `all_surface_points`, `cycle_uv`, `chart_log_probs_at_surface_points`).
    pub surface_points: bool,
}

impl Reads {
    /// Nothing declared: every quantity is evaluated on its own, as it is asked for.
    pub const NOTHING: Reads = Reads { uv_differentials: false, cycle_points: false, surface_points: false };

    /// What either reads.
    pub fn union(self, other: Reads) -> Reads {
        Reads {
            uv_differentials: self.uv_differentials || other.uv_differentials,
            cycle_points: self.cycle_points || other.cycle_points,
            surface_points: self.surface_points || other.surface_points,
        }
    }
}

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
    reads: Reads,
    /// Whether evaluations are stacked at all (always, but in tests that compare with separate ones).
    stack: bool,
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

/// The UV differentials `(t(x + εp) − t(x), t(x + εq) − t(x))` from `t` on rows whose first ones are
/// the distortion rows of `tp` and `tq`.
fn differences(tape: &mut Tape, t: Var, tp: Var, tq: Var) -> (Var, Var) {
    let k = tape.shape(tp).rows;
    let t = if tape.shape(t).rows == k { t } else { tape.slice_rows(t, 0, k) };
    (tape.sub(tp, t), tape.sub(tq, t))
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
        StepContext { tape, nets, data, reads: Reads::NOTHING, stack: true, cache }
    }

    /// This context, told what the step's losses will read, so that it stacks evaluations (module
    /// docs).
    pub fn reading(self, reads: Reads) -> Self {
        StepContext { reads, ..self }
    }

    /// This context, evaluating every input on its own: the reference the stacked evaluations are
    /// tested against.
    #[cfg(test)]
    pub(crate) fn never_stacking(self) -> Self {
        StepContext { stack: false, ..self }
    }

    /// `f` of each of `inputs` (same column count), recorded as one evaluation of them stacked and
    /// sliced back into their own rows (module docs, "Evaluations stacked").
    fn stacked<const N: usize>(&mut self, inputs: [Var; N], f: impl Fn(&mut Tape, Var) -> Var) -> [Var; N] {
        if !self.stack {
            return inputs.map(|x| f(self.tape, x));
        }
        let all = self.tape.concat_rows(&inputs);
        let out = f(self.tape, all);
        let mut start = 0;
        inputs.map(|x| {
            let rows = self.tape.shape(x).rows;
            let part = self.tape.slice_rows(out, start, rows);
            start += rows;
            part
        })
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
        if let Some(t) = self.cache.tex[i] {
            return t;
        }
        if self.support(i).is_none() {
            self.texture_pass(i, false, self.reads.uv_differentials);
        } else {
            let x = self.x();
            self.cache.tex[i] = Some(self.nets.texture(self.tape, i, x));
        }
        self.cache.tex[i].expect("recorded above")
    }

    /// Records `t_i` on chart `i`'s rows (its support when `pruned`, else every sample) and, when
    /// `offsets`, the UV differentials on its distortion rows, as one evaluation of the texture
    /// network (module docs), into the caches of those rows.
    fn texture_pass(&mut self, i: usize, pruned: bool, offsets: bool) {
        let x = self.x();
        let x = if pruned { self.select(ChartRows::new(i, Samples::Support), x) } else { x };
        let nets = self.nets;
        if !offsets {
            let t = nets.texture(self.tape, i, x);
            *self.tex_cache(i, pruned) = Some(t);
            return;
        }
        let (xp, xq) = self.distortion_offsets(i, pruned);
        let [t, tp, tq] = self.stacked([x, xp, xq], |tape, x| nets.texture(tape, i, x));
        *self.tex_cache(i, pruned) = Some(t);
        let d = differences(self.tape, t, tp, tq);
        *self.differentials_cache(i, pruned) = Some(d);
    }

    /// The UV differentials of chart `i`'s distortion rows from `t`, its `t_i` on its rows already
    /// recorded: the two offsets stacked in one evaluation.
    fn differentials_from(&mut self, i: usize, pruned: bool, t: Var) -> (Var, Var) {
        let (xp, xq) = self.distortion_offsets(i, pruned);
        let nets = self.nets;
        let [tp, tq] = self.stacked([xp, xq], |tape, x| nets.texture(tape, i, x));
        differences(self.tape, t, tp, tq)
    }

    /// The offsets `(x + εp, x + εq)` of chart `i`'s distortion rows: those of its support when
    /// `pruned`, else every distortion sample's.
    fn distortion_offsets(&mut self, i: usize, pruned: bool) -> (Var, Var) {
        let (xp, xq) = self.offsets();
        if !pruned {
            return (xp, xq);
        }
        let rows = ChartRows::new(i, Samples::DistortionSupport);
        (self.select(rows, xp), self.select(rows, xq))
    }

    fn tex_cache(&mut self, i: usize, pruned: bool) -> &mut Option<Var> {
        if pruned { &mut self.cache.support_tex[i] } else { &mut self.cache.tex[i] }
    }

    fn differentials_cache(&mut self, i: usize, pruned: bool) -> &mut Option<(Var, Var)> {
        if pruned { &mut self.cache.support_differentials[i] } else { &mut self.cache.differentials[i] }
    }

    fn cycle_points_cache(&mut self, i: usize, pruned: bool) -> &mut Option<Var> {
        if pruned { &mut self.cache.support_cycle_points[i] } else { &mut self.cache.cycle_points[i] }
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
        if let Some(d) = self.cache.differentials[i] {
            return d;
        }
        if self.cache.tex[i].is_none() && self.support(i).is_none() {
            self.texture_pass(i, false, true);
        } else {
            let t = self.tex_everywhere(i);
            self.cache.differentials[i] = Some(self.differentials_from(i, false, t));
        }
        self.cache.differentials[i].expect("recorded above")
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
        if let Some(s) = self.cache.cycle_points[i] {
            return s;
        }
        if self.support(i).is_none() {
            let with_uv = self.reads.surface_points && self.cache.surface_points[i].is_none();
            self.surface_pass(i, false, with_uv);
        } else {
            let t = self.tex_everywhere(i);
            self.cache.cycle_points[i] = Some(self.nets.surface(self.tape, i, t));
        }
        self.cache.cycle_points[i].expect("recorded above")
    }

    /// Records `s_i(t_i(x))` on chart `i`'s rows (its support when `pruned`, else every sample)
    /// and, when `with_uv`, `s_i(u)`, as one evaluation of the surface network (module docs).
    fn surface_pass(&mut self, i: usize, pruned: bool, with_uv: bool) {
        let t = if pruned { self.support_tex(i) } else { self.tex_everywhere(i) };
        let nets = self.nets;
        if !with_uv {
            let s = nets.surface(self.tape, i, t);
            *self.cycle_points_cache(i, pruned) = Some(s);
            return;
        }
        let u = self.uv();
        let [back, s] = self.stacked([t, u], |tape, x| nets.surface(tape, i, x));
        *self.cycle_points_cache(i, pruned) = Some(back);
        self.cache.surface_points[i] = Some(s);
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
        if let Some(s) = self.cache.surface_points[i] {
            return s;
        }
        let pruned = self.support(i).is_some();
        if self.reads.cycle_points && self.cycle_points_cache(i, pruned).is_none() {
            self.surface_pass(i, pruned, true);
        } else {
            let u = self.uv();
            self.cache.surface_points[i] = Some(self.nets.surface(self.tape, i, u));
        }
        self.cache.surface_points[i].expect("recorded above")
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
        if self.cache.support_tex[i].is_none() {
            self.texture_pass(i, true, self.reads.uv_differentials);
        }
        self.cache.support_tex[i].expect("recorded above")
    }

    /// The UV differentials on the distortion samples of chart `i`'s support.
    fn support_uv_differentials(&mut self, i: usize) -> (Var, Var) {
        if self.support(i).is_none() {
            return self.uv_differentials_everywhere(i);
        }
        if let Some(d) = self.cache.support_differentials[i] {
            return d;
        }
        match self.cache.support_tex[i] {
            None => self.texture_pass(i, true, true),
            Some(t) => self.cache.support_differentials[i] = Some(self.differentials_from(i, true, t)),
        }
        self.cache.support_differentials[i].expect("recorded above")
    }

    /// `s_i(t_i(x))` on chart `i`'s support.
    fn support_cycle_points(&mut self, i: usize) -> Var {
        if self.support(i).is_none() {
            return self.cycle_points_everywhere(i);
        }
        if self.cache.support_cycle_points[i].is_none() {
            let with_uv = self.reads.surface_points && self.cache.surface_points[i].is_none();
            self.surface_pass(i, true, with_uv);
        }
        self.cache.support_cycle_points[i].expect("recorded above")
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

#[cfg(test)]
mod tests {
    use super::Reads;
    use crate::Loss;
    use crate::builtin::PAPER;
    use crate::registry::LossRegistry;
    use crate::testing::{Evaluations, Scene};

    /// The paper's eight losses with their default options, plus the signed stretch (which tells
    /// `εp` from `εq`), and what they declare they read.
    fn paper_losses() -> (Vec<Box<dyn Loss>>, Reads) {
        let registry = LossRegistry::with_builtins();
        let mut losses: Vec<Box<dyn Loss>> = PAPER
            .iter()
            .map(|name| registry.build(name, &toml::Table::new()).expect("a built-in loss"))
            .collect();
        let signed: toml::Table = toml::from_str("signed = true").expect("a table");
        losses.push(registry.build("stretch", &signed).expect("the signed stretch"));
        let reads = losses.iter().fold(Reads::NOTHING, |r, l| r.union(l.reads()));
        (losses, reads)
    }

    /// The generic scene with every chart everywhere, and with both charts' supports pruned
    /// (chart 0 keeps samples 0 and 2, chart 1 samples 1, 2 and 3) and three distortion samples.
    fn scenes() -> [(&'static str, Scene); 2] {
        let pruned = Scene::generic()
            .with_chart_logits_along_x(8.0, -3.0)
            .with_chart_support(0.2)
            .with_distortion_samples(3);
        [("every chart everywhere", Scene::generic()), ("pruned supports", pruned)]
    }

    #[test]
    fn the_paper_losses_declare_what_they_read() {
        let (_, reads) = paper_losses();
        assert_eq!(reads, Reads { uv_differentials: true, cycle_points: true, surface_points: true });
    }

    #[test]
    fn stacked_evaluations_give_the_values_and_gradients_of_separate_ones_in_fewer_evaluations() {
        let (losses, reads) = paper_losses();
        for (name, scene) in scenes() {
            let (apart, apart_grads, apart_counts) = scene.total_and_gradients(&losses, None);
            let (stacked, stacked_grads, stacked_counts) = scene.total_and_gradients(&losses, Some(reads));
            let close = |a: f32, b: f32| (a - b).abs() <= 1e-5 * a.abs().max(b.abs()).max(1.0);
            assert!(close(apart, stacked), "{name}: total {apart} apart, {stacked} stacked");
            for (k, (a, b)) in apart_grads.iter().zip(&stacked_grads).enumerate() {
                assert!(a.iter().any(|&g| g != 0.0), "{name}: parameter {k} has no gradient to compare");
                for (&ga, &gb) in a.iter().zip(b) {
                    assert!(close(ga, gb), "{name}: parameter {k}'s gradient {ga} apart, {gb} stacked");
                }
            }
            // Apart: per chart t_i on its rows, at x + εp, at x + εq and on s_i(u); s_i on t_i and on u.
            assert_eq!(apart_counts, Evaluations { chart: 2, texture: 2 * 4, surface: 2 * 2 }, "{name}");
            // Stacked: t_i on its rows and offsets, then on s_i(u); s_i on t_i and u together.
            assert_eq!(stacked_counts, Evaluations { chart: 2, texture: 2 * 2, surface: 2 }, "{name}");
        }
    }

    #[test]
    fn a_quantity_asked_for_but_not_declared_is_evaluated_on_its_own() {
        // Nothing declared: a quantity's own inputs are still stacked (the differentials ask for
        // t_i on the chart's rows and both offsets at once), but s_i(t_i(x)) and s_i(u) are apart.
        let (losses, _) = paper_losses();
        for (name, scene) in scenes() {
            let (apart, _, _) = scene.total_and_gradients(&losses, None);
            let (undeclared, _, counts) = scene.total_and_gradients(&losses, Some(Reads::NOTHING));
            assert!(
                (apart - undeclared).abs() <= 1e-5 * apart.abs().max(1.0),
                "{name}: {apart} against {undeclared}"
            );
            assert_eq!(counts, Evaluations { chart: 2, texture: 2 * 2, surface: 2 * 2 }, "{name}");
        }
    }
}

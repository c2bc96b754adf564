//! The projection warm start: an optional prior that starts every chart as a fold-free projection
//! of the part of the surface that faces it, then fades out.
//!
//! **Why.** From a random initialisation the cycle losses often settle on folded maps they never
//! unfold (BENCHMARKS.md, "Initialisation"), and in a short budget the charts end up as overlapping
//! projections. A projection of the surface along a direction `a` is fold-free wherever the normal
//! faces `a`, and a cube map of the bunny (6 such charts, no training) already scores Stretch 0.90
//! and Conformal 0.93. So for the first `warm_start.steps` steps the objective gets one extra term:
//!
//! `L_warm = −(1/|G|) Σ_x log c(x)[ℓ(x)] + (1/|G|) Σ_x Σ_i m_i(x) ‖t_i(x) − P_i(x)‖²`
//!
//! where `a_i` are the chart axes (spherical k-means, started from the principal axes of the point
//! cloud), `P_i` is chart `i`'s map and `m_i` marks where it is trusted. Two maps
//! (`warm_start.projection`, see [`Projection`]):
//! - `"orthographic"`: `ℓ(x) = argmax_i n(x)·a_i` (axes from the normals), `P_i` projects onto the
//!   plane orthogonal to `a_i`, `m_i(x) = [n(x)·a_i > τ]`;
//! - `"azimuthal"`: with `d(x)` the unit direction from the samples' centroid, `ℓ(x) = argmax_i
//!   d(x)·a_i` (axes from these directions), `P_i` is Lambert's equal-area map of `d` about `a_i`,
//!   `m_i(x) = [n(x)·d(x) > τ]` (seen from the centroid) within a little past the hemisphere;
//!
//! `τ = warm_start.min_alignment`. With `warm_start.occlusion` (orthographic only), `m_i(x)` also
//! requires that chart `i` *sees* `x`: a depth map of the fitting samples along `a_i` (the front-most
//! depth per cell of the projection plane) has nothing in front of `x` beyond what `x`'s own surface
//! reaches within the cell, and `ℓ(x)` is the best-facing chart among those that see `x` (the
//! best-facing of all when none does). Each map is scaled uniformly (conformal) so the part it
//! supervises fills the middle 90% of the square. The prior's weight falls linearly from `warm_start.weight` to 0, while every configured loss runs as
//! usual (the cycle losses teach `s_i` to invert the projection). Not in the paper: it is off
//! unless a config has a `[warm_start]` table with `steps > 0`.
//!
//! **Determinism.** The axes and frames are a pure function of the source's samples for the run's
//! seed, recomputed identically on resume, so no state needs checkpointing.

use nalgebra::{Matrix3, SymmetricEigen, Vector3};
use nuvo_autodiff::{Tensor, Var};
use nuvo_geometry::GeometrySource;
use nuvo_losses::{ChartRows, Loss, LossError, Samples, StepContext};
use serde::{Deserialize, Serialize};

use crate::batch::{ShortBatch, surface_samples};
use crate::config::{ConfigError, ConfigSource, ExperimentConfig};
use crate::seeds::{Stream, derive};

/// `[warm_start]`: the projection prior (see the module docs). Absent or `steps = 0`: off.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct WarmStartConfig {
    /// Steps over which the prior's weight falls linearly to 0 (0: no warm start).
    pub steps: u64,
    /// The prior's weight at step 0.
    pub weight: f32,
    /// How charts are laid flat: `"orthographic"` or `"azimuthal"` (see [`Projection`]).
    pub projection: Projection,
    /// `t_i` is pulled towards its map only where the normal faces the axis (orthographic: `n·a_i`)
    /// or the centroid's eye (azimuthal: `n·d`) by more than this cosine (in `(-1, 1)`): below it
    /// the map foreshortens too much, and past 0 it folds.
    pub min_alignment: f32,
    /// Surface samples drawn once to fit the axes and the projections' extents.
    pub samples: usize,
    /// Orthographic only: a chart's projection supervises only the points it sees, not those hidden
    /// behind another part of the surface along its axis (a depth map of the fitting samples), and a
    /// point starts in the chart it faces most among those that see it. Without it, two parts facing
    /// the same way, one behind the other (the bunny's ears seen edge-on), get the same target UVs
    /// and start overlapping.
    pub occlusion: bool,
    /// Share of `training.batch_3d`, `batch_uv` and `batch_distortion` that a step draws while the
    /// prior weighs in (in `(0, 1]`; rounded, at least one sample of each). Every chart reads
    /// every sample until the prior fades, so these steps cost about twice the later ones;
    /// `nuvo unwrap` sets 0.5.
    pub batch_share: f32,
}

impl Default for WarmStartConfig {
    fn default() -> Self {
        WarmStartConfig {
            steps: 0,
            weight: 10.0,
            projection: Projection::Orthographic,
            min_alignment: 0.3,
            samples: 20_000,
            occlusion: false,
            batch_share: 1.0,
        }
    }
}

impl WarmStartConfig {
    /// Whether the warm start runs at all.
    pub fn enabled(&self) -> bool {
        self.steps > 0
    }

    /// Range checks of `[warm_start]` for a model of `charts` charts.
    pub(crate) fn validate(&self, charts: usize, src: &ConfigSource) -> Result<(), ConfigError> {
        if !(self.weight.is_finite() && self.weight >= 0.0) {
            return Err(src.invalid("warm_start.weight", "must be a non-negative number"));
        }
        if !(-1.0 < self.min_alignment && self.min_alignment < 1.0) {
            return Err(src.invalid("warm_start.min_alignment", "must be in (-1, 1): a cosine"));
        }
        if !(self.batch_share > 0.0 && self.batch_share <= 1.0) {
            return Err(src.invalid("warm_start.batch_share", "must be in (0, 1]: a share of the batch"));
        }
        if self.enabled() && self.samples < charts {
            return Err(src.invalid("warm_start.samples", "needs at least one sample per chart"));
        }
        if self.occlusion && self.projection != Projection::Orthographic {
            return Err(src.invalid(
                "warm_start.occlusion",
                "tests what an orthographic projection sees; set projection = \"orthographic\" or remove it",
            ));
        }
        Ok(())
    }
}

/// How a chart's points are laid flat.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Projection {
    /// Along the chart's axis onto the plane orthogonal to it; charts and axes come from the
    /// normals. Fold-free where the normal faces the axis, but it squashes the surface towards each
    /// chart's silhouette (area factor `n·a`).
    #[default]
    Orthographic,
    /// Lambert's azimuthal equal-area map of the direction `d` from the sample's centroid, about the
    /// chart's axis; charts and axes come from these directions. Fold-free where the surface is
    /// seen from the centroid (`n·d > 0`), and area-preserving on a sphere around it: no squashed
    /// rim on blob-like objects, and straight seams through the centroid.
    Azimuthal,
}

impl Projection {
    /// The config spelling.
    pub fn name(self) -> &'static str {
        match self {
            Projection::Orthographic => "orthographic",
            Projection::Azimuthal => "azimuthal",
        }
    }
}

/// One chart's map: UV = `origin + scale · planar(x)`, with `e1 × e2 = axis`.
#[derive(Clone, Debug, PartialEq)]
struct ChartFrame {
    axis: [f32; 3],
    e1: [f32; 3],
    e2: [f32; 3],
    origin: [f32; 2],
    scale: f32,
}

impl ChartFrame {
    /// A frame for `axis` with unit scale and no offset.
    fn new(axis: [f32; 3]) -> Self {
        let a = Vector3::from(axis);
        // The coordinate axis least aligned with `a` gives a well-conditioned first tangent.
        let k = (0..3).min_by(|&i, &j| a[i].abs().total_cmp(&a[j].abs())).unwrap_or(0);
        let e1 = a.cross(&Vector3::ith(k, 1.0)).normalize();
        let e2 = a.cross(&e1);
        ChartFrame { axis, e1: e1.into(), e2: e2.into(), origin: [0.0; 2], scale: 1.0 }
    }

    fn to_uv(&self, planar: [f32; 2]) -> [f32; 2] {
        [self.origin[0] + self.scale * planar[0], self.origin[1] + self.scale * planar[1]]
    }

    /// Scales and offsets the map so the planar points it supervises fill the middle 90% of the
    /// square (keeping the aspect ratio). Leaves the frame alone when there are none.
    fn fit_extent(&mut self, planar: impl Iterator<Item = [f32; 2]>) {
        let (lo, hi, extent) = planar_bounds(planar);
        if !(extent.is_finite() && extent > 0.0) {
            return;
        }
        self.scale = 0.9 / extent;
        for k in 0..2 {
            self.origin[k] = 0.5 - self.scale * 0.5 * (lo[k] + hi[k]);
        }
    }
}

/// The bounding box `(lo, hi)` of planar points and its longer side (`−∞` when there are none).
fn planar_bounds(planar: impl Iterator<Item = [f32; 2]>) -> ([f32; 2], [f32; 2], f32) {
    let (mut lo, mut hi) = ([f32::INFINITY; 2], [f32::NEG_INFINITY; 2]);
    for q in planar {
        for k in 0..2 {
            lo[k] = lo[k].min(q[k]);
            hi[k] = hi[k].max(q[k]);
        }
    }
    (lo, hi, (hi[0] - lo[0]).max(hi[1] - lo[1]))
}

fn dot(a: &[f32; 3], b: &[f32; 3]) -> f32 {
    glam::Vec3::from(*a).dot(glam::Vec3::from(*b))
}

/// The fitted prior: one map per chart.
#[derive(Clone, Debug, PartialEq)]
pub struct ProjectionPrior {
    projection: Projection,
    /// The sample's centroid (the azimuthal maps' eye).
    center: [f32; 3],
    frames: Vec<ChartFrame>,
    min_alignment: f32,
    /// One per chart when occlusion is tested (orthographic maps with `occlusion`), else empty.
    depth_maps: Vec<DepthMap>,
}

/// What [`ProjectionPrior::coverage`] measured.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Coverage {
    /// Share of the samples their starting chart supervises.
    pub supervised: f64,
    /// Mean `|n · a|` of the samples with their starting chart's axis.
    pub mean_facing: f64,
}

/// Rounds of spherical k-means that adapt the starting axes to the normals.
const KMEANS_ROUNDS: usize = 10;

/// Azimuthal charts stop this far past their hemisphere (`d·a > −AZIMUTHAL_REACH`), where the
/// equal-area map starts to blow up towards the antipode.
const AZIMUTHAL_REACH: f32 = 0.2;

/// The prior as a term of the objective: the trainer adds it with a weight fading out over
/// `warm_start.steps` (`crate::trainer::WeightSchedule::FadeOut`).
impl Loss for ProjectionPrior {
    fn evaluate(&self, ctx: &mut StepContext<'_>) -> Result<Var, LossError> {
        Ok(self.record(ctx))
    }
}

impl ProjectionPrior {
    /// The prior `config`'s `[warm_start]` asks for (`None` when it is off), fitted to a sample of
    /// `source` drawn from the run's seed, so a resumed run fits the same one.
    pub fn for_run(
        config: &ExperimentConfig,
        source: &dyn GeometrySource,
    ) -> Result<Option<Self>, ShortBatch> {
        let Some(cfg) = config.warm_start.as_ref().filter(|w| w.enabled()) else {
            return Ok(None);
        };
        let sample = surface_samples(source, cfg.samples, derive(config.seed, 0, Stream::WarmStart))?;
        Ok(Some(ProjectionPrior::fit(
            &sample.points,
            &sample.normals,
            config.model.charts,
            cfg.projection,
            cfg.min_alignment,
            cfg.occlusion,
        )))
    }

    /// Fits `charts` maps to surface samples (model frame) and their unit normals; with
    /// `occlusion` (orthographic maps only), also each chart's depth map of the samples.
    /// Deterministic; `points` and `normals` must have equal lengths.
    pub fn fit(
        points: &[[f32; 3]],
        normals: &[[f32; 3]],
        charts: usize,
        projection: Projection,
        min_alignment: f32,
        occlusion: bool,
    ) -> Self {
        debug_assert_eq!(points.len(), normals.len());
        let count = points.len().max(1) as f32;
        let center = points
            .iter()
            .fold([0.0f32; 3], |c, p| [c[0] + p[0] / count, c[1] + p[1] / count, c[2] + p[2] / count]);
        let mut prior =
            ProjectionPrior { projection, center, frames: Vec::new(), min_alignment, depth_maps: Vec::new() };
        let keys: Vec<[f32; 3]> = points.iter().zip(normals).map(|(x, n)| prior.key(x, n)).collect();
        let mut axes = starting_axes(points, &keys, charts);
        for _ in 0..KMEANS_ROUNDS {
            let mut sums = vec![Vector3::<f32>::zeros(); charts];
            for k in &keys {
                sums[best_axis(axes.iter().copied(), k)] += Vector3::from(*k);
            }
            for (axis, sum) in axes.iter_mut().zip(&sums) {
                if sum.norm() > 0.0 {
                    *axis = sum.normalize().into();
                }
            }
        }
        prior.frames = axes.iter().map(|&axis| ChartFrame::new(axis)).collect();
        if occlusion && projection == Projection::Orthographic {
            prior.depth_maps = (0..charts)
                .map(|i| {
                    DepthMap::new(points.iter().map(|x| (prior.planar(i, x), dot(x, &prior.frames[i].axis))))
                })
                .collect();
        }
        for i in 0..charts {
            let supervised = points.iter().zip(normals).filter(|(x, n)| prior.supervises(i, x, n));
            let planar: Vec<[f32; 2]> = supervised.map(|(x, _)| prior.planar(i, x)).collect();
            prior.frames[i].fit_extent(planar.into_iter());
        }
        prior
    }

    /// The unit vector charts are assigned by: the normal (orthographic) or the direction from the
    /// centroid (azimuthal).
    fn key(&self, x: &[f32; 3], n: &[f32; 3]) -> [f32; 3] {
        match self.projection {
            Projection::Orthographic => *n,
            Projection::Azimuthal => self.direction(x),
        }
    }

    fn direction(&self, x: &[f32; 3]) -> [f32; 3] {
        let d = Vector3::from(*x) - Vector3::from(self.center);
        if d.norm() > 0.0 {
            d.normalize().into()
        } else {
            self.frames.first().map_or([0.0, 0.0, 1.0], |f| f.axis)
        }
    }

    /// Chart `i`'s map of `x` before scaling into the square.
    fn planar(&self, i: usize, x: &[f32; 3]) -> [f32; 2] {
        let f = &self.frames[i];
        match self.projection {
            Projection::Orthographic => [dot(x, &f.e1), dot(x, &f.e2)],
            Projection::Azimuthal => {
                // Lambert: radius 2·sin(θ/2) along the azimuth, i.e. the in-plane part of `d`
                // times √(2 / (1 + cos θ)).
                let d = self.direction(x);
                let k = (2.0 / (1.0 + dot(&d, &f.axis)).max(1e-3)).sqrt();
                [k * dot(&d, &f.e1), k * dot(&d, &f.e2)]
            }
        }
    }

    /// Whether chart `i`'s map is trusted (fold-free and not too distorted) at `x` with normal `n`.
    fn supervises(&self, i: usize, x: &[f32; 3], n: &[f32; 3]) -> bool {
        let axis = &self.frames[i].axis;
        match self.projection {
            Projection::Orthographic => dot(n, axis) > self.min_alignment && self.sees(i, x, n),
            Projection::Azimuthal => {
                let d = self.direction(x);
                dot(&d, axis) > -AZIMUTHAL_REACH && dot(n, &d) > self.min_alignment
            }
        }
    }

    /// How well these charts can start a sample (model frame, unit normals) fold-free: the share of
    /// the samples that the chart they start in ([`ProjectionPrior::label`]) supervises (it faces
    /// them by more than `min_alignment` and, with depth maps, sees them), and the mean of
    /// `|n · a|` with that chart's axis over all samples (1: every point seen head-on; an
    /// orthographic map shrinks areas by this factor). `nuvo unwrap` picks the chart count with it.
    pub fn coverage(&self, points: &[[f32; 3]], normals: &[[f32; 3]]) -> Coverage {
        let (mut covered, mut facing) = (0usize, 0.0f64);
        for (x, n) in points.iter().zip(normals) {
            let i = self.label(x, n);
            covered += usize::from(self.supervises(i, x, n));
            facing += f64::from(dot(n, &self.frames[i].axis).abs());
        }
        let count = points.len().max(1) as f64;
        Coverage { supervised: covered as f64 / count, mean_facing: facing / count }
    }

    /// The charts' axes (unit vectors).
    pub fn axes(&self) -> Vec<[f32; 3]> {
        self.frames.iter().map(|f| f.axis).collect()
    }

    /// The chart point `x` with normal `n` starts in: the one whose axis its normal (orthographic)
    /// or its direction from the centroid (azimuthal) faces most; with depth maps, the one it faces
    /// most among the charts that see it (all of them when none does).
    pub fn label(&self, x: &[f32; 3], n: &[f32; 3]) -> usize {
        let key = self.key(x, n);
        if self.depth_maps.is_empty() {
            return best_axis(self.frames.iter().map(|f| f.axis), &key);
        }
        let seen =
            (0..self.frames.len()).filter(|&i| dot(&key, &self.frames[i].axis) > 0.0 && self.sees(i, x, n));
        let best_seen = seen.max_by(|&i, &j| {
            let (a, b) = (dot(&key, &self.frames[i].axis), dot(&key, &self.frames[j].axis));
            a.total_cmp(&b).then(i.cmp(&j))
        });
        best_seen.unwrap_or_else(|| best_axis(self.frames.iter().map(|f| f.axis), &key))
    }

    /// Whether chart `i`'s projection sees `x` (normal `n`): not hidden behind other samples along
    /// its axis. Always true without depth maps.
    fn sees(&self, i: usize, x: &[f32; 3], n: &[f32; 3]) -> bool {
        let Some(map) = self.depth_maps.get(i) else { return true };
        let axis = &self.frames[i].axis;
        let facing = dot(n, axis);
        let slope =
            if facing > 0.0 { (1.0 - facing * facing).max(0.0).sqrt() / facing } else { f32::INFINITY };
        map.sees(self.planar(i, x), dot(x, axis), slope)
    }

    /// Chart `i`'s target UV for point `x`.
    pub fn target_uv(&self, i: usize, x: &[f32; 3]) -> [f32; 2] {
        self.frames[i].to_uv(self.planar(i, x))
    }

    /// Records `L_warm` (module docs) for the step's batch on the context's tape, reusing its
    /// shared chart logits and texture coordinates.
    fn record(&self, ctx: &mut StepContext<'_>) -> Var {
        let n = self.frames.len();
        let (points, normals) = (ctx.data().points, ctx.data().normals);
        let b = points.len();
        let mut one_hot = Tensor::zeros(b, n);
        let mut targets: Vec<Tensor> = (0..n).map(|_| Tensor::zeros(b, 2)).collect();
        let mut masks: Vec<Tensor> = (0..n).map(|_| Tensor::zeros(b, 1)).collect();
        for (r, (x, nx)) in points.iter().zip(normals).enumerate() {
            one_hot.data_mut()[r * n + self.label(x, nx)] = 1.0;
            for i in 0..n {
                if self.supervises(i, x, nx) {
                    masks[i].data_mut()[r] = 1.0;
                    targets[i].data_mut()[2 * r..2 * r + 2].copy_from_slice(&self.target_uv(i, x));
                }
            }
        }
        let logits = ctx.chart_logits();
        let mut per_chart = Vec::with_capacity(n);
        for i in 0..n {
            let t = ctx.tex(ChartRows::new(i, Samples::All));
            let tape = &mut *ctx.tape;
            let target = tape.input(&targets[i]);
            let d = tape.sub(t, target);
            let sq = tape.square(d);
            let dist = tape.sum_each_row(sq);
            let mask = tape.input(&masks[i]);
            per_chart.push(tape.mul(dist, mask));
        }
        let tape = &mut *ctx.tape;
        let log_p = tape.log_softmax(logits);
        let one_hot = tape.input(&one_hot);
        let picked = tape.mul(log_p, one_hot);
        let ce = tape.sum_all(picked);
        let ce = tape.scale(ce, -1.0);
        let fit = if n == 1 { per_chart[0] } else { tape.concat_cols(&per_chart) };
        let fit = tape.sum_all(fit);
        let total = tape.add(ce, fit);
        tape.scale(total, 1.0 / b.max(1) as f32)
    }
}

/// Cells per side of a chart's depth map, over the planar extent of the fitting samples: with the
/// default 20,000 samples, a few front-most samples per cell on the bunny.
const DEPTH_CELLS: usize = 64;

/// The steepest surface (depth change per planar distance) whose own depth spread inside a cell is
/// tolerated in full; steeper points get this much tolerance.
const MAX_SLOPE: f32 = 4.0;

/// The front of the samples seen along a chart's axis: per cell of its projection plane, the
/// largest depth `x·a` of a sample projecting there (a z-buffer of points).
#[derive(Clone, Debug, PartialEq)]
struct DepthMap {
    lo: [f32; 2],
    cell: f32,
    /// Row-major `DEPTH_CELLS²`; `−∞` where no sample fell.
    front: Vec<f32>,
}

impl DepthMap {
    /// The map of samples given as (planar position, depth).
    fn new(samples: impl Iterator<Item = ([f32; 2], f32)> + Clone) -> Self {
        let (lo, _, extent) = planar_bounds(samples.clone().map(|(q, _)| q));
        let cell = if extent.is_finite() && extent > 0.0 { extent / DEPTH_CELLS as f32 } else { 1.0 };
        let mut map = DepthMap { lo, cell, front: vec![f32::NEG_INFINITY; DEPTH_CELLS * DEPTH_CELLS] };
        for (q, depth) in samples {
            if let Some(c) = map.cell_index(q) {
                map.front[c] = map.front[c].max(depth);
            }
        }
        map
    }

    fn cell_index(&self, q: [f32; 2]) -> Option<usize> {
        let at = |k: usize| {
            let c = ((q[k] - self.lo[k]) / self.cell).floor();
            (c >= 0.0 && c <= DEPTH_CELLS as f32).then(|| (c as usize).min(DEPTH_CELLS - 1))
        };
        Some(at(0)? * DEPTH_CELLS + at(1)?)
    }

    /// Whether a point at planar `q` and depth `depth`, on a surface whose depth changes by `slope`
    /// per unit of planar distance, is at the front of its cell: no sample there lies further in
    /// front than its own surface can reach within the cell (plus half a cell).
    fn sees(&self, q: [f32; 2], depth: f32, slope: f32) -> bool {
        let Some(c) = self.cell_index(q) else { return true };
        let reach = (slope.min(MAX_SLOPE) * std::f32::consts::SQRT_2 + 0.5) * self.cell;
        self.front[c] <= depth + reach
    }
}

/// The index of the axis `n` is most aligned with (the last of equals; 0 when there are none).
fn best_axis(axes: impl IntoIterator<Item = [f32; 3]>, n: &[f32; 3]) -> usize {
    let alignments = axes.into_iter().map(|a| dot(n, &a)).enumerate();
    alignments.max_by(|(_, a), (_, b)| a.total_cmp(b)).map_or(0, |(i, _)| i)
}

/// The first axes: `±` the principal directions of the points, thinnest first (so two charts
/// split the object into its two broad sides), then the keys farthest from every axis so far.
fn starting_axes(points: &[[f32; 3]], keys: &[[f32; 3]], charts: usize) -> Vec<[f32; 3]> {
    let mut axes: Vec<[f32; 3]> = Vec::with_capacity(charts);
    for dir in principal_directions(points) {
        for sign in [1.0, -1.0] {
            if axes.len() < charts {
                axes.push((dir * sign).into());
            }
        }
    }
    while axes.len() < charts {
        let far = keys.iter().min_by(|a, b| {
            let closeness = |n: &[f32; 3]| axes.iter().map(|ax| dot(n, ax)).fold(f32::NEG_INFINITY, f32::max);
            closeness(a).total_cmp(&closeness(b))
        });
        match far {
            Some(n) => axes.push(*n),
            None => axes.push([0.0, 0.0, 1.0]),
        }
    }
    axes
}

/// Eigenvectors of the points' covariance, smallest variance first (the coordinate axes when
/// there are no points).
fn principal_directions(points: &[[f32; 3]]) -> [Vector3<f32>; 3] {
    let count = points.len().max(1) as f64;
    let mean =
        points.iter().fold(Vector3::<f64>::zeros(), |m, p| m + Vector3::from(*p).cast::<f64>()) / count;
    let cov = points.iter().fold(Matrix3::<f64>::zeros(), |c, p| {
        let d = Vector3::from(*p).cast::<f64>() - mean;
        c + d * d.transpose()
    }) / count;
    let eig = SymmetricEigen::new(cov);
    let mut order = [0usize, 1, 2];
    order.sort_by(|&i, &j| eig.eigenvalues[i].total_cmp(&eig.eigenvalues[j]));
    order.map(|k| {
        let v = eig.eigenvectors.column(k).into_owned().cast::<f32>();
        if v.norm() > 0.0 { v.normalize() } else { Vector3::ith(k, 1.0) }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The six faces of the box with half-sides (0.5, 0.4, 0.3), sampled on a grid, with outward
    /// normals. Distinct sides make its principal axes the coordinate axes.
    fn cube_samples() -> (Vec<[f32; 3]>, Vec<[f32; 3]>) {
        let half = [0.5f32, 0.4, 0.3];
        let (mut p, mut n) = (Vec::new(), Vec::new());
        let g = 8;
        let at = |i: usize, h: f32| ((i as f32 + 0.5) / g as f32 * 2.0 - 1.0) * h;
        for axis in 0..3 {
            let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
            for sign in [-1.0f32, 1.0] {
                for i in 0..g {
                    for j in 0..g {
                        let mut x = [0.0; 3];
                        x[axis] = half[axis] * sign;
                        x[u] = at(i, half[u]);
                        x[v] = at(j, half[v]);
                        let mut nn = [0.0; 3];
                        nn[axis] = sign;
                        p.push(x);
                        n.push(nn);
                    }
                }
            }
        }
        (p, n)
    }

    #[test]
    fn six_charts_on_a_box_take_its_face_normals_as_axes() {
        let (p, n) = cube_samples();
        let prior = ProjectionPrior::fit(&p, &n, 6, Projection::Orthographic, 0.3, false);
        let mut found: Vec<[i32; 3]> = prior.axes().iter().map(|a| a.map(|c| c.round() as i32)).collect();
        found.sort();
        let mut want = vec![[-1, 0, 0], [1, 0, 0], [0, -1, 0], [0, 1, 0], [0, 0, -1], [0, 0, 1]];
        want.sort();
        assert_eq!(found, want);
        for a in prior.axes() {
            assert!((Vector3::from(a).norm() - 1.0).abs() < 1e-5);
        }
    }

    #[test]
    fn each_face_projects_into_the_middle_of_the_square_with_its_own_orientation() {
        let (p, n) = cube_samples();
        let prior = ProjectionPrior::fit(&p, &n, 6, Projection::Orthographic, 0.3, false);
        for (x, nx) in p.iter().zip(&n) {
            let i = prior.label(x, nx);
            let uv = prior.target_uv(i, x);
            assert!(uv.iter().all(|&c| (0.05 - 1e-5..=0.95 + 1e-5).contains(&c)), "{uv:?}");
        }
        // The projection keeps orientation: (e1, e2, axis) is right-handed on every chart.
        for f in &prior.frames {
            let c = Vector3::from(f.e1).cross(&Vector3::from(f.e2));
            assert!((c - Vector3::from(f.axis)).norm() < 1e-5);
        }
        // The top face, 1 × 0.8 in the model frame, keeps its aspect ratio: uniform scale.
        let top: Vec<[f32; 2]> = p
            .iter()
            .zip(&n)
            .filter(|(_, nx)| nx[2] > 0.5)
            .map(|(x, nx)| prior.target_uv(prior.label(x, nx), x))
            .collect();
        let span = |k: usize| {
            let v = top.iter().map(|uv| uv[k]);
            v.clone().fold(f32::NEG_INFINITY, f32::max) - v.fold(f32::INFINITY, f32::min)
        };
        let (a, b) = (span(0).max(span(1)), span(0).min(span(1)));
        assert!((b / a - 0.8).abs() < 0.02, "aspect {a} × {b}");
    }

    #[test]
    fn two_charts_split_along_the_thinnest_direction() {
        // A flat slab, thin in y, sampled in proportion to area: its narrow sides get few samples.
        let (p, n): (Vec<_>, Vec<_>) = cube_samples()
            .0
            .into_iter()
            .zip(cube_samples().1)
            .enumerate()
            .filter(|(k, (_, nx))| nx[1] != 0.0 || k % 10 == 0)
            .map(|(_, (x, nx))| ([x[0], x[1] * 0.1, x[2]], nx))
            .unzip();
        let prior = ProjectionPrior::fit(&p, &n, 2, Projection::Orthographic, 0.3, false);
        let ys: Vec<f32> = prior.axes().iter().map(|a| a[1]).collect();
        assert!(ys.iter().any(|&y| y > 0.7) && ys.iter().any(|&y| y < -0.7), "{:?}", prior.axes());
    }

    #[test]
    fn azimuthal_charts_split_a_sphere_into_hemispheres_with_equal_area_radii() {
        // A Fibonacci sphere of radius 0.5 around (0.1, 0, 0): its centroid is the eye.
        let count = 4000;
        let c = Vector3::new(0.1f32, 0.0, 0.0);
        let (p, n): (Vec<[f32; 3]>, Vec<[f32; 3]>) = (0..count)
            .map(|k| {
                let z = 1.0 - 2.0 * (k as f32 + 0.5) / count as f32;
                let r = (1.0 - z * z).sqrt();
                let a = k as f32 * 2.399_963;
                let d = Vector3::new(r * a.cos(), r * a.sin(), z);
                let (x, d): ([f32; 3], [f32; 3]) = ((c + 0.5 * d).into(), d.into());
                (x, d)
            })
            .unzip();
        let prior = ProjectionPrior::fit(&p, &n, 2, Projection::Azimuthal, 0.3, false);
        let [a0, a1] = [prior.axes()[0], prior.axes()[1]];
        assert!(dot(&a0, &a1) < -0.99, "two charts look in opposite directions: {a0:?} {a1:?}");
        for (chart, f) in prior.frames.iter().enumerate() {
            let (a, e) = (Vector3::from(f.axis), Vector3::from(f.e1));
            let uv_at =
                |angle: f32| prior.target_uv(chart, &(c + 0.5 * (angle.cos() * a + angle.sin() * e)).into());
            let from_centre = |angle: f32| {
                let (uv, o) = (uv_at(angle), uv_at(0.0));
                (uv[0] - o[0]).hypot(uv[1] - o[1])
            };
            // Lambert: radius ∝ 2·sin(θ/2), so 90° lies √2 times as far out as 60°.
            let ratio = from_centre(std::f32::consts::FRAC_PI_2) / from_centre(std::f32::consts::FRAC_PI_3);
            assert!((ratio - std::f32::consts::SQRT_2).abs() < 1e-3, "chart {chart}: ratio {ratio}");
        }
        let mut per_chart = [0usize; 2];
        for (x, nx) in p.iter().zip(&n) {
            let i = prior.label(x, nx);
            per_chart[i] += 1;
            let uv = prior.target_uv(i, x);
            assert!(uv.iter().all(|&c| (0.0..=1.0).contains(&c)), "{uv:?}");
        }
        assert!(per_chart.iter().all(|&k| k.abs_diff(count / 2) < count / 20), "{per_chart:?}");
    }

    /// Two unit squares facing +z, one at z = 0.2 in front of the other at z = −0.2 and shifted by
    /// half a side in x: samples on grids.
    fn occluding_squares() -> (Vec<[f32; 3]>, Vec<[f32; 3]>) {
        let (mut p, mut n) = (Vec::new(), Vec::new());
        let g = 40;
        let at = |i: usize| (i as f32 + 0.5) / g as f32 - 0.5;
        for i in 0..g {
            for j in 0..g {
                p.push([at(i) + 0.25, at(j), 0.2]);
                n.push([0.0, 0.0, 1.0]);
                p.push([at(i) - 0.25, at(j), -0.2]);
                n.push([0.0, 0.0, 1.0]);
            }
        }
        (p, n)
    }

    #[test]
    fn with_occlusion_a_chart_supervises_only_what_it_sees() {
        let (p, n) = occluding_squares();
        let plain = ProjectionPrior::fit(&p, &n, 1, Projection::Orthographic, 0.3, false);
        let aware = ProjectionPrior::fit(&p, &n, 1, Projection::Orthographic, 0.3, true);
        assert!(aware.axes()[0][2] > 0.99, "the chart looks along +z: {:?}", aware.axes());
        let z = 0;
        let (mut hidden, mut shown, mut front_kept) = (0, 0, true);
        for (x, nx) in p.iter().zip(&n) {
            assert!(plain.supervises(z, x, nx), "without occlusion every facing point is supervised");
            let behind = x[2] < 0.0 && x[0] > -0.25 + 0.03; // the back square under the front one
            let clear = x[2] < 0.0 && x[0] < -0.25 - 0.03; // the part of it nothing covers
            if x[2] > 0.0 {
                front_kept &= aware.supervises(z, x, nx);
            } else if behind {
                hidden += usize::from(!aware.supervises(z, x, nx));
            } else if clear {
                shown += usize::from(aware.supervises(z, x, nx));
            }
        }
        assert!(front_kept, "the front square is seen everywhere");
        // 40 × 40 grid: the covered half of the back square is 0.5 − 0.03 of its width.
        assert!(hidden >= 40 * 18, "only {hidden} covered points hidden");
        assert!(shown >= 40 * 18, "only {shown} uncovered points of the back square seen");
    }

    #[test]
    fn it_is_off_by_default() {
        assert!(!WarmStartConfig::default().enabled());
    }
}

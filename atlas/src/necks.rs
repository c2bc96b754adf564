//! Cutting UV islands at their necks where that lets the atlas pack tighter (issue 19, packing).
//!
//! Nuvo makes few, large islands. A square atlas holds such an island only as tightly as its
//! shape allows: a long chart (a one-chart alligator fills 0.16 of the square) or one with limbs
//! (a horse's chart is 0.46 of its convex hull) leaves most of the atlas empty however well the
//! islands are placed ([`crate::islands`] already packs their shapes, not their rectangles). Cut
//! across its narrowest place, such an island becomes two that pack closer, for one short seam.
//!
//! [`cut_necks`] tries cuts greedily and keeps one only when the packer itself says it helps.
//! Definitions (exact):
//! - **Island**: a chart of [`crate::uvstats::uv_charts`]; its UV vertices are
//!   [`crate::refine`]'s unknowns (corners of one mesh vertex with one UV value).
//! - **Waste** of an island: the area of its minimum-area bounding rectangle minus its UV area,
//!   times its 3-D over its UV area (islands come at different texel densities until packed).
//!   Islands of at least [`MIN_FACES`] faces are tried in order of decreasing waste (ties to
//!   the lower first face); each island (identified by its faces) is tried once.
//! - **Neck candidates** of an island: on its outer boundary loop (the loop of largest enclosed
//!   area; an island whose boundary is not a set of simple loops is not cut), [`SAMPLES`] vertices
//!   evenly spaced by arc length; every pair `(a, b)` whose shorter boundary arc is at least
//!   [`MIN_ARC`] of the loop's length is scored by `|uv_a − uv_b| / shorter arc` (small: the
//!   boundary comes close to itself across a narrow place, a neck). Pairs are taken in order of
//!   score, skipping a pair whose ends both lie within `MIN_ARC / 2` of the loop from a taken
//!   pair's, up to [`NeckOptions::candidates`].
//! - **Cut** of a candidate: the shortest path (UV length) from `a` to `b` along mesh edges
//!   whose inner vertices are not on any boundary. The island's faces, joined across every
//!   edge they share except the path's, must fall in exactly two parts, each with at least
//!   [`MIN_PART_SHARE`] of the island's UV area; otherwise the candidate is dropped. The part
//!   without the island's first face gets its own copies of its texture coordinates, moved
//!   beside the island (the packer lays it out anew anyway), so the two are two islands.
//! - **Trial**: a cut must raise the packing efficiency `e` of the current layout (packed by
//!   [`pack_islands`] with [`NeckOptions::packing`]) by a factor `1 + g`, `g` the larger of
//!   [`NeckOptions::min_gain`]` / e` and [`NeckOptions::seam_cost`]` × L / √A` (`L` the cut's
//!   3-D length, `A` the mesh's 3-D area: a seam must buy packing in proportion to its length
//!   relative to the surface's size, as the renders see a seam by its length). At one texel
//!   density the efficiency grows with the square of the common scale, so the trial is one
//!   packing attempt ([`packs_at_scale`](crate::islands::packs_at_scale)) at `√(1 + g)` times
//!   the current scale, not a search. An island's candidates are tried in order and the first
//!   that packs is kept; how much tighter it packs is then measured to [`PROBE_STEP`] by
//!   further attempts (*probes*: steps up that double until one fails, then bisection, asking
//!   the islands the kept trial prepared), and the scale proven last becomes the current one.
//!   The pass ends after [`NeckOptions::max_trials`] trials,
//!   after [`NeckOptions::max_failures`] islands in a row without a kept cut (on a
//!   marching-cubes mesh of thousands of islands no single cut moves the packing), or when
//!   every island has been tried, or once the packing attempts (trials and probes) times the
//!   mesh's faces reach [`NeckOptions::max_face_attempts`] (an attempt turns and rasterises
//!   every face; a probe cut short keeps the scale proven so far); the parts of a cut are
//!   islands that may be cut again.
//! - **Paths**: the pass runs twice from the same layout, side by side: once asking each cut
//!   for the price [`NeckOptions::seam_cost`] (`g` above) and once, *cautiously*, for
//!   [`CAUTIOUS_PRICE`] times it; it keeps the path whose end scores higher by
//!   `ln e − seam_cost × ΣL / √A` (the log of the efficiency its probes proved less the price
//!   of all its seams at the pass's price; on a tie the cautious one). Why: the pass is a
//!   greedy whose path changes wholesale with any detail (a cut kept early changes which later
//!   cuts pack), and at a low price it keeps early cuts that buy little and then block better
//!   ones; the cautious path, whose every cut paid twice the price, is a candidate under the
//!   pass's price too. Each path keeps its own budget, and each is deterministic, so the choice
//!   is. On Common Shapes' re-bakes the cautious path scored higher on 9 of 14 meshes
//!   (BENCHMARKS.md, "Two paths for the necks pass").
//! - **Judgement** ([`judge_cuts`], run by the caller after it relaxed the parts): the cuts of
//!   the pass are kept only when the Editability that the layout will score once packed,
//!   estimated from one rendering of the views of [`JUDGE_SEED`] with every edge between two
//!   islands a seam ([`crate::metrics::unpacked_editability`]), falls by at most
//!   [`NeckOptions::editability_per_packing`] times `ln(efficiency_after / efficiency_before)`;
//!   otherwise all are undone. The seam term above prices a seam by its length against the
//!   surface's size; what a seam costs in the renders also depends on how much of each view the
//!   surface fills, and whether the parts' relaxing pays it back (the docs of
//!   [`EDITABILITY_PER_PACKING`]).
//! - **Many islands**: a layout of more than [`SHAPES_UP_TO`] islands (a marching-cubes mesh's
//!   floaters and crumbs) is left as it is. There [`pack_islands`] packs rectangles, a trial
//!   costs seconds, and no cut moves the packing: on an unruly bunny's density grid (3,815
//!   islands, 350k faces) one cut was kept, for +0.002 of efficiency at 2048² and 10 s.
//!
//! Each part keeps the map it had (a part of an injective map is injective), so no face flips
//! and no distortion changes; only seams and the layout do (the bake's caller then relaxes the
//! parts with SLIM, [`crate::injective`], when it makes islands injective). Deterministic: the
//! same mesh and options give the same bits. A path running alone packs an island's candidates
//! up to a thread's worth at once (the other core was idle during a trial's sequential
//! placements: the README bunny's pass 4.2 → 3.6 s); the first in order that packs is kept and
//! the trials counted are those up to it, so neither the cuts nor the report depend on the
//! number of threads, nor on whether the other path still runs.

use std::sync::atomic::{AtomicUsize, Ordering};

use foldhash::{HashMap, HashMapExt, HashSet, HashSetExt};

use nuvo_geometry::{TriMesh, UvLayer};
use rayon::prelude::*;
use serde::Serialize;

use crate::camera::orbit_views;
use crate::error::AtlasError;
use crate::geom::to_dvec3;
use crate::injective::{path_back, shortest_paths};
use crate::islands::{
    IslandCache, IslandPacking, SHAPES_UP_TO, ScaleTest, convex_hull, min_area_rotation, pack_islands,
    rotated,
};
use crate::metrics::{EvalOptions, unpacked_editability};
use crate::partuv::face_areas_3d;
use crate::refine::island_unknowns;
use crate::uvstats::{Dsu, face_uv_area2, faces_by_edge, require_uv, uv_charts, uv_islands};

/// Boundary vertices sampled per island for neck candidates.
pub const SAMPLES: usize = 48;
/// The shorter boundary arc between a candidate's ends, as a share of the loop's length.
pub const MIN_ARC: f64 = 0.15;
/// The least share of an island's UV area each side of a cut must hold.
pub const MIN_PART_SHARE: f64 = 0.05;
/// The relative precision to which the efficiency of a kept cut is measured.
pub const PROBE_STEP: f64 = 0.01;
/// Islands with fewer faces are not cut.
pub const MIN_FACES: usize = 8;

/// Options of [`cut_necks`].
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct NeckOptions {
    /// How trial layouts are packed (default: 512², gutter 1, rotations on: a quarter of the
    /// default atlas side and of its gutter, fast enough for tens of trials).
    #[serde(skip)]
    pub packing: IslandPacking,
    /// Trial packings (one packing attempt at one scale each) at most, on each path (default 40).
    pub max_trials: usize,
    /// Candidates tried per island (default 4).
    pub candidates: usize,
    /// Least rise of the trial packing's efficiency for which a cut is kept (default 0.01).
    pub min_gain: f64,
    /// Least relative rise of the efficiency per unit of the cut's relative length `L / √A`
    /// (default [`SEAM_COST`]; the cautious path asks [`CAUTIOUS_PRICE`] times it; module docs).
    pub seam_cost: f64,
    /// Islands in a row whose cuts are all refused after which a path ends (default 6).
    pub max_failures: usize,
    /// Packing attempts (trials and probes) times the mesh's faces at most, on each path (default 4e6: 41
    /// attempts of 0.1–0.15 s each on a 97k-face horse, the whole pass on a 6k-face cow; at
    /// 2e6 the Common Shapes' mean packing was 0.670 instead of 0.684, at 6e6 the same 0.684).
    pub max_face_attempts: usize,
    /// The Editability that the cuts may cost per unit of the log of the packing efficiency's
    /// rise, judged by [`judge_cuts`] (default [`EDITABILITY_PER_PACKING`]).
    pub editability_per_packing: f64,
}

impl Default for NeckOptions {
    fn default() -> Self {
        NeckOptions {
            packing: IslandPacking { resolution: 512, gutter: 1, rotate: true, search: 0 },
            max_trials: 40,
            candidates: 4,
            min_gain: 0.01,
            seam_cost: SEAM_COST,
            max_failures: 6,
            max_face_attempts: 4_000_000,
            editability_per_packing: EDITABILITY_PER_PACKING,
        }
    }
}

/// How many times [`NeckOptions::seam_cost`] the second, cautious path of [`cut_necks`] asks of
/// each cut (module docs, **Paths**).
pub const CAUTIOUS_PRICE: f64 = 2.0;

/// How much packing a seam must buy: a cut is tried only when it raises the efficiency by the
/// factor `1 + SEAM_COST · L / √A` at least (module docs, **Trial**; the cautious path asks
/// [`CAUTIOUS_PRICE`] times this). Issue 19 asks for packing ≥ 0.70 with at most 20 charts and a
/// median seam ≤ 16.6 (PartUV's) on Common Shapes; measured there by re-baking the same
/// checkpoints (mean packing, charts, median seam, Editability). One path (BENCHMARKS.md, "More
/// neck cuts"): the earlier defaults (0.25, 20 trials, 2 candidates, 3 failures, 2e6
/// face-attempts, [`EDITABILITY_PER_PACKING`] 0.02) 0.587, 12.4, 13.2, 0.9721; 0.125 with this
/// struct's defaults 0.684, 16.4, 14.4, 0.9675; 0.0625 0.681, 17.2, 15.3, 0.9661 (more seams, no
/// more packing: the greedy spends its trials on small gains). Two paths at this price and twice
/// it (BENCHMARKS.md, "Two paths for the necks pass", a later sitting where one path at 0.125
/// gave 0.690, 17.0, 15.4, 0.9679): 0.0625 0.704, 18.2, 15.7, 0.9675; prices from 0.05 to 0.075
/// 0.699–0.710.
pub const SEAM_COST: f64 = 0.0625;

/// Editability (the paper's metric) that the neck cuts may cost per unit of `ln(e_after /
/// e_before)` of the packing efficiency: a guard against a set of cuts whose seams cost the
/// renders far more than the packing they bought, not a price that decides the usual case. On
/// Common Shapes at the defaults the costliest set is woody's (a flat figure, one isometric
/// chart: five cuts cost 0.027 for a rise 0.499 → 0.742, 0.067 per unit; its Editability 0.981
/// against xatlas's 1.000), then the alligator's (nine cuts, 0.052 for 0.16 → 0.74, 0.034 per
/// unit); on the curved shapes 0.00–0.02 per unit (the parts' relaxing pays back part of their
/// seams). At 0.02 (the earlier value) the pass kept woody whole (packing 0.499) and, with
/// cheaper seams, undid the alligator's cuts (0.16); at 0.05 it undid woody's.
pub const EDITABILITY_PER_PACKING: f64 = 0.1;

/// Seed of the views with which [`judge_cuts`] renders the mesh: as many and as large as the
/// evaluation's ([`EvalOptions`]'s defaults) but from other directions (1, not 0), so that the
/// choice is not made on the very views that score it.
pub const JUDGE_SEED: u64 = 1;

/// What [`cut_necks`] did.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct NeckReport {
    /// Cuts kept (each adds one island).
    pub cuts: usize,
    /// Trial packings run (one attempt at one scale each).
    pub trials: usize,
    /// Packing attempts measuring how much tighter a kept cut packs (to [`PROBE_STEP`]).
    pub probes: usize,
    /// The packing efficiency before, at [`NeckOptions::packing`] (0 when skipped).
    pub efficiency_before: f64,
    /// The same after: the efficiency proven by the last kept cut's probes (to [`PROBE_STEP`]
    /// below the packer's own), before any later relaxing of the parts, and whether or not
    /// [`judge_cuts`] then undid the cuts (`undone`).
    pub efficiency_after: f64,
    /// Summed 3-D length of the cuts kept.
    pub seam_added: f64,
    /// The greedy paths the pass ran (module docs, **Paths**), the priced one first: the fields
    /// above are those of the one kept, `paths[chosen]`.
    pub paths: Vec<NeckPath>,
    /// Which of `paths` was kept.
    pub chosen: usize,
    /// Not run: the layout has more than [`SHAPES_UP_TO`] islands (module docs).
    pub skipped: bool,
    /// The Editability estimated before and after the cuts ([`judge_cuts`]; `None` when no
    /// cut was made or none was judged).
    pub editability: Option<[f64; 2]>,
    /// The cuts were undone by [`judge_cuts`]: they cost more Editability than their packing
    /// was worth.
    pub undone: bool,
}

/// One greedy path of [`cut_necks`] (module docs, **Paths**).
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct NeckPath {
    /// What each of its cuts had to buy: the least relative rise of the efficiency per unit of
    /// the cut's relative length.
    pub seam_cost: f64,
    /// Cuts it kept.
    pub cuts: usize,
    /// Trial packings it ran.
    pub trials: usize,
    /// Probes it ran.
    pub probes: usize,
    /// The efficiency its probes proved.
    pub efficiency_after: f64,
    /// Summed 3-D length of its cuts.
    pub seam_added: f64,
    /// `ln(efficiency_after) − seam_cost × seam_added / √A` at the pass's price
    /// ([`NeckOptions::seam_cost`]), by which the paths are compared.
    pub objective: f64,
}

/// The mesh with its islands cut and what was done.
#[derive(Clone, Debug, PartialEq)]
pub struct Necked {
    /// Same positions, triangles and face order; the UV layer with the cuts (islands not yet
    /// packed: a part sits beside the island it came from).
    pub mesh: TriMesh,
    /// The summary.
    pub report: NeckReport,
}

/// Cuts islands of `mesh` at their necks where the packing gains (module docs).
/// Errors: no UVs; the trial packing's errors.
pub fn cut_necks(mesh: &TriMesh, opts: &NeckOptions) -> Result<Necked, AtlasError> {
    let uv = require_uv(mesh)?;
    if uv_charts(mesh, uv).1 > SHAPES_UP_TO {
        let report = NeckReport { skipped: true, ..Default::default() };
        return Ok(Necked { mesh: mesh.clone(), report });
    }
    let packed = pack_islands(mesh, &opts.packing)?;
    let areas = face_areas_3d(mesh);
    let start = Start {
        efficiency: packed.efficiency,
        scale: packed.scale,
        size: areas.iter().sum::<f64>().sqrt().max(f64::MIN_POSITIVE),
        areas,
    };
    let prices = [opts.seam_cost, opts.seam_cost * CAUTIOUS_PRICE];
    let (mut meshes, paths): (Vec<TriMesh>, Vec<NeckPath>) = if prices[1] > prices[0] {
        let running = AtomicUsize::new(2);
        let (priced, cautious) = rayon::join(
            || greedy_path(mesh, opts, &start, prices[0], &running),
            || greedy_path(mesh, opts, &start, prices[1], &running),
        );
        [priced?, cautious?].into_iter().unzip()
    } else {
        // No dearer price (a seam cost of zero): one path.
        [greedy_path(mesh, opts, &start, prices[0], &AtomicUsize::new(1))?].into_iter().unzip()
    };
    // The better by the objective; on a tie the later path (the cautious one, fewer seams).
    let mut chosen = 0;
    for (k, path) in paths.iter().enumerate().skip(1) {
        if path.objective >= paths[chosen].objective {
            chosen = k;
        }
    }
    let kept = &paths[chosen];
    let report = NeckReport {
        cuts: kept.cuts,
        trials: kept.trials,
        probes: kept.probes,
        efficiency_before: start.efficiency,
        efficiency_after: kept.efficiency_after,
        seam_added: kept.seam_added,
        chosen,
        paths,
        ..Default::default()
    };
    Ok(Necked { mesh: meshes.swap_remove(chosen), report })
}

/// Takes one path off the count of [`greedy_path`]'s `running` when dropped.
struct EndsPath<'a>(&'a AtomicUsize);

impl Drop for EndsPath<'_> {
    fn drop(&mut self) {
        self.0.fetch_sub(1, Ordering::Relaxed);
    }
}

/// What both paths of [`cut_necks`] start from: the layout's packing before any cut, each
/// face's 3-D area and the square root of their sum (the length seams are measured against).
struct Start {
    efficiency: f64,
    scale: f64,
    areas: Vec<f64>,
    size: f64,
}

/// One greedy pass over the islands (module docs, **Trial**) asking each cut to buy packing at
/// `seam_cost`: the mesh with the cuts it kept, and its summary (its objective at the pass's
/// price, [`NeckOptions::seam_cost`]). `running` counts the paths not yet ended, this one
/// included: a path packs ahead (several candidates at once, the next probe beside this one)
/// only while it runs alone. Why: two paths side by side already keep both cores busy, and
/// packing ahead then spends a core on trials and probes that are thrown away (the README
/// bunny's necks phase 1.5–1.6 → 1.3–1.4 s without it). What is packed ahead never changes
/// what is kept or counted, so neither does `running`.
fn greedy_path(
    mesh: &TriMesh,
    opts: &NeckOptions,
    start: &Start,
    seam_cost: f64,
    running: &AtomicUsize,
) -> Result<(TriMesh, NeckPath), AtlasError> {
    // Counted out when the path ends, by an error too.
    let _ended = EndsPath(running);
    let alone = || running.load(Ordering::Relaxed) <= 1;
    let mut current = mesh.clone();
    let (mut efficiency, mut scale) = (start.efficiency, start.scale);
    let mut path = NeckPath { seam_cost, ..Default::default() };
    let mut tried: HashSet<Vec<u32>> = HashSet::new();
    // Each island's waste, by its faces: a cut changes one island (the others keep their faces
    // and coordinates), so only its parts are measured again.
    let mut wastes_seen: HashMap<Vec<u32>, f64> = HashMap::new();
    let (areas, size) = (&start.areas, start.size);
    let mut failures = 0;
    // The islands of the last trial, most of which the next one shares.
    let mut prepared = IslandCache::default();
    // Every packing attempt costs about the same per face (the islands' turns and shapes).
    let face_count = mesh.triangles.len().max(1);
    let affordable = |attempts: usize| attempts * face_count < opts.max_face_attempts;
    while path.trials < opts.max_trials
        && failures < opts.max_failures
        && scale > 0.0
        && affordable(path.trials + path.probes)
    {
        let uv = require_uv(&current)?;
        let mut islands = uv_islands(&current, uv);
        islands.retain(|f| f.len() >= MIN_FACES && !tried.contains(f));
        let unseen: Vec<&Vec<u32>> = islands.iter().filter(|f| !wastes_seen.contains_key(*f)).collect();
        let measured: Vec<f64> = unseen.par_iter().map(|f| waste(uv, areas, f)).collect();
        for (f, w) in unseen.into_iter().zip(measured) {
            wastes_seen.insert(f.clone(), w);
        }
        let wastes: Vec<f64> = islands.iter().map(|f| wastes_seen[f]).collect();
        let Some(pick) = (0..islands.len()).max_by(|&a, &b| wastes[a].total_cmp(&wastes[b]).then(b.cmp(&a)))
        else {
            break;
        };
        let faces = islands.swap_remove(pick);
        tried.insert(faces.clone());
        let candidates = neck_cuts(&current, uv, &faces, opts.candidates);
        let mut kept = None;
        let mut next = 0;
        while kept.is_none() && next < candidates.len() {
            // The candidates the budget lets the pass try from here, one after the other; up to
            // a thread's worth are tried at once, and the first in order that packs is kept, so
            // the pass keeps what trying them one at a time would and counts the same trials.
            let mut room = 0;
            while next + room < candidates.len()
                && path.trials + room < opts.max_trials
                && affordable(path.trials + room + path.probes)
            {
                room += 1;
            }
            let batch = room.min(if alone() { rayon::current_num_threads().max(1) } else { 1 });
            if batch == 0 {
                break;
            }
            let tried_now: Vec<_> = candidates[next..next + batch]
                .par_iter()
                .map(|(side, seam)| {
                    // The efficiency this cut must reach, as a factor on the current one (module
                    // docs); at one texel density the efficiency grows with the square of the scale.
                    let rise = 1.0 + (opts.min_gain / efficiency).max(seam_cost * seam / size);
                    let trial = apply_cut(&current, uv, &faces, side);
                    let (test, cache) = ScaleTest::reusing(&trial, &opts.packing, &prepared)?;
                    let packs = test.packs_at(scale * rise.sqrt());
                    Ok(Trial { mesh: trial, test, cache, seam: *seam, rise, packs })
                })
                .collect::<Result<Vec<Trial>, AtlasError>>()?;
            let first = tried_now.iter().position(|t| t.packs);
            path.trials += first.map_or(batch, |k| k + 1);
            next += batch;
            let last = first.unwrap_or(batch - 1);
            if let Some(t) = tried_now.into_iter().nth(last) {
                prepared = t.cache;
                if t.packs {
                    kept = Some((t.mesh, t.test, t.seam, t.rise));
                }
            }
        }
        let Some((trial, probe, seam, rise)) = kept else {
            failures += 1;
            continue;
        };
        // The cut usually packs tighter than it had to: find how much, to `PROBE_STEP`, asking
        // the islands the trial prepared.
        let (mut lo, mut step) = (rise, PROBE_STEP);
        let mut hi = None;
        let trials = path.trials;
        let goes_on = |lo: f64, hi: Option<f64>, probes: usize| {
            hi.is_none_or(|h: f64| h / lo > 1.0 + PROBE_STEP) && affordable(trials + probes)
        };
        let next_of = |lo: f64, hi: Option<f64>, step: f64| match hi {
            None => lo * (1.0 + step),
            Some(h) => (lo * h).sqrt(),
        };
        while goes_on(lo, hi, path.probes) {
            let next = next_of(lo, hi, step);
            // The probe after this one if this one packs is packed at once (the other core
            // was mostly idle through the probes); it counts only when this one packs, as
            // the sequential probes would then make it next. Same probes, same result.
            let ahead =
                (alone() && goes_on(next, hi, path.probes + 1)).then(|| next_of(next, hi, 2.0 * step));
            let (packs, ahead) = match ahead {
                Some(a) => {
                    let (packs, packs_ahead) = rayon::join(
                        || probe.packs_at(scale * next.sqrt()),
                        || probe.packs_at(scale * a.sqrt()),
                    );
                    (packs, Some((a, packs_ahead)))
                }
                None => (probe.packs_at(scale * next.sqrt()), None),
            };
            path.probes += 1;
            if !packs {
                hi = Some(next);
                continue;
            }
            (lo, step) = (next, 2.0 * step);
            if let Some((a, packs_ahead)) = ahead {
                path.probes += 1;
                if packs_ahead {
                    (lo, step) = (a, 2.0 * step);
                } else {
                    hi = Some(a);
                }
            }
        }
        (efficiency, scale) = (efficiency * lo, scale * lo.sqrt());
        current = trial;
        path.cuts += 1;
        path.seam_added += seam;
        failures = 0;
    }
    path.efficiency_after = efficiency;
    path.objective = if efficiency > 0.0 {
        efficiency.ln() - opts.seam_cost * path.seam_added / size
    } else {
        f64::NEG_INFINITY
    };
    Ok((current, path))
}

/// One candidate cut tried by [`cut_necks`]: the layout with the cut, its packing test, the
/// islands it prepared, the cut's 3-D length, the rise it had to reach and whether it did.
struct Trial {
    mesh: TriMesh,
    test: ScaleTest,
    cache: IslandCache,
    seam: f64,
    rise: f64,
    packs: bool,
}

/// Whether the cuts that turned `before` into `after` (the same mesh with the layout of
/// [`cut_necks`], relaxed or not) are worth their seams: kept when the Editability that `after`
/// will score once packed, estimated by [`unpacked_editability`] over the views of
/// [`JUDGE_SEED`], is at least `before`'s less [`NeckOptions::editability_per_packing`] times
/// the log of the packing rise that `report` measured. Records the estimates and the verdict
/// in `report`. Errors: the meshes differ in positions or faces, no UVs.
pub fn judge_cuts(
    before: &TriMesh,
    after: &TriMesh,
    opts: &NeckOptions,
    report: &mut NeckReport,
) -> Result<bool, AtlasError> {
    if report.cuts == 0 || report.efficiency_before <= 0.0 {
        return Ok(true);
    }
    let Some(e) = judged_editability(before, &[before, after])? else { return Ok(true) };
    let rise = (report.efficiency_after / report.efficiency_before).max(1.0);
    let keep = e[1] >= e[0] - opts.editability_per_packing * rise.ln();
    report.editability = Some([e[0], e[1]]);
    report.undone = !keep;
    Ok(keep)
}

/// [`unpacked_editability`] of each of `layouts` (UV layers of `mesh`) over the views the
/// layout passes judge by: the evaluation's count and size from [`JUDGE_SEED`]. `None` when
/// `mesh` has no bounds (nothing to render). Shared by [`judge_cuts`] and
/// [`crate::creases`]. Errors as [`unpacked_editability`]'s.
pub(crate) fn judged_editability(
    mesh: &TriMesh,
    layouts: &[&TriMesh],
) -> Result<Option<Vec<f64>>, AtlasError> {
    let Some(bounds) = mesh.bounds() else { return Ok(None) };
    let views = EvalOptions { seed: JUDGE_SEED, ..Default::default() };
    let cameras = orbit_views(&bounds, views.views, views.seed, views.resolution, views.resolution);
    unpacked_editability(mesh, layouts, &cameras, &views.image).map(Some)
}

/// The island's minimum-area bounding rectangle's area minus its UV area, in units of 3-D area
/// (islands come at different texel densities: each chart was baked into its own square).
fn waste(uv: &UvLayer, areas: &[f64], faces: &[u32]) -> f64 {
    let points: Vec<[f64; 2]> = faces
        .iter()
        .flat_map(|&f| uv.triangles[f as usize].map(|i| uv.coords[i as usize].map(f64::from)))
        .collect();
    let hull = convex_hull(&points);
    let rot = min_area_rotation(&hull);
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for &p in &hull {
        let q = rotated(p, rot);
        for k in 0..2 {
            lo[k] = lo[k].min(q[k]);
            hi[k] = hi[k].max(q[k]);
        }
    }
    let rect = if hull.len() >= 3 { (hi[0] - lo[0]) * (hi[1] - lo[1]) } else { 0.0 };
    let area_uv = uv_area(uv, faces);
    let area_3d: f64 = faces.iter().map(|&f| areas[f as usize]).sum();
    if area_uv > 0.0 { (rect - area_uv) * area_3d / area_uv } else { 0.0 }
}

/// The summed unsigned UV area of `faces`.
fn uv_area(uv: &UvLayer, faces: &[u32]) -> f64 {
    faces.iter().map(|&f| 0.5 * face_uv_area2(uv, f as usize).abs()).sum()
}

/// The candidate cuts of an island (module docs), each as the side of each of `faces` (true:
/// the part that moves) and the cut's 3-D length.
fn neck_cuts(mesh: &TriMesh, uv: &UvLayer, faces: &[u32], count: usize) -> Vec<(Vec<bool>, f64)> {
    let (corners, n) = island_unknowns(mesh, uv, faces);
    let mut pos = vec![[0.0f64; 2]; n];
    let mut vertex = vec![0u32; n];
    for (t, c) in corners.iter().enumerate() {
        for k in 0..3 {
            pos[c[k] as usize] = uv.coords[uv.triangles[faces[t] as usize][k] as usize].map(f64::from);
            vertex[c[k] as usize] = mesh.triangles[faces[t] as usize][k];
        }
    }
    let length3 = |a: u32, b: u32| {
        let at = |v: u32| to_dvec3(mesh.positions[vertex[v as usize] as usize]);
        at(a).distance(at(b))
    };
    let dist = |a: u32, b: u32| {
        let (p, q) = (pos[a as usize], pos[b as usize]);
        ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2)).sqrt()
    };
    // The faces on each edge; directed boundary edges. Collapsed faces (two corners on one
    // unknown: zero UV area) bound nothing; they still join their neighbours across their
    // edges between two unknowns, as in `uv_charts`.
    let collapsed = |c: &[u32; 3]| c[0] == c[1] || c[1] == c[2] || c[0] == c[2];
    let by_edge = faces_by_edge(corners.iter().enumerate().map(|(t, &c)| (t as u32, c)));
    let uses = |e: &(u32, u32)| by_edge[e].iter().filter(|&&t| !collapsed(&corners[t as usize])).count();
    let mut next: Vec<Option<u32>> = vec![None; n];
    let mut on_boundary = vec![false; n];
    for c in corners.iter().filter(|c| !collapsed(c)) {
        for k in 0..3 {
            let (a, b) = (c[k], c[(k + 1) % 3]);
            if uses(&(a.min(b), a.max(b))) == 1 {
                if next[a as usize].is_some() {
                    return Vec::new(); // two boundary edges leave one vertex: not simple loops
                }
                next[a as usize] = Some(b);
                (on_boundary[a as usize], on_boundary[b as usize]) = (true, true);
            }
        }
    }
    // The loops; the outer one encloses the largest area.
    let mut seen = vec![false; n];
    let mut outer: Option<(f64, Vec<u32>)> = None;
    for s in 0..n as u32 {
        if seen[s as usize] || next[s as usize].is_none() {
            continue;
        }
        let mut lp = Vec::new();
        let mut v = s;
        while !seen[v as usize] {
            seen[v as usize] = true;
            lp.push(v);
            let Some(w) = next[v as usize] else { return Vec::new() };
            v = w;
        }
        if v != s {
            return Vec::new();
        }
        let area: f64 = (0..lp.len())
            .map(|i| {
                let (p, q) = (pos[lp[i] as usize], pos[lp[(i + 1) % lp.len()] as usize]);
                p[0] * q[1] - p[1] * q[0]
            })
            .sum::<f64>()
            .abs();
        if outer.as_ref().is_none_or(|(a, _)| area > *a) {
            outer = Some((area, lp));
        }
    }
    let Some((_, lp)) = outer else { return Vec::new() };
    let m = lp.len();
    let mut arc = vec![0.0; m + 1];
    for i in 0..m {
        arc[i + 1] = arc[i] + dist(lp[i], lp[(i + 1) % m]);
    }
    let perimeter = arc[m];
    if perimeter.is_nan() || perimeter <= 0.0 || m < 4 {
        return Vec::new();
    }
    // Samples evenly by arc length (first loop vertex at or after each mark).
    let mut samples: Vec<usize> = Vec::new();
    let mut i = 0;
    for s in 0..SAMPLES {
        let mark = perimeter * s as f64 / SAMPLES as f64;
        while i < m && arc[i] < mark {
            i += 1;
        }
        if i < m && samples.last() != Some(&i) {
            samples.push(i);
        }
    }
    let mut pairs: Vec<(f64, usize, usize)> = Vec::new();
    for (x, &a) in samples.iter().enumerate() {
        for &b in &samples[x + 1..] {
            let along = arc[b] - arc[a];
            let shorter = along.min(perimeter - along);
            if shorter >= MIN_ARC * perimeter {
                pairs.push((dist(lp[a], lp[b]) / shorter, a, b));
            }
        }
    }
    pairs.sort_by(|x, y| x.0.total_cmp(&y.0).then(x.1.cmp(&y.1)).then(x.2.cmp(&y.2)));
    let near = |i: usize, j: usize| {
        let d = (arc[i] - arc[j]).abs();
        d.min(perimeter - d) < 0.5 * MIN_ARC * perimeter
    };
    // The edges between two unknowns, sorted.
    let mut all: Vec<(u32, u32)> = by_edge.keys().copied().filter(|e| e.0 != e.1).collect();
    all.sort();
    // Vertex adjacency with UV lengths, for the paths: the edges some non-collapsed face uses.
    let mut adj: Vec<Vec<(u32, f64)>> = vec![Vec::new(); n];
    for &(a, b) in all.iter().filter(|e| uses(e) > 0) {
        adj[a as usize].push((b, dist(a, b)));
        adj[b as usize].push((a, dist(a, b)));
    }
    let total = uv_area(uv, faces);
    // Every pair of faces joined across an edge of `all` (collapsed faces join too), by the
    // edge's index there: what `two_parts` walks for every candidate.
    let index: HashMap<(u32, u32), u32> = all.iter().enumerate().map(|(i, &e)| (e, i as u32)).collect();
    let joins: Vec<[u32; 3]> = all
        .iter()
        .enumerate()
        .flat_map(|(i, e)| by_edge[e].windows(2).map(move |w| [i as u32, w[0], w[1]]))
        .collect();
    // A pair's cut: the shortest path between its ends through the inside, the two parts it
    // leaves, and the path's 3-D length; `None` when it does not split the island into two
    // parts of at least `MIN_PART_SHARE` each.
    let cut_of = |a: usize, b: usize| -> Option<(Vec<bool>, f64)> {
        let (va, vb) = (lp[a], lp[b]);
        let (_, prev, reached) =
            shortest_paths(&adj, &[va], |v| v == vb, |v| v == vb || !on_boundary[v as usize]);
        reached?;
        let mut cut = vec![false; all.len()];
        let mut seam = 0.0;
        for (p, v) in path_back(&prev, vb) {
            // Every path edge joins two unknowns of the island (`adj` holds no other).
            cut[index[&(p.min(v), p.max(v))] as usize] = true;
            seam += length3(p, v);
        }
        let side = two_parts(corners.len(), &joins, &cut)?;
        let moved_faces: Vec<u32> = faces.iter().zip(&side).filter(|(_, s)| **s).map(|(&f, _)| f).collect();
        let moved = uv_area(uv, &moved_faces);
        (moved >= MIN_PART_SHARE * total && total - moved >= MIN_PART_SHARE * total).then_some((side, seam))
    };
    let excluded = |a: usize, b: usize, taken: &[(usize, usize)]| {
        taken.iter().any(|&(x, y)| (near(a, x) && near(b, y)) || (near(a, y) && near(b, x)))
    };
    // Pairs in order of score, each taken unless near a taken one or without a cut. A pair's cut
    // does not depend on what was taken, so up to a thread's worth of the next pairs not yet
    // excluded are cut at once and then taken in order: the same cuts as one at a time (a pair
    // excluded by one taken earlier in its batch is skipped as it would have been).
    let batch = rayon::current_num_threads().max(1);
    let mut taken: Vec<(usize, usize)> = Vec::new();
    let mut cuts = Vec::new();
    let mut next = 0;
    while cuts.len() < count && next < pairs.len() {
        let mut ends = Vec::with_capacity(batch);
        while ends.len() < batch && next < pairs.len() {
            let (_, a, b) = pairs[next];
            next += 1;
            if !excluded(a, b, &taken) {
                ends.push((a, b));
            }
        }
        let found: Vec<_> = ends.par_iter().map(|&(a, b)| cut_of(a, b)).collect();
        for ((a, b), cut) in ends.into_iter().zip(found) {
            if cuts.len() >= count || excluded(a, b, &taken) {
                continue;
            }
            if let Some(cut) = cut {
                taken.push((a, b));
                cuts.push(cut);
            }
        }
    }
    cuts
}

/// The two parts of an island's `count` faces, joined across every edge of `joins` (`[edge,
/// face, face]`) that is not `cut`: `side[t]` is true on the part without face 0; `None`
/// unless there are exactly two parts.
fn two_parts(count: usize, joins: &[[u32; 3]], cut: &[bool]) -> Option<Vec<bool>> {
    let mut dsu = Dsu::new(count);
    for &[e, f, g] in joins {
        if !cut[e as usize] {
            dsu.union(f, g);
        }
    }
    let root = dsu.find(0);
    let side: Vec<bool> = (0..count as u32).map(|t| dsu.find(t) != root).collect();
    let other = side.iter().position(|&s| s)?;
    let other_root = dsu.find(other as u32);
    (0..count as u32).all(|t| dsu.find(t) == root || dsu.find(t) == other_root).then_some(side)
}

/// `mesh` with the faces of `faces` on the moved `side` given their own texture coordinates,
/// moved beside the island so the two parts are two islands.
fn apply_cut(mesh: &TriMesh, uv: &UvLayer, faces: &[u32], side: &[bool]) -> TriMesh {
    let (mut lo, mut hi) = ([f32::INFINITY; 2], [f32::NEG_INFINITY; 2]);
    for &f in faces {
        for i in uv.triangles[f as usize] {
            let p = uv.coords[i as usize];
            for k in 0..2 {
                lo[k] = lo[k].min(p[k]);
                hi[k] = hi[k].max(p[k]);
            }
        }
    }
    let shift = 2.0 * (hi[0] - lo[0]).max(hi[1] - lo[1]).max(f32::MIN_POSITIVE);
    let mut coords = uv.coords.clone();
    let mut triangles = uv.triangles.clone();
    let mut copy: HashMap<u32, u32> = HashMap::new();
    for (&f, _) in faces.iter().zip(side).filter(|(_, s)| **s) {
        triangles[f as usize] = uv.triangles[f as usize].map(|i| {
            *copy.entry(i).or_insert_with(|| {
                let p = uv.coords[i as usize];
                coords.push([p[0] + shift, p[1]]);
                (coords.len() - 1) as u32
            })
        });
    }
    TriMesh { uv: Some(UvLayer { coords, triangles }), ..mesh.clone() }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testmesh::grid;
    use crate::uvstats::uv_charts;

    /// The flat grid over `[0, w] × [0, h]` (`n × m` quads) keeping the faces whose centre
    /// `keep` accepts, with UV = position.
    fn shape(n: u32, m: u32, w: f32, h: f32, keep: impl Fn(f32, f32) -> bool) -> TriMesh {
        let base = grid(n.max(m), |p| [p[0], p[1]]);
        let k = n.max(m) as f32;
        let positions: Vec<[f32; 3]> = base
            .positions
            .iter()
            .map(|p| [(p[0] + 1.0) * 0.5 * k / n as f32 * w, (p[1] + 1.0) * 0.5 * k / m as f32 * h, 0.0])
            .collect();
        let triangles: Vec<[u32; 3]> = base
            .triangles
            .iter()
            .copied()
            .filter(|t| {
                let c = t.map(|v| positions[v as usize]);
                let (x, y) = ((c[0][0] + c[1][0] + c[2][0]) / 3.0, (c[0][1] + c[1][1] + c[2][1]) / 3.0);
                x < w && y < h && keep(x, y)
            })
            .collect();
        let coords = positions.iter().map(|p| [p[0], p[1]]).collect();
        TriMesh { positions, uv: Some(UvLayer { coords, triangles: triangles.clone() }), triangles }
    }

    fn tri(uv: &UvLayer, f: u32) -> [[f32; 2]; 3] {
        uv.triangles[f as usize].map(|i| uv.coords[i as usize])
    }

    /// Each face's UV triangle is the input's moved by a translation only.
    fn translated_only(before: &TriMesh, after: &TriMesh) -> bool {
        let (a, b) = (before.uv.as_ref().unwrap(), after.uv.as_ref().unwrap());
        (0..before.triangles.len()).all(|f| {
            let (s, t) = (tri(a, f as u32), tri(b, f as u32));
            (1..3).all(|k| (0..2).all(|c| ((s[k][c] - s[0][c]) - (t[k][c] - t[0][c])).abs() < 1e-5))
        })
    }

    #[test]
    fn a_long_strip_is_cut_and_packs_tighter() {
        let mesh = shape(32, 4, 8.0, 1.0, |_, _| true);
        let out = cut_necks(&mesh, &NeckOptions::default()).unwrap();
        assert!(out.report.cuts >= 1, "{:?}", out.report);
        assert!(out.report.efficiency_after >= out.report.efficiency_before + 0.01, "{:?}", out.report);
        let before = pack_islands(&mesh, &IslandPacking::default()).unwrap().efficiency;
        let after = pack_islands(&out.mesh, &IslandPacking::default()).unwrap().efficiency;
        assert!(after > 1.5 * before, "{before} -> {after}");
        assert!(translated_only(&mesh, &out.mesh));
        let uv = out.mesh.uv.as_ref().unwrap();
        assert_eq!(uv_charts(&out.mesh, uv).1, out.report.cuts + 1);
        assert!(out.report.seam_added > 0.0);
    }

    #[test]
    fn cuts_are_undone_when_their_seams_cost_more_editability_than_the_packing_is_worth() {
        // A flat strip mapped by its own xy into the unit square: one island scores
        // Editability 1; the cut's seam costs some, which the rise in packing pays at a high
        // exchange rate but not at zero.
        let mut mesh = shape(32, 4, 8.0, 1.0, |_, _| true);
        for c in &mut mesh.uv.as_mut().unwrap().coords {
            *c = c.map(|x| x / 8.0);
        }
        let out = cut_necks(&mesh, &NeckOptions::default()).unwrap();
        assert!(out.report.cuts >= 1, "{:?}", out.report);
        let judge = |rate: f64| {
            let mut report = out.report.clone();
            let opts = NeckOptions { editability_per_packing: rate, ..Default::default() };
            (judge_cuts(&mesh, &out.mesh, &opts, &mut report).unwrap(), report)
        };
        let (keep, report) = judge(0.0);
        assert!(!keep && report.undone);
        let [before, after] = report.editability.unwrap();
        assert!((before - 1.0).abs() < 1e-4, "one isometric island: {before}");
        assert!(after < before - 1e-4, "the seam is counted: {after}");
        let (keep, report) = judge(1.0);
        assert!(keep && !report.undone, "{report:?}");
        // No cut: nothing to judge.
        let mut none = NeckReport::default();
        assert!(judge_cuts(&mesh, &mesh, &NeckOptions::default(), &mut none).unwrap());
        assert_eq!(none.editability, None);
    }

    #[test]
    fn one_thread_or_several_try_the_same_cuts_and_count_the_same_trials() {
        // A comb: a spine with four teeth, so that candidates both pass and fail. Candidates
        // are tried a thread's worth at once; what is kept and counted must not depend on it.
        let comb = shape(32, 16, 8.0, 4.0, |x, y| y < 1.0 || (x % 2.0) < 1.0);
        let run = |threads: usize| {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
            pool.install(|| cut_necks(&comb, &NeckOptions::default()).unwrap())
        };
        let one = run(1);
        assert!(one.report.cuts >= 1 && one.report.trials > one.report.cuts, "{:?}", one.report);
        for threads in [2, 3] {
            let several = run(threads);
            assert_eq!(several.report, one.report, "{threads} threads");
            assert!(several.mesh == one.mesh, "{threads} threads");
        }
    }

    #[test]
    fn an_islands_neck_candidates_do_not_depend_on_the_thread_count() {
        // The comb's boundary comes close to itself at many places, so pairs near a taken one
        // are skipped; candidates are cut a thread's worth at once and must be taken as one at
        // a time would take them.
        let comb = shape(32, 16, 8.0, 4.0, |x, y| y < 1.0 || (x % 2.0) < 1.0);
        let uv = comb.uv.as_ref().unwrap();
        let faces: Vec<u32> = (0..comb.triangles.len() as u32).collect();
        let run = |threads: usize| {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
            pool.install(|| neck_cuts(&comb, uv, &faces, 8))
        };
        let one = run(1);
        assert!(one.len() >= 4, "{} candidates", one.len());
        for threads in [2, 3, 5] {
            assert!(run(threads) == one, "{threads} threads");
        }
    }

    #[test]
    fn a_cut_leaves_every_other_island_with_its_faces_and_coordinates() {
        // What the pass's memo of wastes by faces relies on: two combs side by side, one cut.
        let left = shape(32, 16, 8.0, 4.0, |x, y| y < 1.0 || (x % 2.0) < 1.0);
        let mut both = left.clone();
        let (n, uv_n) = (left.positions.len() as u32, left.uv.as_ref().unwrap().coords.len() as u32);
        both.positions.extend(left.positions.iter().map(|p| [p[0] + 10.0, p[1], p[2]]));
        both.triangles.extend(left.triangles.iter().map(|t| t.map(|v| v + n)));
        let uv = both.uv.as_mut().unwrap();
        uv.coords.extend(left.uv.as_ref().unwrap().coords.iter().map(|p| [p[0] + 10.0, p[1]]));
        uv.triangles.extend(left.uv.as_ref().unwrap().triangles.iter().map(|t| t.map(|v| v + uv_n)));
        let uv = both.uv.as_ref().unwrap();
        let islands = uv_islands(&both, uv);
        assert_eq!(islands.len(), 2);
        let cut = &neck_cuts(&both, uv, &islands[0], 1)[0].0;
        let after = apply_cut(&both, uv, &islands[0], cut);
        let after_uv = after.uv.as_ref().unwrap();
        let after_islands = uv_islands(&after, after_uv);
        assert_eq!(after_islands.len(), 3);
        assert!(after_islands.contains(&islands[1]), "the other island keeps its faces");
        assert!(islands[1].iter().all(|&f| tri(uv, f) == tri(after_uv, f)), "and its coordinates");
    }

    #[test]
    fn the_pass_keeps_the_better_of_its_priced_and_cautious_paths() {
        let comb = shape(32, 16, 8.0, 4.0, |x, y| y < 1.0 || (x % 2.0) < 1.0);
        let size = face_areas_3d(&comb).iter().sum::<f64>().sqrt();
        let islands = |m: &TriMesh| uv_charts(m, m.uv.as_ref().unwrap()).1;
        let mut differed = false;
        for price in [0.02, 0.0625, 0.2] {
            let out = cut_necks(&comb, &NeckOptions { seam_cost: price, ..Default::default() }).unwrap();
            let r = &out.report;
            assert_eq!(r.paths.len(), 2, "{r:?}");
            // The cautious path is the pass at twice the price, on its own.
            let dearer = NeckOptions { seam_cost: CAUTIOUS_PRICE * price, ..Default::default() };
            let alone = cut_necks(&comb, &dearer).unwrap().report.paths[0].clone();
            let cautious = &r.paths[1];
            assert_eq!(cautious.seam_cost, CAUTIOUS_PRICE * price);
            assert_eq!(
                (
                    cautious.cuts,
                    cautious.trials,
                    cautious.probes,
                    cautious.efficiency_after,
                    cautious.seam_added
                ),
                (alone.cuts, alone.trials, alone.probes, alone.efficiency_after, alone.seam_added),
                "price {price}"
            );
            // Each path is scored at the pass's price, and the higher is kept (a tie: the cautious).
            for p in &r.paths {
                let expected = p.efficiency_after.ln() - price * p.seam_added / size;
                assert!((p.objective - expected).abs() < 1e-12, "{p:?}");
            }
            let [a, b] = [&r.paths[0], &r.paths[1]];
            assert_eq!(r.chosen, usize::from(b.objective >= a.objective), "price {price}: {r:?}");
            let kept = &r.paths[r.chosen];
            assert_eq!((r.cuts, r.trials, r.probes), (kept.cuts, kept.trials, kept.probes));
            assert_eq!((r.efficiency_after, r.seam_added), (kept.efficiency_after, kept.seam_added));
            assert_eq!(islands(&out.mesh), 1 + r.cuts, "the mesh is the kept path's");
            differed |= a.cuts != b.cuts;
        }
        assert!(differed, "the comb's paths differ at some price");
        // No dearer price than zero: one path.
        let free = cut_necks(&comb, &NeckOptions { seam_cost: 0.0, ..Default::default() }).unwrap();
        assert_eq!((free.report.paths.len(), free.report.chosen), (1, 0));
    }

    #[test]
    fn a_dumbbell_is_cut_across_its_bridge() {
        // Two 2 × 2 squares joined by a 2-long bridge a quarter as wide.
        let mesh = shape(48, 16, 6.0, 2.0, |x, y| !(2.0..4.0).contains(&x) || (0.75..1.25).contains(&y));
        let opts = NeckOptions { max_trials: 1, ..Default::default() };
        let out = cut_necks(&mesh, &opts).unwrap();
        assert_eq!(out.report.cuts, 1, "{:?}", out.report);
        let (chart, n) = uv_charts(&out.mesh, out.mesh.uv.as_ref().unwrap());
        assert_eq!(n, 2);
        let centre_x = |f: usize| out.mesh.corners(f).iter().map(|p| p[0]).sum::<f32>() / 3.0;
        let (left, right): (Vec<usize>, Vec<usize>) = (0..chart.len())
            .filter(|&f| !(2.0..4.0).contains(&centre_x(f)))
            .partition(|&f| centre_x(f) < 2.0);
        let side = |faces: &[usize]| faces.iter().map(|&f| chart[f]).collect::<HashSet<u32>>();
        assert_eq!(side(&left).len(), 1, "the left square is in one island");
        assert_eq!(side(&right).len(), 1, "the right square is in one island");
        assert_ne!(side(&left), side(&right), "and the right square in the other");
        assert!(translated_only(&mesh, &out.mesh));
    }

    #[test]
    fn a_layout_of_very_many_islands_is_left_as_it_is() {
        // A long strip, every face its own island, with more islands than shapes are packed.
        let strip = shape(SHAPES_UP_TO as u32, 1, 8.0, 1.0, |_, _| true);
        let apart = crate::testmesh::with_uv_per_corner(&strip, |f, _, p| [p[0] + 10.0 * f as f32, p[1]]);
        let out = cut_necks(&apart, &NeckOptions::default()).unwrap();
        assert!(out.report.skipped && out.report.cuts == 0);
        assert_eq!(out.mesh, apart);
    }

    #[test]
    fn a_square_is_left_whole_and_a_costly_seam_is_refused() {
        let square = shape(8, 8, 1.0, 1.0, |_, _| true);
        let out = cut_necks(&square, &NeckOptions::default()).unwrap();
        assert_eq!(out.report.cuts, 0);
        assert_eq!(out.mesh, square);
        let strip = shape(32, 4, 8.0, 1.0, |_, _| true);
        let opts = NeckOptions { seam_cost: 1e3, ..Default::default() };
        let out = cut_necks(&strip, &opts).unwrap();
        assert!(out.report.trials >= 1, "a candidate was tried and refused for its seam");
        assert_eq!((out.report.cuts, out.report.efficiency_after), (0, out.report.efficiency_before));
        assert_eq!(out.mesh, strip);
    }
}

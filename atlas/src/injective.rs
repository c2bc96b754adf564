//! Making every UV island injective — no flipped face, no face over another of its island — and
//! lowering its distortion while keeping it so: the guarantee xatlas gives, on Nuvo's few large
//! charts (issue 19, part 1).
//!
//! Nuvo's networks give no bijectivity guarantee (the paper names it as a limitation) and the ARAP
//! refinement ([`crate::refine`]) never adds a flip but cannot remove one, nor undo a chart that
//! wraps round a handle onto itself. [`make_injective`] takes each island and ends with a map that
//! is injective by construction and by check. Per island (and per part, recursively):
//!
//! 1. **Keep** the current map when it passes the injective check (below).
//! 2. **Repair** it in place (`Patch::repair`): the *bad faces* (not positive, or overlapping
//!    another positive face of the island) and the faces within 1, 2, 4, then 8 rings of them form
//!    a region whose inner unknowns (not on the island's boundary) are re-solved as a harmonic map
//!    (symmetrised mean-value weights) with everything else fixed; the first injective result is
//!    kept. This mends a fold inside a chart without a new seam.
//! 3. **Re-embed** the island as a disc: islands with several boundary loops are first cut open
//!    along shortest edge paths from each loop but the longest to another loop, and a closed
//!    island (no boundary: a floater of a marching-cubes mesh) along a slit, the shortest path
//!    between two vertices far apart (the farthest from its first vertex, and the farthest from
//!    that one), so a genus-0 island becomes a disc; the start is the **least-squares conformal
//!    map** (Lévy et al. 2002; two boundary unknowns pinned, scaled to the rest area: an
//!    isometry on a developable patch) when it passes the injective check, else the **Tutte
//!    embedding** (mean-value weights, symmetrised; boundary on a circle by arc length),
//!    injective for any positive weights and a strictly convex boundary (Floater 2003,
//!    "One-to-one piecewise linear mappings over triangulations"), then SLIM (step 5). The
//!    result is kept when its symmetric Dirichlet energy per unit area is at most
//!    [`SPLIT_ENERGY`], or when splitting is not allowed or the island is one face.
//! 4. **Split** (`split`): otherwise the bad faces of the current map are **detached**: the good
//!    faces keep their map and grow back over the bad ones breadth-first (`Patch::grow`: a bad
//!    face joins when it can be placed, by its rest shape on an edge already placed, as a positive
//!    triangle over no good face, whose UV-to-rest area ratio is within [`GROW_SCALE`] of the
//!    good faces' median either way); what stays bad, and each connected piece of the good faces,
//!    becomes a part that goes back to step 1 with the positions it had, mirrored (`v` negated)
//!    when their summed signed area is negative: a part detached because the map mirrors it
//!    (the far side of a thin wall that one chart maps from both sides: 43% of the unruly
//!    vase's faces) is a mirror image of a map that may be good, and is kept or mended whole
//!    instead of being embedded anew and split (the whole island is turned the same way in
//!    step 1). A **ragged** detachment is not made: when it would give more than two parts and
//!    their seams (the summed rest length of the edges between two parts) exceed [`RAGGED_CUT`]
//!    times the cut between the island's two halves (below): where one chart maps both sides
//!    of a thin wall, the flips of the far side interleave with the near side's faces, and
//!    detaching them cut the unruly teapot's charts into hundreds of parts whose seams covered
//!    its body. The island is then split between the wall's **sides** instead: each face
//!    labelled by its orientation in the map, smoothed by a minimum cut that charges the edges
//!    between the sides by their length where the surface does not turn back
//!    ([`SIDE_SMOOTHING`]), and each connected part solved again from the map (the mirrored side
//!    mirrored back). An island with no current map to detach from, whose faces are all bad, or
//!    whose labelling finds one side only or a ragged split too is cut
//!    into its pieces of consistent winding and manifold edges or, when it is one, **in two**
//!    (`Patch::cut_in_two`): the faces within a third of the way (in steps across edges) from
//!    either of two far-apart faces go with that face, and the band between is parted where
//!    the cut is shortest (rest edge lengths, discounted across a bend as for the sides), found
//!    exactly by a minimum cut; the *halves* grown breadth-first from the two faces, whose
//!    seam runs where the two fronts meet, are the fallback and the yardstick of
//!    [`RAGGED_CUT`]. A part of one face is always a disc, so the recursion ends. Without `split` an island
//!    that is neither injective, repairable nor a disc keeps its UVs (counted as not injective).
//! 5. **SLIM** lowers the distortion without losing injectivity (Rabinovich, Poranne, Panozzo,
//!    Sorkine-Hornung, "Scalable Locally Injective Mappings", 2017) on the symmetric Dirichlet
//!    energy `Σ_t A_t (‖J_t‖²_F + ‖J_t⁻¹‖²_F)` (4 per unit area for an isometry, infinite for a
//!    degenerate face), plus [`InjectiveOptions::conformal`] `λ` times the conformal (MIPS)
//!    excess `σ₁/σ₂ + σ₂/σ₁ − 2` on faces with a 3-D area (off by default: on the 14 Common Shapes
//!    λ = 1 raised PartUV's mean angular score 0.959 → 0.962 and lowered Editability 0.9588 →
//!    0.9573, the worst-chart area distortion rising 1.11 → 1.19; BENCHMARKS.md), plus
//!    [`InjectiveOptions::orthogonal`] times `cos²` of the angle the texture axes `∂p/∂u` and
//!    `∂p/∂v` make on the surface and [`InjectiveOptions::equiareal`] times `(det J − 1)²`, on
//!    the same faces (off by default; [`UNWRAP_ORTHOGONAL`] and [`UNWRAP_EQUIAREAL`] in `nuvo
//!    unwrap`). The symmetric Dirichlet energy penalises every stretch; these two terms pull
//!    towards the maps whose axes stay perpendicular and whose faces keep their area, which may
//!    stretch along an axis: what Editability's Conformal and Stretch terms and PartUV's angular
//!    and area scores measure (Common Shapes at 64 and 32: Editability 0.9594 → 0.9721, angular
//!    0.955 → 0.982, for a median anisotropy `σ₁/σ₂` 1.05 → 1.09; BENCHMARKS.md, "Texture axes
//!    kept perpendicular and faces at their island's density"). Each round a
//!    reweighted local/global step (a 2n × 2n sparse Cholesky solve,
//!    `faer`) and a flip-avoiding line search (Smith & Schaefer, "Bijective Parameterization with
//!    Free Boundaries", 2015: at most [`STEP_SHARE`] of the first step at which a face's area
//!    reaches zero, halved until the energy decreases and the map is still injective, at most
//!    [`MAX_HALVINGS`] times). A free boundary could still run into itself, so the free space round
//!    the island inside a box is triangulated (constrained Delaunay, `spade`) into a **scaffold**
//!    (Jiang, Schaefer, Panozzo, "Simplicial Complex Augmentation Framework for Bijective Maps",
//!    2017) whose triangles join the energy (rest shape: their shape at the round's start; total
//!    weight [`SCAFFOLD_WEIGHT`] of the island's) and the line search: as two parts of the boundary
//!    approach, the triangles between them are squeezed and push back, so the iteration slides on
//!    instead of stalling. The triangulation is kept for up to [`SCAFFOLD_ROUNDS`] rounds (the
//!    line search keeps its triangles positive, so it still fills the box) and made anew sooner
//!    after a round whose step it limited; while it is kept, the system's sparsity pattern and
//!    symbolic factorisation are reused and only its values are refilled. Boundary unknowns at
//!    one point (an island touching itself, as the non-manifold vertices of marching-cubes meshes
//!    make it) move as one through every round and are one point of the triangulation, and the
//!    two sides of a closed slit are one edge with no scaffold on it; where the boundary still
//!    cannot be triangulated the round runs without a scaffold. The rounds stop after
//!    [`InjectiveOptions::iterations`], or when one lowers the energy by less than
//!    [`InjectiveOptions::tolerance`] (relative) and by less than
//!    [`InjectiveOptions::excess_tolerance`] of its excess over an isometry's.
//! 6. **Cone cuts** ([`InjectiveOptions::cut_cones`]): a flat map of a surface that gathers an
//!    angle deficit round a point (a horn's tip, a hoof, a box's corner) must stretch or shear
//!    round it unless a seam runs to it, and a slit from the point to the boundary lets the map
//!    open there by the deficit instead. Every solved disc is cut at its **cone points**: interior
//!    unknowns whose angle deficits (2π minus the rest angles of their faces, 0 on the boundary
//!    and where a face without 3-D area touches) summed over the unknowns within
//!    [`CONE_RADIUS`]` · √A` (rest edge lengths, `A` the patch's 3-D area) reach
//!    [`CONE_DEFICIT`], that are farther than that radius from the boundary (which already
//!    relieves them), strongest first, none within twice the radius of one taken, at most
//!    [`MAX_CONES`]. Each is cut along the shortest edge path to the boundary or to a slit cut
//!    before, so the patch stays a disc. Each copy of a cut vertex starts a share
//!    ([`SLIT_SHARE`], halved until the map is injective) of the way towards its own fan's
//!    centre, so the sides are apart, and SLIM (its first round without a scaffold, which would
//!    hold the hair-thin slits shut) runs from there. The cuts are kept when they remove at least
//!    [`CONE_GAIN`] of the disc's energy above an isometry's (`E − 4A`) and raise its PartUV
//!    area distortion (a per-face mean, small faces counted like large ones) by at most
//!    [`CONE_AREA_RISE`]; otherwise the disc stays as it was solved. Cone cuts add seams but no
//!    island.
//!
//! Definitions (exact):
//! - **Island**: a chart of [`crate::uvstats::uv_charts`]; its **unknowns** are those of
//!   [`crate::refine`] (coordinate indices, merged where one mesh vertex has one UV value), further
//!   told apart by mesh vertex, and by fan: an unknown whose faces are not all joined across edges
//!   at it that exactly two faces use in opposite directions gets one unknown per fan, so bowties,
//!   edges of three or more faces and faces wound against their neighbours become boundary. A face
//!   of a valid mesh has two corners on one unknown only when it repeats a vertex (a
//!   **collapsed** face: zero UV area, UV-degenerate, ignored below).
//! - **Rest shape** of a face: its isometric 2-D copy ([`crate::refine`]'s frame) with weight its
//!   area; a face degenerate in 3-D ([`crate::uvstats`]) gets an equilateral triangle with the
//!   island's mean edge length and [`DEGENERATE_WEIGHT`] times that triangle's area as weight, so
//!   that it stays a well-shaped, positively oriented triangle in UV (where it is measured by
//!   nothing) instead of a sliver that rounding to `f32` could flip.
//! - **Disc**: no directed edge used twice, every boundary vertex (an end of an edge used by one
//!   face) starts exactly one boundary edge, one boundary loop, and `V − E + F = 1`.
//! - **Injective check** (on `f64` working positions): every face has positive signed area; the
//!   angles of the faces round every interior vertex sum to 2π (not 4π: a vertex whose fan wraps
//!   twice; counted exactly as the fan's winding, `wedge_crossing`), and those round a boundary
//!   point (every unknown at that position) to at most 2π
//!   (plus [`BOUNDARY_TURN_SLACK`]); no two boundary segments that share no endpoint cross
//!   properly (touching, as the two sides of a closed slit do, covers no area twice and is
//!   allowed); and exactly one boundary loop is counter-clockwise with more than a
//!   [`LOOP_AREA_REL`] share of the island's area (the outer one). For such a map every point of
//!   the plane is covered at most once.
//! - **Orientation and place**: every island comes out counter-clockwise (a mirrored island of the
//!   input is mirrored back to a true image of its surface, so no output face is flipped against
//!   any majority), scaled to the island's input texel density (`sqrt(uv area / 3-D area)`;
//!   parts keep their island's), centred on the input island's UV centroid, or with `split` on
//!   the origin (`Placement`: f32 then keeps an island's shape to a rounding of its own extent).
//!   Parts of one island, and with `split` all islands, lie on top of each other: a packing step
//!   ([`crate::islands`]) must follow, as `split` says. Every part is an island of its own in
//!   the output, read by UVs as the later steps read them: a part that would join another
//!   along a shared edge (congruent faces mapped alike) is moved beside it (`unstacked`).
//!
//! Islands are read and checked in parallel, then solved in parallel dearest first
//! (`dearest_first`, `Prepared::class`); inside an island, the per-face work of SLIM (its
//! weights and rotations, energies, injectivity angles, step bounds, the system's slots) runs in
//! parallel too, in tasks of at least [`FACES_PER_TASK`] faces, each face's value computed alone
//! and every sum, minimum and assembly then taken sequentially in face order, as before. So the
//! result does not depend on the thread count, and is the same bits as a sequential solve. The
//! sparse factorisations stay sequential (`Pattern`).

use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Mutex, OnceLock};

use foldhash::{HashMap, HashMapExt, HashSet, HashSetExt};

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::solvers::Solve;
use faer::sparse::linalg::cholesky::{
    CholeskySymbolicParams, LltRef, SymbolicCholesky, SymmetricOrdering, factorize_symbolic_cholesky,
};
use faer::sparse::linalg::{SupernodalThreshold, amd};
use faer::sparse::{SparseColMat, SymbolicSparseColMat, SymbolicSparseColMatRef, Triplet};
use faer::{Conj, Mat, Par, Side};
use nuvo_geometry::{TriMesh, UvLayer};
use rayon::prelude::*;
use serde::Serialize;

use crate::error::AtlasError;
use crate::geom::to_dvec3;
use crate::refine::{Frame, area2, centroid_of, island_unknowns, write_back};
use crate::uvstats::{degenerate_3d_faces, faces_by_edge, require_uv, uv_islands};

/// Weight of a 3-D-degenerate face's equilateral rest shape, relative to its area.
pub const DEGENERATE_WEIGHT: f64 = 1e-3;
/// Share of the first step at which a face (or scaffold triangle) collapses that a SLIM step
/// takes at most (Smith & Schaefer's flip-avoiding line search).
pub const STEP_SHARE: f64 = 0.8;
/// Times a SLIM step is halved, after the flip-avoiding bound, looking for a lower energy and an
/// injective result before the iteration stops.
pub const MAX_HALVINGS: usize = 12;

/// Singular value below which SLIM's reweighting treats a face as squeezed by this much only.
/// The weight grows as `σ^-1.5`; Tutte starts of some marching-cubes islands (a 12,000-face one
/// of an unruly homer, cut open along its tunnels in an experiment) had faces squeezed so far
/// that the weights overflowed or the system could not be factored, and SLIM never took a step
/// (8e5 per unit area left as it was; 6.3 after 60 rounds with the floor). Capped, the step is
/// no longer SLIM's exact proxy there; the line search, which takes a step only when the true
/// energy drops, keeps the iteration monotone.
pub const WEIGHT_SIGMA_FLOOR: f64 = 1e-3;

/// Share of the energy above an isometry's (`E − 4A`) that a SLIM round must remove for the
/// rounds to go on when it removes less than [`InjectiveOptions::tolerance`] of `E` itself. A
/// tolerance on `E` alone stops a nearly isometric island (a flat or developable piece) while its
/// residual is still all its distortion: woody, a flat mesh, stopped after one round at `E − 4A`
/// = 1.1e-7 per unit area, Stretch and Conformal 0.99993 where xatlas's identity map scores
/// 0.999998. On a curved island `E − 4A` is 0.01–0.5 per unit area and this stops about where
/// `tolerance` does.
pub const EXCESS_TOLERANCE: f64 = 1e-2;

/// Angle deficit (radians) within which every inner vertex of a developable patch lies: far
/// above the rounding of angles summed from `f32` positions, far below any surface's curvature
/// at a vertex.
pub const DEVELOPABLE_DEFICIT: f64 = 1e-5;

/// Rings of faces round the bad faces that `Patch::repair` tries in turn.
pub const REPAIR_RINGS: &[usize] = &[1, 2, 4, 8];
/// The scaffold's box extends this many times the boundary's larger side beyond it.
pub const SCAFFOLD_MARGIN: f64 = 0.5;
/// Rounds a scaffold triangulation serves at most before the free space is triangulated anew
/// (sooner when it limits a step). A kept scaffold's triangles grow thin as the boundary slides
/// and stiffen the global step: kept for good, SLIM ended 10–20% further above an isometry's
/// energy on Common Shapes (rocker-arm 4.0295 against 4.0245 per unit area) and the mean angular
/// score fell 0.001. Every 4 rounds: the same scores as a new triangulation every round
/// (Editability 0.9560 against 0.9558, angular 0.9538 against 0.9537), in 40% of the time
/// (BENCHMARKS.md, "SLIM's system kept between rounds").
pub const SCAFFOLD_ROUNDS: usize = 4;
/// The scaffold's total weight, as a share of the patch's.
pub const SCAFFOLD_WEIGHT: f64 = 1e-2;
/// The fewest faces one parallel task of an island's per-face work handles (module docs): an
/// island smaller than this runs each such loop on its own thread, as all did before. Why
/// parallel inside an island at all: islands are solved in parallel, but the largest one often
/// finishes alone, one core idle (the README job's `injective` phase held ~1 s at 100% CPU).
pub const FACES_PER_TASK: usize = 2048;
/// Rounding slack (radians) on the full turn that the fans at one boundary point may make: the
/// two sides of a closed slit meet at its ends, whose fans turn exactly once.
pub const BOUNDARY_TURN_SLACK: f64 = 1e-9;
/// Signed area, relative to the patch's, above which a boundary loop counts as counter-clockwise.
pub const LOOP_AREA_REL: f64 = 1e-9;
/// Symmetric Dirichlet energy per unit area above which a re-embedded patch is split in two and
/// each part solved again (with `split`): the energy of a uniform 1.5× area distortion, or of a
/// stretch by 1.25 one way and 0.8 the other, is about 4.33.
pub const SPLIT_ENERGY: f64 = 4.5;

/// Symmetric Dirichlet energy per unit area above which SLIM is taken to have failed on a disc
/// re-embedded from a Tutte start (25 times an isometry's 4: faces still squeezed about tenfold).
/// `nuvo unwrap` splits such discs on fragmented inputs, where it splits no other: of the
/// generated unruly cow's and homer's 3,000 re-embedded discs, a handful ended there (one of
/// 7,201 faces at 2.7e5 per unit area, its faces squeezed to specks), and splitting them raised
/// Editability 0.7973 -> 0.8023 and 0.7660 -> 0.7687 with 6–25 more islands; thresholds of 10,
/// 30 and 1000 gave the same within 0.0004 (BENCHMARKS.md, "Splitting the discs SLIM could not
/// flatten").
pub const FAILED_SLIM_ENERGY: f64 = 100.0;

/// [`InjectiveOptions::orthogonal`] in `nuvo unwrap`'s recipe (BENCHMARKS.md, "Texture axes kept
/// perpendicular and faces at their island's density").
pub const UNWRAP_ORTHOGONAL: f64 = 64.0;

/// [`InjectiveOptions::equiareal`] in `nuvo unwrap`'s recipe (as [`UNWRAP_ORTHOGONAL`]).
pub const UNWRAP_EQUIAREAL: f64 = 32.0;

/// How many times longer than the cut between two halves the seams of detaching a map's bad faces
/// may be before the island is halved instead (module docs, step 4). Halving a patch that is not
/// a disc seldom makes discs at once: its halves are halved again, so one halving cut stands for
/// several. Set between what was measured: ragged detachments of thin-walled charts (the unruly
/// teapot's islands of 23k–49k faces, detached into 135–422 parts: 6–680 times the halving cut,
/// mostly over 20) and those of the other generated unruly meshes (spot, the unruly bunny: 1.6–6
/// times, one island of 408 parts 29 times). The unruly vase's islands, as thin-walled, measure
/// 11–87 and are halved too, but there the halves are halved again and again (2,700 more
/// islands) and Editability drops 0.7623 -> 0.7554 where the teapot's rises 0.7646 -> 0.7980
/// (BENCHMARKS.md, "Thin walls").
pub const RAGGED_CUT: f64 = 8.0;

/// Smoothness of the labelling of a thin wall's sides (`Patch::sides`): an edge between the
/// sides costs this many mean edge lengths times its own rest length, times how little the
/// surface bends across it (`(1 + cos θ) / 2` of the angle between the faces' normals: the rim
/// where the wall turns back costs little), against each face's rest area for a label other
/// than its orientation's. On a flat surface a spot of mirrored faces is cut out as a side of
/// its own when its radius exceeds about `2 ·` this many mean edges, and relabelled otherwise.
pub const SIDE_SMOOTHING: f64 = 4.0;

/// Radius of the neighbourhood whose angle deficits make a cone point, as a share of the square
/// root of the patch's 3-D area (module docs, step 6). 0.08 gave the same mean Editability on
/// four Common Shapes meshes (0.9483 against 0.9478) with the cow's worst chart at 1.20
/// instead of 1.19 and homer's at 1.36 instead of 1.23.
pub const CONE_RADIUS: f64 = 0.05;
/// Summed angle deficit (radians) within [`CONE_RADIUS`] at which a vertex is a cone point: 30°.
/// On cow, fandisk, homer and suzanne: mean Editability 0.9478 against 0.9469 at 45° and 0.9478
/// at 20° (which cut 93 cones where 30° cut 69; BENCHMARKS.md, "Cutting discs open at their
/// cone points").
pub const CONE_DEFICIT: f64 = std::f64::consts::FRAC_PI_6;
/// Cone points cut per patch at most: the strongest. 16 cut two more on the cow and lost 0.0025
/// of its Editability.
pub const MAX_CONES: usize = 8;
/// How far towards its own fan's centre each copy of a cut vertex starts (module docs, step 6).
pub const SLIT_SHARE: f64 = 0.2;
/// How many times [`SLIT_SHARE`] is halved before cuts whose start is not injective are given up.
pub const SLIT_HALVINGS: usize = 8;
/// Share of a disc's energy above an isometry's that its cone cuts must remove to be kept. 0.1
/// kept more cuts on the cow and homer at the same mean Editability (0.9477 against 0.9478).
pub const CONE_GAIN: f64 = 0.2;
/// How much cone cuts may raise the disc's PartUV area distortion (the per-face mean that
/// `Patch::area_distortion` takes) and still be kept. The energy weighs faces by area, so a cut
/// can lower it by squeezing small faces: four faces of the beetle closing up into a thin
/// tetrahedron went from 1.65 to 2.38 that way, and are now left uncut (BENCHMARKS.md, "Half
/// batches while the warm start weighs in"). The 14 Common Shapes atlases of the suite re-bake
/// unchanged; of five fragmented ones, one cut is refused on cow_unruly (0.8514 -> 0.8513).
pub const CONE_AREA_RISE: f64 = 0.01;

/// How far a face grown back over the bad ones (`Patch::grow`) may scale its rest shape, as a
/// ratio of areas either way from the median ratio of the good faces (4: twice or half the
/// length). Unbounded, growth went wrong on a marching-cubes vase whose charts hold both sides
/// of a thin wall: a bad face whose three corners were placed on the two sides spanned the gap,
/// faces placed on its edges copied its scale, and the scale compounded face by face to 1e32,
/// leaving 52,000 of an island's 58,000 faces specks once the island was scaled to its 3-D area
/// (Stretch 0 on the vase). Measured on that vase's bake: a bound of 100 gives Stretch 0.33 and
/// Editability 0.48, 4 gives 0.79 and 0.64; on the unruly bunny 0.8268 against 0.8236
/// (BENCHMARKS.md, "Injective islands on fragmented meshes").
pub const GROW_SCALE: f64 = 4.0;

/// Options of [`make_injective`].
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct InjectiveOptions {
    /// SLIM rounds per island at most (default 60).
    pub iterations: usize,
    /// Relative energy decrease below which the rounds stop (default 1e-4). Measured on Common
    /// Shapes against 1e-3 / 30 rounds: mean Editability 0.9510 against 0.9470, the horse's
    /// bake 16 s against 10 s; 1e-5 / 150 rounds gives 0.9529 for 39 s.
    pub tolerance: f64,
    /// The rounds go on, whatever `tolerance` says, while one removes at least this share of
    /// the energy above an isometry's (`E − 4A`; default [`EXCESS_TOLERANCE`]).
    pub excess_tolerance: f64,
    /// Split islands that are neither injective nor discs (default true; the parts overlap until
    /// packed).
    pub split: bool,
    /// Symmetric Dirichlet energy per unit area above which a re-embedded island is split
    /// instead (default [`SPLIT_ENERGY`]).
    pub split_energy: f64,
    /// Cut each solved disc from its cone points to its boundary where that lowers its energy
    /// enough (module docs, step 6; default false).
    pub cut_cones: bool,
    /// Weight `λ` of the conformal term that SLIM minimises with the symmetric Dirichlet energy
    /// (module docs, step 5; default 0, SLIM on the symmetric Dirichlet energy alone).
    pub conformal: f64,
    /// Weight of the texture axes' shear term, `cos²` of the angle between `∂p/∂u` and
    /// `∂p/∂v` on the surface (module docs, step 5; default 0).
    pub orthogonal: f64,
    /// Weight of the area term, `(det J − 1)²` (module docs, step 5; default 0).
    pub equiareal: f64,
}

impl InjectiveOptions {
    /// The weights of the terms SLIM lowers beside the symmetric Dirichlet energy.
    fn terms(&self) -> Terms {
        Terms { conformal: self.conformal, orthogonal: self.orthogonal, equiareal: self.equiareal }
    }
}

impl Default for InjectiveOptions {
    fn default() -> Self {
        InjectiveOptions {
            iterations: 60,
            tolerance: 1e-4,
            excess_tolerance: EXCESS_TOLERANCE,
            split: true,
            split_energy: SPLIT_ENERGY,
            cut_cones: false,
            conformal: 0.0,
            orthogonal: 0.0,
            equiareal: 0.0,
        }
    }
}

/// What [`make_injective`] did.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct InjectiveReport {
    /// UV-connected islands of the input.
    pub islands_before: usize,
    /// Islands of the output (parts of split islands counted one by one).
    pub islands_after: usize,
    /// Input islands whose map was not injective.
    pub not_injective_before: usize,
    /// Output islands whose map is not injective (only possible without `split`).
    pub not_injective_after: usize,
    /// Islands (or parts) whose folds were mended in place (`Patch::repair`).
    pub repaired: usize,
    /// Islands (or parts) restarted from a Tutte embedding.
    pub reembedded: usize,
    /// Input islands split into parts.
    pub split: usize,
    /// Input islands split between the two sides of a thin wall ([`SIDE_SMOOTHING`], module
    /// docs step 4): some of their parts come from that minimum cut.
    pub sided: usize,
    /// Input islands that are not topological discs.
    pub not_disc: usize,
    /// Symmetric Dirichlet energy per unit 3-D area over all faces with a 3-D area, before and
    /// after (4 for an isometry; before: only over the islands that were injective, the energy of
    /// a flipped face being infinite).
    pub energy_before: f64,
    /// The same after.
    pub energy_after: f64,
    /// SLIM rounds run, over all islands.
    pub rounds: usize,
    /// Cone points cut open to their island's boundary (`cut_cones`).
    pub cones: usize,
    /// Islands (or parts) cut open at their cone points.
    pub coned_islands: usize,
}

/// The injective mesh and what was done to it.
#[derive(Clone, Debug, PartialEq)]
pub struct Injective {
    /// The input mesh with new texture coordinates (same positions, triangles and face order).
    pub mesh: TriMesh,
    /// The summary.
    pub report: InjectiveReport,
}

/// Makes every island of `mesh`'s UV layout injective and lowers its distortion (module docs).
/// Errors: no UVs, an invalid mesh.
pub fn make_injective(mesh: &TriMesh, opts: &InjectiveOptions) -> Result<Injective, AtlasError> {
    make_injective_where(mesh, opts, |_| true)
}

/// [`make_injective`] on the islands whose faces (ascending, as [`uv_islands`] lists them)
/// `solve` accepts; every other island keeps its UVs bit for bit and counts in the report only
/// as an island before and after (not in the energies, flips or rounds). Why: after
/// [`crate::necks`] cuts a few islands, only their parts need relaxing. Solving every island
/// again gave the ones no cut touched one more SLIM round each (they had stopped at the
/// tolerance), a symbolic factorisation or two per island: measured on the 14 Common Shapes
/// re-bakes, leaving them out moved Editability by −0.0005 to +0.0012 (mean +0.00004) and cut
/// the necks pass by 0.2–1.4 s (BENCHMARKS.md).
pub fn make_injective_where(
    mesh: &TriMesh,
    opts: &InjectiveOptions,
    solve: impl Fn(&[u32]) -> bool + Sync,
) -> Result<Injective, AtlasError> {
    let uv = require_uv(mesh)?;
    let members = uv_islands(mesh, uv);
    let count = members.len();
    let degenerate = degenerate_3d_faces(mesh);
    let ctx = Ctx { mesh, uv, degenerate: &degenerate, opts };
    // Every island read and checked first, in parallel, so that the dearest go first (below).
    let prepared: Vec<(&[u32], Option<Prepared>)> = members
        .par_iter()
        .map(|faces| (faces.as_slice(), solve(faces).then(|| ctx.prepare(faces))))
        .collect();
    let results = dearest_first(
        prepared,
        |(faces, p)| (p.as_ref().map_or(0, Prepared::class), faces.len()),
        |(faces, p)| match p {
            Some(p) => ctx.island(p),
            None => IslandResult::kept(faces),
        },
    );

    let mut report = InjectiveReport { islands_before: count, ..Default::default() };
    let (mut parts_faces, mut parts_corners) = (Vec::new(), Vec::new());
    let (mut e_before, mut a_before, mut e_after, mut a_after) = (0.0, 0.0, 0.0, 0.0);
    for r in &results {
        report.not_injective_before += usize::from(!r.injective_before);
        report.not_disc += usize::from(!r.disc);
        report.split += usize::from(r.parts.len() > 1);
        report.sided += usize::from(r.parts.iter().any(|p| p.sided));
        if let Some((e, a)) = r.energy_before {
            (e_before, a_before) = (e_before + e, a_before + a);
        }
        for p in &r.parts {
            report.reembedded += usize::from(p.start == Start::Tutte);
            report.repaired += usize::from(p.start == Start::Repaired);
            report.not_injective_after += usize::from(!p.injective);
            report.rounds += p.rounds;
            report.cones += p.cones;
            report.coned_islands += usize::from(p.cones > 0);
            e_after += p.energy.0;
            a_after += p.energy.1;
            parts_faces.push(p.faces.clone());
            parts_corners.push(p.corners.clone());
        }
    }
    report.islands_after = parts_faces.len();
    report.energy_before = if a_before > 0.0 { e_before / a_before } else { 0.0 };
    report.energy_after = if a_after > 0.0 { e_after / a_after } else { 0.0 };
    let layer = unstacked(mesh, uv, &parts_faces, &mut parts_corners);
    let out = TriMesh { uv: Some(layer), ..mesh.clone() };
    Ok(Injective { mesh: out, report })
}

/// The output layer of the parts (`faces`, and `corners` when solved: `None` keeps the input
/// UVs), with every part an island of its own ([`uv_charts`](crate::uvstats::uv_charts)).
/// Why: the solved parts lie on top of each other (module docs, "Orientation and place"), and
/// two of them that share a mesh edge come out with equal UVs at both its ends when their faces
/// are congruent and mapped alike: the two back-to-back pairs of faces a marching-cubes mesh
/// makes where a wall pinches to one edge (the unruly vase's density grid; 4 overlapping faces
/// after packing). Read by UVs, as every later step reads islands, the two were one island
/// folded onto itself. A part that shares an island with an earlier one is moved along `u` by
/// the sum of its extents, beside where it lay (or, when it keeps its input UVs, the earlier
/// part is), until no two parts share an island. A part whose UVs are one point covers nothing
/// and is not moved. Parts that lie apart, nearly always all of them, cost one charting.
fn unstacked(
    mesh: &TriMesh,
    uv: &UvLayer,
    faces: &[Vec<u32>],
    corners: &mut [Option<Vec<[f32; 2]>>],
) -> UvLayer {
    let layer_of = |corners: &[Option<Vec<[f32; 2]>>]| {
        let refs: Vec<Option<&[[f32; 2]]>> = corners.iter().map(|c| c.as_deref()).collect();
        let (coords, triangles, _) = write_back(uv, faces, &refs);
        UvLayer { coords, triangles }
    };
    // Each round moves a part of every shared island, so a round per part is enough.
    for _ in 0..faces.len() {
        let layer = layer_of(corners);
        let (chart, count) = crate::uvstats::uv_charts(mesh, &layer);
        let mut owner = vec![usize::MAX; count];
        let mut moving = vec![false; faces.len()];
        for (p, part) in faces.iter().enumerate() {
            for &f in part {
                let o = &mut owner[chart[f as usize] as usize];
                if *o == usize::MAX {
                    *o = p;
                } else if *o != p {
                    let q = if corners[p].is_some() { p } else { *o };
                    moving[q] = true;
                }
            }
        }
        let mut moved = false;
        for (c, _) in corners.iter_mut().zip(&moving).filter(|(_, m)| **m) {
            let Some(c) = c.as_mut() else { continue };
            let extent = |k: usize| {
                let (lo, hi) = c
                    .iter()
                    .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), q| (lo.min(q[k]), hi.max(q[k])));
                hi - lo
            };
            let shift = extent(0) + extent(1);
            if shift > 0.0 && shift.is_finite() {
                c.iter_mut().for_each(|q| q[0] += shift);
                moved = true;
            }
        }
        if !moved {
            return layer;
        }
    }
    layer_of(corners)
}

/// `work` of every item, in the items' order, computed in parallel with the items taken by
/// decreasing `cost` (ties in order) from one queue by as many workers as the pool has threads.
/// Why: a parallel map over the list splits it in halves, so the dearest island was often
/// started last and solved alone, one core idle (the README bunny's `injective` phase: one
/// thread idle 1.3 s of 3.1 s); dearest first, the cheap islands fill the gaps at the end. Each
/// result depends on its item alone, so the order of work changes no bit of the output.
fn dearest_first<T: Send, K: Ord, R: Send + Sync>(
    items: Vec<T>,
    cost: impl Fn(&T) -> K,
    work: impl Fn(T) -> R + Sync,
) -> Vec<R> {
    let mut queue: Vec<usize> = (0..items.len()).collect();
    // Stable: equal costs keep their order.
    queue.sort_by_key(|&i| std::cmp::Reverse(cost(&items[i])));
    let cells: Vec<Mutex<Option<T>>> = items.into_iter().map(|t| Mutex::new(Some(t))).collect();
    let next = AtomicUsize::new(0);
    let done: Vec<OnceLock<R>> = cells.iter().map(|_| OnceLock::new()).collect();
    let workers = rayon::current_num_threads().min(cells.len());
    (0..workers).into_par_iter().with_max_len(1).for_each(|_| {
        while let Some(&i) = queue.get(next.fetch_add(1, Ordering::Relaxed)) {
            // Each index is taken once, so each item is taken and each cell set once.
            let item = cells[i].lock().unwrap_or_else(|e| e.into_inner()).take().expect("taken once");
            let _ = done[i].set(work(item));
        }
    });
    done.into_iter().map(|cell| cell.into_inner().expect("every item is taken")).collect()
}

/// The inputs every island reads.
struct Ctx<'a> {
    mesh: &'a TriMesh,
    uv: &'a UvLayer,
    degenerate: &'a [bool],
    opts: &'a InjectiveOptions,
}

/// One input island's outcome.
struct IslandResult {
    injective_before: bool,
    disc: bool,
    /// `(Σ energy, Σ 3-D area)` of the input map, when it was injective.
    energy_before: Option<(f64, f64)>,
    parts: Vec<PartResult>,
}

impl IslandResult {
    /// An island passed through untouched ([`make_injective_where`]): one part, its own UVs, no
    /// energy counted.
    fn kept(faces: &[u32]) -> IslandResult {
        let part = PartResult {
            faces: faces.to_vec(),
            corners: None,
            start: Start::Input,
            injective: true,
            rounds: 0,
            cones: 0,
            energy: (0.0, 0.0),
            sided: false,
        };
        IslandResult { injective_before: true, disc: true, energy_before: None, parts: vec![part] }
    }
}

/// Where an output island's map started.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Start {
    /// The input map (injective), or nothing changed.
    Input,
    /// The input map with its folds mended in place.
    Repaired,
    /// Embedded anew: the least-squares conformal map where it is injective, else Tutte's.
    Tutte,
}

/// One output island: its faces and, when its UVs changed, the new UV of each corner (face-major).
struct PartResult {
    faces: Vec<u32>,
    corners: Option<Vec<[f32; 2]>>,
    start: Start,
    injective: bool,
    rounds: usize,
    /// Cone points cut open (`cut_cones`).
    cones: usize,
    /// `(Σ energy, Σ 3-D area)` of the output map over faces with a 3-D area.
    energy: (f64, f64),
    /// Whether the part comes from a split between a thin wall's sides (`Ctx::split_sides`).
    sided: bool,
}

/// An island read and checked, not yet solved: what [`Ctx::island`] starts from, and what
/// tells the dear islands from the cheap ones before any is solved.
struct Prepared {
    patch: Patch,
    placement: Placement,
    /// Its input map, where it has one.
    start: Option<Vec<[f64; 2]>>,
    injective_before: bool,
    energy_before: Option<(f64, f64)>,
}

impl Prepared {
    /// How dear the island is to solve, by what it will take (the module's steps), highest
    /// first: 3 cut open and embedded anew (not injective, not a disc), 2 embedded anew or
    /// mended (not injective), 1 relaxed from its own map (injective). Within a class the
    /// faces rank (`dearest_first`'s key). Why: a re-embedding's SLIM starts far from its
    /// optimum and takes 3–20 times the rounds of a relaxation (the Common Shapes bunny: a
    /// 10k-face island cut open took 98 rounds and 0.71 s, a 12k-face injective one 5 rounds
    /// and 0.07 s), so faces alone started the dearest island third and it ran alone at the end.
    fn class(&self) -> u8 {
        match (self.injective_before, self.patch.topology.disc) {
            (true, _) => 1,
            (false, true) => 2,
            (false, false) => 3,
        }
    }
}

impl Ctx<'_> {
    fn prepare(&self, faces: &[u32]) -> Prepared {
        let patch = Patch::new(self, faces);
        let placement = Placement::of(self, faces, &patch);
        let start = patch.current(self);
        let injective_before = start.as_ref().is_some_and(|p| patch.is_injective(p));
        let energy_before = if injective_before {
            start.as_ref().and_then(|p| patch.energy(p)).map(|e| (e, patch.area3))
        } else {
            None
        };
        Prepared { patch, placement, start, injective_before, energy_before }
    }

    fn island(&self, prepared: Prepared) -> IslandResult {
        let Prepared { patch, placement, start, injective_before, energy_before } = prepared;
        let disc = patch.topology.disc;
        let mut parts = Vec::new();
        self.solve(patch, start, &placement, &mut parts);
        IslandResult { injective_before, disc, energy_before, parts }
    }

    /// Steps 1–3 of the module docs for one patch, pushing its output parts.
    fn solve(
        &self,
        patch: Patch,
        current: Option<Vec<[f64; 2]>>,
        placement: &Placement,
        out: &mut Vec<PartResult>,
    ) {
        // A part detached from its island because the map mirrors it (the far side of a thin
        // wall that one chart maps from both sides) is a mirror image of a map that may be
        // good: mirrored back, it can be kept or mended instead of cut up and embedded anew.
        let current = current.map(|p| patch.facing(p));
        if patch.live().next().is_none() {
            // Only collapsed faces: zero UV area whatever their UVs, nothing to solve.
            let energy = (0.0, patch.area3);
            out.push(PartResult {
                faces: patch.faces,
                corners: None,
                start: Start::Input,
                injective: true,
                rounds: 0,
                cones: 0,
                energy,
                sided: false,
            });
            return;
        }
        if let Some(p) = &current {
            if patch.is_injective(p) {
                // A developable disc's conformal map is an isometry, the optimum that SLIM from
                // the map given only creeps towards (woody, flat: 0.99999 of Stretch and
                // Conformal after 60 rounds).
                let start = match patch.is_developable_disc().then(|| patch.lscm()).flatten() {
                    Some(q) if patch.is_injective(&q) => q,
                    _ => p.clone(),
                };
                return self.finish(patch, start, Start::Input, out, placement);
            }
            if let Some(q) = patch.repair(p) {
                return self.finish(patch, q, Start::Repaired, out, placement);
            }
        }
        // Re-embed as a disc; kept when its distortion is low, or when nothing else may be done.
        let mut disc = patch.clone();
        disc.cut_to_disc();
        let may_split = self.opts.split && patch.live().count() > 1;
        if disc.topology.disc
            && let Some(start) = disc.lscm().filter(|p| disc.is_injective(p)).or_else(|| disc.tutte())
        {
            let (q, rounds) = disc.slim(start, self.opts);
            let density = disc.energy(&q).map_or(f64::INFINITY, |e| e / disc.area3.max(f64::MIN_POSITIVE));
            if !may_split || density <= self.opts.split_energy {
                return self.push(disc, q, Start::Tutte, rounds, out, placement);
            }
        }
        if !may_split {
            let energy = (f64::INFINITY, patch.area3);
            out.push(PartResult {
                faces: patch.faces,
                corners: None,
                start: Start::Input,
                injective: false,
                rounds: 0,
                cones: 0,
                energy,
                sided: false,
            });
            return;
        }
        if let Some(p) = &current
            && self.detach(&patch, p, placement, out)
        {
            return;
        }
        let parts = patch.consistent_parts();
        let parts = if parts.len() > 1 { parts } else { patch.cut_in_two(self) };
        self.solve_parts(&patch, parts, current.as_deref(), placement, out);
    }

    /// SLIM from the injective `p`, then [`Ctx::push`].
    fn finish(
        &self,
        patch: Patch,
        p: Vec<[f64; 2]>,
        start: Start,
        out: &mut Vec<PartResult>,
        placement: &Placement,
    ) {
        let (q, rounds) = patch.slim(p, self.opts);
        self.push(patch, q, start, rounds, out, placement);
    }

    /// Records the solved patch `patch` at positions `p`.
    fn push(
        &self,
        patch: Patch,
        p: Vec<[f64; 2]>,
        start: Start,
        rounds: usize,
        out: &mut Vec<PartResult>,
        placement: &Placement,
    ) {
        let (patch, p, rounds, cones) = match self.opts.cut_cones.then(|| patch.cut_cones(&p, self.opts)) {
            Some(Some(c)) => (c.patch, c.p, rounds + c.rounds, c.cones),
            _ => (patch, p, rounds, 0),
        };
        let injective = patch.is_injective(&p);
        let energy = (patch.energy(&p).unwrap_or(f64::INFINITY), patch.area3);
        let corners = placement.place(&patch, &p);
        out.push(PartResult {
            faces: patch.faces,
            corners,
            start,
            injective,
            rounds,
            cones,
            energy,
            sided: false,
        });
    }
}

/// A patch cut open at its cone points and solved again ([`Patch::cut_cones`]).
struct Coned {
    patch: Patch,
    p: Vec<[f64; 2]>,
    rounds: usize,
    cones: usize,
}

impl Ctx<'_> {
    /// Detaches the faces that make `patch`'s map at `p` not injective: faces of non-positive
    /// area and positive faces overlapping another positive face (module docs). The rest keeps
    /// its map; the good and the bad faces each form parts of connected faces, solved anew.
    /// A ragged detachment (module docs, step 4: [`RAGGED_CUT`]) is not made: the patch is split
    /// between a thin wall's sides instead ([`Ctx::split_sides`]). Returns false (and does
    /// nothing) when no face or every face is bad, or when the detachment is ragged and the
    /// sides' split is not made either.
    fn detach(
        &self,
        patch: &Patch,
        p: &[[f64; 2]],
        placement: &Placement,
        out: &mut Vec<PartResult>,
    ) -> bool {
        let bad = patch.bad_faces(p);
        let count = bad.iter().filter(|&&b| b).count();
        let live = patch.live().count();
        if count == 0 || count >= live {
            return false;
        }
        let (bad, q) = patch.grow(&bad, p);
        let parts = patch.components(&bad);
        // Where the map's bad faces are ragged (a thin wall whose far side one chart maps
        // mirrored, its flips interleaved with the near side's), detaching them cuts the island
        // into many small parts whose seams the renders see everywhere; parting the wall's two
        // sides (or, failing that, two halves: the caller) costs one cut.
        if patch.is_ragged(&parts) {
            return self.split_sides(patch, p, placement, out);
        }
        self.solve_parts(patch, parts, Some(&q), placement, out);
        true
    }

    /// Splits `patch` between the sides of the thin wall that its map `p` holds both of
    /// ([`Patch::sides`]), each part solved again from `p` (a mirrored side mirrored back);
    /// returns false (and does nothing) when the labelling finds one side only or a ragged
    /// split.
    fn split_sides(
        &self,
        patch: &Patch,
        p: &[[f64; 2]],
        placement: &Placement,
        out: &mut Vec<PartResult>,
    ) -> bool {
        let sides = patch.sides(self, p);
        // One side only: the flips were spots of noise, and a patch of several pieces (joined
        // through vertices alone) is left to the pieces of consistent winding.
        if !(sides.contains(&true) && sides.contains(&false)) {
            return false;
        }
        let parts = patch.components(&sides);
        if patch.is_ragged(&parts) {
            return false;
        }
        let first = out.len();
        self.solve_parts(patch, parts, Some(p), placement, out);
        out[first..].iter_mut().for_each(|r| r.sided = true);
        true
    }

    /// Solves each of `parts` (faces of `patch`, covering it) again, from its share of `patch`'s
    /// map `p` when there is one.
    fn solve_parts(
        &self,
        patch: &Patch,
        parts: Vec<Vec<u32>>,
        p: Option<&[[f64; 2]]>,
        placement: &Placement,
        out: &mut Vec<PartResult>,
    ) {
        for part in parts {
            let sub = Patch::new(self, &part);
            let current = p.map(|p| sub.inherit(patch, p));
            self.solve(sub, current, placement, out);
        }
    }
}

/// Where an island's output goes: its input texel density, centroid and orientation.
///
/// With [`InjectiveOptions::split`] the islands are packed afterwards and may lie on each other
/// until then, so each is centred on the origin instead of its input centroid: `f32` then
/// rounds its corners to a share of its own extent. At its input centroid (near the middle of
/// the networks' chart squares, the island a fraction of a square) the rounding is a share of
/// the whole atlas, a shear the packer magnifies as it scales the island up: woody, a flat
/// figure of 1,267 faces mapped by one similarity in exact arithmetic, kept median |cos(T, B)|
/// 3.2e-6 over its faces after packing, where its exact similarity rounded once gives 5.9e-7.
struct Placement {
    /// UV length per 3-D length.
    density: f64,
    centre: [f64; 2],
}

impl Placement {
    fn of(ctx: &Ctx, faces: &[u32], patch: &Patch) -> Placement {
        let tris: Vec<[[f64; 2]; 3]> = faces
            .iter()
            .map(|&f| ctx.uv.triangles[f as usize].map(|i| ctx.uv.coords[i as usize].map(|x| x as f64)))
            .collect();
        let auv: f64 = tris.iter().map(|&t| 0.5 * area2(t).abs()).sum();
        let density = if auv > 0.0 && patch.area3 > 0.0 { (auv / patch.area3).sqrt() } else { 1.0 };
        let centre = if ctx.opts.split { [0.0, 0.0] } else { centroid_of(&tris) };
        Placement { density, centre }
    }

    /// The patch's corners at working positions `p`, scaled and centred (module docs), in `f32`;
    /// `None` when not finite.
    fn place(&self, patch: &Patch, p: &[[f64; 2]]) -> Option<Vec<[f32; 2]>> {
        let tris: Vec<[[f64; 2]; 3]> = patch.corners.iter().map(|t| t.map(|i| p[i as usize])).collect();
        let c = centroid_of(&tris);
        let s = self.density;
        let out: Vec<[f32; 2]> = tris
            .iter()
            .flatten()
            .map(|q| {
                [(self.centre[0] + s * (q[0] - c[0])) as f32, (self.centre[1] + s * (q[1] - c[1])) as f32]
            })
            .collect();
        out.iter().flatten().all(|x| x.is_finite()).then_some(out)
    }
}

/// A face's rest shape: the gradient operator of its map (`J = Σ_k q_k ⊗ g_k`) and its weight.
#[derive(Clone, Copy)]
struct Rest {
    /// Per corner, the gradient of its hat function in the rest frame.
    g: [[f64; 2]; 3],
    /// Weight (rest area, or the degenerate fraction of it).
    weight: f64,
    /// Rest corner positions (for the mean-value weights and boundary lengths).
    x: [[f64; 2]; 3],
    /// Whether the face has a true 3-D area (counted in the energy report).
    real: bool,
}

impl Rest {
    fn new(x: [[f64; 2]; 3], weight: f64, real: bool) -> Rest {
        let d1 = [x[1][0] - x[0][0], x[1][1] - x[0][1]];
        let d2 = [x[2][0] - x[0][0], x[2][1] - x[0][1]];
        let det = d1[0] * d2[1] - d1[1] * d2[0];
        // X = [d1 d2] (columns); rows of X⁻¹ are the gradients of corners 1 and 2.
        let g1 = [d2[1] / det, -d2[0] / det];
        let g2 = [-d1[1] / det, d1[0] / det];
        let g0 = [-g1[0] - g2[0], -g1[1] - g2[1]];
        Rest { g: [g0, g1, g2], weight, x, real }
    }

    /// The terms SLIM lowers on this face besides the symmetric Dirichlet energy: `terms` for a
    /// face with a 3-D area, none for a degenerate face's stand-in and a scaffold triangle (which
    /// only keep shape).
    fn terms(&self, terms: Terms) -> Terms {
        if self.real { terms } else { Terms::default() }
    }

    /// The Jacobian `[[∂u/∂x, ∂u/∂y], [∂v/∂x, ∂v/∂y]]` of the map to UV triangle `q`.
    fn jacobian(&self, q: [[f64; 2]; 3]) -> [[f64; 2]; 2] {
        let mut j = [[0.0; 2]; 2];
        for (qk, gk) in q.iter().zip(&self.g) {
            for r in 0..2 {
                for c in 0..2 {
                    j[r][c] += qk[r] * gk[c];
                }
            }
        }
        j
    }
}

/// Solves `K x = rhs` in place for the symmetric positive definite `dim × dim` matrix `K` whose
/// lower triangle `triplets` give (duplicates summed), by sparse Cholesky; `None` when a value
/// is not finite or `K` cannot be factored.
fn solve_lower(dim: usize, triplets: &[Triplet<usize, usize, f64>], rhs: &mut Mat<f64>) -> Option<()> {
    if triplets.iter().any(|t| !t.val.is_finite()) {
        return None;
    }
    let k = SparseColMat::<usize, f64>::try_new_from_triplets(dim, dim, triplets).ok()?;
    let llt = k.sp_cholesky(Side::Lower).ok()?;
    llt.solve_in_place(rhs.as_mut());
    Some(())
}

/// Whether a SLIM round that lowered the energy by `decrease` from `energy` (an isometry's being
/// `isometric`) ends the rounds: it removed less than [`InjectiveOptions::tolerance`] of the
/// energy and less than [`InjectiveOptions::excess_tolerance`] of the excess over an isometry's.
fn converged(decrease: f64, energy: f64, isometric: f64, opts: &InjectiveOptions) -> bool {
    let excess = (energy - isometric).max(0.0);
    decrease <= (opts.tolerance * energy).min(opts.excess_tolerance * excess)
}

/// A key equal for two positions exactly when they are the same point: `+ 0.0` makes −0.0 the
/// same key as 0.0, as the triangulation compares them.
fn point_key(p: [f64; 2]) -> (u64, u64) {
    ((p[0] + 0.0).to_bits(), (p[1] + 0.0).to_bits())
}

/// The signed angle of triangle `q` at corner `k`, from the edge to corner `k + 1` to the edge to
/// corner `k + 2` (positive in a counter-clockwise triangle).
fn corner_angle(q: [[f64; 2]; 3], k: usize) -> f64 {
    let (o, a, b) = (q[k], q[(k + 1) % 3], q[(k + 2) % 3]);
    let (u, v) = ([a[0] - o[0], a[1] - o[1]], [b[0] - o[0], b[1] - o[1]]);
    (u[0] * v[1] - u[1] * v[0]).atan2(u[0] * v[0] + u[1] * v[1])
}

/// How the wedge of triangle `q` at corner `k` (from the edge to corner `k + 1` to the edge to
/// corner `k + 2`) crosses the ray from the corner towards `+x`: `1` counter-clockwise, `−1`
/// clockwise, `0` not (Sunday's crossing rule on the fan's outer polygon). Summed over the
/// wedges of a closed fan it is the fan's winding number round its centre, exactly: two fans
/// that share an edge compute its vector from the same two points, so each crossing is
/// counted once. For a fan of positive triangles it equals the sum of their angles at the
/// centre over 2π, which [`corner_angle`] finds with three `atan2` a face.
fn wedge_crossing(q: [[f64; 2]; 3], k: usize) -> i8 {
    let (o, a, b) = (q[k], q[(k + 1) % 3], q[(k + 2) % 3]);
    let (u, w) = ([a[0] - o[0], a[1] - o[1]], [b[0] - o[0], b[1] - o[1]]);
    let turn = u[0] * w[1] - u[1] * w[0];
    if u[1] <= 0.0 && w[1] > 0.0 && turn > 0.0 {
        1
    } else if w[1] <= 0.0 && u[1] > 0.0 && turn < 0.0 {
        -1
    } else {
        0
    }
}

/// `f` of every face index `0..faces`, in order, computed in parallel tasks of at least
/// [`FACES_PER_TASK`] faces (module docs: the caller folds the values in order).
fn per_face<T: Send>(faces: usize, f: impl Fn(usize) -> T + Sync + Send) -> Vec<T> {
    (0..faces).into_par_iter().with_min_len(FACES_PER_TASK).map(f).collect()
}

/// `x > 0`, false for NaN: the test every area and determinant must pass.
fn is_positive(x: f64) -> bool {
    x > 0.0
}

/// The symmetric Dirichlet energy density `‖J‖² + ‖J⁻¹‖²` (infinite unless `det J > 0`).
fn sym_dirichlet(j: [[f64; 2]; 2]) -> f64 {
    slim_density(j, Terms::default())
}

/// The weights of the terms SLIM lowers beside the symmetric Dirichlet energy, per unit of rest
/// area ([`slim_density`]); all 0 (the default): the symmetric Dirichlet energy alone.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct Terms {
    /// [`InjectiveOptions::conformal`].
    conformal: f64,
    /// [`InjectiveOptions::orthogonal`].
    orthogonal: f64,
    /// [`InjectiveOptions::equiareal`].
    equiareal: f64,
}

/// The density SLIM minimises on a face with a 3-D area: the symmetric Dirichlet energy
/// `‖J‖² + ‖J⁻¹‖² = ‖J‖² + ‖J‖²/det²`, plus `terms.conformal` times the conformal (MIPS) excess
/// `σ₁/σ₂ + σ₂/σ₁ − 2 = ‖J‖²/det J − 2` (0 for a similarity), plus `terms.orthogonal` times
/// [`axes_cos`]`²` (0 when the texture axes are perpendicular on the surface), plus
/// `terms.equiareal` times `(det J − 1)²` (0 when the face keeps its area); infinite unless
/// `det J > 0`. 4 for an isometry whatever the weights, so every threshold stated against an
/// isometry's energy keeps its meaning.
fn slim_density(j: [[f64; 2]; 2], terms: Terms) -> f64 {
    let det = j[0][0] * j[1][1] - j[0][1] * j[1][0];
    if !is_positive(det) {
        return f64::INFINITY;
    }
    let f = j[0][0] * j[0][0] + j[0][1] * j[0][1] + j[1][0] * j[1][0] + j[1][1] * j[1][1];
    let mut e = f + f / (det * det);
    if terms.conformal != 0.0 {
        e += terms.conformal * (f / det - 2.0).max(0.0);
    }
    if terms.orthogonal != 0.0 {
        e += terms.orthogonal * axes_cos_squared(j);
    }
    if terms.equiareal != 0.0 {
        e += terms.equiareal * (det - 1.0).powi(2);
    }
    e
}

/// `cos` of the angle between the rows of `J`, `∇u · ∇v / (|∇u| |∇v|)`, and its gradient in
/// `J`. The rows are the gradients of `u` and `v` on the face, and each texture axis (`∂p/∂u`,
/// `∂p/∂v`: the columns of `J⁻¹`) is perpendicular to one of them, so the axes make the same
/// angle up to its sign: `|cos|` is what PartUV's angular score and the paper's Conformal
/// metric measure. The gradient is perpendicular to `J` (`cos` does not change as a row is
/// scaled). The rows must not be zero (they are not when `det J > 0`).
fn axes_cos(j: [[f64; 2]; 2]) -> (f64, [[f64; 2]; 2]) {
    let [a, b] = j;
    // Not `hypot`: its care against overflow costs several times a square root, and a
    // Jacobian's rows are nowhere near `f64`'s range (SLIM floors their singular values).
    let (na, nb) = ((a[0] * a[0] + a[1] * a[1]).sqrt(), (b[0] * b[0] + b[1] * b[1]).sqrt());
    let c = (a[0] * b[0] + a[1] * b[1]) / (na * nb);
    let d = |r: [f64; 2], o: [f64; 2], nr: f64| [0, 1].map(|k| o[k] / (na * nb) - c * r[k] / (nr * nr));
    (c, [d(a, b, na), d(b, a, nb)])
}

/// [`axes_cos`]`²` without a square root: `(∇u · ∇v)² / (|∇u|² |∇v|²)`. What the energy reads
/// on every face at every step of the line search.
fn axes_cos_squared(j: [[f64; 2]; 2]) -> f64 {
    let [a, b] = j;
    let dot = a[0] * b[0] + a[1] * b[1];
    dot * dot / ((a[0] * a[0] + a[1] * a[1]) * (b[0] * b[0] + b[1] * b[1]))
}

/// The signed SVD of a 2×2 matrix, `J = rot(φ) diag(s1, s2) rot(θ)` (`s1 ≥ |s2|`, `s2 < 0`
/// iff `det J < 0`), with the rotations as unit vectors instead of angles: `(cos, sin)` of
/// `φ + θ` is `sum` and of `φ − θ` is `difference`. Why: SLIM's terms need only these (and
/// `2φ`, their sum), and the two `atan2`, two `hypot` and three `sin_cos` that the angles took
/// were a tenth of the `injective` phase's time. Where a part is zero (`s1 = ±s2`) its unit
/// vector is `(1, 0)`: any is a valid SVD there.
#[derive(Clone, Copy, Debug)]
struct Svd2 {
    s1: f64,
    s2: f64,
    sum: [f64; 2],
    difference: [f64; 2],
}

impl Svd2 {
    fn of(j: [[f64; 2]; 2]) -> Svd2 {
        let [[a, b], [c, d]] = j;
        let (e, f, g, h) = ((a + d) / 2.0, (a - d) / 2.0, (c + b) / 2.0, (c - b) / 2.0);
        let (q, r) = ((e * e + h * h).sqrt(), (f * f + g * g).sqrt());
        let unit = |x: f64, y: f64, n: f64| if n > 0.0 { [x / n, y / n] } else { [1.0, 0.0] };
        Svd2 { s1: q + r, s2: q - r, sum: unit(e, h, q), difference: unit(f, g, r) }
    }

    /// `rot(φ) diag(x1, x2) rot(−φ)`: the symmetric matrix with eigenvalues `x1`, `x2` along
    /// the columns of `U = rot(φ)`.
    fn along_u(&self, x1: f64, x2: f64) -> [[f64; 2]; 2] {
        // 2φ = (φ + θ) + (φ − θ).
        let [cs, ss] = self.sum;
        let [cd, sd] = self.difference;
        let (c2, s2) = (cs * cd - ss * sd, ss * cd + cs * sd);
        let (m, h) = ((x1 + x2) / 2.0, (x1 - x2) / 2.0);
        [[m + h * c2, h * s2], [h * s2, m - h * c2]]
    }

    /// `rot(φ) diag(y1, y2) rot(θ)`: `J` with its singular values replaced.
    fn with_values(&self, y1: f64, y2: f64) -> [[f64; 2]; 2] {
        let [cs, ss] = self.sum;
        let [cd, sd] = self.difference;
        let (m, h) = ((y1 + y2) / 2.0, (y1 - y2) / 2.0);
        [[m * cs + h * cd, -m * ss + h * sd], [m * ss + h * sd, m * cs - h * cd]]
    }
}

/// The combinatorics of a patch.
#[derive(Clone, Debug, Default)]
struct Topology {
    disc: bool,
    /// Boundary loops, each a cycle of unknowns in the direction of its faces' edges; empty when
    /// the boundary is not a set of simple cycles (a boundary vertex starting two boundary edges).
    loops: Vec<Vec<u32>>,
    /// Whether the boundary could be followed (every boundary vertex starts one boundary edge and
    /// no directed edge is used twice).
    manifold: bool,
    /// Whether each unknown is on a boundary loop.
    on_boundary: Vec<bool>,
}

/// One island, or one part of it, as the solver sees it.
#[derive(Clone)]
struct Patch {
    /// Mesh faces (global ids) in island order.
    faces: Vec<u32>,
    /// Unknown of each corner of each face.
    corners: Vec<[u32; 3]>,
    /// Rest shape of each face.
    rest: Vec<Rest>,
    /// Faces with two corners on one unknown (module docs): ignored by the solver.
    collapsed: Vec<bool>,
    n: usize,
    /// Σ 3-D area of the faces with one.
    area3: f64,
    topology: Topology,
}

impl Patch {
    fn new(ctx: &Ctx, faces: &[u32]) -> Patch {
        let (merged, _) = island_unknowns(ctx.mesh, ctx.uv, faces);
        // Tell unknowns apart by mesh vertex too (module docs).
        let mut ids: HashMap<(u32, u32), u32> = HashMap::with_capacity(faces.len());
        let corners: Vec<[u32; 3]> = faces
            .iter()
            .zip(&merged)
            .map(|(&f, m)| {
                let v = ctx.mesh.triangles[f as usize];
                [0, 1, 2].map(|k| {
                    let next = ids.len() as u32;
                    *ids.entry((m[k], v[k])).or_insert(next)
                })
            })
            .collect();
        let collapsed: Vec<bool> =
            corners.iter().map(|c| c[0] == c[1] || c[1] == c[2] || c[0] == c[2]).collect();
        let (corners, n) = separate_fans(corners, &collapsed, ids.len(), &Default::default());
        let frames: Vec<Option<Frame>> = faces
            .iter()
            .map(|&f| if ctx.degenerate[f as usize] { None } else { Frame::of(ctx.mesh, f as usize) })
            .collect();
        let (mut len, mut edges) = (0.0, 0usize);
        for &f in faces {
            let p = ctx.mesh.corners(f as usize).map(to_dvec3);
            for k in 0..3 {
                let l = p[(k + 1) % 3].distance(p[k]);
                if l.is_finite() {
                    len += l;
                    edges += 1;
                }
            }
        }
        let mean = if edges > 0 && len > 0.0 { len / edges as f64 } else { 1.0 };
        let equilateral = [[0.0, 0.0], [mean, 0.0], [0.5 * mean, 0.5 * 3f64.sqrt() * mean]];
        let mut area3 = 0.0;
        let rest: Vec<Rest> = frames
            .iter()
            .map(|fr| match fr {
                Some(fr) => {
                    let a = 0.5 * area2(fr.x);
                    area3 += a;
                    Rest::new(fr.x, a, true)
                }
                None => Rest::new(equilateral, DEGENERATE_WEIGHT * 0.5 * area2(equilateral), false),
            })
            .collect();
        let mut patch = Patch {
            faces: faces.to_vec(),
            corners,
            rest,
            collapsed,
            n,
            area3,
            topology: Topology::default(),
        };
        patch.topology = patch.topology();
        patch
    }

    /// The summed weight of the live faces' rest shapes: the patch's rest area (each degenerate
    /// face counted at its [`DEGENERATE_WEIGHT`]); an isometry's energy is four times it.
    fn rest_weight(&self) -> f64 {
        self.live().map(|(t, _)| self.rest[t].weight).sum()
    }

    /// The live faces: `(index, corners)` of the faces that are not collapsed.
    fn live(&self) -> impl Iterator<Item = (usize, [u32; 3])> + Clone + '_ {
        self.corners.iter().enumerate().filter(|(t, _)| !self.collapsed[*t]).map(|(t, &c)| (t, c))
    }

    fn topology(&self) -> Topology {
        let mut directed: HashMap<(u32, u32), u32> = HashMap::with_capacity(3 * self.corners.len());
        let mut manifold = true;
        let mut faces = 0usize;
        for (_, c) in self.live() {
            faces += 1;
            for k in 0..3 {
                let e = (c[k], c[(k + 1) % 3]);
                *directed.entry(e).or_insert(0) += 1;
            }
        }
        let mut next = vec![u32::MAX; self.n];
        let mut used = vec![false; self.n];
        let mut undirected = 0usize;
        // Deterministic order: walk faces, not the map.
        for (_, c) in self.live() {
            for k in 0..3 {
                let (a, b) = (c[k], c[(k + 1) % 3]);
                used[a as usize] = true;
                if directed[&(a, b)] > 1 {
                    manifold = false;
                }
                match directed.get(&(b, a)) {
                    Some(_) => {
                        if a < b {
                            undirected += 1;
                        }
                    }
                    None => {
                        undirected += 1;
                        if next[a as usize] != u32::MAX {
                            manifold = false;
                        }
                        next[a as usize] = b;
                    }
                }
            }
        }
        let mut loops = Vec::new();
        let mut on_boundary = vec![false; self.n];
        if manifold {
            let mut seen = vec![false; self.n];
            for s in 0..self.n {
                if next[s] == u32::MAX || seen[s] {
                    continue;
                }
                let mut cycle = Vec::new();
                let mut v = s as u32;
                while !seen[v as usize] {
                    seen[v as usize] = true;
                    on_boundary[v as usize] = true;
                    cycle.push(v);
                    v = next[v as usize];
                    if v == u32::MAX {
                        manifold = false;
                        break;
                    }
                }
                if v as usize != s {
                    manifold = false;
                }
                loops.push(cycle);
            }
        }
        let vertices = used.iter().filter(|&&u| u).count() as i64;
        let euler = vertices - undirected as i64 + faces as i64;
        let disc = manifold && loops.len() == 1 && euler == 1;
        if !manifold {
            loops.clear();
        }
        Topology { disc, loops, manifold, on_boundary }
    }

    /// The island's current UVs as working positions (scaled to 3-D area, mirrored to a
    /// counter-clockwise majority), `None` when they have no area.
    fn current(&self, ctx: &Ctx) -> Option<Vec<[f64; 2]>> {
        let mut p = vec![[0.0f64; 2]; self.n];
        for (&f, c) in self.faces.iter().zip(&self.corners) {
            let t = ctx.uv.triangles[f as usize].map(|i| ctx.uv.coords[i as usize].map(|x| x as f64));
            for k in 0..3 {
                p[c[k] as usize] = t[k];
            }
        }
        let p = self.facing(p);
        let auv: f64 = self.live().map(|(_, c)| 0.5 * area2(c.map(|i| p[i as usize])).abs()).sum();
        let total = self.rest_weight();
        if !(auv > 0.0 && total > 0.0) {
            return None;
        }
        let s = (total / auv).sqrt();
        Some(p.iter().map(|q| [s * q[0], s * q[1]]).collect())
    }

    /// `p`, mirrored (its `v` negated) when the patch's summed signed UV area is negative.
    fn facing(&self, p: Vec<[f64; 2]>) -> Vec<[f64; 2]> {
        let signed: f64 = self.live().map(|(_, c)| area2(c.map(|i| p[i as usize]))).sum();
        if signed < 0.0 { p.into_iter().map(|q| [q[0], -q[1]]).collect() } else { p }
    }

    /// The injective check of the module docs.
    fn is_injective(&self, p: &[[f64; 2]]) -> bool {
        if !self.topology.manifold || p.iter().flatten().any(|x| !x.is_finite()) {
            return false;
        }
        // Per corner: its wedge's crossing of the ray to +x (the winding of an inner unknown's
        // fan, exactly, with no angle taken), and its angle where the unknown is on the
        // boundary (the turn round a boundary point, below).
        let on_boundary = &self.topology.on_boundary;
        let corners = per_face(self.corners.len(), |t| {
            let c = self.corners[t];
            let q = c.map(|i| p[i as usize]);
            (!self.collapsed[t] && is_positive(area2(q))).then(|| {
                let angles =
                    [0, 1, 2].map(|k| if on_boundary[c[k] as usize] { corner_angle(q, k) } else { 0.0 });
                (angles, [0, 1, 2].map(|k| wedge_crossing(q, k)))
            })
        });
        let mut angle = vec![0.0f64; self.n];
        let mut winding = vec![0i32; self.n];
        for (t, c) in self.live() {
            let Some((a, w)) = corners[t] else { return false };
            for k in 0..3 {
                angle[c[k] as usize] += a[k];
                winding[c[k] as usize] += i32::from(w[k]);
            }
        }
        // Round an inner unknown every face is positive, so its angles sum to 2π times the
        // winding of its fan: once round it, not twice (nor 0: an unknown in no live face).
        if (0..self.n).any(|v| !on_boundary[v] && winding[v] != 0 && winding[v] != 1) {
            return false;
        }
        let tau = std::f64::consts::TAU;
        // The fans at one boundary point (one unknown, or several at the very same position
        // where the island touches itself) turn at most once round it. A fan that turns further
        // lays its last faces over its first, and no boundary crossing shows it: the two
        // boundary segments that cross there share the point (seen on a teapot's handle, 20
        // faces overlapping in an atlas that passed every other test).
        let mut turn_at: HashMap<(u64, u64), f64> = HashMap::new();
        for v in (0..self.n).filter(|&v| self.topology.on_boundary[v]) {
            *turn_at.entry(point_key(p[v])).or_insert(0.0) += angle[v];
        }
        if turn_at.values().any(|&a| a > tau + BOUNDARY_TURN_SLACK) {
            return false;
        }
        // A loop of (nearly) no area, a closed slit, encloses nothing either way.
        let total: f64 = self.live().map(|(_, c)| area2(c.map(|i| p[i as usize]))).sum();
        let ccw = self
            .topology
            .loops
            .iter()
            .filter(|l| {
                let mut s = 0.0;
                for (i, &a) in l.iter().enumerate() {
                    let (pa, pb) = (p[a as usize], p[l[(i + 1) % l.len()] as usize]);
                    s += pa[0] * pb[1] - pa[1] * pb[0];
                }
                s > LOOP_AREA_REL * total
            })
            .count();
        (self.topology.loops.is_empty() || ccw == 1) && !boundary_crosses(&self.topology.loops, p)
    }

    /// Σ weight × symmetric Dirichlet over the live faces with a 3-D area (what the reports and
    /// the split and cone decisions read); `None` when some live face is not positive.
    fn energy(&self, p: &[[f64; 2]]) -> Option<f64> {
        self.energy_of(p, false, Terms::default())
    }

    /// What SLIM minimises: [`slim_density`] × weight over every live face, the terms besides
    /// the symmetric Dirichlet energy only on faces with a 3-D area; `None` when some face is not
    /// positive.
    fn objective(&self, p: &[[f64; 2]], terms: Terms) -> Option<f64> {
        self.energy_of(p, true, terms)
    }

    fn energy_of(&self, p: &[[f64; 2]], all: bool, terms: Terms) -> Option<f64> {
        let density = per_face(self.corners.len(), |t| {
            let rest = &self.rest[t];
            let q = self.corners[t].map(|i| p[i as usize]);
            if self.collapsed[t] { 0.0 } else { slim_density(rest.jacobian(q), rest.terms(terms)) }
        });
        let mut e = 0.0;
        for (t, _) in self.live() {
            let (rest, d) = (&self.rest[t], density[t]);
            if !d.is_finite() {
                return None;
            }
            if all || rest.real {
                e += rest.weight * d;
            }
        }
        Some(e)
    }

    /// PartUV's area distortion ([`crate::partuv`]) of the faces with a 3-D area at positions
    /// `p`: the mean over faces of each one's UV-to-rest area ratio against the patch's, folded
    /// and clipped. Unlike the energy it weighs every face alike, small ones too.
    fn area_distortion(&self, p: &[[f64; 2]]) -> f64 {
        let (mut rest, mut uv) = (vec![0.0; self.faces.len()], vec![0.0; self.faces.len()]);
        let mut set = Vec::with_capacity(self.faces.len());
        for (t, c) in self.live() {
            if self.rest[t].real {
                rest[t] = self.rest[t].weight;
                uv[t] = 0.5 * area2(c.map(|i| p[i as usize])).abs();
                set.push(t as u32);
            }
        }
        crate::partuv::area_distortion(&rest, &uv, &set).value.unwrap_or(1.0)
    }

    /// The rest length of each edge of a boundary `loop_` (from each unknown to the next).
    fn rest_arcs(&self, loop_: &[u32]) -> Vec<f64> {
        let mut lengths: HashMap<(u32, u32), f64> = HashMap::new();
        for (t, c) in self.live() {
            for k in 0..3 {
                let (a, b) = (self.rest[t].x[k], self.rest[t].x[(k + 1) % 3]);
                lengths.insert((c[k], c[(k + 1) % 3]), (b[0] - a[0]).hypot(b[1] - a[1]));
            }
        }
        (0..loop_.len())
            .map(|i| lengths.get(&(loop_[i], loop_[(i + 1) % loop_.len()])).copied().unwrap_or(0.0))
            .collect()
    }

    /// The Tutte embedding (module docs); `None` for a patch that is not a disc or whose system
    /// cannot be factored.
    fn tutte(&self) -> Option<Vec<[f64; 2]>> {
        let boundary = self.topology.loops.first().filter(|_| self.topology.disc)?;
        // Boundary on a circle of the patch's rest area, by rest arc length.
        let arcs: Vec<f64> = self.rest_arcs(boundary).into_iter().map(|a| a.max(f64::MIN_POSITIVE)).collect();
        let perimeter: f64 = arcs.iter().sum();
        let total = self.rest_weight();
        let radius = (total.max(f64::MIN_POSITIVE) / std::f64::consts::PI).sqrt();
        let mut p = vec![[0.0f64; 2]; self.n];
        let mut s = 0.0;
        for (i, &v) in boundary.iter().enumerate() {
            let a = std::f64::consts::TAU * s / perimeter;
            p[v as usize] = [radius * a.cos(), radius * a.sin()];
            s += arcs[i];
        }
        let free: Vec<bool> = self.topology.on_boundary.iter().map(|&b| !b).collect();
        self.harmonic(p, &free)
    }

    /// The least-squares conformal map of a disc (Lévy, Petitjean, Ray, Maillot, "Least Squares
    /// Conformal Maps for Automatic Texture Atlas Generation", 2002): the map whose Jacobians
    /// are closest to similarities, `Σ_t w_t ((J₀₀ − J₁₁)² + (J₀₁ + J₁₀)²)` over the rest
    /// shapes, with two boundary unknowns pinned (the loop's first and the one half way round
    /// it by rest length) and the result scaled to the patch's rest area. On a developable
    /// patch it is an isometry up to that scale, where Tutte's convex boundary is far from one
    /// (woody, a flat figure: SLIM from Tutte's start ended 60 rounds at 1.5e-4 per unit area
    /// above an isometry). It may fold or overlap on a curved patch, so the caller checks it.
    /// `None` when the patch is not a disc or the system cannot be solved.
    fn lscm(&self) -> Option<Vec<[f64; 2]>> {
        let boundary = self.topology.loops.first().filter(|_| self.topology.disc)?;
        let arcs = self.rest_arcs(boundary);
        let perimeter: f64 = arcs.iter().sum();
        let (mut s, mut half) = (0.0, 0);
        while half + 1 < boundary.len() && s + arcs[half] <= 0.5 * perimeter {
            s += arcs[half];
            half += 1;
        }
        let pins = [boundary[0], boundary[half.max(1).min(boundary.len() - 1)]];
        if pins[0] == pins[1] {
            return None;
        }
        let mut p = vec![[0.0f64; 2]; self.n];
        p[pins[1] as usize] = [s.max(f64::MIN_POSITIVE), 0.0];
        let mut row = vec![u32::MAX; self.n];
        let mut m = 0usize;
        for (v, r) in row.iter_mut().enumerate() {
            if !pins.contains(&(v as u32)) {
                *r = m as u32;
                m += 1;
            }
        }
        if m == 0 {
            return None;
        }
        // Unknowns: the free u's, then the free v's.
        let var =
            |v: u32, comp: usize| (row[v as usize] != u32::MAX).then(|| comp * m + row[v as usize] as usize);
        let mut triplets = Vec::new();
        let mut rhs = Mat::<f64>::zeros(2 * m, 1);
        for (t, c) in self.live() {
            let (g, w) = (self.rest[t].g, self.rest[t].weight);
            // The two residuals' coefficients on (u_k, v_k): J₀₀ − J₁₁ and J₀₁ + J₁₀.
            let rows: [[(u32, usize, f64); 6]; 2] = [
                std::array::from_fn(|x| (c[x % 3], x / 3, if x < 3 { g[x][0] } else { -g[x % 3][1] })),
                std::array::from_fn(|x| (c[x % 3], x / 3, if x < 3 { g[x][1] } else { g[x % 3][0] })),
            ];
            for a in &rows {
                for &(vx, cx, ax) in a {
                    let Some(i) = var(vx, cx) else { continue };
                    for &(vy, cy, ay) in a {
                        match var(vy, cy) {
                            Some(j) if j <= i => triplets.push(Triplet::new(i, j, w * ax * ay)),
                            Some(_) => {}
                            None => rhs[(i, 0)] -= w * ax * ay * p[vy as usize][cy],
                        }
                    }
                }
            }
        }
        solve_lower(2 * m, &triplets, &mut rhs)?;
        for (v, &r) in row.iter().enumerate() {
            if r != u32::MAX {
                p[v] = [rhs[(r as usize, 0)], rhs[(m + r as usize, 0)]];
            }
        }
        let uv_area: f64 = self.live().map(|(_, c)| 0.5 * area2(c.map(|v| p[v as usize]))).sum();
        let rest_area = self.rest_weight();
        let scale = (rest_area / uv_area).sqrt();
        if !(uv_area > 0.0 && scale.is_finite()) {
            return None;
        }
        p.iter_mut().for_each(|q| *q = q.map(|x| x * scale));
        p.iter().flatten().all(|x| x.is_finite()).then_some(p)
    }

    /// `p` with the `free` unknowns moved to solve `Σ_j W_ij (p_i − p_j) = 0`, `W` the
    /// symmetrised mean-value weights of the rest shapes (positive, so each free unknown lands
    /// in the convex hull of its neighbours); `None` when the system cannot be solved.
    fn harmonic(&self, mut p: Vec<[f64; 2]>, free: &[bool]) -> Option<Vec<[f64; 2]>> {
        let mut row = vec![u32::MAX; self.n];
        let mut interior = Vec::new();
        for (v, r) in row.iter_mut().enumerate() {
            if free[v] {
                *r = interior.len() as u32;
                interior.push(v as u32);
            }
        }
        if interior.is_empty() {
            return Some(p);
        }
        let m = interior.len();
        let mut triplets = Vec::new();
        let mut rhs = Mat::<f64>::zeros(m, 2);
        for (t, c) in self.live() {
            if c.iter().all(|&v| !free[v as usize]) {
                continue;
            }
            let x = self.rest[t].x;
            for k in 0..3 {
                let (o, a, b) = (x[k], x[(k + 1) % 3], x[(k + 2) % 3]);
                let (u, v) = ([a[0] - o[0], a[1] - o[1]], [b[0] - o[0], b[1] - o[1]]);
                let theta = (u[0] * v[1] - u[1] * v[0]).atan2(u[0] * v[0] + u[1] * v[1]);
                let half = (0.5 * theta).tan();
                for (other, len) in [(c[(k + 1) % 3], u[0].hypot(u[1])), (c[(k + 2) % 3], v[0].hypot(v[1]))] {
                    let w = half / len;
                    let (i, j) = (c[k], other);
                    // w is i's weight for j; added symmetrically, so W_ij = w_ij + w_ji.
                    let (ri, rj) = (row[i as usize], row[j as usize]);
                    for (ra, pb, rb) in [(ri, p[j as usize], rj), (rj, p[i as usize], ri)] {
                        if ra == u32::MAX {
                            continue;
                        }
                        triplets.push(Triplet::new(ra as usize, ra as usize, w));
                        if rb == u32::MAX {
                            rhs[(ra as usize, 0)] += w * pb[0];
                            rhs[(ra as usize, 1)] += w * pb[1];
                        } else if rb < ra {
                            triplets.push(Triplet::new(ra as usize, rb as usize, -w));
                        }
                    }
                }
            }
        }
        solve_lower(m, &triplets, &mut rhs)?;
        for (r, &v) in interior.iter().enumerate() {
            p[v as usize] = [rhs[(r, 0)], rhs[(r, 1)]];
        }
        p.iter().flatten().all(|x| x.is_finite()).then_some(p)
    }

    /// A local repair of the non-injective map `p` (module docs): the unknowns inside a region
    /// round the bad faces ([`Patch::bad_faces`]), grown by [`REPAIR_RINGS`] rings of faces in
    /// turn, are re-solved as a harmonic map with everything else fixed; the first injective
    /// result is returned. `None` when no region works (a fold on the boundary, an overlap of
    /// two distant parts).
    fn repair(&self, p: &[[f64; 2]]) -> Option<Vec<[f64; 2]>> {
        let mut region = self.bad_faces(p);
        if !region.iter().any(|&b| b) {
            return None;
        }
        let mut faces_of: Vec<Vec<u32>> = vec![Vec::new(); self.n];
        for (t, c) in self.live() {
            for &v in &c {
                faces_of[v as usize].push(t as u32);
            }
        }
        let mut grown = 0;
        for &rings in REPAIR_RINGS {
            while grown < rings {
                let touched: Vec<bool> =
                    (0..self.n).map(|v| faces_of[v].iter().any(|&t| region[t as usize])).collect();
                for (t, c) in self.live() {
                    if c.iter().any(|&v| touched[v as usize]) {
                        region[t] = true;
                    }
                }
                grown += 1;
            }
            let free: Vec<bool> = (0..self.n)
                .map(|v| {
                    !self.topology.on_boundary[v]
                        && !faces_of[v].is_empty()
                        && faces_of[v].iter().all(|&t| region[t as usize])
                })
                .collect();
            if !free.iter().any(|&f| f) {
                continue;
            }
            if let Some(q) = self.harmonic(p.to_vec(), &free)
                && self.is_injective(&q)
            {
                return Some(q);
            }
        }
        None
    }

    /// SLIM rounds from the injective `p` (module docs); returns the last injective positions and
    /// the rounds taken.
    ///
    /// The scaffold's triangulation is kept from round to round, its rest shapes reset to the
    /// round's start, for [`SCAFFOLD_ROUNDS`] rounds or until it limits a step (a scaffold
    /// triangle would collapse before any face of the patch does): then the free space is
    /// triangulated anew. Its triangles stay positive in between because the line search never
    /// lets one reach zero area, so it still fills the box round the patch, and the system's
    /// pattern and symbolic factorisation are reused.
    fn slim(&self, p: Vec<[f64; 2]>, opts: &InjectiveOptions) -> (Vec<[f64; 2]>, usize) {
        self.slim_from(p, opts, 0)
    }

    /// [`Patch::slim`] whose first `free_rounds` rounds run without a scaffold: the sides of a
    /// slit that start a hair apart open in one step instead of against the scaffold's slivers
    /// between them (the line search still refuses a step that is not injective).
    fn slim_from(
        &self,
        mut p: Vec<[f64; 2]>,
        opts: &InjectiveOptions,
        free_rounds: usize,
    ) -> (Vec<[f64; 2]>, usize) {
        let terms = opts.terms();
        let Some(mut energy) = self.objective(&p, terms) else { return (p, 0) };
        let isometric = 4.0 * self.rest_weight();
        let glue = self.coincident_boundary(&p);
        let mut system = SlimSystem::new(self, glue, terms);
        let mut rounds = 0;
        let mut kept: Option<Scaffold> = None;
        for _ in 0..opts.iterations {
            let scaffold = match kept.take().and_then(|sc| sc.rested(&p)) {
                _ if rounds < free_rounds => None,
                Some(sc) => Some(sc),
                None => {
                    system.new_scaffold();
                    Scaffold::build(self, &p, &system.glue)
                }
            };
            let target = match &scaffold {
                Some(sc) => system.global_scaffold(self, &p, sc),
                None => system.global(self, &p),
            };
            let Some(target) = target else { break };
            rounds += 1;
            let d: Vec<[f64; 2]> = target.iter().zip(&p).map(|(a, b)| [a[0] - b[0], a[1] - b[1]]).collect();
            let island_bound = self.max_step(&p, &d);
            let scaffold_bound = scaffold.as_ref().map_or(f64::INFINITY, |sc| sc.max_step(&p, &d));
            let bound = island_bound.min(scaffold_bound);
            // The objective `e` at `q` plus the scaffold's energy there: what the line search lowers.
            let with_scaffold = |q: &[[f64; 2]], e: f64| -> Option<f64> {
                match &scaffold {
                    Some(sc) => Some(e + sc.energy(q)?),
                    None => Some(e),
                }
            };
            // `energy` is the objective at `p` already (its value when `p` was accepted).
            let Some(now) = with_scaffold(&p, energy) else { break };
            let mut t = (STEP_SHARE * bound).min(1.0);
            let mut accepted = None;
            for _ in 0..=MAX_HALVINGS {
                let q: Vec<[f64; 2]> =
                    p.iter().zip(&d).map(|(a, b)| [a[0] + t * b[0], a[1] + t * b[1]]).collect();
                if let Some(e) = self.objective(&q, terms)
                    && let Some(total) = with_scaffold(&q, e)
                    && total < now
                    && self.is_injective(&q)
                {
                    accepted = Some((q, e));
                    break;
                }
                t *= 0.5;
            }
            let Some((q, e)) = accepted else { break };
            let done = converged(energy - e, energy, isometric, opts);
            (p, energy) = (q, e);
            if done {
                break;
            }
            let scaffold_limited = scaffold_bound < island_bound && STEP_SHARE * scaffold_bound < 1.0;
            if !scaffold_limited && rounds % SCAFFOLD_ROUNDS != 0 {
                kept = scaffold;
            }
        }
        (p, rounds)
    }

    /// Per unknown, the unknown it is glued to during SLIM: boundary unknowns at the very same
    /// position share the lowest-numbered of them, every other unknown is its own. Why: the
    /// networks' islands of a marching-cubes mesh touch themselves at boundary points (a
    /// non-manifold vertex split into fans, two cuts meeting), and measured on one (homer made
    /// unruly) such a point stopped SLIM on every large island at its first round: the scaffold
    /// cannot triangulate two boundary vertices at one point, and without it any step moves the
    /// two apart so that boundary segments cross. Moving together, they keep touching (which
    /// covers no area twice) and the scaffold sees one point.
    fn coincident_boundary(&self, p: &[[f64; 2]]) -> Vec<u32> {
        let mut glue: Vec<u32> = (0..self.n as u32).collect();
        let mut first: HashMap<(u64, u64), u32> = HashMap::new();
        for v in 0..self.n {
            if self.topology.on_boundary[v] {
                glue[v] = *first.entry(point_key(p[v])).or_insert(v as u32);
            }
        }
        glue
    }

    /// The first `t > 0` at which some live face's signed area along `p + t d` reaches zero
    /// (infinity when none does).
    fn max_step(&self, p: &[[f64; 2]], d: &[[f64; 2]]) -> f64 {
        let step = per_face(self.corners.len(), |t| {
            let c = self.corners[t];
            triangle_zero_step(c.map(|i| p[i as usize]), c.map(|i| d[i as usize]))
        });
        self.live().map(|(t, _)| step[t]).fold(f64::INFINITY, f64::min)
    }

    /// Cuts a patch open into a disc (module docs, step 3): a closed patch along a slit, the
    /// shortest path between two of its vertices farthest apart (by rest edge length); a patch
    /// with several boundary loops along shortest paths from each loop but the longest to
    /// another loop, until one loop is left. A patch of genus 0 becomes a disc. Does nothing to a
    /// patch whose boundary cannot be followed.
    fn cut_to_disc(&mut self) {
        if self.topology.manifold && self.topology.loops.is_empty() {
            self.slit_open();
        }
        for _ in 0..self.topology.loops.len() {
            if !self.topology.manifold || self.topology.loops.len() < 2 {
                return;
            }
            let adj = self.edge_graph();
            // A boundary edge of a manifold patch has one face: its length is the one `adj` holds.
            let length = |a: u32, b: u32| adj[a as usize].iter().find(|e| e.0 == b).map_or(0.0, |e| e.1);
            let loop_length =
                |l: &Vec<u32>| -> f64 { (0..l.len()).map(|i| length(l[i], l[(i + 1) % l.len()])).sum() };
            let outer = (0..self.topology.loops.len())
                .max_by(|&a, &b| {
                    loop_length(&self.topology.loops[a])
                        .total_cmp(&loop_length(&self.topology.loops[b]))
                        .then(b.cmp(&a))
                })
                .unwrap_or(0);
            let hole = if outer == 0 { 1 } else { 0 };
            let mut loop_of = vec![usize::MAX; self.n];
            for (li, l) in self.topology.loops.iter().enumerate() {
                for &v in l {
                    loop_of[v as usize] = li;
                }
            }
            // From the hole to the nearest vertex of another loop.
            let (_, prev, reached) = shortest_paths(
                &adj,
                &self.topology.loops[hole],
                |v| loop_of[v as usize] != usize::MAX && loop_of[v as usize] != hole,
                |w| loop_of[w as usize] != hole,
            );
            let Some(v) = reached else { return };
            self.cut_along(&prev, v);
        }
    }

    /// Cuts a closed patch along the shortest path between two vertices far apart: the farthest
    /// from its first vertex, and the farthest from that one (module docs). The slit's two sides
    /// become its one boundary loop.
    fn slit_open(&mut self) {
        let Some((_, first)) = self.live().next() else { return };
        let adj = self.edge_graph();
        let farthest = |dist: &[f64]| {
            (0..dist.len() as u32)
                .filter(|&v| dist[v as usize].is_finite())
                .max_by(|&a, &b| dist[a as usize].total_cmp(&dist[b as usize]).then(b.cmp(&a)))
        };
        let (dist, _, _) = shortest_paths(&adj, &[first[0]], |_| false, |_| true);
        let Some(a) = farthest(&dist) else { return };
        let (dist, prev, _) = shortest_paths(&adj, &[a], |_| false, |_| true);
        match farthest(&dist) {
            Some(b) if b != a => self.cut_along(&prev, b),
            _ => {}
        }
    }

    /// The adjacency lists of the live faces' edges, each edge with its rest length in the first
    /// face (in face order) that uses it, and listed in the order the faces first reach it
    /// ([`sorted_edge_uses`]).
    fn edge_graph(&self) -> Adjacency {
        let uses = sorted_edge_uses(&self.corners, &self.collapsed);
        let mut first: Vec<(u32, u8)> = uses.chunk_by(|x, y| x.0 == y.0).map(|e| (e[0].1, e[0].2)).collect();
        first.sort_unstable();
        let mut adj: Adjacency = vec![Vec::new(); self.n];
        for (t, k) in first {
            let (t, k) = (t as usize, k as usize);
            let (a, b) = (self.corners[t][k], self.corners[t][(k + 1) % 3]);
            let (xa, xb) = (self.rest[t].x[k], self.rest[t].x[(k + 1) % 3]);
            let l = (xb[0] - xa[0]).hypot(xb[1] - xa[1]);
            adj[a as usize].push((b, l));
            adj[b as usize].push((a, l));
        }
        adj
    }

    /// Cuts the edges of the path that `prev` leads along from `v` back to its source, then
    /// takes the topology again.
    fn cut_along(&mut self, prev: &[u32], v: u32) {
        let cut: HashSet<(u32, u32)> =
            path_back(prev, v).into_iter().map(|(u, w)| (u.min(w), u.max(w))).collect();
        let (corners, n) = separate_fans(std::mem::take(&mut self.corners), &self.collapsed, self.n, &cut);
        (self.corners, self.n) = (corners, n);
        self.topology = self.topology();
    }

    /// Step 6 of the module docs: this disc, solved to `p`, cut from its cone points to its
    /// boundary and solved again; `None` when it has no cone point, or when the cut does not
    /// lower its energy above an isometry's by [`CONE_GAIN`].
    fn cut_cones(&self, p: &[[f64; 2]], opts: &InjectiveOptions) -> Option<Coned> {
        if !self.topology.disc || self.area3 <= 0.0 {
            return None;
        }
        let adj = self.edge_graph();
        let cones = self.cone_points(&adj);
        if cones.is_empty() {
            return None;
        }
        let mut target = self.topology.on_boundary.clone();
        let mut cut = HashSet::new();
        for &c in &cones {
            let (_, prev, reached) = shortest_paths(&adj, &[c], |v| target[v as usize], |_| true);
            let Some(v) = reached else { continue };
            for (u, w) in path_back(&prev, v) {
                cut.insert((u.min(w), u.max(w)));
                target[w as usize] = true;
            }
            target[c as usize] = true;
        }
        let mut coned = self.clone();
        (coned.corners, coned.n) = separate_fans(self.corners.clone(), &self.collapsed, self.n, &cut);
        coned.topology = coned.topology();
        if !coned.topology.disc {
            return None;
        }
        // Each copy of a cut vertex starts where it was, moved a share of the way to its own
        // fan's centre, so the two sides of a slit are apart; a share that leaves the map not
        // injective is halved.
        let mut origin = vec![u32::MAX; coned.n];
        let (mut centre, mut count) = (vec![[0.0f64; 2]; coned.n], vec![0usize; coned.n]);
        for ((t, c), old) in coned.corners.iter().enumerate().zip(&self.corners) {
            for k in 0..3 {
                origin[c[k] as usize] = old[k];
            }
            if self.collapsed[t] {
                continue;
            }
            let q = old.map(|i| p[i as usize]);
            let mid = [(q[0][0] + q[1][0] + q[2][0]) / 3.0, (q[0][1] + q[1][1] + q[2][1]) / 3.0];
            for &v in c {
                let v = v as usize;
                centre[v] = [centre[v][0] + mid[0], centre[v][1] + mid[1]];
                count[v] += 1;
            }
        }
        let mut split = vec![false; self.n];
        for v in self.n..coned.n {
            split[origin[v] as usize] = true;
        }
        let start = |share: f64| -> Vec<[f64; 2]> {
            (0..coned.n)
                .map(|v| {
                    let o = origin[v];
                    let at = if o == u32::MAX { [0.0; 2] } else { p[o as usize] };
                    if o == u32::MAX || !split[o as usize] || count[v] == 0 {
                        return at;
                    }
                    let m = [centre[v][0] / count[v] as f64, centre[v][1] / count[v] as f64];
                    [at[0] + share * (m[0] - at[0]), at[1] + share * (m[1] - at[1])]
                })
                .collect()
        };
        let q = (0..SLIT_HALVINGS as i32)
            .map(|h| start(SLIT_SHARE * 0.5f64.powi(h)))
            .find(|q| coned.is_injective(q))?;
        let (q, rounds) = coned.slim_from(q, opts, 1);
        let (before, after) = (self.energy(p)?, coned.energy(&q)?);
        let excess = before - 4.0 * self.area3;
        let spread = coned.area_distortion(&q) <= self.area_distortion(p) + CONE_AREA_RISE;
        (excess > 0.0 && before - after >= CONE_GAIN * excess && spread).then_some(Coned {
            patch: coned,
            p: q,
            rounds,
            cones: cones.len(),
        })
    }

    /// Per unknown, its angle deficit: 2π minus the rest angles of its faces; 0 on the boundary
    /// and where a face without 3-D area touches (whose rest angles are made up).
    fn deficits(&self) -> Vec<f64> {
        let n = self.n;
        // Angle sums of the faces with a true 3-D area round each unknown; unknowns on the
        // boundary, or touching a face without 3-D area (whose rest angles are made up), have no
        // deficit of their own.
        let mut angle = vec![0.0f64; n];
        let mut usable: Vec<bool> = self.topology.on_boundary.iter().map(|b| !b).collect();
        for (t, c) in self.live() {
            let x = self.rest[t].x;
            for k in 0..3 {
                if !self.rest[t].real {
                    usable[c[k] as usize] = false;
                    continue;
                }
                // Rest shapes are positive triangles: their signed angles are their angles.
                angle[c[k] as usize] += corner_angle(x, k);
            }
        }
        (0..n).map(|v| if usable[v] { std::f64::consts::TAU - angle[v] } else { 0.0 }).collect()
    }

    /// Whether the patch is a developable disc: every inner angle deficit within
    /// [`DEVELOPABLE_DEFICIT`]. Its least-squares conformal map is then an isometry.
    fn is_developable_disc(&self) -> bool {
        self.topology.disc && self.deficits().iter().all(|d| d.abs() <= DEVELOPABLE_DEFICIT)
    }

    /// The cone points of this disc (module docs, step 6), strongest first; `adj` is its
    /// [`Patch::edge_graph`].
    fn cone_points(&self, adj: &Adjacency) -> Vec<u32> {
        let n = self.n;
        let deficit = self.deficits();
        let radius = CONE_RADIUS * self.area3.sqrt();
        let boundary: Vec<u32> = (0..n as u32).filter(|&v| self.topology.on_boundary[v as usize]).collect();
        let (to_boundary, _, _) = shortest_paths(adj, &boundary, |_| false, |_| true);
        let mut ball = Ball::new(n);
        let mut candidates: Vec<(f64, u32)> = (0..n as u32)
            .filter(|&v| deficit[v as usize] > 0.0 && to_boundary[v as usize] > radius)
            .filter_map(|v| {
                let k: f64 = ball.around(adj, v, radius).iter().map(|&w| deficit[w as usize]).sum();
                (k >= CONE_DEFICIT).then_some((k, v))
            })
            .collect();
        candidates.sort_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)));
        let mut taken = vec![false; n];
        let mut cones = Vec::new();
        for (_, v) in candidates {
            if cones.len() >= MAX_CONES {
                break;
            }
            if taken[v as usize] {
                continue;
            }
            cones.push(v);
            for w in ball.around(adj, v, 2.0 * radius) {
                taken[w as usize] = true;
            }
        }
        cones
    }

    /// The faces joined across edges that exactly two live faces use in opposite directions, as
    /// connected parts in order of their first face (module docs): the patch's pieces of
    /// consistent winding and manifold edges. Collapsed faces go with the first part.
    fn consistent_parts(&self) -> Vec<Vec<u32>> {
        let mut uses: HashMap<(u32, u32), Vec<(u32, bool)>> = HashMap::new();
        for (t, c) in self.live() {
            for k in 0..3 {
                let (a, b) = (c[k], c[(k + 1) % 3]);
                uses.entry((a.min(b), a.max(b))).or_default().push((t as u32, a < b));
            }
        }
        let mut dsu = crate::uvstats::Dsu::new(self.faces.len());
        for (t, c) in self.live() {
            for k in 0..3 {
                let (a, b) = (c[k], c[(k + 1) % 3]);
                if let [(f, x), (g, y)] = uses[&(a.min(b), a.max(b))][..]
                    && x != y
                {
                    debug_assert!(f as usize == t || g as usize == t);
                    dsu.union(f, g);
                }
            }
        }
        self.group(|t| if self.collapsed[t] { 0 } else { dsu.find(t as u32) })
    }

    /// The patch's faces grouped by `key(face index)`, groups in order of their first face.
    fn group(&self, mut key: impl FnMut(usize) -> u32) -> Vec<Vec<u32>> {
        let mut index: HashMap<u32, usize> = HashMap::new();
        let mut parts: Vec<Vec<u32>> = Vec::new();
        for t in 0..self.faces.len() {
            let next = parts.len();
            let i = *index.entry(key(t)).or_insert(next);
            if i == parts.len() {
                parts.push(Vec::new());
            }
            parts[i].push(self.faces[t]);
        }
        parts
    }

    /// This patch's working positions taken from `parent`'s positions `p` (the patch's faces
    /// are some of the parent's, in the same order).
    fn inherit(&self, parent: &Patch, p: &[[f64; 2]]) -> Vec<[f64; 2]> {
        let index: HashMap<u32, usize> = parent.faces.iter().enumerate().map(|(i, &f)| (f, i)).collect();
        let mut q = vec![[0.0f64; 2]; self.n];
        for (j, &f) in self.faces.iter().enumerate() {
            let i = index[&f];
            for k in 0..3 {
                q[self.corners[j][k] as usize] = p[parent.corners[i][k] as usize];
            }
        }
        q
    }

    /// Grows the good faces (not `bad`) of the map `p` back over the bad ones, breadth-first
    /// across shared edges: a bad face joins when its corners already placed (used by a good
    /// face, or placed by this growth) and, for a face with one corner not yet placed, that
    /// corner put where the face's rest shape puts it on the placed edge, make a positive
    /// triangle that overlaps no good face. Returns the faces still bad and the positions.
    fn grow(&self, bad: &[bool], p: &[[f64; 2]]) -> (Vec<bool>, Vec<[f64; 2]>) {
        let mut bad = bad.to_vec();
        let mut q = p.to_vec();
        let mut placed = vec![false; self.n];
        let by_edge = faces_by_edge(self.live().map(|(t, c)| (t as u32, c)));
        let mut good: Vec<(usize, [[f64; 2]; 3])> = Vec::new();
        for (t, c) in self.live() {
            if !bad[t] {
                c.iter().for_each(|&v| placed[v as usize] = true);
                good.push((t, c.map(|v| p[v as usize])));
            }
        }
        if good.is_empty() {
            return (bad, q);
        }
        let mut grid = TriangleGrid::new(&good, mean_edge(&good));
        let ratio = |t: usize, tri: [[f64; 2]; 3]| area2(tri) / area2(self.rest[t].x);
        let mut ratios: Vec<f64> =
            good.iter().filter(|&&(t, _)| self.rest[t].real).map(|&(t, tri)| ratio(t, tri)).collect();
        let median = if ratios.is_empty() {
            1.0
        } else {
            let mid = ratios.len() / 2;
            *ratios.select_nth_unstable_by(mid, f64::total_cmp).1
        };
        let (low, high) = (median / GROW_SCALE, median * GROW_SCALE);
        let mut queue: std::collections::VecDeque<u32> = std::collections::VecDeque::new();
        for (t, c) in self.live() {
            if bad[t] && c.iter().filter(|&&v| placed[v as usize]).count() >= 2 {
                queue.push_back(t as u32);
            }
        }
        while let Some(t) = queue.pop_front() {
            let t = t as usize;
            if !bad[t] {
                continue;
            }
            let c = self.corners[t];
            let missing: Vec<usize> = (0..3).filter(|&k| !placed[c[k] as usize]).collect();
            let tri = match missing[..] {
                [] => c.map(|v| q[v as usize]),
                [k] => {
                    // Corner k from the rest shape, by the similarity taking the rest edge
                    // (k+1, k+2) onto its placed image.
                    let x = self.rest[t].x;
                    let (i, j) = ((k + 1) % 3, (k + 2) % 3);
                    let (xa, xb, xk) = (x[i], x[j], x[k]);
                    let (qa, qb) = (q[c[i] as usize], q[c[j] as usize]);
                    let (ex, eq) = ([xb[0] - xa[0], xb[1] - xa[1]], [qb[0] - qa[0], qb[1] - qa[1]]);
                    let l2 = ex[0] * ex[0] + ex[1] * ex[1];
                    if !is_positive(l2) {
                        continue;
                    }
                    // Complex ratio eq / ex as (cos, sin) · scale.
                    let (re, im) =
                        ((eq[0] * ex[0] + eq[1] * ex[1]) / l2, (eq[1] * ex[0] - eq[0] * ex[1]) / l2);
                    let d = [xk[0] - xa[0], xk[1] - xa[1]];
                    let pk = [qa[0] + re * d[0] - im * d[1], qa[1] + im * d[0] + re * d[1]];
                    let mut tri = c.map(|v| q[v as usize]);
                    tri[k] = pk;
                    tri
                }
                _ => continue,
            };
            if !is_positive(area2(tri))
                || tri.iter().flatten().any(|x| !x.is_finite())
                || (self.rest[t].real && !(low..=high).contains(&ratio(t, tri)))
                || !grid.overlapping(tri).is_empty()
            {
                continue;
            }
            for (k, &v) in c.iter().enumerate() {
                if !placed[v as usize] {
                    placed[v as usize] = true;
                    q[v as usize] = tri[k];
                }
            }
            bad[t] = false;
            grid.insert(tri);
            for k in 0..3 {
                let (a, b) = (c[k], c[(k + 1) % 3]);
                for &o in &by_edge[&(a.min(b), a.max(b))] {
                    if bad[o as usize] {
                        queue.push_back(o);
                    }
                }
            }
        }
        (bad, q)
    }

    /// Faces of `p` that are not positive, or positive and overlapping another positive face
    /// (interiors intersect; touching is not overlapping), found through a hashed grid. Collapsed
    /// faces are never bad.
    fn bad_faces(&self, p: &[[f64; 2]]) -> Vec<bool> {
        let mut bad = vec![false; self.faces.len()];
        let mut tris: Vec<(usize, [[f64; 2]; 3])> = Vec::new();
        for (t, c) in self.live() {
            let q = c.map(|i| p[i as usize]);
            if area2(q) > 0.0 {
                tris.push((t, q));
            } else {
                bad[t] = true;
            }
        }
        if tris.is_empty() {
            return bad;
        }
        let mut grid = TriangleGrid::new(&tris[..0], mean_edge(&tris));
        for (t, q) in &tris {
            for o in grid.overlapping(*q) {
                bad[*t] = true;
                bad[tris[o as usize].0] = true;
            }
            grid.insert(*q);
        }
        bad
    }

    /// Each face's side of a thin wall (true: the side the map `p` mirrors), where one chart's
    /// map holds both sides of a wall thinner than the networks can tell apart: the far side
    /// comes mirrored, but its flips interleave with the near side's faces along the noise of a
    /// marching-cubes surface, so the faces' own orientations cut the patch into hundreds of
    /// parts (module docs, step 4). The labelling of least energy (each face's rest area for a
    /// label against its orientation, plus [`SIDE_SMOOTHING`] for the edges between the sides)
    /// is a minimum cut ([`crate::mincut`]): spots of flips join their side, and the sides part
    /// where the wall turns back. Collapsed faces cost nothing either way.
    fn sides(&self, ctx: &Ctx, p: &[[f64; 2]]) -> Vec<bool> {
        let mut unary = vec![(0.0, 0.0); self.faces.len()];
        for (t, c) in self.live() {
            let w = self.rest[t].weight;
            unary[t] = if area2(c.map(|i| p[i as usize])) > 0.0 { (0.0, w) } else { (w, 0.0) };
        }
        let edges = self.edges_between(ctx, self.live());
        let lengths: f64 = edges.iter().map(|e| e.2).sum();
        let mut pairs: Vec<(u32, u32, f64)> =
            edges.iter().map(|&(f, g, length, bend)| (f, g, length * bend)).collect();
        let mean_edge = if pairs.is_empty() { 0.0 } else { lengths / pairs.len() as f64 };
        for pair in &mut pairs {
            pair.2 *= SIDE_SMOOTHING * mean_edge;
        }
        crate::mincut::two_labels(&unary, &pairs)
    }

    /// The connected parts (faces joined across a shared edge, both with the same `label`) of
    /// the patch, in order of their first face.
    fn components(&self, label: &[bool]) -> Vec<Vec<u32>> {
        let mut first: HashMap<(u32, u32), u32> = HashMap::new();
        let mut dsu = crate::uvstats::Dsu::new(self.faces.len());
        for (t, c) in self.corners.iter().enumerate() {
            for k in 0..3 {
                let (a, b) = (c[k], c[(k + 1) % 3]);
                match first.entry((a.min(b), a.max(b))) {
                    std::collections::hash_map::Entry::Vacant(e) => {
                        e.insert(t as u32);
                    }
                    std::collections::hash_map::Entry::Occupied(e) => {
                        let o = *e.get();
                        if label[o as usize] == label[t] {
                            dsu.union(o, t as u32);
                        }
                    }
                }
            }
        }
        self.group(|t| dsu.find(t as u32))
    }

    /// Whether splitting the patch into `parts` (mesh faces, covering it) is ragged (module docs,
    /// step 4): more than two parts whose seams exceed [`RAGGED_CUT`] times the cut between the
    /// patch's [`Patch::halves`].
    fn is_ragged(&self, parts: &[Vec<u32>]) -> bool {
        parts.len() > 2 && RAGGED_CUT * self.cut_length(&self.halves()) < self.cut_length(parts)
    }

    /// Summed rest length of the edges between two faces that `parts` (mesh faces, covering the
    /// patch) put in different parts: the seam that splitting the patch so would add.
    fn cut_length(&self, parts: &[Vec<u32>]) -> f64 {
        let part_of: HashMap<u32, usize> =
            parts.iter().enumerate().flat_map(|(i, p)| p.iter().map(move |&f| (f, i))).collect();
        let by_edge = faces_by_edge(self.corners.iter().enumerate().map(|(t, &c)| (t as u32, c)));
        let part = |t: u32| part_of.get(&self.faces[t as usize]).copied();
        let mut length = 0.0;
        for (t, c) in self.corners.iter().enumerate() {
            for k in 0..3 {
                let (a, b) = (c[k], c[(k + 1) % 3]);
                if let [f, g] = by_edge[&(a.min(b), a.max(b))][..]
                    && f == t as u32
                    && part(f) != part(g)
                {
                    let x = &self.rest[t].x;
                    length += (x[(k + 1) % 3][0] - x[k][0]).hypot(x[(k + 1) % 3][1] - x[k][1]);
                }
            }
        }
        length
    }

    /// Two parts of connected faces grown from two far-apart faces (module docs).
    fn halves(&self) -> [Vec<u32>; 2] {
        let adj = self.face_adjacency();
        let (a, b, _) = far_apart(&adj);
        self.halves_from(&adj, a, b)
    }

    /// [`Patch::halves`] for the adjacency `adj` it builds and its far-apart faces `a`, `b`.
    fn halves_from(&self, adj: &[Vec<u32>], a: u32, b: u32) -> [Vec<u32>; 2] {
        let (_, owner) = breadth_first(adj, &[a, b]);
        let mut halves = [Vec::new(), Vec::new()];
        for (t, &o) in owner.iter().enumerate() {
            // Faces no edge reaches (only possible through collapsed faces) go with the first part.
            halves[if o == 1 { 1 } else { 0 }].push(self.faces[t]);
        }
        if halves[1].is_empty() {
            let moved = halves[0].split_off(halves[0].len() / 2);
            halves[1] = moved;
        }
        halves
    }

    /// The patch cut in two where a cut between two far-apart faces is shortest (module docs,
    /// step 4): every face is numbered by its distance in steps from each of the two faces of
    /// [`Patch::halves`]; a face at most a third of the way from one of them goes with it, and
    /// the band between is parted by the cut of least summed rest edge length, each edge's
    /// length weighted by `(1 + cos θ) / 2` of the angle between its faces' normals as in
    /// [`Patch::sides`] (a seam along a crease costs little), found exactly by a minimum cut.
    /// Returns the connected parts of that labelling, or [`Patch::halves`] when it gives one.
    ///
    /// Why: halving by breadth-first growth parts the faces where the two fronts meet, a seam
    /// that zigzags along mesh edges wherever the patch happens to be and ignores where the
    /// surface narrows or folds; an island SLIM cannot flatten whole is cut once per halving, so
    /// every such seam is seen by the renders.
    fn cut_in_two(&self, ctx: &Ctx) -> Vec<Vec<u32>> {
        let adj = self.face_adjacency();
        let (a, b, from_a) = far_apart(&adj);
        let from_b = breadth_first(&adj, &[b]).0;
        // The end each face is bound to (`false` the first), `None` in the band between.
        let end: Vec<Option<bool>> = from_a
            .iter()
            .zip(&from_b)
            .map(|(&da, &db)| {
                let (da, db) = (da as u64, db as u64);
                if da == u32::MAX as u64 || 3 * da <= da + db {
                    // Near the first end, or reached by no edge (the first part, as in `halves`).
                    Some(false)
                } else if 3 * db <= da + db {
                    Some(true)
                } else {
                    None
                }
            })
            .collect();
        // Only the band's faces are labelled: an edge from one to a face bound to an end charges
        // it for taking the other label (the ends contracted into the source and the sink).
        let mut node = vec![u32::MAX; end.len()];
        let mut band = 0;
        for (t, e) in end.iter().enumerate() {
            if e.is_none() {
                node[t] = band;
                band += 1;
            }
        }
        let mut unary = vec![(0.0, 0.0); band as usize];
        let mut pairs = Vec::new();
        let all = self.corners.iter().copied().enumerate();
        for (f, g, length, bend) in self.edges_between(ctx, all) {
            let w = length * bend;
            let (f, g) = (f as usize, g as usize);
            let mut charge = |t: usize, bound: bool| {
                let cost = &mut unary[node[t] as usize];
                if bound { cost.0 += w } else { cost.1 += w }
            };
            match (end[f], end[g]) {
                (None, None) => pairs.push((node[f], node[g], w)),
                (None, Some(e)) => charge(f, e),
                (Some(e), None) => charge(g, e),
                (Some(_), Some(_)) => {}
            }
        }
        let in_band = crate::mincut::two_labels(&unary, &pairs);
        let label: Vec<bool> =
            end.iter().enumerate().map(|(t, e)| e.unwrap_or_else(|| in_band[node[t] as usize])).collect();
        let parts = self.components(&label);
        if parts.len() > 1 { parts } else { self.halves_from(&adj, a, b).to_vec() }
    }

    /// The edges that exactly two of `faces` (patch face indices and their corners) share, as
    /// `(f, g, rest length, (1 + cos θ) / 2)`, θ the angle between the two faces' normals: what
    /// [`Patch::sides`] and [`Patch::cut_in_two`] charge for parting two faces (little where
    /// the surface folds back or bends sharply). Each edge once, in order of its first face.
    fn edges_between(
        &self,
        ctx: &Ctx,
        faces: impl Iterator<Item = (usize, [u32; 3])> + Clone,
    ) -> Vec<(u32, u32, f64, f64)> {
        // Each face's unit normal once (a face meets up to three edges).
        let normals: Vec<glam::DVec3> = self
            .faces
            .iter()
            .map(|&f| {
                let [a, b, c] = ctx.mesh.corners(f as usize).map(to_dvec3);
                (b - a).cross(c - a).normalize_or_zero()
            })
            .collect();
        let by_edge = faces_by_edge(faces.clone().map(|(t, c)| (t as u32, c)));
        let mut edges = Vec::with_capacity(by_edge.len());
        for (t, c) in faces {
            for k in 0..3 {
                let (a, b) = (c[k], c[(k + 1) % 3]);
                if let [f, g] = by_edge[&(a.min(b), a.max(b))][..]
                    && f == t as u32
                {
                    let x = &self.rest[t].x;
                    let length = (x[(k + 1) % 3][0] - x[k][0]).hypot(x[(k + 1) % 3][1] - x[k][1]);
                    let bend = 0.5 * (1.0 + normals[f as usize].dot(normals[g as usize]));
                    edges.push((f, g, length, bend));
                }
            }
        }
        edges
    }

    /// Each face's neighbours across its edges (in order of first meeting, no repeats).
    fn face_adjacency(&self) -> Vec<Vec<u32>> {
        let by_edge = faces_by_edge(self.corners.iter().enumerate().map(|(t, &c)| (t as u32, c)));
        let mut adj: Vec<Vec<u32>> = vec![Vec::new(); self.faces.len()];
        for (t, c) in self.corners.iter().enumerate() {
            for k in 0..3 {
                let (a, b) = (c[k], c[(k + 1) % 3]);
                for &o in &by_edge[&(a.min(b), a.max(b))] {
                    if o as usize != t && !adj[t].contains(&o) {
                        adj[t].push(o);
                    }
                }
            }
        }
        adj
    }
}

/// Breadth-first distances in steps over `adj` from `sources`, and which source reached each
/// node first (`u32::MAX` for both where none does).
fn breadth_first(adj: &[Vec<u32>], sources: &[u32]) -> (Vec<u32>, Vec<u32>) {
    let m = adj.len();
    let (mut dist, mut owner) = (vec![u32::MAX; m], vec![u32::MAX; m]);
    let mut queue = std::collections::VecDeque::new();
    for (i, &s) in sources.iter().enumerate() {
        dist[s as usize] = 0;
        owner[s as usize] = i as u32;
        queue.push_back(s);
    }
    while let Some(f) = queue.pop_front() {
        for &o in &adj[f as usize] {
            if dist[o as usize] == u32::MAX {
                dist[o as usize] = dist[f as usize] + 1;
                owner[o as usize] = owner[f as usize];
                queue.push_back(o);
            }
        }
    }
    (dist, owner)
}

/// Two far-apart nodes of `adj` (not empty): `a` the farthest from node 0, `b` the farthest
/// from `a` (ties to the lower index), and every node's distance in steps from `a`.
fn far_apart(adj: &[Vec<u32>]) -> (u32, u32, Vec<u32>) {
    let farthest = |dist: &[u32]| -> u32 {
        (0..dist.len() as u32)
            .max_by_key(|&f| (dist[f as usize] != u32::MAX, dist[f as usize], std::cmp::Reverse(f)))
            .unwrap_or(0)
    };
    let a = farthest(&breadth_first(adj, &[0]).0);
    let from_a = breadth_first(adj, &[a]).0;
    let b = farthest(&from_a);
    (a, b, from_a)
}

/// Every edge of the faces not `collapsed` as `(low << 32 | high, face, edge)`, sorted: the uses
/// of one edge are adjacent, in face order. Why sorted and not a map of lists: `cut_to_disc`
/// asks [`separate_fans`] and [`Patch::edge_graph`] once a hole, on the whole patch, and a
/// marching-cubes island has hundreds of holes (with maps of lists the two were 15% and 7% of
/// the unruly vase's `injective`).
fn sorted_edge_uses(corners: &[[u32; 3]], collapsed: &[bool]) -> Vec<(u64, u32, u8)> {
    let mut uses: Vec<(u64, u32, u8)> = Vec::with_capacity(3 * corners.len());
    for (t, c) in corners.iter().enumerate().filter(|(t, _)| !collapsed[*t]) {
        for k in 0..3 {
            let (a, b) = (c[k], c[(k + 1) % 3]);
            uses.push((u64::from(a.min(b)) << 32 | u64::from(a.max(b)), t as u32, k as u8));
        }
    }
    uses.sort_unstable();
    uses
}

/// `corners` with every unknown whose live faces form several fans given one unknown per fan:
/// the first fan (in face order) keeps it, the others get new ones. Two faces are in one fan of
/// an unknown when they are joined across an edge at it that exactly two live faces use, in
/// opposite directions, and that is not in `cut`. So two pieces touching at one point (a
/// "bowtie"), edges of three or more faces, faces wound against their neighbours and the edges
/// of `cut` all become boundary. Returns the corners and the new number of unknowns.
fn separate_fans(
    mut corners: Vec<[u32; 3]>,
    collapsed: &[bool],
    n: usize,
    cut: &HashSet<(u32, u32)>,
) -> (Vec<[u32; 3]>, usize) {
    let uses = sorted_edge_uses(&corners, collapsed);
    // The corner of face `f` at unknown `x`, `f`'s edge `k` having `x` as an end.
    let corner_at = |corners: &[[u32; 3]], f: u32, k: usize, x: u32| -> u32 {
        let j = if corners[f as usize][k] == x { k } else { (k + 1) % 3 };
        3 * f + j as u32
    };
    // The fans are the classes of the corners joined here, whatever order they are joined in.
    let mut dsu = crate::uvstats::Dsu::new(3 * corners.len());
    for edge in uses.chunk_by(|x, y| x.0 == y.0) {
        let &[(_, f, kf), (_, g, kg)] = edge else { continue };
        let (kf, kg) = (kf as usize, kg as usize);
        let (a, b) = (corners[f as usize][kf], corners[f as usize][(kf + 1) % 3]);
        if !cut.contains(&(a.min(b), a.max(b))) && corners[g as usize][kg] == b {
            for x in [a, b] {
                dsu.union(corner_at(&corners, f, kf, x), corner_at(&corners, g, kg, x));
            }
        }
    }
    let mut fan_of: HashMap<u32, u32> = HashMap::new();
    let mut owner_root: Vec<u32> = vec![u32::MAX; n];
    let mut next = n as u32;
    for (t, c) in corners.iter_mut().enumerate() {
        if collapsed[t] {
            continue;
        }
        for (k, corner) in c.iter_mut().enumerate() {
            let v = *corner as usize;
            let root = dsu.find(3 * t as u32 + k as u32);
            if owner_root[v] == u32::MAX {
                owner_root[v] = root;
            } else if owner_root[v] != root {
                let id = *fan_of.entry(root).or_insert_with(|| {
                    next += 1;
                    next - 1
                });
                *corner = id;
            }
        }
    }
    (corners, next as usize)
}

/// The mean length of the first two edges of the triangles (1 when there are none).
pub(crate) fn mean_edge(tris: &[(usize, [[f64; 2]; 3])]) -> f64 {
    if tris.is_empty() {
        return 1.0;
    }
    let sum: f64 = tris
        .iter()
        .map(|(_, q)| {
            (q[1][0] - q[0][0]).hypot(q[1][1] - q[0][1]) + (q[2][0] - q[0][0]).hypot(q[2][1] - q[0][1])
        })
        .sum();
    sum / (2 * tris.len()) as f64
}

/// Triangles in a hashed uniform grid (cells of twice a typical edge), for overlap queries.
/// Triangles over more than [`TriangleGrid::MAX_CELLS`] cells are kept aside and tested against
/// every query, and such a query tests everything, so the answers are exact.
pub(crate) struct TriangleGrid {
    cell: f64,
    cells: HashMap<(i64, i64), Vec<u32>>,
    big: Vec<u32>,
    tris: Vec<[[f64; 2]; 3]>,
}

impl TriangleGrid {
    const MAX_CELLS: i64 = 4096;

    /// A grid holding `start`, with cells of twice `edge`.
    pub(crate) fn new(start: &[(usize, [[f64; 2]; 3])], edge: f64) -> TriangleGrid {
        let cell = (2.0 * edge).max(f64::MIN_POSITIVE);
        let mut g = TriangleGrid { cell, cells: HashMap::new(), big: Vec::new(), tris: Vec::new() };
        for (_, t) in start {
            g.insert(*t);
        }
        g
    }

    /// The cells `[x0, x1, y0, y1]` a triangle's bounding box covers, `None` when too many.
    fn range(&self, t: [[f64; 2]; 3]) -> Option<[i64; 4]> {
        let key = |x: f64| (x / self.cell).floor() as i64;
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for v in t {
            for k in 0..2 {
                lo[k] = lo[k].min(v[k]);
                hi[k] = hi[k].max(v[k]);
            }
        }
        let r = [key(lo[0]), key(hi[0]), key(lo[1]), key(hi[1])];
        ((r[1] - r[0] + 1).saturating_mul(r[3] - r[2] + 1) <= Self::MAX_CELLS).then_some(r)
    }

    pub(crate) fn insert(&mut self, t: [[f64; 2]; 3]) {
        let id = self.tris.len() as u32;
        self.tris.push(t);
        match self.range(t) {
            Some([x0, x1, y0, y1]) => {
                for x in x0..=x1 {
                    for y in y0..=y1 {
                        self.cells.entry((x, y)).or_default().push(id);
                    }
                }
            }
            None => self.big.push(id),
        }
    }

    /// The stored triangles that `t` overlaps ([`triangles_overlap`]), by insertion index; one
    /// may be listed more than once.
    pub(crate) fn overlapping(&self, t: [[f64; 2]; 3]) -> Vec<u32> {
        let hit = |&i: &u32| triangles_overlap(t, self.tris[i as usize]);
        let Some([x0, x1, y0, y1]) = self.range(t) else {
            return (0..self.tris.len() as u32).filter(hit).collect();
        };
        let mut out: Vec<u32> = self.big.iter().copied().filter(hit).collect();
        for x in x0..=x1 {
            for y in y0..=y1 {
                if let Some(ids) = self.cells.get(&(x, y)) {
                    out.extend(ids.iter().copied().filter(hit));
                }
            }
        }
        out
    }
}

/// Whether two counter-clockwise triangles' interiors intersect: no edge of either has the other
/// wholly on its outer side or on it (separating axes of two convex polygons).
fn triangles_overlap(a: [[f64; 2]; 3], b: [[f64; 2]; 3]) -> bool {
    let separated = |s: [[f64; 2]; 3], t: [[f64; 2]; 3]| {
        (0..3).any(|k| {
            let (o, e) = (s[k], s[(k + 1) % 3]);
            t.iter().all(|v| (e[0] - o[0]) * (v[1] - o[1]) - (e[1] - o[1]) * (v[0] - o[0]) <= 0.0)
        })
    };
    !separated(a, b) && !separated(b, a)
}

/// Per vertex, its neighbours and the rest lengths of the edges to them.
type Adjacency = Vec<Vec<(u32, f64)>>;

/// Dijkstra over `adj` from the `sources` (distance 0), entering only vertices `may_enter`
/// accepts; stops at the first vertex popped that `is_target` accepts. Returns the distances,
/// each vertex's predecessor (`u32::MAX` for sources and unreached ones) and the target reached.
pub(crate) fn shortest_paths(
    adj: &[Vec<(u32, f64)>],
    sources: &[u32],
    is_target: impl Fn(u32) -> bool,
    may_enter: impl Fn(u32) -> bool,
) -> (Vec<f64>, Vec<u32>, Option<u32>) {
    let mut dist = vec![f64::INFINITY; adj.len()];
    let mut prev = vec![u32::MAX; adj.len()];
    let mut heap = std::collections::BinaryHeap::new();
    for &v in sources {
        dist[v as usize] = 0.0;
        heap.push((std::cmp::Reverse(OrdF64(0.0)), v));
    }
    while let Some((std::cmp::Reverse(OrdF64(d)), v)) = heap.pop() {
        if d > dist[v as usize] {
            continue;
        }
        if is_target(v) {
            return (dist, prev, Some(v));
        }
        for &(w, l) in &adj[v as usize] {
            let nd = d + l;
            if nd < dist[w as usize] && may_enter(w) {
                dist[w as usize] = nd;
                prev[w as usize] = v;
                heap.push((std::cmp::Reverse(OrdF64(nd)), w));
            }
        }
    }
    (dist, prev, None)
}

/// The edges of the path that [`shortest_paths`]' `prev` leads along from `v` back to its source,
/// as `(prev[w], w)` from `v`'s end.
pub(crate) fn path_back(prev: &[u32], mut v: u32) -> Vec<(u32, u32)> {
    let mut edges = Vec::new();
    while prev[v as usize] != u32::MAX {
        let u = prev[v as usize];
        edges.push((u, v));
        v = u;
    }
    edges
}

/// Bounded Dijkstra balls on one graph, reusing their distance array between calls.
struct Ball {
    dist: Vec<f64>,
    touched: Vec<u32>,
}

impl Ball {
    fn new(n: usize) -> Ball {
        Ball { dist: vec![f64::INFINITY; n], touched: Vec::new() }
    }

    /// The vertices within `radius` of `v` along `adj`'s edges (`v` first).
    fn around(&mut self, adj: &[Vec<(u32, f64)>], v: u32, radius: f64) -> Vec<u32> {
        for &w in &self.touched {
            self.dist[w as usize] = f64::INFINITY;
        }
        self.touched.clear();
        let mut heap = std::collections::BinaryHeap::new();
        self.dist[v as usize] = 0.0;
        self.touched.push(v);
        heap.push((std::cmp::Reverse(OrdF64(0.0)), v));
        let mut inside = Vec::new();
        while let Some((std::cmp::Reverse(OrdF64(d)), u)) = heap.pop() {
            if d > self.dist[u as usize] {
                continue;
            }
            inside.push(u);
            for &(w, l) in &adj[u as usize] {
                let nd = d + l;
                if nd <= radius && nd < self.dist[w as usize] {
                    if self.dist[w as usize].is_infinite() {
                        self.touched.push(w);
                    }
                    self.dist[w as usize] = nd;
                    heap.push((std::cmp::Reverse(OrdF64(nd)), w));
                }
            }
        }
        inside
    }
}

/// An `f64` ordered by [`f64::total_cmp`], for the Dijkstra heap.
#[derive(Clone, Copy, PartialEq)]
struct OrdF64(f64);

impl Eq for OrdF64 {}

impl PartialOrd for OrdF64 {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}

impl Ord for OrdF64 {
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        self.0.total_cmp(&other.0)
    }
}

/// The smallest positive root of `a t² + b t + c` (infinity when there is none).
fn smallest_positive_root(a: f64, b: f64, c: f64) -> f64 {
    let scale = a.abs().max(b.abs()).max(c.abs());
    if scale == 0.0 {
        return f64::INFINITY;
    }
    let (a, b, c) = (a / scale, b / scale, c / scale);
    let positive = |t: f64| if t > 0.0 && t.is_finite() { t } else { f64::INFINITY };
    if a.abs() < 1e-12 {
        return if b.abs() < 1e-300 { f64::INFINITY } else { positive(-c / b) };
    }
    let disc = b * b - 4.0 * a * c;
    if disc < 0.0 {
        return f64::INFINITY;
    }
    // Numerically stable pair of roots.
    let q = -0.5 * (b + b.signum() * disc.sqrt());
    let (r1, r2) = (q / a, if q != 0.0 { c / q } else { f64::INFINITY });
    positive(r1).min(positive(r2))
}

/// Whether any two boundary segments that share no endpoint cross (module docs), found
/// through a hashed uniform grid of the segments' bounding boxes.
fn boundary_crosses(loops: &[Vec<u32>], p: &[[f64; 2]]) -> bool {
    let segments: Vec<[u32; 2]> =
        loops.iter().flat_map(|l| (0..l.len()).map(move |i| [l[i], l[(i + 1) % l.len()]])).collect();
    if segments.len() < 3 {
        return false;
    }
    let total: f64 = segments
        .iter()
        .map(|s| {
            let (a, b) = (p[s[0] as usize], p[s[1] as usize]);
            (b[0] - a[0]).hypot(b[1] - a[1])
        })
        .sum();
    let cell = (2.0 * total / segments.len() as f64).max(f64::MIN_POSITIVE);
    let mut grid: HashMap<(i64, i64), Vec<u32>> = HashMap::new();
    let key = |x: f64| (x / cell).floor() as i64;
    for (i, s) in segments.iter().enumerate() {
        let (a, b) = (p[s[0] as usize], p[s[1] as usize]);
        let (x0, x1) = (key(a[0].min(b[0])), key(a[0].max(b[0])));
        let (y0, y1) = (key(a[1].min(b[1])), key(a[1].max(b[1])));
        if (x1 - x0 + 1).saturating_mul(y1 - y0 + 1) > 4 * segments.len() as i64 {
            // A segment as long as the whole boundary: test it against everything.
            for j in 0..segments.len() {
                if j != i && segments_cross(segments[i], segments[j], p) {
                    return true;
                }
            }
            continue;
        }
        for x in x0..=x1 {
            for y in y0..=y1 {
                let bucket = grid.entry((x, y)).or_default();
                for &j in bucket.iter() {
                    if segments_cross(*s, segments[j as usize], p) {
                        return true;
                    }
                }
                bucket.push(i as u32);
            }
        }
    }
    false
}

/// Whether segments `s` and `t` (unknown pairs) cross properly: each has its ends strictly on
/// both sides of the other's line. Segments that only touch (an end on the other, collinear
/// overlap, a slit whose sides coincide) do not: they cover no area twice.
fn segments_cross(s: [u32; 2], t: [u32; 2], p: &[[f64; 2]]) -> bool {
    if s[0] == t[0] || s[0] == t[1] || s[1] == t[0] || s[1] == t[1] {
        return false;
    }
    let [a, b] = s.map(|i| p[i as usize]);
    let [c, d] = t.map(|i| p[i as usize]);
    let orient =
        |o: [f64; 2], u: [f64; 2], v: [f64; 2]| (u[0] - o[0]) * (v[1] - o[1]) - (u[1] - o[1]) * (v[0] - o[0]);
    let (d1, d2, d3, d4) = (orient(c, d, a), orient(c, d, b), orient(a, b, c), orient(a, b, d));
    ((d1 > 0.0 && d2 < 0.0) || (d1 < 0.0 && d2 > 0.0)) && ((d3 > 0.0 && d4 < 0.0) || (d3 < 0.0 && d4 > 0.0))
}

/// The free space round a patch inside a box, triangulated (constrained Delaunay, `spade`), whose
/// triangles join the SLIM energy with their current shape as rest shape and small weights, and
/// the flip-avoiding line search (Jiang, Schaefer, Panozzo, "Simplicial Complex Augmentation
/// Framework for Bijective Maps", 2017): while no scaffold triangle flips, no part of the
/// boundary can cross another, and as two parts approach, the triangles between them are
/// squeezed and push back. Rebuilt every round.
struct Scaffold {
    /// Triangles; a vertex `< n` is an unknown of the patch (the one a glued group moves as),
    /// `n + k` the fixed box corner `k`.
    tris: Vec<[u32; 3]>,
    rest: Vec<Rest>,
    /// Every triangle's weight: [`SCAFFOLD_WEIGHT`] of the patch's, shared equally.
    weight: f64,
    corners: [[f64; 2]; 4],
    n: usize,
}

impl Scaffold {
    /// The scaffold round `p`, on the glued boundary points (`glue`, from
    /// `Patch::coincident_boundary`); `None` when the boundary cannot be triangulated as it is
    /// (two boundary vertices at one point that are not glued, touching boundary segments, no
    /// boundary).
    fn build(patch: &Patch, p: &[[f64; 2]], glue: &[u32]) -> Option<Scaffold> {
        use spade::handles::FixedVertexHandle;
        use spade::{ConstrainedDelaunayTriangulation, Point2, Triangulation};
        let loops = &patch.topology.loops;
        // One triangulation vertex per glued boundary point (`Patch::coincident_boundary`).
        let mut ids: Vec<u32> = Vec::new();
        let mut vertex_of: HashMap<u32, usize> = HashMap::new();
        for &v in loops.iter().flatten() {
            let g = glue[v as usize];
            vertex_of.entry(g).or_insert_with(|| {
                ids.push(g);
                ids.len() - 1
            });
        }
        if ids.len() < 3 {
            return None;
        }
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for &v in &ids {
            for k in 0..2 {
                lo[k] = lo[k].min(p[v as usize][k]);
                hi[k] = hi[k].max(p[v as usize][k]);
            }
        }
        let m = (hi[0] - lo[0]).max(hi[1] - lo[1]) * SCAFFOLD_MARGIN;
        if !(m > 0.0 && m.is_finite()) {
            return None;
        }
        let corners =
            [[lo[0] - m, lo[1] - m], [hi[0] + m, lo[1] - m], [hi[0] + m, hi[1] + m], [lo[0] - m, hi[1] + m]];
        let mut vertices: Vec<Point2<f64>> =
            ids.iter().map(|&v| Point2::new(p[v as usize][0], p[v as usize][1])).collect();
        vertices.extend(corners.iter().map(|c| Point2::new(c[0], c[1])));
        // Boundary edges between glued points, each once. An edge whose reverse is a boundary
        // edge too is a closed slit: both its sides are the patch's, so no scaffold grows there.
        let mut directed: Vec<[usize; 2]> = Vec::with_capacity(ids.len());
        let mut seen = HashSet::new();
        for l in loops {
            for i in 0..l.len() {
                let e = [l[i], l[(i + 1) % l.len()]].map(|v| vertex_of[&glue[v as usize]]);
                if e[0] != e[1] && seen.insert(e) {
                    directed.push(e);
                }
            }
        }
        let outer: Vec<[usize; 2]> =
            directed.iter().copied().filter(|e| !seen.contains(&[e[1], e[0]])).collect();
        let edges: Vec<[usize; 2]> =
            directed.into_iter().filter(|e| e[0] < e[1] || !seen.contains(&[e[1], e[0]])).collect();
        let mut conflicts = 0usize;
        let cdt = ConstrainedDelaunayTriangulation::<Point2<f64>>::try_bulk_load_cdt(
            vertices,
            edges.clone(),
            |_| conflicts += 1,
        )
        .ok()?;
        if conflicts > 0 || cdt.num_vertices() != ids.len() + 4 || cdt.num_constraints() != edges.len() {
            return None;
        }
        // The faces right of each boundary edge (the patch lies left of it) and everything
        // reachable from them without crossing a constraint.
        let mut scaffold = vec![false; cdt.num_all_faces()];
        let mut stack = Vec::new();
        for e in &outer {
            let edge = cdt.get_edge_from_neighbors(
                FixedVertexHandle::from_index(e[0]),
                FixedVertexHandle::from_index(e[1]),
            )?;
            if let Some(f) = edge.rev().face().as_inner() {
                stack.push(f.fix());
            }
        }
        while let Some(f) = stack.pop() {
            if std::mem::replace(&mut scaffold[f.index()], true) {
                continue;
            }
            for e in cdt.face(f).adjacent_edges() {
                if !e.as_undirected().is_constraint_edge()
                    && let Some(g) = e.rev().face().as_inner()
                    && !scaffold[g.index()]
                {
                    stack.push(g.fix());
                }
            }
        }
        let n = patch.n;
        let id = |i: usize| if i < ids.len() { ids[i] } else { (n + i - ids.len()) as u32 };
        let mut tris = Vec::new();
        for f in cdt.inner_faces() {
            if scaffold[f.fix().index()] {
                tris.push(f.vertices().map(|v| id(v.fix().index())));
            }
        }
        let total: f64 = patch.live().map(|(t, _)| patch.rest[t].weight).sum();
        let weight = SCAFFOLD_WEIGHT * total / tris.len().max(1) as f64;
        Scaffold { tris, rest: Vec::new(), weight, corners, n }.rested(p)
    }

    /// The same triangulation with its rest shapes taken at `p` (their shapes there, each of
    /// weight `self.weight`); `None` when a triangle is not positive at `p`.
    fn rested(mut self, p: &[[f64; 2]]) -> Option<Scaffold> {
        let rest = self
            .tris
            .iter()
            .map(|t| {
                let x = t.map(|v| self.pos(p, v));
                is_positive(area2(x)).then(|| Rest::new(x, self.weight, false))
            })
            .collect::<Option<Vec<Rest>>>()?;
        self.rest = rest;
        Some(self)
    }

    fn pos(&self, p: &[[f64; 2]], v: u32) -> [f64; 2] {
        if (v as usize) < self.n { p[v as usize] } else { self.corners[v as usize - self.n] }
    }

    /// The scaffold's energy at `p`; `None` when a triangle is not positive.
    fn energy(&self, p: &[[f64; 2]]) -> Option<f64> {
        let mut e = 0.0;
        for (t, r) in self.tris.iter().zip(&self.rest) {
            let d = sym_dirichlet(r.jacobian(t.map(|v| self.pos(p, v))));
            if !d.is_finite() {
                return None;
            }
            e += r.weight * d;
        }
        Some(e)
    }

    /// The first `t > 0` at which a scaffold triangle's area along `p + t d` reaches zero.
    fn max_step(&self, p: &[[f64; 2]], d: &[[f64; 2]]) -> f64 {
        let zero = [0.0, 0.0];
        let dir = |v: u32| if (v as usize) < self.n { d[v as usize] } else { zero };
        per_face(self.tris.len(), |k| {
            let t = self.tris[k];
            triangle_zero_step(t.map(|v| self.pos(p, v)), t.map(dir))
        })
        .into_iter()
        .fold(f64::INFINITY, f64::min)
    }
}

/// The first `t > 0` at which triangle `q + t d` has zero signed area (infinity when never).
fn triangle_zero_step(q: [[f64; 2]; 3], d: [[f64; 2]; 3]) -> f64 {
    let [a, b, c] = q;
    let [da, db, dc] = d;
    let (e1, e2) = ([b[0] - a[0], b[1] - a[1]], [c[0] - a[0], c[1] - a[1]]);
    let (f1, f2) = ([db[0] - da[0], db[1] - da[1]], [dc[0] - da[0], dc[1] - da[1]]);
    let cr = |x: [f64; 2], y: [f64; 2]| x[0] * y[1] - x[1] * y[0];
    smallest_positive_root(cr(f1, f2), cr(e1, f2) + cr(f1, e2), cr(e1, e2))
}

/// SLIM's reweighted least-squares terms of one face at UV triangle `q`: four rows for the
/// symmetric Dirichlet and conformal terms, the residuals `(W J)_{r,c} − (W T)_{r,c}`, and one
/// row for each of the orthogonal and equiareal terms that is on; `None` when the first four
/// are not finite.
///
/// With `J = U diag(σ₁, σ₂) Vᵀ`, the symmetric Dirichlet term is `‖W_d (J − U Vᵀ)‖²` (the closest
/// rotation) and the conformal term of [`slim_density`] `‖W_c (J − g U Vᵀ)‖²` (the closest
/// similarity, `g = √(σ₁σ₂)`), each weight `U diag(w) Uᵀ` with `w² = f′(σ) / (2 (σ − target))`
/// so that the proxy's gradient is the energy's (Rabinovich et al. 2017, and libigl's conformal
/// case). Both share `U`, so their sum is one term `‖W (J − T)‖²` up to a constant, with
/// `W = U diag(√(w_d² + w_c²)) Uᵀ` and `T = U diag((w_d² + w_c² g) / (w_d² + w_c²)) Vᵀ`: the
/// system keeps its four rows and its pattern.
///
/// The orthogonal and equiareal terms are each the square of one function of `J` (`√λ cos` of
/// [`axes_cos`], `√λ (det J − 1)`), whose Gauss–Newton proxy is the square of its linearisation
/// at the current `J`: one row over the same unknowns (the pattern stays), with the energy's
/// gradient there and a curvature only along the one direction the term sees. (An isotropic
/// proxy with the same gradient, `λ′ ‖J − T‖²`, stiffens every direction: tried first, it made
/// the horse's `injective` phase 3× slower.) A row that is not finite (a face squeezed to a
/// needle) is left out; the line search reads the true energy.
fn slim_terms(rest: &Rest, q: [[f64; 2]; 3], terms: Terms) -> Option<FaceRows> {
    let conformal = terms.conformal;
    let j = rest.jacobian(q);
    let svd = Svd2::of(j);
    let (s1, s2) = (svd.s1.max(WEIGHT_SIGMA_FLOOR), svd.s2.max(WEIGHT_SIGMA_FLOOR));
    // Symmetric Dirichlet: w² = f'(σ) / (2 (σ − 1)) = (σ + 1)(σ² + 1) / σ³.
    let dirichlet = |s: f64| (s + 1.0) * (s * s + 1.0) / (s * s * s);
    // Conformal, λ (σ₁/σ₂ + σ₂/σ₁ − 2): w₁² = λ (σ₁ + σ₂)(√σ₁ + √σ₂) / (2 σ₁² σ₂ √σ₁), and w₂²
    // with the roles swapped (the quotient f′ / (σ − g) in closed form, finite at σ₁ = σ₂).
    let (r1, r2) = (s1.sqrt(), s2.sqrt());
    let common = conformal * (s1 + s2) * (r1 + r2) / (2.0 * s1 * s2);
    let (c1, c2) = (common / (s1 * r1), common / (s2 * r2));
    let g = r1 * r2;
    let (d1, d2) = (dirichlet(s1), dirichlet(s2));
    let (o1, o2) = (d1 + c1, d2 + c2);
    let (t1, t2) = ((d1 + c1 * g) / o1, (d2 + c2 * g) / o2);
    let w = svd.along_u(o1.sqrt(), o2.sqrt());
    let wr = svd.with_values(o1.sqrt() * t1, o2.sqrt() * t2);
    let mut rows = [[0.0f64; 6]; 6];
    let mut targets = [0.0f64; 6];
    for r in 0..2 {
        for col in 0..2 {
            let a = &mut rows[2 * r + col];
            for s in 0..2 {
                for k in 0..3 {
                    a[3 * s + k] = w[r][s] * rest.g[k][col];
                }
            }
            targets[2 * r + col] = wr[r][col];
        }
    }
    if !rows[..4].iter().flatten().chain(&targets[..4]).all(|x| x.is_finite()) {
        return None;
    }
    let mut out = FaceRows { rows, targets, len: 4 };
    if terms.orthogonal != 0.0 {
        // √λ (cos + ⟨G, J′ − J⟩) at the next J′, G the gradient of cos.
        let (c, g) = axes_cos(j);
        out.push_linear(rest, terms.orthogonal, g, frobenius(g, j) - c);
    }
    if terms.equiareal != 0.0 {
        // √λ (det + ⟨C, J′ − J⟩ − 1), the cofactor matrix C being det's gradient.
        let det = j[0][0] * j[1][1] - j[0][1] * j[1][0];
        let cof = [[j[1][1], -j[1][0]], [-j[0][1], j[0][0]]];
        out.push_linear(rest, terms.equiareal, cof, frobenius(cof, j) - det + 1.0);
    }
    Some(out)
}

/// The rows of one face's terms in SLIM's global step ([`slim_terms`]): the first `len` rows `a`
/// over the six local unknowns (`u` of corners 0–2, then `v`) with their targets, each the
/// residual `a · z − target`.
struct FaceRows {
    rows: [[f64; 6]; 6],
    targets: [f64; 6],
    len: usize,
}

impl FaceRows {
    fn iter(&self) -> impl Iterator<Item = (&[f64; 6], f64)> {
        self.rows[..self.len].iter().zip(self.targets[..self.len].iter().copied())
    }

    /// Adds the residual `√weight (⟨G, J⟩ − target)` of a linear function `⟨G, J⟩` of the
    /// face's Jacobian (`J = Σ_k q_k ⊗ g_k`), unless it is not finite.
    fn push_linear(&mut self, rest: &Rest, weight: f64, g: [[f64; 2]; 2], target: f64) {
        let root = weight.sqrt();
        let mut a = [0.0f64; 6];
        for s in 0..2 {
            for k in 0..3 {
                a[3 * s + k] = root * (g[s][0] * rest.g[k][0] + g[s][1] * rest.g[k][1]);
            }
        }
        let t = root * target;
        if a.iter().all(|x| x.is_finite()) && t.is_finite() {
            self.rows[self.len] = a;
            self.targets[self.len] = t;
            self.len += 1;
        }
    }
}

/// `⟨a, b⟩`, the Frobenius product of two 2×2 matrices.
fn frobenius(a: [[f64; 2]; 2], b: [[f64; 2]; 2]) -> f64 {
    a[0][0] * b[0][0] + a[0][1] * b[0][1] + a[1][0] * b[1][0] + a[1][1] * b[1][1]
}

/// A fixed sparsity pattern of the SLIM global step's 2n × 2n matrix (lower triangle) for a list
/// of triangles over the patch's unknowns, where each triangle's entries land in it, and its
/// symbolic factorisation (fill-reducing ordering and elimination structure). Built once for a
/// set of triangles and refilled every round: building it (then from sorted entries) cost over
/// twice what the numeric factorisation does, measured on the bunny's bake; built from the
/// unknowns' graph ([`Pattern::new`]), about half of it on the horse's (2.4 s of CPU for 197
/// patterns against 4.9 s for 436 factorisations).
///
/// Tried and left: faer's supernode amalgamation (`relax`) looser or tighter than its default
/// changed the horse's factorisation time by no more than the run-to-run noise.
///
/// The factorisation is always supernodal (faer's default picks simplicial for these sparse
/// systems by their flop ratio): measured on the Common Shapes bunny's bake, `injective` took
/// 5.6 s simplicial and 3.8 s supernodal, the necks pass 5.7 and 4.6 s, with the same atlas;
/// the fragmented inputs' thousands of small islands took no longer, and their scores moved by
/// the other rounding's later choices (−0.0003 to −0.0005, BENCHMARKS.md). It runs sequentially
/// (`Par::Seq`) inside each island, as islands are solved in parallel, so the result does not
/// depend on the thread count. Tried and left: faer's parallel factorisation (`Par::rayon`, the
/// `rayon` feature) gave the same bits on the horse but made `injective` slower (6.0 s against
/// 4.5–5.1 s; these systems' supernodes are too small to share).
struct Pattern {
    matrix: SparseColMat<usize, f64>,
    /// Per triangle, the value index of each `(x, y)` pair of its 6 local unknowns (`u` of
    /// corners 0–2, then `v`) whose system rows ([`Pattern::row`]) satisfy `row(x) ≥ row(y)`;
    /// `usize::MAX` for the other pairs and for a corner `≥ n`, which is a fixed point (a
    /// scaffold's box corner) with no row.
    slots: Vec<[[usize; 6]; 6]>,
    /// The value index of each diagonal entry, by system row.
    diagonal: Vec<usize>,
    symbolic: SymbolicCholesky<usize>,
    /// The factor's values, refilled by every numeric factorisation.
    factor: Vec<f64>,
    /// Scratch space of the numeric factorisation and the solve.
    scratch: MemBuffer,
    /// Per unknown, its place in the fill-reducing order: its `u` is system row `2 · rank`,
    /// its `v` the next.
    rank: Vec<usize>,
}

impl Pattern {
    /// The pattern of `triangles` (corners: unknowns `< n`, fixed points `≥ n`) plus the full
    /// diagonal and every vertex's own `(v, u)` entry (a structural zero for an unknown in no
    /// triangle: one glued to another); `None` when the symbolic factorisation fails.
    ///
    /// Built from the unknowns' graph ([`UnknownGraph`]), not from the 36 entries of every
    /// triangle: each vertex's `u` and `v` couple with the same neighbours, so the 2n × 2n
    /// pattern is the vertex graph's with every vertex a 2 × 2 block, and its columns can be
    /// written out in order. The fill-reducing ordering is the vertex graph's AMD ordering with
    /// each vertex's `u` and `v` kept together: the same elimination AMD finds on the whole
    /// system (the two are indistinguishable nodes there), found on a graph with a quarter of
    /// the entries. Measured on the horse's bake, building patterns from the triangles' entries
    /// took a third of SLIM's CPU time, this way a quarter.
    ///
    /// The system is numbered in that order already ([`Pattern::row`]), so faer factorises it
    /// as it stands (`SymmetricOrdering::Identity`): given the ordering instead, it copied the
    /// matrix into its permuted form before every numeric factorisation and the right-hand side
    /// before every solve (5% of the horse's `injective` phase).
    fn new(n: usize, triangles: &[[u32; 3]]) -> Option<Pattern> {
        let graph = UnknownGraph::new(n, triangles)?;
        let (col_ptr, row_idx) = graph.system_columns();
        let matrix = SparseColMat::new(
            SymbolicSparseColMat::new_checked(2 * n, 2 * n, col_ptr, None, row_idx),
            vec![0.0; graph.system_entries()],
        );
        let slots = graph.slots(triangles);
        // Every column's first entry is its diagonal (type docs of `UnknownGraph`).
        let diagonal = graph.col_ptr[..2 * n].to_vec();
        let params = CholeskySymbolicParams {
            supernodal_flop_ratio_threshold: SupernodalThreshold::FORCE_SUPERNODAL,
            ..Default::default()
        };
        // Given no ordering, faer reads the pattern as an upper triangle (whatever the side):
        // its symbolic factorisation is given the transpose, the numeric one the lower triangle.
        let (upper_ptr, upper_rows) = graph.upper_columns();
        let upper = SymbolicSparseColMat::new_checked(2 * n, 2 * n, upper_ptr, None, upper_rows);
        let symbolic =
            factorize_symbolic_cholesky(upper.as_ref(), Side::Upper, SymmetricOrdering::Identity, params)
                .ok()?;
        let factor = vec![0.0; symbolic.len_val()];
        let req = symbolic
            .factorize_numeric_llt_scratch::<f64>(Par::Seq, Default::default())
            .or(symbolic.solve_in_place_scratch::<f64>(1, Par::Seq));
        let scratch = MemBuffer::try_new(req).ok()?;
        Some(Pattern { matrix, slots, diagonal, symbolic, factor, scratch, rank: graph.rank })
    }

    /// The system row of unknown `v`'s `u` (`component` 0) or `v` (1).
    fn row(&self, v: usize, component: usize) -> usize {
        system_row(&self.rank, v, component)
    }

    /// Factorises the matrix as its values stand and solves `matrix · x = rhs` in place (both in
    /// system rows); `None` when the matrix is not positive definite.
    fn solve_in_place(&mut self, rhs: &mut Mat<f64>) -> Option<()> {
        let Pattern { matrix, symbolic, factor, scratch, .. } = self;
        symbolic
            .factorize_numeric_llt(
                factor,
                matrix.as_ref(),
                Side::Lower,
                Default::default(),
                Par::Seq,
                MemStack::new(scratch),
                Default::default(),
            )
            .ok()?;
        let llt = LltRef::new(symbolic, factor);
        llt.solve_in_place_with_conj(Conj::No, rhs.as_mut(), Par::Seq, MemStack::new(scratch));
        Some(())
    }
}

/// The graph of a SLIM system's unknowns, in its fill-reducing order: per vertex `j < n` (by
/// rank), the vertices `< n` it shares a triangle with, itself included, sorted by rank
/// (`full`); fixed points (corners `≥ n`) have no node. The system's lower triangle, with `u` of
/// the vertex of rank `r` as row `2r` and its `v` as row `2r + 1`, is in column `2j` (`u_j`):
/// rows `2r, 2r + 1` for the neighbours `r ≥ j`; in column `2j + 1` (`v_j`): row `2j + 1`, then
/// rows `2r, 2r + 1` for the neighbours `r > j`. Rows come out sorted, so the columns are
/// written directly.
struct UnknownGraph {
    /// `full[start[j]..start[j + 1]]`: the neighbours of the vertex of rank `j`, by rank.
    start: Vec<usize>,
    full: Vec<usize>,
    /// Per rank, where its neighbours `≥ j` begin in its slice of `full`.
    lower: Vec<usize>,
    /// Per system column (`2n`), where it begins among the system's entries.
    col_ptr: Vec<usize>,
    /// Per vertex (the triangles' numbering), its rank.
    rank: Vec<usize>,
}

impl UnknownGraph {
    /// The graph of `triangles`, ranked by the vertex graph's AMD ordering; `None` when AMD
    /// fails.
    fn new(n: usize, triangles: &[[u32; 3]]) -> Option<UnknownGraph> {
        let (start, full) = vertex_graph(n, triangles);
        // The AMD ordering of the vertex graph: `fwd[rank]` is the vertex, `rank[vertex]` its rank.
        let graph = SymbolicSparseColMatRef::new_checked(n, n, &start, None, &full);
        let (mut fwd, mut rank) = (vec![0usize; n], vec![0usize; n]);
        let mut scratch = MemBuffer::try_new(amd::order_scratch::<usize>(n, full.len())).ok()?;
        amd::order(&mut fwd, &mut rank, graph, amd::Control::default(), MemStack::new(&mut scratch)).ok()?;
        // The same graph with every vertex replaced by its rank, neighbours sorted by rank.
        let mut ranked_start = Vec::with_capacity(n + 1);
        ranked_start.push(0);
        let mut ranked = Vec::with_capacity(full.len());
        for &v in &fwd {
            let at = ranked.len();
            ranked.extend(full[start[v]..start[v + 1]].iter().map(|&w| rank[w]));
            ranked[at..].sort_unstable();
            ranked_start.push(ranked.len());
        }
        let (start, full) = (ranked_start, ranked);
        let lower: Vec<usize> =
            (0..n).map(|j| full[start[j]..start[j + 1]].partition_point(|&r| r < j)).collect();
        let mut col_ptr = Vec::with_capacity(2 * n + 1);
        col_ptr.push(0);
        for j in 0..n {
            let below = 2 * (start[j + 1] - start[j] - lower[j]);
            col_ptr.push(col_ptr[2 * j] + below);
            col_ptr.push(col_ptr[2 * j + 1] + below - 1);
        }
        Some(UnknownGraph { start, full, lower, col_ptr, rank })
    }

    fn n(&self) -> usize {
        self.lower.len()
    }

    /// The neighbours `≥ j` of rank `j`, by rank (the first is `j` itself).
    fn below(&self, j: usize) -> &[usize] {
        &self.full[self.start[j] + self.lower[j]..self.start[j + 1]]
    }

    fn system_entries(&self) -> usize {
        self.col_ptr[2 * self.n()]
    }

    /// The system's column pointers and row indices (type docs).
    fn system_columns(&self) -> (Vec<usize>, Vec<usize>) {
        let n = self.n();
        let mut rows = Vec::with_capacity(self.system_entries());
        for j in 0..n {
            let below = self.below(j);
            rows.extend(below.iter().flat_map(|&r| [2 * r, 2 * r + 1]));
            rows.extend(below.iter().flat_map(|&r| [2 * r, 2 * r + 1]).skip(1));
        }
        (self.col_ptr.clone(), rows)
    }

    /// The column pointers and row indices of the system's upper triangle (the transpose of
    /// [`UnknownGraph::system_columns`]): in column `2j`, rows `2r, 2r + 1` for the neighbours
    /// `r < j`, then `2j`; in column `2j + 1`, the same and `2j + 1`.
    fn upper_columns(&self) -> (Vec<usize>, Vec<usize>) {
        let n = self.n();
        let mut col_ptr = Vec::with_capacity(2 * n + 1);
        let mut rows = Vec::with_capacity(self.system_entries());
        col_ptr.push(0);
        for j in 0..n {
            let above = &self.full[self.start[j]..self.start[j] + self.lower[j]];
            for last in [2 * j, 2 * j + 1] {
                rows.extend(above.iter().flat_map(|&r| [2 * r, 2 * r + 1]));
                rows.extend(2 * j..=last);
                col_ptr.push(rows.len());
            }
        }
        (col_ptr, rows)
    }

    /// Per triangle, the value index of each `(x, y)` pair of its local unknowns ([`Pattern`]'s
    /// `slots`): one search per pair of corners, whose four entries lie side by side.
    fn slots(&self, triangles: &[[u32; 3]]) -> Vec<[[usize; 6]; 6]> {
        let n = self.n();
        triangles
            .par_iter()
            .with_min_len(FACES_PER_TASK)
            .map(|c| {
                let mut s = [[usize::MAX; 6]; 6];
                for a in 0..3 {
                    for b in 0..3 {
                        let (va, vb) = (c[a] as usize, c[b] as usize);
                        if va >= n || vb >= n || self.rank[va] < self.rank[vb] {
                            continue;
                        }
                        let (k, j) = (self.rank[va], self.rank[vb]);
                        let at = self.below(j).binary_search(&k).expect("entry in the pattern");
                        for ca in 0..2 {
                            for cb in 0..2 {
                                let (r, col) = (2 * k + ca, 2 * j + cb);
                                if r >= col {
                                    s[3 * ca + a][3 * cb + b] = self.col_ptr[col] + 2 * at + ca - cb;
                                }
                            }
                        }
                    }
                }
                s
            })
            .collect()
    }
}

/// The system row of unknown `v`'s `u` (`component` 0) or `v` (1), `rank` the unknowns' places
/// in the fill-reducing order ([`Pattern::row`], for where the pattern is borrowed in parts).
fn system_row(rank: &[usize], v: usize, component: usize) -> usize {
    2 * rank[v] + component
}

/// The adjacency of the unknowns `< n` that `triangles` join, each vertex its own neighbour, as
/// compressed sorted lists (`full[start[v]..start[v + 1]]`). Bucketed by vertex, then each
/// short list sorted on its own: sorting all the pairs at once took a fifth of building a
/// pattern.
fn vertex_graph(n: usize, triangles: &[[u32; 3]]) -> (Vec<usize>, Vec<usize>) {
    let inner = |c: &[u32; 3]| c.map(|v| (v as usize) < n);
    let mut start = vec![0usize; n + 1];
    for c in triangles {
        let inside = inner(c);
        let others = inside.iter().filter(|&&i| i).count().saturating_sub(1);
        for a in 0..3 {
            if inside[a] {
                start[c[a] as usize + 1] += others;
            }
        }
    }
    for v in 0..n {
        start[v + 1] += start[v] + 1;
    }
    let mut next: Vec<usize> = start[..n].to_vec();
    let mut full = vec![0usize; start[n]];
    for v in 0..n {
        full[next[v]] = v;
        next[v] += 1;
    }
    for c in triangles {
        let inside = inner(c);
        for a in 0..3 {
            for b in 0..3 {
                if a != b && inside[a] && inside[b] {
                    let x = c[a] as usize;
                    full[next[x]] = c[b] as usize;
                    next[x] += 1;
                }
            }
        }
    }
    // Sorted and without repeats, moved down over the repeats removed before it.
    let mut kept = 0;
    let mut from = 0;
    for v in 0..n {
        let end = start[v + 1];
        full[from..end].sort_unstable();
        start[v] = kept;
        let mut last = usize::MAX;
        for i in from..end {
            if full[i] != last {
                last = full[i];
                full[kept] = last;
                kept += 1;
            }
        }
        from = end;
    }
    start[n] = kept;
    full.truncate(kept);
    (start, full)
}

/// The SLIM global step's system: the island's pattern (fixed for the whole run, built when first
/// needed), the pattern with the current scaffold's triangles (kept as long as the scaffold is),
/// the glue, and the proximal weight.
struct SlimSystem {
    /// The island's faces alone, on the glued unknowns; built by the first
    /// [`SlimSystem::global`], as most solves never call it (every round has a scaffold), and a
    /// pattern's symbolic factorisation costs about what a numeric one does.
    island: Option<Pattern>,
    /// The island's faces followed by the scaffold's triangles, for the scaffold it was built for.
    with_scaffold: Option<Pattern>,
    /// Per unknown, the unknown it moves with (`Patch::coincident_boundary`): faces are assembled
    /// on the glued unknowns, and an unknown glued to another keeps only the proximal term and
    /// takes the other's solution.
    glue: Vec<u32>,
    /// Diagonal proximal weight, `1e-4 ×` the mean face weight: keeps the system positive
    /// definite (translations are otherwise free) and each step small where nothing pulls.
    proximal: f64,
    /// The terms besides the symmetric Dirichlet energy ([`InjectiveOptions::terms`]).
    terms: Terms,
}

impl SlimSystem {
    fn new(patch: &Patch, glue: Vec<u32>, terms: Terms) -> SlimSystem {
        let live = patch.live().count().max(1);
        let proximal = 1e-4 * patch.live().map(|(t, _)| patch.rest[t].weight).sum::<f64>() / live as f64;
        SlimSystem { island: None, with_scaffold: None, glue, proximal, terms }
    }

    /// Forgets the scaffold's pattern: the next [`SlimSystem::global_scaffold`] builds one for
    /// the scaffold it is given.
    fn new_scaffold(&mut self) {
        self.with_scaffold = None;
    }

    /// The global step at `p`: the positions minimising `Σ_t A_t ‖W_t (J_t − R_t)‖² +
    /// proximal ‖q − p‖²`, with SLIM's weights `W_t` and rotations `R_t` of `p`.
    fn global(&mut self, patch: &Patch, p: &[[f64; 2]]) -> Option<Vec<[f64; 2]>> {
        if self.island.is_none() {
            let faces: Vec<[u32; 3]> = glued_faces(patch, &self.glue).map(|(c, _)| c).collect();
            self.island = Some(Pattern::new(patch.n, &faces)?);
        }
        let pattern = self.island.as_mut().expect("built above");
        let faces = glued_faces(patch, &self.glue);
        let x = solve(pattern, patch.n, self.proximal, self.terms, p, faces, &[])?;
        self.unglued(&x)
    }

    /// [`SlimSystem::global`] with the scaffold's triangles in the energy. The pattern is built
    /// on the first call after [`SlimSystem::new_scaffold`] and refilled on the later ones, so
    /// `sc` must be the same triangulation (its rest shapes may change) until then.
    fn global_scaffold(&mut self, patch: &Patch, p: &[[f64; 2]], sc: &Scaffold) -> Option<Vec<[f64; 2]>> {
        let glue = &self.glue;
        let all = || glued_faces(patch, glue).chain(sc.tris.iter().copied().zip(&sc.rest));
        if self.with_scaffold.is_none() {
            let corners: Vec<[u32; 3]> = all().map(|(c, _)| c).collect();
            self.with_scaffold = Some(Pattern::new(patch.n, &corners)?);
        }
        let pattern = self.with_scaffold.as_mut().expect("built above");
        let x = solve(pattern, patch.n, self.proximal, self.terms, p, all(), &sc.corners)?;
        self.unglued(&x)
    }

    /// The positions of a solved system (per unknown), every unknown at the position of the
    /// one it is glued to; `None` when not finite.
    fn unglued(&self, x: &[[f64; 2]]) -> Option<Vec<[f64; 2]>> {
        let q: Vec<[f64; 2]> = self.glue.iter().map(|&g| x[g as usize]).collect();
        q.iter().flatten().all(|v| v.is_finite()).then_some(q)
    }
}

/// The live faces of `patch` with their corners on the glued unknowns and their rest shapes, in
/// `Patch::live` order: the island's triangles of every SLIM system.
fn glued_faces<'p>(patch: &'p Patch, glue: &'p [u32]) -> impl Iterator<Item = ([u32; 3], &'p Rest)> + 'p {
    patch.live().map(move |(t, c)| (c.map(|v| glue[v as usize]), &patch.rest[t]))
}

/// Fills `pattern` with SLIM's reweighted terms of `triangles` (in the order the pattern was
/// built for; a corner `n + k` is the fixed point `fixed[k]`, whose terms go to the right-hand
/// side) and the proximal term at `p`, factorises it with the kept symbolic factorisation and
/// solves. `None` when a term is not finite or the factorisation fails.
fn solve<'r>(
    pattern: &mut Pattern,
    n: usize,
    proximal: f64,
    terms: Terms,
    p: &[[f64; 2]],
    triangles: impl Iterator<Item = ([u32; 3], &'r Rest)>,
    fixed: &[[f64; 2]],
) -> Option<Vec<[f64; 2]>> {
    let pos = |v: u32| if (v as usize) < n { p[v as usize] } else { fixed[v as usize - n] };
    let mut rhs = Mat::<f64>::zeros(2 * n, 1);
    {
        let Pattern { matrix, slots, diagonal, rank, .. } = &mut *pattern;
        let vals = matrix.val_mut();
        vals.iter_mut().for_each(|v| *v = 0.0);
        let triangles: Vec<([u32; 3], &Rest)> = triangles.collect();
        let mut faces = Vec::with_capacity(ASSEMBLY_BLOCK.min(triangles.len()));
        for (block, slots) in triangles.chunks(ASSEMBLY_BLOCK).zip(slots.chunks(ASSEMBLY_BLOCK)) {
            block
                .par_iter()
                .with_min_len(FACES_PER_TASK)
                .map(|&(verts, rest)| {
                    let rows = slim_terms(rest, verts.map(pos), rest.terms(terms))?;
                    Some(rows.system(rest.weight, verts, n, fixed))
                })
                .collect_into_vec(&mut faces);
            assemble(block, slots, &faces, rank, &mut rhs, vals)?;
        }
        for (i, q) in p.iter().enumerate() {
            rhs[(system_row(rank, i, 0), 0)] += proximal * q[0];
            rhs[(system_row(rank, i, 1), 0)] += proximal * q[1];
        }
        for &d in diagonal.iter() {
            vals[d] += proximal;
        }
    }
    pattern.solve_in_place(&mut rhs)?;
    Some((0..n).map(|i| [rhs[(pattern.row(i, 0), 0)], rhs[(pattern.row(i, 1), 0)]]).collect())
}

/// Triangles whose SLIM terms [`solve`] computes (in parallel) before adding them into the
/// system (in order): a block's terms take ~1.5 MB, where the whole island's would take 340
/// bytes a face.
const ASSEMBLY_BLOCK: usize = 8 * FACES_PER_TASK;

/// One face's share of SLIM's global step: the 6 × 6 block `weight · Σ a aᵀ` of its rows over
/// its local unknowns (`u` of corners 0–2, then `v`), and its part of the right-hand side,
/// `weight · Σ a (target − a · fixed)` (the fixed points' terms moved across). Summed per face
/// where the terms are computed, in parallel, so that what [`assemble`] adds in order, on one
/// thread, is one value per entry instead of one per row and entry (the assembly was a fifth
/// of the islands' solves' instructions, all of it sequential).
struct FaceSystem {
    block: [[f64; 6]; 6],
    rhs: [f64; 6],
}

impl FaceRows {
    /// This face's [`FaceSystem`] with `weight`, its corners `verts` (a corner `n + k` the fixed
    /// point `fixed[k]`).
    fn system(&self, weight: f64, verts: [u32; 3], n: usize, fixed: &[[f64; 2]]) -> FaceSystem {
        let mut out = FaceSystem { block: [[0.0; 6]; 6], rhs: [0.0; 6] };
        for (a, target) in self.iter() {
            let fixed_part: f64 = (0..6)
                .filter(|&y| verts[y % 3] as usize >= n)
                .map(|y| a[y] * fixed[verts[y % 3] as usize - n][y / 3])
                .sum();
            for ((row, rhs), &ax) in out.block.iter_mut().zip(&mut out.rhs).zip(a) {
                let wa = weight * ax;
                *rhs += wa * (target - fixed_part);
                for (entry, &ay) in row.iter_mut().zip(a) {
                    *entry += wa * ay;
                }
            }
        }
        out
    }
}

/// Adds the systems `faces` of the triangles `block` (each with its `slots`; a corner `≥ n`, `n`
/// the unknowns `rank` orders, is a fixed point with no row) into the system's values and
/// right-hand side (rows of [`Pattern::row`]), in order; `None` at the first triangle whose
/// terms are not finite.
fn assemble(
    block: &[([u32; 3], &Rest)],
    slots: &[[[usize; 6]; 6]],
    faces: &[Option<FaceSystem>],
    rank: &[usize],
    rhs: &mut Mat<f64>,
    vals: &mut [f64],
) -> Option<()> {
    let n = rank.len();
    for (((verts, _), slots), face) in block.iter().zip(slots).zip(faces) {
        let face = face.as_ref()?;
        for x in 0..6 {
            let vx = verts[x % 3] as usize;
            if vx >= n {
                continue;
            }
            rhs[(system_row(rank, vx, x / 3), 0)] += face.rhs[x];
            for (&slot, &value) in slots[x].iter().zip(&face.block[x]) {
                if slot != usize::MAX {
                    vals[slot] += value;
                }
            }
        }
    }
    Some(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testmesh::grid;
    use crate::uvstats::analyse_uv;

    /// The signed SVD `J = rot(φ) diag(s1, s2) rot(θ)` of a 2×2 matrix (`s1 ≥ |s2|`, `s2 < 0` iff
    /// `det J < 0`), as `(φ, s1, s2, θ)`.
    fn svd2(j: [[f64; 2]; 2]) -> (f64, f64, f64, f64) {
        let [[a, b], [c, d]] = j;
        let (e, f, g, h) = ((a + d) / 2.0, (a - d) / 2.0, (c + b) / 2.0, (c - b) / 2.0);
        let (q, r) = (e.hypot(h), f.hypot(g));
        let (a1, a2) = (g.atan2(f), h.atan2(e));
        ((a2 + a1) / 2.0, q + r, q - r, (a2 - a1) / 2.0)
    }

    fn rot(angle: f64) -> [[f64; 2]; 2] {
        let (s, c) = angle.sin_cos();
        [[c, -s], [s, c]]
    }

    fn mul(a: [[f64; 2]; 2], b: [[f64; 2]; 2]) -> [[f64; 2]; 2] {
        let mut m = [[0.0; 2]; 2];
        for r in 0..2 {
            for c in 0..2 {
                m[r][c] = a[r][0] * b[0][c] + a[r][1] * b[1][c];
            }
        }
        m
    }

    #[test]
    fn the_signed_svd_reconstructs_the_matrix() {
        for j in [
            [[1.0, 0.3], [-0.2, 2.0]],
            [[0.5, -1.5], [2.0, 0.1]],
            [[1.0, 0.0], [0.0, -1.0]],
            [[0.0, 0.0], [0.0, 0.0]],
        ] {
            let (phi, s1, s2, theta) = svd2(j);
            let m = mul(mul(rot(phi), [[s1, 0.0], [0.0, s2]]), rot(theta));
            for r in 0..2 {
                for c in 0..2 {
                    assert!((m[r][c] - j[r][c]).abs() < 1e-12, "{j:?} -> {m:?}");
                }
            }
            let det = j[0][0] * j[1][1] - j[0][1] * j[1][0];
            assert!(s1 >= s2.abs() - 1e-12 && (s2 < 0.0) == (det < -1e-15), "{j:?}: {s1} {s2}");
        }
    }

    /// [`Svd2`] is [`svd2`] without the angles: the same singular values, and the matrices SLIM
    /// builds from its rotations (`rot(φ) diag rot(−φ)`, `rot(φ) diag rot(θ)`) the same, on
    /// random matrices of either sign of determinant and on those where a part of the
    /// decomposition is zero (a similarity, a reflection, zero).
    #[test]
    fn the_svd_without_angles_builds_what_the_angles_did() {
        let mut state = 7u64;
        let mut draw = || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (state >> 11) as f64 / (1u64 << 53) as f64 * 4.0 - 2.0
        };
        let mut cases: Vec<[[f64; 2]; 2]> = (0..200).map(|_| [[draw(), draw()], [draw(), draw()]]).collect();
        cases.extend([
            [[1.5, -0.5], [0.5, 1.5]],
            [[1.0, 0.3], [0.3, -1.0]],
            [[0.0, 0.0], [0.0, 0.0]],
            [[2.0, 0.0], [0.0, 2.0]],
        ]);
        let close = |a: [[f64; 2]; 2], b: [[f64; 2]; 2]| {
            (0..4).all(|i| (a[i / 2][i % 2] - b[i / 2][i % 2]).abs() < 1e-12 * (1.0 + b[i / 2][i % 2].abs()))
        };
        for j in cases {
            let (phi, s1, s2, theta) = svd2(j);
            let svd = Svd2::of(j);
            assert!((svd.s1 - s1).abs() < 1e-12 && (svd.s2 - s2).abs() < 1e-12, "{j:?}");
            let (x1, x2) = (draw().abs() + 0.1, draw().abs() + 0.1);
            let along = mul(mul(rot(phi), [[x1, 0.0], [0.0, x2]]), rot(-phi));
            assert!(close(svd.along_u(x1, x2), along), "{j:?}: {:?} {along:?}", svd.along_u(x1, x2));
            let with = mul(mul(rot(phi), [[x1, 0.0], [0.0, x2]]), rot(theta));
            assert!(close(svd.with_values(x1, x2), with), "{j:?}: {:?} {with:?}", svd.with_values(x1, x2));
            assert!(close(svd.with_values(svd.s1, svd.s2), j), "{j:?}");
        }
    }

    /// The system pattern written out from the unknowns' graph is the one the triangles'
    /// entries make (summed like faer's triplet assembly) in the pattern's own numbering
    /// ([`Pattern::row`]: each unknown's `u` and `v` side by side), fixed points and an
    /// isolated unknown included; that numbering fills the factor about as little as AMD on
    /// the whole system does (a wrong ordering convention would fill it several times over);
    /// and solved through it, the system gives what a plain Cholesky of the same entries in
    /// the triangles' numbering gives.
    #[test]
    fn the_system_pattern_is_the_triangles_entries_and_its_ordering_is_amds() {
        let mesh = grid(12, |p| [p[0], p[1]]);
        let n = mesh.positions.len() + 1; // the last unknown is in no triangle
        let mut triangles: Vec<[u32; 3]> = mesh.triangles.clone();
        triangles.push([0, n as u32, n as u32 + 1]); // a scaffold triangle to two fixed points
        let mut pattern = Pattern::new(n, &triangles).unwrap();
        let mut ranks: Vec<usize> = (0..n).map(|v| pattern.row(v, 0)).collect();
        ranks.sort_unstable();
        assert_eq!(ranks, (0..n).map(|r| 2 * r).collect::<Vec<_>>(), "every unknown a pair of rows");
        // The entries each (row, column) pair of unknowns gets, in the triangles' numbering
        // (`u` of unknown `i` row `i`, `v` row `n + i`) and in the pattern's.
        let value = |a: usize, b: usize| {
            let (lo, hi) = (a.min(b), a.max(b));
            if lo == hi { 40.0 + (lo % 7) as f64 } else { -1.0 - ((hi + 3 * lo) % 5) as f64 * 0.1 }
        };
        let mut pairs: Vec<(usize, usize)> = (0..2 * n).map(|i| (i, i)).collect();
        pairs.extend((0..n).map(|i| (n + i, i)));
        for c in &triangles {
            for a in 0..6 {
                for b in 0..6 {
                    let (va, vb) = (c[a % 3] as usize, c[b % 3] as usize);
                    if va < n && vb < n {
                        pairs.push(((a / 3) * n + va, (b / 3) * n + vb));
                    }
                }
            }
        }
        pairs.retain(|&(r, col)| r >= col);
        pairs.sort_unstable();
        pairs.dedup();
        let rows: Vec<usize> = (0..2 * n).map(|x| pattern.row(x % n, x / n)).collect();
        let ours = |x: usize| rows[x];
        let triplets: Vec<Triplet<usize, usize, f64>> = pairs
            .iter()
            .map(|&(r, col)| {
                let (a, b) = (ours(r), ours(col));
                Triplet::new(a.max(b), a.min(b), 1.0)
            })
            .collect();
        let reference = SparseColMat::<usize, f64>::try_new_from_triplets(2 * n, 2 * n, &triplets).unwrap();
        assert_eq!(pattern.matrix.symbolic().col_ptr(), reference.symbolic().col_ptr());
        assert_eq!(pattern.matrix.symbolic().row_idx(), reference.symbolic().row_idx());
        for (i, &d) in pattern.diagonal.iter().enumerate() {
            assert_eq!(pattern.matrix.symbolic().row_idx()[d], i);
        }
        for c in &triangles {
            for a in 0..6 {
                for b in 0..6 {
                    let (va, vb) = (c[a % 3] as usize, c[b % 3] as usize);
                    if va < n && vb < n && ours((a / 3) * n + va) >= ours((b / 3) * n + vb) {
                        let slot =
                            pattern.slots.iter().zip(&triangles).find(|(_, t)| *t == c).unwrap().0[a][b];
                        let col =
                            (0..2 * n).find(|&j| pattern.matrix.symbolic().col_ptr()[j + 1] > slot).unwrap();
                        assert_eq!(
                            (pattern.matrix.symbolic().row_idx()[slot], col),
                            (ours((a / 3) * n + va), ours((b / 3) * n + vb)),
                            "slot of {c:?} ({a}, {b})"
                        );
                    }
                }
            }
        }
        let params = CholeskySymbolicParams {
            supernodal_flop_ratio_threshold: SupernodalThreshold::FORCE_SUPERNODAL,
            ..Default::default()
        };
        let amd =
            factorize_symbolic_cholesky(reference.symbolic(), Side::Lower, SymmetricOrdering::Amd, params)
                .unwrap()
                .len_val();
        let fill = pattern.symbolic.len_val();
        assert!((fill as f64) < 1.25 * amd as f64, "the pattern's order fills {fill} entries, AMD {amd}");
        // Solved in the pattern's numbering and in the triangles' by a plain Cholesky.
        let col_ptr = pattern.matrix.symbolic().col_ptr().to_vec();
        let row_idx = pattern.matrix.symbolic().row_idx().to_vec();
        let mut plain_triplets = Vec::new();
        let vals = pattern.matrix.val_mut();
        for &(r, col) in &pairs {
            let (a, b) = (ours(r), ours(col));
            let (hi, lo) = (a.max(b), a.min(b));
            let k = (col_ptr[lo]..col_ptr[lo + 1]).find(|&k| row_idx[k] == hi).unwrap();
            vals[k] = value(r, col);
            plain_triplets.push(Triplet::new(r, col, value(r, col)));
        }
        let b = |x: usize| 1.0 + (x % 11) as f64;
        let mut ours_rhs = Mat::<f64>::zeros(2 * n, 1);
        let mut plain = Mat::<f64>::zeros(2 * n, 1);
        for x in 0..2 * n {
            ours_rhs[(ours(x), 0)] = b(x);
            plain[(x, 0)] = b(x);
        }
        pattern.solve_in_place(&mut ours_rhs).unwrap();
        solve_lower(2 * n, &plain_triplets, &mut plain).unwrap();
        for x in 0..2 * n {
            assert!((ours_rhs[(ours(x), 0)] - plain[(x, 0)]).abs() < 1e-12, "unknown row {x}");
        }
    }

    #[test]
    fn smallest_positive_roots() {
        assert_eq!(smallest_positive_root(0.0, 0.0, 1.0), f64::INFINITY);
        assert!((smallest_positive_root(0.0, -2.0, 1.0) - 0.5).abs() < 1e-15);
        assert!((smallest_positive_root(1.0, -3.0, 2.0) - 1.0).abs() < 1e-12);
        assert_eq!(smallest_positive_root(1.0, 0.0, 1.0), f64::INFINITY);
        assert_eq!(smallest_positive_root(1.0, 3.0, 2.0), f64::INFINITY);
    }

    #[test]
    fn crossing_and_disjoint_segments() {
        let p = [[0.0, 0.0], [1.0, 1.0], [0.0, 1.0], [1.0, 0.0], [2.0, 2.0], [3.0, 3.0]];
        assert!(segments_cross([0, 1], [2, 3], &p));
        assert!(!segments_cross([0, 1], [4, 5], &p));
        assert!(!segments_cross([0, 1], [1, 2], &p), "neighbours share an endpoint");
        let touching = [[0.0, 0.0], [2.0, 0.0], [1.0, 0.0], [1.0, 1.0]];
        assert!(!segments_cross([0, 1], [2, 3], &touching), "an endpoint on a segment only touches");
        let slit = [[0.0, 0.0], [2.0, 0.0], [0.5, 0.0], [1.5, 0.0]];
        assert!(!segments_cross([0, 1], [2, 3], &slit), "coinciding sides only touch");
    }

    #[test]
    fn a_flat_grid_is_a_disc_and_already_injective() {
        let m = grid(6, |p| [(p[0] + 1.0) * 0.5, (p[1] + 1.0) * 0.5]);
        let out = make_injective(&m, &InjectiveOptions::default()).unwrap();
        let r = &out.report;
        assert_eq!(
            (r.islands_before, r.islands_after, r.not_injective_before, r.not_injective_after),
            (1, 1, 0, 0)
        );
        assert_eq!((r.not_disc, r.repaired, r.reembedded, r.split), (0, 0, 0, 0));
        assert!((r.energy_after - 4.0).abs() < 1e-6, "{r:?}");
        let a = analyse_uv(&out.mesh, None, 256).unwrap();
        assert_eq!((a.stats.flipped_faces, a.stats.overlapping_faces), (0, 0));
    }

    #[test]
    fn the_rounds_stop_on_the_smaller_of_the_two_tolerances() {
        let opts = InjectiveOptions::default(); // 1e-4 of E, 1e-2 of E − 4A
        // A curved island, 0.5 per unit area above an isometry: the rule on E decides.
        assert!(converged(3.9e-4, 4.5, 4.0, &opts) && !converged(4.6e-4, 4.5, 4.0, &opts));
        // A nearly isometric one (woody's first round left 1.1e-7 per unit area): a round that
        // removes 1e-8 is far below 1e-4 of E but a tenth of the excess, so the rounds go on.
        assert!(!converged(1e-8, 4.0 + 1.1e-7, 4.0, &opts));
        assert!(converged(1e-10, 4.0 + 1.1e-7, 4.0, &opts));
        // At an isometry (or a hair below, by rounding) nothing is left to remove.
        assert!(converged(0.0, 4.0 - 1e-15, 4.0, &opts));
        let on_e_alone = InjectiveOptions { excess_tolerance: f64::INFINITY, ..opts };
        assert!(converged(1e-8, 4.0 + 1.1e-7, 4.0, &on_e_alone));
    }

    /// A cone `z = h (1 − |(x, y)|)` over the grid, its apex at the centre vertex, with the
    /// flat projection as its map: the apex gathers an angle deficit of about
    /// `2π (1 − 1/√(1 + h²))` (105° for `h = 1`), which no uncut flat map holds.
    fn cone(n: u32, h: f32) -> TriMesh {
        let mut m = grid(n, |p| [(p[0] + 1.0) * 0.5, (p[1] + 1.0) * 0.5]);
        for p in &mut m.positions {
            p[2] = h * (1.0 - p[0].hypot(p[1]));
        }
        m
    }

    #[test]
    fn a_cone_is_cut_from_its_apex_and_flattens_nearly_isometrically() {
        let m = cone(16, 1.0);
        let uncut = make_injective(&m, &InjectiveOptions::default()).unwrap().report;
        let opts = InjectiveOptions { cut_cones: true, ..Default::default() };
        let out = make_injective(&m, &opts).unwrap();
        let r = &out.report;
        assert_eq!((r.cones, r.coned_islands, r.islands_after), (1, 1, 1), "{r:?}");
        // Per unit area, 4 is an isometry: the slit removes most of the excess.
        assert!(uncut.energy_after > 4.1, "{uncut:?}");
        assert!(r.energy_after - 4.0 < 0.25 * (uncut.energy_after - 4.0), "{r:?} against {uncut:?}");
        let a = analyse_uv(&out.mesh, None, 256).unwrap();
        assert_eq!((a.stats.charts, a.stats.flipped_faces, a.stats.overlapping_faces), (1, 0, 0));
        // A flat grid has no cone point: nothing is cut.
        let flat = grid(8, |p| [(p[0] + 1.0) * 0.5, (p[1] + 1.0) * 0.5]);
        let r = make_injective(&flat, &opts).unwrap().report;
        assert_eq!((r.cones, r.coned_islands), (0, 0));
    }

    /// The conformal term is 0 on a similarity and the MIPS excess otherwise, and an isometry
    /// costs 4 whatever its weight.
    #[test]
    fn the_slim_density_adds_the_conformal_excess_to_the_symmetric_dirichlet_energy() {
        let turn = rot(0.7);
        for lambda in [0.0, 0.5, 3.0] {
            let conformal = Terms { conformal: lambda, ..Default::default() };
            assert!((slim_density(turn, conformal) - 4.0).abs() < 1e-12);
            let similar = mul(turn, [[2.0, 0.0], [0.0, 2.0]]);
            assert!((slim_density(similar, conformal) - (8.0 + 0.5)).abs() < 1e-12);
            // diag(2, 1): ‖J‖² + ‖J⁻¹‖² = 5 + 1.25, σ₁/σ₂ + σ₂/σ₁ − 2 = 0.5.
            let stretched = mul(mul(turn, [[2.0, 0.0], [0.0, 1.0]]), rot(-0.3));
            assert!((slim_density(stretched, conformal) - (6.25 + 0.5 * lambda)).abs() < 1e-12);
            assert_eq!(slim_density([[1.0, 0.0], [0.0, -1.0]], conformal), f64::INFINITY);
        }
    }

    /// The orthogonal term is `cos²` of the angle between the texture axes and 0 for any
    /// stretch along them, the equiareal term `(det J − 1)²`; an isometry still costs 4.
    #[test]
    fn the_slim_density_adds_the_axes_shear_and_the_area_change() {
        let (o, a) = (3.0, 5.0);
        let terms = Terms { orthogonal: o, equiareal: a, ..Default::default() };
        assert!((slim_density(rot(0.7), terms) - 4.0).abs() < 1e-12);
        // A stretch along the texture axes: cos 0, det 1; ‖J‖² + ‖J⁻¹‖² = 4.25 + 4.25.
        let along = [[2.0, 0.0], [0.0, 0.5]];
        assert!((slim_density(along, terms) - 8.5).abs() < 1e-12);
        // The same stretch at 45° to them (a rotation on the left turns the texture axes; one on
        // the right, the 3-D frame, changes nothing): the rows (2c, −s/2) and (2s, c/2) at
        // c = s = 1/√2 make cos = 1.875 / 2.125 = 15/17; det 1.
        let diagonal = mul(rot(std::f64::consts::FRAC_PI_4), along);
        assert!((slim_density(mul(along, rot(0.4)), terms) - 8.5).abs() < 1e-12);
        let cos = (15.0f64 / 17.0).powi(2);
        assert!((slim_density(diagonal, terms) - (8.5 + o * cos)).abs() < 1e-12);
        // A shear: rows (1, ½) and (0, 1), cos² = 0.25 / 1.25; det 1.
        let shear = [[1.0, 0.5], [0.0, 1.0]];
        let sd = 2.25 + 2.25;
        assert!((slim_density(shear, terms) - (sd + o * 0.2)).abs() < 1e-12);
        // Twice the size: det 4, cos 0.
        assert!((slim_density([[2.0, 0.0], [0.0, 2.0]], terms) - (8.5 + a * 9.0)).abs() < 1e-12);
        // Rows swapped (a mirror): no map, whatever the terms.
        assert_eq!(slim_density([[0.0, 1.0], [1.0, 0.0]], terms), f64::INFINITY);
    }

    /// SLIM's proxy `Σ_k (a_k · z − target_k)²` has the energy density's gradient at the current
    /// map (what makes its reweighting a descent method), with and without the conformal,
    /// orthogonal and equiareal terms.
    #[test]
    fn the_slim_proxy_has_the_energy_gradient_at_the_current_map() {
        let rest = Rest::new([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]], 1.0, true);
        let maps = [
            [[0.1, -0.2], [1.3, 0.1], [0.4, 0.9]],
            [[0.0, 0.0], [0.5, 0.2], [-0.1, 2.0]],
            [[0.3, 0.3], [0.9, 0.35], [0.35, 0.6]],
        ];
        let weights = [
            Terms::default(),
            Terms { conformal: 0.7, ..Default::default() },
            Terms { conformal: 4.0, ..Default::default() },
            Terms { orthogonal: 3.0, ..Default::default() },
            Terms { equiareal: 2.5, ..Default::default() },
            Terms { conformal: 0.7, orthogonal: 64.0, equiareal: 32.0 },
        ];
        for lambda in weights {
            for q in maps {
                let face = slim_terms(&rest, q, lambda).unwrap();
                let on = [lambda.orthogonal, lambda.equiareal].iter().filter(|&&w| w != 0.0).count();
                assert_eq!(face.len, 4 + on, "{lambda:?}");
                let z = [q[0][0], q[1][0], q[2][0], q[0][1], q[1][1], q[2][1]];
                let density = |z: [f64; 6]| {
                    slim_density(rest.jacobian([[z[0], z[3]], [z[1], z[4]], [z[2], z[5]]]), lambda)
                };
                for x in 0..6 {
                    let proxy: f64 = face
                        .iter()
                        .map(|(a, t)| 2.0 * (a.iter().zip(z).map(|(a, z)| a * z).sum::<f64>() - t) * a[x])
                        .sum();
                    let h = 1e-6;
                    let (mut up, mut down) = (z, z);
                    up[x] += h;
                    down[x] -= h;
                    let numeric = (density(up) - density(down)) / (2.0 * h);
                    assert!(
                        (proxy - numeric).abs() < 1e-5 * (1.0 + numeric.abs()),
                        "{lambda:?}, {q:?}, unknown {x}: proxy {proxy} energy {numeric}"
                    );
                    // The face's system, `2 (K z − b)`, has that gradient too: with every corner
                    // an unknown, and with corner 2 a fixed point (its terms moved across).
                    for (verts, n) in [([0, 1, 2], 3), ([0, 1, 2], 2)] {
                        if verts[x % 3] as usize >= n {
                            continue;
                        }
                        let system = face.system(1.0, verts, n, &[q[2]]);
                        let free = |y: usize| (verts[y % 3] as usize) < n;
                        let kz: f64 = (0..6).filter(|&y| free(y)).map(|y| system.block[x][y] * z[y]).sum();
                        let gradient = 2.0 * (kz - system.rhs[x]);
                        assert!(
                            (gradient - numeric).abs() < 1e-5 * (1.0 + numeric.abs()),
                            "{lambda:?}, {q:?}, unknown {x} of {verts:?}: system {gradient} energy {numeric}"
                        );
                    }
                }
            }
        }
    }

    /// On a doubly curved patch (a spherical cap, which no flat map holds without distortion)
    /// the conformal term trades area for angle: the angular score rises, the area distortion
    /// too, and the map stays injective.
    #[test]
    fn the_conformal_term_keeps_angles_on_a_curved_cap_at_the_cost_of_area() {
        let mut cap = grid(12, |p| [(p[0] + 1.0) * 0.5, (p[1] + 1.0) * 0.5]);
        for p in &mut cap.positions {
            p[2] = (3.0 - p[0] * p[0] - p[1] * p[1]).sqrt();
        }
        let solved = |conformal: f64| {
            let out = make_injective(&cap, &InjectiveOptions { conformal, ..Default::default() }).unwrap();
            let a = analyse_uv(&out.mesh, None, 256).unwrap();
            assert_eq!((a.stats.charts, a.stats.flipped_faces, a.stats.overlapping_faces), (1, 0, 0));
            crate::partuv::partuv_metrics(&out.mesh).unwrap()
        };
        // Measured: angular 0.9822 → 0.9884, worst-chart area distortion 1.026 → 1.042.
        let (plain, conformal) = (solved(0.0), solved(8.0));
        assert!(
            1.0 - conformal.angular_score < 0.75 * (1.0 - plain.angular_score),
            "angular {} against {}",
            conformal.angular_score,
            plain.angular_score
        );
        assert!(conformal.area_distortion > plain.area_distortion, "{conformal:?} against {plain:?}");
    }

    /// On the same cap the orthogonal and equiareal terms keep the texture axes perpendicular and
    /// every face at the island's density, both better than the symmetric Dirichlet energy
    /// alone: the stretch left goes along the axes, where neither score sees it.
    #[test]
    fn the_orthogonal_and_equiareal_terms_keep_axes_and_area_on_a_curved_cap() {
        let mut cap = grid(12, |p| [(p[0] + 1.0) * 0.5, (p[1] + 1.0) * 0.5]);
        for p in &mut cap.positions {
            p[2] = (3.0 - p[0] * p[0] - p[1] * p[1]).sqrt();
        }
        let solved = |orthogonal: f64, equiareal: f64| {
            let opts = InjectiveOptions { orthogonal, equiareal, ..Default::default() };
            let out = make_injective(&cap, &opts).unwrap();
            let a = analyse_uv(&out.mesh, None, 256).unwrap();
            assert_eq!((a.stats.charts, a.stats.flipped_faces, a.stats.overlapping_faces), (1, 0, 0));
            crate::partuv::partuv_metrics(&out.mesh).unwrap()
        };
        // Measured: angular 0.9822 → 0.9909, worst-chart area distortion 1.026 → 1.011.
        let (plain, both) = (solved(0.0, 0.0), solved(64.0, 32.0));
        assert!(
            1.0 - both.angular_score < 0.6 * (1.0 - plain.angular_score),
            "angular {} against {}",
            both.angular_score,
            plain.angular_score
        );
        assert!(both.area_distortion < plain.area_distortion, "{both:?} against {plain:?}");
    }

    /// The least-squares conformal map of a flat patch is an isometry (its energy is exactly an
    /// isometry's), and of a developable but curved one (a bent strip) nearly so, where Tutte's
    /// start is far from one; a patch made non-injective by its map is re-embedded from it.
    #[test]
    fn the_conformal_start_of_a_developable_patch_is_an_isometry() {
        let energy_density = |m: &TriMesh| {
            whole_patch(m, |patch, _| {
                let lscm = patch.lscm().unwrap();
                assert!(patch.is_injective(&lscm));
                let per_area = |p: &[[f64; 2]]| patch.energy(p).unwrap() / patch.area3;
                (per_area(&lscm), per_area(&patch.tutte().unwrap()))
            })
        };
        // A flat 3 × 1 strip with irregular triangles, and the same strip bent into an arc.
        let flat =
            strip(12, 4, |s, t| [3.0 * s + 0.1 * (7.0 * t).sin() * s * (1.0 - s), t, 0.0], |s, t| [s, t]);
        let (lscm, tutte) = energy_density(&flat);
        assert!((lscm - 4.0).abs() < 1e-9 && tutte > 4.5, "{lscm} {tutte}");
        let bent = strip(12, 4, |s, t| [(2.0 * s).sin(), t, (2.0 * s).cos()], |s, t| [s, t]);
        let (lscm, tutte) = energy_density(&bent);
        assert!(lscm < 4.0 + 1e-3 && tutte > 4.5, "{lscm} {tutte}");
        // Folded over itself, the flat strip is embedded anew, from the conformal start.
        let folded = crate::testmesh::with_uv_per_corner(&flat, |_, _, uv| [(uv[0] - 0.5).abs(), uv[1]]);
        let out = make_injective(&folded, &InjectiveOptions::default()).unwrap();
        let r = &out.report;
        assert_eq!((r.reembedded, r.not_injective_after, r.split), (1, 0, 0), "{r:?}");
        assert!((r.energy_after - 4.0).abs() < 1e-9 && r.rounds <= 3, "{r:?}");
        // Injective but distorted, the flat strip starts from its conformal map too (it is
        // developable), and ends exactly isometric. The bent strip is developable too; a cone is
        // not.
        let sheared =
            crate::testmesh::with_uv_per_corner(&flat, |_, _, uv| [uv[0] + 0.05 * uv[1] * uv[1], uv[1]]);
        let r = make_injective(&sheared, &InjectiveOptions::default()).unwrap().report;
        assert_eq!((r.not_injective_before, r.reembedded), (0, 0), "{r:?}");
        assert!(
            r.energy_before > 4.0 + 1e-6 && (r.energy_after - 4.0).abs() < 1e-9 && r.rounds <= 3,
            "{r:?}"
        );
        let developable = |m: &TriMesh| whole_patch(m, |patch, _| patch.is_developable_disc());
        assert!(developable(&flat) && developable(&bent) && !developable(&cone(6, 1.0)));
    }

    /// `f` of the patch of all of `m`'s faces and its context, with default options.
    fn whole_patch<R>(m: &TriMesh, f: impl FnOnce(&Patch, &Ctx) -> R) -> R {
        let uv = m.uv.as_ref().unwrap();
        let degenerate = degenerate_3d_faces(m);
        let opts = InjectiveOptions::default();
        let ctx = Ctx { mesh: m, uv, degenerate: &degenerate, opts: &opts };
        let faces: Vec<u32> = (0..m.triangles.len() as u32).collect();
        f(&Patch::new(&ctx, &faces), &ctx)
    }

    /// A fan whose positive faces wind twice round its centre is not injective, though no
    /// face is flipped and its boundary (a circle traced twice) crosses nowhere: only the
    /// winding of the inner unknown's fan tells, and it counts exactly the turns the angles sum
    /// to, whatever the ray's direction meets (a ring vertex on it, an edge along it).
    #[test]
    fn a_fan_winding_twice_round_its_centre_is_not_injective() {
        let fan = |turns: u32, start: f64| {
            let m = 12u32;
            let mut positions = vec![[0.0f32, 0.0, 0.0]];
            let mut coords = vec![[0.0f32, 0.0]];
            for i in 0..m {
                let a = std::f64::consts::TAU * i as f64 / m as f64;
                positions.push([a.cos() as f32, a.sin() as f32, 0.2 * (i % 2) as f32]);
                let b = start + turns as f64 * a;
                coords.push([b.cos() as f32, b.sin() as f32]);
            }
            let triangles: Vec<[u32; 3]> = (0..m).map(|i| [0, 1 + i, 1 + (i + 1) % m]).collect();
            let m =
                TriMesh { positions, uv: Some(UvLayer { coords, triangles: triangles.clone() }), triangles };
            whole_patch(&m, |patch, ctx| {
                let p = patch.current(ctx).unwrap();
                let winding: i32 = (0..patch.corners.len())
                    .map(|t| {
                        let c = patch.corners[t];
                        (0..3)
                            .filter(|&k| c[k] == 0)
                            .map(|k| i32::from(wedge_crossing(c.map(|i| p[i as usize]), k)))
                            .sum::<i32>()
                    })
                    .sum();
                (patch.is_injective(&p), winding)
            })
        };
        // Starting on the ray (a ring vertex at +x), and off it.
        for start in [0.0, 0.1, -0.3] {
            assert_eq!(fan(1, start), (true, 1), "{start}");
            assert_eq!(fan(2, start), (false, 2), "{start}");
        }
    }

    /// The global step refilled into a kept pattern (the scaffold kept, its rest shapes taken
    /// anew) is exactly the step of a system built afresh for the same triangles: no value of
    /// the previous round survives the refill.
    #[test]
    fn a_refilled_system_solves_like_a_new_one() {
        let m = strip(6, 4, |s, t| [s, t, 0.4 * s * s], |s, t| [s + 0.2 * s * t, t]);
        let uv = m.uv.as_ref().unwrap();
        let degenerate = degenerate_3d_faces(&m);
        let opts = InjectiveOptions::default();
        let ctx = Ctx { mesh: &m, uv, degenerate: &degenerate, opts: &opts };
        let faces: Vec<u32> = (0..m.triangles.len() as u32).collect();
        let patch = Patch::new(&ctx, &faces);
        let p0 = patch.current(&ctx).unwrap();
        let glue = patch.coincident_boundary(&p0);
        let mut kept = SlimSystem::new(&patch, glue.clone(), Terms::default());
        let sc0 = Scaffold::build(&patch, &p0, &glue).unwrap();
        let step0 = kept.global_scaffold(&patch, &p0, &sc0).unwrap();
        let island0 = kept.global(&patch, &p0).unwrap();
        let p1: Vec<[f64; 2]> =
            p0.iter().zip(&step0).map(|(a, b)| [0.5 * (a[0] + b[0]), 0.5 * (a[1] + b[1])]).collect();
        let sc1 = Scaffold::build(&patch, &p0, &glue).unwrap().rested(&p1).unwrap();
        let step1 = kept.global_scaffold(&patch, &p1, &sc1).unwrap();
        let island1 = kept.global(&patch, &p1).unwrap();
        let mut fresh = SlimSystem::new(&patch, glue, Terms::default());
        assert_eq!(step1, fresh.global_scaffold(&patch, &p1, &sc1).unwrap());
        assert_eq!(island1, fresh.global(&patch, &p1).unwrap());
        // The two rounds did solve different systems.
        assert_ne!(step0, step1);
        assert_ne!(island0, island1);
    }

    #[test]
    fn a_pattern_solves_its_system_as_a_plain_cholesky_does() {
        // The SLIM pattern of a 12 × 12 grid, filled with a positive definite matrix (each
        // entry's value from its position, diagonally dominant), solved through the kept
        // symbolic factorisation and by a fresh `sp_cholesky` of the same entries.
        let mesh = grid(12, |p| [p[0], p[1]]);
        let n = mesh.positions.len();
        let mut pattern = Pattern::new(n, &mesh.triangles).unwrap();
        let col_ptr = pattern.matrix.symbolic().col_ptr().to_vec();
        let row_idx = pattern.matrix.symbolic().row_idx().to_vec();
        let value = |r: usize, col: usize| {
            if r == col { 40.0 + (col % 7) as f64 } else { -1.0 - ((r + 3 * col) % 5) as f64 * 0.1 }
        };
        let mut triplets = Vec::new();
        let vals = pattern.matrix.val_mut();
        for col in 0..2 * n {
            for k in col_ptr[col]..col_ptr[col + 1] {
                vals[k] = value(row_idx[k], col);
                triplets.push(Triplet::new(row_idx[k], col, vals[k]));
            }
        }
        let rhs = Mat::<f64>::from_fn(2 * n, 1, |i, _| ((i * 37) % 11) as f64 - 5.0);
        let mut ours = rhs.clone();
        pattern.solve_in_place(&mut ours).unwrap();
        let mut plain = rhs.clone();
        solve_lower(2 * n, &triplets, &mut plain).unwrap();
        for i in 0..2 * n {
            assert!(
                (ours[(i, 0)] - plain[(i, 0)]).abs() < 1e-10,
                "row {i}: {} vs {}",
                ours[(i, 0)],
                plain[(i, 0)]
            );
        }
        // Refilled with twice the values, the same pattern solves the new system: half the solution.
        pattern.matrix.val_mut().iter_mut().for_each(|v| *v *= 2.0);
        let mut halved = rhs.clone();
        pattern.solve_in_place(&mut halved).unwrap();
        for i in 0..2 * n {
            assert!((2.0 * halved[(i, 0)] - plain[(i, 0)]).abs() < 1e-10, "row {i}");
        }
    }

    /// A strip of `n × m` quads on a surface `pos(s, t)` over `[0,1]²`, UVs `uv(s, t)`.
    fn strip(
        n: u32,
        m: u32,
        pos: impl Fn(f64, f64) -> [f64; 3],
        uv: impl Fn(f64, f64) -> [f64; 2],
    ) -> TriMesh {
        let (mut positions, mut coords) = (Vec::new(), Vec::new());
        for j in 0..=m {
            for i in 0..=n {
                let (s, t) = (i as f64 / n as f64, j as f64 / m as f64);
                positions.push(pos(s, t).map(|x| x as f32));
                coords.push(uv(s, t).map(|x| x as f32));
            }
        }
        let id = |i: u32, j: u32| j * (n + 1) + i;
        let mut triangles = Vec::new();
        for j in 0..m {
            for i in 0..n {
                triangles.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
                triangles.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
            }
        }
        TriMesh { positions, uv: Some(UvLayer { coords, triangles: triangles.clone() }), triangles }
    }

    /// Items are taken dearest first, but each result lands at its item's place, computed once:
    /// as a sequential map in order gives them.
    #[test]
    fn dearest_first_returns_every_item_in_its_place() {
        let sizes = [3usize, 40, 1, 40, 7, 0, 12, 5, 90, 2];
        let islands: Vec<Vec<u32>> = sizes
            .iter()
            .enumerate()
            .map(|(i, &n)| (0..n as u32).map(|f| 1000 * i as u32 + f).collect())
            .collect();
        let calls = AtomicUsize::new(0);
        let got = dearest_first(islands.clone(), Vec::len, |faces| {
            calls.fetch_add(1, Ordering::Relaxed);
            (faces.len(), faces.first().copied())
        });
        let expected: Vec<(usize, Option<u32>)> =
            islands.iter().map(|f| (f.len(), f.first().copied())).collect();
        assert_eq!(got, expected);
        assert_eq!(calls.load(Ordering::Relaxed), islands.len());
        assert!(dearest_first(Vec::<Vec<u32>>::new(), Vec::len, |f| f.len()).is_empty());
    }

    /// Two islands, one large enough that SLIM's per-face loops split into several tasks
    /// ([`FACES_PER_TASK`]), solved in pools of 1, 2 and 3 threads: the same UVs to the bit and
    /// the same report. A sum or assembly taken in the tasks' order of completion, or a result
    /// put in the order islands finish, would differ between them.
    #[test]
    fn islands_solve_to_the_same_bits_on_any_thread_count() {
        let big =
            strip(64, 48, |s, t| [s, t, 0.4 * (s * s + t * t)], |s, t| [s + 0.3 * s * t, t + 0.1 * s * s]);
        let small = strip(12, 6, |s, t| [s + 3.0, t, 0.3 * s * t], |s, t| [s * s + 5.0, t]);
        assert!(big.triangles.len() > 2 * FACES_PER_TASK);
        let offset = big.positions.len() as u32;
        let (bu, su) = (big.uv.as_ref().unwrap(), small.uv.as_ref().unwrap());
        let shift = |t: &[u32; 3]| t.map(|v| v + offset);
        let mesh = TriMesh {
            positions: big.positions.iter().chain(&small.positions).copied().collect(),
            triangles: big.triangles.iter().copied().chain(small.triangles.iter().map(shift)).collect(),
            uv: Some(UvLayer {
                coords: bu.coords.iter().chain(&su.coords).copied().collect(),
                triangles: bu.triangles.iter().copied().chain(su.triangles.iter().map(shift)).collect(),
            }),
        };
        let solved: Vec<Injective> = [1, 2, 3]
            .map(|threads| {
                let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
                pool.install(|| make_injective(&mesh, &InjectiveOptions::default()).unwrap())
            })
            .into();
        assert!(solved[0].report.rounds > 2, "SLIM ran: {:?}", solved[0].report);
        for other in &solved[1..] {
            assert_eq!(other.report, solved[0].report);
            let (a, b) = (other.mesh.uv.as_ref().unwrap(), solved[0].mesh.uv.as_ref().unwrap());
            assert_eq!(a.triangles, b.triangles);
            let bits = |l: &UvLayer| l.coords.iter().map(|c| c.map(f32::to_bits)).collect::<Vec<_>>();
            assert_eq!(bits(a), bits(b));
        }
    }

    /// The sorted edge passes give what the map-based ones they replaced gave (kept here as
    /// the reference): the same fans and new unknowns with a cut, and the same adjacency lists,
    /// in the same order, each edge at its first face's rest length. On a curved grid with two
    /// holes, a face wound backwards and a bowtie (two faces touching at one vertex only).
    #[test]
    fn the_sorted_edge_passes_give_what_the_maps_gave() {
        fn reference_fans(
            mut corners: Vec<[u32; 3]>,
            collapsed: &[bool],
            n: usize,
            cut: &HashSet<(u32, u32)>,
        ) -> (Vec<[u32; 3]>, usize) {
            let mut uses: HashMap<(u32, u32), Vec<(u32, usize)>> = HashMap::new();
            for (t, c) in corners.iter().enumerate().filter(|(t, _)| !collapsed[*t]) {
                for k in 0..3 {
                    let (a, b) = (c[k], c[(k + 1) % 3]);
                    uses.entry((a.min(b), a.max(b))).or_default().push((t as u32, k));
                }
            }
            let corner_at = |corners: &[[u32; 3]], f: u32, k: usize, x: u32| -> u32 {
                3 * f + if corners[f as usize][k] == x { k } else { (k + 1) % 3 } as u32
            };
            let mut dsu = crate::uvstats::Dsu::new(3 * corners.len());
            for (t, c) in corners.iter().enumerate().filter(|(t, _)| !collapsed[*t]) {
                for k in 0..3 {
                    let (a, b) = (c[k], c[(k + 1) % 3]);
                    let key = (a.min(b), a.max(b));
                    if let [(f, kf), (g, kg)] = uses[&key][..]
                        && !cut.contains(&key)
                        && f as usize == t
                        && corners[g as usize][kg] == b
                    {
                        for x in [a, b] {
                            dsu.union(corner_at(&corners, f, kf, x), corner_at(&corners, g, kg, x));
                        }
                    }
                }
            }
            let (mut fan_of, mut owner_root, mut next) = (HashMap::new(), vec![u32::MAX; n], n as u32);
            for (t, c) in corners.iter_mut().enumerate().filter(|(t, _)| !collapsed[*t]) {
                for (k, corner) in c.iter_mut().enumerate() {
                    let (v, root) = (*corner as usize, dsu.find(3 * t as u32 + k as u32));
                    if owner_root[v] == u32::MAX {
                        owner_root[v] = root;
                    } else if owner_root[v] != root {
                        *corner = *fan_of.entry(root).or_insert_with(|| {
                            next += 1;
                            next - 1
                        });
                    }
                }
            }
            (corners, next as usize)
        }
        fn reference_adjacency(patch: &Patch) -> Adjacency {
            let mut seen: HashSet<(u32, u32)> = HashSet::new();
            let mut adj: Adjacency = vec![Vec::new(); patch.n];
            for (t, c) in patch.live() {
                for k in 0..3 {
                    let (a, b) = (c[k], c[(k + 1) % 3]);
                    let (xa, xb) = (patch.rest[t].x[k], patch.rest[t].x[(k + 1) % 3]);
                    if seen.insert((a.min(b), a.max(b))) {
                        let l = (xb[0] - xa[0]).hypot(xb[1] - xa[1]);
                        adj[a as usize].push((b, l));
                        adj[b as usize].push((a, l));
                    }
                }
            }
            adj
        }
        let mut m = strip(12, 9, |s, t| [s, t, 0.3 * s * t + 0.2 * s * s], |s, t| [s, t]);
        // Two holes, a face wound backwards, and a bowtie: a face touching the grid at a corner.
        let holes = [40u32, 41, 64, 65, 66, 67];
        let keep: Vec<usize> = (0..m.triangles.len()).filter(|f| !holes.contains(&(*f as u32))).collect();
        let mut triangles: Vec<[u32; 3]> = keep.iter().map(|&f| m.triangles[f]).collect();
        triangles[30].swap(1, 2);
        let corner = m.positions.len() as u32;
        m.positions.extend([[-0.5, -0.2, 0.0], [-0.2, -0.5, 0.0]]);
        triangles.push([0, corner, corner + 1]);
        let uv = m.uv.as_mut().unwrap();
        uv.coords.extend([[-0.5, -0.2], [-0.2, -0.5]]);
        uv.triangles = triangles.clone();
        m.triangles = triangles;
        let uv = m.uv.as_ref().unwrap();
        let degenerate = degenerate_3d_faces(&m);
        let opts = InjectiveOptions::default();
        let ctx = Ctx { mesh: &m, uv, degenerate: &degenerate, opts: &opts };
        let faces: Vec<u32> = (0..m.triangles.len() as u32).collect();
        let patch = Patch::new(&ctx, &faces);
        let cut: HashSet<(u32, u32)> =
            patch.corners[50..56].iter().map(|c| (c[0].min(c[1]), c[0].max(c[1]))).collect();
        for cut in [HashSet::new(), cut] {
            let got = separate_fans(patch.corners.clone(), &patch.collapsed, patch.n, &cut);
            assert_eq!(got, reference_fans(patch.corners.clone(), &patch.collapsed, patch.n, &cut));
            assert!(cut.is_empty() || got.1 > patch.n, "the cut splits unknowns");
        }
        assert!(patch.n > m.positions.len(), "the bowtie's and the backward face's vertices split");
        assert_eq!(patch.edge_graph(), reference_adjacency(&patch));
        let mut holed = patch.clone();
        holed.cut_to_disc();
        let loops = |p: &Patch| p.topology.loops.len();
        assert!(
            loops(&holed) < loops(&patch),
            "holes cut open: {} -> {} loops",
            loops(&patch),
            loops(&holed)
        );
        assert_eq!(holed.edge_graph(), reference_adjacency(&holed));
    }

    /// Flipped and overlapping faces of `mesh` after packing its islands apart.
    fn flips_and_overlaps(mesh: &TriMesh) -> (usize, usize) {
        let opts = crate::islands::IslandPacking { resolution: 1024, gutter: 2, rotate: true, search: 0 };
        let packed = crate::islands::pack_islands(mesh, &opts).unwrap();
        let a = analyse_uv(&packed.mesh, None, 1024).unwrap();
        (a.stats.flipped_faces, a.stats.overlapping_faces)
    }

    /// Median over faces of |cos| between the 3-D directions of +U and +V (the Conformal
    /// metric's per-face quantity), for a mesh in the plane `z = 0`.
    fn median_shear(m: &TriMesh) -> f64 {
        let uv = m.uv.as_ref().unwrap();
        let mut shear: Vec<f64> = (0..m.triangles.len())
            .map(|f| {
                let p = m.triangles[f].map(|i| m.positions[i as usize].map(|x| x as f64));
                let t = uv.triangles[f].map(|i| uv.coords[i as usize].map(|x| x as f64));
                let (du1, du2) =
                    ([t[1][0] - t[0][0], t[1][1] - t[0][1]], [t[2][0] - t[0][0], t[2][1] - t[0][1]]);
                let (dp1, dp2) =
                    ([p[1][0] - p[0][0], p[1][1] - p[0][1]], [p[2][0] - p[0][0], p[2][1] - p[0][1]]);
                // [∂p/∂u ∂p/∂v] = [dp1 dp2] · [du1 du2]⁻¹.
                let det = du1[0] * du2[1] - du1[1] * du2[0];
                let inv = [[du2[1] / det, -du2[0] / det], [-du1[1] / det, du1[0] / det]];
                let tangent = [0, 1].map(|k| dp1[k] * inv[0][0] + dp2[k] * inv[1][0]);
                let bitangent = [0, 1].map(|k| dp1[k] * inv[0][1] + dp2[k] * inv[1][1]);
                let dot = tangent[0] * bitangent[0] + tangent[1] * bitangent[1];
                (dot / (tangent[0].hypot(tangent[1]) * bitangent[0].hypot(bitangent[1]))).abs()
            })
            .collect();
        shear.sort_by(f64::total_cmp);
        shear[shear.len() / 2]
    }

    #[test]
    fn a_flat_island_at_the_networks_small_density_keeps_its_shape_to_f32_rounding_of_its_extent() {
        // A flat square of 3,200 faces whose input map is sheared and small (2% × 1% of the
        // atlas near its middle, as a chart of the networks' square layout): its flattening is a
        // similarity in exact arithmetic. Centred where it came from, f32 rounds each corner to
        // ~3e-8, a 6e-5 share of a face there (median |cos| 6e-5 measured before the change);
        // centred on the origin, to a share of the island's own extent.
        let m = strip(
            40,
            40,
            |s, t| [3.0 * s + 100.0, 3.0 * t - 7.0, 0.0],
            |s, t| [0.49 + 0.02 * s + 0.01 * t, 0.49 + 0.01 * t],
        );
        assert!(median_shear(&m) > 0.1, "the input map is sheared: {:e}", median_shear(&m));
        let split = make_injective(&m, &InjectiveOptions::default()).unwrap();
        let shear = median_shear(&split.mesh);
        assert!(shear < 1e-5, "split (packed afterwards): median |cos(T, B)| {shear:e}");
        // Without `split` the islands stay where the networks put them (the squares layout).
        let kept = make_injective(&m, &InjectiveOptions { split: false, ..Default::default() }).unwrap();
        let coords = &kept.mesh.uv.as_ref().unwrap().coords;
        let mean = [0, 1].map(|k| coords.iter().map(|c| c[k] as f64).sum::<f64>() / coords.len() as f64);
        assert!((mean[0] - 0.505).abs() < 1e-3 && (mean[1] - 0.495).abs() < 1e-3, "{mean:?}");
    }

    #[test]
    fn a_cut_cylinder_projected_onto_a_plane_refines_to_an_isometry() {
        // Half a cylinder (a developable patch), projected along its depth: injective but squashed
        // towards the sides.
        let angle = |s: f64| 0.1 + 0.8 * std::f64::consts::PI * s;
        let m =
            strip(24, 12, |s, t| [angle(s).cos(), 2.0 * t, angle(s).sin()], |s, t| [angle(s).cos(), 2.0 * t]);
        let out = make_injective(&m, &InjectiveOptions { tolerance: 1e-6, ..Default::default() }).unwrap();
        let r = &out.report;
        assert_eq!((r.not_injective_before, r.not_injective_after, r.reembedded, r.split), (0, 0, 0, 0));
        assert!(r.energy_before > 4.5, "the projection is far from isometric: {r:?}");
        assert!(r.energy_after < 4.0 + 1e-3, "{r:?}");
        let p = crate::partuv::partuv_metrics(&out.mesh).unwrap();
        assert!(p.angular_score > 0.999 && p.area_distortion < 1.01, "{p:?}");
    }

    #[test]
    fn an_island_touching_itself_at_a_boundary_point_still_refines() {
        // A 6 × 6 grid without its corner and centre 2 × 2 blocks: a "C" whose two tips meet at
        // one mesh vertex (two fans, so two unknowns at one point, as marching cubes makes them).
        // Its UVs are a smooth injective stretch of the plane, far from isometric.
        let m = grid(6, |p| {
            let (u, v) = ((p[0] + 1.0) * 0.5, (p[1] + 1.0) * 0.5);
            [u + 0.6 * u * u, v * (1.0 + 0.8 * u)]
        });
        let uv = m.uv.as_ref().unwrap();
        let keep: Vec<usize> = (0..m.triangles.len())
            .filter(|&t| {
                let (i, j) = ((t / 2) % 6 / 2, (t / 2) / 6 / 2);
                !((i, j) == (0, 0) || (i, j) == (1, 1))
            })
            .collect();
        let triangles: Vec<[u32; 3]> = keep.iter().map(|&t| m.triangles[t]).collect();
        let uv =
            UvLayer { coords: uv.coords.clone(), triangles: keep.iter().map(|&t| uv.triangles[t]).collect() };
        let m = TriMesh { positions: m.positions.clone(), triangles, uv: Some(uv) };
        let out = make_injective(&m, &InjectiveOptions { tolerance: 1e-6, ..Default::default() }).unwrap();
        let r = &out.report;
        assert_eq!((r.islands_before, r.not_injective_before, r.not_injective_after), (1, 0, 0), "{r:?}");
        assert_eq!((r.reembedded, r.split), (0, 0), "{r:?}");
        assert!(r.energy_before > 4.2, "the start is far from isometric: {r:?}");
        // Stalled at the start (4.4) before the two unknowns at the tips moved together.
        assert!(r.energy_after < 4.01, "{r:?}");
        assert_eq!(flips_and_overlaps(&out.mesh), (0, 0));
    }

    #[test]
    fn a_folded_corner_comes_out_fold_free() {
        // One interior vertex pulled across its neighbours folds the faces round it.
        let m = grid(8, |p| {
            let uv = [(p[0] + 1.0) * 0.5, (p[1] + 1.0) * 0.5];
            if (p[0] - 0.5).abs() < 1e-6 && (p[1] - 0.5).abs() < 1e-6 { [0.1, 0.2] } else { uv }
        });
        let before = analyse_uv(&m, None, 1024).unwrap().stats;
        assert!(before.flipped_faces > 0 && before.overlapping_faces > 0, "{before:?}");
        let out = make_injective(&m, &InjectiveOptions::default()).unwrap();
        let r = &out.report;
        assert_eq!((r.not_injective_before, r.not_injective_after, r.split), (1, 0, 0), "{r:?}");
        assert_eq!((r.repaired, r.reembedded), (1, 0), "a fold inside the chart is mended in place: {r:?}");
        assert_eq!(flips_and_overlaps(&out.mesh), (0, 0));
        assert!(r.energy_after < 4.01, "a flat grid flattens isometrically: {r:?}");
    }

    #[test]
    fn only_the_islands_asked_for_are_solved_and_the_others_keep_their_uvs() {
        // Two copies of a grid with a folded corner, side by side as two islands: asked to solve
        // the island of face 0 only, that one comes out fold-free and the other is left as it was.
        let one = grid(8, |p| {
            let uv = [(p[0] + 1.0) * 0.5, (p[1] + 1.0) * 0.5];
            if (p[0] - 0.5).abs() < 1e-6 && (p[1] - 0.5).abs() < 1e-6 { [0.1, 0.2] } else { uv }
        });
        let (faces, vertices) = (one.triangles.len(), one.positions.len() as u32);
        let uv = one.uv.as_ref().unwrap();
        let coords = uv.coords.len() as u32;
        let mut two = one.clone();
        two.positions.extend(one.positions.iter().map(|p| [p[0] + 3.0, p[1], p[2]]));
        two.triangles.extend(one.triangles.iter().map(|t| t.map(|v| v + vertices)));
        let two_uv = two.uv.as_mut().unwrap();
        two_uv.coords.extend(uv.coords.iter().map(|c| [c[0] + 2.0, c[1]]));
        two_uv.triangles.extend(uv.triangles.iter().map(|t| t.map(|c| c + coords)));
        let out = make_injective_where(&two, &InjectiveOptions::default(), |f| f.contains(&0)).unwrap();
        let r = &out.report;
        assert_eq!(
            (r.islands_before, r.islands_after, r.not_injective_before, r.not_injective_after),
            (2, 2, 1, 0)
        );
        let corner_uvs = |m: &TriMesh, f: usize| {
            let uv = m.uv.as_ref().unwrap();
            uv.triangles[f].map(|c| uv.coords[c as usize])
        };
        let first: Vec<u32> = (0..faces as u32).collect();
        let solved = analyse_uv(&out.mesh, None, 1024).unwrap();
        assert!(solved.flipped.iter().all(|f| !first.contains(f)), "{:?}", solved.flipped);
        assert!(!solved.flipped.is_empty(), "the second island still has its fold");
        for f in faces..2 * faces {
            assert_eq!(corner_uvs(&out.mesh, f), corner_uvs(&two, f), "face {f}");
        }
    }

    #[test]
    fn random_folds_never_survive() {
        for seed in 1..=6u64 {
            let mut state = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15);
            let mut noise = move || {
                state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                ((state >> 11) as f64 / (1u64 << 53) as f64 - 0.5) as f32
            };
            let mut m = grid(10, |p| [(p[0] + 1.0) * 0.5, (p[1] + 1.0) * 0.5]);
            for c in &mut m.uv.as_mut().unwrap().coords {
                *c = [c[0] + 0.25 * noise(), c[1] + 0.25 * noise()];
            }
            let before = analyse_uv(&m, None, 1024).unwrap().stats;
            assert!(before.flipped_faces > 10, "seed {seed}: {before:?}");
            let out = make_injective(&m, &InjectiveOptions::default()).unwrap();
            assert_eq!(out.report.not_injective_after, 0, "seed {seed}: {:?}", out.report);
            assert_eq!(flips_and_overlaps(&out.mesh), (0, 0), "seed {seed}");
        }
    }

    #[test]
    fn a_chart_wrapping_round_a_tube_is_cut_and_flattened() {
        // A closed tube (an annulus, not a disc) projected onto a plane: its back lies on its
        // front, mirrored.
        let n = 24;
        let mut m = strip(
            n,
            6,
            |s, t| {
                let a = std::f64::consts::TAU * s;
                [a.cos(), 2.0 * t, a.sin()]
            },
            |s, t| [(std::f64::consts::TAU * s).cos(), 2.0 * t],
        );
        // Weld the seam: the last column of vertices is the first.
        for tri in m.triangles.iter_mut().chain(m.uv.as_mut().unwrap().triangles.iter_mut()) {
            for v in tri.iter_mut() {
                if *v % (n + 1) == n {
                    *v -= n;
                }
            }
        }
        let before = analyse_uv(&m, None, 1024).unwrap().stats;
        assert_eq!(before.charts, 1);
        assert!(before.flipped_faces > 0 && before.overlapping_faces > 0, "{before:?}");
        let out = make_injective(&m, &InjectiveOptions::default()).unwrap();
        let r = &out.report;
        assert_eq!((r.not_disc, r.not_injective_after), (1, 0), "{r:?}");
        assert_eq!(
            (r.islands_after, r.reembedded, r.split),
            (1, 1, 0),
            "cut open along a slit, one island: {r:?}"
        );
        assert_eq!(flips_and_overlaps(&out.mesh), (0, 0));
        assert!(r.energy_after < 4.05, "each part of a tube is developable: {r:?}");
    }

    /// A closed UV sphere of `rings` × `segments` quads (poles as fans) with the UVs of its
    /// orthographic projection onto the xy-plane: its back lies on its front, mirrored.
    fn projected_sphere(rings: u32, segments: u32) -> TriMesh {
        let mut positions = vec![[0.0f32, 0.0, 1.0]];
        for r in 1..rings {
            let theta = std::f64::consts::PI * r as f64 / rings as f64;
            for k in 0..segments {
                let phi = std::f64::consts::TAU * k as f64 / segments as f64;
                let p = [theta.sin() * phi.cos(), theta.sin() * phi.sin(), theta.cos()];
                positions.push(p.map(|x| x as f32));
            }
        }
        positions.push([0.0, 0.0, -1.0]);
        let (north, south) = (0, positions.len() as u32 - 1);
        let id = |r: u32, k: u32| 1 + (r - 1) * segments + k % segments;
        let mut triangles = Vec::new();
        for k in 0..segments {
            triangles.push([north, id(1, k), id(1, k + 1)]);
            triangles.push([south, id(rings - 1, k + 1), id(rings - 1, k)]);
            for r in 1..rings - 1 {
                triangles.push([id(r, k), id(r + 1, k), id(r + 1, k + 1)]);
                triangles.push([id(r, k), id(r + 1, k + 1), id(r, k + 1)]);
            }
        }
        let coords = positions.iter().map(|p| [p[0], p[1]]).collect();
        TriMesh { positions, uv: Some(UvLayer { coords, triangles: triangles.clone() }), triangles }
    }

    /// The projected sphere's near side speckled with flips (a few vertices of the upper
    /// hemisphere pushed across their neighbours, as the noise of a marching-cubes wall does):
    /// the faces' own orientations make more parts than the two sides; the sides' labelling
    /// gives exactly the two hemispheres, parted at the equator.
    #[test]
    fn the_sides_of_a_speckled_projection_part_at_its_rim() {
        let mut m = projected_sphere(24, 48);
        let upper_ring = |r: u32, k: u32| (1 + (r - 1) * 48 + k) as usize;
        let coords = &mut m.uv.as_mut().unwrap().coords;
        for (r, k) in [(6, 0), (6, 12), (6, 24), (9, 36), (4, 30)] {
            coords[upper_ring(r, k)][0] += 0.3;
        }
        whole_patch(&m, |patch, ctx| {
            let p = patch.current(ctx).unwrap();
            let own: Vec<bool> = (0..patch.faces.len())
                .map(|t| patch.collapsed[t] || area2(patch.corners[t].map(|i| p[i as usize])) <= 0.0)
                .collect();
            assert!(patch.components(&own).len() > 2, "the speckles flip faces");
            let sides = patch.sides(ctx, &p);
            assert_eq!(patch.components(&sides).len(), 2);
            let lower = |t: usize| {
                let f = patch.faces[t] as usize;
                m.triangles[f].iter().map(|&v| m.positions[v as usize][2]).sum::<f32>() < 0.0
            };
            let mirrored_side_is_lower = sides[0] == lower(0);
            for (t, &side) in sides.iter().enumerate() {
                assert_eq!(side == lower(t), mirrored_side_is_lower, "face {t}");
            }
        });
    }

    /// A flat strip 30 × 6 units with a neck two units wide at a third and a bit of its length:
    /// cut in two, it parts across the neck (a seam of 2) where halving by breadth-first growth
    /// parts it near the middle, across the full width (at least 6).
    #[test]
    fn an_island_cut_in_two_parts_at_its_narrowest_place_in_the_middle_band() {
        let (w, h) = (30u32, 6u32);
        let id = |i: u32, j: u32| j * (w + 1) + i;
        let positions: Vec<[f32; 3]> =
            (0..=h).flat_map(|j| (0..=w).map(move |i| [i as f32, j as f32, 0.0])).collect();
        let mut triangles = Vec::new();
        for j in 0..h {
            for i in 0..w {
                if i == 12 && !(2..4).contains(&j) {
                    continue;
                }
                triangles.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
                triangles.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
            }
        }
        let coords = positions.iter().map(|p| [p[0] / 30.0, p[1] / 30.0]).collect();
        let m = TriMesh { positions, uv: Some(UvLayer { coords, triangles: triangles.clone() }), triangles };
        whole_patch(&m, |patch, ctx| {
            let parts = patch.cut_in_two(ctx);
            assert_eq!(parts.len(), 2);
            let mut all: Vec<u32> = parts.concat();
            all.sort_unstable();
            assert_eq!(
                all,
                (0..m.triangles.len() as u32).collect::<Vec<_>>(),
                "the parts cover the patch once"
            );
            let cut = patch.cut_length(&parts);
            assert!((cut - 2.0).abs() < 1e-9, "the cut runs across the neck: {cut}");
            let halved = patch.cut_length(&patch.halves());
            assert!(halved >= 6.0 - 1e-9, "halving parts the strip elsewhere: {halved}");
        });
    }

    #[test]
    fn a_closed_blob_is_slit_open_into_one_island_when_discs_are_never_split() {
        let m = projected_sphere(8, 12);
        let before = analyse_uv(&m, None, 1024).unwrap().stats;
        assert_eq!(before.charts, 1);
        assert!(before.flipped_faces > 0 && before.overlapping_faces > 0, "{before:?}");
        let opts = InjectiveOptions { split_energy: f64::INFINITY, ..Default::default() };
        let out = make_injective(&m, &opts).unwrap();
        let r = &out.report;
        assert_eq!((r.not_disc, r.not_injective_after, r.split), (1, 0, 0), "{r:?}");
        assert_eq!((r.islands_after, r.reembedded), (1, 1), "one slit, one island: {r:?}");
        assert_eq!(flips_and_overlaps(&out.mesh), (0, 0));
        // The slit runs between two far-apart vertices: on a sphere, pole to pole at most (half
        // the circumference, π), so its two sides are the island's whole boundary.
        let boundary = analyse_uv(&out.mesh, None, 1024).unwrap().stats;
        assert_eq!(boundary.charts, 1);
        // With the default threshold a sphere, which no disc maps without distortion, is split.
        let split = make_injective(&m, &InjectiveOptions::default()).unwrap().report;
        assert!(split.islands_after > 1 && split.not_injective_after == 0, "{split:?}");
    }

    #[test]
    fn a_patch_measures_partuv_area_distortion_face_by_face() {
        // Two unit right triangles side by side (a square), the second stretched to three times
        // the first's UV area: ratios 1/2 and 3/2 of the patch's (4 UV over 2 rest), folded to
        // 2 and 3/2, mean 7/4 whatever the faces' sizes.
        let positions = vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]];
        let triangles = vec![[0, 1, 2], [0, 2, 3]];
        let coords = vec![[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]];
        let m = TriMesh { positions, uv: Some(UvLayer { coords, triangles: triangles.clone() }), triangles };
        whole_patch(&m, |patch, ctx| {
            // The map as given: UV area 1 over rest area 1, so not rescaled.
            let mut p = patch.current(ctx).unwrap();
            assert!((patch.area_distortion(&p) - 1.0).abs() < 1e-12);
            // Move the corner only the second face uses: its UV area triples.
            let v = patch.corners[1][2] as usize;
            p[v][0] -= 2.0;
            assert!((patch.area_distortion(&p) - 1.75).abs() < 1e-12, "{}", patch.area_distortion(&p));
        });
    }

    #[test]
    fn a_cut_measures_the_rest_length_between_its_parts() {
        // A flat 2 × 1 strip of 8 × 4 cells (faces 2k, 2k + 1 share cell k = 8j + i). Split at
        // s = 1/2 (x = 1): one straight cut of length 1 across its four rows. Split into the
        // cells of even and odd column: seven cuts of length 1. The same halves with a third,
        // empty part change nothing; a cell's own two faces never count (they share a part).
        let m = strip(8, 4, |s, t| [2.0 * s, t, 0.0], |s, t| [s, t]);
        let cell = |f: u32| (f / 2 % 8, f / 16);
        let faces = 0..m.triangles.len() as u32;
        whole_patch(&m, |patch, _| {
            let halves: Vec<Vec<u32>> = vec![
                faces.clone().filter(|&f| cell(f).0 < 4).collect(),
                faces.clone().filter(|&f| cell(f).0 >= 4).collect(),
            ];
            assert!((patch.cut_length(&halves) - 1.0).abs() < 1e-12, "{}", patch.cut_length(&halves));
            let columns: Vec<Vec<u32>> =
                (0..2).map(|r| faces.clone().filter(|&f| cell(f).0 % 2 == r).collect()).collect();
            assert!((patch.cut_length(&columns) - 7.0).abs() < 1e-12, "{}", patch.cut_length(&columns));
            let with_empty = [halves.clone(), vec![Vec::new()]].concat();
            assert_eq!(patch.cut_length(&with_empty), patch.cut_length(&halves));
            assert_eq!(patch.cut_length(&[faces.clone().collect()]), 0.0);
        });
    }

    #[test]
    fn a_split_into_many_parts_with_long_seams_is_ragged() {
        // A flat 4 × 0.5 strip of 16 × 2 cells. Its halves are cut across it (about 0.5 long);
        // its 16 columns of cells are 15 cuts of 0.5 (7.5, over 8 times the halves' cut): ragged.
        // Four blocks of four columns (three cuts, 1.5) are not, nor are the two halves.
        let m = strip(16, 2, |s, t| [4.0 * s, 0.5 * t, 0.0], |s, t| [s, t]);
        let faces = 0..m.triangles.len() as u32;
        let by = |k: u32, of: fn(u32) -> u32| -> Vec<Vec<u32>> {
            (0..k).map(|r| faces.clone().filter(|&f| of(f) == r).collect()).collect()
        };
        whole_patch(&m, |patch, _| {
            let halves = patch.halves();
            let across = patch.cut_length(&halves);
            assert!((0.5..1.0).contains(&across), "the halves' cut: {across}");
            let columns = by(16, |f| f / 2 % 16);
            assert!((patch.cut_length(&columns) - 7.5).abs() < 1e-12);
            assert!(patch.is_ragged(&columns));
            let blocks = by(4, |f| f / 2 % 16 / 4);
            assert!(!patch.is_ragged(&blocks));
            assert!(!patch.is_ragged(&halves));
        });
    }

    #[test]
    fn a_face_squeezed_to_nothing_still_gets_finite_slim_terms() {
        let rest = Rest::new([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]], 0.5, true);
        // The global step sums squares of the rows: without the floor they overflow from a
        // squeeze of about 1e-103 on, and the terms themselves from about 1e-205.
        for squeeze in [1e-3, 1e-120, 1e-250] {
            let every = Terms { conformal: 1.0, orthogonal: 64.0, equiareal: 32.0 };
            let face = slim_terms(&rest, [[0.0, 0.0], [1.0, 0.0], [0.0, squeeze]], every);
            let face = face.unwrap_or_else(|| panic!("squeezed by {squeeze}"));
            let finite = face.iter().all(|(a, t)| a.iter().chain([&t]).all(|a| (a * a).is_finite()));
            assert!(finite, "squeezed by {squeeze}");
        }
    }

    #[test]
    fn growing_back_does_not_span_a_gap() {
        // A strip whose right half jumps away in UV (as a network's chart jumps across a thin
        // wall): the middle column of faces, marked bad, has every corner placed by good faces on
        // both sides. Without a gap it grows back; across a wide gap it would be a giant face,
        // and faces placed on its edges would copy its scale.
        let n = 16;
        for (shift, grows) in [(0.0, true), (20.0, false)] {
            let m = strip(n, 4, |s, t| [s, t, 0.0], |s, t| if s <= 0.5 { [s, t] } else { [s + shift, t] });
            let (uv, degenerate, opts) =
                (m.uv.as_ref().unwrap(), degenerate_3d_faces(&m), Default::default());
            let ctx = Ctx { mesh: &m, uv, degenerate: &degenerate, opts: &opts };
            let faces: Vec<u32> = (0..m.triangles.len() as u32).collect();
            let patch = Patch::new(&ctx, &faces);
            let p = patch.current(&ctx).unwrap();
            let bad: Vec<bool> = (0..faces.len()).map(|f| (f / 2) as u32 % n == n / 2).collect();
            let (still, _) = patch.grow(&bad, &p);
            assert_eq!(still.contains(&true), !grows, "shift {shift}");
        }
    }

    #[test]
    fn a_strip_curled_onto_itself_is_opened() {
        // A flat strip mapped to an annulus sector of 1.5 turns: no face flips, but the map
        // covers the first half turn twice.
        let m = strip(
            60,
            4,
            |s, t| [6.0 * s, 0.4 * t, 0.0],
            |s, t| {
                let a = 1.5 * std::f64::consts::TAU * s;
                let r = 1.0 + 0.4 * t;
                [r * a.cos(), r * a.sin()]
            },
        );
        let out = make_injective(&m, &InjectiveOptions::default()).unwrap();
        let r = &out.report;
        assert_eq!((r.not_injective_before, r.not_injective_after, r.reembedded), (1, 0, 1), "{r:?}");
        assert_eq!(flips_and_overlaps(&out.mesh), (0, 0));
        assert!(r.energy_after < 4.05, "a flat strip flattens isometrically: {r:?}");
    }

    #[test]
    fn a_face_wound_against_its_neighbours_gets_an_island_of_its_own() {
        let mut m = grid(6, |p| [(p[0] + 1.0) * 0.5, (p[1] + 1.0) * 0.5]);
        m.triangles[20].swap(1, 2);
        m.uv.as_mut().unwrap().triangles[20].swap(1, 2);
        let before = analyse_uv(&m, None, 1024).unwrap().stats;
        assert_eq!(before.flipped_faces, 1, "{before:?}");
        let out = make_injective(&m, &InjectiveOptions::default()).unwrap();
        let r = &out.report;
        assert_eq!((r.not_injective_before, r.not_injective_after, r.not_disc), (1, 0, 1), "{r:?}");
        assert_eq!(r.islands_after, 2, "{r:?}");
        assert_eq!(flips_and_overlaps(&out.mesh), (0, 0));
    }

    /// One projection maps a closed surface's far side mirrored under its near side, as Nuvo's
    /// networks map the two sides of a thin wall. The far side, detached, is a mirror image of
    /// a good map: it keeps that map mirrored back instead of being embedded anew.
    #[test]
    fn the_mirrored_far_side_of_a_projection_keeps_its_map() {
        let m = projected_sphere(12, 24);
        let out = make_injective(&m, &InjectiveOptions::default()).unwrap();
        let r = &out.report;
        assert_eq!((r.islands_after, r.split, r.not_injective_after), (2, 1, 0), "{r:?}");
        assert_eq!(r.reembedded, 0, "no part needed a Tutte embedding: {r:?}");
        assert_eq!(flips_and_overlaps(&out.mesh), (0, 0));
    }

    #[test]
    fn without_split_islands_stay_whole_and_a_disc_is_still_mended() {
        let m = grid(8, |p| {
            let uv = [(p[0] + 1.0) * 0.5, (p[1] + 1.0) * 0.5];
            if (p[0] + 0.5).abs() < 1e-6 && (p[1] - 0.25).abs() < 1e-6 { [0.9, 0.9] } else { uv }
        });
        let before = analyse_uv(&m, None, 1024).unwrap().stats;
        assert!(before.flipped_faces > 0, "{before:?}");
        let opts = InjectiveOptions { split: false, ..Default::default() };
        let out = make_injective(&m, &opts).unwrap();
        let r = &out.report;
        assert_eq!((r.islands_after, r.not_injective_after, r.split), (1, 0, 0), "{r:?}");
        let a = analyse_uv(&out.mesh, None, 1024).unwrap().stats;
        assert_eq!((a.flipped_faces, a.overlapping_faces), (0, 0), "{a:?}");
    }

    /// Two back-to-back pairs of faces on one edge, the pairs folded onto each other: what a
    /// marching-cubes mesh makes where a wall pinches to an edge (the unruly vase's density grid
    /// has two: faces 260187/260188 and 260652/260653 of its atlas). Every face becomes a part
    /// of its own, and the parts lie on top of each other at the origin; two of them are the
    /// same triangle from the same two mesh vertices, so their UVs along the shared edge were
    /// equal at both ends and the next step read them as one island of two faces folded onto
    /// each other (4 overlapping faces after packing). Each part must come out its own island.
    #[test]
    fn congruent_parts_on_a_shared_edge_come_out_as_separate_islands() {
        let positions = vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.5, 0.7, -0.3], [0.5, 0.7, 0.3]];
        let triangles = vec![[2, 0, 1], [1, 0, 2], [1, 0, 3], [3, 0, 1]];
        // One UV per vertex, the two apexes on one point: one island folded onto itself.
        let coords = vec![[0.0, 0.0], [1.0, 0.0], [0.5, 0.7], [0.5, 0.7]];
        let mesh =
            TriMesh { positions, uv: Some(UvLayer { coords, triangles: triangles.clone() }), triangles };
        let out = make_injective(&mesh, &InjectiveOptions::default()).unwrap();
        let (_, charts) = crate::uvstats::uv_charts(&out.mesh, out.mesh.uv.as_ref().unwrap());
        assert_eq!(charts, out.report.islands_after, "{:?}", out.report);
        assert_eq!(flips_and_overlaps(&out.mesh), (0, 0));
    }
}

//! `nuvo_atlas::refine`: local/global ARAP refinement of UV islands. Developable surfaces (a cut
//! cylinder, a cut cone) have an exact isometric unrolling, so their refined UVs must be
//! near-isometric whatever smooth warp they start from; folded, degenerate and shared-vertex
//! layouts must never get worse.

use std::time::Instant;

use nuvo_atlas::AtlasError;
use nuvo_atlas::partuv::partuv_metrics;
use nuvo_atlas::refine::{RefineOptions, RefineReport, Refined, refine_islands};
use nuvo_atlas::uvstats::{analyse_uv, uv_charts};
use nuvo_geometry::{TriMesh, UvLayer};

const TAU: f64 = std::f64::consts::TAU;

fn refine(m: &TriMesh) -> Refined {
    refine_islands(m, &RefineOptions::default()).expect("a valid mesh with UVs")
}

/// Twice the signed area of a 2-D triangle.
fn area2(a: [f32; 2], b: [f32; 2], c: [f32; 2]) -> f64 {
    let (a, b, c) = (a.map(f64::from), b.map(f64::from), c.map(f64::from));
    (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
}

fn area3(m: &TriMesh, f: usize) -> f64 {
    let [a, b, c] = m.corners(f).map(|p| p.map(f64::from));
    let (e1, e2) = ([b[0] - a[0], b[1] - a[1], b[2] - a[2]], [c[0] - a[0], c[1] - a[1], c[2] - a[2]]);
    let n = [e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0]];
    0.5 * (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt()
}

fn uv_tri(m: &TriMesh, f: usize) -> [[f32; 2]; 3] {
    let uv = m.uv.as_ref().unwrap();
    uv.triangles[f].map(|i| uv.coords[i as usize])
}

/// The largest `|r − 1|` over faces of `r = (A_uv / A_3d) / (ΣA_uv / ΣA_3d)`.
fn worst_area_ratio(m: &TriMesh) -> f64 {
    let n = m.triangles.len();
    let a3: Vec<f64> = (0..n).map(|f| area3(m, f)).collect();
    let auv: Vec<f64> = (0..n)
        .map(|f| {
            let [a, b, c] = uv_tri(m, f);
            0.5 * area2(a, b, c).abs()
        })
        .collect();
    let set = auv.iter().sum::<f64>() / a3.iter().sum::<f64>();
    (0..n).map(|f| (auv[f] / a3[f] / set - 1.0).abs()).fold(0.0, f64::max)
}

/// The same mesh and the same faces, every coordinate finite, and the report consistent with
/// `uvstats` on both sides.
fn check_invariants(input: &TriMesh, r: &Refined) {
    assert_eq!(r.mesh.positions, input.positions);
    assert_eq!(r.mesh.triangles, input.triangles);
    let uv = r.mesh.uv.as_ref().unwrap();
    assert_eq!(uv.triangles.len(), input.triangles.len());
    assert!(uv.coords.iter().flatten().all(|x| x.is_finite()), "non-finite UV");
    let rep = &r.report;
    assert_eq!(rep.refined + rep.refused + rep.small, rep.islands);
    assert!(rep.angular_before.is_finite() && rep.angular_after.is_finite());
    let before = analyse_uv(input, None, 64).unwrap().stats;
    let after = analyse_uv(&r.mesh, None, 64).unwrap().stats;
    assert_eq!(before.flipped_faces, rep.flipped_before, "flips before disagree with uvstats");
    assert_eq!(after.flipped_faces, rep.flipped_after, "flips after disagree with uvstats");
    assert!(rep.flipped_after <= rep.flipped_before, "flips increased: {rep:?}");
    assert!(rep.angular_after >= rep.angular_before - 1e-9, "angular score dropped: {rep:?}");
    // The islands stay the islands.
    let (fc_in, n_in) = uv_charts(input, input.uv.as_ref().unwrap());
    let (fc_out, n_out) = uv_charts(&r.mesh, uv);
    assert_eq!((fc_in, n_in), (fc_out, n_out), "the islands changed");
}

/// Area-weighted UV centroid and total UV area of faces `faces`.
fn placement(m: &TriMesh, faces: impl Iterator<Item = usize>) -> ([f64; 2], f64) {
    let (mut c, mut w) = ([0.0f64; 2], 0.0);
    for f in faces {
        let t = uv_tri(m, f);
        let a = area2(t[0], t[1], t[2]).abs() * 0.5;
        for p in t {
            c[0] += a * p[0] as f64 / 3.0;
            c[1] += a * p[1] as f64 / 3.0;
        }
        w += a;
    }
    ([c[0] / w, c[1] / w], w)
}

/// A grid mesh: `rows × cols` quads over mesh vertices `vid(i, j)` (i along, j across), each quad
/// two triangles `(i,j) (i+1,j) (i+1,j+1)` and `(i,j) (i+1,j+1) (i,j+1)`, with one UV coordinate
/// per grid node `(i, j)`, `0 ≤ i ≤ cols`, `0 ≤ j ≤ rows` (so a seam where `vid` wraps).
fn grid_mesh(
    positions: Vec<[f32; 3]>,
    cols: u32,
    rows: u32,
    vid: impl Fn(u32, u32) -> u32,
    uv_at: impl Fn(u32, u32) -> [f32; 2],
) -> TriMesh {
    let cid = |i: u32, j: u32| j * (cols + 1) + i;
    let mut coords = Vec::new();
    for j in 0..=rows {
        for i in 0..=cols {
            coords.push(uv_at(i, j));
        }
    }
    let (mut tris, mut uvt) = (Vec::new(), Vec::new());
    for j in 0..rows {
        for i in 0..cols {
            for q in [[(i, j), (i + 1, j), (i + 1, j + 1)], [(i, j), (i + 1, j + 1), (i, j + 1)]] {
                tris.push(q.map(|(a, b)| vid(a, b)));
                uvt.push(q.map(|(a, b)| cid(a, b)));
            }
        }
    }
    TriMesh { positions, triangles: tris, uv: Some(UvLayer { coords, triangles: uvt }) }
}

/// A closed cylinder of radius 1 and height 2 (`n` segments round, `m` up), cut open along the
/// line θ = 0 in UV, with UVs `warp(θ / 2π, (z + 1) / 2)`.
fn cylinder(n: u32, m: u32, warp: impl Fn(f64, f64) -> [f64; 2]) -> TriMesh {
    let mut positions = Vec::new();
    for j in 0..=m {
        for i in 0..n {
            let t = TAU * i as f64 / n as f64;
            positions.push([t.cos() as f32, t.sin() as f32, (-1.0 + 2.0 * j as f64 / m as f64) as f32]);
        }
    }
    grid_mesh(
        positions,
        n,
        m,
        |i, j| j * n + i % n,
        |i, j| warp(i as f64 / n as f64, j as f64 / m as f64).map(|x| x as f32),
    )
}

/// A smooth, fold-free warp of the unit square into itself, far from isometric for a cylinder
/// (whose unrolling is π : 1, not 1 : 1).
fn cylinder_warp(s: f64, t: f64) -> [f64; 2] {
    [
        0.05 + 0.9 * (s + 0.06 * (TAU * t).sin() * (std::f64::consts::PI * s).sin()),
        0.1 + 0.8 * (t + 0.08 * (TAU * s).sin() * t * (1.0 - t)),
    ]
}

#[test]
fn a_warped_cut_cylinder_refines_to_near_isometry() {
    for mirrored in [false, true] {
        let m = cylinder(48, 16, |s, t| {
            let [u, v] = cylinder_warp(s, t);
            if mirrored { [u, 1.0 - v] } else { [u, v] }
        });
        let before = partuv_metrics(&m).unwrap();
        let r = refine(&m);
        check_invariants(&m, &r);
        let after = partuv_metrics(&r.mesh).unwrap();
        assert_eq!((r.report.islands, r.report.refined), (1, 1), "{:?}", r.report);
        assert!(before.angular_score < 0.9, "the warp should distort angles: {}", before.angular_score);
        assert!(worst_area_ratio(&m) > 0.15, "the warp should distort areas");
        assert!(after.angular_score >= 0.999, "mirrored {mirrored}: angular {}", after.angular_score);
        let worst = worst_area_ratio(&r.mesh);
        assert!(worst <= 0.01, "mirrored {mirrored}: worst area ratio off by {worst}");
        assert_eq!(r.report.flipped_after, 0);
        assert!((r.report.angular_after - after.angular_score).abs() < 1e-12);
        // Same place and size in the atlas.
        let (c0, a0) = placement(&m, 0..m.triangles.len());
        let (c1, a1) = placement(&r.mesh, 0..m.triangles.len());
        assert!((a1 / a0 - 1.0).abs() < 1e-4, "area {a0} -> {a1}");
        assert!((c1[0] - c0[0]).hypot(c1[1] - c0[1]) < 1e-5, "centroid {c0:?} -> {c1:?}");
        // The developed rectangle is 2π × 2: its UV width over height must be π.
        let uv = r.mesh.uv.as_ref().unwrap();
        let (lo, hi) = uv.coords.iter().fold(([f32::MAX; 2], [f32::MIN; 2]), |(lo, hi), p| {
            ([lo[0].min(p[0]), lo[1].min(p[1])], [hi[0].max(p[0]), hi[1].max(p[1])])
        });
        let aspect = (hi[0] - lo[0]) as f64 / (hi[1] - lo[1]) as f64;
        assert!((aspect - std::f64::consts::PI).abs() < 0.02, "aspect {aspect}");
    }
}

/// A cone with apex `(0, 0, 1)` over the unit circle at z = 0 (`n` segments, `m` rings), cut open
/// along θ = 0, its apex one UV vertex; UVs `ρ(s) (cos kθ, sin kθ)` for slant fraction `s`.
fn cone(n: u32, m: u32, k: f64, rho: impl Fn(f64) -> f64) -> TriMesh {
    let mut positions = vec![[0.0, 0.0, 1.0]];
    for j in 1..=m {
        let s = j as f64 / m as f64;
        for i in 0..n {
            let t = TAU * i as f64 / n as f64;
            positions.push([(s * t.cos()) as f32, (s * t.sin()) as f32, (1.0 - s) as f32]);
        }
    }
    let mut coords = vec![[0.5f32, 0.5]];
    for j in 1..=m {
        let r = rho(j as f64 / m as f64);
        for i in 0..=n {
            let t = k * TAU * i as f64 / n as f64;
            coords.push([(0.5 + 0.45 * r * t.cos()) as f32, (0.5 + 0.45 * r * t.sin()) as f32]);
        }
    }
    let vid = |i: u32, j: u32| if j == 0 { 0 } else { 1 + (j - 1) * n + i % n };
    let cid = |i: u32, j: u32| if j == 0 { 0 } else { 1 + (j - 1) * (n + 1) + i };
    let (mut tris, mut uvt) = (Vec::new(), Vec::new());
    for i in 0..n {
        tris.push([vid(i, 0), vid(i, 1), vid(i + 1, 1)]);
        uvt.push([cid(i, 0), cid(i, 1), cid(i + 1, 1)]);
    }
    for j in 1..m {
        for i in 0..n {
            for q in [[(i, j), (i, j + 1), (i + 1, j + 1)], [(i, j), (i + 1, j + 1), (i + 1, j)]] {
                tris.push(q.map(|(a, b)| vid(a, b)));
                uvt.push(q.map(|(a, b)| cid(a, b)));
            }
        }
    }
    TriMesh { positions, triangles: tris, uv: Some(UvLayer { coords, triangles: uvt }) }
}

/// Refines `m` (a [`cone`]) with `iterations` rounds and checks the near-isometry: angular score,
/// per-face area ratios and the developed sector's opening angle 2π / √2 (slant length √2).
fn check_cone(m: &TriMesh, iterations: usize) {
    let before = partuv_metrics(m).unwrap();
    let r = refine_islands(m, &RefineOptions { iterations, ..RefineOptions::default() }).unwrap();
    check_invariants(m, &r);
    let after = partuv_metrics(&r.mesh).unwrap();
    assert_eq!((r.report.islands, r.report.refined), (1, 1), "{:?}", r.report);
    assert!(before.angular_score < 0.85, "the warp should distort angles: {}", before.angular_score);
    assert!(worst_area_ratio(m) > 0.5, "the warp should distort areas");
    assert!(after.angular_score >= 0.999, "angular {}", after.angular_score);
    let worst = worst_area_ratio(&r.mesh);
    assert!(worst <= 0.01, "worst area ratio off by {worst}");
    // The sector's opening angle at the apex: the two cut edges' directions from the apex UV.
    let uv = r.mesh.uv.as_ref().unwrap();
    let apex = uv.coords[0];
    let dir = |c: usize| {
        let p = uv.coords[c];
        ((p[1] - apex[1]) as f64).atan2((p[0] - apex[0]) as f64)
    };
    let (first, last) = (dir(1 + 15 * 49), dir(1 + 15 * 49 + 48));
    // The initial map runs counter-clockwise round the apex, and orientation is kept.
    let open = (last - first).rem_euclid(TAU);
    let want = TAU / 2f64.sqrt();
    assert!((open - want).abs() < 0.01, "sector opens {open} rad, want {want}");
}

#[test]
fn a_warped_cut_cone_refines_to_near_isometry() {
    // The developed cone is a sector of 2π / √2 ≈ 255°; the initial map opens it to 216°
    // (k = 0.6) and squeezes it radially (ρ = s^1.15): angular score 0.82, areas off by 56%.
    check_cone(&cone(48, 16, 0.6, |s| s.powf(1.15)), 10);
}

#[test]
fn a_strongly_warped_cone_needs_more_rounds() {
    // Opened to 162° (k = 0.45) and ρ = s^1.4 (angular score 0.53, areas off by 89%): 10 rounds
    // reach 0.998 only, 20 reach the isometry.
    let m = cone(48, 16, 0.45, |s| s.powf(1.4));
    let r = refine(&m);
    assert!(r.report.angular_after > 0.99 && r.report.angular_after < 0.999, "{:?}", r.report);
    check_cone(&m, 20);
}

/// The plane z = 0 over `[-1, 1]²` as `n × n` quads with one UV per vertex, `uv(x, y)`.
fn plane(n: u32, uv: impl Fn(f64, f64) -> [f64; 2]) -> TriMesh {
    let mut positions = Vec::new();
    for j in 0..=n {
        for i in 0..=n {
            positions.push([-1.0 + 2.0 * i as f32 / n as f32, -1.0 + 2.0 * j as f32 / n as f32, 0.0]);
        }
    }
    let at = |i: u32, j: u32| {
        let (x, y) = (-1.0 + 2.0 * i as f64 / n as f64, -1.0 + 2.0 * j as f64 / n as f64);
        uv(x, y).map(|c| c as f32)
    };
    grid_mesh(positions, n, n, |i, j| j * (n + 1) + i, at)
}

/// Reflects `(x, y)` across the line `{p · d = c}` (`d` a unit vector) when `p · d > c`: the part
/// of the plane beyond the line folds back over the rest.
fn fold(p: [f64; 2], d: [f64; 2], c: f64) -> [f64; 2] {
    let s = p[0] * d[0] + p[1] * d[1] - c;
    if s > 0.0 { [p[0] - 2.0 * s * d[0], p[1] - 2.0 * s * d[1]] } else { p }
}

#[test]
fn a_folded_corner_is_unfolded_and_an_isometric_fold_is_left_alone() {
    // The corner x + y > 1.1 of the plane is folded back over the chart: 30 faces flipped, the
    // faces cut by the fold line distorted. ARAP from there unfolds it.
    let d = [0.5f64.sqrt(); 2];
    let m = plane(12, |x, y| fold([x, y], d, 1.1 * 0.5f64.sqrt()).map(|c| 0.5 + 0.4 * c));
    let r = refine(&m);
    check_invariants(&m, &r);
    assert_eq!((r.report.flipped_before, r.report.flipped_after), (30, 0), "{:?}", r.report);
    assert!(r.report.angular_after > 0.99 && r.report.angular_before < 0.97, "{:?}", r.report);

    // Folded along x + y = 1 through grid vertices, every face is an isometry or its mirror image
    // (12 faces collapse onto the fold line and PartUV skips them): angular score 1. Unfolding
    // would lower it, so the island keeps its UVs, flips and all.
    let m = plane(12, |x, y| fold([x, y], d, 0.5f64.sqrt()).map(|c| 0.5 + 0.4 * c));
    let r = refine(&m);
    check_invariants(&m, &r);
    assert_eq!((r.report.refused, r.report.flipped_before, r.report.flipped_after), (1, 30, 30));
    assert_eq!(r.mesh, m);
}

/// SplitMix64: a tiny deterministic generator for the fuzz below.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
    }
    fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.next()
    }
}

#[test]
fn random_folds_never_gain_flips_or_lose_angles() {
    let (mut refined, mut flips_before, mut flips_after) = (0, 0, 0);
    for seed in 0..24u64 {
        let mut rng = Rng(seed);
        let n = 6 + (rng.next() * 10.0) as u32;
        let a = rng.range(0.0, TAU);
        let d = [a.cos(), a.sin()];
        let c = rng.range(0.2, 1.2);
        let (wx, wy, f) = (rng.range(-0.15, 0.15), rng.range(-0.15, 0.15), rng.range(1.0, 4.0));
        let jitter = rng.range(0.0, 0.6) / n as f64;
        let m = plane(n, |x, y| {
            let p = fold([x + wx * (f * y).sin(), y + wy * (f * x).cos()], d, c);
            // Per-vertex jitter (deterministic in the position) can flip faces anywhere.
            let h = ((x * 1000.0).round() as i64 * 7919 + (y * 1000.0).round() as i64) as u64;
            let mut g = Rng(seed.wrapping_mul(31).wrapping_add(h));
            [0.5 + 0.3 * p[0] + jitter * (g.next() - 0.5), 0.5 + 0.3 * p[1] + jitter * (g.next() - 0.5)]
        });
        let r = refine(&m);
        check_invariants(&m, &r);
        refined += r.report.refined;
        flips_before += r.report.flipped_before;
        flips_after += r.report.flipped_after;
    }
    // Not only safe but useful: most folds are undone (measured: 23 of 24 refined, 1155 flipped
    // faces down to 49).
    eprintln!("fuzz: {refined} of 24 refined, flips {flips_before} -> {flips_after}");
    assert!(refined >= 20, "{refined} of 24 refined");
    assert!(flips_after * 10 <= flips_before, "flips {flips_before} -> {flips_after}");
}

#[test]
fn degenerate_faces_produce_no_nan() {
    // A plane whose middle row of vertices is collapsed onto the row below it (zero-area faces),
    // with one face using a vertex twice, one UV-degenerate face, and one island made only of
    // zero-area faces.
    let n = 8;
    let mut m = plane(n, |x, y| [0.5 + 0.3 * x + 0.05 * (3.0 * y).sin(), 0.5 + 0.45 * y]);
    for i in 0..=n {
        let (src, dst) = ((n / 2) * (n + 1) + i, (n / 2 + 1) * (n + 1) + i);
        m.positions[dst as usize] = m.positions[src as usize];
    }
    m.triangles[5][2] = m.triangles[5][0];
    {
        let uv = m.uv.as_mut().unwrap();
        uv.triangles[9][1] = uv.triangles[9][0];
    }
    let base = m.positions.len() as u32;
    m.positions.extend([[2.0, 2.0, 0.0], [2.0, 2.0, 0.0], [3.0, 3.0, 0.0], [4.0, 4.0, 0.0]]);
    let uv = m.uv.as_mut().unwrap();
    let cb = uv.coords.len() as u32;
    uv.coords.extend([[0.9, 0.9], [0.95, 0.9], [0.95, 0.95], [0.9, 0.97]]);
    for t in [[0, 1, 2], [0, 2, 3], [1, 3, 2]] {
        m.triangles.push(t.map(|k| base + k));
        uv.triangles.push(t.map(|k| cb + k));
    }
    let r = refine(&m);
    check_invariants(&m, &r);
    assert!(r.report.refined >= 1, "{:?}", r.report);
}

#[test]
fn a_mesh_without_uvs_is_an_error() {
    let m = TriMesh { uv: None, ..cylinder(8, 2, cylinder_warp) };
    assert!(matches!(refine_islands(&m, &RefineOptions::default()), Err(AtlasError::NoUv { .. })));
    let mut bad = cylinder(8, 2, cylinder_warp);
    bad.uv.as_mut().unwrap().triangles.pop();
    assert!(matches!(refine_islands(&bad, &RefineOptions::default()), Err(AtlasError::Invalid { .. })));
}

#[test]
fn small_islands_stay_and_islands_touching_at_a_point_get_their_own_copy() {
    // Two warped planes side by side sharing one corner coordinate (they touch at a point in UV
    // and on the mesh), plus a lone face and a pair of faces, each its own island.
    let a = plane(6, |x, y| [0.25 + 0.2 * x + 0.03 * (2.0 * y).sin(), 0.5 + 0.2 * y * (1.0 + 0.3 * x)]);
    let na = a.positions.len() as u32;
    let nca = a.uv.as_ref().unwrap().coords.len() as u32;
    let corner = 6 * 7 + 6; // (x, y) = (1, 1) of plane a
    let at = a.uv.as_ref().unwrap().coords[corner as usize].map(f64::from);
    let b = plane(6, |x, y| {
        let (x, y) = (x + 1.0, y + 1.0);
        [at[0] + 0.15 * x + 0.02 * y * y, at[1] + 0.15 * y * (1.0 + 0.2 * x)]
    });
    let mut m = a.clone();
    // Plane b's lower-left vertex (index 0) is plane a's upper-right corner: mesh vertex and UV.
    let remap_v = |v: u32| if v == 0 { corner } else { na + v };
    let remap_c = |c: u32| if c == 0 { corner } else { nca + c };
    let ub = b.uv.as_ref().unwrap();
    let shift = [
        b.positions[0][0] - a.positions[corner as usize][0],
        b.positions[0][1] - a.positions[corner as usize][1],
    ];
    m.positions.extend(b.positions.iter().map(|p| [p[0] - shift[0], p[1] - shift[1], 0.0]));
    m.triangles.extend(b.triangles.iter().map(|t| t.map(remap_v)));
    let mut coords = a.uv.as_ref().unwrap().coords.clone();
    let mut bc = ub.coords.clone();
    bc[0] = coords[corner as usize];
    coords.extend(bc);
    let mut uvt = a.uv.as_ref().unwrap().triangles.clone();
    uvt.extend(ub.triangles.iter().map(|t| t.map(remap_c)));
    // Small islands: one face, then two faces sharing an edge.
    let p = m.positions.len() as u32;
    m.positions.extend([[5.0, 0.0, 0.0], [6.0, 0.0, 0.0], [5.0, 1.0, 0.0], [6.0, 1.0, 0.0]]);
    let c = coords.len() as u32;
    coords.extend([[0.05, 0.9], [0.1, 0.9], [0.05, 0.97], [0.12, 0.96]]);
    let first_small = m.triangles.len();
    m.triangles.push([p, p + 1, p + 2]);
    uvt.push([c, c + 1, c + 2]);
    let q = m.positions.len() as u32;
    m.positions.extend([[7.0, 0.0, 0.0], [8.0, 0.0, 0.0], [7.0, 1.0, 0.0], [8.0, 1.0, 0.0]]);
    let d = coords.len() as u32;
    coords.extend([[0.2, 0.9], [0.3, 0.9], [0.2, 0.99], [0.31, 0.97]]);
    m.triangles.extend([[q, q + 1, q + 3], [q, q + 3, q + 2]]);
    uvt.extend([[d, d + 1, d + 3], [d, d + 3, d + 2]]);
    m.uv = Some(UvLayer { coords, triangles: uvt });

    let r = refine(&m);
    check_invariants(&m, &r);
    let rep: &RefineReport = &r.report;
    assert_eq!((rep.islands, rep.refined, rep.small, rep.refused), (4, 2, 2, 0), "{rep:?}");
    assert_eq!(rep.split_coords, 1, "the shared corner needs one copy");
    let (ui, uo) = (m.uv.as_ref().unwrap(), r.mesh.uv.as_ref().unwrap());
    for f in first_small..m.triangles.len() {
        assert_eq!(uv_tri(&m, f), uv_tri(&r.mesh, f), "small island face {f} moved");
    }
    assert_eq!(uo.coords.len(), ui.coords.len() + 1);
    // Each plane keeps its place and UV area.
    let fa = a.triangles.len();
    for faces in [0..fa, fa..first_small] {
        let (c0, a0) = placement(&m, faces.clone());
        let (c1, a1) = placement(&r.mesh, faces);
        assert!((a1 / a0 - 1.0).abs() < 1e-4 && (c1[0] - c0[0]).hypot(c1[1] - c0[1]) < 1e-5);
    }
    assert!(rep.angular_after > rep.angular_before + 0.01, "{rep:?}");
}

#[test]
fn a_hundred_thousand_faces_refine_in_seconds() {
    // 250 × 200 quads = 100 000 faces in one island. The bound is loose (a busy 2-core machine);
    // the time is printed for the record.
    let m = cylinder(250, 200, cylinder_warp);
    assert_eq!(m.triangles.len(), 100_000);
    let t = Instant::now();
    let r = refine(&m);
    let secs = t.elapsed().as_secs_f64();
    eprintln!("refine_islands: 100k faces in {secs:.2} s, {:?}", r.report);
    assert_eq!(r.report.refined, 1);
    assert!(r.report.angular_after >= 0.999, "{:?}", r.report);
    assert!(secs < 60.0, "took {secs} s");
}

/// Refines a real atlas given by `NUVO_REFINE_ATLAS` (an OBJ with UVs) and prints the PartUV
/// metrics and flips before and after. `cargo test --release --test refine -- --ignored
/// --nocapture real_atlas`.
#[test]
#[ignore]
fn real_atlas() {
    let Ok(path) = std::env::var("NUVO_REFINE_ATLAS") else { return };
    for p in path.split(',') {
        let m = nuvo_atlas::load::load_mesh_with_uv(std::path::Path::new(p)).unwrap();
        let t = Instant::now();
        let r = refine(&m);
        let secs = t.elapsed().as_secs_f64();
        let (b, a) = (partuv_metrics(&m).unwrap(), partuv_metrics(&r.mesh).unwrap());
        println!(
            "{p}: {} faces, {secs:.2} s\n  angular {:.4} -> {:.4}, area (worst chart) {:.4} -> {:.4}, overall area {:.4} -> {:.4}, flips {} -> {}\n  {:?}",
            m.triangles.len(),
            b.angular_score,
            a.angular_score,
            b.area_distortion,
            a.area_distortion,
            b.overall_area_distortion,
            a.overall_area_distortion,
            r.report.flipped_before,
            r.report.flipped_after,
            r.report
        );
        check_invariants(&m, &r);
    }
}

//! The PartUV metric set (`nuvo_atlas::partuv`) on small meshes whose answers are computed by hand
//! in the comments.

use nuvo_atlas::AtlasError;
use nuvo_atlas::metrics::{EvalOptions, evaluate};
use nuvo_atlas::partuv::{PartUvMetrics, partuv_metrics};
use nuvo_geometry::{TriMesh, UvLayer};

/// A mesh from 3-D corners and UV corners per face; every face gets its own UV coordinates.
/// `faces[f]` indexes `positions`; `uvs[f]` are the UVs of its three corners.
fn mesh(positions: &[[f32; 3]], faces: &[[u32; 3]], uvs: &[[[f32; 2]; 3]]) -> TriMesh {
    assert_eq!(faces.len(), uvs.len());
    let coords = uvs.iter().flatten().copied().collect();
    let triangles = (0..faces.len() as u32).map(|f| [3 * f, 3 * f + 1, 3 * f + 2]).collect();
    TriMesh {
        positions: positions.to_vec(),
        triangles: faces.to_vec(),
        uv: Some(UvLayer { coords, triangles }),
    }
}

/// A square of side `s` in the plane z = 0 with its lower-left corner at `(x, y)`, as two
/// counter-clockwise triangles `[0, 1, 2]`, `[0, 2, 3]` over the corners
/// `(x, y), (x + s, y), (x + s, y + s), (x, y + s)`, vertex ids starting at `first`.
fn square(x: f32, y: f32, s: f32, first: u32) -> (Vec<[f32; 3]>, Vec<[u32; 3]>) {
    let p = vec![[x, y, 0.0], [x + s, y, 0.0], [x + s, y + s, 0.0], [x, y + s, 0.0]];
    let i = first;
    (p, vec![[i, i + 1, i + 2], [i, i + 2, i + 3]])
}

/// The UVs of [`square`]'s two triangles when its corners map to `(u, v), (u + t, v), ...`.
fn square_uv(u: f32, v: f32, t: f32) -> Vec<[[f32; 2]; 3]> {
    let c = [[u, v], [u + t, v], [u + t, v + t], [u, v + t]];
    vec![[c[0], c[1], c[2]], [c[0], c[2], c[3]]]
}

fn close(what: &str, got: f64, want: f64, tol: f64) {
    assert!((got - want).abs() <= tol, "{what}: got {got}, want {want} ± {tol}");
}

fn metrics(m: &TriMesh) -> PartUvMetrics {
    partuv_metrics(m).expect("a valid mesh with UVs")
}

#[test]
fn an_isometric_square_scores_perfectly_and_its_seam_is_its_perimeter() {
    // Side 0.5 in 3-D, mapped to [0.25, 0.75]² unscaled: one chart, no distortion, seam = the UV
    // perimeter 4 × 0.5 (the diagonal joins the two faces), efficiency = 0.25 of [0,1]².
    let (p, f) = square(0.0, 0.0, 0.5, 0);
    let m = mesh(&p, &f, &square_uv(0.25, 0.25, 0.5));
    let r = metrics(&m);
    assert_eq!(r.charts, 1);
    close("seam", r.seam_length, 2.0, 1e-12);
    close("angular", r.angular_score, 1.0, 1e-12);
    close("area", r.area_distortion, 1.0, 1e-12);
    close("overall area", r.overall_area_distortion, 1.0, 1e-12);
    close("efficiency", r.packing_efficiency, 0.25, 1e-12);
    assert!(r.uv_in_unit_square);
    assert_eq!((r.atlas_min, r.atlas_side), ([0.0, 0.0], 1.0));
    assert_eq!((r.angular_skipped_faces, r.area_skipped_faces, r.area_unmeasured_charts), (0, 0, 0));
}

#[test]
fn a_shear_scores_one_minus_cos_45_and_its_seam_is_the_parallelogram() {
    // u = (x + y)/4, v = y/2 on the unit square, so x = 4u − 2v, y = 2v: T = ∂p/∂u = (4, 0, 0),
    // B = ∂p/∂v = (−2, 2, 0), |cos θ| = 8 / (4 · √8) = 1/√2 on both faces. The shear is uniform, so
    // the area distortions are 1. UV parallelogram (0,0), (¼,0), (½,½), (¼,½): area ⅛, perimeter
    // 2 · ¼ + 2 · √(¼² + ½²) = ½ + √1.25.
    let (p, f) = square(0.0, 0.0, 1.0, 0);
    let uv = |q: [f32; 3]| [(q[0] + q[1]) / 4.0, q[1] / 2.0];
    let uvs: Vec<[[f32; 2]; 3]> = f.iter().map(|t| t.map(|v| uv(p[v as usize]))).collect();
    let r = metrics(&mesh(&p, &f, &uvs));
    assert_eq!(r.charts, 1);
    close("angular", r.angular_score, 1.0 - std::f64::consts::FRAC_1_SQRT_2, 1e-12);
    close("area", r.area_distortion, 1.0, 1e-12);
    close("overall area", r.overall_area_distortion, 1.0, 1e-12);
    close("efficiency", r.packing_efficiency, 0.125, 1e-12);
    close("seam", r.seam_length, 0.5 + 1.25f64.sqrt(), 1e-12);
}

#[test]
fn the_angular_score_is_a_mean_over_faces_not_a_median() {
    // Three separate faces: two mapped without shear (|cos| = 0) and one sheared as above
    // (|cos| = 1/√2). The mean |cos| is 1/(3√2); a median would be 0.
    let pos = [
        [0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [2.0, 0.0, 0.0],
        [3.0, 0.0, 0.0],
        [2.0, 1.0, 0.0],
        [4.0, 0.0, 0.0],
        [5.0, 0.0, 0.0],
        [5.0, 1.0, 0.0],
    ];
    let faces = [[0, 1, 2], [3, 4, 5], [6, 7, 8]];
    // The third: (x, y) ↦ (0.5, 0.3) + ((x + y)/4, y/2) relative to its first corner.
    let uvs = [
        [[0.0, 0.0], [0.2, 0.0], [0.0, 0.2]],
        [[0.3, 0.0], [0.5, 0.0], [0.3, 0.2]],
        [[0.5, 0.3], [0.75, 0.3], [1.0, 0.8]],
    ];
    let r = metrics(&mesh(&pos, &faces, &uvs));
    assert_eq!(r.charts, 3);
    assert!(r.uv_in_unit_square);
    close("angular", r.angular_score, 1.0 - std::f64::consts::FRAC_1_SQRT_2 / 3.0, 1e-6);
    assert_eq!(r.angular_skipped_faces, 0);
}

#[test]
fn two_charts_at_different_scales_are_fine_alone_but_not_together() {
    // Two unit squares, far apart in 3-D, mapped without distortion at UV sides ¼ and ½. Each chart
    // alone has one UV/3-D ratio: worst-chart distortion 1. Together: ΣA_uv = 1/16 + 1/4 = 5/16 over
    // ΣA_3d = 2, set ratio 5/32. The small chart's faces have r = (1/16)/(5/32) = 0.4 → 2.5, the
    // large one's r = (1/4)/(5/32) = 1.6; plain mean over the four faces (2.5 + 1.6)/2 = 2.05.
    let (mut p, mut f) = square(0.0, 0.0, 1.0, 0);
    let (p2, f2) = square(3.0, 0.0, 1.0, 4);
    p.extend(p2);
    f.extend(f2);
    let mut uvs = square_uv(0.0, 0.0, 0.25);
    uvs.extend(square_uv(0.5, 0.5, 0.5));
    let m = mesh(&p, &f, &uvs);
    let r = metrics(&m);
    assert_eq!(r.charts, 2);
    close("area (worst chart)", r.area_distortion, 1.0, 1e-12);
    close("overall area", r.overall_area_distortion, 2.05, 1e-12);
    close("efficiency", r.packing_efficiency, 5.0 / 16.0, 1e-12);
    close("seam", r.seam_length, 4.0 * 0.25 + 4.0 * 0.5, 1e-12);
    close("angular", r.angular_score, 1.0, 1e-12);
    // Both distortions are free of the 3-D scale.
    let mut big = m.clone();
    big.positions.iter_mut().for_each(|q| *q = q.map(|c| c * 8.0));
    let rb = metrics(&big);
    close("overall area, 8× larger", rb.overall_area_distortion, 2.05, 1e-12);
    close("seam, 8× larger", rb.seam_length, r.seam_length, 0.0);
}

#[test]
fn a_face_split_off_is_a_second_chart_and_the_cut_counts_once_per_side() {
    // The square of the first test with its second face moved in UV: the two faces still share the
    // mesh edge 0–2 (the diagonal) but not its UVs. Two charts; every edge use now bounds a chart,
    // so the seam is both triangles' perimeters, 2 × (½ + ½ + ½√2) = 2 + √2: the diagonal counts
    // twice, once for each chart it bounds.
    let (p, f) = square(0.0, 0.0, 0.5, 0);
    let mut uvs = square_uv(0.0, 0.0, 0.5);
    uvs[1] = uvs[1].map(|q| [q[0] + 0.5, q[1] + 0.25]);
    let r = metrics(&mesh(&p, &f, &uvs));
    assert_eq!(r.charts, 2);
    close("seam", r.seam_length, 2.0 + std::f64::consts::SQRT_2, 1e-12);
    close("area", r.area_distortion, 1.0, 1e-12);
    close("overall area", r.overall_area_distortion, 1.0, 1e-12);
    close("efficiency", r.packing_efficiency, 0.25, 1e-12);
}

#[test]
fn a_cut_inside_one_chart_counts_both_sides_although_the_chart_stays_whole() {
    // A fan of four faces around the centre c = (0,0), outer corners (1,0), (0,1), (−1,0), (0,−1),
    // mapped by uv = (½,½) + ¼·(x, y), except that the last face [c, (0,−1), (1,0)] puts (1,0) at
    // (¾, ¼) instead of (¾, ½). It still shares spoke c–(0,−1) with the third face, so the fan is
    // one chart, but spoke c–(1,0) is cut: its two sides count, ¼ (first face) and ¼√2 (last face).
    // Outer edges: 3 × ¼√2 for the first three faces and ¼ for the last. Total ½ + √2.
    let pos = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]];
    let faces = [[0, 1, 2], [0, 2, 3], [0, 3, 4], [0, 4, 1]];
    let uv = |v: u32| {
        let q: [f32; 3] = pos[v as usize];
        [0.5 + 0.25 * q[0], 0.5 + 0.25 * q[1]]
    };
    let mut uvs: Vec<[[f32; 2]; 3]> = faces.iter().map(|t| t.map(uv)).collect();
    uvs[3][2] = [0.75, 0.25];
    let r = metrics(&mesh(&pos, &faces, &uvs));
    assert_eq!(r.charts, 1);
    close("seam", r.seam_length, 0.5 + std::f64::consts::SQRT_2, 1e-7);
}

#[test]
fn a_folded_ratio_is_clipped_at_ten() {
    // The unit square with corner 3 moved in UV to (0.49, 0.51), next to the diagonal: face 1 keeps
    // UV area ½, face 2 shrinks to 0.01; both have 3-D area ½. Set ratio 0.51 / 1: face 1 has
    // r = 1/0.51 = 100/51, face 2 r = 0.02/0.51 → 25.5, clipped to 10. One chart, so worst chart =
    // overall = (100/51 + 10)/2 = 610/102 (unclipped it would be 13.7).
    let (p, f) = square(0.0, 0.0, 1.0, 0);
    let mut uvs = square_uv(0.0, 0.0, 1.0);
    uvs[1][2] = [0.49, 0.51];
    let r = metrics(&mesh(&p, &f, &uvs));
    assert_eq!(r.charts, 1);
    close("area", r.area_distortion, 610.0 / 102.0, 1e-5);
    close("overall area", r.overall_area_distortion, 610.0 / 102.0, 1e-5);
    close("efficiency", r.packing_efficiency, 0.51, 1e-6);
}

#[test]
fn degenerate_and_negligible_faces_are_skipped_and_counted() {
    // Four charts, each on its own vertices:
    // - the isometric ½-square (two faces, 3-D and UV areas ⅛ each);
    // - Z: 3-D area ⅛, all three UVs on one point (zero UV area);
    // - S: a 3-D sliver of area ½ · ½ · 4e-6 = 1e-6 with legs along x and y, UV area ½ · 0.1² =
    //   0.005 with legs along u and v (so |cos| = 0);
    // - D: a face using one vertex twice (zero 3-D area) with UV area 0.005.
    // Angular: Z (UV-degenerate) and D (3-D-degenerate) are skipped; the other three have |cos| 0.
    // Overall area distortion: ΣA_3d = ⅜ + 1e-6 over 5 faces, so faces below 1e-4 × 0.075 are
    // left out: S, and Z (zero UV area) and D (zero 3-D area). The sums still include them:
    // ΣA_uv = ¼ + 0.005 + 0.005 = 0.26, so the two square faces have r = 0.26/0.375001 and fold to
    // 0.375001/0.26 (1 if the sums left the skipped faces out).
    // Worst chart: the square 1, S alone (its own mean, so measured) 1; Z and D measure nothing.
    let (mut p, mut f) = square(0.0, 0.0, 0.5, 0);
    let mut uvs = square_uv(0.0, 0.0, 0.5);
    p.extend([[1.0, 0.0, 0.0], [1.5, 0.0, 0.0], [1.0, 0.5, 0.0]]); // Z: 4, 5, 6
    f.push([4, 5, 6]);
    uvs.push([[0.7, 0.7]; 3]);
    p.extend([[2.0, 0.0, 0.0], [2.5, 0.0, 0.0], [2.0, 4e-6, 0.0]]); // S: 7, 8, 9
    f.push([7, 8, 9]);
    uvs.push([[0.6, 0.0], [0.7, 0.0], [0.6, 0.1]]);
    p.extend([[3.0, 0.0, 0.0], [3.0, 1.0, 0.0]]); // D: 10, 11
    f.push([10, 10, 11]);
    uvs.push([[0.8, 0.0], [0.9, 0.0], [0.8, 0.1]]);
    let r = metrics(&mesh(&p, &f, &uvs));
    assert_eq!(r.charts, 4);
    close("angular", r.angular_score, 1.0, 1e-9);
    assert_eq!(r.angular_skipped_faces, 2);
    let sliver = 0.25 * 4e-6f32 as f64; // the sliver's 3-D area, from its f32 leg
    close("overall area", r.overall_area_distortion, (0.375 + sliver) / 0.26, 1e-6);
    assert_eq!(r.area_skipped_faces, 3);
    close("area (worst chart)", r.area_distortion, 1.0, 1e-9);
    assert_eq!(r.area_unmeasured_charts, 2);
    close("efficiency", r.packing_efficiency, 0.26, 1e-6);
}

#[test]
fn nothing_measurable_scores_the_worst_values() {
    // One face whose UVs all sit on one point: no angle, no area ratio.
    let m = mesh(&[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]], &[[0, 1, 2]], &[[[0.5, 0.5]; 3]]);
    let r = metrics(&m);
    assert_eq!((r.angular_score, r.angular_skipped_faces), (0.0, 1));
    assert_eq!((r.area_distortion, r.area_unmeasured_charts), (10.0, 1));
    assert_eq!((r.overall_area_distortion, r.area_skipped_faces), (10.0, 1));
    assert_eq!((r.packing_efficiency, r.seam_length), (0.0, 0.0));
    assert!(r.uv_in_unit_square);
}

#[test]
fn uvs_outside_the_unit_square_are_measured_in_their_bounding_square() {
    // The ½-square mapped to [2, 4]² (4× larger, still without distortion): the atlas square is
    // the UVs' bounding square, side 2 at (2, 2), which they fill: efficiency 1, seam 8/2 = 4.
    let (p, f) = square(0.0, 0.0, 0.5, 0);
    let r = metrics(&mesh(&p, &f, &square_uv(2.0, 2.0, 2.0)));
    assert!(!r.uv_in_unit_square);
    assert_eq!((r.atlas_min, r.atlas_side), ([2.0, 2.0], 2.0));
    close("efficiency", r.packing_efficiency, 1.0, 1e-12);
    close("seam", r.seam_length, 4.0, 1e-12);
    close("area", r.overall_area_distortion, 1.0, 1e-12);
    close("angular", r.angular_score, 1.0, 1e-12);
}

#[test]
fn missing_uvs_and_empty_meshes_are_errors() {
    let (p, f) = square(0.0, 0.0, 1.0, 0);
    let mut m = mesh(&p, &f, &square_uv(0.0, 0.0, 1.0));
    m.uv = None;
    assert!(matches!(partuv_metrics(&m), Err(AtlasError::NoUv { .. })));
    let empty = mesh(&p, &[], &[]);
    assert!(matches!(partuv_metrics(&empty), Err(AtlasError::Invalid { .. })));
}

#[test]
fn evaluate_carries_the_set_in_its_json() {
    let (p, f) = square(0.0, 0.0, 0.5, 0);
    let m = mesh(&p, &f, &square_uv(0.25, 0.25, 0.5));
    let opts = EvalOptions { views: 2, resolution: 64, uv_raster: 32, ..Default::default() };
    let e = evaluate(&m, &opts).unwrap();
    assert_eq!(e.partuv, metrics(&m));
    let json = serde_json::to_value(&e).unwrap();
    for key in ["charts", "seam_length", "angular_score", "area_distortion", "overall_area_distortion"] {
        assert!(json["partuv"][key].is_number(), "{key} missing: {}", json["partuv"]);
    }
    assert_eq!(json["partuv"]["packing_efficiency"], 0.25);
}

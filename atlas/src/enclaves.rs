//! Absorbing chart enclaves in the bake: a small patch of faces that the chart network gave to
//! one chart, surrounded by faces of one other chart, moves to the surrounding chart when that
//! chart maps it the right way round.
//!
//! Why: on marching-cubes meshes of neural fields the chart network's argmax is noisy face by face,
//! and a chart region is riddled with specks of another chart, often a single face. Each speck is
//! an island of its own after the bake, with a seam all round it that every render crossing it
//! sees: on a marching-cubes homer such holes drew rings of boundary pixels over the whole body.
//! The surrounding chart's texture network is defined there too and usually continuous across
//! the speck, so taking it over removes the seam without a new fold. The join step after the
//! layout ([`crate::join`]) cannot do this: it needs the speck's island to fit into the hole that
//! refinement left, with a bounded distortion, and mostly refuses.
//!
//! Definitions (exact):
//! - **Regions**: faces joined across a mesh edge used by exactly two faces, both of one chart
//!   (the connected components of the chart labels). Edges of one face or of three or more do not
//!   join.
//! - **Neighbours** of a region: the faces across its joining edges that are of another chart.
//! - **Enclave**: a region with neighbours, all of one chart `j`, whose 3-D area is below that of
//!   the largest region of `j` it borders (so the smaller side moves, and whole components such as
//!   floaters, which have no neighbours, never do).
//! - **Check**: every face of the enclave that has a 3-D area must have, under chart `j`'s texture
//!   map, a positive UV area with `j`'s majority orientation (the sign of the summed signed UV area
//!   of `j`'s faces as baked), so absorbing adds no flipped face; faces degenerate in 3-D
//!   ([`crate::uvstats`]) are not checked, as no render sees them and refinement reshapes them.
//!   And the caller's `allowed(face, j)` must hold for every face (the bake's round-trip check).
//! - **Order**: the regions of the start are judged once each in order of their starting area
//!   (ties: lowest face), against the labels and regions as they are by then. An enclave and the
//!   host regions it touches become one region, judged when the largest host's turn comes, so a
//!   speck inside a speck moves before its host is judged; a region already absorbed is skipped.
//!
//! Deterministic: no hashing order is observed.

use nuvo_geometry::TriMesh;

use crate::geom::signed_area2_2d;
use crate::partuv::face_areas_3d;
use crate::uvstats::{Dsu, degenerate_3d_faces, faces_by_edge};

/// Moves every enclave (module docs) of `face_chart` to its surrounding chart where the check
/// passes; `chart_uv(v, c)` is chart `c`'s UV at vertex `v`, and `allowed(f, c)` must hold for
/// every face `f` of an enclave for it to take chart `c` (the bake's round-trip check, so that an
/// absorbed speck does not bring back an overlap that check removed). Returns the faces moved.
pub fn absorb_enclaves(
    mesh: &TriMesh,
    chart_uv: impl Fn(u32, u32) -> [f32; 2],
    allowed: impl Fn(u32, u32) -> bool,
    face_chart: &mut [u32],
) -> usize {
    let faces = mesh.triangles.len();
    let degenerate = degenerate_3d_faces(mesh);
    let area = face_areas_3d(mesh);
    let signed = |f: usize, c: u32| {
        let t = mesh.triangles[f];
        signed_area2_2d(chart_uv(t[0], c), chart_uv(t[1], c), chart_uv(t[2], c))
    };
    let charts = face_chart.iter().map(|&c| c as usize + 1).max().unwrap_or(0);
    let mut majority = vec![0.0f64; charts];
    for (f, &c) in face_chart.iter().enumerate() {
        majority[c as usize] += signed(f, c);
    }
    // Faces across each joining edge (exactly two faces use it).
    let uses = faces_by_edge(mesh.triangles.iter().enumerate().map(|(f, &t)| (f as u32, t)));
    let mut across: Vec<Vec<u32>> = vec![Vec::new(); faces];
    for (f, t) in mesh.triangles.iter().enumerate() {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            let pair = &uses[&(a.min(b), a.max(b))];
            if pair.len() == 2 {
                let o = if pair[0] == f as u32 { pair[1] } else { pair[0] };
                if o != f as u32 {
                    across[f].push(o);
                }
            }
        }
    }
    let mut dsu = Dsu::new(faces);
    for f in 0..faces {
        for &o in &across[f] {
            if face_chart[o as usize] == face_chart[f] {
                dsu.union(f as u32, o);
            }
        }
    }
    // Each face's region at the start (its lowest face), and where each region has been merged
    // into since: a region that absorbs a speck stays under the key of the largest region it
    // joined, which has yet to be judged, whatever the face numbering.
    let start: Vec<u32> = (0..faces as u32).map(|f| dsu.find(f)).collect();
    let mut owner: Vec<u32> = (0..faces as u32).collect();
    let current = |owner: &mut Vec<u32>, mut x: u32| -> u32 {
        while owner[x as usize] != x {
            let up = owner[owner[x as usize] as usize];
            owner[x as usize] = up;
            x = up;
        }
        x
    };
    let mut members: Vec<Vec<u32>> = vec![Vec::new(); faces];
    let mut region_area = vec![0.0f64; faces];
    for (f, a) in area.iter().enumerate() {
        members[start[f] as usize].push(f as u32);
        region_area[start[f] as usize] += a;
    }
    let mut order: Vec<u32> = (0..faces as u32).filter(|&r| !members[r as usize].is_empty()).collect();
    order.sort_by(|&a, &b| region_area[a as usize].total_cmp(&region_area[b as usize]).then(a.cmp(&b)));
    let mut moved = 0;
    for r in order {
        if current(&mut owner, r) != r {
            continue; // absorbed into another region, judged under that one's key
        }
        let own = face_chart[members[r as usize][0] as usize];
        let mut host: Option<u32> = None;
        let mut single = true;
        let mut hosts: Vec<u32> = Vec::new();
        for &f in &members[r as usize] {
            for &o in &across[f as usize] {
                let c = face_chart[o as usize];
                if c == own {
                    continue;
                }
                single &= host.is_none_or(|h| h == c);
                host = Some(c);
                hosts.push(current(&mut owner, start[o as usize]));
            }
        }
        let Some(j) = host else { continue };
        hosts.sort_unstable();
        hosts.dedup();
        // The largest host region (ties: the lowest key).
        let Some(&key) = hosts
            .iter()
            .max_by(|&&a, &&b| region_area[a as usize].total_cmp(&region_area[b as usize]).then(b.cmp(&a)))
        else {
            continue;
        };
        if !single || region_area[r as usize] >= region_area[key as usize] {
            continue;
        }
        let sign = majority[j as usize];
        let fits = members[r as usize]
            .iter()
            .all(|&f| allowed(f, j) && (degenerate[f as usize] || signed(f as usize, j) * sign > 0.0));
        if !fits {
            continue;
        }
        for &f in &members[r as usize] {
            face_chart[f as usize] = j;
        }
        moved += members[r as usize].len();
        // One region now: the enclave and every host region it touches, under `key`.
        for h in hosts.into_iter().filter(|&h| h != key).chain([r]) {
            let mut taken = std::mem::take(&mut members[h as usize]);
            members[key as usize].append(&mut taken);
            region_area[key as usize] += region_area[h as usize];
            owner[h as usize] = key;
        }
    }
    moved
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testmesh::grid;

    /// An 8 × 8-quad plane (128 faces) whose every vertex has UV `(x, y)` in chart 0 and
    /// `(x, -y)` in chart 1 (mirrored); `face_chart` puts every face on chart 0 but those listed.
    fn plane(on_one: &[usize]) -> (TriMesh, Vec<u32>) {
        let m = grid(8, |p| [p[0], p[1]]);
        let mut chart = vec![0u32; m.triangles.len()];
        for &f in on_one {
            chart[f] = 1;
        }
        (m, chart)
    }

    fn uv_of(m: &TriMesh) -> impl Fn(u32, u32) -> [f32; 2] + '_ {
        |v, c| {
            let p = m.positions[v as usize];
            if c == 0 { [p[0], p[1]] } else { [p[0], -p[1]] }
        }
    }

    #[test]
    fn a_speck_inside_a_chart_joins_it() {
        // Faces 2 × (3·8 + 3) and its pair: one quad in the middle.
        let (m, mut chart) = plane(&[54, 55]);
        assert_eq!(absorb_enclaves(&m, uv_of(&m), |_, _| true, &mut chart), 2);
        assert!(chart.iter().all(|&c| c == 0));
    }

    #[test]
    fn a_speck_inside_a_speck_moves_first_then_its_host_whatever_the_face_order() {
        // Chart 2 is one quad (faces 54, 55) inside a 4 × 4-quad block of chart 1 (columns and
        // rows 2–5), inside chart 0. Then the same mesh with the inner speck's faces numbered
        // first, so that it, not its host, holds the lowest face.
        for speck_first in [false, true] {
            let (mut m, _) = plane(&[]);
            let mut order: Vec<usize> = (0..m.triangles.len()).collect();
            if speck_first {
                order.retain(|&f| f != 54 && f != 55);
                order.splice(0..0, [54, 55]);
            }
            m.triangles = order.iter().map(|&f| m.triangles[f]).collect();
            let mut chart: Vec<u32> = order
                .iter()
                .map(|&f| {
                    let (i, j) = ((f / 2) % 8, (f / 2) / 8);
                    if f == 54 || f == 55 {
                        2
                    } else if (2..6).contains(&i) && (2..6).contains(&j) {
                        1
                    } else {
                        0
                    }
                })
                .collect();
            // Every chart maps the plane as it is: nothing flips anywhere.
            let uv = |v: u32, _c: u32| {
                let p = m.positions[v as usize];
                [p[0], p[1]]
            };
            // The speck's 2 faces join the block, then the block's 32 join chart 0.
            assert_eq!(absorb_enclaves(&m, uv, |_, _| true, &mut chart), 34, "speck first: {speck_first}");
            assert!(chart.iter().all(|&c| c == 0), "speck first: {speck_first}");
        }
    }

    #[test]
    fn a_speck_the_caller_does_not_allow_stays() {
        let (m, mut chart) = plane(&[54, 55]);
        assert_eq!(absorb_enclaves(&m, uv_of(&m), |f, _| f != 55, &mut chart), 0);
        assert_eq!(chart.iter().filter(|&&c| c == 1).count(), 2);
    }

    #[test]
    fn the_larger_side_stays() {
        // Chart 1 holds the upper half: its only neighbour chart is 0, but it is not smaller.
        let half: Vec<usize> = (64..128).collect();
        let (m, mut chart) = plane(&half);
        let before = chart.clone();
        assert_eq!(absorb_enclaves(&m, uv_of(&m), |_, _| true, &mut chart), 0);
        assert_eq!(chart, before);
    }

    #[test]
    fn a_speck_its_host_would_flip_stays() {
        // The host chart 0 mirrors the speck's quad (x in [-0.25, 0], y in [-0.25, 0]) in u.
        let (m, mut chart) = plane(&[54, 55]);
        let folded = |v: u32, c: u32| {
            let p = m.positions[v as usize];
            let corner = (-0.3..0.05).contains(&p[0]) && (-0.3..0.05).contains(&p[1]);
            match (c, corner) {
                (0, true) => [-0.25 - p[0], p[1]],
                (0, false) => [p[0], p[1]],
                _ => [p[0], -p[1]],
            }
        };
        assert_eq!(absorb_enclaves(&m, folded, |_, _| true, &mut chart), 0);
        assert_eq!(chart.iter().filter(|&&c| c == 1).count(), 2);
    }

    #[test]
    fn a_region_between_two_other_charts_stays() {
        // Chart 1 is a full-height band (columns 3–4) between chart 0 on the left and chart 2 on
        // the right: its neighbours are of two charts.
        let (m, mut chart) = plane(&[]);
        for (f, c) in chart.iter_mut().enumerate() {
            let column = (f / 2) % 8;
            *c = match column {
                0..=2 => 0,
                3..=4 => 1,
                _ => 2,
            };
        }
        let before = chart.clone();
        let uv = |v: u32, _c: u32| {
            let p = m.positions[v as usize];
            [p[0], p[1]]
        };
        assert_eq!(absorb_enclaves(&m, uv, |_, _| true, &mut chart), 0);
        assert_eq!(chart, before);
    }
}

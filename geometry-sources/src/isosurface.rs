//! Triangle meshes from node-sampled scalar grids: marching cubes, for giving a density grid a mesh to
//! bake UVs onto.
//!
//! The cube-by-cube triangulation is the `mcubes` crate's (the classic Lorensen–Cline tables); this
//! module runs it over slabs of the grid in parallel, maps its vertices back into our axis order and
//! frame, and turns its triangle soup (three fresh vertices per triangle) into a welded mesh:
//!
//! - **Welding.** Every marching-cubes vertex lies on a grid edge (or on a node, when a value equals
//!   the level), so vertices are welded by the edge or node they lie on, not by comparing floats:
//!   neighbouring cells interpolate a shared edge from opposite ends and may differ in the last bit.
//! - **Degenerate triangles.** Where a node's value equals the level, several edges' vertices meet
//!   at that node and some triangles collapse to a segment or a point; those (two equal corners after
//!   welding) are dropped, and vertices only they used are removed. Triangles with three distinct but
//!   collinear corners are kept: they close the surface topologically, and [`TriMesh`] allows them.
//! - **Winding.** Outward, i.e. normals point towards values below the level (for a density: out of
//!   the matter, towards empty space).
//! - **Boundary.** The grid is not padded: a surface that reaches the grid's box stays open there,
//!   like scikit-image's `marching_cubes` (which made the shared test meshes), so every vertex lies
//!   inside the box.

use std::collections::HashMap;
use std::hash::{BuildHasherDefault, Hasher};

use rayon::prelude::*;

use crate::coords::V3;
use crate::mesh::TriMesh;

/// Cell layers (along the slowest axis) per slab extracted in parallel. Fixed, so the mesh does not
/// depend on the number of threads.
const SLAB_CELLS: usize = 32;

/// A scalar field sampled at the nodes of a box. Invariant: `dims[k] >= 2`,
/// `values.len() == dims[0] * dims[1] * dims[2]` in C order (`array[i, j, k]`, `k` fastest), values
/// finite, `min < max` componentwise. Node `(i, j, k)` sits at `min + (max - min) * (i, j, k) / (dims - 1)`.
#[derive(Clone, Copy, Debug)]
pub struct NodeGrid<'a> {
    /// Nodes per axis.
    pub dims: [usize; 3],
    /// The values, C order.
    pub values: &'a [f32],
    /// Where node `(0, 0, 0)` sits.
    pub min: V3,
    /// Where the last node sits.
    pub max: V3,
}

/// The surface where the grid's trilinear field equals `level`, by marching cubes: welded, outward
/// (normals towards values below `level`), no collapsed triangles, every vertex inside the box.
/// Values at or above `level` count as inside. Empty when no cell straddles the level.
///
/// # Panics
/// When `grid` breaks its invariants (a programming error: callers validate user input first).
pub fn marching_cubes(grid: &NodeGrid, level: f32) -> TriMesh {
    let [n0, n1, n2] = grid.dims;
    assert!(grid.dims.iter().all(|&n| n >= 2), "grid dims {:?} need 2 nodes per axis", grid.dims);
    assert_eq!(grid.values.len(), n0 * n1 * n2, "grid values do not match dims {:?}", grid.dims);
    let slabs: Vec<usize> = (0..n0 - 1).step_by(SLAB_CELLS).collect();
    let soups: Vec<Vec<V3>> = slabs.par_iter().map(|&i0| slab_soup(grid, level, i0)).collect();
    weld(grid, &soups)
}

/// The triangle corners (three per triangle, outward order) of the cells whose first node layer is
/// in `i0 .. i0 + SLAB_CELLS`, in grid index coordinates `(i, j, k)`.
fn slab_soup(grid: &NodeGrid, level: f32, i0: usize) -> Vec<V3> {
    let [n0, n1, n2] = grid.dims;
    let i1 = (i0 + SLAB_CELLS).min(n0 - 1);
    let layer = n1 * n2;
    let values = grid.values[i0 * layer..(i1 + 1) * layer].to_vec();
    // mcubes indexes `values[x + y * nx + z * nx * ny]`: its x is our k, its z our i.
    let mc = mcubes::MarchingCubes::new(
        (n2, n1, i1 - i0 + 1),
        (1.0, 1.0, 1.0),
        (1.0, 1.0, 1.0),
        lin_alg::f32::Vec3::new_zero(),
        values,
        level,
    )
    .expect("slab length matches its dims");
    // Its `OutsideOnly` triangles, with the axes swapped back to ours (a reflection, which reverses
    // the winding), wind counter-clockwise seen from the low side: pinned by the sphere test.
    let soup = mc.generate(mcubes::MeshSide::OutsideOnly);
    soup.indices
        .iter()
        .map(|&v| {
            let p = soup.vertices[v].posit;
            // Integer offsets keep the edge coordinates exact integers (see `weld`).
            [p.z + i0 as f32, p.y, p.x]
        })
        .collect()
}

/// The grid element a vertex (in grid index coordinates `g`) lies on, as one number: the edge along
/// axis `a` from node `n`, or the node `n` itself (`a = 3`), is `4 * linear(n) + a`.
///
/// Marching cubes puts a vertex at `p + (q - p) * t` on the edge between nodes `p` and `q`, so two of
/// its coordinates are exact integers and the third is the interpolated one; at `t = 0` or `1` all
/// three are.
fn site(dims: [usize; 3], g: V3) -> u64 {
    let axis = (0..3).find(|&k| g[k].fract() != 0.0).unwrap_or(3) as u64;
    let [i, j, k] = g.map(|c| c.floor() as u64);
    4 * ((i * dims[1] as u64 + j) * dims[2] as u64 + k) + axis
}

/// A multiplicative hash for [`site`] numbers, which are distinct integers: SipHash's resistance to
/// chosen keys buys nothing here and made welding a third of the extraction time.
#[derive(Default)]
struct SiteHasher(u64);

impl Hasher for SiteHasher {
    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.write_u64(u64::from(b));
        }
    }

    fn write_u64(&mut self, x: u64) {
        self.0 = (self.0 ^ x).wrapping_mul(0x9e37_79b9_7f4a_7c15);
    }

    fn finish(&self) -> u64 {
        // hashbrown takes buckets from the low bits and tags from the top ones: mix both ways.
        self.0.rotate_left(26)
    }
}

/// Welds the slabs' soups of triangle corners (grid index coordinates, three per triangle) into a
/// mesh in the grid's frame, dropping collapsed triangles and the vertices only they used.
fn weld(grid: &NodeGrid, soups: &[Vec<V3>]) -> TriMesh {
    let corners = soups.iter().map(Vec::len).sum::<usize>();
    // A closed marching-cubes surface has about one vertex per six triangle corners.
    let mut ids: HashMap<u64, u32, BuildHasherDefault<SiteHasher>> =
        HashMap::with_capacity_and_hasher(corners / 5, BuildHasherDefault::default());
    let mut sites: Vec<V3> = Vec::with_capacity(corners / 5);
    let mut corner_ids = Vec::with_capacity(corners);
    for &g in soups.iter().flatten() {
        let id = *ids.entry(site(grid.dims, g)).or_insert_with(|| {
            sites.push(g);
            sites.len() as u32 - 1
        });
        corner_ids.push(id);
    }
    let kept: Vec<[u32; 3]> = corner_ids
        .chunks_exact(3)
        .map(|t| [t[0], t[1], t[2]])
        .filter(|[a, b, c]| a != b && b != c && a != c)
        .collect();
    // Renumber in order of first use so vertices of dropped triangles disappear.
    let mut remap = vec![u32::MAX; sites.len()];
    let mut positions = Vec::new();
    let triangles = kept
        .iter()
        .map(|t| {
            t.map(|v| {
                if remap[v as usize] == u32::MAX {
                    remap[v as usize] = positions.len() as u32;
                    positions.push(to_frame(grid, sites[v as usize]));
                }
                remap[v as usize]
            })
        })
        .collect();
    TriMesh { positions, triangles, uv: None }
}

/// Grid index coordinates to the grid's frame; the first and last node layers land exactly on
/// `min` and `max`, so the mesh never leaves the box.
fn to_frame(grid: &NodeGrid, g: V3) -> V3 {
    std::array::from_fn(|k| {
        let t = g[k] / (grid.dims[k] - 1) as f32;
        grid.min[k] * (1.0 - t) + grid.max[k] * t
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `f` sampled on an `n^3` grid over `[-1, 1]^3`.
    fn sampled(n: usize, f: impl Fn(V3) -> f32) -> Vec<f32> {
        let c = |i: usize| -1.0 + 2.0 * i as f32 / (n - 1) as f32;
        let mut v = Vec::with_capacity(n * n * n);
        for i in 0..n {
            for j in 0..n {
                for k in 0..n {
                    v.push(f([c(i), c(j), c(k)]));
                }
            }
        }
        v
    }

    fn grid(n: usize, values: &[f32]) -> NodeGrid<'_> {
        NodeGrid { dims: [n; 3], values, min: [-1.0; 3], max: [1.0; 3] }
    }

    #[test]
    fn a_plane_is_welded_flat_and_faces_the_low_side() {
        // Values grow with x: the surface x = 0.1 faces -x, towards the low values.
        let n = 9;
        let values = sampled(n, |p| p[0]);
        let m = marching_cubes(&grid(n, &values), 0.1);
        assert!(!m.triangles.is_empty());
        for f in 0..m.triangles.len() {
            let nrm = m.face_normal_scaled(f);
            assert!(nrm[0] < 0.0 && nrm[1].abs() < 1e-6 && nrm[2].abs() < 1e-6, "face {f}: {nrm:?}");
        }
        // A welded (n-1)^2-cell plane has n^2 vertices.
        assert_eq!(m.positions.len(), n * n);
        assert!(m.positions.iter().all(|p| (p[0] - 0.1).abs() < 1e-6));
    }

    #[test]
    fn values_equal_to_the_level_give_no_collapsed_triangles_or_orphan_vertices() {
        // Integer values with many nodes exactly at the level, like uint8 grids.
        let n = 12;
        let values =
            sampled(n, |p| ((p[0] * 7.0).round() + (p[1] * 5.0).round() + (p[2] * 3.0).round()).abs());
        let m = marching_cubes(&grid(n, &values), 3.0);
        assert!(!m.triangles.is_empty());
        let mut used = vec![false; m.positions.len()];
        for t in &m.triangles {
            assert!(t[0] != t[1] && t[1] != t[2] && t[0] != t[2], "collapsed {t:?}");
            t.iter().for_each(|&v| used[v as usize] = true);
        }
        assert!(used.iter().all(|&u| u), "unreferenced vertices");
        assert!(m.validate().is_ok());
    }

    #[test]
    fn the_mesh_does_not_depend_on_the_slab_split_or_threads() {
        // A grid deeper than one slab: vertices on slab boundaries must weld.
        let n = 2 * SLAB_CELLS + 7;
        let values = sampled(n, |p| 1.0 - (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt());
        let g = grid(n, &values);
        let one = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap()
            .install(|| marching_cubes(&g, 0.3));
        let two = rayon::ThreadPoolBuilder::new()
            .num_threads(2)
            .build()
            .unwrap()
            .install(|| marching_cubes(&g, 0.3));
        assert_eq!(one, two);
        // Closed: every edge is shared by exactly two triangles, in opposite directions.
        let mut edges = HashMap::new();
        for t in &one.triangles {
            for k in 0..3 {
                *edges.entry((t[k], t[(k + 1) % 3])).or_insert(0) += 1;
            }
        }
        for (&(a, b), &count) in &edges {
            assert_eq!(count, 1, "edge {a}-{b} used {count} times in one direction");
            assert_eq!(edges.get(&(b, a)), Some(&1), "edge {a}-{b} is open");
        }
    }

    #[test]
    fn no_crossing_gives_an_empty_mesh() {
        let values = vec![5.0; 27];
        assert!(marching_cubes(&grid(3, &values), 12.0).triangles.is_empty());
        assert!(marching_cubes(&grid(3, &values), 1.0).triangles.is_empty());
    }
}

//! A volume-density grid and volume rendering along rays: the NeRF side of the density source.
//!
//! Densities live on grid *nodes* (`x_i = min + i * (max - min) / (n - 1)`), are interpolated
//! trilinearly and are zero outside the grid. Rendering follows NeRF: along a ray clipped to the grid,
//! stratified samples `t_i` (one uniform jitter per step), `alpha_i = 1 - exp(-sigma_i * delta)`,
//! transmittance `T_i = prod_{j<i} (1 - alpha_j)`, weight `w_i = T_i * alpha_i`.

use rand::Rng;

use crate::camera::Ray;
use crate::coords::V3;

/// Marching stops once the transmittance drops below this: the remaining weight along the ray is
/// at most this much, and skipping it makes opaque rays cheap.
pub const TRANSMITTANCE_CUTOFF: f32 = 1e-4;

/// Nodes per side of an empty-space-skipping block.
const BLOCK: usize = 8;

/// Node-sampled volume density. Invariant: `dims[k] >= 2`, `data.len() == dims[0]*dims[1]*dims[2]`
/// in C order (`x` slowest), values finite and `>= 0`, `min < max` componentwise.
#[derive(Clone, Debug)]
pub struct DensityGrid {
    dims: [usize; 3],
    data: Vec<f32>,
    min: V3,
    max: V3,
    /// Node spacing per axis.
    cell: V3,
    /// Blocks of `BLOCK^3` cells, per axis.
    blocks: [usize; 3],
    /// `occupied[b]`: some node touching block `b` (its `(BLOCK+1)^3` corner nodes) has density > 0.
    /// Marching jumps over unoccupied blocks, where the interpolated density is exactly zero.
    occupied: Vec<bool>,
}

impl DensityGrid {
    /// Wraps `data` (C order) sampled at the nodes of the box `[min, max]`. The caller guarantees the
    /// invariants (the density source validates them with file context).
    pub fn new(dims: [usize; 3], data: Vec<f32>, min: V3, max: V3) -> DensityGrid {
        let cell = std::array::from_fn(|k| (max[k] - min[k]) / (dims[k] - 1) as f32);
        let blocks: [usize; 3] = std::array::from_fn(|k| (dims[k] - 1).div_ceil(BLOCK));
        let mut occupied = vec![false; blocks[0] * blocks[1] * blocks[2]];
        for i in 0..dims[0] {
            for j in 0..dims[1] {
                for k in 0..dims[2] {
                    if data[(i * dims[1] + j) * dims[2] + k] > 0.0 {
                        // A node touches the blocks on both sides when it lies on a block boundary.
                        for bi in block_range(i, blocks[0]) {
                            for bj in block_range(j, blocks[1]) {
                                for bk in block_range(k, blocks[2]) {
                                    occupied[(bi * blocks[1] + bj) * blocks[2] + bk] = true;
                                }
                            }
                        }
                    }
                }
            }
        }
        DensityGrid { dims, data, min, max, cell, blocks, occupied }
    }

    /// The block holding `p` and the parameter where `ray` leaves it, when that block is empty.
    fn empty_block_exit(&self, p: V3, ray: &Ray) -> Option<f32> {
        let mut b = [0usize; 3];
        for k in 0..3 {
            let g = (p[k] - self.min[k]) / (self.cell[k] * BLOCK as f32);
            if g.is_nan() || g < 0.0 {
                return None;
            }
            b[k] = (g as usize).min(self.blocks[k] - 1);
        }
        if self.occupied[(b[0] * self.blocks[1] + b[1]) * self.blocks[2] + b[2]] {
            return None;
        }
        let mut exit = f32::INFINITY;
        for (k, &bk) in b.iter().enumerate() {
            let lo = self.min[k] + (bk * BLOCK) as f32 * self.cell[k];
            let hi = lo + BLOCK as f32 * self.cell[k];
            let plane = if ray.dir[k] > 0.0 { hi } else { lo };
            let t = (plane - ray.origin[k]) / ray.dir[k];
            if t.is_finite() {
                exit = exit.min(t);
            }
        }
        Some(exit)
    }

    /// The grid's box.
    pub fn bounds(&self) -> (V3, V3) {
        (self.min, self.max)
    }

    /// The smallest node spacing.
    pub fn voxel_size(&self) -> f32 {
        self.cell.iter().copied().fold(f32::INFINITY, f32::min)
    }

    fn at(&self, i: usize, j: usize, k: usize) -> f32 {
        self.data[(i * self.dims[1] + j) * self.dims[2] + k]
    }

    /// Trilinearly interpolated density at `p`; zero outside the grid.
    pub fn density(&self, p: V3) -> f32 {
        let mut idx = [0usize; 3];
        let mut frac = [0.0f32; 3];
        for k in 0..3 {
            let g = (p[k] - self.min[k]) / self.cell[k];
            if !(g >= 0.0 && g <= (self.dims[k] - 1) as f32) {
                return 0.0;
            }
            let i = (g as usize).min(self.dims[k] - 2);
            idx[k] = i;
            frac[k] = g - i as f32;
        }
        let [i, j, k] = idx;
        let [fx, fy, fz] = frac;
        let lerp = |a: f32, b: f32, t: f32| a + (b - a) * t;
        let c00 = lerp(self.at(i, j, k), self.at(i + 1, j, k), fx);
        let c10 = lerp(self.at(i, j + 1, k), self.at(i + 1, j + 1, k), fx);
        let c01 = lerp(self.at(i, j, k + 1), self.at(i + 1, j, k + 1), fx);
        let c11 = lerp(self.at(i, j + 1, k + 1), self.at(i + 1, j + 1, k + 1), fx);
        lerp(lerp(c00, c10, fy), lerp(c01, c11, fy), fz)
    }

    /// The density gradient at `p` by central differences of the interpolated field, one node
    /// spacing either side (smoother than the piecewise-constant derivative of the trilinear cell).
    pub fn gradient(&self, p: V3) -> V3 {
        std::array::from_fn(|k| {
            let h = self.cell[k];
            let mut a = p;
            let mut b = p;
            a[k] += h;
            b[k] -= h;
            (self.density(a) - self.density(b)) / (2.0 * h)
        })
    }

    /// The parameter interval where `ray` is inside the grid box (from `t >= 0`), if any.
    pub fn clip(&self, ray: &Ray) -> Option<(f32, f32)> {
        let mut lo = 0.0f32;
        let mut hi = f32::INFINITY;
        for k in 0..3 {
            let inv = 1.0 / ray.dir[k];
            let t1 = (self.min[k] - ray.origin[k]) * inv;
            let t2 = (self.max[k] - ray.origin[k]) * inv;
            lo = lo.max(t1.min(t2));
            hi = hi.min(t1.max(t2));
        }
        (lo < hi && hi.is_finite()).then_some((lo, hi))
    }

    /// Volume-renders `ray` with steps of about `step`, calling `visit(t, weight)` for every sample
    /// with positive weight in order, until the transmittance falls below [`TRANSMITTANCE_CUTOFF`].
    /// The stratification jitter comes from `rng`, so marching twice with equal generators visits
    /// exactly the same samples. Returns the total weight (the ray's opacity).
    pub fn march(&self, ray: &Ray, step: f32, rng: &mut impl Rng, mut visit: impl FnMut(f32, f32)) -> f32 {
        let Some((t0, t1)) = self.clip(ray) else { return 0.0 };
        let steps = ((t1 - t0) / step).ceil().max(1.0) as usize;
        let delta = (t1 - t0) / steps as f32;
        let mut transmittance = 1.0f32;
        let mut i = 0;
        while i < steps {
            let start = t0 + i as f32 * delta;
            if let Some(exit) = self.empty_block_exit(ray.at(start), ray) {
                // Jump to the step whose interval holds the exit point; skipped samples had density 0.
                i = (((exit - t0) / delta) as usize).max(i + 1);
                continue;
            }
            let t = start + rng.random::<f32>() * delta;
            i += 1;
            let sigma = self.density(ray.at(t));
            if sigma > 0.0 {
                let alpha = 1.0 - (-sigma * delta).exp();
                let w = transmittance * alpha;
                if w > 0.0 {
                    visit(t, w);
                }
                transmittance *= 1.0 - alpha;
                if transmittance < TRANSMITTANCE_CUTOFF {
                    break;
                }
            }
        }
        1.0 - transmittance
    }
}

/// The blocks that node index `i` belongs to (two when it lies on a boundary between blocks).
fn block_range(i: usize, blocks: usize) -> std::ops::RangeInclusive<usize> {
    let hi = (i / BLOCK).min(blocks - 1);
    let lo = if i.is_multiple_of(BLOCK) && i > 0 { i / BLOCK - 1 } else { hi };
    lo..=hi
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    /// A 3×3×3 grid with density 8 x + 4 y + 2 z + 1 (trilinear reproduces it exactly).
    fn linear_grid() -> DensityGrid {
        let mut data = Vec::new();
        for i in 0..3 {
            for j in 0..3 {
                for k in 0..3 {
                    let (x, y, z) = (i as f32 - 1.0, j as f32 - 1.0, k as f32 - 1.0);
                    data.push(8.0 * x + 4.0 * y + 2.0 * z + 10.0);
                }
            }
        }
        DensityGrid::new([3, 3, 3], data, [-1.0; 3], [1.0; 3])
    }

    #[test]
    fn trilinear_interpolation_and_gradient_of_a_linear_field() {
        let g = linear_grid();
        let p = [0.3, -0.2, 0.55];
        assert!((g.density(p) - (8.0 * 0.3 - 4.0 * 0.2 + 2.0 * 0.55 + 10.0)).abs() < 1e-5);
        // Central differences one cell (= 1 here) either side stay inside the grid only at the centre.
        let grad = g.gradient([0.0, 0.0, 0.0]);
        assert!((grad[0] - 8.0).abs() < 1e-4 && (grad[1] - 4.0).abs() < 1e-4 && (grad[2] - 2.0).abs() < 1e-4);
        assert_eq!(g.density([1.5, 0.0, 0.0]), 0.0);
        assert!((g.density([1.0, 1.0, 1.0]) - 24.0).abs() < 1e-5);
    }

    #[test]
    fn empty_space_skipping_is_conservative() {
        // A 40^3 grid, empty except for a small blob: wherever the density is positive the block must
        // count as occupied, and rays through the blob see the same opacity as without skipping.
        let n = 40;
        let mut data = vec![0.0; n * n * n];
        data[(17 * n + 23) * n + 8] = 50.0;
        let g = DensityGrid::new([n, n, n], data, [-1.0; 3], [1.0; 3]);
        assert!(g.occupied.iter().filter(|&&o| o).count() <= 8);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(4);
        let ray = Ray { origin: [0.0; 3], dir: [1.0, 0.0, 0.0] };
        for _ in 0..20000 {
            let p: V3 = std::array::from_fn(|_| rng.random_range(-1.0..1.0));
            if g.density(p) > 0.0 {
                assert!(g.empty_block_exit(p, &ray).is_none(), "{p:?} has density but its block is empty");
            }
        }
        let blob = [-1.0 + 2.0 * 17.0 / 39.0, -1.0 + 2.0 * 23.0 / 39.0, -1.0 + 2.0 * 8.0 / 39.0];
        let ray = Ray { origin: [blob[0], blob[1], -3.0], dir: [0.0, 0.0, 1.0] };
        let fine = g.march(&ray, 0.001, &mut rng, |_, _| {});
        let expected = 1.0 - (-50.0f32 * 2.0 / 39.0 / 2.0 * 2.0 / 2.0).exp();
        assert!(fine > 0.5 * expected, "opacity {fine} through the blob, expected about {expected}");
    }

    #[test]
    fn weights_of_a_homogeneous_slab_follow_beer_lambert() {
        // Constant density 2 over the box [-1, 1]^3: opacity along x is 1 - exp(-2 * 2).
        let g = DensityGrid::new([2, 2, 2], vec![2.0; 8], [-1.0; 3], [1.0; 3]);
        let ray = Ray { origin: [-5.0, 0.1, 0.2], dir: [1.0, 0.0, 0.0] };
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
        let mut sum = 0.0;
        let total = g.march(&ray, 0.01, &mut rng, |t, w| {
            assert!((4.0..=6.0).contains(&t));
            sum += w;
        });
        assert!((total - (1.0 - (-4.0f32).exp())).abs() < 1e-4, "{total}");
        assert!((sum - total).abs() < 1e-4);
        let miss = Ray { origin: [-5.0, 3.0, 0.0], dir: [1.0, 0.0, 0.0] };
        assert_eq!(g.march(&miss, 0.01, &mut rng, |_, _| panic!("no samples on a miss")), 0.0);
    }
}

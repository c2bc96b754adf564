//! The surface-coordinate loss: a symmetric Chamfer distance with kd-tree nearest neighbours.

use kiddo::{ImmutableKdTree, SquaredEuclidean};
use nuvo_autodiff::Var;
use rayon::prelude::*;

use crate::context::{Reads, StepContext};
use crate::loss::{Loss, LossError, squared_distance};
use crate::registry::{LossInfo, RegisteredLoss, no_options};

/// `L_surface = (1/|G|) Σ_x min_{x'∈S} ‖x' − x‖² + (1/|S|) Σ_{x'∈S} min_x ‖x' − x‖²` with
/// `S = ⋃_i s_i(T)`. Nearest neighbours are found in kd-trees (kiddo) built from this step's values;
/// the gradient flows through the chosen pairs (the argmin itself is piecewise constant).
pub struct Surface;

/// For every query point, the index of its nearest neighbour among `points`.
fn nearest_indices(points: &[[f32; 3]], queries: &[[f32; 3]]) -> Vec<u32> {
    let tree: ImmutableKdTree<f32, 3> = ImmutableKdTree::new_from_slice(points);
    queries.par_iter().map(|q| tree.nearest_one::<SquaredEuclidean>(q).item as u32).collect()
}

fn as_points(values: &[f32]) -> Vec<[f32; 3]> {
    values.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect()
}

impl RegisteredLoss for Surface {
    const INFO: LossInfo = LossInfo {
        name: "surface",
        summary: "symmetric Chamfer distance between ⋃_i s_i(T) and the surface samples (kd-tree nearest neighbours)",
        default_weight: 10.0,
        options: &[],
    };

    fn from_options(options: &toml::Table) -> Result<Self, LossError> {
        no_options(Self::INFO.name, options)?;
        Ok(Surface)
    }
}

impl Loss for Surface {
    fn evaluate(&self, ctx: &mut StepContext<'_>) -> Result<Var, LossError> {
        let s = ctx.all_surface_points();
        let x = ctx.x();
        let s_points = as_points(ctx.tape.value(s));
        let x_points = ctx.data().points;
        if s_points.is_empty() || x_points.is_empty() {
            return Err(LossError::Evaluation {
                loss: Surface::INFO.name.into(),
                message: "empty batch".into(),
            });
        }
        let nearest_s = nearest_indices(&s_points, x_points);
        let nearest_x = nearest_indices(x_points, &s_points);
        let s_near_x = ctx.tape.gather_rows(s, &nearest_s);
        let x_near_s = ctx.tape.gather_rows(x, &nearest_x);
        let d_x = squared_distance(ctx, s_near_x, x);
        let d_s = squared_distance(ctx, s, x_near_s);
        let t = &mut *ctx.tape;
        let m_x = t.mean_all(d_x);
        let m_s = t.mean_all(d_s);
        Ok(t.add(m_x, m_s))
    }

    fn reads(&self) -> Reads {
        Reads { surface_points: true, ..Reads::NOTHING }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::{Scene, check_loss_gradient};

    #[test]
    fn chamfer_of_known_point_sets() {
        // s(u) = (u, v, 0). UV points (0,0) and (1,0) → surface points (0,0,0), (1,0,0).
        // Samples (0,0,0.5) and (0.9,0,0): x→S: 0.25 and 0.01, mean 0.13; S→x: 0.25 and 0.01, mean 0.13.
        let scene =
            Scene::plane_points(&[[0.0, 0.0, 0.5], [0.9, 0.0, 0.0]]).with_uv(&[[0.0, 0.0], [1.0, 0.0]]);
        assert!((scene.evaluate(&Surface) - 0.26).abs() < 1e-6, "{}", scene.evaluate(&Surface));
    }

    #[test]
    fn chamfer_is_asymmetric_in_counts_but_symmetric_in_definition() {
        // One sample at the origin, three surface points at distance² 0, 1, 4 along x:
        // x→S = 0; S→x = (0 + 1 + 4)/3.
        let scene = Scene::plane_points(&[[0.0, 0.0, 0.0]]).with_uv(&[[0.0, 0.0], [1.0, 0.0], [2.0, 0.0]]);
        assert!((scene.evaluate(&Surface) - 5.0 / 3.0).abs() < 1e-5);
    }

    #[test]
    fn nearest_indices_agree_with_brute_force() {
        let pts: Vec<[f32; 3]> = (0..500)
            .map(|i| {
                let f = i as f32;
                [(f * 0.37).sin(), (f * 0.71).cos(), (f * 0.13).sin() * (f * 0.05).cos()]
            })
            .collect();
        let queries: Vec<[f32; 3]> =
            (0..200).map(|i| [(i as f32 * 0.3).cos(), (i as f32 * 0.2).sin(), 0.1]).collect();
        let d2 = |a: &[f32; 3], b: &[f32; 3]| (0..3).map(|k| (a[k] - b[k]).powi(2)).sum::<f32>();
        for (q, &i) in queries.iter().zip(&nearest_indices(&pts, &queries)) {
            let best = pts.iter().map(|p| d2(p, q)).fold(f32::INFINITY, f32::min);
            assert!((d2(&pts[i as usize], q) - best).abs() < 1e-6);
        }
    }

    #[test]
    fn gradient_matches_finite_differences() {
        check_loss_gradient(&Surface);
    }
}

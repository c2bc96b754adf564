//! Drawing one step's data: surface samples, UV samples and random tangent frames.

use nuvo_geometry::GeometrySource;
use nuvo_losses::StepData;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::model::MODEL_FRAME_SCALE;
use crate::seeds::{Stream, derive};

/// The data of one step, in the model frame. Invariant: `points` and `normals` have equal lengths;
/// the tangents, equal to each other, cover the first of them (see [`StepData`]).
#[derive(Clone, Debug, Default)]
pub struct StepBatch {
    pub points: Vec<[f32; 3]>,
    pub normals: Vec<[f32; 3]>,
    pub uv: Vec<[f32; 2]>,
    pub tangents_p: Vec<[f32; 3]>,
    pub tangents_q: Vec<[f32; 3]>,
}

/// Why a batch could not be drawn.
#[derive(Debug, thiserror::Error)]
#[error("geometry source `{source_kind}` returned {got} samples for a request of {wanted}")]
pub struct ShortBatch {
    pub source_kind: String,
    pub got: usize,
    pub wanted: usize,
}

impl StepBatch {
    /// Draws the batch of `step` for a run seeded with `seed`: a pure function of its arguments.
    /// Tangent frames are drawn for the first `batch_distortion` samples only (the ones the
    /// distortion losses read), from the same stream, so they do not depend on that count.
    pub fn draw(
        source: &dyn GeometrySource,
        (batch_3d, batch_uv, batch_distortion): (usize, usize, usize),
        seed: u64,
        step: u64,
    ) -> Result<Self, ShortBatch> {
        let SurfaceSamples { points, normals } =
            surface_samples(source, batch_3d, derive(seed, step, Stream::Surface))?;
        let mut rng = ChaCha8Rng::seed_from_u64(derive(seed, step, Stream::Uv));
        let uv = (0..batch_uv).map(|_| [rng.random::<f32>(), rng.random::<f32>()]).collect();
        let mut rng = ChaCha8Rng::seed_from_u64(derive(seed, step, Stream::Tangents));
        let (tangents_p, tangents_q) =
            normals.iter().take(batch_distortion).map(|n| random_tangent_frame(n, &mut rng)).unzip();
        Ok(StepBatch { points, normals, uv, tangents_p, tangents_q })
    }

    /// The loss context's view of this batch, with the distortion step `ε` and the chart-support
    /// threshold (see [`StepData`]).
    pub fn data(&self, epsilon: f32, chart_support: f32) -> StepData<'_> {
        StepData {
            points: &self.points,
            normals: &self.normals,
            uv: &self.uv,
            tangents_p: &self.tangents_p,
            tangents_q: &self.tangents_q,
            epsilon,
            chart_support,
        }
    }
}

/// Surface samples in the model frame. Invariant: `points` and `normals` have equal lengths.
#[derive(Clone, Debug, Default)]
pub struct SurfaceSamples {
    pub points: Vec<[f32; 3]>,
    /// Unit normals.
    pub normals: Vec<[f32; 3]>,
}

/// Exactly `count` surface samples drawn with `seed`. A source that returns fewer (or mismatched
/// normals) is a [`ShortBatch`].
pub fn surface_samples(
    source: &dyn GeometrySource,
    count: usize,
    seed: u64,
) -> Result<SurfaceSamples, ShortBatch> {
    let samples = source.sample(count, seed);
    if samples.len() != count || samples.normals.len() != count {
        return Err(ShortBatch { source_kind: source.kind().to_owned(), got: samples.len(), wanted: count });
    }
    let points = samples.positions.iter().map(|p| p.map(|c| c * MODEL_FRAME_SCALE)).collect();
    Ok(SurfaceSamples { points, normals: samples.normals })
}

fn dot(a: [f32; 3], b: [f32; 3]) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn cross(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}

/// A uniformly random orthonormal pair `(p, q = n × p)` in the tangent plane of the unit normal `n`.
pub fn random_tangent_frame(n: &[f32; 3], rng: &mut impl Rng) -> ([f32; 3], [f32; 3]) {
    // Any vector not parallel to n, projected and normalised, then rotated by a random angle.
    let helper = if n[0].abs() < 0.9 { [1.0, 0.0, 0.0] } else { [0.0, 1.0, 0.0] };
    let d = dot(helper, *n);
    let a: [f32; 3] = std::array::from_fn(|k| helper[k] - d * n[k]);
    let la = dot(a, a).sqrt();
    let a = a.map(|v| v / la);
    let b = cross(*n, a);
    let angle: f32 = rng.random_range(0.0..std::f32::consts::TAU);
    let (s, c) = angle.sin_cos();
    let p: [f32; 3] = std::array::from_fn(|k| c * a[k] + s * b[k]);
    (p, cross(*n, p))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tangent_frames_are_orthonormal_and_tangent() {
        let mut rng = ChaCha8Rng::seed_from_u64(0);
        for n in [[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.6, 0.0, 0.8], [-0.48, 0.6, 0.64]] {
            let (p, q) = random_tangent_frame(&n, &mut rng);
            assert!(dot(p, n).abs() < 1e-6 && dot(q, n).abs() < 1e-6 && dot(p, q).abs() < 1e-6);
            assert!((dot(p, p) - 1.0).abs() < 1e-5 && (dot(q, q) - 1.0).abs() < 1e-5);
        }
    }
}

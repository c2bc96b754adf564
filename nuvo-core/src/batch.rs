//! Drawing one step's data: surface samples, UV samples and random tangent frames.

use glam::Vec3;
use nuvo_geometry::GeometrySource;
use nuvo_losses::StepData;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::config::TrainingConfig;
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

/// How many samples of each kind a step draws.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BatchSizes {
    /// Surface samples `x` (`training.batch_3d`).
    pub points: usize,
    /// UV samples `u` (`training.batch_uv`).
    pub uv: usize,
    /// Of the surface samples, how many (the first) carry a tangent frame for the distortion
    /// losses (`training.batch_distortion`, all of them by default).
    pub distortion: usize,
}

impl BatchSizes {
    /// The sizes `[training]` asks for.
    pub fn of(t: &TrainingConfig) -> Self {
        BatchSizes {
            points: t.batch_3d,
            uv: t.batch_uv,
            distortion: t.batch_distortion.unwrap_or(t.batch_3d),
        }
    }

    /// These sizes times `share` (in `(0, 1]`), rounded to the nearest (not up: `0.3_f32` is a
    /// little above 0.3), and at least one sample of each kind that had one.
    pub fn share(self, share: f32) -> Self {
        let scaled = |n: usize| ((n as f64 * f64::from(share)).round() as usize).clamp(n.min(1), n);
        BatchSizes { points: scaled(self.points), uv: scaled(self.uv), distortion: scaled(self.distortion) }
    }
}

impl StepBatch {
    /// Draws the batch of `step` for a run seeded with `seed`: a pure function of its arguments.
    /// Tangent frames are drawn for the first `sizes.distortion` samples only (the ones the
    /// distortion losses read), from the same stream, so they do not depend on that count.
    pub fn draw(
        source: &dyn GeometrySource,
        sizes: BatchSizes,
        seed: u64,
        step: u64,
    ) -> Result<Self, ShortBatch> {
        let SurfaceSamples { points, normals } =
            surface_samples(source, sizes.points, derive(seed, step, Stream::Surface))?;
        let mut rng = ChaCha8Rng::seed_from_u64(derive(seed, step, Stream::Uv));
        let uv = (0..sizes.uv).map(|_| [rng.random::<f32>(), rng.random::<f32>()]).collect();
        let mut rng = ChaCha8Rng::seed_from_u64(derive(seed, step, Stream::Tangents));
        let (tangents_p, tangents_q) =
            normals.iter().take(sizes.distortion).map(|n| random_tangent_frame(n, &mut rng)).unzip();
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

/// A uniformly random orthonormal pair `(p, q = n × p)` in the tangent plane of the unit normal `n`.
pub fn random_tangent_frame(n: &[f32; 3], rng: &mut impl Rng) -> ([f32; 3], [f32; 3]) {
    let n = Vec3::from(*n);
    // Any vector not parallel to n, projected and normalised, then rotated by a random angle.
    let helper = if n.x.abs() < 0.9 { Vec3::X } else { Vec3::Y };
    let a = helper - helper.dot(n) * n;
    // Divided by the length (not multiplied by its reciprocal, as `normalize` does): the frames,
    // and so every run's bytes, stay what they were.
    let a = a / a.length();
    let b = n.cross(a);
    let angle: f32 = rng.random_range(0.0..std::f32::consts::TAU);
    let (s, c) = angle.sin_cos();
    let p = c * a + s * b;
    (p.into(), n.cross(p).into())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_share_of_the_batch_rounds_to_the_nearest_and_keeps_one_of_each_kind_it_had() {
        let sizes = BatchSizes { points: 7, uv: 1, distortion: 0 };
        assert_eq!(sizes.share(0.5), BatchSizes { points: 4, uv: 1, distortion: 0 });
        assert_eq!(sizes.share(0.01), BatchSizes { points: 1, uv: 1, distortion: 0 });
        assert_eq!(sizes.share(1.0), sizes);
    }

    #[test]
    fn tangent_frames_are_orthonormal_and_tangent() {
        let mut rng = ChaCha8Rng::seed_from_u64(0);
        for n in [[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.6, 0.0, 0.8], [-0.48, 0.6, 0.64]] {
            let (p, q) = random_tangent_frame(&n, &mut rng);
            let (p, q, n) = (Vec3::from(p), Vec3::from(q), Vec3::from(n));
            assert!(p.dot(n).abs() < 1e-6 && q.dot(n).abs() < 1e-6 && p.dot(q).abs() < 1e-6);
            assert!((p.length() - 1.0).abs() < 1e-5 && (q.length() - 1.0).abs() < 1e-5);
        }
    }
}

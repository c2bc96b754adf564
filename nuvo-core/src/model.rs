//! The Nuvo model: a chart-assignment MLP, `n` texture-coordinate MLPs, `n` surface-coordinate MLPs,
//! the learned average stretch `σ`, and `n` normal grids.
//!
//! **Model frame.** The networks and the losses work in a frame where the object's longest side has
//! length 1 (`model = MODEL_FRAME_SCALE · canonical`, i.e. inside `[-0.5, 0.5]³`): the paper's loss
//! weights balance squared 3-D distances against squared UV distances, and UV charts have side 1.
//!
//! **Encodings.** Each network sees `γ_L(ω·z)` ([`nuvo_autodiff::Tape::posenc`]) of its input `z`
//! centred in a unit-extent box: 3-D points as they are in the model frame, UVs as `u − ½`; `ω` is
//! `model.encoding_scale`, so the frequencies are `2^k·ω` for `k < L` per unit of the object's extent.

use nuvo_autodiff::nn::{Mlp, MlpConfig};
use nuvo_autodiff::{Activation, ParamId, ParamStore, Tape, Tensor, Var, posenc_width};
use nuvo_losses::Networks;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use crate::config::ModelConfig;

/// Canonical frame (`[-1, 1]³`) → model frame (`[-0.5, 0.5]³`).
pub const MODEL_FRAME_SCALE: f32 = 0.5;

/// Parameter groups, which get separate learning rates.
pub mod groups {
    /// Every MLP weight and bias.
    pub const MLP: &str = "mlp";
    /// The scalar `σ`.
    pub const SIGMA: &str = "sigma";
    /// The normal grids.
    pub const GRID: &str = "grid";
}

/// One network with its input encoding.
#[derive(Clone, Debug)]
struct EncodedMlp {
    mlp: Mlp,
    degree: usize,
    /// Subtracted from the input before encoding (centres UVs).
    center: f32,
    /// Multiplies the centred input before encoding.
    scale: f32,
}

impl EncodedMlp {
    fn forward(&self, tape: &mut Tape, z: Var) -> Var {
        let centred = if self.center != 0.0 { tape.add_scalar(z, -self.center) } else { z };
        let scaled = tape.scale(centred, self.scale);
        let e = tape.posenc(scaled, self.degree);
        self.mlp.forward(tape, e)
    }
}

/// The networks and auxiliary parameters of one atlas. The values live in a [`ParamStore`] (owned by
/// the trainer's tape); this struct holds the handles.
#[derive(Clone, Debug)]
pub struct NuvoModel {
    chart: EncodedMlp,
    texture: Vec<EncodedMlp>,
    surface: Vec<EncodedMlp>,
    sigma: ParamId,
    grids: Vec<ParamId>,
    grid_res: usize,
}

impl NuvoModel {
    /// Registers every parameter in `params`, initialised from `seed` (same seed, same weights).
    /// Names: `chart.l{k}.{w,b}`, `texture.{i}.l{k}.{w,b}`, `surface.{i}.l{k}.{w,b}`, `sigma`,
    /// `normal_grid.{i}`.
    pub fn new(cfg: &ModelConfig, params: &mut ParamStore, seed: u64) -> Self {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let n = cfg.charts;
        let net = |params: &mut ParamStore,
                   rng: &mut ChaCha8Rng,
                   name: &str,
                   shape: (usize, usize, usize),
                   io: (usize, usize, Activation),
                   center: f32| {
            let (depth, width, degree) = shape;
            let mlp_cfg = MlpConfig { depth, width, activation: cfg.activation, init: cfg.init };
            let (inputs, outputs, act) = io;
            let mlp = Mlp::new(
                params,
                name,
                groups::MLP,
                &mlp_cfg,
                (posenc_width(inputs, degree), outputs, act),
                rng,
            );
            EncodedMlp { mlp, degree, center, scale: cfg.encoding_scale }
        };
        let chart = net(params, &mut rng, "chart", cfg.chart_shape(), (3, n, Activation::Identity), 0.0);
        let texture = (0..n)
            .map(|i| {
                net(
                    params,
                    &mut rng,
                    &format!("texture.{i}"),
                    cfg.texture_shape(),
                    (3, 2, Activation::Sigmoid),
                    0.0,
                )
            })
            .collect();
        let surface = (0..n)
            .map(|i| {
                net(
                    params,
                    &mut rng,
                    &format!("surface.{i}"),
                    cfg.surface_shape(),
                    (2, 3, Activation::Identity),
                    0.5,
                )
            })
            .collect();
        let sigma = params.add("sigma", groups::SIGMA, Tensor::scalar(cfg.sigma_init));
        let grid_res = cfg.grid_resolution();
        let grids = (0..n)
            .map(|i| {
                params.add(format!("normal_grid.{i}"), groups::GRID, Tensor::zeros(grid_res * grid_res, 3))
            })
            .collect();
        NuvoModel { chart, texture, surface, sigma, grids, grid_res }
    }

    /// Texels per side of each normal grid.
    pub fn grid_resolution(&self) -> usize {
        self.grid_res
    }

    /// Handle of normal grid `i`.
    pub fn grid_param(&self, i: usize) -> ParamId {
        self.grids[i]
    }

    /// Handle of `σ`.
    pub fn sigma_param(&self) -> ParamId {
        self.sigma
    }

    /// Multiply-adds per point of one forward pass of each kind of network: (chart, texture, surface).
    pub fn macs_per_point(&self) -> (usize, usize, usize) {
        (
            self.chart.mlp.macs_per_row(),
            self.texture[0].mlp.macs_per_row(),
            self.surface[0].mlp.macs_per_row(),
        )
    }
}

impl Networks for NuvoModel {
    fn charts(&self) -> usize {
        self.texture.len()
    }

    fn chart_logits(&self, tape: &mut Tape, x: Var) -> Var {
        self.chart.forward(tape, x)
    }

    fn texture(&self, tape: &mut Tape, chart: usize, x: Var) -> Var {
        self.texture[chart].forward(tape, x)
    }

    fn surface(&self, tape: &mut Tape, chart: usize, uv: Var) -> Var {
        self.surface[chart].forward(tape, uv)
    }

    fn sigma(&self, tape: &mut Tape) -> Var {
        tape.param(self.sigma)
    }

    fn normal_grid(&self, tape: &mut Tape, chart: usize) -> (Var, usize) {
        (tape.param(self.grids[chart]), self.grid_res)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nuvo_autodiff::Shape;

    fn small(charts: usize) -> ModelConfig {
        ModelConfig { charts, depth: 3, width: 16, grid_resolution: Some(8), ..ModelConfig::default() }
    }

    #[test]
    fn shapes_ranges_and_parameter_names() {
        let mut params = ParamStore::new();
        let model = NuvoModel::new(&small(3), &mut params, 0);
        assert_eq!(model.charts(), 3);
        for name in ["chart.l0.w", "texture.2.l2.b", "surface.0.l1.w", "sigma", "normal_grid.2"] {
            assert!(params.find(name).is_some(), "{name} missing");
        }
        assert_eq!(params.value(params.find("normal_grid.1").unwrap()).shape(), Shape::new(64, 3));
        let mut tape = Tape::new(params);
        let x = tape.input(&Tensor::from_rows(&[[0.1, -0.2, 0.3], [0.4, 0.0, -0.5]]));
        let logits = model.chart_logits(&mut tape, x);
        assert_eq!(tape.shape(logits), Shape::new(2, 3));
        let uv = model.texture(&mut tape, 1, x);
        assert!(tape.value(uv).iter().all(|&u| (0.0..=1.0).contains(&u)));
        let s = model.surface(&mut tape, 2, uv);
        assert_eq!(tape.shape(s), Shape::new(2, 3));
    }

    #[test]
    fn initialisation_is_seeded() {
        let weights = |seed| {
            let mut p = ParamStore::new();
            NuvoModel::new(&small(2), &mut p, seed);
            p.value(p.find("texture.1.l0.w").unwrap()).clone()
        };
        assert_eq!(weights(5), weights(5));
        assert_ne!(weights(5), weights(6));
    }
}

//! Layers built on the tape: [`Linear`] and [`Mlp`], with seeded initialisation.

use rand::Rng;
use serde::{Deserialize, Serialize};

use crate::ops::Activation;
use crate::params::{ParamId, ParamStore};
use crate::tape::{Tape, Var};
use crate::tensor::Tensor;

/// An affine layer `act(x·W + b)` with `W: in×out` and `b: 1×out` stored as parameters.
#[derive(Clone, Copy, Debug, Serialize, Deserialize)]
pub struct Linear {
    pub weight: ParamId,
    pub bias: ParamId,
    pub in_dim: usize,
    pub out_dim: usize,
}

/// How [`Linear`] layers draw their initial weights and biases (uniform distributions).
///
/// `Torch` is PyTorch's `nn.Linear` default, `U(±1/√in)` for weights and biases: the scale the
/// published Nuvo implementations start from, and the one under which the bijectivity losses learn
/// even a flat square cleanly (BENCHMARKS.md, "Initialisation"). `He` is `U(±√(6/in))` for hidden
/// ReLU layers and Glorot `U(±√(6/(in+out)))` for the output layer, zero biases: larger initial
/// maps, which fold the easy cases but measured better on the full bunny objective at a five-minute
/// budget.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Init {
    /// PyTorch's `nn.Linear` default: weights and biases `U(±1/√in)`.
    #[default]
    Torch,
    /// He-uniform hidden layers, Glorot-uniform output layer, zero biases.
    He,
}

impl Init {
    /// `(weight bound, bias bound)` for a layer of `in_dim → out_dim`; `output_layer` selects
    /// Glorot over He for the last layer of an MLP.
    pub fn bounds(self, in_dim: usize, out_dim: usize, output_layer: bool) -> (f32, f32) {
        let fan_in = in_dim.max(1) as f32;
        match self {
            Init::Torch => (1.0 / fan_in.sqrt(), 1.0 / fan_in.sqrt()),
            Init::He if output_layer => ((6.0 / (fan_in + out_dim as f32)).sqrt(), 0.0),
            Init::He => ((6.0 / fan_in).sqrt(), 0.0),
        }
    }
}

impl Linear {
    /// Registers `{name}.w` and `{name}.b` in `params` (group `group`), drawn uniformly within
    /// `(weight bound, bias bound)` (see [`Init::bounds`]; a bound of 0 gives zeros).
    pub fn new(
        params: &mut ParamStore,
        name: &str,
        group: &str,
        (in_dim, out_dim): (usize, usize),
        (w_bound, b_bound): (f32, f32),
        rng: &mut impl Rng,
    ) -> Self {
        let mut uniform = |n: usize, bound: f32| -> Vec<f32> {
            (0..n).map(|_| if bound > 0.0 { rng.random_range(-bound..=bound) } else { 0.0 }).collect()
        };
        let w = uniform(in_dim * out_dim, w_bound);
        let b = uniform(out_dim, b_bound);
        let weight = params.add(format!("{name}.w"), group, Tensor::from_vec(in_dim, out_dim, w));
        let bias = params.add(format!("{name}.b"), group, Tensor::from_vec(1, out_dim, b));
        Linear { weight, bias, in_dim, out_dim }
    }

    /// `act(x·W + b)` as one fused op.
    pub fn forward(&self, tape: &mut Tape, x: Var, act: Activation) -> Var {
        let w = tape.param(self.weight);
        let b = tape.param(self.bias);
        tape.linear(x, w, Some(b), act)
    }

    /// Multiply-adds per input row.
    pub fn macs_per_row(&self) -> usize {
        self.in_dim * self.out_dim
    }
}

/// Shape of an [`Mlp`]: `depth` fully-connected layers in all, the first `depth − 1` of them `width`
/// units wide with `activation`, the last mapping to the output with the output activation. This is
/// how the paper counts: its "8 fully-connected layers, each with 256 channels" is depth 8, width 256
/// (seven hidden ReLU layers and the output layer).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MlpConfig {
    /// Number of fully-connected layers, at least 1 (1 is a single affine map).
    pub depth: usize,
    /// Units per hidden layer.
    pub width: usize,
    /// Hidden activation.
    #[serde(default = "default_activation")]
    pub activation: Activation,
    /// Initialisation scheme.
    #[serde(default)]
    pub init: Init,
}

fn default_activation() -> Activation {
    Activation::Relu
}

/// A multilayer perceptron of fused [`Linear`] layers.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Mlp {
    layers: Vec<Linear>,
    hidden: Activation,
    output: Activation,
}

impl Mlp {
    /// Registers the layers as `{name}.l0`, `{name}.l1`, … in `params` (group `group`). `io` is
    /// `(input width, output width, output activation)`.
    ///
    /// # Panics
    /// If `cfg.depth` is 0 (configs are validated before models are built).
    pub fn new(
        params: &mut ParamStore,
        name: &str,
        group: &str,
        cfg: &MlpConfig,
        io: (usize, usize, Activation),
        rng: &mut impl Rng,
    ) -> Self {
        let (in_dim, out_dim, output) = io;
        assert!(cfg.depth >= 1, "an MLP needs at least one layer");
        let mut layers = Vec::with_capacity(cfg.depth);
        let mut d = in_dim;
        for l in 0..cfg.depth - 1 {
            let bounds = cfg.init.bounds(d, cfg.width, false);
            let layer = Linear::new(params, &format!("{name}.l{l}"), group, (d, cfg.width), bounds, rng);
            layers.push(layer);
            d = cfg.width;
        }
        let last = cfg.depth - 1;
        let bounds = cfg.init.bounds(d, out_dim, true);
        layers.push(Linear::new(params, &format!("{name}.l{last}"), group, (d, out_dim), bounds, rng));
        Mlp { layers, hidden: cfg.activation, output }
    }

    /// Runs the network on `x` (`B×in_dim` → `B×out_dim`).
    pub fn forward(&self, tape: &mut Tape, x: Var) -> Var {
        let last = self.layers.len() - 1;
        self.layers.iter().enumerate().fold(x, |h, (i, layer)| {
            layer.forward(tape, h, if i == last { self.output } else { self.hidden })
        })
    }

    /// The layers, input first.
    pub fn layers(&self) -> &[Linear] {
        &self.layers
    }

    /// Input width.
    pub fn in_dim(&self) -> usize {
        self.layers[0].in_dim
    }

    /// Output width.
    pub fn out_dim(&self) -> usize {
        self.layers[self.layers.len() - 1].out_dim
    }

    /// Multiply-adds per input row of one forward pass (FLOPs are twice this; forward + backward
    /// about three times the forward).
    pub fn macs_per_row(&self) -> usize {
        self.layers.iter().map(Linear::macs_per_row).sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn same_seed_same_weights_and_shapes_chain() {
        let cfg = MlpConfig { depth: 4, width: 16, activation: Activation::Relu, init: Init::Torch };
        let build = |seed| {
            let mut p = ParamStore::new();
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            let m = Mlp::new(&mut p, "m", "mlp", &cfg, (5, 2, Activation::Sigmoid), &mut rng);
            (m, p)
        };
        let (m, p1) = build(7);
        let (_, p2) = build(7);
        let (_, p3) = build(8);
        assert_eq!(p1.value(m.layers()[0].weight), p2.value(m.layers()[0].weight));
        assert_ne!(p1.value(m.layers()[0].weight), p3.value(m.layers()[0].weight));
        assert_eq!(m.layers().len(), 4);
        assert_eq!((m.in_dim(), m.out_dim()), (5, 2));
        assert_eq!(m.macs_per_row(), 5 * 16 + 16 * 16 * 2 + 16 * 2);
        let mut tape = Tape::new(p1);
        let x = tape.input(&Tensor::full(4, 5, 0.3));
        let y = m.forward(&mut tape, x);
        assert_eq!(tape.shape(y), crate::Shape::new(4, 2));
        assert!(tape.value(y).iter().all(|&v| v > 0.0 && v < 1.0));
    }
}

//! Unit-testing a plugin without nuvo: run it in-process through the same `extern "C"` entry points
//! nuvo calls, on synthetic steps, and check its gradients against finite differences.
//!
//! ```ignore
//! use nuvo_plugin_api::testing::{TestPlugin, TestStep};
//! use nuvo_plugin_api::Dims;
//!
//! let step = TestStep::random(Dims { charts: 2, batch_3d: 6, batch_uv: 4 }, 1e-2, 7);
//! let mut plugin = TestPlugin::new::<MyLoss>("")?;
//! plugin.check_gradients(&step, 1e-2, 1e-2)?;
//! ```

use std::ffi::c_void;

use crate::abi::{
    PluginDescriptor, PluginString, RawInputs, RawMatrix, RawMatrixMut, RawOutputs, SLOTS,
    STATUS_BAD_OPTIONS, STATUS_OK, STATUS_PANIC, Status, take_plugin_string,
};
use crate::export::descriptor;
use crate::plugin::LossPlugin;
use crate::quantity::{Dims, Quantities, Quantity};

/// Longest message kept from a plugin.
const MAX_MESSAGE: usize = 64 * 1024;

/// The values of every quantity for one synthetic step (each slot shaped as [`Quantity::shape`]).
#[derive(Clone, Debug)]
pub struct TestStep {
    dims: Dims,
    epsilon: f32,
    values: [Vec<f32>; SLOTS],
}

/// A plugin's result on one step: its value and its gradient for each declared differentiable
/// quantity.
#[derive(Clone, Debug)]
pub struct Evaluation {
    /// The loss's value.
    pub value: f32,
    gradients: [Vec<f32>; SLOTS],
}

/// One plugin instance, created and driven through its C entry points.
pub struct TestPlugin {
    descriptor: PluginDescriptor,
    reads: Quantities,
    instance: *mut c_void,
}

/// SplitMix64: a tiny deterministic generator, so steps are reproducible without dependencies.
struct SplitMix(u64);

impl SplitMix {
    fn uniform(&mut self, lo: f32, hi: f32) -> f32 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^= z >> 31;
        lo + (hi - lo) * ((z >> 40) as f32 / (1u64 << 24) as f32)
    }
}

impl TestStep {
    /// A step of sizes `dims` with plausible pseudo-random values from `seed`: points and surface
    /// points in `[-0.5, 0.5]³` (nuvo's model frame), unit normals, UVs in `[0, 1]²`, chart
    /// probabilities that are positive and sum to 1 per row, UV differentials `ε·(I + noise)` (a
    /// well-conditioned Jacobian near the identity), and `σ = ε²`.
    pub fn random(dims: Dims, epsilon: f32, seed: u64) -> TestStep {
        let mut rng = SplitMix(seed);
        let values = std::array::from_fn(|slot| match Quantity::from_slot(slot) {
            None => Vec::new(),
            Some(q) => {
                let (rows, cols) = q.shape(dims);
                (0..rows).flat_map(|_| random_row(q, cols, epsilon, &mut rng)).collect()
            }
        });
        TestStep { dims, epsilon, values }
    }

    /// The step's sizes.
    pub fn dims(&self) -> Dims {
        self.dims
    }

    /// The values of `q`, row-major.
    pub fn values(&self, q: Quantity) -> &[f32] {
        &self.values[q.slot()]
    }

    /// Replaces the values of `q`; fails if `values` does not have `q`'s shape.
    pub fn set(&mut self, q: Quantity, values: &[f32]) -> Result<(), String> {
        let (rows, cols) = q.shape(self.dims);
        if values.len() != rows * cols {
            return Err(format!("`{q}` needs {rows}×{cols} = {} values, got {}", rows * cols, values.len()));
        }
        self.values[q.slot()] = values.to_vec();
        Ok(())
    }
}

fn random_row(q: Quantity, cols: usize, eps: f32, rng: &mut SplitMix) -> Vec<f32> {
    let mut row: Vec<f32> = match q {
        Quantity::Uv | Quantity::Tex | Quantity::CycleUv => {
            (0..cols).map(|_| rng.uniform(0.0, 1.0)).collect()
        }
        Quantity::ChartProbs => (0..cols).map(|_| rng.uniform(0.1, 1.0)).collect(),
        Quantity::UvDifferentials => {
            [1.0, 0.0, 0.0, 1.0].iter().map(|&j| eps * (j + rng.uniform(-0.25, 0.25))).collect()
        }
        Quantity::Sigma => vec![eps * eps],
        _ => (0..cols).map(|_| rng.uniform(-0.5, 0.5)).collect(),
    };
    let norm = match q {
        Quantity::ChartProbs => row.iter().sum::<f32>(),
        Quantity::Normals => row.iter().map(|v| v * v).sum::<f32>().sqrt().max(1e-6),
        _ => 1.0,
    };
    row.iter_mut().for_each(|v| *v /= norm);
    row
}

impl Evaluation {
    /// The gradient with respect to `q` (empty if `q` is not a declared differentiable quantity).
    pub fn gradient(&self, q: Quantity) -> &[f32] {
        &self.gradients[q.slot()]
    }
}

/// A failed call's status and message as one line.
fn describe_failure(status: Status, message: Option<String>) -> String {
    let message = message.unwrap_or_else(|| "(no message)".to_owned());
    match status {
        STATUS_PANIC => format!("panicked: {message}"),
        STATUS_BAD_OPTIONS => format!("bad options: {message}"),
        _ => format!("failed (status {status}): {message}"),
    }
}

impl TestPlugin {
    /// Creates an instance of `P` from options text (TOML, as nuvo passes it).
    pub fn new<P: LossPlugin>(options: &str) -> Result<TestPlugin, String> {
        let d = descriptor::<P>();
        let (Some(create), Some(free)) = (d.create, d.free_string) else {
            return Err("the descriptor has no create or free_string".into());
        };
        let mut instance = std::ptr::null_mut();
        let mut error = PluginString::null();
        // SAFETY: `create` is this crate's glue for `P`; the options text and out-pointers are valid for
        // the call.
        let status = unsafe { create(options.as_ptr(), options.len(), &mut instance, &mut error) };
        // SAFETY: `error` is null or a message from this plugin, taken once.
        let message = unsafe { take_plugin_string(error, free, MAX_MESSAGE) };
        if status != STATUS_OK {
            return Err(describe_failure(status, message));
        }
        let reads =
            Quantities::from_bits(d.reads).map_err(|bits| format!("unknown quantity bits {bits:#x}"))?;
        Ok(TestPlugin { descriptor: d, reads, instance })
    }

    /// Evaluates the plugin on `step`, the way nuvo does: only declared quantities are passed, and
    /// each declared differentiable one gets a zero-filled gradient buffer.
    pub fn evaluate(&mut self, step: &TestStep) -> Result<Evaluation, String> {
        let (Some(evaluate), Some(free)) = (self.descriptor.evaluate, self.descriptor.free_string) else {
            return Err("the descriptor has no evaluate or free_string".into());
        };
        let dims = step.dims;
        let mut gradients: [Vec<f32>; SLOTS] = std::array::from_fn(|_| Vec::new());
        let mut inputs = RawInputs {
            charts: dims.charts,
            batch_3d: dims.batch_3d,
            batch_uv: dims.batch_uv,
            epsilon: step.epsilon,
            quantities: [RawMatrix::EMPTY; SLOTS],
        };
        let mut outputs = RawOutputs { value: f32::NAN, gradients: [RawMatrixMut::EMPTY; SLOTS] };
        for q in self.reads.iter() {
            let (rows, cols) = q.shape(dims);
            inputs.quantities[q.slot()] = RawMatrix { data: step.values[q.slot()].as_ptr(), rows, cols };
            if q.is_differentiable() {
                let g = &mut gradients[q.slot()];
                *g = vec![0.0; rows * cols];
                outputs.gradients[q.slot()] = RawMatrixMut { data: g.as_mut_ptr(), rows, cols };
            }
        }
        let mut error = PluginString::null();
        // SAFETY: the instance is live and used by this thread only; inputs point at `step`'s vectors,
        // which have exactly the declared shapes, and gradient buffers at distinct zeroed vectors, all
        // alive and unmoved during the call.
        let status = unsafe { evaluate(self.instance, &inputs, &mut outputs, &mut error) };
        // SAFETY: `error` is null or a message from this plugin, taken once.
        let message = unsafe { take_plugin_string(error, free, MAX_MESSAGE) };
        if status != STATUS_OK {
            return Err(describe_failure(status, message));
        }
        Ok(Evaluation { value: outputs.value, gradients })
    }

    /// Compares the gradient of every declared differentiable quantity with central differences,
    /// entry by entry. Each entry moves by `relative_step` times the larger of its magnitude and the
    /// quantity's RMS; an entry passes if analytic and numeric gradients differ by at most
    /// `tolerance` times the largest of the two and the quantity's RMS gradient. The first failure is
    /// reported with the quantity, row and column.
    pub fn check_gradients(
        &mut self,
        step: &TestStep,
        relative_step: f32,
        tolerance: f32,
    ) -> Result<(), String> {
        let base = self.evaluate(step)?;
        if !base.value.is_finite() {
            return Err(format!("the value is {}", base.value));
        }
        let mut probe = step.clone();
        for q in self.reads.iter().filter(|q| q.is_differentiable()) {
            let (values, analytic) = (step.values(q), base.gradient(q));
            let scale = rms(values).max(1e-6);
            let typical = rms(analytic);
            let cols = q.shape(step.dims).1;
            for (j, (&v, &a)) in values.iter().zip(analytic).enumerate() {
                let h = relative_step * v.abs().max(scale);
                let (up, down) = (v + h, v - h);
                probe.values[q.slot()][j] = up;
                let f_up = self.evaluate(&probe)?.value;
                probe.values[q.slot()][j] = down;
                let f_down = self.evaluate(&probe)?.value;
                probe.values[q.slot()][j] = v;
                let numeric = ((f_up as f64 - f_down as f64) / (up as f64 - down as f64)) as f32;
                let allowed = tolerance * a.abs().max(numeric.abs()).max(typical).max(1e-12);
                let agrees = (numeric - a).abs() <= allowed; // false for NaN too
                if !agrees {
                    return Err(format!(
                        "gradient of `{q}` at row {}, column {}: analytic {a}, finite differences {numeric}",
                        j / cols,
                        j % cols
                    ));
                }
            }
        }
        Ok(())
    }
}

fn rms(v: &[f32]) -> f32 {
    if v.is_empty() {
        return 0.0;
    }
    (v.iter().map(|x| (*x as f64).powi(2)).sum::<f64>() / v.len() as f64).sqrt() as f32
}

impl Drop for TestPlugin {
    fn drop(&mut self) {
        if let Some(destroy) = self.descriptor.destroy {
            // SAFETY: the instance came from this plugin's `create` and is destroyed exactly once, here.
            unsafe { destroy(self.instance) };
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::abi::OptionDoc;
    use crate::plugin::{Gradients, Inputs};

    /// `Σ_rows Σ_i c_i · (t_i,u)²` over the batch: touches a per-chart and a per-sample quantity.
    struct Weighted {
        fail: bool,
    }

    impl LossPlugin for Weighted {
        const NAME: &'static str = "weighted";
        const DESCRIPTION: &'static str = "test";
        const OPTIONS: &'static [OptionDoc] = &[OptionDoc::new("mode", "\"ok\"", "ok, error or panic")];
        const READS: Quantities = Quantities::of(&[Quantity::ChartProbs, Quantity::Tex, Quantity::X]);

        fn new(options: &str) -> Result<Self, String> {
            match options.trim() {
                "" | "mode = \"ok\"" => Ok(Weighted { fail: false }),
                "mode = \"error\"" => Ok(Weighted { fail: true }),
                "mode = \"panic\"" => panic!("refusing to start"),
                other => Err(format!("unknown field `{other}`, expected `mode`")),
            }
        }

        fn evaluate(&mut self, inputs: &Inputs<'_>, gradients: &mut Gradients<'_>) -> Result<f32, String> {
            if self.fail {
                return Err("asked to fail".into());
            }
            let c = inputs.get(Quantity::ChartProbs)?;
            let mut gc = gradients.take(Quantity::ChartProbs)?;
            let mut gt = gradients.take(Quantity::Tex)?;
            let b = inputs.batch_3d();
            let mut value = 0.0;
            for i in 0..inputs.charts() {
                let t = inputs.chart(Quantity::Tex, i)?;
                for k in 0..b {
                    let (ci, u) = (c.row(k)[i], t.row(k)[0]);
                    value += ci * u * u;
                    gc.row_mut(k)[i] += u * u;
                    gt.row_mut(i * b + k)[0] += 2.0 * ci * u;
                }
            }
            assert!(inputs.get(Quantity::X)?.rows() == b);
            assert!(gradients.take(Quantity::X).is_err() && gradients.take(Quantity::Tex).is_err());
            Ok(value)
        }
    }

    fn step() -> TestStep {
        TestStep::random(Dims { charts: 3, batch_3d: 5, batch_uv: 2 }, 1e-2, 1)
    }

    #[test]
    fn a_correct_gradient_passes_and_a_wrong_one_is_located() {
        let mut p = TestPlugin::new::<Weighted>("").unwrap();
        p.check_gradients(&step(), 1e-2, 1e-2).unwrap();
        let e = p.evaluate(&step()).unwrap();
        assert!(e.gradient(Quantity::X).is_empty() && e.gradient(Quantity::Tex).len() == 30);
        // The check is not vacuous: a plugin whose gradient is off by a factor fails it.
        struct Doubled(Weighted);
        impl LossPlugin for Doubled {
            const NAME: &'static str = "doubled";
            const DESCRIPTION: &'static str = "test";
            const READS: Quantities = Weighted::READS;
            fn new(o: &str) -> Result<Self, String> {
                Weighted::new(o).map(Doubled)
            }
            fn evaluate(&mut self, i: &Inputs<'_>, g: &mut Gradients<'_>) -> Result<f32, String> {
                self.0.evaluate(i, g).map(|v| v / 2.0)
            }
        }
        let e = TestPlugin::new::<Doubled>("").unwrap().check_gradients(&step(), 1e-2, 1e-2).unwrap_err();
        assert!(e.contains("`chart_probs` at row 0, column 0"), "{e}");
    }

    #[test]
    fn errors_and_panics_become_statuses_with_their_messages() {
        let e = TestPlugin::new::<Weighted>("mode = \"panic\"").err().unwrap();
        assert_eq!(e, "panicked: refusing to start");
        let e = TestPlugin::new::<Weighted>("flor = 1").err().unwrap();
        assert!(e.starts_with("bad options: unknown field `flor = 1`"), "{e}");
        let mut p = TestPlugin::new::<Weighted>("mode = \"error\"").unwrap();
        assert_eq!(p.evaluate(&step()).unwrap_err(), "failed (status 1): asked to fail");
    }

    #[test]
    fn random_steps_are_reproducible_and_well_formed() {
        let (a, b) = (step(), step());
        assert_eq!(a.values(Quantity::Tex), b.values(Quantity::Tex));
        for row in a.values(Quantity::ChartProbs).chunks(3) {
            assert!((row.iter().sum::<f32>() - 1.0).abs() < 1e-5);
        }
        let mut s = step();
        assert!(s.set(Quantity::Sigma, &[1.0, 2.0]).is_err());
        s.set(Quantity::Sigma, &[3.0]).unwrap();
        assert_eq!(s.values(Quantity::Sigma), &[3.0]);
    }
}

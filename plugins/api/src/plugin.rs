//! The safe layer: what a plugin author implements ([`LossPlugin`]) and what each evaluation is
//! handed ([`Inputs`] to read, [`Gradients`] to fill).

use crate::abi::{OptionDoc, RawInputs, RawOutputs, SLOTS};
use crate::matrix::{Matrix, MatrixMut};
use crate::quantity::{Dims, Quantities, Quantity};

/// A loss computed outside nuvo's autodiff engine: it reads some per-step [`Quantity`]s and returns
/// its value and its gradient with respect to them. Export it with [`crate::export_loss_plugin!`].
///
/// Contract (see [`crate::abi`] for the full one):
/// - the value is *unweighted*; nuvo multiplies by the configured weight;
/// - gradients are of the returned value, written into the zero-filled buffers of [`Gradients`];
/// - `evaluate` is never called concurrently on one library, but may be called from different threads
///   over time (hence `Send`);
/// - returning `Err` fails the training step with your message; a panic does too, and the instance is
///   not called again. A non-finite value skips the step like any other non-finite loss.
pub trait LossPlugin: Sized + Send + 'static {
    /// Short identifier shown by `nuvo losses` and in error messages (1 to 64 bytes of `a-z`, `0-9`
    /// and `_`). The config's `[losses.NAME]` key names the term in logs, and need not match.
    const NAME: &'static str;
    /// What the loss computes, in a sentence or a paragraph.
    const DESCRIPTION: &'static str;
    /// The weight used when the config gives none.
    const DEFAULT_WEIGHT: f32 = 1.0;
    /// The options `new` accepts, for `nuvo losses`.
    const OPTIONS: &'static [OptionDoc] = &[];
    /// The quantities `evaluate` reads. Only these are computed and handed over.
    const READS: Quantities;

    /// Builds the loss from its options: the TOML text of the config's `[losses.NAME]` table without
    /// the `plugin` and `weight` keys (empty if there are none). Parse it with the `toml` crate, or by
    /// hand. Reject unknown keys: an error worded like serde's (`unknown field \`x\`, expected ...`)
    /// lets nuvo point at the config line.
    fn new(options: &str) -> Result<Self, String>;

    /// Computes the value for one step and writes its gradient with respect to every differentiable
    /// quantity in [`Self::READS`] that it depends on (untouched buffers stay zero).
    fn evaluate(&mut self, inputs: &Inputs<'_>, gradients: &mut Gradients<'_>) -> Result<f32, String>;
}

/// The quantities of one step that the plugin declared, as matrices (see [`Quantity`] for shapes).
pub struct Inputs<'a> {
    dims: Dims,
    epsilon: f32,
    slots: [Option<Matrix<'a>>; SLOTS],
}

/// The gradient buffers of one step: one zero-filled matrix per declared differentiable quantity,
/// shaped like the quantity.
pub struct Gradients<'a> {
    reads: Quantities,
    slots: [Option<MatrixMut<'a>>; SLOTS],
}

fn not_declared(q: Quantity) -> String {
    format!("`{q}` is not in this plugin's READS; declare it to receive it")
}

fn dims_of(raw: &RawInputs) -> Result<Dims, String> {
    let dims = Dims { charts: raw.charts, batch_3d: raw.batch_3d, batch_uv: raw.batch_uv };
    if dims.charts == 0 {
        return Err("the host passed a step with 0 charts".into());
    }
    Ok(dims)
}

impl<'a> Inputs<'a> {
    /// Views the host's inputs, checking each declared slot's shape against the step's sizes.
    ///
    /// # Safety
    /// For every quantity in `reads`, `raw.quantities[slot]` must point at `rows · cols` readable
    /// `f32`s that stay valid and unchanged for `'a` (the host's promise for the duration of a call).
    pub(crate) unsafe fn from_raw(raw: &'a RawInputs, reads: Quantities) -> Result<Self, String> {
        let dims = dims_of(raw)?;
        let mut slots = [None; SLOTS];
        for q in reads.iter() {
            let m = raw.quantities[q.slot()];
            let (rows, cols) = q.shape(dims);
            if (m.rows, m.cols) != (rows, cols) {
                return Err(format!(
                    "the host passed `{q}` as {}×{}, expected {rows}×{cols}",
                    m.rows, m.cols
                ));
            }
            let data: &'a [f32] = match rows * cols {
                0 => &[],
                _ if m.data.is_null() => return Err(format!("the host passed no data for `{q}`")),
                // SAFETY: non-null and, by this function's contract, `rows · cols` valid f32s for 'a.
                len => unsafe { std::slice::from_raw_parts(m.data, len) },
            };
            slots[q.slot()] = Matrix::new(data, rows, cols);
        }
        Ok(Inputs { dims, epsilon: raw.epsilon, slots })
    }

    /// The step's sizes.
    pub fn dims(&self) -> Dims {
        self.dims
    }

    /// Number of charts `n`.
    pub fn charts(&self) -> usize {
        self.dims.charts
    }

    /// Number of 3-D samples `B`.
    pub fn batch_3d(&self) -> usize {
        self.dims.batch_3d
    }

    /// Number of UV samples `T`.
    pub fn batch_uv(&self) -> usize {
        self.dims.batch_uv
    }

    /// The finite-difference step `ε` behind [`Quantity::UvDifferentials`].
    pub fn epsilon(&self) -> f32 {
        self.epsilon
    }

    /// Quantity `q`, whole (per-chart quantities stacked, chart 0 first).
    pub fn get(&self, q: Quantity) -> Result<Matrix<'a>, String> {
        self.slots[q.slot()].ok_or_else(|| not_declared(q))
    }

    /// Chart `i`'s block of a per-chart quantity.
    pub fn chart(&self, q: Quantity, i: usize) -> Result<Matrix<'a>, String> {
        let m = self.get(q)?;
        let rows = q.rows_per_chart(self.dims).ok_or_else(|| format!("`{q}` is not a per-chart quantity"))?;
        if i >= self.dims.charts {
            return Err(format!("chart {i} does not exist; the model has {} charts", self.dims.charts));
        }
        Ok(m.rows_range(i * rows, rows))
    }
}

impl<'a> Gradients<'a> {
    /// Views the host's gradient buffers, checking each one's shape.
    ///
    /// # Safety
    /// For every differentiable quantity in `reads`, `raw.gradients[slot]` must point at `rows · cols`
    /// writable `f32`s, overlapping nothing else, valid for `'a`.
    pub(crate) unsafe fn from_raw(raw: &RawOutputs, reads: Quantities, dims: Dims) -> Result<Self, String> {
        let mut slots = [const { None }; SLOTS];
        for q in reads.iter().filter(|q| q.is_differentiable()) {
            let m = raw.gradients[q.slot()];
            let (rows, cols) = q.shape(dims);
            if (m.rows, m.cols) != (rows, cols) {
                return Err(format!(
                    "the host passed a {}×{} gradient buffer for `{q}`, expected {rows}×{cols}",
                    m.rows, m.cols
                ));
            }
            let data: &'a mut [f32] = match rows * cols {
                0 => &mut [],
                _ if m.data.is_null() => return Err(format!("the host passed no gradient buffer for `{q}`")),
                // SAFETY: non-null and, by this function's contract, `rows · cols` exclusive f32s for 'a.
                len => unsafe { std::slice::from_raw_parts_mut(m.data, len) },
            };
            slots[q.slot()] = MatrixMut::new(data, rows, cols);
        }
        Ok(Gradients { reads, slots })
    }

    /// The gradient buffer of `q` (zero-filled, shaped like `q`). Each buffer can be taken once per
    /// evaluation, so several can be filled at the same time.
    pub fn take(&mut self, q: Quantity) -> Result<MatrixMut<'a>, String> {
        if !q.is_differentiable() {
            return Err(format!("`{q}` is a constant of the batch; it has no gradient"));
        }
        if !self.reads.contains(q) {
            return Err(not_declared(q));
        }
        self.slots[q.slot()].take().ok_or_else(|| format!("the gradient of `{q}` was already taken"))
    }
}

//! The host-owned gradient buffers of one evaluation, with guard words after each one, and the checks
//! of what the plugin left in them.
//!
//! Each declared differentiable quantity gets a zero-filled buffer of exactly its shape, followed by
//! [`GUARD`] words holding a NaN bit pattern no arithmetic produces. After the call, a changed
//! pointer or shape in [`RawOutputs`], or a changed guard word, means the plugin wrote outside what
//! the ABI gave it; the evaluation is refused with the quantity named.

use nuvo_plugin_api::abi::{RawMatrixMut, RawOutputs, SLOTS};
use nuvo_plugin_api::{Dims, Quantities, Quantity};

/// Guard words after each buffer.
const GUARD: usize = 8;
/// A quiet NaN with a payload arithmetic never produces.
const GUARD_BITS: u32 = 0x7fc0_dead;

/// One evaluation's gradient buffers.
pub(crate) struct GradientBuffers {
    dims: Dims,
    reads: Quantities,
    /// Slot `k`: `rows · cols` zeros then `GUARD` guard words, or empty.
    slots: [Vec<f32>; SLOTS],
}

impl GradientBuffers {
    /// Zero-filled, guarded buffers for every differentiable quantity in `reads`.
    pub fn new(reads: Quantities, dims: Dims) -> Self {
        let slots = std::array::from_fn(|slot| match Quantity::from_slot(slot) {
            Some(q) if reads.contains(q) && q.is_differentiable() => {
                let (rows, cols) = q.shape(dims);
                let mut v = vec![0.0; rows * cols + GUARD];
                v[rows * cols..].fill(f32::from_bits(GUARD_BITS));
                v
            }
            _ => Vec::new(),
        });
        GradientBuffers { dims, reads, slots }
    }

    /// The outputs struct handed to the plugin, pointing at the buffers. The pointers stay valid as
    /// long as `self` is neither moved out of nor mutated.
    pub fn raw_outputs(&mut self) -> RawOutputs {
        let mut out = RawOutputs { value: f32::NAN, gradients: [RawMatrixMut::EMPTY; SLOTS] };
        for q in self.differentiable() {
            let (rows, cols) = q.shape(self.dims);
            out.gradients[q.slot()] = RawMatrixMut { data: self.slots[q.slot()].as_mut_ptr(), rows, cols };
        }
        out
    }

    /// Checks that the plugin left every pointer, shape and guard word as they were.
    pub fn check_untouched(&mut self, out: &RawOutputs) -> Result<(), String> {
        let expected = self.raw_outputs();
        for slot in 0..SLOTS {
            if out.gradients[slot] != expected.gradients[slot] {
                let what = Quantity::from_slot(slot).map_or(format!("slot {slot}"), |q| format!("`{q}`"));
                return Err(format!("it changed the pointer or shape of the gradient buffer of {what}"));
            }
        }
        for q in self.differentiable() {
            let (rows, cols) = q.shape(self.dims);
            if self.slots[q.slot()][rows * cols..].iter().any(|g| g.to_bits() != GUARD_BITS) {
                return Err(format!(
                    "it wrote past the end of the gradient buffer of `{q}` ({rows}×{cols} values)"
                ));
            }
        }
        Ok(())
    }

    /// Checks that every gradient is finite, naming the first that is not.
    pub fn check_finite(&self) -> Result<(), String> {
        for q in self.differentiable() {
            if let Some(k) = self.gradient(q).iter().position(|g| !g.is_finite()) {
                return Err(format!(
                    "its gradient with respect to `{q}` is {} at {} (gradients must be finite when the \
                     value is)",
                    self.gradient(q)[k],
                    self.locate(q, k)
                ));
            }
        }
        Ok(())
    }

    /// Zeroes every gradient (when the value is not finite, the step is skipped anyway and the tape
    /// must not hold the plugin's garbage).
    pub fn zero(&mut self) {
        for q in self.differentiable() {
            let (rows, cols) = q.shape(self.dims);
            self.slots[q.slot()][..rows * cols].fill(0.0);
        }
    }

    /// The gradient of `q`, without guard words (empty unless `q` is declared and differentiable).
    pub fn gradient(&self, q: Quantity) -> &[f32] {
        let (rows, cols) = q.shape(self.dims);
        self.slots[q.slot()].get(..rows * cols).unwrap_or(&[])
    }

    /// The declared differentiable quantities.
    pub fn differentiable(&self) -> impl Iterator<Item = Quantity> + use<> {
        self.reads.iter().filter(|q| q.is_differentiable())
    }

    /// "row r, column c" of element `k` of `q`, with the chart and sample for per-chart quantities.
    fn locate(&self, q: Quantity, k: usize) -> String {
        let cols = q.shape(self.dims).1.max(1);
        let (row, col) = (k / cols, k % cols);
        match q.rows_per_chart(self.dims) {
            Some(per) if per > 0 => {
                format!("row {row} (chart {}, sample {}), column {col}", row / per, row % per)
            }
            _ => format!("row {row}, column {col}"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const DIMS: Dims = Dims { charts: 2, batch_3d: 3, batch_uv: 1 };

    fn buffers() -> GradientBuffers {
        GradientBuffers::new(Quantities::of(&[Quantity::X, Quantity::Tex, Quantity::Sigma]), DIMS)
    }

    #[test]
    fn only_differentiable_declared_quantities_get_zeroed_exactly_shaped_buffers() {
        let mut b = buffers();
        let out = b.raw_outputs();
        assert!(out.gradients[Quantity::X.slot()].data.is_null());
        assert_eq!(out.gradients[Quantity::Tex.slot()].rows, 6);
        assert_eq!(b.gradient(Quantity::Tex), &[0.0; 12]);
        assert_eq!(b.gradient(Quantity::Sigma), &[0.0]);
        assert!(b.check_untouched(&out).is_ok() && b.check_finite().is_ok());
    }

    #[test]
    fn overruns_retargeting_and_non_finite_values_are_named() {
        let mut b = buffers();
        let out = b.raw_outputs();
        // SAFETY: writes the first guard word, inside the allocation.
        unsafe { out.gradients[Quantity::Tex.slot()].data.add(12).write(1.0) };
        let e = b.check_untouched(&out).unwrap_err();
        assert!(e.contains("past the end") && e.contains("`tex` (6×2 values)"), "{e}");

        let mut b = buffers();
        let mut out = b.raw_outputs();
        out.gradients[Quantity::Tex.slot()].rows = 7;
        assert!(b.check_untouched(&out).unwrap_err().contains("shape of the gradient buffer of `tex`"));
        out = b.raw_outputs();
        out.gradients[12].rows = 1;
        assert!(b.check_untouched(&out).unwrap_err().contains("slot 12"));

        let mut b = buffers();
        let out = b.raw_outputs();
        // SAFETY: element 9 is inside the 12-value `tex` buffer.
        unsafe { out.gradients[Quantity::Tex.slot()].data.add(9).write(f32::NAN) };
        let e = b.check_finite().unwrap_err();
        assert!(e.contains("`tex` is NaN at row 4 (chart 1, sample 1), column 1"), "{e}");
        b.zero();
        assert!(b.check_finite().is_ok());
    }
}

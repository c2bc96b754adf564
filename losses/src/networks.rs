//! What a loss needs from a Nuvo model: its networks, evaluated on the tape.

use nuvo_autodiff::{Tape, Var};

/// The `2n + 1` networks of a Nuvo atlas plus its two auxiliary parameters, as functions recorded on
/// a tape. `nuvo-core`'s model implements this; tests implement it with tiny hand-made functions.
///
/// Frame invariant: 3-D points are in the model frame (the trainer's scaled canonical frame) and UVs
/// are each chart's own `[0, 1]²`.
pub trait Networks {
    /// Number of charts `n`.
    fn charts(&self) -> usize;

    /// Chart-assignment logits for 3-D points `x` (`B×3` → `B×n`); `c(x)` is their softmax.
    fn chart_logits(&self, tape: &mut Tape, x: Var) -> Var;

    /// Texture coordinates `t_i(x)` of chart `chart` (`B×3` → `B×2`, in `[0, 1]²`).
    fn texture(&self, tape: &mut Tape, chart: usize, x: Var) -> Var;

    /// Surface points `s_i(u)` of chart `chart` (`B×2` → `B×3`).
    fn surface(&self, tape: &mut Tape, chart: usize, uv: Var) -> Var;

    /// The learned average stretch `σ` (1×1).
    fn sigma(&self, tape: &mut Tape) -> Var;

    /// The normal grid `N_i` of chart `chart` (`res²×3`, texel `(x, y)` at row `y·res + x`) and `res`.
    fn normal_grid(&self, tape: &mut Tape, chart: usize) -> (Var, usize);
}

//! The per-step quantities a plugin may read, their shapes and layouts.
//!
//! These are the same quantities nuvo's built-in losses read from its per-step context, computed once
//! per step and shared. A plugin declares the ones it reads ([`crate::LossPlugin::READS`]); the host
//! evaluates only those and hands the plugin their values. For each *differentiable* one, the plugin
//! returns the gradient of its value, which the host chains into the networks (the plugin is a custom
//! op with its own vector-Jacobian product).
//!
//! Notation: `n` charts, `B` 3-D samples, `T` UV samples. Per-chart quantities stack the charts'
//! blocks, chart 0 first: chart `i` owns rows `i·B .. (i+1)·B` (or `i·T ..`).

use std::fmt;

use crate::abi::SLOTS;

/// One quantity; its discriminant is its slot in [`crate::abi::RawInputs`] and its bit in
/// [`crate::abi::PluginDescriptor::reads`]. Never renumbered (see the ABI's versioning rule).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
#[repr(u32)]
pub enum Quantity {
    /// The 3-D samples `x` in the model frame, `B×3`. Constant.
    X = 0,
    /// Their unit normals `n(x)`, `B×3`. Constant.
    Normals = 1,
    /// The UV samples `u`, uniform in `[0, 1]²` and shared by every chart, `T×2`. Constant.
    Uv = 2,
    /// The chart probabilities `c(x)` (rows sum to 1), `B×n`.
    ChartProbs = 3,
    /// `t_i(x)` for every chart, stacked: `nB×2`.
    Tex = 4,
    /// The finite-difference UV differentials `D t_i(εp) = t_i(x + εp) − t_i(x)` and `D t_i(εq)` for
    /// orthonormal tangents `p`, `q = n × p` at `x`, stacked per chart: `nB×4`, each row
    /// `[Dp_u, Dp_v, Dq_u, Dq_v]`. Not divided by `ε`: `J ≈ [Dp Dq] / ε` is the 2×2 Jacobian of
    /// `t_i` on the tangent plane.
    UvDifferentials = 5,
    /// `s_i(u)` for every chart, stacked: `nT×3`.
    SurfacePoints = 6,
    /// The 3→2→3 round trip `s_i(t_i(x))`, stacked: `nB×3`.
    CyclePoints = 7,
    /// The 2→3→2 round trip `t_i(s_i(u))`, stacked: `nT×2`.
    CycleUv = 8,
    /// The learned average stretch `σ`, `1×1`.
    Sigma = 9,
}

/// The sizes of one step. Invariant: `charts ≥ 1`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Dims {
    /// Number of charts `n`.
    pub charts: usize,
    /// 3-D samples `B`.
    pub batch_3d: usize,
    /// UV samples `T`.
    pub batch_uv: usize,
}

impl Quantity {
    /// Every quantity of this ABI version, by slot.
    pub const ALL: [Quantity; 10] = [
        Quantity::X,
        Quantity::Normals,
        Quantity::Uv,
        Quantity::ChartProbs,
        Quantity::Tex,
        Quantity::UvDifferentials,
        Quantity::SurfacePoints,
        Quantity::CyclePoints,
        Quantity::CycleUv,
        Quantity::Sigma,
    ];

    /// Its slot in the input and gradient arrays.
    pub const fn slot(self) -> usize {
        self as usize
    }

    /// Its bit in a [`Quantities`] mask.
    pub const fn bit(self) -> u32 {
        1 << (self as u32)
    }

    /// The quantity in `slot`, if this version defines one there.
    pub fn from_slot(slot: usize) -> Option<Quantity> {
        Quantity::ALL.get(slot).copied()
    }

    /// Its name in messages and in `nuvo losses`.
    pub const fn name(self) -> &'static str {
        match self {
            Quantity::X => "x",
            Quantity::Normals => "normals",
            Quantity::Uv => "uv",
            Quantity::ChartProbs => "chart_probs",
            Quantity::Tex => "tex",
            Quantity::UvDifferentials => "uv_differentials",
            Quantity::SurfacePoints => "surface_points",
            Quantity::CyclePoints => "cycle_points",
            Quantity::CycleUv => "cycle_uv",
            Quantity::Sigma => "sigma",
        }
    }

    /// Whether the host wants its gradient: false for the batch's constants (`x`, normals, `u`).
    pub const fn is_differentiable(self) -> bool {
        !matches!(self, Quantity::X | Quantity::Normals | Quantity::Uv)
    }

    /// Rows of each chart's block for per-chart quantities (`B` or `T`); `None` for the others.
    pub const fn rows_per_chart(self, d: Dims) -> Option<usize> {
        match self {
            Quantity::Tex | Quantity::UvDifferentials | Quantity::CyclePoints => Some(d.batch_3d),
            Quantity::SurfacePoints | Quantity::CycleUv => Some(d.batch_uv),
            _ => None,
        }
    }

    /// `(rows, cols)` for a step of sizes `d`.
    pub const fn shape(self, d: Dims) -> (usize, usize) {
        let (n, b, t) = (d.charts, d.batch_3d, d.batch_uv);
        match self {
            Quantity::X | Quantity::Normals => (b, 3),
            Quantity::Uv => (t, 2),
            Quantity::ChartProbs => (b, n),
            Quantity::Tex => (n * b, 2),
            Quantity::UvDifferentials => (n * b, 4),
            Quantity::SurfacePoints => (n * t, 3),
            Quantity::CyclePoints => (n * b, 3),
            Quantity::CycleUv => (n * t, 2),
            Quantity::Sigma => (1, 1),
        }
    }
}

impl fmt::Display for Quantity {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// A set of quantities, as the bit mask the descriptor carries.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct Quantities(u32);

impl Quantities {
    /// The empty set.
    pub const NONE: Quantities = Quantities(0);

    /// The set of `list`: `Quantities::of(&[Quantity::ChartProbs, Quantity::Tex])`.
    pub const fn of(list: &[Quantity]) -> Quantities {
        let mut bits = 0;
        let mut k = 0;
        while k < list.len() {
            bits |= list[k].bit();
            k += 1;
        }
        Quantities(bits)
    }

    /// The mask.
    pub const fn bits(self) -> u32 {
        self.0
    }

    /// The set a mask describes, or the bits this version does not know.
    pub const fn from_bits(bits: u32) -> Result<Quantities, u32> {
        let known = (1u32 << Quantity::ALL.len()) - 1;
        if bits & !known == 0 { Ok(Quantities(bits)) } else { Err(bits & !known) }
    }

    /// Whether `q` is in the set.
    pub const fn contains(self, q: Quantity) -> bool {
        self.0 & q.bit() != 0
    }

    /// The members, by slot.
    pub fn iter(self) -> impl Iterator<Item = Quantity> {
        Quantity::ALL.into_iter().filter(move |q| self.contains(*q))
    }
}

impl fmt::Display for Quantities {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.0 == 0 {
            return f.write_str("nothing");
        }
        let names: Vec<&str> = self.iter().map(Quantity::name).collect();
        f.write_str(&names.join(", "))
    }
}

const _: () = assert!(Quantity::ALL.len() <= SLOTS, "more quantities than ABI slots");

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn slots_follow_the_declaration_order_and_masks_round_trip() {
        for (k, q) in Quantity::ALL.into_iter().enumerate() {
            assert_eq!(q.slot(), k);
            assert_eq!(Quantity::from_slot(k), Some(q));
        }
        let s = Quantities::of(&[Quantity::Tex, Quantity::ChartProbs]);
        assert_eq!(s.iter().collect::<Vec<_>>(), vec![Quantity::ChartProbs, Quantity::Tex]);
        assert_eq!(Quantities::from_bits(s.bits()), Ok(s));
        assert_eq!(Quantities::from_bits(1 << 12 | 1), Err(1 << 12));
        assert_eq!(s.to_string(), "chart_probs, tex");
    }

    #[test]
    fn per_chart_quantities_stack_one_block_per_chart() {
        let d = Dims { charts: 3, batch_3d: 5, batch_uv: 7 };
        for q in Quantity::ALL {
            if let Some(r) = q.rows_per_chart(d) {
                assert_eq!(q.shape(d).0, 3 * r, "{q}");
            }
        }
    }
}

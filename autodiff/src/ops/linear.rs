//! The fused affine layer `act(x·W + b)`.
//!
//! Both directions walk the batch in blocks of [`kernels::ROW_BLOCK`] rows, blocks in parallel, and
//! finish each block while it is still in cache: forward, a block's GEMM then its bias and
//! activation; backward, a block's activation derivative, its bias-gradient partial sums and its
//! `dx` GEMM. Only `dW = xᵀ·dz`, which needs every row, runs as one separate GEMM. Measured
//! against whole-batch passes: 10% faster single-threaded on the 8×256 MLP, neutral on 2-thread
//! training steps (BENCHMARKS.md, "What got the step here"). Every value is computed exactly as by
//! the unfused passes (a block's GEMM rows equal the whole GEMM's; the bias sums use the
//! reduction's own blocks), so the blocking changes no bits.
//!
//! What the backward needs is made in the forward's blocks where that saves a pass over memory
//! (BENCHMARKS.md, "`xᵀ` packed in the forward"), again without changing a bit:
//! - in bf16, `dW`'s factors are packed in the blocks: `xᵀ` in the forward from the bf16 pairs
//!   the block's product has just packed (kept on the tape, [`Tape::packed`]: half the size of
//!   `x`, +36% peak memory on the paper's step, for ~4% less time), `dz` in the backward's;
//! - a ReLU layer that trains keeps one bit an element, `y > 0` ([`Tape::masks`]), and its
//!   backward multiplies by those instead of reading the outputs again (160 KB instead of a
//!   5 MB pass per 5000×256 layer from L3 or memory: ~5% of the paper's bf16 step).

use serde::{Deserialize, Serialize};

use super::Op;
use super::unary::sigmoid;
use rayon::prelude::*;

use crate::bf16::{
    MatmulPrecision, PackedLeft, PackedRight, gemm_bf16, gemm_bf16_packed_left, gemm_bf16_single_thread,
    gemm_bf16_single_thread_packing_xt, pack_right_block, packs_left_whole, tiles_take,
};
use crate::kernels::{self, MatRef, ROW_BLOCK, gemm, gemm_single_thread};
use crate::shape::Shape;
use crate::tape::{GradSink, Reader, Tape, Var};

/// Activation applied by a fused [`Tape::linear`] layer. Every derivative is computed from the
/// layer's output alone, so the pre-activation is never stored.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Activation {
    /// `y = z`.
    #[default]
    Identity,
    /// `y = max(z, 0)`.
    Relu,
    /// `y = 1 / (1 + e^{−z})`, the range (0, 1).
    Sigmoid,
    /// `y = tanh z`, the range (−1, 1).
    Tanh,
}

impl Activation {
    #[inline(always)]
    fn apply(self, z: f32) -> f32 {
        match self {
            Activation::Identity => z,
            Activation::Relu => z.max(0.0),
            Activation::Sigmoid => sigmoid(z),
            Activation::Tanh => z.tanh(),
        }
    }

    /// dy/dz from the output y.
    #[inline(always)]
    fn derivative_from_output(self, y: f32) -> f32 {
        match self {
            Activation::Identity => 1.0,
            Activation::Relu => (y > 0.0) as u8 as f32,
            Activation::Sigmoid => y * (1.0 - y),
            Activation::Tanh => 1.0 - y * y,
        }
    }
}

impl Tape {
    /// `act(x·w + b)` with `x: B×in`, `w: in×out`, `b: 1×out` (optional).
    pub fn linear(&mut self, x: Var, w: Var, b: Option<Var>, act: Activation) -> Var {
        let (sx, sw) = (self.shape(x), self.shape(w));
        assert_eq!(sx.cols, sw.rows, "linear: input {sx} does not fit weight {sw}");
        if let Some(b) = b {
            assert_eq!(self.shape(b), Shape::new(1, sw.cols), "linear: bias must be 1×{}", sw.cols);
        }
        let shape = Shape::new(sx.rows, sw.cols);
        let mut out = self.pool.take(shape.len());
        let precision = self.matmul_precision;
        // The backward's `dW = xᵀ·dz` on the tiles takes `xᵀ` packed: each block packs its rows
        // of `x` here, where the product has just read them (module docs).
        let mut xt = (precision == MatmulPrecision::Bf16
            && self.nodes[w.index()].requires_grad
            && tiles_take(sx.rows, sw.cols)
            && packs_left_whole(sx.cols))
        .then(|| {
            let words = self.packed_words(PackedLeft::words(sx.cols, sx.rows));
            PackedLeft::for_transpose(sx.cols, sx.rows, words)
        });
        // A ReLU layer's backward reads its derivative from one bit an element, written here
        // while the block's outputs are in cache, not from the outputs (module docs).
        let mut mask = (act == Activation::Relu
            && shape.cols > 0
            && [Some(x), Some(w), b].iter().flatten().any(|v| self.nodes[v.index()].requires_grad))
        .then(|| self.mask_words(shape.len().div_ceil(32)));
        let (xv, wv) = (MatRef::new(self.value(x), sx), MatRef::new(self.value(w), sw));
        let bias = b.map(|b| self.value(b));
        let right = Right::of(wv, precision);
        let block_count = sx.rows.div_ceil(ROW_BLOCK);
        let mut xt_blocks: Vec<Option<(&mut [u32], usize)>> = match xt.as_mut() {
            Some(p) => p.transpose_blocks(ROW_BLOCK).map(Some).collect(),
            None => (0..block_count).map(|_| None).collect(),
        };
        assert_eq!(xt_blocks.len(), block_count, "xᵀ's packed blocks and the row blocks differ");
        let mut mask_blocks: Vec<Option<&mut [u32]>> = match mask.as_mut() {
            Some(m) => m.chunks_mut(ROW_BLOCK * shape.cols / 32).map(Some).collect(),
            None => (0..block_count).map(|_| None).collect(),
        };
        assert_eq!(mask_blocks.len(), block_count, "the mask's blocks and the row blocks differ");
        let finish_block = |first_row: usize,
                            block: &mut [f32],
                            xt_block: &mut Option<(&mut [u32], usize)>,
                            mask_block: &mut Option<&mut [u32]>| {
            let rows = block.len() / shape.cols;
            let x_block = xv.row_range(first_row, rows);
            match (&right, xt_block) {
                (Right::Bf16(w), Some((words, row_tiles))) => {
                    gemm_bf16_single_thread_packing_xt(block, x_block, w, false, words, *row_tiles)
                }
                (Right::F32(_), Some(_)) => {
                    unreachable!("xᵀ is packed only where W's product runs on the tiles (over 32 inputs)")
                }
                (_, None) => right.product(block, x_block, false),
            }
            for row in block.chunks_exact_mut(shape.cols) {
                match bias {
                    Some(bias) => row.iter_mut().zip(bias).for_each(|(y, &b)| *y = act.apply(*y + b)),
                    None if act != Activation::Identity => row.iter_mut().for_each(|y| *y = act.apply(*y)),
                    None => {}
                }
            }
            if let Some(words) = mask_block {
                positive_bits(words, block);
            }
        };
        if shape.cols > 0 {
            out.as_mut_slice()
                .par_chunks_mut(ROW_BLOCK * shape.cols)
                .zip(xt_blocks.par_iter_mut().zip(mask_blocks.par_iter_mut()))
                .enumerate()
                .with_min_len(min_blocks_per_job(sx.rows * sx.cols * sw.cols))
                .for_each(|(i, (block, (xt_block, mask_block)))| {
                    finish_block(i * ROW_BLOCK, block, xt_block, mask_block)
                });
        }
        drop((xt_blocks, mask_blocks));
        let packed_xt = xt.map(|p| self.keep_packed(p));
        let relu_mask = mask.map(|m| self.keep_mask(m));
        let inputs = [x, w, b.unwrap_or(w)];
        self.push(Op::Linear { x, w, b, act, precision, packed_xt, relu_mask }, shape, out, &inputs)
    }
}

#[allow(clippy::too_many_arguments)]
pub(crate) fn backward(
    r: &Reader<'_>,
    s: &mut GradSink<'_>,
    out: &[f32],
    g: &mut [f32],
    x: Var,
    w: Var,
    b: Option<Var>,
    act: Activation,
    precision: MatmulPrecision,
    packed_xt: Option<u32>,
    relu_mask: Option<u32>,
) {
    let (sx, sw) = (r.shape(x), r.shape(w));
    let cols = sw.cols;
    if cols == 0 || sx.rows == 0 {
        return; // no output: every gradient of this layer is empty or zero-rows
    }
    let want_db = b.filter(|&b| s.needs(b));
    let want_dw = s.needs(w);
    let mut dx = (s.needs(x) && sx.cols > 0).then(|| s.slot(x));
    let wt = dx.as_ref().map(|_| Right::of(MatRef::new(r.value(w), sw).t(), precision));
    // `dW = xᵀ·dz` on the tiles takes `dz` packed in pairs of rows: each block packs its own
    // rows while they are hot, instead of a pass over the whole of `dz` afterwards.
    let tiled_dw = want_dw && precision == MatmulPrecision::Bf16 && tiles_take(sx.rows, cols);
    let mut dz_packed = tiled_dw.then(|| PackedRight::unfilled(sx.rows, cols));
    let block_count = sx.rows.div_ceil(ROW_BLOCK);
    let mut dz_words: Vec<Option<&mut [u32]>> = match dz_packed.as_mut() {
        Some(p) => p.row_blocks(ROW_BLOCK).map(Some).collect(),
        None => (0..block_count).map(|_| None).collect(),
    };
    assert_eq!(dz_words.len(), block_count, "dz's packed blocks and the row blocks differ");
    // Per block: dz = g ⊙ act'(y) in place (and packed for dW), the block's bias-gradient sums,
    // and dx = dz·Wᵀ.
    let mask = relu_mask.map(|i| &r.masks[i as usize][..]);
    let finish_block = |g_block: &mut [f32],
                        (i, y_block): (usize, &[f32]),
                        dz_words: &mut Option<&mut [u32]>,
                        dx_block: Option<(&mut [f32], bool)>| {
        match mask {
            Some(mask) => times_bits(g_block, &mask[i * ROW_BLOCK * cols / 32..]),
            None if act != Activation::Identity => {
                g_block.iter_mut().zip(y_block).for_each(|(g, &y)| *g *= act.derivative_from_output(y))
            }
            None => {}
        }
        let dz = MatRef::new(g_block, Shape::new(g_block.len() / cols, cols));
        if let Some(words) = dz_words.as_deref_mut() {
            pack_right_block(words, dz);
        }
        if let (Some((dx_block, fresh)), Some(wt)) = (dx_block, wt.as_ref()) {
            wt.product(dx_block, dz, !fresh);
        }
        want_db.map(|_| kernels::dense_block_sums(g_block, cols))
    };
    let per_job = min_blocks_per_job(sx.rows * sx.cols * cols);
    let (g_blocks, y_blocks) = (g.par_chunks_mut(ROW_BLOCK * cols), out.par_chunks(ROW_BLOCK * cols));
    let blocks = g_blocks.zip(y_blocks.enumerate()).zip(dz_words.par_iter_mut());
    let partials: Vec<Option<Vec<f64>>> = match dx.as_mut() {
        Some((dx, fresh)) => blocks
            .zip(dx.par_chunks_mut(ROW_BLOCK * sx.cols))
            .with_min_len(per_job)
            .map(|(((g, y), words), d)| finish_block(g, y, words, Some((d, *fresh))))
            .collect(),
        None => blocks.with_min_len(per_job).map(|((g, y), words)| finish_block(g, y, words, None)).collect(),
    };
    drop(dz_words);
    if let Some(b) = want_db {
        let partials: Vec<Vec<f64>> = partials.into_iter().flatten().collect();
        let (db, fresh) = s.slot(b);
        kernels::combine_block_sums(db, &partials, !fresh);
    }
    if want_dw {
        let (dw, fresh) = s.slot(w);
        let xt = MatRef::new(r.value(x), sx).t();
        match (dz_packed, packed_xt) {
            (Some(dz), Some(i)) => gemm_bf16_packed_left(dw, &r.packed[i as usize], &dz, !fresh),
            (Some(dz), None) => gemm_bf16(dw, xt, &dz, !fresh),
            (None, _) => gemm(dw, xt, MatRef::new(g, Shape::new(sx.rows, cols)), !fresh),
        }
    }
}

/// The right factor of a layer's row-block products (`W` forward, `Wᵀ` for `dx`): as it is for
/// f32, packed once for the tiles when the layer runs in bf16 and the shape takes them
/// ([`crate::bf16`]).
enum Right<'a> {
    F32(MatRef<'a>),
    Bf16(PackedRight),
}

impl<'a> Right<'a> {
    fn of(b: MatRef<'a>, precision: MatmulPrecision) -> Self {
        if precision == MatmulPrecision::Bf16 && tiles_take(b.rows, b.cols) {
            Right::Bf16(PackedRight::new(b))
        } else {
            Right::F32(b)
        }
    }

    /// `dst = a·self` (or `+=`) on the calling thread.
    fn product(&self, dst: &mut [f32], a: MatRef<'_>, accumulate: bool) {
        match self {
            Right::F32(b) => gemm_single_thread(dst, a, *b, accumulate),
            Right::Bf16(b) => gemm_bf16_single_thread(dst, a, b, accumulate),
        }
    }
}

/// `words` = the bits of `y > 0` of `y`'s elements, element `32w + i` in bit `i` of word `w`
/// (the last word's high bits 0). NaN is not positive, as [`Activation::derivative_from_output`]
/// has it.
fn positive_bits(words: &mut [u32], y: &[f32]) {
    debug_assert!(words.len() >= y.len().div_ceil(32));
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx512f") {
        // SAFETY: the CPU has AVX-512F (checked above).
        unsafe { positive_bits_avx512(words, y) };
        return;
    }
    positive_bits_portable(words, y);
}

/// [`positive_bits`] one value at a time.
fn positive_bits_portable(words: &mut [u32], y: &[f32]) {
    for (w, v) in words.iter_mut().zip(y.chunks(32)) {
        *w = v.iter().enumerate().fold(0, |m, (i, &v)| m | (u32::from(v > 0.0) << i));
    }
}

/// [`positive_bits`] sixteen values a compare.
///
/// # Safety
/// The CPU must have AVX-512F.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
unsafe fn positive_bits_avx512(words: &mut [u32], y: &[f32]) {
    use std::arch::x86_64::*;
    let mut values = y.chunks_exact(32);
    let zero = _mm512_setzero_ps();
    for (w, v) in words.iter_mut().zip(&mut values) {
        // SAFETY: `v` holds 32 values; unaligned loads.
        let (lo, hi) = unsafe { (_mm512_loadu_ps(v.as_ptr()), _mm512_loadu_ps(v.as_ptr().add(16))) };
        let (lo, hi) =
            (_mm512_cmp_ps_mask::<_CMP_GT_OQ>(lo, zero), _mm512_cmp_ps_mask::<_CMP_GT_OQ>(hi, zero));
        *w = u32::from(lo) | (u32::from(hi) << 16);
    }
    let rest = values.remainder();
    if let Some(w) = words.get_mut(y.len() / 32).filter(|_| !rest.is_empty()) {
        *w = rest.iter().enumerate().fold(0, |m, (i, &v)| m | (u32::from(v > 0.0) << i));
    }
}

/// `g ⊙ relu'(y)` from the bits [`positive_bits`] wrote for `y` (starting at `g`'s first
/// element): each `g` times 1 or 0, the same bits as multiplying by the derivative computed
/// from `y`.
fn times_bits(g: &mut [f32], words: &[u32]) {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx512f") {
        // SAFETY: the CPU has AVX-512F (checked above).
        unsafe { times_bits_avx512(g, words) };
        return;
    }
    times_bits_portable(g, words);
}

/// [`times_bits`] one value at a time.
fn times_bits_portable(g: &mut [f32], words: &[u32]) {
    for (v, &w) in g.chunks_mut(32).zip(words) {
        v.iter_mut().enumerate().for_each(|(i, g)| *g *= ((w >> i) & 1) as f32);
    }
}

/// [`times_bits`] sixteen values a multiply.
///
/// # Safety
/// The CPU must have AVX-512F.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
unsafe fn times_bits_avx512(g: &mut [f32], words: &[u32]) {
    use std::arch::x86_64::*;
    let last = words.get(g.len() / 32).copied();
    let mut values = g.chunks_exact_mut(32);
    let one = _mm512_set1_ps(1.0);
    for (v, &w) in (&mut values).zip(words) {
        let p = v.as_mut_ptr();
        // SAFETY: `v` holds 32 values; unaligned loads and stores.
        unsafe {
            let lo = _mm512_mul_ps(_mm512_loadu_ps(p), _mm512_maskz_mov_ps(w as u16, one));
            let hi = _mm512_mul_ps(_mm512_loadu_ps(p.add(16)), _mm512_maskz_mov_ps((w >> 16) as u16, one));
            _mm512_storeu_ps(p, lo);
            _mm512_storeu_ps(p.add(16), hi);
        }
    }
    if let Some(w) = last {
        values.into_remainder().iter_mut().enumerate().for_each(|(i, g)| *g *= ((w >> i) & 1) as f32);
    }
}

/// The row blocks per rayon job for a layer of `work` multiply-adds: one job per block when that is
/// worth it, otherwise one job for all blocks, run on this thread.
fn min_blocks_per_job(work: usize) -> usize {
    if kernels::worth_parallel(work) { 1 } else { usize::MAX }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::tensor::Tensor;

    fn filled(rows: usize, cols: usize, salt: usize) -> Tensor {
        let v = (0..rows * cols).map(|i| (((i * 7919 + salt * 104_729) % 2003) as f32 - 1001.0) / 1001.0);
        Tensor::from_vec(rows, cols, v.collect())
    }

    /// Gradients of `Σ r ⊙ layer(x, w, b)` for x, w, b; `fused` picks `Tape::linear` or the same layer
    /// composed from unfused ops (`relu(x·w + 1·b)`).
    fn gradients(fused: bool, threads: usize) -> Vec<Vec<f32>> {
        gradients_of(fused, threads, MatmulPrecision::F32, &filled, 24)
    }

    /// [`gradients`] at `precision`, the tensors made by `fill(rows, cols, salt)`, `inputs` wide
    /// (more than 32: a bf16 layer packs `xᵀ` in its forward).
    fn gradients_of(
        fused: bool,
        threads: usize,
        precision: MatmulPrecision,
        fill: &(dyn Fn(usize, usize, usize) -> Tensor + Sync),
        inputs: usize,
    ) -> Vec<Vec<f32>> {
        let (rows, i, o) = (1100, inputs, 40); // five row blocks, the last a short one
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        pool.install(|| {
            let mut t = Tape::default();
            t.set_matmul_precision(precision);
            let x = t.leaf(&fill(rows, i, 1));
            let w = t.leaf(&fill(i, o, 2));
            let b = t.leaf(&fill(1, o, 3));
            let y = if fused {
                t.linear(x, w, Some(b), Activation::Relu)
            } else {
                let ones = t.constant(Shape::new(rows, 1), 1.0);
                let (xw, bias) = (t.matmul(x, w), t.matmul(ones, b));
                let z = t.add(xw, bias);
                t.relu(z)
            };
            let r = t.input(&fill(rows, o, 4));
            let weighted = t.mul(y, r);
            let loss = t.sum_all(weighted);
            t.backward(loss);
            [x, w, b].iter().map(|&v| t.grad(v).unwrap().to_vec()).collect()
        })
    }

    #[test]
    fn blocked_layer_matches_unfused_ops_and_any_thread_count() {
        let reference = gradients(false, 1);
        let one = gradients(true, 1);
        assert!(gradients(true, 2) == one, "two threads changed the bits");
        for (name, (got, want)) in ["dx", "dw", "db"].iter().zip(one.iter().zip(&reference)) {
            let scale = want.iter().fold(1.0f32, |m, v| m.max(v.abs()));
            for (g, w) in got.iter().zip(want) {
                assert!((g - w).abs() <= 1e-5 * scale, "{name}: {g} vs {w}");
            }
        }
    }

    /// Small integers: every bf16 rounding and every f32 sum of the layer is exact, so a layer whose
    /// three products run on the tiles must give the f32 layer's values bit for bit (a known answer
    /// for the plumbing: forward, `dx` and `dW` each take the tile path at these sizes).
    #[test]
    fn a_bf16_layer_on_exact_values_gives_the_f32_gradients() {
        if !crate::bf16_matmul_available() {
            eprintln!("no AMX bf16 on this machine: the tile path is not exercised");
            return;
        }
        let ints = |rows: usize, cols: usize, salt: usize| {
            let v = (0..rows * cols).map(|i| ((i * 7919 + salt * 104_729) % 17) as f32 - 8.0);
            Tensor::from_vec(rows, cols, v.collect())
        };
        for inputs in [24, 40] {
            let want = gradients_of(true, 1, MatmulPrecision::F32, &ints, inputs);
            assert!(gradients_of(true, 1, MatmulPrecision::Bf16, &ints, inputs) == want, "{inputs} inputs");
            assert!(gradients_of(true, 2, MatmulPrecision::Bf16, &ints, inputs) == want, "{inputs} inputs");
        }
    }

    /// General values: bf16 layers stay within the factors' rounding of the f32 gradients, and
    /// their bits do not depend on the thread count.
    #[test]
    fn a_bf16_layer_is_close_to_f32_and_deterministic() {
        if !crate::bf16_matmul_available() {
            // bf16 falls back to f32 here, which the last assertion below would refuse.
            assert!(gradients_of(true, 1, MatmulPrecision::Bf16, &filled, 24) == gradients(true, 1));
            return;
        }
        let want = gradients(true, 1);
        let got = gradients_of(true, 1, MatmulPrecision::Bf16, &filled, 24);
        assert!(
            gradients_of(true, 2, MatmulPrecision::Bf16, &filled, 24) == got,
            "two threads changed the bits"
        );
        // In norm: a ReLU whose input the rounding moves across zero changes its row's terms
        // wholly, which no per-element bound allows.
        for (name, (got, want)) in ["dx", "dw", "db"].iter().zip(got.iter().zip(&want)) {
            let norm = |v: &mut dyn Iterator<Item = f32>| v.map(|x| (x as f64).powi(2)).sum::<f64>().sqrt();
            let error = norm(&mut got.iter().zip(want).map(|(g, w)| g - w));
            let size = norm(&mut want.iter().copied());
            assert!(error <= 3e-2 * size, "{name}: error {error} against norm {size}");
            assert!(error > 0.0, "{name}: bf16 gave the f32 bits on general values");
        }
    }

    /// The ReLU bits: `y > 0` per element (NaN and both zeros not), and `g` times them gives
    /// the bits of `g` times the derivative from `y` (−0.0 where `g` is negative), at lengths
    /// that end inside a word, and the same from the vector and the portable code.
    #[test]
    fn relu_bits_give_the_derivative_from_the_output() {
        let special = [f32::NAN, -0.0, 0.0, 1e-30, -1e-30, f32::INFINITY, f32::NEG_INFINITY];
        for len in [0, 1, 16, 31, 32, 33, 100, 256 * 3 + 5] {
            let y: Vec<f32> =
                (0..len)
                    .map(|i| {
                        if i % 5 == 0 { special[i / 5 % special.len()] } else { ((i * 37 % 11) as f32) - 5.0 }
                    })
                    .collect();
            let g: Vec<f32> = (0..len).map(|i| ((i * 13 % 7) as f32) - 3.5).collect();
            let words = len.div_ceil(32);
            let (mut bits, mut portable) = (vec![u32::MAX; words], vec![u32::MAX; words]);
            positive_bits(&mut bits, &y);
            positive_bits_portable(&mut portable, &y);
            assert_eq!(bits, portable, "{len} values");
            for (i, &v) in y.iter().enumerate() {
                assert_eq!((bits[i / 32] >> (i % 32)) & 1 == 1, v > 0.0, "value {i} of {len}: {v}");
            }
            let want: Vec<u32> = g
                .iter()
                .zip(&y)
                .map(|(g, &y)| (g * Activation::Relu.derivative_from_output(y)).to_bits())
                .collect();
            let (mut got, mut got_portable) = (g.clone(), g.clone());
            times_bits(&mut got, &bits);
            times_bits_portable(&mut got_portable, &bits);
            assert_eq!(got.iter().map(|x| x.to_bits()).collect::<Vec<_>>(), want, "{len} values");
            assert_eq!(got_portable.iter().map(|x| x.to_bits()).collect::<Vec<_>>(), want, "{len} values");
        }
    }
}

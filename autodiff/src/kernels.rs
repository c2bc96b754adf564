//! Low-level kernels: GEMM through the `gemm` crate with strided (transposed) views, and parallel
//! elementwise and reduction loops.
//!
//! Determinism invariant: every kernel here gives bit-identical results for the same inputs whatever
//! the number of threads. Elementwise loops are trivially so; reductions split the rows into blocks of a
//! fixed size (not a per-thread split), reduce each block in order in f64, and combine the blocks in
//! order.

use rayon::prelude::*;

use crate::shape::Shape;

/// Elementwise loops shorter than this run on one thread: below it the fork/join overhead dominates.
/// 4096: the per-chart rows of a training step (a few hundred rows, narrow columns) are mostly
/// below the 32k this was before, and left the second core idle (BENCHMARKS.md, "Finer blocks for
/// the training step").
pub(crate) const PAR_MIN_LEN: usize = 1 << 12;
/// Chunk length of parallel elementwise loops.
const PAR_CHUNK: usize = 1 << 11;
/// Rows per block in reductions (fixed, so the summation order never depends on the thread count),
/// and so in the fused linear layer's row-block loops ([`ROW_BLOCK`]). 256: a chart's support of
/// 550–900 rows made two 512-row blocks, one up to ten times the other, so one core waited; 256 keeps
/// the big layers' GEMMs as fast (BENCHMARKS.md, "Finer blocks for the training step").
const REDUCE_BLOCK_ROWS: usize = 256;

/// A read-only matrix view with arbitrary strides, so transposes are free.
#[derive(Clone, Copy)]
pub(crate) struct MatRef<'a> {
    pub data: &'a [f32],
    pub rows: usize,
    pub cols: usize,
    pub row_stride: isize,
    pub col_stride: isize,
}

impl<'a> MatRef<'a> {
    /// A row-major view of `data` with `shape`.
    pub fn new(data: &'a [f32], shape: Shape) -> Self {
        debug_assert_eq!(data.len(), shape.len());
        MatRef { data, rows: shape.rows, cols: shape.cols, row_stride: shape.cols as isize, col_stride: 1 }
    }

    /// The transposed view (no copy).
    pub fn t(self) -> Self {
        MatRef {
            data: self.data,
            rows: self.cols,
            cols: self.rows,
            row_stride: self.col_stride,
            col_stride: self.row_stride,
        }
    }

    /// Rows `start .. start + count` of the view (no copy).
    ///
    /// # Panics
    /// If the rows are out of range, or the view has a negative stride (views here never do).
    pub fn row_range(self, start: usize, count: usize) -> Self {
        assert!(start + count <= self.rows, "row_range: rows {start}+{count} of {}", self.rows);
        let offset = if count == 0 { 0 } else { start * usize::try_from(self.row_stride).expect("stride") };
        MatRef { data: &self.data[offset..], rows: count, ..self }
    }

    /// Where the element at row `r`, column `c` is in `data`.
    #[inline(always)]
    pub fn offset(&self, r: usize, c: usize) -> usize {
        (r as isize * self.row_stride + c as isize * self.col_stride) as usize
    }

    /// The element at row `r`, column `c`.
    #[inline(always)]
    pub fn at(&self, r: usize, c: usize) -> f32 {
        self.data[self.offset(r, c)]
    }

    /// The view, transposed when `transpose` is set.
    pub fn maybe_t(self, transpose: bool) -> Self {
        if transpose { self.t() } else { self }
    }
}

/// Products smaller than this many multiply-adds run on one thread: below it the fork/join
/// overhead is comparable to the work.
const PAR_GEMM_MIN_MACS: usize = 1 << 18;
/// Products with fewer output rows than this are left to the `gemm` crate's own threading (which
/// splits columns too); taller ones are split by rows here.
const PAR_GEMM_MIN_ROWS: usize = 64;
/// Row blocks of a split product start at multiples of this (the AVX-512 micro-kernel's height), so
/// no block but the last runs the narrower tail kernels.
const GEMM_ROW_ALIGN: usize = 32;
/// How many row blocks a split product has, whatever the pool's size: the `gemm` crate picks its
/// inner-dimension blocking from the shape of each call, so the blocks (not the threads) must be
/// fixed for the result not to depend on the thread count. Two: the cores of the machines this
/// is tuned for.
const GEMM_ROW_BLOCKS: usize = 2;

/// `dst (m×n, row-major) = a·b` or, with `accumulate`, `dst += a·b`.
///
/// Threading: a large product with a tall output is split into [`GEMM_ROW_BLOCKS`] contiguous
/// blocks of output rows, each computed by a single-threaded `gemm` call, blocks in parallel. The
/// split depends only on the shape, never on the thread count (the crate's blocking of the inner
/// dimension depends on the rows of a call: a 128-row call and two 64-row calls round differently
/// at some inner sizes), so results are bit-identical for any thread count. This split measured
/// ~25% faster than the crate's own threading for the weight-gradient shape `dW = Xᵀ·dY`
/// (`256×5000 · 5000×256`) and equal for the forward shapes (BENCHMARKS.md, "GEMM threading").
///
/// # Panics
/// On inconsistent dimensions (a programming error).
pub(crate) fn gemm(dst: &mut [f32], a: MatRef<'_>, b: MatRef<'_>, accumulate: bool) {
    if trivial_product(dst, a, b, accumulate) {
        return;
    }
    let (m, k, n) = (a.rows, a.cols, b.cols);
    if m * k * n < PAR_GEMM_MIN_MACS {
        gemm_call(dst, a, b, accumulate, gemm::Parallelism::None);
    } else if m >= PAR_GEMM_MIN_ROWS {
        let rows_per_block = m.div_ceil(GEMM_ROW_BLOCKS).next_multiple_of(GEMM_ROW_ALIGN);
        dst.par_chunks_mut(rows_per_block * n).enumerate().for_each(|(block, d)| {
            let rows = a.row_range(block * rows_per_block, d.len() / n);
            gemm_call(d, rows, b, accumulate, gemm::Parallelism::None);
        });
    } else if rayon::current_num_threads() > 1 {
        gemm_call(dst, a, b, accumulate, gemm::Parallelism::Rayon(0));
    } else {
        gemm_call(dst, a, b, accumulate, gemm::Parallelism::None);
    }
}

/// `dst = a·b` (or `+=`) on the calling thread only: for callers that already split the work into
/// blocks and run the blocks in parallel themselves.
///
/// # Panics
/// On inconsistent dimensions (a programming error).
pub(crate) fn gemm_single_thread(dst: &mut [f32], a: MatRef<'_>, b: MatRef<'_>, accumulate: bool) {
    if !trivial_product(dst, a, b, accumulate) {
        gemm_call(dst, a, b, accumulate, gemm::Parallelism::None);
    }
}

/// Checks the dimensions and finishes the products that need no arithmetic (an empty output, or an
/// empty inner dimension: zeros, or nothing to add); true when it did.
fn trivial_product(dst: &mut [f32], a: MatRef<'_>, b: MatRef<'_>, accumulate: bool) -> bool {
    let (m, k, n) = (a.rows, a.cols, b.cols);
    assert_eq!(k, b.rows, "gemm: inner dimensions {k} and {} differ", b.rows);
    assert_eq!(dst.len(), m * n, "gemm: destination holds {} values, expected {m}×{n}", dst.len());
    if k == 0 && !accumulate {
        dst.fill(0.0);
    }
    m == 0 || n == 0 || k == 0
}

/// Whether a product of `macs` multiply-adds is worth spreading over the pool's threads.
pub(crate) fn worth_parallel(macs: usize) -> bool {
    macs >= PAR_GEMM_MIN_MACS && rayon::current_num_threads() > 1
}

/// One call of the `gemm` crate on checked dimensions (`dst` is `a.rows × b.cols`, row-major).
fn gemm_call(
    dst: &mut [f32],
    a: MatRef<'_>,
    b: MatRef<'_>,
    accumulate: bool,
    parallelism: gemm::Parallelism,
) {
    let (m, k, n) = (a.rows, a.cols, b.cols);
    debug_assert!(k == b.rows && dst.len() == m * n);
    // SAFETY: the views' strides and extents were built from slices holding every element they
    // address (by construction of the MatRefs, and `row_range` keeps that), dst holds exactly m×n
    // (checked by the caller), so every address gemm touches is inside its slice; dst does not alias
    // a or b because it is a distinct &mut.
    unsafe {
        gemm::gemm(
            m,
            n,
            k,
            dst.as_mut_ptr(),
            1,
            n as isize,
            accumulate,
            a.data.as_ptr(),
            a.col_stride,
            a.row_stride,
            b.data.as_ptr(),
            b.col_stride,
            b.row_stride,
            1.0,
            1.0,
            false,
            false,
            false,
            parallelism,
        );
    }
}

/// `out[i] = f(x[i])`, in parallel for long slices.
pub(crate) fn map1(out: &mut [f32], x: &[f32], f: impl Fn(f32) -> f32 + Sync) {
    debug_assert_eq!(out.len(), x.len());
    if out.len() >= PAR_MIN_LEN {
        out.par_chunks_mut(PAR_CHUNK).zip(x.par_chunks(PAR_CHUNK)).for_each(|(o, x)| {
            o.iter_mut().zip(x).for_each(|(o, &x)| *o = f(x));
        });
    } else {
        out.iter_mut().zip(x).for_each(|(o, &x)| *o = f(x));
    }
}

/// `out[i] = f(out[i], x[i])`, in parallel for long slices.
pub(crate) fn update1(out: &mut [f32], x: &[f32], f: impl Fn(f32, f32) -> f32 + Sync) {
    debug_assert_eq!(out.len(), x.len());
    if out.len() >= PAR_MIN_LEN {
        out.par_chunks_mut(PAR_CHUNK).zip(x.par_chunks(PAR_CHUNK)).for_each(|(o, x)| {
            o.iter_mut().zip(x).for_each(|(o, &x)| *o = f(*o, x));
        });
    } else {
        out.iter_mut().zip(x).for_each(|(o, &x)| *o = f(*o, x));
    }
}

/// `out[i] = f(out[i], x[i], y[i])`, in parallel for long slices.
pub(crate) fn update2(out: &mut [f32], x: &[f32], y: &[f32], f: impl Fn(f32, f32, f32) -> f32 + Sync) {
    debug_assert!(out.len() == x.len() && out.len() == y.len());
    if out.len() >= PAR_MIN_LEN {
        out.par_chunks_mut(PAR_CHUNK).zip(x.par_chunks(PAR_CHUNK)).zip(y.par_chunks(PAR_CHUNK)).for_each(
            |((o, x), y)| {
                o.iter_mut().zip(x).zip(y).for_each(|((o, &x), &y)| *o = f(*o, x, y));
            },
        );
    } else {
        out.iter_mut().zip(x).zip(y).for_each(|((o, &x), &y)| *o = f(*o, x, y));
    }
}

/// Calls `f(row_index, out_row)` for every row of `out` (`cols` wide), in parallel for large outputs.
pub(crate) fn for_each_row(out: &mut [f32], cols: usize, f: impl Fn(usize, &mut [f32]) + Sync) {
    if cols == 0 {
        return;
    }
    if out.len() >= PAR_MIN_LEN {
        let rows_per_chunk = (PAR_CHUNK / cols).max(1);
        out.par_chunks_mut(rows_per_chunk * cols).enumerate().for_each(|(c, chunk)| {
            for (r, row) in chunk.chunks_mut(cols).enumerate() {
                f(c * rows_per_chunk + r, row);
            }
        });
    } else {
        out.chunks_mut(cols).enumerate().for_each(|(r, row)| f(r, row));
    }
}

/// Per-column sums of a `rows × cols` matrix whose element `(r, c)` is `value(r, c)`, written (or
/// added, with `accumulate`) into `dst` (length `cols`). Deterministic blocked summation in f64.
pub(crate) fn column_sums(
    dst: &mut [f32],
    rows: usize,
    cols: usize,
    accumulate: bool,
    value: impl Fn(usize, usize) -> f32 + Sync,
) {
    debug_assert_eq!(dst.len(), cols);
    let block = |b: usize| {
        let mut acc = vec![0.0f64; cols];
        for r in b * REDUCE_BLOCK_ROWS..((b + 1) * REDUCE_BLOCK_ROWS).min(rows) {
            for (c, a) in acc.iter_mut().enumerate() {
                *a += value(r, c) as f64;
            }
        }
        acc
    };
    combine_column_blocks(dst, rows, accumulate, block);
}

/// Per-column sums of a dense row-major `rows × cols` matrix `data`: the fast path of
/// [`column_sums`] (same blocks, same order, so the same result), written to vectorise.
pub(crate) fn column_sums_dense(dst: &mut [f32], data: &[f32], cols: usize, accumulate: bool) {
    debug_assert_eq!(dst.len(), cols);
    let rows = data.len().checked_div(cols).unwrap_or(0);
    let block = |b: usize| {
        let end = ((b + 1) * REDUCE_BLOCK_ROWS).min(rows);
        dense_block_sums(&data[b * REDUCE_BLOCK_ROWS * cols..end * cols], cols)
    };
    combine_column_blocks(dst, rows, accumulate, block);
}

/// The f64 column sums of one reduction block (`data` is at most [`REDUCE_BLOCK_ROWS`] rows of
/// `cols`), summed row by row: what [`column_sums_dense`] computes per block, for callers that walk
/// the same blocks themselves (see [`ROW_BLOCK`]).
pub(crate) fn dense_block_sums(data: &[f32], cols: usize) -> Vec<f64> {
    let mut acc = vec![0.0f64; cols];
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx512f") {
        // SAFETY: the CPU has AVX-512F (checked above).
        unsafe { add_rows_avx512(&mut acc, data, cols) };
        return acc;
    }
    add_rows(&mut acc, data, cols);
    acc
}

/// `acc[c] += row[c]` in f64 for each row of `data`, in row order.
#[inline(always)]
fn add_rows(acc: &mut [f64], data: &[f32], cols: usize) {
    for row in data.chunks_exact(cols) {
        acc.iter_mut().zip(row).for_each(|(a, &v)| *a += v as f64);
    }
}

/// [`add_rows`] compiled for AVX-512 (eight columns an instruction, not two; each column's sum
/// in the same order, so the same bits): the bias gradients' sums were 3–4% of the paper's step.
///
/// # Safety
/// The CPU must have AVX-512F.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
unsafe fn add_rows_avx512(acc: &mut [f64], data: &[f32], cols: usize) {
    add_rows(acc, data, cols);
}

/// Rows per block of the fused row-block loops (the linear layer's forward and backward). Equal to
/// the reduction block, so per-block column sums taken inside those loops are exactly the blocks
/// [`column_sums_dense`] would sum, and [`combine_block_sums`] gives the same bits.
pub(crate) const ROW_BLOCK: usize = REDUCE_BLOCK_ROWS;

/// The shared half of the column sums: runs `block(b)` (the f64 column sums of rows
/// `b·REDUCE_BLOCK_ROWS ..`) for every block, in parallel when large, and adds the blocks in a fixed
/// order into `dst`, so the result does not depend on the thread count.
fn combine_column_blocks(
    dst: &mut [f32],
    rows: usize,
    accumulate: bool,
    block: impl Fn(usize) -> Vec<f64> + Sync + Send,
) {
    let blocks = rows.div_ceil(REDUCE_BLOCK_ROWS);
    let partials: Vec<Vec<f64>> = if rows * dst.len() >= PAR_MIN_LEN {
        (0..blocks).into_par_iter().map(block).collect()
    } else {
        (0..blocks).map(block).collect()
    };
    combine_block_sums(dst, &partials, accumulate);
}

/// Adds per-block f64 column sums into `dst` in block order (or overwrites, without `accumulate`).
pub(crate) fn combine_block_sums(dst: &mut [f32], partials: &[Vec<f64>], accumulate: bool) {
    for (c, d) in dst.iter_mut().enumerate() {
        let s: f64 = partials.iter().map(|p| p[c]).sum();
        *d = if accumulate { *d + s as f32 } else { s as f32 };
    }
}

/// Per-row sums of `value(r, c)` over `c`, written (or added) into `dst` (length `rows`).
pub(crate) fn row_sums(
    dst: &mut [f32],
    cols: usize,
    accumulate: bool,
    value: impl Fn(usize, usize) -> f32 + Sync,
) {
    for_each_row(dst, 1, |r, d| {
        let s: f64 = (0..cols).map(|c| value(r, c) as f64).sum();
        d[0] = if accumulate { d[0] + s as f32 } else { s as f32 };
    });
}

/// The sum of `value(r, c)` over a whole `rows × cols` matrix, deterministic, in f64.
pub(crate) fn total_sum(rows: usize, cols: usize, value: impl Fn(usize, usize) -> f32 + Sync) -> f64 {
    let block = |b: usize| -> f64 {
        let mut acc = 0.0f64;
        for r in b * REDUCE_BLOCK_ROWS..((b + 1) * REDUCE_BLOCK_ROWS).min(rows) {
            for c in 0..cols {
                acc += value(r, c) as f64;
            }
        }
        acc
    };
    let blocks = rows.div_ceil(REDUCE_BLOCK_ROWS);
    if rows * cols >= PAR_MIN_LEN {
        let partials: Vec<f64> = (0..blocks).into_par_iter().map(block).collect();
        partials.iter().sum()
    } else {
        (0..blocks).map(block).sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn naive(a: MatRef<'_>, b: MatRef<'_>) -> Vec<f32> {
        let at = |m: MatRef<'_>, r: usize, c: usize| {
            m.data[(r as isize * m.row_stride + c as isize * m.col_stride) as usize]
        };
        let mut out = vec![0.0; a.rows * b.cols];
        for i in 0..a.rows {
            for j in 0..b.cols {
                out[i * b.cols + j] = (0..a.cols).map(|k| at(a, i, k) * at(b, k, j)).sum();
            }
        }
        out
    }

    #[test]
    fn gemm_matches_naive_for_all_transpose_combinations_and_accumulates() {
        let (m, k, n) = (70, 33, 65);
        let a: Vec<f32> = (0..m * k).map(|i| ((i * 7 % 13) as f32 - 6.0) / 5.0).collect();
        let b: Vec<f32> = (0..k * n).map(|i| ((i * 5 % 11) as f32 - 5.0) / 4.0).collect();
        for ta in [false, true] {
            for tb in [false, true] {
                let av = if ta {
                    MatRef::new(&a, Shape::new(k, m)).t()
                } else {
                    MatRef::new(&a, Shape::new(m, k))
                };
                let bv = if tb {
                    MatRef::new(&b, Shape::new(n, k)).t()
                } else {
                    MatRef::new(&b, Shape::new(k, n))
                };
                let want = naive(av, bv);
                let mut got = vec![1.0; m * n];
                gemm(&mut got, av, bv, false);
                for (g, w) in got.iter().zip(&want) {
                    assert!((g - w).abs() < 1e-3, "{g} vs {w}");
                }
                gemm(&mut got, av, bv, true);
                for (g, w) in got.iter().zip(&want) {
                    assert!((g - 2.0 * w).abs() < 2e-3);
                }
            }
        }
    }

    #[test]
    fn split_gemm_is_exact_and_bit_identical_across_thread_counts() {
        // Large enough for the row split (m·n·k ≥ PAR_GEMM_MIN_MACS, m ≥ PAR_GEMM_MIN_ROWS): m not a
        // multiple of the block alignment, so the last block is a short one; and weight-gradient
        // shapes (m = 128 inputs, k = a batch of rows, narrow n) at inner sizes where the `gemm`
        // crate blocks a 128-row call differently from a 64-row one.
        for (m, k, n) in [(301, 97, 40), (128, 1111, 4), (128, 731, 64), (128, 2731, 2)] {
            assert!(m * n * k >= PAR_GEMM_MIN_MACS && m >= PAR_GEMM_MIN_ROWS);
            let a: Vec<f32> = (0..m * k).map(|i| ((i * 7919 % 1013) as f32 - 506.0) / 377.0).collect();
            let b: Vec<f32> = (0..k * n).map(|i| ((i * 104729 % 997) as f32 - 498.0) / 311.0).collect();
            let product = |threads: usize, ta: bool| {
                let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
                let av = if ta {
                    MatRef::new(&a, Shape::new(k, m)).t()
                } else {
                    MatRef::new(&a, Shape::new(m, k))
                };
                let mut out = vec![0.5; m * n];
                pool.install(|| gemm(&mut out, av, MatRef::new(&b, Shape::new(k, n)), true));
                (out, naive(av, MatRef::new(&b, Shape::new(k, n))))
            };
            for ta in [false, true] {
                let (one, want) = product(1, ta);
                for threads in [2, 3] {
                    assert!(
                        product(threads, ta).0 == one,
                        "{m}×{k}×{n}: {threads} threads differ from one (ta {ta})"
                    );
                }
                for (g, w) in one.iter().zip(&want) {
                    assert!((g - (w + 0.5)).abs() < 1e-3 * (1.0 + w.abs()), "{g} vs {}", w + 0.5);
                }
            }
        }
    }

    #[test]
    fn reductions_are_exact_on_integers() {
        let rows = 2000;
        let cols = 3;
        let mut cs = vec![0.0; cols];
        column_sums(&mut cs, rows, cols, false, |r, c| (r % 7 + c) as f32);
        let want: Vec<f32> = (0..cols).map(|c| (0..rows).map(|r| (r % 7 + c) as f32).sum()).collect();
        assert_eq!(cs, want);
        let dense: Vec<f32> = (0..rows * cols).map(|i| ((i / cols) % 7 + i % cols) as f32).collect();
        let mut cd = vec![0.0; cols];
        column_sums_dense(&mut cd, &dense, cols, false);
        assert_eq!(cd, want);
        let total = total_sum(rows, cols, |r, c| (r % 7 + c) as f32);
        assert_eq!(total as f32, want.iter().sum::<f32>());
    }
}

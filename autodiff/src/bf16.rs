//! Matrix products with bf16 inputs and f32 accumulation, on the AMX tiles of recent Intel
//! Xeons (Sapphire Rapids and later, [`amx`]) or on AVX-512 BF16 where a CPU has that but no
//! tiles (AMD Zen 4 and later, [`dot`]): the lower-precision lever of issue 20.
//!
//! [`MatmulPrecision::Bf16`] asks the fused linear layers ([`crate::Tape::linear`]) to round both
//! factors of each of their three products (forward `x·W`, backward `dz·Wᵀ` and `xᵀ·dz`) to
//! bfloat16 and multiply them on this machine's [`Bf16Kernel`], accumulating in f32. On a CPU
//! with neither (or where Linux refuses the tile permission and there is no AVX-512 BF16) the
//! layers run in f32 exactly as with [`MatmulPrecision::F32`], and [`bf16_matmul_available`]
//! says so. The kernel is chosen once per process ([`bf16_kernel`]: the tiles first).
//!
//! Definitions and invariants (exact):
//! - **Rounding**: each f32 factor is rounded to the nearest bf16, ties to even (the top 16 bits
//!   after adding `0x7fff` plus the lowest kept bit); NaNs stay NaNs. So a factor that is already a
//!   bf16 value (8 significant bits) is used exactly, and a product of such values whose partial
//!   sums are exact in f32 equals the f32 product bit for bit (the unit tests' known answers, on
//!   every kernel).
//! - **Accumulation**: per output element, the products of the inner indices are added to one f32
//!   accumulator, the inner dimension walked in increasing order, zero-padded at its end to a
//!   multiple of 32 (`TDPBF16PS` adds 32 inner indices an instruction, `VDPBF16PS` 2; the two
//!   kernels' bits may differ, so a bf16 run repeats per machine kind). With `accumulate`, the
//!   finished block product is added to the destination once at the end (`dst + A·B`, not
//!   interleaved).
//! - **Determinism**: each output element's sum is formed in the same order whatever the row
//!   range of the call, its position within it, and the thread that runs it (no split of the inner
//!   dimension, ever). So results are bit-identical for any thread count, and a product computed
//!   in row blocks equals the whole product's rows, as the f32 path promises
//!   ([`crate::kernels`]).
//! - **Which products**: those whose inner dimension and output width are both at least
//!   [`MIN_SIDE`]; narrower ones (a 2-wide UV head, a 3-wide position head) stay f32, where the
//!   kernels would mostly multiply padding. The rule depends on the shape only.
//! - **Packing**: both kernels read the same packed factors, one 32×32 output block at a time
//!   ([`block_row`]). The right factor is packed once per product in VNNI pairs ([`PackedRight`]),
//!   the left one 32 rows at a time into a per-thread buffer, or, when its columns are contiguous
//!   (the `xᵀ` of a weight gradient), whole in one pass ([`PackedLeft`]) — or, for a layer that
//!   trains, block by block in its forward from the pairs of `x`'s rows packed for its product
//!   ([`gemm_bf16_single_thread_packing_xt`]; the tape keeps it for the backward). Only the
//!   packing differs between these paths, never the order of a sum.
//!
//! Permission: Linux gives a process the AMX state only after it asks ([`amx::granted`]); a
//! tile instruction without it is a SIGILL, so the tiles are chosen only after it was granted.

use std::cell::RefCell;
use std::sync::OnceLock;

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::kernels::MatRef;
use crate::lines::LineBuf;

/// The arithmetic of the fused linear layers' products.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum MatmulPrecision {
    /// f32 factors, f32 accumulation (the `gemm` crate's kernels).
    #[default]
    F32,
    /// bf16 factors, f32 accumulation, on AMX tiles or AVX-512 BF16 where the CPU has them
    /// (module docs); f32 elsewhere.
    Bf16,
}

impl MatmulPrecision {
    /// The precision the layers actually run at on this machine: `Bf16` only where
    /// [`bf16_matmul_available`].
    pub fn effective(self) -> MatmulPrecision {
        match self {
            MatmulPrecision::Bf16 if bf16_matmul_available() => MatmulPrecision::Bf16,
            _ => MatmulPrecision::F32,
        }
    }
}

/// Products whose inner dimension or output width is below this stay f32 (module docs).
pub(crate) const MIN_SIDE: usize = 16;

/// Output rows and columns of one block of tiles.
const BLOCK: usize = 32;
/// The inner dimension of one block of the packed factors, in bf16 elements: what one
/// `TDPBF16PS` consumes, 16 `VDPBF16PS` steps of a pair each.
const INNER: usize = 32;

mod amx;
mod dot;

/// The instructions that multiply the bf16 factors on this machine (module docs).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Bf16Kernel {
    /// AMX tiles, `TDPBF16PS` (Intel Xeon, Sapphire Rapids and later).
    Amx,
    /// AVX-512 BF16, `VDPBF16PS` on 512-bit registers (AMD Zen 4 and later, Intel Cooper Lake).
    Avx512,
}

impl Bf16Kernel {
    /// What a user reads: the hardware the products run on.
    pub fn describe(self) -> &'static str {
        match self {
            Bf16Kernel::Amx => "AMX tiles",
            Bf16Kernel::Avx512 => "AVX-512 BF16",
        }
    }
}

/// The kernel bf16 products run on in this process: the tiles where the CPU has AMX and Linux
/// grants its state, else AVX-512 BF16 where the CPU has it, else none (the layers run f32).
/// Asked once; later calls read the answer.
pub fn bf16_kernel() -> Option<Bf16Kernel> {
    static KERNEL: OnceLock<Option<Bf16Kernel>> = OnceLock::new();
    *KERNEL.get_or_init(|| kernels_here().first().copied())
}

/// Every kernel this process can run, the preferred first (the tiles: 16 times the products of
/// an instruction). The tests run each of them.
fn kernels_here() -> Vec<Bf16Kernel> {
    [(Bf16Kernel::Amx, amx::granted()), (Bf16Kernel::Avx512, dot::available())]
        .into_iter()
        .filter_map(|(kernel, here)| here.then_some(kernel))
        .collect()
}

/// Whether this process can multiply in bf16 ([`bf16_kernel`] names how).
pub fn bf16_matmul_available() -> bool {
    bf16_kernel().is_some()
}

/// The kernel of this process, for the packed products' entry points.
///
/// # Panics
/// When there is none (a programming error: callers take the bf16 path only when
/// [`bf16_matmul_available`]).
fn chosen() -> Bf16Kernel {
    bf16_kernel().expect("a bf16 product on a machine without AMX or AVX-512 BF16")
}

/// Whether a product with inner dimension `k` and output width `n` runs on the tiles when the
/// layer asks for bf16 (module docs: shape only).
pub(crate) fn tiles_take(k: usize, n: usize) -> bool {
    k >= MIN_SIDE && n >= MIN_SIDE
}

/// The f32 with bits `bits` rounded to the nearest bf16, ties to even, in the high half (the low
/// half zero); a NaN becomes the quiet NaN `0x7fc0` (module docs).
#[inline(always)]
fn rounded(bits: u32) -> u32 {
    if bits & 0x7fff_ffff > 0x7f80_0000 {
        0x7fc0_0000
    } else {
        bits.wrapping_add(0x7fff + ((bits >> 16) & 1)) & 0xffff_0000
    }
}

/// `x` rounded to the nearest bf16, as its bits.
#[cfg(test)]
fn to_bf16(x: f32) -> u16 {
    (rounded(x.to_bits()) >> 16) as u16
}

/// Two consecutive inner-index values as the tiles read them: one 32-bit word, the even index's
/// bf16 in the low half.
#[inline(always)]
fn pair(even: f32, odd: f32) -> u32 {
    rounded(odd.to_bits()) | (rounded(even.to_bits()) >> 16)
}

/// `a`'s element at `(r, c)`, 0 outside it (the padding).
#[inline(always)]
fn get(a: MatRef<'_>, r: usize, c: usize) -> f32 {
    if r < a.rows && c < a.cols { a.at(r, c) } else { 0.0 }
}

/// Fills the 16 × 16 words `block` with `m`'s pairs down its columns: `block[q · 16 + c]` the pair
/// `(m[i0 + 2q][c0 + c], m[i0 + 2q + 1][c0 + c])`, 0 outside `m`. Rows of `m` whose 16 values are
/// contiguous are read as runs.
#[cfg_attr(target_arch = "x86_64", target_feature(enable = "avx512f"))]
unsafe fn pairs_down(block: &mut [u32; 256], m: MatRef<'_>, i0: usize, c0: usize) {
    if m.col_stride == 1 && i0 + 32 <= m.rows && c0 + 16 <= m.cols {
        for (q, words) in block.chunks_exact_mut(16).enumerate() {
            let s0 = m.offset(i0 + 2 * q, c0);
            let s1 = m.offset(i0 + 2 * q + 1, c0);
            let (even, odd) = (&m.data[s0..s0 + 16], &m.data[s1..s1 + 16]);
            words.iter_mut().zip(even.iter().zip(odd)).for_each(|(w, (&e, &o))| *w = pair(e, o));
        }
    } else {
        for (q, words) in block.chunks_exact_mut(16).enumerate() {
            for (c, w) in words.iter_mut().enumerate() {
                *w = pair(get(m, i0 + 2 * q, c0 + c), get(m, i0 + 2 * q + 1, c0 + c));
            }
        }
    }
}

/// `words[q]` = the pair `(src[2q], src[2q + 1])`, `src` twice as long as `words`; in runs of 16
/// words, which the compiler turns into vector shuffles (a loop over `chunks_exact(2)` stays
/// scalar).
#[inline(always)]
fn pairs_of_row(words: &mut [u32], src: &[f32]) {
    debug_assert_eq!(src.len(), 2 * words.len());
    let mut runs = words.chunks_exact_mut(16);
    let mut from = src.chunks_exact(32);
    for (w, s) in (&mut runs).zip(&mut from) {
        let (w, s): (&mut [u32; 16], &[f32; 32]) = (w.try_into().unwrap(), s.try_into().unwrap());
        for q in 0..16 {
            w[q] = pair(s[2 * q], s[2 * q + 1]);
        }
    }
    for (w, p) in runs.into_remainder().iter_mut().zip(from.remainder().chunks_exact(2)) {
        *w = pair(p[0], p[1]);
    }
}

/// Fills the 16 × 16 words `block` with `m`'s pairs along its rows: `block[r · 16 + q]` the pair
/// `(m[r0 + r][k0 + 2q], m[r0 + r][k0 + 2q + 1])`, 0 outside `m`. Rows whose 32 values are
/// contiguous are read as runs.
#[cfg_attr(target_arch = "x86_64", target_feature(enable = "avx512f"))]
unsafe fn pairs_along(block: &mut [u32; 256], m: MatRef<'_>, r0: usize, k0: usize) {
    if m.col_stride == 1 && r0 + 16 <= m.rows && k0 + 32 <= m.cols {
        for (r, words) in block.chunks_exact_mut(16).enumerate() {
            let s = m.offset(r0 + r, k0);
            pairs_of_row(words, &m.data[s..s + 32]);
        }
    } else {
        for (r, words) in block.chunks_exact_mut(16).enumerate() {
            for (q, w) in words.iter_mut().enumerate() {
                *w = pair(get(m, r0 + r, k0 + 2 * q), get(m, r0 + r, k0 + 2 * q + 1));
            }
        }
    }
}

/// Packed bf16 pairs on whole cache lines, so that every tile row the kernel loads starts on a
/// line: the layouts keep rows and tiles at multiples of 16 words ([`crate::lines`]).
pub(crate) type Words = LineBuf<u32>;

/// The right factor `B` (`k × n`) of a product, rounded to bf16 and laid out for the tiles: `kp / 2`
/// rows of `np` words, word `(q, j)` the pair `(B[2q][j], B[2q+1][j])` (the VNNI layout
/// `TDPBF16PS` reads), `kp` = `k` rounded up to 32, `np` = `n` rounded up to 32, zeros in the
/// padding. A tile of 16 columns is 16 word rows `np` words apart.
pub(crate) struct PackedRight {
    data: Words,
    k: usize,
    n: usize,
    /// Inner dimension rounded up to [`INNER`].
    kp: usize,
    /// Columns rounded up to [`BLOCK`].
    np: usize,
}

impl PackedRight {
    /// Packs `b` (any strides), blocks of rows in parallel when it is large. A row-major `b` (an
    /// activation gradient `dz`) is read row by row; a transposed one (a weight `Wᵀ`, whose columns
    /// are contiguous) 16 × 16 words at a time, transposed in registers.
    ///
    /// # Panics
    /// When [`bf16_matmul_available`] is false (the packing uses AVX-512, which every CPU with
    /// AMX or AVX-512 BF16 has).
    pub(crate) fn new(b: MatRef<'_>) -> Self {
        let (k, n) = (b.rows, b.cols);
        let mut packed = PackedRight::unfilled(k, n);
        let np = packed.np;
        let chunk = 16 * np; // 16 word rows: one tile's height
        // SAFETY: AVX-512F is present where a bf16 kernel is (`unfilled` asserted it).
        let fill = |(c, rows): (usize, &mut [u32])| unsafe { pack_right_rows(rows, b, 16 * c, np) };
        if k * n >= 1 << 16 {
            packed.data.par_chunks_mut(chunk).enumerate().for_each(fill);
        } else {
            packed.data.chunks_mut(chunk).enumerate().for_each(fill);
        }
        packed
    }

    /// Room for a `k × n` factor, its words any value until [`PackedRight::new`] fills them,
    /// or the caller block by block ([`PackedRight::row_blocks`], [`pack_right_block`]) where it
    /// computes the rows: each writes every word of what it packs, padding included, so the
    /// buffer is not cleared first (a 2.5 MB pass per 5000×256 `dz`: 2% of the paper's step).
    ///
    /// # Panics
    /// As [`PackedRight::new`].
    pub(crate) fn unfilled(k: usize, n: usize) -> Self {
        assert!(bf16_matmul_available(), "PackedRight on a machine without bf16 products");
        let (kp, np) = (k.next_multiple_of(INNER), n.next_multiple_of(BLOCK));
        PackedRight { data: spare_words(kp / 2 * np), k, n, kp, np }
    }

    /// The words of each block of `rows` factor rows in turn (the last block's padding
    /// included): as many blocks as `k.div_ceil(rows)`.
    ///
    /// # Panics
    /// When `rows` is not a positive multiple of [`INNER`] (a block must hold whole pairs and
    /// end on a padded row).
    pub(crate) fn row_blocks(&mut self, rows: usize) -> impl Iterator<Item = &mut [u32]> {
        assert!(rows > 0 && rows.is_multiple_of(INNER), "row blocks of {rows} rows");
        self.data.chunks_mut(rows / 2 * self.np)
    }
}

/// Packs the row-major rows `block` into `words`, a block of [`PackedRight::row_blocks`] of
/// the factor those rows belong to (the same words [`PackedRight::new`] writes for them).
///
/// # Panics
/// When `block` is not row-major, or `words` is not one such block of its width.
pub(crate) fn pack_right_block(words: &mut [u32], block: MatRef<'_>) {
    assert!(bf16_matmul_available(), "packing on a machine without bf16 products");
    assert_eq!(block.col_stride, 1, "pack_right_block packs row-major rows");
    let np = block.cols.next_multiple_of(BLOCK);
    assert!(words.len().is_multiple_of(np) && 2 * words.len() / np >= block.rows, "words of another block");
    // SAFETY: AVX-512F is present where a bf16 kernel is (asserted above); `words` holds whole
    // word rows.
    unsafe { pack_right_rows(words, block, 0, np) };
}

impl Drop for PackedRight {
    fn drop(&mut self) {
        give_back(std::mem::take(&mut self.data));
    }
}

/// Word rows `q0 ..` of [`PackedRight`]'s layout (`rows`: whole rows of `np` words; 16 of them
/// when `b` is not row-major), every word written: zeros past `b`'s rows and columns.
///
/// # Safety
/// The CPU must have AVX-512F.
#[cfg_attr(target_arch = "x86_64", target_feature(enable = "avx512f"))]
unsafe fn pack_right_rows(rows: &mut [u32], b: MatRef<'_>, q0: usize, np: usize) {
    let (k, n) = (b.rows, b.cols);
    if b.col_stride == 1 {
        for (qq, row) in rows.chunks_exact_mut(np).enumerate() {
            let q = q0 + qq;
            if 2 * q >= k {
                row.fill(0);
                continue;
            }
            let even = &b.data[b.offset(2 * q, 0)..][..n];
            if 2 * q + 1 < k {
                let odd = &b.data[b.offset(2 * q + 1, 0)..][..n];
                row.iter_mut().zip(even.iter().zip(odd)).for_each(|(w, (&e, &o))| *w = pair(e, o));
            } else {
                row.iter_mut().zip(even).for_each(|(w, &e)| *w = pair(e, 0.0));
            }
            row[n..].fill(0);
        }
    } else {
        debug_assert_eq!(rows.len(), 16 * np);
        let mut block = [0u32; 256];
        for j0 in (0..n).step_by(16) {
            // block[c][qq]: column j0 + c's pair at rows 2(q0 + qq), + 1, i.e. row j0 + c of `bᵀ`
            // (contiguous); the word rows are its transpose.
            // SAFETY: AVX-512F (the caller's), `rows` holds 16 rows of `np ≥ j0 + 16` words.
            unsafe {
                pairs_along(&mut block, b.t(), j0, 2 * q0);
                transpose16(&block, rows[j0..].as_mut_ptr(), np);
            }
        }
        let written = n.next_multiple_of(16);
        rows.chunks_exact_mut(np).for_each(|row| row[written..].fill(0));
    }
}

/// The left factor `A` (`m × k`) of a product whose columns are contiguous (the `xᵀ` of a weight
/// gradient), rounded to bf16 and laid out tile by tile: for each block of 16 inner pairs, for
/// each block of 16 rows, the tile's 16 rows of 16 words (word `(r, q)` the pair
/// `(A[r][2q], A[r][2q + 1])`), zeros in the padding. Packed in one pass over `A`'s memory
/// (blocks of inner pairs in parallel), where packing 32 rows at a time would read all of it
/// with a stride per row; or by the caller, one block of `Aᵀ`'s rows at a time while it computes
/// them ([`PackedLeft::for_transpose`], [`gemm_bf16_single_thread_packing_xt`]): a layer's forward packs the
/// `xᵀ` of its weight gradient that way.
pub(crate) struct PackedLeft {
    data: Words,
    /// Row blocks of 16 (rows rounded up to 32, over 16).
    row_tiles: usize,
    /// `A`'s rows and inner dimension.
    m: usize,
    k: usize,
}

impl PackedLeft {
    /// # Safety
    /// The CPU must have AVX-512F.
    unsafe fn new(a: MatRef<'_>, kp: usize) -> Self {
        debug_assert_eq!(kp, a.cols.next_multiple_of(INNER));
        let words = spare_words(PackedLeft::words(a.rows, a.cols));
        let mut left = PackedLeft::for_transpose(a.rows, a.cols, words);
        let row_tiles = left.row_tiles;
        left.data.par_chunks_mut(256 * row_tiles).enumerate().for_each(|(qb, tiles)| {
            // SAFETY: AVX-512F (the caller's); `tiles` is inner block `qb`'s.
            unsafe { pack_transposed_tiles(tiles, a.t(), 32 * qb, row_tiles) };
        });
        left
    }

    /// Room for the `m × k` factor `A` in `words` (any contents: every word is written when each
    /// block of [`PackedLeft::transpose_blocks`] is packed by
    /// [`gemm_bf16_single_thread_packing_xt`]).
    ///
    /// # Panics
    /// When [`bf16_matmul_available`] is false.
    pub(crate) fn for_transpose(m: usize, k: usize, mut words: Words) -> Self {
        assert!(bf16_matmul_available(), "PackedLeft on a machine without bf16 products");
        words.set_len(PackedLeft::words(m, k));
        PackedLeft { data: words, row_tiles: m.next_multiple_of(BLOCK) / 16, m, k }
    }

    /// The words an `m × k` factor takes.
    pub(crate) fn words(m: usize, k: usize) -> usize {
        k.next_multiple_of(INNER) / 2 * m.next_multiple_of(BLOCK)
    }

    /// The words of each block of `rows` rows of `Aᵀ` (inner indices of `A`) in turn, the last
    /// block's padding included: as many blocks as `k.div_ceil(rows)`, each with the tile count
    /// [`gemm_bf16_single_thread_packing_xt`] needs.
    ///
    /// # Panics
    /// When `rows` is not a positive multiple of [`INNER`].
    pub(crate) fn transpose_blocks(&mut self, rows: usize) -> impl Iterator<Item = (&mut [u32], usize)> {
        assert!(rows > 0 && rows.is_multiple_of(INNER), "row blocks of {rows} rows");
        let row_tiles = self.row_tiles;
        self.data.chunks_mut(rows / INNER * 256 * row_tiles).map(move |w| (w, row_tiles))
    }

    /// The buffer, for reuse.
    pub(crate) fn into_words(mut self) -> Words {
        std::mem::take(&mut self.data)
    }
}

/// Packs rows `i0 ..` of the row-major `at` (= `Aᵀ`) into `tiles`, whole inner blocks of
/// [`PackedLeft`]'s layout (`256 · row_tiles` words each) from inner index `i0` on; rows past
/// `at`'s end and columns past its width are zeros.
///
/// # Safety
/// The CPU must have AVX-512F.
#[cfg_attr(target_arch = "x86_64", target_feature(enable = "avx512f"))]
unsafe fn pack_transposed_tiles(tiles: &mut [u32], at: MatRef<'_>, i0: usize, row_tiles: usize) {
    let mut block = [0u32; 256];
    for (qq, inner) in tiles.chunks_exact_mut(256 * row_tiles).enumerate() {
        for (t, tile) in inner.chunks_exact_mut(256).enumerate() {
            // block[qq][c]: row 16t + c's pair at inner indices i0 + 32qq + 2q, + 1, i.e. the
            // pairs down `Aᵀ` (contiguous rows); the tile is its transpose.
            // SAFETY: AVX-512F (the caller's); `tile` holds 16 rows of 16 words.
            unsafe {
                pairs_down(&mut block, at, i0 + 32 * qq, 16 * t);
                transpose16(&block, tile.as_mut_ptr(), 16);
            }
        }
    }
}

impl Drop for PackedLeft {
    fn drop(&mut self) {
        give_back(std::mem::take(&mut self.data));
    }
}

/// Packed factors' buffers kept for the next products on this thread, at most this many.
const SPARES: usize = 4;

thread_local! {
    /// Buffers of dropped packed factors ([`spare_words`]).
    static SPARE: RefCell<Vec<Words>> = const { RefCell::new(Vec::new()) };
}

/// `len` words for a packed factor (any values: every packer writes all of its words, padding
/// included), in a buffer a dropped one left on this thread when one holds them. Why: every
/// product packs its factors anew, and fresh multi-megabyte buffers came from the kernel as
/// zeroed pages each time (page faults and clearing: ~3% of the paper's bf16 step).
fn spare_words(len: usize) -> Words {
    let mut w = spare_buffer(len);
    w.set_len(len);
    w
}

/// The spare buffer that best holds `len` words (module docs of [`spare_words`]), or a new one.
fn spare_buffer(len: usize) -> Words {
    SPARE.with_borrow_mut(|spare| take_best_fit(spare, len))
}

/// Takes from `spare` the buffer that best holds `len` words: the smallest that holds them,
/// else the largest (to be grown), else a new one. Why not any: a large buffer taken for a
/// small factor would leave the next large one to fresh pages.
pub(crate) fn take_best_fit(spare: &mut Vec<Words>, len: usize) -> Words {
    let by_capacity = |&i: &usize| spare[i].capacity();
    let fits = (0..spare.len()).filter(|&i| spare[i].capacity() >= len).min_by_key(by_capacity);
    fits.or_else(|| (0..spare.len()).max_by_key(by_capacity))
        .map(|i| spare.swap_remove(i))
        .unwrap_or_default()
}

/// Keeps `w` for [`spare_words`] (the largest [`SPARES`] of them).
fn give_back(w: Words) {
    if w.capacity() == 0 {
        return;
    }
    SPARE.with_borrow_mut(|spare| {
        spare.push(w);
        if spare.len() > SPARES {
            let smallest = (0..spare.len()).min_by_key(|&i| spare[i].capacity()).expect("not empty");
            spare.swap_remove(smallest);
        }
    });
}

thread_local! {
    /// One 32-row block of the left factor in bf16 pairs, reused by every product on this thread.
    static LEFT: RefCell<Words> = const { RefCell::new(Words::new()) };
}

/// Where a block row's left tiles are: the tile of row half `h` (0, 1) and inner block `qb` starts
/// `h · half_step + qb · q_step` words after `base`, its rows `stride` bytes apart.
#[derive(Clone, Copy)]
struct LeftTiles {
    base: *const u32,
    half_step: usize,
    q_step: usize,
    stride: isize,
}

/// `dst (m×n, row-major) = a·b` or, with `accumulate`, `dst += a·b`, on the calling thread, with
/// `b` packed (module docs).
///
/// # Panics
/// On inconsistent dimensions, or when [`bf16_matmul_available`] is false (a programming error:
/// callers choose this path only when it is true).
pub(crate) fn gemm_bf16_single_thread(dst: &mut [f32], a: MatRef<'_>, b: &PackedRight, accumulate: bool) {
    gemm_rows(dst, a, b, accumulate, None, chosen());
}

/// [`gemm_bf16_single_thread`] that also packs `aᵀ` as the left factor of a later product
/// (`xᵀ·dz`, the weight gradient of the layer whose input `a` is): into `xt`, the block of
/// [`PackedLeft::transpose_blocks`] holding `a`'s rows, with its `row_tiles`. Each 32 rows'
/// pairs come from the block of bf16 pairs just packed for this product, still in L1, not
/// from `a` again (the same words as [`PackedLeft`] packed whole from `aᵀ`).
///
/// # Panics
/// As [`gemm_bf16_single_thread`], and when `xt` is not such a block for `a`.
pub(crate) fn gemm_bf16_single_thread_packing_xt(
    dst: &mut [f32],
    a: MatRef<'_>,
    b: &PackedRight,
    accumulate: bool,
    xt: &mut [u32],
    row_tiles: usize,
) {
    assert!(
        b.kp == 16 * row_tiles
            && xt.len().is_multiple_of(256 * row_tiles)
            && xt.len() / (256 * row_tiles) * INNER >= a.rows,
        "words of another block"
    );
    gemm_rows(dst, a, b, accumulate, Some(xt), chosen());
}

/// [`gemm_bf16_single_thread_packing_xt`], or without `xt` [`gemm_bf16_single_thread`], on
/// `kernel`.
fn gemm_rows(
    dst: &mut [f32],
    a: MatRef<'_>,
    b: &PackedRight,
    accumulate: bool,
    xt: Option<&mut [u32]>,
    kernel: Bf16Kernel,
) {
    let (m, n) = (a.rows, b.n);
    check(dst, a, b);
    if m == 0 || n == 0 {
        return;
    }
    let half = b.kp / 2;
    let mut xt_blocks = xt.map(|w| w.chunks_exact_mut(16 * b.kp));
    LEFT.with_borrow_mut(|left| {
        left.set_zeroed(BLOCK * half);
        for i0 in (0..m).step_by(BLOCK) {
            let rows = BLOCK.min(m - i0);
            // SAFETY: AVX-512F is present where a bf16 kernel is (checked).
            unsafe { pack_left(left, a, i0, rows) };
            if let Some(tiles) = xt_blocks.as_mut().and_then(Iterator::next) {
                // SAFETY: as above; `left` holds 32 rows of `half` words, `tiles` 256 · kp / 16.
                unsafe { transposed_tiles_from_left(tiles, left, half) };
            }
            let tiles = LeftTiles {
                base: left.as_ptr(),
                half_step: 16 * half,
                q_step: 16,
                stride: (half * 4) as isize,
            };
            // SAFETY: the tile state was granted (checked); `left` holds 32 rows of `kp / 2`
            // words, which is all the kernel reads of it; `dst` rows `i0..i0 + rows` exist.
            unsafe { block_row(kernel, &mut dst[i0 * n..(i0 + rows) * n], rows, tiles, b, accumulate) };
        }
    });
}

/// One inner block of [`PackedLeft`]'s layout for `Aᵀ` (`tiles`: `2 · half / 16` tiles of 256
/// words) from the 32 rows of `A` in `left` ([`pack_left`]'s layout: row `r` `half` words, its
/// bf16 values in order as 16-bit halves): tile `t`'s block before its transpose has row `q`
/// interleaving the values of `A`'s rows `2q` and `2q + 1` at columns `16t ..`.
///
/// # Safety
/// The CPU must have AVX-512F.
#[cfg_attr(target_arch = "x86_64", target_feature(enable = "avx512f"))]
unsafe fn transposed_tiles_from_left(tiles: &mut [u32], left: &[u32], half: usize) {
    let mut block = [0u32; 256];
    for (t, tile) in tiles.chunks_exact_mut(256).enumerate() {
        for (q, words) in block.chunks_exact_mut(16).enumerate() {
            let (even, odd) = (&left[2 * q * half + 8 * t..][..8], &left[(2 * q + 1) * half + 8 * t..][..8]);
            for (j, (&e, &o)) in even.iter().zip(odd).enumerate() {
                words[2 * j] = (e & 0xffff) | (o << 16);
                words[2 * j + 1] = (e >> 16) | (o & 0xffff_0000);
            }
        }
        // SAFETY: AVX-512F (the caller's); `tile` holds 16 rows of 16 words.
        unsafe { transpose16(&block, tile.as_mut_ptr(), 16) };
    }
}

/// The dimensions agree and the tiles can run (panics otherwise: module docs).
fn check(dst: &[f32], a: MatRef<'_>, b: &PackedRight) {
    let (m, k, n) = (a.rows, a.cols, b.n);
    assert_eq!(k, b.k, "gemm_bf16: inner dimensions {k} and {} differ", b.k);
    assert_eq!(dst.len(), m * n, "gemm_bf16: destination holds {} values, expected {m}×{n}", dst.len());
    assert!(bf16_matmul_available(), "gemm_bf16 called on a machine without bf16 products");
}

/// [`gemm_bf16_single_thread`] with blocks of 32 output rows spread over the pool (the same bits:
/// module docs). A left factor whose columns are contiguous is packed whole first
/// ([`PackedLeft`]).
pub(crate) fn gemm_bf16(dst: &mut [f32], a: MatRef<'_>, b: &PackedRight, accumulate: bool) {
    gemm_bf16_on(chosen(), dst, a, b, accumulate);
}

/// [`gemm_bf16`] on `kernel`.
fn gemm_bf16_on(kernel: Bf16Kernel, dst: &mut [f32], a: MatRef<'_>, b: &PackedRight, accumulate: bool) {
    let n = b.n;
    if n == 0 || !packs_left_whole(a.rows) {
        return gemm_rows(dst, a, b, accumulate, None, kernel);
    }
    if a.row_stride == 1 && a.col_stride != 1 {
        check(dst, a, b);
        // SAFETY: both kernels' CPUs have AVX-512F (checked).
        let left = unsafe { PackedLeft::new(a, b.kp) };
        return gemm_bf16_packed_left_on(kernel, dst, &left, b, accumulate);
    }
    dst.par_chunks_mut(BLOCK * n).enumerate().for_each(|(block, d)| {
        gemm_rows(d, a.row_range(block * BLOCK, d.len() / n), b, accumulate, None, kernel);
    });
}

/// `dst (m×n) = a·b` (or `+=`) with the left factor packed already, blocks of 32 output rows
/// spread over the pool (the same bits as [`gemm_bf16`] on the unpacked factor).
///
/// # Panics
/// On inconsistent dimensions.
pub(crate) fn gemm_bf16_packed_left(dst: &mut [f32], a: &PackedLeft, b: &PackedRight, accumulate: bool) {
    gemm_bf16_packed_left_on(chosen(), dst, a, b, accumulate);
}

/// [`gemm_bf16_packed_left`] on `kernel`.
fn gemm_bf16_packed_left_on(
    kernel: Bf16Kernel,
    dst: &mut [f32],
    a: &PackedLeft,
    b: &PackedRight,
    accumulate: bool,
) {
    let n = b.n;
    assert_eq!(a.k, b.k, "gemm_bf16: inner dimensions {} and {} differ", a.k, b.k);
    assert_eq!(dst.len(), a.m * n, "gemm_bf16: destination holds {} values, expected {}×{n}", dst.len(), a.m);
    if n == 0 || a.m == 0 {
        return;
    }
    let q_step = 256 * a.row_tiles;
    let base = SendPtr(a.data.as_ptr());
    dst.par_chunks_mut(BLOCK * n).enumerate().for_each(|(block, d)| {
        // SAFETY: row tiles 2·block and 2·block + 1 exist (rows rounded up to 32); `kernel` runs
        // here (`PackedLeft` exists only where one does); `d` holds this block's rows.
        unsafe {
            let tiles =
                LeftTiles { base: base.get().add(2 * block * 256), half_step: 256, q_step, stride: 64 };
            block_row(kernel, d, d.len() / n, tiles, b, accumulate);
        }
    });
}

/// One row of 32 × 32 output blocks, `dst` (`rows ≤ 32` × `b.n`) `=` or `+=` the left rows `a`
/// times `b`, on `kernel` (its module: [`amx`], [`dot`]).
///
/// # Safety
/// `kernel` must run on this machine ([`kernels_here`]); `a` must address 32 rows (2 halves of
/// 16) of `b.kp / 2` words in its layout, and `dst` hold `rows × b.n` values.
unsafe fn block_row(
    kernel: Bf16Kernel,
    dst: &mut [f32],
    rows: usize,
    a: LeftTiles,
    b: &PackedRight,
    accumulate: bool,
) {
    // SAFETY: the caller's.
    unsafe {
        match kernel {
            Bf16Kernel::Amx => amx::block_row(dst, rows, a, b, accumulate),
            Bf16Kernel::Avx512 => dot::block_row(dst, rows, a, b, accumulate),
        }
    }
}

/// Whether [`gemm_bf16`] packs a left factor of `rows` rows with contiguous columns whole
/// ([`PackedLeft`]) rather than 32 rows at a time on one thread: when it has more than one block
/// of rows to spread over the pool.
pub(crate) fn packs_left_whole(rows: usize) -> bool {
    rows > BLOCK
}

/// A pointer into data that outlives a parallel loop and is only read in it.
#[derive(Clone, Copy)]
struct SendPtr(*const u32);

impl SendPtr {
    /// The pointer (a method, so a closure captures the `Sync` wrapper, not its field).
    fn get(self) -> *const u32 {
        self.0
    }
}
// SAFETY: the pointee is read-only for the loop's duration (it is borrowed immutably around it).
unsafe impl Send for SendPtr {}
// SAFETY: as above.
unsafe impl Sync for SendPtr {}

/// Rows `i0 .. i0 + rows` of `a` into `left`: 32 rows of `left.len() / 32` words, word `(r, q)` the
/// pair `(a[i0 + r][2q], a[i0 + r][2q + 1])`, zeros in the padding. Row-major `a` is paired along
/// its rows; other layouts 16 × 16 words at a time, transposed in registers.
///
/// # Safety
/// The CPU must have AVX-512F.
#[cfg_attr(target_arch = "x86_64", target_feature(enable = "avx512f"))]
unsafe fn pack_left(left: &mut [u32], a: MatRef<'_>, i0: usize, rows: usize) {
    let (k, half) = (a.cols, left.len() / BLOCK);
    let full_pairs = k / 2;
    if a.col_stride == 1 {
        for r in 0..rows {
            let s = a.offset(i0 + r, 0);
            let src = &a.data[s..s + k];
            let dst = &mut left[r * half..(r + 1) * half];
            pairs_of_row(&mut dst[..full_pairs], &src[..2 * full_pairs]);
            if k % 2 == 1 {
                dst[full_pairs] = pair(src[k - 1], 0.0);
            }
            dst[k.div_ceil(2)..].fill(0);
        }
        left[rows * half..].fill(0);
    } else {
        let mut block = [0u32; 256];
        for r0 in (0..BLOCK).step_by(16) {
            for q0 in (0..half).step_by(16) {
                // SAFETY: AVX-512F (the caller's); rows r0..r0 + 16 of `left` hold `half ≥ q0 + 16`.
                unsafe {
                    pairs_down(&mut block, a.row_range(i0, rows).t(), 2 * q0, r0);
                    transpose16(&block, left[r0 * half + q0..].as_mut_ptr(), half);
                }
            }
        }
    }
}

/// Writes the transpose of the 16 × 16 words `block` (row-major) to `dst`, rows `stride` words
/// apart: `dst[r · stride + c] = block[c · 16 + r]`.
///
/// # Safety
/// The CPU must have AVX-512F, and `dst` must be valid for 16 rows of 16 words at `stride`.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
unsafe fn transpose16(block: &[u32; 256], dst: *mut u32, stride: usize) {
    use std::arch::x86_64::*;
    // SAFETY: the loads read inside `block`, the stores write the 16 rows the caller vouches for.
    unsafe {
        let mut r: [__m512i; 16] =
            std::array::from_fn(|i| _mm512_loadu_si512(block.as_ptr().add(16 * i).cast()));
        let mut t = [_mm512_setzero_si512(); 16];
        // 2 × 2 blocks of words, then of word pairs (within 128-bit lanes), then of lanes.
        for i in 0..8 {
            t[2 * i] = _mm512_unpacklo_epi32(r[2 * i], r[2 * i + 1]);
            t[2 * i + 1] = _mm512_unpackhi_epi32(r[2 * i], r[2 * i + 1]);
        }
        for i in 0..4 {
            let b = 4 * i;
            r[b] = _mm512_unpacklo_epi64(t[b], t[b + 2]);
            r[b + 1] = _mm512_unpackhi_epi64(t[b], t[b + 2]);
            r[b + 2] = _mm512_unpacklo_epi64(t[b + 1], t[b + 3]);
            r[b + 3] = _mm512_unpackhi_epi64(t[b + 1], t[b + 3]);
        }
        for h in 0..2 {
            let b = 8 * h;
            for j in 0..4 {
                t[b + j] = _mm512_shuffle_i32x4::<0x88>(r[b + j], r[b + j + 4]);
                t[b + j + 4] = _mm512_shuffle_i32x4::<0xdd>(r[b + j], r[b + j + 4]);
            }
        }
        for j in 0..8 {
            r[j] = _mm512_shuffle_i32x4::<0x88>(t[j], t[j + 8]);
            r[j + 8] = _mm512_shuffle_i32x4::<0xdd>(t[j], t[j + 8]);
        }
        for (i, row) in r.iter().enumerate() {
            _mm512_storeu_si512(dst.add(i * stride).cast(), *row);
        }
    }
}

#[cfg(not(target_arch = "x86_64"))]
unsafe fn transpose16(block: &[u32; 256], dst: *mut u32, stride: usize) {
    for r in 0..16 {
        for c in 0..16 {
            unsafe { *dst.add(r * stride + c) = block[c * 16 + r] };
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kernels::gemm;
    use crate::shape::Shape;

    fn lcg(seed: u64, n: usize, scale: f32) -> Vec<f32> {
        let mut s = seed;
        (0..n)
            .map(|_| {
                s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                ((s >> 40) as f32 / (1u64 << 24) as f32 - 0.5) * scale
            })
            .collect()
    }

    #[test]
    fn rounding_is_to_nearest_even_and_keeps_bf16_values() {
        assert_eq!(to_bf16(1.0), 0x3f80);
        assert_eq!(to_bf16(-2.5), 0xc020);
        // 1 + 2^-8 lies halfway between 1 and 1 + 2^-7: ties go to the even (1.0).
        assert_eq!(to_bf16(f32::from_bits(0x3f80_8000)), 0x3f80);
        // 1 + 3·2^-8 lies halfway between 1 + 2^-7 (odd) and 1 + 2^-6: up to the even.
        assert_eq!(to_bf16(f32::from_bits(0x3f81_8000)), 0x3f82);
        assert_eq!(to_bf16(f32::from_bits(0x3f80_8001)), 0x3f81);
        assert!(f32::from_bits((to_bf16(f32::NAN) as u32) << 16).is_nan());
        assert_eq!(to_bf16(f32::INFINITY), 0x7f80);
        assert_eq!(pair(1.0, -2.5), 0xc020_3f80);
    }

    #[test]
    fn a_block_of_words_is_transposed() {
        if !bf16_matmul_available() {
            return;
        }
        let block: [u32; 256] = std::array::from_fn(|i| i as u32);
        let mut out = vec![0u32; 16 * 20];
        // SAFETY: AVX-512F is present where a bf16 kernel is; `out` holds 16 rows of 20 words.
        unsafe { transpose16(&block, out.as_mut_ptr(), 20) };
        for r in 0..16 {
            for c in 0..16 {
                assert_eq!(out[r * 20 + c], (c * 16 + r) as u32, "({r}, {c})");
            }
            assert!(out[r * 20 + 16..r * 20 + 20].iter().all(|&w| w == 0));
        }
    }

    /// Products of small integers are exact in bf16 and in f32: every kernel must give the f32
    /// product bit for bit, whatever the shape's padding (odd sizes), the transposes, and with
    /// accumulation.
    #[test]
    fn exact_inputs_give_the_f32_product_bit_for_bit() {
        if !bf16_matmul_available() {
            eprintln!("no AMX or AVX-512 BF16 on this machine: no bf16 kernel is exercised");
            return;
        }
        for kernel in kernels_here() {
            exact_inputs_on(kernel);
        }
    }

    fn exact_inputs_on(kernel: Bf16Kernel) {
        for &(m, k, n) in
            &[(1, 16, 16), (33, 47, 17), (64, 64, 64), (64, 200, 48), (100, 300, 70), (5, 1000, 40)]
        {
            let ints = |seed, len| lcg(seed, len, 16.0).into_iter().map(f32::round).collect::<Vec<f32>>();
            let (a, b, c0) = (ints(1, m * k), ints(2, k * n), ints(3, m * n));
            for (ta, tb) in [(false, false), (true, false), (false, true)] {
                let (sa, sb) = (
                    if ta { Shape::new(k, m) } else { Shape::new(m, k) },
                    if tb { Shape::new(n, k) } else { Shape::new(k, n) },
                );
                let av = MatRef::new(&a, sa).maybe_t(ta);
                let bv = MatRef::new(&b, sb).maybe_t(tb);
                for accumulate in [false, true] {
                    // A dropped factor of the same padded size, all words NaN, leaves its
                    // buffer for the next: the padding must be written (0 · NaN is NaN).
                    let (kp, np) = (k.next_multiple_of(INNER), n.next_multiple_of(BLOCK));
                    drop(PackedRight::new(MatRef::new(&vec![f32::NAN; kp * np], Shape::new(kp, np))));
                    let (mut want, mut got) = (c0.clone(), c0.clone());
                    gemm(&mut want, av, bv, accumulate);
                    gemm_bf16_on(kernel, &mut got, av, &PackedRight::new(bv), accumulate);
                    assert_eq!(got, want, "{kernel:?} {m}×{k}×{n} ta {ta} tb {tb} accumulate {accumulate}");
                }
            }
        }
    }

    /// General inputs: within bf16's rounding of the factors (relative 2^-8 each), and the same
    /// bits computed whole, in row blocks, and on one thread or many, on every kernel.
    #[test]
    fn general_inputs_are_close_and_do_not_depend_on_the_split() {
        if !bf16_matmul_available() {
            eprintln!("no AMX or AVX-512 BF16 on this machine: no bf16 kernel is exercised");
            return;
        }
        for kernel in kernels_here() {
            general_inputs_on(kernel);
        }
    }

    fn general_inputs_on(kernel: Bf16Kernel) {
        let (m, k, n) = (300, 256, 96);
        let (a, b) = (lcg(4, m * k, 2.0), lcg(5, k * n, 2.0));
        let (av, bv) = (MatRef::new(&a, Shape::new(m, k)), MatRef::new(&b, Shape::new(k, n)));
        let mut want = vec![0.0; m * n];
        gemm(&mut want, av, bv, false);
        let packed = PackedRight::new(bv);
        let mut whole = vec![0.0; m * n];
        gemm_bf16_on(kernel, &mut whole, av, &packed, false);
        // |error| ≤ Σ |a||b| · 2 · 2^-8 (each factor's rounding), with room for the f32 sums.
        for i in 0..m {
            for j in 0..n {
                let bound: f32 =
                    (0..k).map(|kk| (a[i * k + kk] * b[kk * n + j]).abs()).sum::<f32>() * 2.0 / 256.0;
                let (w, g) = (want[i * n + j], whole[i * n + j]);
                assert!(
                    (w - g).abs() <= bound * 1.01 + 1e-6,
                    "{kernel:?} ({i},{j}): {g} vs {w}, bound {bound}"
                );
            }
        }
        let mut blocks = vec![0.0; m * n];
        for start in (0..m).step_by(70) {
            let rows = 70.min(m - start);
            let block = &mut blocks[start * n..(start + rows) * n];
            gemm_rows(block, av.row_range(start, rows), &packed, false, None, kernel);
        }
        assert_eq!(blocks, whole, "{kernel:?}");
        let one = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
        let mut single = vec![0.0; m * n];
        one.install(|| gemm_bf16_on(kernel, &mut single, av, &packed, false));
        assert_eq!(single, whole, "{kernel:?}");
    }

    /// `xᵀ` packed block by block while `x·W` is multiplied (as a layer's forward packs it, into
    /// a buffer of stale words) is the factor packed whole from `xᵀ` and gives the same product;
    /// the product `x·W` is unchanged by the packing beside it.
    #[test]
    fn xt_packed_by_row_blocks_is_xt_packed_whole() {
        if !bf16_matmul_available() {
            eprintln!("no AMX or AVX-512 BF16 on this machine: no bf16 kernel is exercised");
            return;
        }
        for &(rows, cols, n, block) in &[(1100, 40, 24, 256), (300, 100, 33, 64), (64, 33, 16, 32)] {
            let (x, dz, w) = (lcg(6, rows * cols, 2.0), lcg(7, rows * n, 2.0), lcg(8, cols * n, 2.0));
            let xv = MatRef::new(&x, Shape::new(rows, cols));
            let dz = PackedRight::new(MatRef::new(&dz, Shape::new(rows, n)));
            let w = PackedRight::new(MatRef::new(&w, Shape::new(cols, n)));
            let mut stale = LineBuf::zeroed(PackedLeft::words(cols, rows));
            stale.fill(0x7fc0_7fc0); // bf16 NaNs: a word left unwritten would poison a product
            let mut by_blocks = PackedLeft::for_transpose(cols, rows, stale);
            let (mut xw, mut xw_alone) = (vec![0.0; rows * n], vec![0.0; rows * n]);
            let starts = (0..rows).step_by(block);
            for ((words, row_tiles), start) in by_blocks.transpose_blocks(block).zip(starts) {
                let r = block.min(rows - start);
                let dst = &mut xw[start * n..(start + r) * n];
                gemm_bf16_single_thread_packing_xt(dst, xv.row_range(start, r), &w, false, words, row_tiles);
            }
            gemm_bf16(&mut xw_alone, xv, &w, false);
            assert_eq!(xw, xw_alone, "{rows}×{cols}: the product changed");
            // SAFETY: AVX-512F is present where a bf16 kernel is.
            let whole = unsafe { PackedLeft::new(xv.t(), rows.next_multiple_of(INNER)) };
            assert!(by_blocks.data[..] == whole.data[..], "{rows}×{cols} in blocks of {block}");
            let (mut want, mut got) = (vec![1.0; cols * n], vec![1.0; cols * n]);
            gemm_bf16(&mut want, xv.t(), &dz, true);
            gemm_bf16_packed_left(&mut got, &by_blocks, &dz, true);
            assert_eq!(got, want);
        }
    }
}

//! The AVX-512 BF16 kernel of [`super`]: one row of 32 × 32 output blocks by `VDPBF16PS`, for
//! CPUs that have the instruction but no AMX tiles (AMD Zen 4 and later, Intel Cooper Lake).
//!
//! `VDPBF16PS` adds to each of 16 f32 lanes the products of one pair of bf16 values from each
//! operand: lane `j` of `acc += a · b` gains `a[2j]·b[2j] + a[2j+1]·b[2j+1]`. With one
//! operand the left factor's pair `(A[r][2q], A[r][2q+1])` broadcast to every lane and the
//! other 16 words of [`PackedRight`]'s row `q` (the pairs `(B[2q][j], B[2q+1][j])`, the VNNI
//! layout the tiles read), lane `j` gains row `r`'s contribution of inner pair `q` to
//! `C[r][j]`. So the kernel reads exactly the packed factors the tiles do, and only the inner
//! loop differs.
//!
//! Register block: 8 rows × 32 columns in 16 accumulators, two right rows and one broadcast
//! word per row at each inner pair (16 independent sums cover the instruction's latency on
//! two pipes). Each output element's sum runs over the inner pairs in increasing order, its
//! own accumulator from zero, whatever the block's rows and the thread: the same bits for
//! any split of the rows ([`super`]'s determinism). With `accumulate` the finished sum is
//! added to the destination once (`dst + A·B`), as on the tiles.

use super::{BLOCK, INNER, LeftTiles, PackedRight};

/// Rows of one register block (a 32-row block row is four of them).
const ROWS: usize = 8;

/// Whether this CPU has `VDPBF16PS` on 512-bit registers (and the AVX-512F the packing runs
/// on).
pub(super) fn available() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::arch::is_x86_feature_detected!("avx512f") && std::arch::is_x86_feature_detected!("avx512bf16")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// One row of 32×32 output blocks: `dst` (`rows` × `b.n`, `rows ≤ 32`) from the left pairs `a`
/// and `b` (module docs).
///
/// # Safety
/// The CPU must have AVX-512F and AVX-512 BF16 ([`available`]); `a` must address 32 rows of
/// `b.kp / 2` words in its layout (rows past `rows` included: they are read, not stored), and
/// `dst` hold `rows × b.n` values.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx512bf16")]
pub(super) unsafe fn block_row(
    dst: &mut [f32],
    rows: usize,
    a: LeftTiles,
    b: &PackedRight,
    accumulate: bool,
) {
    use std::arch::x86_64::*;
    let (n, np, kp) = (b.n, b.np, b.kp);
    debug_assert!(rows <= BLOCK && dst.len() == rows * n && b.data.len() == kp / 2 * np);
    let row_words = a.stride as usize / 4;
    for j0 in (0..n).step_by(BLOCK) {
        let cols = BLOCK.min(n - j0);
        let masks = [lanes(cols), lanes(cols.saturating_sub(16))];
        // SAFETY: `j0 + 32 ≤ np`, so every right row read below holds the 32 words from `j0`.
        let right = unsafe { b.data.as_ptr().add(j0) };
        for r0 in (0..rows).step_by(ROWS) {
            // SAFETY: rows `r0 .. r0 + 8` lie in one 16-row half (`r0` is a multiple of 8), whose
            // rows the caller's layout puts `row_words` words apart.
            let first = unsafe { a.base.add((r0 / 16) * a.half_step + (r0 % 16) * row_words) };
            let mut acc = [[_mm512_setzero_ps(); 2]; ROWS];
            for qb in 0..kp / INNER {
                // SAFETY: inner block `qb < kp / 32` of the left rows and of the right factor.
                let (left, b_rows) = unsafe { (first.add(qb * a.q_step), right.add(qb * 16 * np)) };
                for q in 0..16 {
                    // SAFETY: right word row `16 qb + q < kp / 2`, 32 words from `j0`; left word
                    // `(r, 16 qb + q)` of the caller's 32 rows.
                    unsafe {
                        let b0: __m512bh = std::mem::transmute(_mm512_loadu_si512(b_rows.add(q * np).cast()));
                        let b1: __m512bh =
                            std::mem::transmute(_mm512_loadu_si512(b_rows.add(q * np + 16).cast()));
                        for (r, acc) in acc.iter_mut().enumerate() {
                            let pair: __m512bh =
                                std::mem::transmute(_mm512_set1_epi32(*left.add(r * row_words + q) as i32));
                            acc[0] = _mm512_dpbf16_ps(acc[0], pair, b0);
                            acc[1] = _mm512_dpbf16_ps(acc[1], pair, b1);
                        }
                    }
                }
            }
            for (r, acc) in acc.iter().enumerate().take(rows - r0) {
                for (h, (&sum, &mask)) in acc.iter().zip(&masks).enumerate() {
                    // SAFETY: row `r0 + r < rows` of `dst`, columns `j0 + 16h ..` under `mask`
                    // (inside the row's `cols`); masked lanes are neither read nor written.
                    unsafe {
                        let d = dst.as_mut_ptr().add((r0 + r) * n + j0 + 16 * h);
                        let value =
                            if accumulate { _mm512_add_ps(_mm512_maskz_loadu_ps(mask, d), sum) } else { sum };
                        _mm512_mask_storeu_ps(d, mask, value);
                    }
                }
            }
        }
    }
}

#[cfg(not(target_arch = "x86_64"))]
pub(super) unsafe fn block_row(_: &mut [f32], _: usize, _: LeftTiles, _: &PackedRight, _: bool) {
    unreachable!("no AVX-512 BF16 off x86-64")
}

/// The lane mask of the first `count` of 16 lanes (all of them from 16 on).
#[inline(always)]
fn lanes(count: usize) -> u16 {
    if count >= 16 { u16::MAX } else { (1u16 << count) - 1 }
}

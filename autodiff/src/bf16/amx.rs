//! The AMX tile kernel of [`super`]: one row of 32 × 32 output blocks by `TDPBF16PS`, four
//! accumulator tiles at a time (Intel Xeon, Sapphire Rapids and later).

use super::{BLOCK, INNER, LeftTiles, PackedRight};

/// A 32 × 32 output block on whole cache lines (tile stores, [`crate::lines`]).
#[repr(C, align(64))]
struct OutBlock([f32; BLOCK * BLOCK]);

/// The 64-byte tile configuration: palette 1, eight tiles of 16 rows × 64 bytes.
#[repr(C, align(64))]
struct TileConfig([u8; 64]);

const TILE_CONFIG: TileConfig = {
    let mut c = [0u8; 64];
    c[0] = 1; // palette
    let mut t = 0;
    while t < 8 {
        c[16 + 2 * t] = 64; // bytes per row (low byte of the u16 `colsb`)
        c[48 + t] = 16; // rows
        t += 1;
    }
    TileConfig(c)
};

/// One row of 32×32 output blocks: `dst` (`rows` × `b.n`) from the left tiles `a` and `b`.
///
/// # Safety
/// The tile state must have been granted ([`granted`]), `a` must address 2 row
/// halves × `b.kp / 32` tiles of 16 rows of 64 bytes, and `dst` hold `rows × b.n` values.
#[cfg(target_arch = "x86_64")]
pub(super) unsafe fn block_row(
    dst: &mut [f32],
    rows: usize,
    a: LeftTiles,
    b: &PackedRight,
    accumulate: bool,
) {
    use std::arch::asm;
    let (n, np, kp) = (b.n, b.np, b.kp);
    debug_assert!(dst.len() == rows * n && b.data.len() == kp / 2 * np);
    let mut out = OutBlock([0f32; BLOCK * BLOCK]);
    let out = &mut out.0;
    let (b_stride, out_stride) = ((np * 4) as isize, (BLOCK * 4) as isize);
    // SAFETY (for every asm block below): the configuration is a valid palette-1 layout; every
    // tile load reads 16 rows of 64 bytes: a left tile the caller vouches for, or 16 word rows of
    // `b` from row `qb · 16`, columns `j0 .. j0 + 32` (inside: `kp / 2` rows of `np ≥ j0 + 32`
    // words); every store writes 16 rows of 64 bytes inside `out` or, for a whole block (32
    // rows, 32 columns from `j0`), inside `dst`'s rows; the tiles are released before returning.
    unsafe {
        asm!("ldtilecfg [{}]", in(reg) TILE_CONFIG.0.as_ptr(), options(nostack, readonly));
        for j0 in (0..n).step_by(BLOCK) {
            asm!("tilezero tmm0", "tilezero tmm1", "tilezero tmm2", "tilezero tmm3", options(nostack, nomem));
            let right = b.data.as_ptr().add(j0);
            for qb in 0..kp / INNER {
                let a0 = a.base.add(qb * a.q_step);
                let b0 = right.add(qb * 16 * np);
                asm!(
                    "tileloadd tmm4, [{a0} + {sa}*1]",
                    "tileloadd tmm5, [{a1} + {sa}*1]",
                    "tileloadd tmm6, [{b0} + {sb}*1]",
                    "tileloadd tmm7, [{b1} + {sb}*1]",
                    "tdpbf16ps tmm0, tmm4, tmm6",
                    "tdpbf16ps tmm1, tmm4, tmm7",
                    "tdpbf16ps tmm2, tmm5, tmm6",
                    "tdpbf16ps tmm3, tmm5, tmm7",
                    a0 = in(reg) a0,
                    a1 = in(reg) a0.add(a.half_step),
                    b0 = in(reg) b0,
                    b1 = in(reg) b0.add(16),
                    sa = in(reg) a.stride,
                    sb = in(reg) b_stride,
                    options(nostack, readonly),
                );
            }
            let cols = BLOCK.min(n - j0);
            // A whole block that replaces its destination is stored there directly.
            let direct = !accumulate && rows == BLOCK && cols == BLOCK;
            let (o, s) = if direct {
                (dst.as_mut_ptr().add(j0), (n * 4) as isize)
            } else {
                (out.as_mut_ptr(), out_stride)
            };
            let row_16 = if direct { 16 * n } else { 16 * BLOCK };
            asm!(
                "tilestored [{o0} + {s}*1], tmm0",
                "tilestored [{o1} + {s}*1], tmm1",
                "tilestored [{o2} + {s}*1], tmm2",
                "tilestored [{o3} + {s}*1], tmm3",
                o0 = in(reg) o,
                o1 = in(reg) o.add(16),
                o2 = in(reg) o.add(row_16),
                o3 = in(reg) o.add(row_16 + 16),
                s = in(reg) s,
                options(nostack),
            );
            if direct {
                continue;
            }
            for r in 0..rows {
                let d = &mut dst[r * n + j0..r * n + j0 + cols];
                let src = &out[r * BLOCK..r * BLOCK + cols];
                if accumulate {
                    d.iter_mut().zip(src).for_each(|(d, &s)| *d += s);
                } else {
                    d.copy_from_slice(src);
                }
            }
        }
        asm!("tilerelease", options(nostack, nomem));
    }
}

#[cfg(not(target_arch = "x86_64"))]
pub(super) unsafe fn block_row(_: &mut [f32], _: usize, _: LeftTiles, _: &PackedRight, _: bool) {
    unreachable!("no AMX off x86-64")
}

/// Whether this process may run tile instructions: the CPU has AMX-TILE and AMX-BF16 (and the
/// AVX-512F the packing runs on) and Linux granted the tile state. Linux gives a process the AMX
/// state only after it asks (`arch_prctl(ARCH_REQ_XCOMP_PERM, XFEATURE_XTILEDATA)`); a tile
/// instruction without it is a SIGILL, so every use is behind this answer.
#[cfg(all(target_arch = "x86_64", target_os = "linux"))]
pub(super) fn granted() -> bool {
    // CPUID leaf 7, sub-leaf 0: EDX bit 22 AMX-BF16, bit 24 AMX-TILE.
    let leaf7 = std::arch::x86_64::__cpuid_count(7, 0);
    let has_amx = leaf7.edx & (1 << 22) != 0 && leaf7.edx & (1 << 24) != 0;
    // The packing runs on AVX-512F, which every CPU with AMX has; checked all the same.
    if !has_amx || !std::arch::is_x86_feature_detected!("avx512f") {
        return false;
    }
    const ARCH_REQ_XCOMP_PERM: libc::c_long = 0x1023;
    const XFEATURE_XTILEDATA: libc::c_long = 18;
    // SAFETY: a plain system call with integer arguments; it changes only this process's permitted
    // extended state (it fails, returning -1, on kernels without AMX support).
    unsafe { libc::syscall(libc::SYS_arch_prctl, ARCH_REQ_XCOMP_PERM, XFEATURE_XTILEDATA) == 0 }
}

#[cfg(not(all(target_arch = "x86_64", target_os = "linux")))]
pub(super) fn granted() -> bool {
    false
}

//! The Cortex-M4/M7 DSP kernels (thumbv7em): the three DSP instructions
//! as register-only inline assembly (stable Rust has no ARM DSP
//! intrinsics) and the hand-scheduled loops built on them.

use core::arch::asm;

/// Rows per group of the encoder kernel ([`dot4`]).
pub const QUAD: usize = 4;

/// Sign-extends bytes 0 and 2 into two 16-bit halves.
#[inline(always)]
pub fn sxtb16(x: u32) -> u32 {
    let r;
    // SAFETY: register-only arithmetic, no memory or flags touched.
    unsafe {
        asm!("sxtb16 {0}, {1}", out(reg) r, in(reg) x, options(pure, nomem, nostack, preserves_flags))
    };
    r
}

/// Sign-extends bytes 1 and 3 into two 16-bit halves.
#[inline(always)]
pub fn sxtb16_ror8(x: u32) -> u32 {
    let r;
    // SAFETY: register-only arithmetic, no memory or flags touched.
    unsafe {
        asm!("sxtb16 {0}, {1}, ror #8", out(reg) r, in(reg) x, options(pure, nomem, nostack, preserves_flags))
    };
    r
}

/// `acc + a.lo * b.lo + a.hi * b.hi` (16-bit halves, signed).
#[inline(always)]
pub fn smlad(a: u32, b: u32, acc: i32) -> i32 {
    let r;
    // SAFETY: register-only arithmetic; SMLAD may set the sticky Q flag,
    // which nothing reads (and which cannot be set here, see `dot`).
    unsafe {
        asm!("smlad {0}, {1}, {2}, {3}", out(reg) r, in(reg) a, in(reg) b, in(reg) acc, options(pure, nomem, nostack))
    };
    r
}

/// `a.lo - b.lo` and `a.hi - b.hi` (16-bit halves, wrapping): exact for
/// differences within `i16`.
#[inline(always)]
pub fn ssub16(a: u32, b: u32) -> u32 {
    let r;
    // SAFETY: register-only arithmetic; SSUB16 sets the GE flags, which
    // nothing reads (no `preserves_flags`).
    unsafe {
        asm!("ssub16 {0}, {1}, {2}", out(reg) r, in(reg) a, in(reg) b, options(pure, nomem, nostack))
    };
    r
}

/// `a.lo * b.lo + a.hi * b.hi` (16-bit halves, signed; wrapping).
#[inline(always)]
pub fn smuad(a: u32, b: u32) -> i32 {
    let r;
    // SAFETY: register-only arithmetic; SMUAD may set the sticky Q flag,
    // which nothing reads.
    unsafe {
        asm!("smuad {0}, {1}, {2}", out(reg) r, in(reg) a, in(reg) b, options(pure, nomem, nostack))
    };
    r
}

/// Expands four rows of `inputs` int8 activations (`inputs % 4 == 0`)
/// into int16 pairs in the order [`dot4`] reads them: for every group
/// of four inputs `x[4g..4g+4]`, for each row in turn, the word
/// `(x[4g], x[4g+2])` then `(x[4g+1], x[4g+3])` (low half first), the
/// same pairing `SXTB16` and `SXTB16 ror #8` make of a weight word.
#[inline(always)]
pub fn expand_quad(rows: &[i8], inputs: usize, out: &mut [u32]) {
    let groups = inputs / 4;
    for (r, row) in super::rows(rows, inputs).take(QUAD).enumerate() {
        for (g, x) in row.as_chunks::<4>().0.iter().take(groups).enumerate() {
            let v = u32::from_le_bytes(x.map(|b| b as u8));
            let at = 2 * (QUAD * g + r);
            if let Some(pair) = out.get_mut(at..at + 2) {
                pair[0] = sxtb16(v);
                pair[1] = sxtb16_ror8(v);
            }
        }
    }
}

/// The loop both kernels run around their group body (a macro giving
/// the assembly of one group): the `{n} % 4` odd groups first (one,
/// then two), then four groups a turn, counting `{n}` down; `{n}` must
/// be at least 1. Four groups a turn make the `SUBS`/`BNE` cost 1/32
/// instruction per MAC.
macro_rules! groups_unrolled_4 {
    ($group:ident) => {
        concat!(
            "tst {n}, #1\n",
            "beq 2f\n",
            $group!(),
            "2:\n",
            "tst {n}, #2\n",
            "beq 3f\n",
            $group!(),
            $group!(),
            "3:\n",
            "lsrs {n}, {n}, #2\n",
            "beq 5f\n",
            "4:\n",
            $group!(),
            $group!(),
            $group!(),
            $group!(),
            "subs {n}, {n}, #1\n",
            "bne 4b\n",
            "5:\n",
        )
    };
}

/// One group of [`dot4`]: four inputs of four rows.
macro_rules! dot4_group {
    () => {
        concat!(
            "ldr {w}, [{wp}], #4\n",
            "sxtb16 {we}, {w}\n",
            "sxtb16 {w}, {w}, ror #8\n",
            "ldm {ap}!, {{r8, r9, r10, r11}}\n",
            "smlad {c0}, {we}, r8, {c0}\n",
            "smlad {c0}, {w}, r9, {c0}\n",
            "smlad {c1}, {we}, r10, {c1}\n",
            "smlad {c1}, {w}, r11, {c1}\n",
            "ldm {ap}!, {{r8, r9, r10, r11}}\n",
            "smlad {c2}, {we}, r8, {c2}\n",
            "smlad {c2}, {w}, r9, {c2}\n",
            "smlad {c3}, {we}, r10, {c3}\n",
            "smlad {c3}, {w}, r11, {c3}\n",
        )
    };
}

/// One group of [`dot_rows4`]: four inputs of four rows.
macro_rules! rows4_group {
    () => {
        concat!(
            "ldrd {ae}, {ao}, [{ap}], #8\n",
            "ldr {w}, [{r0}, {s}]\n",
            "sxtb16 {we}, {w}\n",
            "sxtb16 {w}, {w}, ror #8\n",
            "smlad {c1}, {we}, {ae}, {c1}\n",
            "smlad {c1}, {w}, {ao}, {c1}\n",
            "ldr {w}, [{r0}], #4\n",
            "sxtb16 {we}, {w}\n",
            "sxtb16 {w}, {w}, ror #8\n",
            "smlad {c0}, {we}, {ae}, {c0}\n",
            "smlad {c0}, {w}, {ao}, {c0}\n",
            "ldr {w}, [{r2}, {s}]\n",
            "sxtb16 {we}, {w}\n",
            "sxtb16 {w}, {w}, ror #8\n",
            "smlad {c3}, {we}, {ae}, {c3}\n",
            "smlad {c3}, {w}, {ao}, {c3}\n",
            "ldr {w}, [{r2}], #4\n",
            "sxtb16 {we}, {w}\n",
            "sxtb16 {w}, {w}, ror #8\n",
            "smlad {c2}, {we}, {ae}, {c2}\n",
            "smlad {c2}, {w}, {ao}, {c2}\n",
        )
    };
}

/// `init` plus four dot products of one int8 weight row with four rows'
/// expanded activations ([`expand_quad`]), over `min(w.len() / 4,
/// acts.len() / 8)` groups of four inputs (the bias rides in as `init`).
///
/// Register plan, per group (13 instructions for 16 MACs, and a
/// `SUBS`/`BNE` every four groups: 0.84 instructions per MAC):
/// `LDR` the weight word (post-increment), `SXTB16` it into the even
/// pair `we` and, rotated, the odd pair `w`; `LDM` the first two rows'
/// four activation words into r8-r11 (LDM fills ascending registers from
/// ascending addresses, so the list is fixed), two `SMLAD` per row into
/// `c0`, `c1`; the same for rows 3 and 4 into `c2`, `c3`.
/// Nine registers besides r8-r11: the allocator has r0-r6, r12 and lr.
#[inline(always)]
pub fn dot4(w: &[u8], acts: &[u32], init: i32) -> [i32; 4] {
    let groups = (w.len() / 4).min(acts.len() / (2 * QUAD));
    let (mut c0, mut c1, mut c2, mut c3) = (init, init, init, init);
    if groups == 0 {
        return [init; 4];
    }
    // SAFETY: `groups >= 1` groups run (`groups % 4`, then fours); each
    // reads 4 bytes at `wp` and 32 bytes at `ap`, and both slices hold
    // at least `groups` such blocks (checked above). `acts` is a `u32` slice, so
    // `ap` is 4-byte aligned as LDM requires; `LDR` allows any alignment
    // on ARMv7E-M. Nothing is written; the flags are clobbered (SUBS).
    unsafe {
        asm!(
            groups_unrolled_4!(dot4_group),
            wp = inout(reg) w.as_ptr() => _,
            ap = inout(reg) acts.as_ptr() => _,
            n = inout(reg) groups => _,
            w = out(reg) _,
            we = out(reg) _,
            c0 = inout(reg) c0,
            c1 = inout(reg) c1,
            c2 = inout(reg) c2,
            c3 = inout(reg) c3,
            out("r8") _,
            out("r9") _,
            out("r10") _,
            out("r11") _,
            options(nostack, readonly),
        );
    }
    [c0, c1, c2, c3]
}

/// Expands int8 values (as bytes, `len % 4 == 0`) to the int16 pairs
/// [`dot_rows4`] reads: per group of four, `(x0, x2)` then `(x1, x3)`.
#[inline(always)]
pub fn expand_vector(x: &[u8], out: &mut [u32]) {
    for (x, pair) in x.as_chunks::<4>().0.iter().zip(out.as_chunks_mut::<2>().0) {
        let v = u32::from_le_bytes(*x);
        *pair = [sxtb16(v), sxtb16_ror8(v)];
    }
}

/// `init[j]` plus the dot product of weight row `j` (rows `stride`
/// bytes apart in `w`) with the expanded vector `acts`
/// ([`expand_vector`]), for the four rows, over `min(stride, 2 x
/// acts.len()) / 4` groups of four inputs (none if `w` is shorter than
/// four rows).
///
/// Register plan, per group (21 instructions for 16 MACs, and a
/// `SUBS`/`BNE` every four groups: 1.34 instructions per MAC): `LDRD` the
/// group's two activation words; for each row, `LDR` its weight word,
/// `SXTB16` it into the even pair `we` and, rotated, the odd pair `w`,
/// and two `SMLAD`; `SUBS`/`BNE`. Rows 0 and 2 are addressed by `r0`
/// and `r2`, which advance 4 bytes a group; rows 1 and 3 at `+stride`
/// from them. Thirteen registers: all the allocator has.
#[inline(always)]
pub fn dot_rows4(w: &[u8], stride: usize, acts: &[u32], init: [i32; 4]) -> [i32; 4] {
    let groups = stride.min(2 * acts.len()) / 4;
    let [mut c0, mut c1, mut c2, mut c3] = init;
    if groups == 0 || w.len() < 4 * stride {
        return init;
    }
    // SAFETY: `groups >= 1` groups run (`groups % 4`, then fours); group
    // `g` reads the words at `4g` bytes into rows 0..4 (each `stride >= 4 * groups`
    // bytes long, all inside `w`, checked above) and 8 bytes at `8g`
    // into `acts` (`acts.len() >= 2 * groups` words). `acts` is a `u32`
    // slice, so LDRD's address is 4-byte aligned as it requires; `LDR`
    // allows any alignment on ARMv7E-M. Nothing is written; the flags
    // are clobbered (SUBS).
    unsafe {
        asm!(
            groups_unrolled_4!(rows4_group),
            r0 = inout(reg) w.as_ptr() => _,
            r2 = inout(reg) w.as_ptr().wrapping_add(2 * stride) => _,
            s = in(reg) stride,
            ap = inout(reg) acts.as_ptr() => _,
            n = inout(reg) groups => _,
            ae = out(reg) _,
            ao = out(reg) _,
            w = out(reg) _,
            we = out(reg) _,
            c0 = inout(reg) c0,
            c1 = inout(reg) c1,
            c2 = inout(reg) c2,
            c3 = inout(reg) c3,
            options(nostack, readonly),
        );
    }
    [c0, c1, c2, c3]
}

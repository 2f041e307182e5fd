//! Sizes read from a blob's bytes at compile time ([`scratch_len_for`]).
//!
//! Only the header and the architecture at the front of the payload are
//! decoded, with `const` code that follows postcard's rules (varints,
//! a length before each sequence), so a firmware sizes its `static`
//! scratch from the `include_bytes!` of its model instead of typing the
//! layer widths by hand.

use crate::arch::{MAX_LAYERS, MAX_TILE, int8_scratch_len};
use crate::format::{CRC_LEN, FORMAT_VERSION, HEADER_LEN, MAGIC, ModelKind, OLDEST_READABLE};

// The header pattern in `int8_payload` spells these bytes out one by one.
const _: () = assert!(HEADER_LEN == 11 && MAGIC.len() == 4);

/// Bytes of scratch an int8 model blob needs with `tile` points per pass,
/// read from the blob's own bytes in a `const`: the same figure as
/// [`Int8Model::scratch_len`](crate::Int8Model::scratch_len) of the loaded
/// model, which is all that [`Int8Model::register`](crate::Int8Model::register)
/// (network, flip resolution, ICP: refinement takes no scratch),
/// `network_pose`, `infer` and `encode` use at that tile. Given more, they
/// use the largest tile that fits; [`MAX_TILE`] is the fastest.
///
/// ```
/// use pcrnet_core::{Int8Model, MAX_TILE, Options, scratch_len_for};
///
/// // In firmware: `include_bytes!("model.pcrn")`, in flash.
/// # const MODEL: &[u8] = include_bytes!("../../models/embedded-default-int8.pcrn");
/// const SCRATCH: usize = scratch_len_for(MODEL, MAX_TILE).expect("not a pcrnet int8 blob");
///
/// # fn main() -> Result<(), pcrnet_core::Error> {
/// // In firmware: a `static mut [i8; SCRATCH]` (cortex-m-rt's `#[entry]`
/// // hands one to `main` as `&'static mut`).
/// let mut scratch = [0i8; SCRATCH];
/// let model = Int8Model::load(MODEL, &scratch)?;
/// assert_eq!(model.scratch_len(MAX_TILE), SCRATCH);
/// let source = [[0.1, 0.2, 0.3], [0.0, -0.1, 0.25], [-0.2, 0.05, 0.0]];
/// let result = model.register(&source, &Options::default(), &mut scratch)?;
/// # let _ = result;
/// # Ok(())
/// # }
/// ```
///
/// `None` when `tile` is outside `1..=MAX_TILE`, or when `blob` is not a
/// well-formed int8 blob as far as this reads: a wrong magic, format
/// version or kind (an f32 blob), a length other than the header's payload
/// length plus the header and the CRC (a truncated file), or an
/// architecture that does not decode or breaks [`Arch::validate`](crate::Arch::validate)'s
/// limits. In a `const`, `expect` on `None` stops the build.
///
/// It checks neither the CRC nor the rest of the payload:
/// [`Int8Model::load`](crate::Int8Model::load) does, at run time, and may
/// still reject a blob this sized.
pub const fn scratch_len_for(blob: &[u8], tile: usize) -> Option<usize> {
    if tile == 0 || tile > MAX_TILE {
        return None;
    }
    let Some(payload) = int8_payload(blob) else {
        return None;
    };
    // The payload starts with the `Arch`: the encoder's widths, then the head's.
    let Some((encoder, encoder_len, rest)) = widths(payload) else {
        return None;
    };
    let Some((head, head_len, _)) = widths(rest) else {
        return None;
    };
    if encoder_len == 0 {
        return None;
    }
    let (Some((encoder, _)), Some((head, _))) = (
        encoder.split_at_checked(encoder_len),
        head.split_at_checked(head_len),
    ) else {
        return None;
    };
    Some(int8_scratch_len(encoder, head, tile))
}

/// The payload of a blob whose header says int8, a format version this
/// build reads, and
/// a payload length that with the header and the CRC is the blob's length.
const fn int8_payload(blob: &[u8]) -> Option<&[u8]> {
    let [m0, m1, m2, m3, v0, v1, kind, p0, p1, p2, p3, rest @ ..] = blob else {
        return None;
    };
    if *m0 != MAGIC[0] || *m1 != MAGIC[1] || *m2 != MAGIC[2] || *m3 != MAGIC[3] {
        return None;
    }
    let version = u16::from_le_bytes([*v0, *v1]);
    if version < OLDEST_READABLE || version > FORMAT_VERSION || *kind != ModelKind::Int8 as u8 {
        return None;
    }
    let payload_len = u32::from_le_bytes([*p0, *p1, *p2, *p3]) as usize;
    match payload_len.checked_add(CRC_LEN) {
        Some(len) if len == rest.len() => match rest.split_at_checked(payload_len) {
            Some((payload, _)) => Some(payload),
            None => None,
        },
        _ => None,
    }
}

/// One `heapless::Vec<u16, MAX_LAYERS>` of layer widths as postcard
/// writes it (a varint length, then a varint per width): the widths (the
/// first `len` entries), `len` and the bytes after it. `None` if it does
/// not decode, holds more than [`MAX_LAYERS`] widths or a width of 0.
const fn widths(bytes: &[u8]) -> Option<([u16; MAX_LAYERS], usize, &[u8])> {
    let Some((len, mut rest)) = varint(bytes, usize::BITS) else {
        return None;
    };
    if len > MAX_LAYERS as u64 {
        return None;
    }
    let mut out = [0u16; MAX_LAYERS];
    let mut slots: &mut [u16] = &mut out;
    let mut left = len;
    while left > 0 {
        let Some((width, tail)) = varint(rest, u16::BITS) else {
            return None;
        };
        if width == 0 {
            return None;
        }
        // Moved out, then split: the next slot and the ones after it.
        let all = slots;
        let [slot, others @ ..] = all else {
            return None;
        };
        *slot = width as u16;
        slots = others;
        rest = tail;
        left -= 1;
    }
    Some((out, len as usize, rest))
}

/// A postcard varint of a `bits`-bit unsigned integer (LEB128, low group
/// first, at most `ceil(bits / 7)` bytes, the last one holding no bit
/// past the type's width), and the bytes after it.
const fn varint(bytes: &[u8], bits: u32) -> Option<(u64, &[u8])> {
    let most = bits.div_ceil(7);
    let last_max = (1u16 << (bits - 7 * (most - 1))) - 1;
    let mut value = 0u64;
    let mut rest = bytes;
    let mut i = 0;
    while i < most {
        let [byte, tail @ ..] = rest else {
            return None;
        };
        value |= ((*byte & 0x7F) as u64) << (7 * i);
        rest = tail;
        if *byte & 0x80 == 0 {
            if i == most - 1 && *byte as u16 > last_max {
                return None;
            }
            return Some((value, rest));
        }
        i += 1;
    }
    None
}

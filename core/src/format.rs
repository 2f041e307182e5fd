//! The model blob: a fixed header, a postcard payload and a CRC.
//!
//! ```text
//! offset  size  field
//! 0       4     magic  b"PCRN"
//! 4       2     format version, u16 little-endian (currently 7; 3 to 6 are read too)
//! 6       1     kind: 0 = int8 (device), 1 = f32 (host reference)
//! 7       4     payload length P, u32 little-endian
//! 11      P     payload: postcard encoding of Int8Payload or F32Payload,
//!               then (format 4) of Option<NearestTable>,
//!               then (format 5) of Option<LkSolver>,
//!               then (format 6) of Option<f32>, the residual floor,
//!               then (format 7) of Option<[f32; 3]>, the template's up axis
//! 11+P    4     CRC-32 (ISO-HDLC, as zlib) of bytes 0 .. 11+P, little-endian
//! ```
//!
//! Format 4 adds only the template's closest-point table after the payload
//! ([`NearestTable`]: a precomputed answer to the nearest-point search, which
//! makes ICP several times cheaper); a format-3 blob reads as one without a
//! table and gives the same results, more slowly. `pcrnet upgrade` adds the
//! table to a format-3 blob.
//!
//! Format 5 adds, after the table, PointNetLK's solver ([`LkSolver`]): the
//! template's side of the Lucas-Kanade step ([`crate::lk`]), for refining a
//! pose in feature space ([`crate::Options::lk_iterations`]). A blob of a
//! model trained as PointNetLK has it and no head (the payload's head and
//! output layer are empty). Blobs of formats 3 and 4 read as having none.
//!
//! Format 6 adds the template's residual floor ([`Trailer::residual_floor`]):
//! what a right pose scores beyond the noise because the stored points
//! cannot represent the object exactly, measured by the exporter; the
//! recommended options calibrate the verdict with it
//! ([`crate::registration::max_residual_for`]). Blobs of formats 3 to 5
//! read as having none.
//!
//! Format 7 adds the template's up axis ([`Trailer::up`]): the axis of the
//! object pointing away from the surface it rests on, given at export
//! (`pcrnet train --object FILE --up z`), so that finding the object
//! standing on a table in any yaw ([`crate::sweep`]) needs no more than the
//! blob (`Int8Model::scene_options`). Blobs of formats 3 to 6 read as
//! having none.
//!
//! The payload starts with the architecture ([`Arch`]), the template's
//! [`Frame`] and [`TemplateCloud`] and, for int8, the quantization
//! parameters, followed by the layers. Every multi-byte number
//! inside the weight arrays is little-endian and read with `from_le_bytes`,
//! so a blob needs **no alignment** and is used in place: the parsed model
//! borrows its weights from the blob (e.g. a `&'static [u8]` from
//! `include_bytes!` in flash) and nothing is copied into RAM.
//!
//! Checks happen in that order — magic, version, kind, length, CRC, payload
//! decoding, then dimensions and parameter ranges — so every corruption gives
//! the most specific [`Error`] available.

use serde::{Deserialize, Serialize};

use crate::arch::{Arch, MAX_LAYERS};
use crate::error::{Error, Result};
pub use crate::header::{FORMAT_VERSION, ModelKind, OLDEST_READABLE};

/// First four bytes of every blob.
pub const MAGIC: [u8; 4] = *b"PCRN";
/// Most symmetry turns a blob may store (so at most `1 + MAX_TURNS` hypotheses).
pub const MAX_TURNS: usize = 15;
/// Bytes before the payload.
pub const HEADER_LEN: usize = 11;
/// Bytes after the payload.
pub const CRC_LEN: usize = 4;

/// The CRC's lookup table: on a device one of 256 words (1 KB of flash),
/// a byte at a time; on a host (`std`) sixteen of them (16 KB), sixteen
/// bytes at a time, several times faster on the blobs a host checks and
/// writes for every bound template. The same checksum either way.
#[cfg(feature = "std")]
type CrcTable = crc::Table<16>;
#[cfg(not(feature = "std"))]
type CrcTable = crc::Table<1>;

/// CRC-32 (ISO-HDLC, as zlib) over a blob's header and payload.
static CRC32: crc::Crc<u32, CrcTable> = crc::Crc::<u32, CrcTable>::new(&crc::CRC_32_ISO_HDLC);

/// How the user's coordinates (the template file's and the sensor's units
/// and axes) map to the frame the network works in:
/// `p_model = scale * (p_user - centre)`.
///
/// The exporter takes `centre` = the template's centroid and `scale` =
/// `0.5 / max_k |p_k - centre_k|` over the template's points, so the
/// template fills `[-0.5, 0.5]^3` as the training shapes did. `pcrnet-core`
/// applies it to every source point and turns the network's pose back into
/// user units, so callers never see the model frame.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Frame {
    /// Where the model frame's origin lies, user units.
    pub centre: [f32; 3],
    /// Model units per user unit (finite, > 0).
    pub scale: f32,
}

impl Frame {
    /// The identity: model frame = user frame.
    pub const IDENTITY: Frame = Frame {
        centre: [0.0; 3],
        scale: 1.0,
    };
}

/// The template's points (subsampled), in the model frame, for checking
/// and refining a pose on the device, laid out for nearest-neighbour search.
///
/// - `points`: `M x 3` int16 little-endian, `p_model = q * step`, sorted
///   by grid cell (x slowest, z fastest);
/// - `normals`: `M x 3` int8, the surface normal at each point times 127
///   (rounded; sign arbitrary), in the same order, for point-to-plane
///   distances;
/// - the grid has `grid^3` cubic cells of `cell` int16 steps, its lowest
///   corner at `origin` (int16 steps); `cells` holds `grid^3 + 1` u16
///   little-endian offsets into the points: cell `c` holds points
///   `cells[c] .. cells[c + 1]`;
/// - `turns`: unit quaternions `[w, x, y, z]` in the model frame (half and
///   quarter turns about the template's principal axes through its
///   centroid), the extra starting poses tried by flip resolution.
///
/// Built by [`crate::template::build`]; checked by [`crate::template::Template::new`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TemplateCloud<'a> {
    /// Model units per int16 step.
    pub step: f32,
    /// Points, `M x 3` int16 little-endian, sorted by cell.
    pub points: &'a [u8],
    /// Unit normals times 127, `M x 3` int8, in the points' order.
    pub normals: &'a [u8],
    /// Cells per axis (1..=32).
    pub grid: u8,
    /// Lowest corner of the grid, int16 steps.
    pub origin: [i16; 3],
    /// Edge of a cell, int16 steps (>= 1).
    pub cell: u16,
    /// `grid^3 + 1` u16 little-endian offsets into the points.
    pub cells: &'a [u8],
    /// Symmetry turns (unit quaternions, model frame).
    pub turns: heapless::Vec<[f32; 4], MAX_TURNS>,
}

/// The template's closest-point table: for each cell of a box of cubic
/// cells around the template, the stored points that can be the nearest
/// to some place in the cell, so a search there scans a few points instead
/// of walking the grid ([`crate::template`]).
///
/// - cell `(i, j, k)` (x slowest, z fastest) covers int16 steps
///   `origin + (i, j, k) * edge ..= origin + (i, j, k) * edge + edge - 1`;
/// - `offsets`: `dims[0] * dims[1] * dims[2] + 1` u16 little-endian
///   offsets into `candidates`, counted in entries: cell `c` holds entries
///   `offsets[c] .. offsets[c + 1]`;
/// - `candidates`: u16 little-endian indices of template points (in the
///   blob's sorted order), ascending within a cell. A cell without entries
///   is not tabulated (its list would be too long): the grid search answers
///   there, as it does outside the box.
///
/// A point is left out of a cell only when another point is strictly
/// nearer to every place in the cell, so the table finds exactly the point
/// the grid search finds, ties included. Built by
/// [`crate::template::build_table`]; checked by
/// [`crate::template::Template::new`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct NearestTable<'a> {
    /// Lowest corner of the box, int16 steps.
    pub origin: [i16; 3],
    /// Edge of a cell, int16 steps (>= 1).
    pub edge: u16,
    /// Cells along x, y and z (each >= 1).
    pub dims: [u8; 3],
    /// `cells + 1` u16 little-endian offsets into `candidates` (entries).
    pub offsets: &'a [u8],
    /// u16 little-endian template point indices.
    pub candidates: &'a [u8],
}

/// PointNetLK's solver for the blob's template ([`crate::lk`]): the damped
/// pseudo-inverse `P = (J^T J + lambda I)^-1 J^T` of the template feature's
/// Jacobian `J` (`F x 6`, finite differences of step `jacobian_step` about
/// the template), so that a step's twist is `P r` for the feature
/// residual `r`.
///
/// In an int8 blob `r` is the int8 difference `q_S - q_T` and `J` is in
/// the same int8 steps, computed by the int8 encoder itself (the template
/// and its six moves), so that `P` and the device's residuals come from
/// the same arithmetic. In an f32 blob both are the f32 encoder's.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct LkSolver<'a> {
    /// Step of the Jacobian's finite differences (twist units: radians and
    /// model units): informational.
    pub jacobian_step: f32,
    /// Central differences (else forward ones): informational.
    pub central: bool,
    /// Damping `lambda` relative to the mean diagonal of `J^T J`: informational.
    pub damping: f32,
    /// `P`, `6 x F` f32 little-endian, row-major by twist component
    /// (rotation vector, then translation).
    pub rows: &'a [u8],
}

/// What follows the payload: the closest-point table (format 4),
/// PointNetLK's solver (format 5), the template's residual floor (format
/// 6) and its up axis (format 7), each optional.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Trailer<'a> {
    /// The template's closest-point table.
    #[serde(borrow)]
    pub table: Option<NearestTable<'a>>,
    /// PointNetLK's solver.
    #[serde(borrow)]
    pub lk: Option<LkSolver<'a>>,
    /// The template's residual floor, a share of its size: the relative
    /// plane residual of the object's points the template did not store,
    /// at the template's own pose, measured by the exporter (finite, at
    /// least 0). The recommended options calibrate the verdict with it
    /// ([`crate::registration::max_residual_for`]).
    pub residual_floor: Option<f32>,
    /// The template's up axis: a unit vector in the template's frame (its
    /// file's axes), pointing away from the surface the object rests on,
    /// when the exporter was given one (format 7). Scene options made for
    /// the model sweep the yaw about it ([`crate::sweep`]).
    pub up: Option<[f32; 3]>,
}

/// One quantized hidden layer (encoder or head).
///
/// `y = clamp(requantize(bias[o] + sum_i w[o][i] * x[i], multiplier[o], shift[o]) + out_zero_point, act_min, 127)`
/// with `act_min = max(out_zero_point, -128)` (fused ReLU). The input zero
/// point is folded into the bias by the exporter:
/// `bias[o] = round(b[o] / (s_x s_w[o])) - z_x * sum_i w[o][i]`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Int8Layer<'a> {
    /// Real value of one output step (informational: dequantizing features).
    pub out_scale: f32,
    /// Output zero point.
    pub out_zero_point: i8,
    /// Weights, `outputs x inputs` int8 (stored as bytes), row-major by output.
    pub weights: &'a [u8],
    /// Biases, `outputs` x i32 little-endian, input zero point folded in.
    pub bias: &'a [u8],
    /// Q31 multipliers, `outputs` x i32 little-endian.
    pub multiplier: &'a [u8],
    /// Shifts, `outputs` x i8 in `-31..=31`.
    pub shift: &'a [u8],
}

/// The linear output layer of the int8 head: its i32 accumulators are the
/// raw head output and are not requantized to int8 (which would cost the
/// pose precision); they are turned into reals by a per-output scale.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Int8Output<'a> {
    /// Weights, `7 x inputs` int8, row-major by output.
    pub weights: &'a [u8],
    /// Biases, 7 x i32 little-endian, input zero point folded in.
    pub bias: &'a [u8],
    /// Real value of one accumulator step per output, 7 x f32 little-endian.
    pub scale: &'a [u8],
}

/// Payload of an int8 blob.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Int8Payload<'a> {
    /// Network shape.
    pub arch: Arch,
    /// Whether the network expects the source centred on its centroid
    /// (see [`crate::pose::centring`]); the pose is then composed back.
    pub centre_source: bool,
    /// Network passes the model was trained for: 1 for PCRNet, more for
    /// i-PCRNet (run it with [`crate::Options::passes`] set to this).
    pub passes: u16,
    /// User units and axes -> model frame.
    pub frame: Frame,
    /// The template's points, for checking and refining.
    #[serde(borrow)]
    pub template: TemplateCloud<'a>,
    /// Real value of one step of the int16 input coordinates (zero point 0).
    pub input_scale: f32,
    /// Encoder layers, in order; the last one's output parameters are the feature's.
    #[serde(borrow)]
    pub encoder: heapless::Vec<Int8Layer<'a>, MAX_LAYERS>,
    /// Hidden head layers, in order.
    #[serde(borrow)]
    pub head: heapless::Vec<Int8Layer<'a>, MAX_LAYERS>,
    /// Output layer.
    #[serde(borrow)]
    pub output: Int8Output<'a>,
    /// The template's feature, computed by the int8 encoder on the host, F int8.
    pub template_feature: &'a [u8],
}

/// One f32 layer: weights `outputs x inputs` then biases, f32 little-endian.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct F32Layer<'a> {
    /// Weights, row-major by output, f32 little-endian.
    pub weights: &'a [u8],
    /// Biases, f32 little-endian.
    pub bias: &'a [u8],
}

/// Payload of an f32 blob.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct F32Payload<'a> {
    /// Network shape.
    pub arch: Arch,
    /// Whether the network expects the source centred on its centroid.
    pub centre_source: bool,
    /// Network passes the model was trained for: 1 for PCRNet, more for
    /// i-PCRNet (run it with [`crate::Options::passes`] set to this).
    pub passes: u16,
    /// User units and axes -> model frame.
    pub frame: Frame,
    /// The template's points, for checking and refining.
    #[serde(borrow)]
    pub template: TemplateCloud<'a>,
    /// Encoder layers then head layers (hidden and output), in order.
    #[serde(borrow)]
    pub layers: heapless::Vec<F32Layer<'a>, { 2 * MAX_LAYERS + 1 }>,
    /// The template's feature, F x f32 little-endian.
    pub template_feature: &'a [u8],
}

/// Checks a model blob's envelope (magic, a version this build reads, kind,
/// length, CRC) and decodes its payload and [`Trailer`] (from format 4 the
/// template's closest-point table, from format 5 PointNetLK's solver, from
/// format 6 the template's residual floor, from format 7 its up axis). The
/// payload and trailer must use every payload byte.
pub fn decode_model<'a, T: Deserialize<'a>>(
    blob: &'a [u8],
    expected: ModelKind,
) -> Result<(T, Trailer<'a>)> {
    let (version, body) = envelope(blob, expected, |v| {
        (OLDEST_READABLE..=FORMAT_VERSION).contains(&v)
    })?;
    let (payload, rest) = postcard::take_from_bytes::<T>(body).map_err(|_| Error::Malformed)?;
    Ok((payload, decode_trailer(version, rest)?))
}

/// The [`Trailer`] of a blob of format `version`: nothing in format 3, the
/// table in format 4, the table and the solver in format 5, those and the
/// floor in format 6, all four parts from format 7. Not inlined: its
/// temporaries stay out of the loaders' frames (the load stack counts on a
/// 16 KiB device).
#[inline(never)]
fn decode_trailer(version: u16, rest: &[u8]) -> Result<Trailer<'_>> {
    Ok(match version {
        3 => decode::<()>(rest).map(|()| Trailer::default())?,
        4 => Trailer {
            table: decode(rest)?,
            ..Trailer::default()
        },
        5 => {
            let (table, lk) = decode(rest)?;
            Trailer {
                table,
                lk,
                ..Trailer::default()
            }
        }
        6 => {
            let (table, lk, residual_floor) = decode(rest)?;
            Trailer {
                table,
                lk,
                residual_floor,
                up: None,
            }
        }
        _ => decode(rest)?,
    })
}

/// Checks the envelope of a blob of format `version` exactly and returns
/// its payload bytes (tools that read older formats to upgrade them).
pub fn open_version(blob: &[u8], expected: ModelKind, version: u16) -> Result<&[u8]> {
    envelope(blob, expected, |v| v == version).map(|(_, body)| body)
}

/// The version and payload bytes of a blob whose version `accept`s.
fn envelope(
    blob: &[u8],
    expected: ModelKind,
    accept: impl Fn(u16) -> bool,
) -> Result<(u16, &[u8])> {
    let header = blob.get(..HEADER_LEN).ok_or(Error::Truncated {
        needed: HEADER_LEN + CRC_LEN,
        available: blob.len(),
    });
    // A blob shorter than the magic is judged by what it has.
    if blob.len() < MAGIC.len() {
        return if MAGIC.starts_with(blob) {
            Err(Error::Truncated {
                needed: HEADER_LEN + CRC_LEN,
                available: blob.len(),
            })
        } else {
            Err(Error::BadMagic)
        };
    }
    if blob[..4] != MAGIC {
        return Err(Error::BadMagic);
    }
    let header = header?;
    let found = u16::from_le_bytes([header[4], header[5]]);
    if !accept(found) {
        return Err(Error::UnsupportedVersion { found });
    }
    if header[6] != expected as u8 {
        return Err(Error::WrongKind {
            expected,
            found: header[6],
        });
    }
    let payload_len = u32::from_le_bytes([header[7], header[8], header[9], header[10]]) as usize;
    let total = HEADER_LEN
        .saturating_add(payload_len)
        .saturating_add(CRC_LEN);
    if blob.len() < total {
        return Err(Error::Truncated {
            needed: total,
            available: blob.len(),
        });
    }
    if blob.len() > total {
        return Err(Error::TrailingData {
            extra: blob.len() - total,
        });
    }
    let (body, crc) = blob.split_at(total - CRC_LEN);
    let stored = u32::from_le_bytes([crc[0], crc[1], crc[2], crc[3]]);
    let computed = CRC32.checksum(body);
    if stored != computed {
        return Err(Error::BadCrc { stored, computed });
    }
    Ok((found, &body[HEADER_LEN..]))
}

/// Decodes a payload, requiring that it is consumed exactly.
pub fn decode<'a, T: Deserialize<'a>>(payload: &'a [u8]) -> Result<T> {
    match postcard::take_from_bytes::<T>(payload) {
        Ok((value, [])) => Ok(value),
        _ => Err(Error::Malformed),
    }
}

/// Bytes a blob of this payload and trailer takes.
pub fn blob_len<T: Serialize>(payload: &T, trailer: &Trailer<'_>) -> Result<usize> {
    let size =
        |bytes: core::result::Result<usize, postcard::Error>| bytes.map_err(|_| Error::Malformed);
    let p = size(postcard::serialize_with_flavor(
        payload,
        postcard::ser_flavors::Size::default(),
    ))?;
    let t = size(postcard::serialize_with_flavor(
        trailer,
        postcard::ser_flavors::Size::default(),
    ))?;
    Ok(HEADER_LEN + p + t + CRC_LEN)
}

/// Writes a blob of the current format (header, payload, trailer, CRC)
/// into `out`, returning its length.
pub fn write_blob<T: Serialize>(
    kind: ModelKind,
    payload: &T,
    trailer: &Trailer<'_>,
    out: &mut [u8],
) -> Result<usize> {
    let needed = blob_len(payload, trailer)?;
    let available = out.len();
    let out = out
        .get_mut(..needed)
        .ok_or(Error::BufferTooSmall { needed, available })?;
    let payload_len = needed - HEADER_LEN - CRC_LEN;
    let (header, rest) = out.split_at_mut(HEADER_LEN);
    header[..4].copy_from_slice(&MAGIC);
    header[4..6].copy_from_slice(&FORMAT_VERSION.to_le_bytes());
    header[6] = kind as u8;
    header[7..11].copy_from_slice(&(payload_len as u32).to_le_bytes());
    let body = &mut rest[..payload_len];
    let used = postcard::to_slice(payload, body)
        .map_err(|_| Error::Malformed)?
        .len();
    postcard::to_slice(trailer, &mut body[used..]).map_err(|_| Error::Malformed)?;
    let crc = CRC32.checksum(&out[..needed - CRC_LEN]);
    out[needed - CRC_LEN..].copy_from_slice(&crc.to_le_bytes());
    Ok(needed)
}

/// Iterates over the little-endian i32 values of a blob array (biases, multipliers).
pub fn le_i32s(bytes: &[u8]) -> impl Iterator<Item = i32> + '_ {
    bytes
        .as_chunks::<4>()
        .0
        .iter()
        .map(|&c| i32::from_le_bytes(c))
}

/// Iterates over the little-endian f32 values of a blob array.
pub fn le_f32s(bytes: &[u8]) -> impl Iterator<Item = f32> + '_ {
    bytes
        .as_chunks::<4>()
        .0
        .iter()
        .map(|&c| f32::from_le_bytes(c))
}

/// Checks that a byte array holds `count` elements of `size` bytes.
pub(crate) fn expect_len(
    bytes: &[u8],
    count: usize,
    size: usize,
    what: &'static str,
) -> Result<()> {
    if count.checked_mul(size) == Some(bytes.len()) {
        Ok(())
    } else {
        Err(Error::InconsistentDimensions { what })
    }
}

/// Checks a blob's trained pass count (at least 1).
pub(crate) fn check_passes(passes: u16) -> Result<()> {
    if passes >= 1 {
        Ok(())
    } else {
        Err(Error::InvalidParameter {
            what: "trained passes must be at least 1",
        })
    }
}

/// Checks a blob's frame: finite centre, finite positive scale.
pub(crate) fn check_frame(frame: &Frame) -> Result<()> {
    if frame.centre.iter().all(|c| c.is_finite()) && frame.scale.is_finite() && frame.scale > 0.0 {
        Ok(())
    } else {
        Err(Error::InvalidParameter {
            what: "frame centre or scale",
        })
    }
}

#[cfg(test)]
mod tests {
    use super::CRC32;
    use crate::testing::SplitMix64;

    /// The host's sliced table gives the device's byte-at-a-time checksum
    /// (a device checks what a host writes), on lengths around the slice
    /// width and on a blob-sized buffer.
    #[test]
    fn host_crc_is_the_device_crc() {
        let device = crc::Crc::<u32, crc::Table<1>>::new(&crc::CRC_32_ISO_HDLC);
        let mut rng = SplitMix64(8);
        let bytes: std::vec::Vec<u8> = (0..100_000).map(|_| rng.int(0, 255) as u8).collect();
        for n in (0..=40).chain([255, 4096, 100_000]) {
            let b = &bytes[..n];
            assert_eq!(CRC32.checksum(b), device.checksum(b), "{n} bytes");
        }
        // The standard check value of CRC-32/ISO-HDLC.
        assert_eq!(CRC32.checksum(b"123456789"), 0xCBF4_3926);
    }
}

//! PCD (Point Cloud Library) reader: `DATA ascii`, `binary` and
//! `binary_compressed`.
//!
//! Header: v0.7, and v0.6/v0.5 headers without `VERSION` (`COLUMNS` is
//! accepted for `FIELDS`, a missing `COUNT` means 1 per field, a missing
//! `POINTS` means `WIDTH * HEIGHT`). Keywords are case-insensitive. Any
//! fields may be present (rgb, intensity, normals, `COUNT > 1` descriptors,
//! `_` padding); only the first element of `x`, `y` and `z` is read, which may
//! be of TYPE F (SIZE 4 or 8), I or U (SIZE 1, 2, 4 or 8). Binary data is
//! little endian, as PCL writes it on every platform it supports.
//!
//! Organised clouds (`HEIGHT > 1`, `WIDTH * HEIGHT = POINTS`) keep NaN
//! placeholders for missing returns; points with any non-finite coordinate
//! are dropped.
//!
//! `binary_compressed` data is a little-endian `u32` compressed size, a `u32`
//! uncompressed size, then LZF data that decompresses to the fields one after
//! the other (all `x`, then all `y`, ...). The LZF decompressor is written
//! here (`lzf_decompress`) rather than taken from a crate: the `lzf`
//! crate is deprecated by its author and allocates the claimed output size up
//! front, and `pcd-rs` embeds its own but panics on inconsistent sizes.

use super::{FormatError, Scalar, next_line, parse_coordinate, snippet, text};

const FMT: &str = "PCD";

/// How the point data is stored.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum DataKind {
    Ascii,
    Binary,
    BinaryCompressed,
}

/// One field (column) of a record.
#[derive(Debug, Clone)]
struct Field {
    name: String,
    /// Size of one element in bytes (SIZE).
    size: usize,
    /// Decoder for the element, when TYPE and SIZE name a supported scalar.
    scalar: Option<Scalar>,
    /// Number of elements (COUNT).
    count: usize,
}

/// Where x, y or z lives in a record.
#[derive(Debug, Clone, Copy)]
struct Coord {
    scalar: Scalar,
    /// Byte offset of the field inside a binary record.
    offset: usize,
    /// Bytes of the whole field per point (SIZE x COUNT).
    stride: usize,
    /// Index of the field's first value on an ascii line.
    value_index: usize,
}

#[derive(Debug)]
struct Header {
    points: usize,
    /// `WIDTH` (the point count when absent).
    width: usize,
    /// `HEIGHT` (1 when absent).
    height: usize,
    data: DataKind,
    /// Bytes per point in binary layouts.
    record_size: usize,
    /// Values per line in the ascii layout.
    values_per_point: usize,
    xyz: [Coord; 3],
    /// Byte offset of the data section.
    body_start: usize,
    /// Number of header lines (for ascii line numbers in errors).
    header_lines: usize,
}

/// Parses a PCD file held in memory and returns its finite points.
pub fn parse(bytes: &[u8]) -> Result<Vec<[f32; 3]>, FormatError> {
    parse_limited(bytes, super::DEFAULT_MAX_POINTS)
}

/// [`parse`], refusing a file whose `POINTS` exceeds `max_points`.
pub fn parse_limited(bytes: &[u8], max_points: usize) -> Result<Vec<[f32; 3]>, FormatError> {
    parse_f64_limited(bytes, max_points).map(super::to_f32)
}

/// [`parse_limited`] at full precision: coordinates as `f64` (binary `f32`
/// fields widen exactly, text and `f64` fields are not rounded). Every
/// point read is returned, non-finite ones included: [`parse_limited`] and
/// [`super::Format::parse_local`] drop them (the latter counts them).
pub fn parse_f64_limited(bytes: &[u8], max_points: usize) -> Result<Vec<[f64; 3]>, FormatError> {
    let h = parse_header(bytes)?;
    FormatError::check_count("PCD POINTS", h.points, max_points)?;
    let body = bytes.get(h.body_start..).unwrap_or_default();
    match h.data {
        DataKind::Ascii => parse_ascii(&h, body),
        DataKind::Binary => parse_binary(&h, body),
        DataKind::BinaryCompressed => parse_compressed(&h, body),
    }
}

/// An organised PCD cloud: `width x height` points in row order, NaN
/// where the sensor saw nothing, as [`pcrnet_core::scene::OrganisedPoints`]
/// reads them.
#[derive(Debug, Clone, PartialEq)]
pub struct OrganisedCloud {
    /// Points in row order; every coordinate NaN where there is no point.
    pub points: Vec<[f32; 3]>,
    /// Points per row (`WIDTH`).
    pub width: usize,
    /// Rows (`HEIGHT`).
    pub height: usize,
}

/// Parses an organised PCD file (`HEIGHT > 1`) keeping its grid: a point
/// with any non-finite coordinate becomes all NaN. An unorganised file
/// (`HEIGHT 1` or none) is an error saying so.
pub fn parse_organised(bytes: &[u8], max_points: usize) -> Result<OrganisedCloud, FormatError> {
    let h = parse_header(bytes)?;
    if h.height <= 1 {
        return Err(err(
            "HEIGHT is 1: not an organised cloud (a sensor frame has HEIGHT > 1); give a depth image with --intrinsics instead",
        ));
    }
    let points = parse_f64_limited(bytes, max_points)?;
    if points.len() != h.width * h.height {
        return Err(err(format!(
            "{} points read for WIDTH {} x HEIGHT {}",
            points.len(),
            h.width,
            h.height
        )));
    }
    let points = points
        .into_iter()
        .map(|p| {
            let q = p.map(|c| c as f32);
            if q.iter().all(|c| c.is_finite()) {
                q
            } else {
                [f32::NAN; 3]
            }
        })
        .collect();
    Ok(OrganisedCloud {
        points,
        width: h.width,
        height: h.height,
    })
}

fn err(message: impl Into<String>) -> FormatError {
    FormatError::header(FMT, message)
}

fn parse_usize(key: &str, tok: &str) -> Result<usize, FormatError> {
    tok.parse::<usize>()
        .map_err(|_| err(format!("{key} value {} is not a count", snippet(tok))))
}

fn parse_header(bytes: &[u8]) -> Result<Header, FormatError> {
    let mut pos = 0;
    let mut lineno = 0;
    let mut names: Option<Vec<String>> = None;
    let mut sizes: Option<Vec<usize>> = None;
    let mut types: Option<Vec<String>> = None;
    let mut counts: Option<Vec<usize>> = None;
    let mut width: Option<usize> = None;
    let mut height: Option<usize> = None;
    let mut points: Option<usize> = None;
    let data = loop {
        let Some(raw) = next_line(bytes, &mut pos) else {
            return Err(if lineno == 0 {
                err("file is empty")
            } else {
                err("no DATA line (file ends inside the header)")
            });
        };
        lineno += 1;
        let line = std::str::from_utf8(raw)
            .map_err(|_| err(format!("line {lineno} is not text (not a PCD file?)")))?
            .trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let mut toks = line.split_ascii_whitespace();
        let Some(key) = toks.next() else { continue };
        let key = key.to_ascii_uppercase();
        let values: Vec<&str> = toks.collect();
        let single = |values: &[&str]| -> Result<usize, FormatError> {
            match values {
                [v] => parse_usize(&key, v),
                _ => Err(err(format!(
                    "{key} needs one value, found {}",
                    values.len()
                ))),
            }
        };
        match key.as_str() {
            "VERSION" | "VIEWPOINT" => {}
            "FIELDS" | "COLUMNS" => names = Some(values.iter().map(|s| s.to_string()).collect()),
            "SIZE" => {
                sizes = Some(
                    values
                        .iter()
                        .map(|v| parse_usize("SIZE", v))
                        .collect::<Result<_, _>>()?,
                )
            }
            "TYPE" => types = Some(values.iter().map(|s| s.to_ascii_uppercase()).collect()),
            "COUNT" => {
                counts = Some(
                    values
                        .iter()
                        .map(|v| parse_usize("COUNT", v))
                        .collect::<Result<_, _>>()?,
                )
            }
            "WIDTH" => width = Some(single(&values)?),
            "HEIGHT" => height = Some(single(&values)?),
            "POINTS" => points = Some(single(&values)?),
            "DATA" => {
                let kind = values.first().map(|s| s.to_ascii_lowercase());
                break match kind.as_deref() {
                    Some("ascii") => DataKind::Ascii,
                    Some("binary") => DataKind::Binary,
                    Some("binary_compressed") => DataKind::BinaryCompressed,
                    Some(other) => {
                        return Err(err(format!(
                            "DATA {} is not ascii, binary or binary_compressed",
                            snippet(other)
                        )));
                    }
                    None => return Err(err("DATA line names no storage kind")),
                };
            }
            _ => {
                return Err(err(format!(
                    "line {lineno}: unknown keyword {} (not a PCD file?)",
                    snippet(&key)
                )));
            }
        }
    };

    let names = names.ok_or_else(|| err("no FIELDS line"))?;
    if names.is_empty() {
        return Err(err("FIELDS lists no fields"));
    }
    let sizes = sizes.ok_or_else(|| err("no SIZE line"))?;
    let types = types.ok_or_else(|| err("no TYPE line"))?;
    let counts = counts.unwrap_or_else(|| vec![1; names.len()]);
    for (key, len) in [
        ("SIZE", sizes.len()),
        ("TYPE", types.len()),
        ("COUNT", counts.len()),
    ] {
        if len != names.len() {
            return Err(err(format!(
                "FIELDS has {} names but {key} has {len} values",
                names.len()
            )));
        }
    }
    let mut fields = Vec::with_capacity(names.len());
    for (((name, &size), ty), &count) in names.into_iter().zip(&sizes).zip(&types).zip(&counts) {
        let scalar = match (ty.as_str(), size) {
            ("F", 4) => Some(Scalar::F32),
            ("F", 8) => Some(Scalar::F64),
            ("I", 1) => Some(Scalar::I8),
            ("I", 2) => Some(Scalar::I16),
            ("I", 4) => Some(Scalar::I32),
            ("I", 8) => Some(Scalar::I64),
            ("U", 1) => Some(Scalar::U8),
            ("U", 2) => Some(Scalar::U16),
            ("U", 4) => Some(Scalar::U32),
            ("U", 8) => Some(Scalar::U64),
            ("F" | "I" | "U", _) => None,
            _ => {
                return Err(err(format!(
                    "field {}: TYPE {} is not F, I or U",
                    snippet(&name),
                    snippet(ty)
                )));
            }
        };
        if size == 0 {
            return Err(err(format!("field {}: SIZE is 0", snippet(&name))));
        }
        fields.push(Field {
            name,
            size,
            scalar,
            count,
        });
    }

    // Layout: byte offsets (binary) and value indices (ascii).
    let mut coords: [Option<Coord>; 3] = [None; 3];
    let mut offset = 0usize;
    let mut value_index = 0usize;
    for f in &fields {
        let slot = ["x", "y", "z"]
            .iter()
            .position(|c| f.name.eq_ignore_ascii_case(c));
        let bytes = f
            .size
            .checked_mul(f.count)
            .ok_or_else(|| err(format!("field {}: SIZE x COUNT overflows", f.name)))?;
        if let Some(k) = slot
            && coords[k].is_none()
        {
            let scalar = f.scalar.ok_or_else(|| {
                err(format!(
                    "field {}: TYPE/SIZE combination is not a supported number type",
                    f.name
                ))
            })?;
            if f.count == 0 {
                return Err(err(format!("field {}: COUNT is 0", f.name)));
            }
            coords[k] = Some(Coord {
                scalar,
                offset,
                stride: bytes,
                value_index,
            });
        }
        offset = offset
            .checked_add(bytes)
            .ok_or_else(|| err("record size overflows"))?;
        value_index = value_index
            .checked_add(f.count)
            .ok_or_else(|| err("values per point overflow"))?;
    }
    let mut xyz = [Coord {
        scalar: Scalar::F32,
        offset: 0,
        stride: 0,
        value_index: 0,
    }; 3];
    for (k, name) in ["x", "y", "z"].iter().enumerate() {
        xyz[k] = coords[k].ok_or_else(|| err(format!("FIELDS has no {name}")))?;
    }

    let points = match (points, width) {
        (Some(p), Some(w)) => {
            let h = height.unwrap_or(1);
            if w.checked_mul(h) != Some(p) {
                return Err(err(format!(
                    "WIDTH {w} x HEIGHT {h} does not equal POINTS {p}"
                )));
            }
            p
        }
        (Some(p), None) => p,
        (None, Some(w)) => w
            .checked_mul(height.unwrap_or(1))
            .ok_or_else(|| err("WIDTH x HEIGHT overflows"))?,
        (None, None) => return Err(err("neither POINTS nor WIDTH is given")),
    };

    let (width, height) = match (width, height) {
        (Some(w), h) => (w, h.unwrap_or(1)),
        (None, _) => (points, 1),
    };
    Ok(Header {
        points,
        width,
        height,
        data,
        record_size: offset,
        values_per_point: value_index,
        xyz,
        body_start: pos,
        header_lines: lineno,
    })
}

fn parse_ascii(h: &Header, body: &[u8]) -> Result<Vec<[f64; 3]>, FormatError> {
    const SECTION: &str = "DATA ascii";
    let body = text(body, SECTION)?;
    let mut out = Vec::new();
    let mut seen = 0usize;
    for (i, line) in body.lines().enumerate() {
        if seen == h.points {
            break;
        }
        let line = line.trim();
        if line.is_empty() {
            continue;
        }
        let section = || format!("{SECTION} line {}", h.header_lines + i + 1);
        let toks: Vec<&str> = line
            .split_ascii_whitespace()
            .take(h.values_per_point)
            .collect();
        if toks.len() < h.values_per_point {
            return Err(FormatError::data(
                section(),
                format!(
                    "expected {} values per point, found {}",
                    h.values_per_point,
                    toks.len()
                ),
            ));
        }
        let mut p = [0f64; 3];
        for (k, c) in h.xyz.iter().enumerate() {
            let tok = toks.get(c.value_index).copied().unwrap_or_default();
            p[k] = parse_coordinate(tok, k, section())?;
        }
        seen += 1;
        out.push(p);
    }
    if seen < h.points {
        return Err(FormatError::truncated(
            SECTION,
            h.points as u64,
            "points",
            seen as u64,
        ));
    }
    Ok(out)
}

fn read_coord(raw: &[u8], at: usize, scalar: Scalar, section: &str) -> Result<f64, FormatError> {
    raw.get(at..)
        .and_then(|b| scalar.read(b, false))
        .ok_or_else(|| FormatError::data(section, "field lies outside the data"))
}

fn data_bytes(h: &Header, section: &str) -> Result<usize, FormatError> {
    h.points.checked_mul(h.record_size).ok_or_else(|| {
        FormatError::data(
            section,
            format!(
                "POINTS {} x {} bytes per point overflows",
                h.points, h.record_size
            ),
        )
    })
}

fn parse_binary(h: &Header, body: &[u8]) -> Result<Vec<[f64; 3]>, FormatError> {
    const SECTION: &str = "DATA binary";
    let need = data_bytes(h, SECTION)?;
    let Some(data) = body.get(..need) else {
        return Err(FormatError::truncated(
            SECTION,
            need as u64,
            "bytes of points",
            body.len() as u64,
        ));
    };
    // The bytes are there, so `points` is bounded by the input size.
    let mut out = super::points_vec(h.points, SECTION)?;
    for rec in data.chunks_exact(h.record_size) {
        let mut p = [0f64; 3];
        for (v, c) in p.iter_mut().zip(&h.xyz) {
            *v = read_coord(rec, c.offset, c.scalar, SECTION)?;
        }
        out.push(p);
    }
    Ok(out)
}

fn parse_compressed(h: &Header, body: &[u8]) -> Result<Vec<[f64; 3]>, FormatError> {
    const SECTION: &str = "DATA binary_compressed";
    if h.points == 0 {
        return Ok(Vec::new());
    }
    let need = data_bytes(h, SECTION)?;
    let Some(sizes) = body.get(..8) else {
        return Err(FormatError::truncated(
            SECTION,
            8,
            "bytes of size header",
            body.len() as u64,
        ));
    };
    let compressed = u32::from_le_bytes([sizes[0], sizes[1], sizes[2], sizes[3]]) as usize;
    let uncompressed = u32::from_le_bytes([sizes[4], sizes[5], sizes[6], sizes[7]]) as usize;
    if uncompressed != need {
        return Err(FormatError::data(
            SECTION,
            format!(
                "uncompressed size {uncompressed} does not match POINTS {} x {} bytes per point = {need}",
                h.points, h.record_size
            ),
        ));
    }
    let rest = &body[8..];
    let Some(lzf) = rest.get(..compressed) else {
        return Err(FormatError::truncated(
            SECTION,
            compressed as u64,
            "bytes of compressed data",
            rest.len() as u64,
        ));
    };
    // LZF's best case is a 3-byte back-reference copying 264 bytes: more
    // than 88 x the compressed size cannot be there (refused before the
    // output buffer is sized).
    if need > compressed.saturating_mul(LZF_MAX_RATIO) {
        return Err(FormatError::data(
            SECTION,
            format!(
                "{compressed} compressed bytes cannot hold the {need} bytes POINTS {} declares \
                 (LZF expands at most {LZF_MAX_RATIO} x)",
                h.points
            ),
        ));
    }
    let raw = lzf_decompress(lzf, need).map_err(|m| FormatError::data(SECTION, m))?;
    // Struct-of-arrays: field f's column starts at points * (its record
    // offset), and point i's element at column + i * (SIZE * COUNT).
    let mut out = super::points_vec(h.points, SECTION)?;
    for i in 0..h.points {
        let mut p = [0f64; 3];
        for (v, c) in p.iter_mut().zip(&h.xyz) {
            // Cannot overflow: every position is below `need`, checked above.
            let at = h.points * c.offset + i * c.stride;
            *v = read_coord(&raw, at, c.scalar, SECTION)?;
        }
        out.push(p);
    }
    Ok(out)
}

/// Most bytes LZF can produce per compressed byte: a back-reference of
/// 3 bytes (control, extra length, offset) copies at most 7 + 255 + 2.
const LZF_MAX_RATIO: usize = 88;

/// Decompresses LZF (Marc Lehmann's liblzf format, as used by PCL) into
/// exactly `expected` bytes.
///
/// Control byte `c < 32`: a literal run of `c + 1` bytes follows. Otherwise a
/// back-reference: length `(c >> 5) + 2` (if `c >> 5 == 7`, a further byte is
/// added to the length), distance `((c & 0x1f) << 8) + next byte + 1`.
/// One input byte yields at most 88 output bytes, which bounds the
/// allocation by the input actually present.
fn lzf_decompress(input: &[u8], expected: usize) -> Result<Vec<u8>, String> {
    let mut out: Vec<u8> = Vec::new();
    out.try_reserve_exact(expected.min(input.len().saturating_mul(LZF_MAX_RATIO)))
        .map_err(|_| format!("cannot allocate {expected} bytes to decompress into"))?;
    let mut i = 0;
    let ends = || format!("LZF data ends early (at byte {})", input.len());
    while let Some(&ctrl) = input.get(i) {
        i += 1;
        let ctrl = usize::from(ctrl);
        if ctrl < 32 {
            let len = ctrl + 1;
            let lit = input.get(i..i + len).ok_or_else(ends)?;
            if out.len() + len > expected {
                return Err(format!("LZF data decompresses past {expected} bytes"));
            }
            out.extend_from_slice(lit);
            i += len;
        } else {
            let mut len = ctrl >> 5;
            if len == 7 {
                len += usize::from(*input.get(i).ok_or_else(ends)?);
                i += 1;
            }
            len += 2;
            let distance = ((ctrl & 0x1f) << 8) + usize::from(*input.get(i).ok_or_else(ends)?) + 1;
            i += 1;
            if distance > out.len() {
                return Err(format!(
                    "LZF back-reference {distance} bytes before output byte {}",
                    out.len()
                ));
            }
            if out.len() + len > expected {
                return Err(format!("LZF data decompresses past {expected} bytes"));
            }
            let start = out.len() - distance;
            // Byte by byte: the source may overlap what is being written.
            for k in start..start + len {
                let b = out[k];
                out.push(b);
            }
        }
    }
    if out.len() != expected {
        return Err(format!(
            "LZF data decompresses to {} bytes, expected {expected}",
            out.len()
        ));
    }
    Ok(out)
}

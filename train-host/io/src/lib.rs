//! # pcrnet-io
//!
//! Point clouds in and out of files for the pcrnet tools, with no training
//! dependency: readers for PCD, PLY, OFF (sampled to points), XYZ and CSV
//! text and raw little-endian `f32` ([`mod@write`] has the writers), the file's
//! own frame kept exact ([`frame`]), seeded reduction of large clouds
//! ([`reduce`], with [`sampling`]'s farthest point sampling), and a
//! progress bar for long jobs ([`progress`]).
//!
//! [`read_cloud`] picks the format from the file extension and returns the
//! points as `[x, y, z]` in `f32`. Each format also has a `parse` function
//! over bytes, so callers (and tests) need no files.
//!
//! Every reader parses at full precision (`f64`) first. [`read_cloud_local`]
//! keeps that precision for clouds far from their file's origin (map
//! coordinates: an easting of 500,000 m has an `f32` spacing of 3 cm, a
//! northing of 5,400,000 m one of 50 cm): it moves the cloud to a local
//! origin before rounding to `f32` and returns the origin, so results can
//! be given back in the file's frame ([`LocalCloud`]).
//!
//! Common rules:
//! - Only x, y and z are kept; every other field, property or column is read
//!   past and dropped.
//! - Points with a non-finite coordinate (NaN placeholders of organised PCD
//!   clouds, stray `inf`s) are dropped, in every format, and counted
//!   ([`LocalCloud::left_out`]). A valid file whose points are all
//!   dropped, or that declares none, gives an empty cloud.
//! - No input panics, and no buffer is sized from a count in the file before
//!   the bytes that count promises have been checked to be there.
//!
//! Crate choices (checked against crates.io with `cargo info` and by reading
//! the published sources):
//! - `pcd-rs` 0.13 reads `binary_compressed` and dynamic fields, but it sizes
//!   buffers from the untrusted `u32` compressed/uncompressed sizes
//!   (`vec![0u8; compressed_size]`) and transposes the decompressed columns by
//!   slicing without checking the length against `POINTS`, which panics on
//!   malformed files; it also pulls in `regex`, `itertools` and `thiserror` 1.
//!   So PCD is parsed here ([`pcd`]).
//! - `lzf` 1.0 is marked DEPRECATED by its author and allocates the full
//!   claimed output size up front; the LZF decompressor here is ~40 lines of
//!   safe Rust with bounded allocation (see [`pcd`]).
//! - `ply-rs` 0.1.3 is unmaintained (last release years ago, `peg` 0.6,
//!   a `skeptic` build script) and builds a hash map per element, which is
//!   heavy for clouds; the focused parser in [`ply`] only extracts x, y, z.

use std::fmt;
use std::path::{Path, PathBuf};

pub mod depth;
pub mod frame;
pub mod off;
pub mod pcd;
pub mod ply;
pub mod progress;
pub mod raw;
pub mod reduce;
pub mod sampling;
pub mod write;
pub mod xyz;

/// Most points a reader takes from one file unless told otherwise: 20
/// million (480 MB while read as f64, 240 MB as f32), four times a 5 M-point scan. Every reader
/// refuses a larger declared size before allocating ([`FormatError::TooLarge`]);
/// binary data must also be present in full before anything is sized from
/// it, and `binary_compressed` PCD may not claim more than LZF can expand
/// its bytes to (88 x). `pcrnet register --max-cloud-points` raises the limit.
pub const DEFAULT_MAX_POINTS: usize = 20_000_000;

/// Number of points [`read_cloud`] samples from an OFF mesh.
pub const DEFAULT_OFF_SAMPLES: usize = 2048;

/// Seed [`read_cloud`] uses when sampling an OFF mesh.
pub const DEFAULT_OFF_SEED: u64 = 0x5EED;

/// What is wrong with the bytes of a file (independent of where they came from).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum FormatError {
    /// The header is missing, malformed, or describes a layout this reader
    /// does not support.
    #[error("{format} header: {message}")]
    Header {
        /// Format name, e.g. `"PCD"`.
        format: &'static str,
        /// What is wrong.
        message: String,
    },
    /// The data ends before everything the header promises.
    #[error("{section}: expected {expected} {unit}, found {found}")]
    Truncated {
        /// Part of the file being read, e.g. `"DATA binary"`.
        section: String,
        /// What was expected.
        expected: u64,
        /// Unit of `expected` and `found`, e.g. `"bytes of points"`.
        unit: &'static str,
        /// What was there.
        found: u64,
    },
    /// A value in the data section is malformed.
    #[error("{section}: {message}")]
    Data {
        /// Part of the file being read, e.g. `"DATA ascii line 12"`.
        section: String,
        /// What is wrong.
        message: String,
    },
    /// The file declares (or holds) more points than the reader's limit
    /// ([`DEFAULT_MAX_POINTS`] unless raised): refused before allocating.
    #[error(
        "{what} {declared}, more than the limit of {limit} points (a hostile or mistaken size; \
         if the file is real, raise the limit: pcrnet register --max-cloud-points N)"
    )]
    TooLarge {
        /// What was counted, e.g. `"PCD POINTS"`.
        what: &'static str,
        /// The count in the file.
        declared: u64,
        /// The limit in force.
        limit: usize,
    },
    /// A mesh cannot be sampled (no faces, zero area, bad indices).
    #[error("OFF mesh: {0}")]
    Mesh(String),
}

impl FormatError {
    /// [`FormatError::TooLarge`] unless `declared <= limit`.
    pub(crate) fn check_count(
        what: &'static str,
        declared: usize,
        limit: usize,
    ) -> Result<(), FormatError> {
        if declared <= limit {
            Ok(())
        } else {
            Err(FormatError::TooLarge {
                what,
                declared: declared as u64,
                limit,
            })
        }
    }

    pub(crate) fn header(format: &'static str, message: impl Into<String>) -> Self {
        FormatError::Header {
            format,
            message: message.into(),
        }
    }

    pub(crate) fn data(section: impl Into<String>, message: impl Into<String>) -> Self {
        FormatError::Data {
            section: section.into(),
            message: message.into(),
        }
    }

    pub(crate) fn truncated(
        section: impl Into<String>,
        expected: u64,
        unit: &'static str,
        found: u64,
    ) -> Self {
        FormatError::Truncated {
            section: section.into(),
            expected,
            unit,
            found,
        }
    }
}

/// Failure to read a point cloud file. The message names the file and says
/// what is wrong, e.g.
/// `bunny.pcd: DATA binary: expected 12288 bytes of points, found 100`.
///
/// The cause is already part of the message, so `source()` returns `None`
/// (error reporters would otherwise print it twice); match on the variant to
/// get at it.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ReadError {
    /// The file could not be read.
    #[error("{}: {error}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying error.
        error: std::io::Error,
    },
    /// The file was read but its contents are not a valid cloud.
    #[error("{}: {error}", path.display())]
    Format {
        /// The file.
        path: PathBuf,
        /// What is wrong with the contents.
        error: FormatError,
    },
    /// The extension names no supported format.
    #[error(
        "{}: unknown point cloud format (expected extension .pcd, .ply, .off, .xyz or .txt)",
        path.display()
    )]
    UnknownFormat {
        /// The file.
        path: PathBuf,
    },
}

/// Supported file formats.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Format {
    /// Point Cloud Library PCD (ascii, binary, binary_compressed).
    Pcd,
    /// Stanford PLY (ascii, binary little and big endian).
    Ply,
    /// Object File Format mesh, sampled to points.
    Off,
    /// Whitespace- or comma-separated text, one point per line.
    Xyz,
    /// Comma-separated text (`.csv`): read as [`Format::Xyz`] (a first
    /// line of column names is skipped), written with an `x,y,z` header.
    Csv,
    /// Raw little-endian `f32` `x y z` triples (`.f32`, no header; see
    /// [`raw`]): what firmware links.
    F32,
}

impl Format {
    /// Format named by the extension of `path` (case-insensitive):
    /// `.pcd`, `.ply`, `.off`, `.xyz`, `.txt`, `.csv` or `.f32`.
    pub fn from_path(path: &Path) -> Option<Format> {
        let ext = path.extension()?.to_str()?.to_ascii_lowercase();
        match ext.as_str() {
            "pcd" => Some(Format::Pcd),
            "ply" => Some(Format::Ply),
            "off" => Some(Format::Off),
            "xyz" | "txt" => Some(Format::Xyz),
            "csv" => Some(Format::Csv),
            "f32" => Some(Format::F32),
            _ => None,
        }
    }

    /// Parses `bytes` in this format with [`DEFAULT_MAX_POINTS`]. OFF
    /// meshes are sampled with [`DEFAULT_OFF_SAMPLES`] points and
    /// [`DEFAULT_OFF_SEED`].
    pub fn parse(self, bytes: &[u8]) -> Result<Vec<[f32; 3]>, FormatError> {
        self.parse_limited(bytes, DEFAULT_MAX_POINTS)
    }

    /// [`Format::parse`], refusing files that declare or hold more than
    /// `max_points` points (OFF: vertices or faces).
    pub fn parse_limited(
        self,
        bytes: &[u8],
        max_points: usize,
    ) -> Result<Vec<[f32; 3]>, FormatError> {
        // About the origin: every point rounded to f32 where it is.
        Ok(self.parse_local(bytes, max_points, Some([0.0; 3]))?.points)
    }

    /// [`Format::parse_limited`] about a local origin (see [`LocalCloud`]):
    /// the points are read in `f64`, the origin is `origin` or, if `None`,
    /// their coordinate-wise median (OFF: of the vertices), and each point
    /// becomes `(p - origin)` rounded to `f32`. Points that do not fit
    /// `f32` there are dropped like non-finite ones. With the origin at
    /// zero the points are exactly [`Format::parse_limited`]'s.
    pub fn parse_local(
        self,
        bytes: &[u8],
        max_points: usize,
        origin: Option<[f64; 3]>,
    ) -> Result<LocalCloud, FormatError> {
        // A BOM is text's; raw f32 bytes are taken as they are.
        let bytes = if self == Format::F32 {
            bytes
        } else {
            strip_bom(bytes)
        };
        let points = match self {
            Format::Pcd => pcd::parse_f64_limited(bytes, max_points)?,
            Format::Ply => ply::parse_f64_limited(bytes, max_points)?,
            Format::Xyz | Format::Csv => xyz::parse_f64_limited(bytes, max_points)?,
            Format::F32 => raw::parse_f64_limited(bytes, max_points)?,
            Format::Off => {
                let mesh = off::parse_limited(bytes, max_points)?;
                let origin = origin.unwrap_or_else(|| median(&mesh.vertices));
                if mesh.triangles.is_empty() {
                    mesh.vertices
                } else {
                    let points =
                        off::sample_about(&mesh, origin, DEFAULT_OFF_SAMPLES, DEFAULT_OFF_SEED)?;
                    return Ok(LocalCloud {
                        origin,
                        points,
                        left_out: 0,
                    });
                }
            }
        };
        let origin = origin.unwrap_or_else(|| median(&points));
        let read = points.len();
        let points: Vec<_> = points
            .into_iter()
            .filter_map(|p| localise(p, origin))
            .collect();
        Ok(LocalCloud {
            origin,
            left_out: read - points.len(),
            points,
        })
    }
}

/// A cloud moved to a local origin before its coordinates were rounded to
/// `f32`: point `i` of the file is `origin + points[i]` (up to the `f32`
/// rounding of `points[i]`, which is relative to the cloud's own extent,
/// not to its distance from the file's origin).
#[derive(Debug, Clone, PartialEq)]
pub struct LocalCloud {
    /// Where the cloud's local frame sits in the file's frame, in file
    /// units: the one asked for, or the coordinate-wise median of the
    /// points read (robust to a few stray points; `[0, 0, 0]` for an empty
    /// cloud).
    pub origin: [f64; 3],
    /// The points relative to `origin`.
    pub points: Vec<[f32; 3]>,
    /// Points read but left out: a coordinate not finite (the NaN
    /// placeholders of organised PCD clouds, a stray `nan` or `inf`) or
    /// not fitting `f32` about `origin`.
    pub left_out: usize,
}

impl LocalCloud {
    /// What a reader left out of `path`, for the user (`None` when
    /// nothing): how many of the points read, and why.
    pub fn left_out_note(&self, path: &Path) -> Option<String> {
        (self.left_out > 0).then(|| {
            format!(
                "{}: {} of {} points left out (a coordinate is nan or inf, or beyond f32)",
                path.display(),
                self.left_out,
                self.left_out + self.points.len()
            )
        })
    }
}

/// Coordinate-wise median of finite points (the upper one of an even
/// count), `[0, 0, 0]` if there are none.
fn median(points: &[[f64; 3]]) -> [f64; 3] {
    let mut column: Vec<f64> = Vec::new();
    [0, 1, 2].map(|k| {
        column.clear();
        column.extend(points.iter().map(|p| p[k]).filter(|v| v.is_finite()));
        let mid = column.len() / 2;
        if column.is_empty() {
            0.0
        } else {
            *column.select_nth_unstable_by(mid, f64::total_cmp).1
        }
    })
}

impl fmt::Display for Format {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Format::Pcd => "PCD",
            Format::Ply => "PLY",
            Format::Off => "OFF",
            Format::Xyz => "XYZ",
            Format::Csv => "CSV",
            Format::F32 => "raw f32",
        })
    }
}

fn read_bytes(path: &Path) -> Result<Vec<u8>, ReadError> {
    std::fs::read(path).map_err(|error| ReadError::Io {
        path: path.to_path_buf(),
        error,
    })
}

fn with_path<T>(path: &Path, r: Result<T, FormatError>) -> Result<T, ReadError> {
    r.map_err(|error| ReadError::Format {
        path: path.to_path_buf(),
        error,
    })
}

/// Reads a point cloud, choosing the format by extension (see
/// [`Format::from_path`]). OFF meshes are sampled to [`DEFAULT_OFF_SAMPLES`]
/// points with the fixed seed [`DEFAULT_OFF_SEED`].
pub fn read_cloud(path: &Path) -> Result<Vec<[f32; 3]>, ReadError> {
    read_cloud_limited(path, DEFAULT_MAX_POINTS)
}

/// [`read_cloud`] with a limit on the points a file may declare or hold
/// (see [`DEFAULT_MAX_POINTS`]).
pub fn read_cloud_limited(path: &Path, max_points: usize) -> Result<Vec<[f32; 3]>, ReadError> {
    Ok(read_cloud_local(path, max_points, Some([0.0; 3]))?.points)
}

/// [`read_cloud_limited`] about a local origin: see [`Format::parse_local`]
/// and [`LocalCloud`].
pub fn read_cloud_local(
    path: &Path,
    max_points: usize,
    origin: Option<[f64; 3]>,
) -> Result<LocalCloud, ReadError> {
    let format = Format::from_path(path).ok_or_else(|| ReadError::UnknownFormat {
        path: path.to_path_buf(),
    })?;
    let bytes = read_bytes(path)?;
    with_path(path, format.parse_local(&bytes, max_points, origin))
}

/// Reads an OFF mesh and samples `n` points uniformly over its surface,
/// deterministically for a given `seed` (see [`off::sample`]).
pub fn read_off_sampled(path: &Path, n: usize, seed: u64) -> Result<Vec<[f32; 3]>, ReadError> {
    let bytes = read_bytes(path)?;
    with_path(path, off::parse_sampled(strip_bom(&bytes), n, seed))
}

/// The bytes after a UTF-8 byte-order mark, as Windows editors save text
/// (every format's header is text, so this is safe for binary bodies too).
fn strip_bom(bytes: &[u8]) -> &[u8] {
    bytes.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(bytes)
}

/// An empty point vector with room for `n` points, or an error naming
/// `section` if the memory is not there (instead of aborting the process).
pub(crate) fn points_vec(n: usize, section: &str) -> Result<Vec<[f64; 3]>, FormatError> {
    let mut out = Vec::new();
    out.try_reserve_exact(n)
        .map_err(|_| FormatError::data(section, out_of_memory(n)))?;
    Ok(out)
}

pub(crate) fn out_of_memory(points: usize) -> String {
    format!("cannot allocate {points} points: not enough memory")
}

/// `p - origin` rounded to `f32`, or `None` if a coordinate is not finite
/// there. With the origin at zero this is `p` rounded to `f32` (`x - 0.0`
/// is `x`, signed zeros included).
pub(crate) fn localise(p: [f64; 3], origin: [f64; 3]) -> Option<[f32; 3]> {
    let q = [
        (p[0] - origin[0]) as f32,
        (p[1] - origin[1]) as f32,
        (p[2] - origin[2]) as f32,
    ];
    q.iter().all(|v| v.is_finite()).then_some(q)
}

/// The points rounded to `f32`, dropping any that do not fit.
pub(crate) fn to_f32(points: Vec<[f64; 3]>) -> Vec<[f32; 3]> {
    points
        .into_iter()
        .filter_map(|p| localise(p, [0.0; 3]))
        .collect()
}

/// Parses a text number as `f64` (accepts `nan`, `inf`, exponents).
pub(crate) fn parse_num(tok: &str) -> Option<f64> {
    tok.parse::<f64>().ok()
}

/// Parses coordinate `k` (0 = x, 1 = y, 2 = z) of a text row, naming the
/// coordinate and the offending text in the error.
pub(crate) fn parse_coordinate(
    tok: &str,
    k: usize,
    section: impl Into<String>,
) -> Result<f64, FormatError> {
    parse_num(tok).ok_or_else(|| {
        let name = ["x", "y", "z"].get(k).copied().unwrap_or("coordinate");
        FormatError::data(
            section,
            format!("{name} value {} is not a number", snippet(tok)),
        )
    })
}

/// Shortens untrusted text for error messages.
pub(crate) fn snippet(s: &str) -> String {
    const MAX: usize = 40;
    let s = s.trim();
    if s.chars().count() <= MAX {
        format!("{s:?}")
    } else {
        let cut: String = s.chars().take(MAX).collect();
        format!("{cut:?}...")
    }
}

/// Binary scalar types shared by PCD and PLY.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    I64,
    U64,
    F32,
    F64,
}

impl Scalar {
    /// Size in bytes.
    pub(crate) fn size(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::I64 | Scalar::U64 | Scalar::F64 => 8,
        }
    }

    pub(crate) fn is_integer(self) -> bool {
        !matches!(self, Scalar::F32 | Scalar::F64)
    }

    /// Decodes a value from exactly `self.size()` bytes. Returns `None` if
    /// `b` is too short.
    pub(crate) fn read(self, b: &[u8], big_endian: bool) -> Option<f64> {
        let b = b.get(..self.size())?;
        macro_rules! num {
            ($t:ty) => {{
                let arr = b.try_into().ok()?;
                if big_endian {
                    <$t>::from_be_bytes(arr)
                } else {
                    <$t>::from_le_bytes(arr)
                }
            }};
        }
        Some(match self {
            Scalar::I8 => f64::from(b[0] as i8),
            Scalar::U8 => f64::from(b[0]),
            Scalar::I16 => f64::from(num!(i16)),
            Scalar::U16 => f64::from(num!(u16)),
            Scalar::I32 => f64::from(num!(i32)),
            Scalar::U32 => f64::from(num!(u32)),
            Scalar::I64 => num!(i64) as f64,
            Scalar::U64 => num!(u64) as f64,
            Scalar::F32 => f64::from(num!(f32)),
            Scalar::F64 => num!(f64),
        })
    }
}

/// Splits off the next line (without `\n` or a trailing `\r`) starting at
/// `*pos`, advancing `*pos` past the newline. `None` at end of input.
pub(crate) fn next_line<'a>(bytes: &'a [u8], pos: &mut usize) -> Option<&'a [u8]> {
    let rest = bytes.get(*pos..).filter(|r| !r.is_empty())?;
    let (line, advance) = match rest.iter().position(|&c| c == b'\n') {
        Some(i) => (&rest[..i], i + 1),
        None => (rest, rest.len()),
    };
    *pos += advance;
    Some(line.strip_suffix(b"\r").unwrap_or(line))
}

/// Decodes the bytes of a text format; `section` names the part for errors.
pub(crate) fn text<'a>(bytes: &'a [u8], section: &str) -> Result<&'a str, FormatError> {
    std::str::from_utf8(bytes).map_err(|e| {
        FormatError::data(
            section,
            format!("not text (invalid UTF-8 at byte {})", e.valid_up_to()),
        )
    })
}

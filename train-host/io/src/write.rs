//! Point cloud writers: the format is the one the file's extension names
//! (see [`Format::from_path`]), so `--aligned out.pcd` is a PCD file.
//!
//! Every writer keeps the values exactly: text formats print each
//! coordinate's shortest round-trip decimal, binary formats store the
//! coordinate type itself (`f32` as PCD `F 4` / PLY `float`, `f64` as
//! PCD `F 8` / PLY `double`). What they write, the readers of this
//! module read back bit for bit.
//!
//! | extension | written as |
//! |---|---|
//! | `.pcd` | PCD 0.7, fields x y z, `DATA binary` (little-endian) |
//! | `.ply` | PLY 1.0 `binary_little_endian`, `element vertex` x y z |
//! | `.xyz`, `.txt` | one `x y z` line per point |
//! | `.csv` | an `x,y,z` header, then one `x,y,z` line per point |
//! | `.off` | `OFF` with the points as vertices and no faces |
//! | `.f32` | raw little-endian `f32` `x y z` triples, no header (f64 coordinates rounded to f32: the format has no other type) |

use std::fmt::Debug;
use std::path::{Path, PathBuf};

use super::Format;

/// A coordinate type the writers store as is.
pub trait Coordinate: Copy + Debug {
    /// PCD `SIZE` (bytes) of the type, `TYPE` being `F`.
    const PCD_SIZE: usize;
    /// PLY property type name.
    const PLY_TYPE: &'static str;
    /// Appends the little-endian bytes.
    fn put_le(self, out: &mut Vec<u8>);
    /// The value as `f32` (rounded to nearest from `f64`), for `.f32`.
    fn to_f32(self) -> f32;
}

impl Coordinate for f32 {
    const PCD_SIZE: usize = 4;
    const PLY_TYPE: &'static str = "float";
    fn put_le(self, out: &mut Vec<u8>) {
        out.extend_from_slice(&self.to_le_bytes());
    }
    fn to_f32(self) -> f32 {
        self
    }
}

impl Coordinate for f64 {
    const PCD_SIZE: usize = 8;
    const PLY_TYPE: &'static str = "double";
    fn put_le(self, out: &mut Vec<u8>) {
        out.extend_from_slice(&self.to_le_bytes());
    }
    fn to_f32(self) -> f32 {
        self as f32
    }
}

/// Failure to write a cloud file.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum WriteError {
    /// The extension names no supported format.
    #[error(
        "{}: unknown point cloud format to write (use the extension .pcd, .ply, .xyz, .txt, .csv, .off or .f32)",
        path.display()
    )]
    UnknownFormat {
        /// The file.
        path: PathBuf,
    },
    /// The file could not be written.
    #[error("writing {}: {error}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying error.
        error: std::io::Error,
    },
}

/// Writes `points` to `path` in the format its extension names.
pub fn write_cloud<C: Coordinate>(path: &Path, points: &[[C; 3]]) -> Result<(), WriteError> {
    let format = Format::from_path(path).ok_or_else(|| WriteError::UnknownFormat {
        path: path.to_path_buf(),
    })?;
    std::fs::write(path, encode(format, points)).map_err(|error| WriteError::Io {
        path: path.to_path_buf(),
        error,
    })
}

/// The bytes of `points` in `format` (see the module docs).
pub fn encode<C: Coordinate>(format: Format, points: &[[C; 3]]) -> Vec<u8> {
    let n = points.len();
    match format {
        Format::Pcd => {
            let s = C::PCD_SIZE;
            let mut out = format!(
                "# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\nFIELDS x y z\n\
                 SIZE {s} {s} {s}\nTYPE F F F\nCOUNT 1 1 1\nWIDTH {n}\nHEIGHT 1\n\
                 VIEWPOINT 0 0 0 1 0 0 0\nPOINTS {n}\nDATA binary\n"
            )
            .into_bytes();
            put_binary(&mut out, points);
            out
        }
        Format::Ply => {
            let t = C::PLY_TYPE;
            let mut out = format!(
                "ply\nformat binary_little_endian 1.0\ncomment written by pcrnet\n\
                 element vertex {n}\nproperty {t} x\nproperty {t} y\nproperty {t} z\nend_header\n"
            )
            .into_bytes();
            put_binary(&mut out, points);
            out
        }
        Format::Xyz => text_lines(String::new(), points, ' ').into_bytes(),
        Format::Csv => text_lines("x,y,z\n".into(), points, ',').into_bytes(),
        Format::Off => text_lines(format!("OFF\n{n} 0 0\n"), points, ' ').into_bytes(),
        Format::F32 => points
            .iter()
            .flatten()
            .flat_map(|c| c.to_f32().to_le_bytes())
            .collect(),
    }
}

fn put_binary<C: Coordinate>(out: &mut Vec<u8>, points: &[[C; 3]]) {
    out.reserve(points.len() * 3 * C::PCD_SIZE);
    for &[x, y, z] in points {
        x.put_le(out);
        y.put_le(out);
        z.put_le(out);
    }
}

/// `head` then one `x y z` line per point (the values apart by `sep`),
/// each value's shortest decimal that reads back to the same value
/// (`{:?}`).
fn text_lines<C: Coordinate>(mut head: String, points: &[[C; 3]], sep: char) -> String {
    use std::fmt::Write;
    for [x, y, z] in points {
        // Writing to a String cannot fail.
        let _ = writeln!(head, "{x:?}{sep}{y:?}{sep}{z:?}");
    }
    head
}

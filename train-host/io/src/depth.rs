//! Depth images: 16-bit grayscale PNG in and out, and the small JSON of
//! camera intrinsics beside it.
//!
//! The PNG holds one raw value per pixel (`u16`, row order), as RGB-D
//! datasets store depth (TUM RGB-D, BOP, Azure Kinect recordings). The
//! intrinsics file says how raw values become points:
//!
//! ```json
//! { "fx": 194.0, "fy": 194.0, "cx": 111.5, "cy": 85.5, "depth_scale": 0.001, "invalid": 0 }
//! ```
//!
//! `fx fy cx cy` in pixels (pixel centres at integers); `depth_scale` the
//! user units per raw value (0.001 reads millimetres as metres; TUM's
//! 5,000-per-metre PNGs take 0.0002; BOP's `camera.json` gives millimetres
//! per raw value, so multiply its `depth_scale` by 0.001 for metres);
//! `invalid` the raw value of a missing pixel besides 0 (optional, 0).
//! The PNG is decoded with the `png` crate (the reference Rust decoder,
//! also under `image`); only 16-bit grayscale is accepted, since an 8-bit
//! image holds no usable depth.

use std::path::Path;

use pcrnet_core::scene::Intrinsics;

/// A depth image: `width x height` raw values in row order.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DepthFrame {
    /// Raw values, row order.
    pub depth: Vec<u16>,
    /// Pixels per row.
    pub width: usize,
    /// Rows.
    pub height: usize,
}

/// The intrinsics file's contents.
#[derive(Debug, Clone, Copy, PartialEq, serde::Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields)]
pub struct CameraFile {
    /// Focal length along u, pixels.
    pub fx: f32,
    /// Focal length along v, pixels.
    pub fy: f32,
    /// Principal point, column.
    pub cx: f32,
    /// Principal point, row.
    pub cy: f32,
    /// User units per raw value.
    pub depth_scale: f32,
    /// Raw value of a missing pixel besides 0.
    #[serde(default)]
    pub invalid: u16,
}

impl CameraFile {
    /// The pinhole intrinsics.
    pub fn intrinsics(&self) -> Intrinsics {
        Intrinsics {
            fx: self.fx,
            fy: self.fy,
            cx: self.cx,
            cy: self.cy,
        }
    }
}

/// What can go wrong reading a depth image or its intrinsics.
#[derive(Debug, thiserror::Error)]
pub enum DepthError {
    /// The file cannot be read.
    #[error("reading {path}: {error}")]
    Io {
        /// The file.
        path: String,
        /// Why (printed in the message, so not also the error's source).
        error: std::io::Error,
    },
    /// The PNG does not decode.
    #[error("{path}: not a readable PNG ({message})")]
    Png {
        /// The file.
        path: String,
        /// The decoder's words.
        message: String,
    },
    /// The PNG decodes but is not 16-bit grayscale.
    #[error(
        "{path}: a depth image must be 16-bit grayscale, this one is {color:?} at {bits} bits; save the depth channel as a 16-bit PNG"
    )]
    NotDepth {
        /// The file.
        path: String,
        /// Its colour type.
        color: png::ColorType,
        /// Its bits per sample.
        bits: u8,
    },
    /// The intrinsics file is not the JSON described in this module.
    #[error(
        "{path}: not an intrinsics file ({message}); expected {{\"fx\": .., \"fy\": .., \"cx\": .., \"cy\": .., \"depth_scale\": .., \"invalid\": 0}} in pixels and user units per raw value"
    )]
    Camera {
        /// The file.
        path: String,
        /// What is wrong.
        message: String,
    },
}

/// Reads a 16-bit grayscale PNG depth image.
///
/// # Errors
/// [`DepthError`] naming the file.
pub fn read_png(path: &Path) -> Result<DepthFrame, DepthError> {
    let name = path.display().to_string();
    let bytes = std::fs::read(path).map_err(|error| DepthError::Io {
        path: name.clone(),
        error,
    })?;
    parse_png(&bytes).map_err(|e| match e {
        ParseError::Png(message) => DepthError::Png {
            path: name,
            message,
        },
        ParseError::NotDepth(color, bits) => DepthError::NotDepth {
            path: name,
            color,
            bits,
        },
    })
}

/// Why PNG bytes are not a depth image.
#[derive(Debug)]
pub enum ParseError {
    /// They do not decode.
    Png(String),
    /// They are not 16-bit grayscale: colour type and bits.
    NotDepth(png::ColorType, u8),
}

/// Decodes PNG bytes as a 16-bit grayscale depth image (big-endian
/// samples, as PNG stores them).
///
/// # Errors
/// [`ParseError`].
pub fn parse_png(bytes: &[u8]) -> Result<DepthFrame, ParseError> {
    let decoder = png::Decoder::new(std::io::Cursor::new(bytes));
    let mut reader = decoder
        .read_info()
        .map_err(|e| ParseError::Png(e.to_string()))?;
    let info = reader.info();
    let (color, bits) = (info.color_type, info.bit_depth);
    if color != png::ColorType::Grayscale || bits != png::BitDepth::Sixteen {
        return Err(ParseError::NotDepth(color, bits as u8));
    }
    let (width, height) = (info.width as usize, info.height as usize);
    // The decoder's default limits (64 MiB) bound this allocation.
    let size = reader.output_buffer_size();
    let mut buffer = vec![0u8; size];
    let frame = reader
        .next_frame(&mut buffer)
        .map_err(|e| ParseError::Png(e.to_string()))?;
    let bytes = buffer.get(..frame.buffer_size()).unwrap_or_default();
    let depth: Vec<u16> = bytes
        .chunks_exact(2)
        .map(|b| u16::from_be_bytes([b[0], b[1]]))
        .collect();
    if depth.len() != width * height {
        return Err(ParseError::Png(format!(
            "{} samples for {width} x {height}",
            depth.len()
        )));
    }
    Ok(DepthFrame {
        depth,
        width,
        height,
    })
}

/// Writes `frame` as a 16-bit grayscale PNG.
///
/// # Errors
/// The file cannot be written, or the frame's size is not `depth.len()`.
pub fn write_png(path: &Path, frame: &DepthFrame) -> std::io::Result<()> {
    if frame.depth.len() != frame.width * frame.height {
        return Err(std::io::Error::other("depth length is not width x height"));
    }
    let file = std::io::BufWriter::new(std::fs::File::create(path)?);
    let (w, h) = (
        u32::try_from(frame.width).map_err(std::io::Error::other)?,
        u32::try_from(frame.height).map_err(std::io::Error::other)?,
    );
    let mut encoder = png::Encoder::new(file, w, h);
    encoder.set_color(png::ColorType::Grayscale);
    encoder.set_depth(png::BitDepth::Sixteen);
    let mut writer = encoder.write_header().map_err(std::io::Error::other)?;
    let bytes: Vec<u8> = frame.depth.iter().flat_map(|d| d.to_be_bytes()).collect();
    writer
        .write_image_data(&bytes)
        .map_err(std::io::Error::other)?;
    writer.finish().map_err(std::io::Error::other)
}

/// Reads an intrinsics file.
///
/// # Errors
/// [`DepthError`] naming the file.
pub fn read_camera(path: &Path) -> Result<CameraFile, DepthError> {
    let name = path.display().to_string();
    let text = std::fs::read_to_string(path).map_err(|error| DepthError::Io {
        path: name.clone(),
        error,
    })?;
    serde_json::from_str(&text).map_err(|e| DepthError::Camera {
        path: name,
        message: e.to_string(),
    })
}

//! Plain text point lists (`.xyz`, `.txt`, `.csv`): one point per line,
//! the first three numbers being x, y and z, separated by whitespace and/or
//! commas. Further columns (normals, colours, labels) are ignored, blank
//! lines and `#` comments (whole-line or trailing) are skipped, and so is a
//! first line of column names (no token of it a number, as `x,y,z`).

use super::{DEFAULT_MAX_POINTS, FormatError, parse_coordinate, parse_num, text};

/// Parses an XYZ text file held in memory and returns its finite points.
pub fn parse(bytes: &[u8]) -> Result<Vec<[f32; 3]>, FormatError> {
    parse_limited(bytes, DEFAULT_MAX_POINTS)
}

/// [`parse`], refusing more than `max_points` point lines.
pub fn parse_limited(bytes: &[u8], max_points: usize) -> Result<Vec<[f32; 3]>, FormatError> {
    parse_f64_limited(bytes, max_points).map(super::to_f32)
}

/// [`parse_limited`] at full precision: coordinates as `f64` (binary `f32`
/// fields widen exactly, text and `f64` fields are not rounded). Every
/// point read is returned, non-finite ones included: [`parse_limited`] and
/// [`super::Format::parse_local`] drop them (the latter counts them).
pub fn parse_f64_limited(bytes: &[u8], max_points: usize) -> Result<Vec<[f64; 3]>, FormatError> {
    let body = text(bytes, "XYZ")?;
    let mut out = Vec::new();
    let mut header_seen = false;
    for (i, line) in body.lines().enumerate() {
        let line = line.split('#').next().unwrap_or_default();
        let mut toks = line
            .split(|c: char| c.is_whitespace() || c == ',')
            .filter(|t| !t.is_empty());
        let Some(first) = toks.next() else { continue };
        // Column names before the first point (a CSV header).
        if out.is_empty() && !header_seen && parse_num(first).is_none() {
            let mut rest = toks.clone();
            if rest.all(|t| parse_num(t).is_none()) {
                header_seen = true;
                continue;
            }
        }
        header_seen = true;
        FormatError::check_count("XYZ point lines", out.len() + 1, max_points)?;
        let section = || format!("XYZ line {}", i + 1);
        let mut p = [0f64; 3];
        for (k, v) in p.iter_mut().enumerate() {
            let tok = if k == 0 { Some(first) } else { toks.next() };
            let tok = tok.ok_or_else(|| {
                FormatError::data(section(), format!("expected 3 numbers, found {k}"))
            })?;
            *v = parse_coordinate(tok, k, section())?;
        }
        out.push(p);
    }
    Ok(out)
}

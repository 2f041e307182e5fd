//! PLY (Stanford polygon format) reader: `ascii`, `binary_little_endian` and
//! `binary_big_endian`.
//!
//! The `vertex` element must have scalar `x`, `y` and `z` properties of any
//! type (`float`/`float32`, `double`/`float64`, or an integer type, which is
//! converted). Every other property and element is read past, including list
//! properties such as `face`'s `vertex_indices`, so the whole file is checked
//! against its header: a file cut short anywhere is an error, not a shorter
//! cloud.
//!
//! A focused parser rather than the `ply-rs` crate: `ply-rs` 0.1.3 is
//! unmaintained (old `peg` 0.6 grammar, a `skeptic` build script) and stores
//! every element as a hash map of properties, which is heavy for large
//! clouds when only x, y and z are wanted.

use super::{FormatError, Scalar, next_line, parse_num, snippet, text};

const FMT: &str = "PLY";

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Encoding {
    Ascii,
    BinaryLittleEndian,
    BinaryBigEndian,
}

impl Encoding {
    fn name(self) -> &'static str {
        match self {
            Encoding::Ascii => "ascii",
            Encoding::BinaryLittleEndian => "binary_little_endian",
            Encoding::BinaryBigEndian => "binary_big_endian",
        }
    }
}

#[derive(Debug, Clone, Copy)]
enum Kind {
    Scalar(Scalar),
    List { count: Scalar, item: Scalar },
}

#[derive(Debug, Clone)]
struct Property {
    name: String,
    kind: Kind,
}

#[derive(Debug, Clone)]
struct Element {
    name: String,
    count: usize,
    props: Vec<Property>,
}

#[derive(Debug)]
struct Header {
    encoding: Encoding,
    elements: Vec<Element>,
    /// Index of the `vertex` element in `elements`.
    vertex: usize,
    /// Property indices and types of x, y and z within the vertex element.
    xyz: [(usize, Scalar); 3],
    body_start: usize,
}

/// Parses a PLY file held in memory and returns the finite vertex positions.
pub fn parse(bytes: &[u8]) -> Result<Vec<[f32; 3]>, FormatError> {
    parse_limited(bytes, super::DEFAULT_MAX_POINTS)
}

/// [`parse`], refusing a file whose `vertex` element count exceeds `max_points`.
pub fn parse_limited(bytes: &[u8], max_points: usize) -> Result<Vec<[f32; 3]>, FormatError> {
    parse_f64_limited(bytes, max_points).map(super::to_f32)
}

/// [`parse_limited`] at full precision: coordinates as `f64` (binary `f32`
/// fields widen exactly, text and `f64` fields are not rounded). Every
/// point read is returned, non-finite ones included: [`parse_limited`] and
/// [`super::Format::parse_local`] drop them (the latter counts them).
pub fn parse_f64_limited(bytes: &[u8], max_points: usize) -> Result<Vec<[f64; 3]>, FormatError> {
    let h = parse_header(bytes)?;
    let vertices = h.elements.get(h.vertex).map_or(0, |e| e.count);
    FormatError::check_count("PLY element vertex", vertices, max_points)?;
    let body = bytes.get(h.body_start..).unwrap_or_default();
    match h.encoding {
        Encoding::Ascii => parse_ascii(&h, body),
        Encoding::BinaryLittleEndian => parse_binary(&h, body, false),
        Encoding::BinaryBigEndian => parse_binary(&h, body, true),
    }
}

fn err(message: impl Into<String>) -> FormatError {
    FormatError::header(FMT, message)
}

fn scalar_type(name: &str) -> Option<Scalar> {
    Some(match name {
        "char" | "int8" => Scalar::I8,
        "uchar" | "uint8" => Scalar::U8,
        "short" | "int16" => Scalar::I16,
        "ushort" | "uint16" => Scalar::U16,
        "int" | "int32" => Scalar::I32,
        "uint" | "uint32" => Scalar::U32,
        "float" | "float32" => Scalar::F32,
        "double" | "float64" => Scalar::F64,
        _ => return None,
    })
}

fn parse_header(bytes: &[u8]) -> Result<Header, FormatError> {
    let mut pos = 0;
    match next_line(bytes, &mut pos) {
        Some(l) if l.trim_ascii() == b"ply" => {}
        None => return Err(err("file is empty")),
        Some(_) => return Err(err("first line is not \"ply\" (not a PLY file?)")),
    }
    let mut lineno = 1;
    let mut encoding = None;
    let mut elements: Vec<Element> = Vec::new();
    loop {
        let Some(raw) = next_line(bytes, &mut pos) else {
            return Err(err("no end_header line (file ends inside the header)"));
        };
        lineno += 1;
        let line = std::str::from_utf8(raw)
            .map_err(|_| err(format!("line {lineno} is not text")))?
            .trim();
        let toks: Vec<&str> = line.split_ascii_whitespace().collect();
        match toks.as_slice() {
            [] => {}
            ["comment" | "obj_info", ..] => {}
            ["end_header"] => break,
            ["format", enc, _version] => {
                encoding = Some(match *enc {
                    "ascii" => Encoding::Ascii,
                    "binary_little_endian" => Encoding::BinaryLittleEndian,
                    "binary_big_endian" => Encoding::BinaryBigEndian,
                    other => {
                        return Err(err(format!("unknown format {}", snippet(other))));
                    }
                })
            }
            ["element", name, count] => {
                let count = count.parse::<usize>().map_err(|_| {
                    err(format!(
                        "element {} count {} is not a number",
                        snippet(name),
                        snippet(count)
                    ))
                })?;
                elements.push(Element {
                    name: name.to_string(),
                    count,
                    props: Vec::new(),
                });
            }
            ["property", "list", count_ty, item_ty, name] => {
                let el = elements
                    .last_mut()
                    .ok_or_else(|| err(format!("line {lineno}: property before any element")))?;
                let count = scalar_type(count_ty)
                    .filter(|s| s.is_integer())
                    .ok_or_else(|| {
                        err(format!(
                            "list {}: count type {} is not an integer type",
                            snippet(name),
                            snippet(count_ty)
                        ))
                    })?;
                let item = scalar_type(item_ty).ok_or_else(|| {
                    err(format!(
                        "list {}: unknown item type {}",
                        snippet(name),
                        snippet(item_ty)
                    ))
                })?;
                el.props.push(Property {
                    name: name.to_string(),
                    kind: Kind::List { count, item },
                });
            }
            ["property", ty, name] => {
                let el = elements
                    .last_mut()
                    .ok_or_else(|| err(format!("line {lineno}: property before any element")))?;
                let s = scalar_type(ty).ok_or_else(|| {
                    err(format!(
                        "property {}: unknown type {}",
                        snippet(name),
                        snippet(ty)
                    ))
                })?;
                el.props.push(Property {
                    name: name.to_string(),
                    kind: Kind::Scalar(s),
                });
            }
            _ => {
                return Err(err(format!(
                    "line {lineno}: cannot parse {}",
                    snippet(line)
                )));
            }
        }
    }
    let encoding = encoding.ok_or_else(|| err("no format line"))?;
    let vertex = elements
        .iter()
        .position(|e| e.name == "vertex")
        .ok_or_else(|| err("no vertex element"))?;
    let mut xyz = [(0usize, Scalar::F32); 3];
    for (k, c) in ["x", "y", "z"].iter().enumerate() {
        let props = &elements[vertex].props;
        let i = props
            .iter()
            .position(|p| p.name == *c)
            .ok_or_else(|| err(format!("vertex element has no {c} property")))?;
        let Kind::Scalar(s) = props[i].kind else {
            return Err(err(format!("vertex property {c} is a list")));
        };
        xyz[k] = (i, s);
    }
    Ok(Header {
        encoding,
        elements,
        vertex,
        xyz,
        body_start: pos,
    })
}

fn parse_binary(h: &Header, body: &[u8], be: bool) -> Result<Vec<[f64; 3]>, FormatError> {
    let enc = h.encoding.name();
    let mut pos = 0usize;
    let mut out = Vec::new();
    for (ei, el) in h.elements.iter().enumerate() {
        let is_vertex = ei == h.vertex;
        let section = format!("{enc} element {}", snippet(&el.name));
        if el.props.is_empty() {
            continue;
        }
        let scalar_row: Option<usize> = el.props.iter().try_fold(0usize, |acc, p| match p.kind {
            Kind::Scalar(s) => acc.checked_add(s.size()),
            Kind::List { .. } => None,
        });
        if let Some(row) = scalar_row {
            // Fixed-size rows: check the whole element is there at once.
            let avail = body.len() - pos;
            let need = el.count.checked_mul(row).filter(|&n| n <= avail);
            let Some(need) = need else {
                return Err(FormatError::Truncated {
                    section,
                    expected: (el.count as u64).saturating_mul(row as u64),
                    unit: "bytes",
                    found: avail as u64,
                });
            };
            let data = &body[pos..pos + need];
            if is_vertex {
                let offsets: Vec<usize> = el
                    .props
                    .iter()
                    .scan(0usize, |off, p| {
                        let here = *off;
                        if let Kind::Scalar(s) = p.kind {
                            *off += s.size();
                        }
                        Some(here)
                    })
                    .collect();
                out.try_reserve_exact(el.count).map_err(|_| {
                    FormatError::data(section.clone(), super::out_of_memory(el.count))
                })?;
                for rec in data.chunks_exact(row) {
                    let mut p = [0f64; 3];
                    for (v, &(pi, s)) in p.iter_mut().zip(&h.xyz) {
                        *v = rec
                            .get(offsets[pi]..)
                            .and_then(|b| s.read(b, be))
                            .ok_or_else(|| {
                                FormatError::data(section.clone(), "property outside row")
                            })?;
                    }
                    out.push(p);
                }
            }
            pos += need;
            continue;
        }
        // Rows with list properties: walk them one by one. Every row
        // consumes at least one byte, so the loop is bounded by the input.
        for r in 0..el.count {
            let ends =
                || FormatError::truncated(section.clone(), el.count as u64, "rows", r as u64);
            let mut p = [0f64; 3];
            for (pi, prop) in el.props.iter().enumerate() {
                match prop.kind {
                    Kind::Scalar(s) => {
                        let v = body
                            .get(pos..)
                            .and_then(|b| s.read(b, be))
                            .ok_or_else(ends)?;
                        pos += s.size();
                        if is_vertex && let Some(k) = h.xyz.iter().position(|&(x, _)| x == pi) {
                            p[k] = v;
                        }
                    }
                    Kind::List { count, item } => {
                        let n = body
                            .get(pos..)
                            .and_then(|b| count.read(b, be))
                            .ok_or_else(ends)?;
                        pos += count.size();
                        if n < 0.0 {
                            return Err(FormatError::data(
                                section.clone(),
                                format!("row {r}: list {} has negative length {n}", prop.name),
                            ));
                        }
                        let skip = (n as usize)
                            .checked_mul(item.size())
                            .filter(|&s| s <= body.len() - pos)
                            .ok_or_else(ends)?;
                        pos += skip;
                    }
                }
            }
            if is_vertex {
                out.push(p);
            }
        }
    }
    Ok(out)
}

fn parse_ascii(h: &Header, body: &[u8]) -> Result<Vec<[f64; 3]>, FormatError> {
    let body = text(body, "ascii data")?;
    let mut toks = body.split_ascii_whitespace();
    let mut out = Vec::new();
    for (ei, el) in h.elements.iter().enumerate() {
        let is_vertex = ei == h.vertex;
        let section = format!("ascii element {}", snippet(&el.name));
        if el.props.is_empty() {
            continue;
        }
        // Every row consumes at least one token, so the loop is bounded by
        // the input whatever the declared count.
        for r in 0..el.count {
            let ends =
                || FormatError::truncated(section.clone(), el.count as u64, "rows", r as u64);
            let mut p = [0f64; 3];
            for (pi, prop) in el.props.iter().enumerate() {
                match prop.kind {
                    Kind::Scalar(_) => {
                        let tok = toks.next().ok_or_else(ends)?;
                        if is_vertex && let Some(k) = h.xyz.iter().position(|&(x, _)| x == pi) {
                            p[k] = parse_num(tok).ok_or_else(|| {
                                FormatError::data(
                                    format!("{section} row {r}"),
                                    format!("{} value {} is not a number", prop.name, snippet(tok)),
                                )
                            })?;
                        }
                    }
                    Kind::List { .. } => {
                        let tok = toks.next().ok_or_else(ends)?;
                        let n = tok.parse::<u64>().map_err(|_| {
                            FormatError::data(
                                format!("{section} row {r}"),
                                format!(
                                    "list {} length {} is not a count",
                                    prop.name,
                                    snippet(tok)
                                ),
                            )
                        })?;
                        for _ in 0..n {
                            toks.next().ok_or_else(ends)?;
                        }
                    }
                }
            }
            if is_vertex {
                out.push(p);
            }
        }
    }
    Ok(out)
}

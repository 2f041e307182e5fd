//! OFF (Object File Format) mesh reader and area-weighted surface sampling.
//!
//! Accepted layout (text, `#` starts a comment):
//!
//! ```text
//! OFF                 # also COFF, NOFF, CNOFF, STOFF...; or no keyword at all
//! nv nf ne            # ne is ignored and may be missing
//! x y z [extra...]    # nv lines; colours / normals after x y z are ignored
//! k i1 i2 ... ik [..] # nf lines; polygons are triangulated as a fan
//! ```
//!
//! The counts may also sit on the keyword line (`OFF 8 6 0`) or be glued to
//! it, as in some ModelNet files (`OFF490 500 0`). Faces with fewer than three
//! vertices add no area and are skipped. Binary OFF and 4D/nD variants are
//! not supported.
//!
//! [`sample`] draws points uniformly over the surface: a triangle is chosen
//! with probability proportional to its area, then a point inside it by the
//! square-root barycentric method, from a `ChaCha8Rng` seeded with the given
//! seed, so the result depends only on the mesh, `n` and the seed.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::{FormatError, parse_coordinate, parse_num, snippet, text};

const FMT: &str = "OFF";

/// A triangle mesh read from an OFF file.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Mesh {
    /// Vertex positions, as written in the file (not rounded to `f32`).
    pub vertices: Vec<[f64; 3]>,
    /// Triangles as indices into `vertices` (polygons already fanned).
    pub triangles: Vec<[usize; 3]>,
}

/// Parses an OFF file held in memory into a triangle mesh.
pub fn parse(bytes: &[u8]) -> Result<Mesh, FormatError> {
    parse_limited(bytes, super::DEFAULT_MAX_POINTS)
}

/// [`parse`], refusing more than `max_points` vertices or faces.
pub fn parse_limited(bytes: &[u8], max_points: usize) -> Result<Mesh, FormatError> {
    let body = text(bytes, FMT)?;
    // Content lines with their 1-based line numbers, comments removed.
    let mut lines = body.lines().enumerate().filter_map(|(i, l)| {
        let l = l.split('#').next().unwrap_or_default().trim();
        (!l.is_empty()).then_some((i + 1, l))
    });

    let Some((_, first)) = lines.next() else {
        return Err(FormatError::header(FMT, "file is empty"));
    };
    let mut first_toks = first.split_ascii_whitespace();
    let keyword = first_toks.next().unwrap_or_default();
    let mut counts: Vec<&str> = Vec::new();
    match keyword.find("OFF") {
        Some(at) if keyword[..at].chars().all(|c| "STCN".contains(c)) => {
            // ModelNet quirk: "OFF490 500 0" has the vertex count glued on.
            let glued = &keyword[at + 3..];
            if !glued.is_empty() {
                counts.push(glued);
            }
            counts.extend(first_toks);
        }
        Some(_) => {
            return Err(FormatError::header(
                FMT,
                format!("unsupported variant {}", snippet(keyword)),
            ));
        }
        // No keyword: the first line holds the counts.
        None if parse_num(keyword).is_some() => {
            counts.push(keyword);
            counts.extend(first_toks);
        }
        None => {
            return Err(FormatError::header(
                FMT,
                format!(
                    "first line {} is neither OFF nor vertex/face counts (not an OFF file?)",
                    snippet(first)
                ),
            ));
        }
    }
    if counts.first() == Some(&"BINARY") {
        return Err(FormatError::header(FMT, "binary OFF is not supported"));
    }
    if counts.is_empty() {
        let Some((_, l)) = lines.next() else {
            return Err(FormatError::header(FMT, "no vertex/face count line"));
        };
        counts.extend(l.split_ascii_whitespace());
    }
    let count = |i: usize, what: &str| -> Result<usize, FormatError> {
        let tok = counts
            .get(i)
            .copied()
            .ok_or_else(|| FormatError::header(FMT, format!("count line has no {what} count")))?;
        tok.parse::<usize>().map_err(|_| {
            FormatError::header(
                FMT,
                format!("{what} count {} is not a number", snippet(tok)),
            )
        })
    };
    let nv = count(0, "vertex")?;
    let nf = count(1, "face")?;
    FormatError::check_count("OFF vertex count", nv, max_points)?;
    FormatError::check_count("OFF face count", nf, max_points)?;

    // No capacity from the counts: vectors grow with the lines present.
    let mut vertices = Vec::new();
    for i in 0..nv {
        let Some((lineno, l)) = lines.next() else {
            return Err(FormatError::truncated(
                "OFF vertices",
                nv as u64,
                "vertices",
                i as u64,
            ));
        };
        let section = || format!("OFF line {lineno} (vertex {i})");
        let mut toks = l.split_ascii_whitespace();
        let mut p = [0f64; 3];
        for (k, v) in p.iter_mut().enumerate() {
            let tok = toks
                .next()
                .ok_or_else(|| FormatError::data(section(), "expected 3 coordinates"))?;
            *v = parse_coordinate(tok, k, section())?;
        }
        if !p.iter().all(|v| v.is_finite()) {
            return Err(FormatError::data(section(), "non-finite coordinate"));
        }
        vertices.push(p);
    }

    let mut triangles = Vec::new();
    for f in 0..nf {
        let Some((lineno, l)) = lines.next() else {
            return Err(FormatError::truncated(
                "OFF faces",
                nf as u64,
                "faces",
                f as u64,
            ));
        };
        let section = || format!("OFF line {lineno} (face {f})");
        let mut toks = l.split_ascii_whitespace();
        let k_tok = toks.next().unwrap_or_default();
        let k = k_tok.parse::<usize>().map_err(|_| {
            FormatError::data(
                section(),
                format!("vertex count {} is not a number", snippet(k_tok)),
            )
        })?;
        let mut index = |j: usize| -> Result<usize, FormatError> {
            let tok = toks.next().ok_or_else(|| {
                FormatError::data(section(), format!("expected {k} vertex indices, found {j}"))
            })?;
            let i = tok.parse::<usize>().map_err(|_| {
                FormatError::data(
                    section(),
                    format!("vertex index {} is not a number", snippet(tok)),
                )
            })?;
            if i >= nv {
                return Err(FormatError::data(
                    section(),
                    format!("vertex index {i} out of range (mesh has {nv} vertices)"),
                ));
            }
            Ok(i)
        };
        if k < 3 {
            // Points and edges have no area; still check the indices.
            for j in 0..k {
                index(j)?;
            }
            continue;
        }
        let a = index(0)?;
        let mut prev = index(1)?;
        for j in 2..k {
            let cur = index(j)?;
            triangles.push([a, prev, cur]);
            prev = cur;
        }
    }
    Ok(Mesh {
        vertices,
        triangles,
    })
}

/// Samples `n` points uniformly over the surface of `mesh`, deterministically
/// for a given `seed`. Fails if the mesh has no triangles or zero total area.
pub fn sample(mesh: &Mesh, n: usize, seed: u64) -> Result<Vec<[f32; 3]>, FormatError> {
    sample_about(mesh, [0.0; 3], n, seed)
}

/// [`sample`] with the mesh moved by `-origin` first: each vertex becomes
/// `(v - origin)` rounded to `f32` (with the origin at zero, the vertex
/// rounded to `f32`), and the points are sampled from those triangles. A
/// vertex that does not fit `f32` there is an error.
pub fn sample_about(
    mesh: &Mesh,
    origin: [f64; 3],
    n: usize,
    seed: u64,
) -> Result<Vec<[f32; 3]>, FormatError> {
    if mesh.triangles.is_empty() {
        return Err(FormatError::Mesh("no faces to sample from".into()));
    }
    let corner = |i: usize| -> Result<[f64; 3], FormatError> {
        let v = mesh.vertices.get(i).ok_or_else(|| {
            FormatError::Mesh(format!(
                "vertex index {i} out of range (mesh has {} vertices)",
                mesh.vertices.len()
            ))
        })?;
        super::localise(*v, origin)
            .map(|p| p.map(f64::from))
            .ok_or_else(|| {
                FormatError::Mesh(format!(
                    "vertex {i} {v:?} does not fit f32 (move the mesh nearer its origin)"
                ))
            })
    };
    let mut tris = Vec::with_capacity(mesh.triangles.len());
    let mut cumulative = Vec::with_capacity(mesh.triangles.len());
    let mut total = 0f64;
    for t in &mesh.triangles {
        let [a, b, c] = [corner(t[0])?, corner(t[1])?, corner(t[2])?];
        let u = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
        let v = [c[0] - a[0], c[1] - a[1], c[2] - a[2]];
        let cross = [
            u[1] * v[2] - u[2] * v[1],
            u[2] * v[0] - u[0] * v[2],
            u[0] * v[1] - u[1] * v[0],
        ];
        total += 0.5 * (cross[0] * cross[0] + cross[1] * cross[1] + cross[2] * cross[2]).sqrt();
        cumulative.push(total);
        tris.push([a, b, c]);
    }
    if !(total > 0.0 && total.is_finite()) {
        return Err(FormatError::Mesh(format!(
            "total surface area is {total}, nothing to sample"
        )));
    }

    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut out = Vec::with_capacity(n);
    for _ in 0..n {
        let r = rng.random::<f64>() * total;
        // First triangle whose cumulative area exceeds r: zero-area
        // triangles are never picked.
        let t = cumulative.partition_point(|&c| c <= r).min(tris.len() - 1);
        let [a, b, c] = tris[t];
        let s = rng.random::<f64>().sqrt();
        let r2 = rng.random::<f64>();
        let w = [1.0 - s, s * (1.0 - r2), s * r2];
        let mut p = [0f32; 3];
        for (k, out_k) in p.iter_mut().enumerate() {
            let v = w[0] * a[k] + w[1] * b[k] + w[2] * c[k];
            // Rounding must not push a point off the triangle's bounds.
            let lo = a[k].min(b[k]).min(c[k]);
            let hi = a[k].max(b[k]).max(c[k]);
            *out_k = v.clamp(lo, hi) as f32;
        }
        out.push(p);
    }
    Ok(out)
}

/// Parses an OFF file and samples `n` points from its surface (see
/// [`sample`]); a file without triangles is a point cloud: its finite
/// vertices, as stored.
pub fn parse_sampled(bytes: &[u8], n: usize, seed: u64) -> Result<Vec<[f32; 3]>, FormatError> {
    parse_sampled_limited(bytes, n, seed, super::DEFAULT_MAX_POINTS)
}

/// [`parse_sampled`] with [`parse_limited`]'s limit.
pub fn parse_sampled_limited(
    bytes: &[u8],
    n: usize,
    seed: u64,
    max_points: usize,
) -> Result<Vec<[f32; 3]>, FormatError> {
    let mesh = parse_limited(bytes, max_points)?;
    if mesh.triangles.is_empty() {
        // Vertices without a surface (`OFF` / `N 0 0`, a common way to store
        // a scan, or only point and edge "faces"): a point cloud.
        return Ok(super::to_f32(mesh.vertices));
    }
    sample(&mesh, n, seed)
}

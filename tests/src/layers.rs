//! Instructions per MAC for every layer, measured on the device by
//! prefixes: for an architecture with encoder widths `E` and head widths
//! `H`, random models with the encoder `E[..k]` (k = 1..=|E|, no hidden head
//! layer) and with the whole encoder and the head `H[..k]` (k = 0..=|H|)
//! encode one 1,024-point cloud at tile 8. Encoder layer k's cost is the
//! increase of `encode` from prefix k - 1 to prefix k, head layer k's the
//! increase of `infer - encode`; the increments add up to the whole
//! network's count exactly.
//!
//! What an increment contains, precisely: adding encoder layer k also turns
//! layer k - 1 from the max-pooled last layer into a stored hidden layer,
//! so that layer's larger output step (one per point instead of one per
//! four) is billed to layer k; head layer 0's row is the output layer (7
//! raw outputs) with the pose (quaternion normalisation) and the saturation
//! count, which are not MACs.

use pcrnet_core::Int8Model;

use crate::compare::DeviceRun;
use crate::vectors::{Case, TestModel, random_model};

/// `(encode, infer)` instructions of a model's measured case, if it ran.
pub type Measurement = Option<(u64, u64)>;

/// Blob bytes per device run: the prefixes go in batches that fit the
/// 16 MiB data region with their clouds.
pub const BATCH_BYTES: usize = 14 << 20;

/// Points of the measured cloud.
pub const POINTS: usize = 1024;

/// The architectures measured: the paper's, the shipped embedded default
/// and a narrow one.
pub const ARCHITECTURES: [(&str, &[u16], &[u16]); 3] = [
    (
        "paper",
        pcrnet_core::arch::PAPER_ENCODER,
        pcrnet_core::arch::PCRNET_HEAD,
    ),
    ("embedded default", &[32, 64, 128, 256], &[256, 128, 64]),
    ("narrow", &[16, 24, 64], &[48, 32]),
];

/// One prefix model and where it sits.
pub struct Prefix {
    /// Index into [`ARCHITECTURES`].
    pub arch: usize,
    /// Encoder layers in the model.
    pub encoder: usize,
    /// Hidden head layers in the model.
    pub head: usize,
    /// The model.
    pub model: TestModel,
}

/// Every prefix model of every architecture, seeded.
pub fn prefixes() -> Vec<Prefix> {
    let mut out = Vec::new();
    for (a, (name, enc, head)) in ARCHITECTURES.iter().enumerate() {
        let mut push = |e: usize, h: usize| {
            let label = format!("{name} encoder {:?} head {:?}", &enc[..e], &head[..h]);
            let seed = 900 + 20 * a as u64 + (e + 10 * h) as u64;
            out.push(Prefix {
                arch: a,
                encoder: e,
                head: h,
                model: random_model(&label, seed, &enc[..e], &head[..h]),
            });
        };
        for e in 1..=enc.len() {
            push(e, 0);
        }
        for h in 1..=head.len() {
            push(enc.len(), h);
        }
    }
    out
}

/// Consecutive ranges of `prefixes` whose blobs take at most
/// [`BATCH_BYTES`] together (a larger blob gets a batch of its own).
pub fn batches(prefixes: &[Prefix]) -> Vec<std::ops::Range<usize>> {
    let mut out = Vec::new();
    let (mut start, mut bytes) = (0, 0);
    for (i, p) in prefixes.iter().enumerate() {
        if i > start && bytes + p.model.blob.len() > BATCH_BYTES {
            out.push(start..i);
            (start, bytes) = (i, 0);
        }
        bytes += p.model.blob.len();
    }
    if start < prefixes.len() {
        out.push(start..prefixes.len());
    }
    out
}

/// `(encode, infer)` instructions of model `m`'s measured (uniform,
/// 1,024-point) case in one device run.
pub fn measured(cases: &[Case], device: &DeviceRun, m: usize) -> Measurement {
    cases
        .iter()
        .enumerate()
        .find(|(_, c)| c.model == m && c.cloud.len() == POINTS && c.label.starts_with("uniform"))
        .and_then(|(i, _)| device.cases.get(&i))
        .filter(|d| d.infer_instructions > 0)
        .map(|d| (d.encode_instructions, d.infer_instructions))
}

/// Prints the per-layer table (markdown) from the `(encode, infer)`
/// measurements of the [`prefixes`] (same order); fails if one is missing. Each row's MACs are the increase in MACs from the previous
/// prefix (a new head layer also changes the output layer's inputs), so
/// the instructions and the MACs of the rows add up to the network's.
pub fn report(prefixes: &[Prefix], measurements: &[Measurement]) -> anyhow::Result<()> {
    println!(
        "\n| architecture | layer | inputs -> outputs | MACs / point | instructions / point | instr/MAC |\n|---|---|---|---|---|---|"
    );
    let n = POINTS as u64;
    for (a, (name, enc, head)) in ARCHITECTURES.iter().enumerate() {
        // (encode instructions per point, head instructions, encoder MACs
        // per point, head MACs) of prefix (e, h).
        let of = |e: usize, h: usize| -> anyhow::Result<(u64, u64, usize, usize)> {
            let m = prefixes
                .iter()
                .position(|p| p.arch == a && p.encoder == e && p.head == h);
            let found = m.and_then(|m| {
                let model = Int8Model::from_bytes(&prefixes[m].model.blob).ok()?;
                let arch = model.arch();
                let (encode, infer) = (*measurements.get(m)?)?;
                Some((
                    encode / n,
                    infer.saturating_sub(encode),
                    arch.encoder_macs_per_point(),
                    arch.head_macs(),
                ))
            });
            found.ok_or_else(|| anyhow::anyhow!("no measurement for {name} prefix {e}/{h}"))
        };
        let row = |layer: String, shape: String, macs: usize, instr: u64| {
            println!(
                "| {name} | {layer} | {shape} | {macs} | {instr} | {:.2} |",
                instr as f64 / macs.max(1) as f64
            );
        };
        let (mut instr, mut macs, mut inputs) = (0u64, 0usize, 3usize);
        for (k, &w) in enc.iter().enumerate() {
            let (e, _, m, _) = of(k + 1, 0)?;
            let shape = format!("{inputs} -> {w}");
            row(
                format!("encoder {}", k + 1),
                shape,
                m - macs,
                e.saturating_sub(instr),
            );
            (instr, macs, inputs) = (e, m, w as usize);
        }
        let (_, h0, _, m0) = of(enc.len(), 0)?;
        row(
            "head output + pose".into(),
            format!("{} -> 7", 2 * inputs),
            m0,
            h0,
        );
        let (mut instr, mut macs, mut inputs) = (h0, m0, 2 * inputs);
        for (k, &w) in head.iter().enumerate() {
            let (_, h, _, m) = of(enc.len(), k + 1)?;
            let shape = format!("{inputs} -> {w}");
            row(
                format!("head {}", k + 1),
                shape,
                m - macs,
                h.saturating_sub(instr),
            );
            (instr, macs, inputs) = (h, m, w as usize);
        }
    }
    println!();
    Ok(())
}

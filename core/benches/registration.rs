//! Benchmarks of the whole device pipeline on the host.
// criterion_group! generates an undocumented public function.
#![allow(missing_docs)]
//! `Int8Model::register` with the shipped embedded default and its demo
//! source (512 points, `models/`): the network only (the score's
//! nearest-point searches included), one hypothesis with ICP, and the
//! default ten; and the network only on a prepared scratch. The same calls the QEMU harness counts in instructions on
//! the Cortex-M4F (README, "The whole device pipeline"); here their host
//! time, most of it the template's nearest-point search.

use criterion::{Criterion, criterion_group, criterion_main};
use pcrnet_core::{Int8Model, Options};
use std::hint::black_box;

const MODEL: &[u8] = include_bytes!("../../models/embedded-default-int8.pcrn");
/// 512 points, x y z f32 little-endian, user units.
const SOURCE: &[u8] = include_bytes!("../../models/embedded-default-source.f32");

fn registration(c: &mut Criterion) {
    let model = Int8Model::from_bytes(MODEL).expect("the shipped model loads");
    let source: Vec<[f32; 3]> = SOURCE
        .chunks_exact(12)
        .map(|p| [0, 4, 8].map(|i| f32::from_le_bytes([p[i], p[i + 1], p[i + 2], p[i + 3]])))
        .collect();
    let mut scratch = vec![0i8; model.host_scratch_len()];
    let mut group = c.benchmark_group("registration");
    group.sample_size(20);
    let defaults = Options::default();
    for (name, options) in [
        ("network_only", Options::network_only()),
        (
            "k1_icp",
            Options {
                hypotheses: 1,
                ..defaults
            },
        ),
        ("default_k10", defaults),
    ] {
        group.bench_function(name, |b| {
            b.iter(|| {
                model
                    .register(black_box(&source), &options, &mut scratch)
                    .map(|r| r.pose)
            })
        });
    }
    // The network alone on a scratch prepared once (`Int8Model::prepare`),
    // beside the same call on the model itself above.
    let mut prepared = model.prepare(&mut scratch).expect("the host scratch fits");
    let network_only = Options::network_only();
    group.bench_function("network_only_prepared", |b| {
        b.iter(|| {
            prepared
                .register(black_box(&source), &network_only)
                .map(|r| r.pose)
        })
    });
    group.finish();
}

criterion_group!(benches, registration);
criterion_main!(benches);

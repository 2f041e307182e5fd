//! Training step time (forward + backward + Adam) at batch 32, for the
//! paper-size PCRNet and the embedded default, on generated shapes.
//! Throughput is reported in pairs (samples) per second.
// criterion_group! generates an undocumented public function.
#![allow(missing_docs)]

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use pcrnet_core::arch::{PAPER_ENCODER, PCRNET_HEAD};
use pcrnet_train::dataset::Dataset;
use pcrnet_train::{EMBEDDED_ENCODER, EMBEDDED_HEAD};
use pcrnet_train::{TrainConfig, Trainer};

fn train_step(c: &mut Criterion) {
    let mut group = c.benchmark_group("train_step");
    group.sample_size(10);
    for (name, encoder, head, points) in [
        ("paper_n1024", PAPER_ENCODER, PCRNET_HEAD, 1024),
        ("embedded_n1024", EMBEDDED_ENCODER, EMBEDDED_HEAD, 1024),
        ("embedded_n256", EMBEDDED_ENCODER, EMBEDDED_HEAD, 256),
    ] {
        let config = TrainConfig {
            encoder: encoder.to_vec(),
            head: head.to_vec(),
            epochs: 1_000_000,
            ..TrainConfig::default()
        };
        let batch = config.batch as u64;
        let data = Dataset::generated(64, points, 1);
        let val = Dataset::generated(2, points, 2);
        let mut trainer = Trainer::new(config, data, val).expect("valid config");
        group.throughput(Throughput::Elements(batch));
        group.bench_function(name, |b| b.iter(|| trainer.step()));
    }
    group.finish();
}

criterion_group!(benches, train_step);
criterion_main!(benches);

//! Benchmarks of the pcrnet-core encoder.
// criterion_group! generates an undocumented public function.
#![allow(missing_docs)]
//! Host throughput of the encoder, int8 and f32, for the paper's widths and
//! a small embedded configuration. Throughput is reported in points/s; the
//! benchmark id carries the MACs per point, so MAC/s = points/s x MACs.

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use pcrnet_core::arch::{PAPER_ENCODER, PCRNET_HEAD};
use pcrnet_core::testing::{SplitMix64, random_f32_blob_into, random_int8_blob_into};
use pcrnet_core::{Arch, F32Model, Int8Model, MAX_TILE};
use std::hint::black_box;

/// A configuration small enough for a microcontroller (int8 blob ~ 215 KB).
const SMALL_ENCODER: &[u16] = &[32, 64, 128, 256];
const SMALL_HEAD: &[u16] = &[256, 128, 64];
const POINTS: usize = 1024;

fn encoder(c: &mut Criterion) {
    let mut rng = SplitMix64(1);
    let cloud: Vec<[f32; 3]> = (0..POINTS)
        .map(|_| [0; 3].map(|_: i32| rng.uniform(-1.0, 1.0)))
        .collect();
    let mut group = c.benchmark_group("encoder");
    group.throughput(Throughput::Elements(POINTS as u64));
    group.sample_size(10);
    for (name, enc, head) in [
        ("small", SMALL_ENCODER, SMALL_HEAD),
        ("paper", PAPER_ENCODER, PCRNET_HEAD),
    ] {
        let macs = Arch::new(enc, head).unwrap().encoder_macs_per_point();
        let (mut arena, mut out) = (vec![0u8; 20 << 20], vec![0u8; 20 << 20]);
        let blob = random_int8_blob_into(2, enc, head, &mut arena, &mut out).unwrap();
        let model = Int8Model::from_bytes(blob).unwrap();
        for tile in [1, MAX_TILE] {
            let mut scratch = vec![0i8; model.scratch_len(tile)];
            let id = BenchmarkId::new(format!("int8_tile{tile}"), format!("{name}_{macs}mac"));
            group.bench_function(id, |b| {
                b.iter(|| {
                    model
                        .encode_tiled(black_box(&cloud), tile, &mut scratch)
                        .map(|f| f[0])
                })
            });
        }
        // The host's scratch: the x86-64 block kernel where it runs.
        let mut scratch = vec![0i8; model.host_scratch_len()];
        let id = BenchmarkId::new("int8_host", format!("{name}_{macs}mac"));
        group.bench_function(id, |b| {
            b.iter(|| model.encode(black_box(&cloud), &mut scratch).map(|f| f[0]))
        });
        let (mut arena, mut out) = (vec![0u8; 20 << 20], vec![0u8; 20 << 20]);
        let blob = random_f32_blob_into(2, enc, head, &mut arena, &mut out).unwrap();
        let model = F32Model::from_bytes(blob).unwrap();
        let mut scratch = vec![0f32; model.tiled_scratch_len()];
        let id = BenchmarkId::new("f32", format!("{name}_{macs}mac"));
        group.bench_function(id, |b| {
            b.iter(|| {
                model
                    .network()
                    .encode(black_box(&cloud), &mut scratch)
                    .map(|f| f[0])
            })
        });
    }
    group.finish();
}

criterion_group!(benches, encoder);
criterion_main!(benches);

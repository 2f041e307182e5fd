//! Helpers the trainer tests share: a small configuration, generated data
//! sets and the weights' bits.

use pcrnet_train::{Dataset, PairConfig, TrainConfig};

/// A small, fast configuration: two epochs of three steps, seeded.
pub fn small_config() -> TrainConfig {
    TrainConfig {
        encoder: vec![16, 32],
        head: vec![32, 16],
        batch: 4,
        epochs: 2,
        steps_per_epoch: Some(3),
        lr: 2e-3,
        seed: 5,
        pairs: PairConfig {
            noise: Some([0.0, 0.02]),
            ..PairConfig::default()
        },
        val_pairs: 8,
        ..TrainConfig::default()
    }
}

/// Generated training (12 shapes) and validation (6) sets of `points` points.
pub fn data_sets(points: usize) -> (Dataset, Dataset) {
    (
        Dataset::generated(12, points, 1),
        Dataset::generated(6, points, 2),
    )
}

/// The weights' bits, to compare runs exactly.
pub fn bits(p: &pcrnet_train::F32Params) -> Vec<u32> {
    p.layers
        .iter()
        .flat_map(|(w, b)| w.iter().chain(b).map(|v| v.to_bits()))
        .collect()
}

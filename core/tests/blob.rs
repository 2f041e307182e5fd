//! The model blob: round trips, and every kind of corruption gives an error, never a panic.

use pcrnet_core::format::{self, CRC_LEN, FORMAT_VERSION, HEADER_LEN, ModelKind};
use pcrnet_core::testing::{SplitMix64, random_f32_blob_into, random_int8_blob_into};
use pcrnet_core::{Error, F32Model, Int8Model};
use proptest::prelude::*;

fn int8_blob() -> Vec<u8> {
    let (mut arena, mut out) = (vec![0u8; 1 << 16], vec![0u8; 1 << 16]);
    random_int8_blob_into(5, &[8, 16], &[12], &mut arena, &mut out)
        .unwrap()
        .to_vec()
}

fn f32_blob() -> Vec<u8> {
    let (mut arena, mut out) = (vec![0u8; 1 << 16], vec![0u8; 1 << 16]);
    random_f32_blob_into(6, &[8, 16], &[12], &mut arena, &mut out)
        .unwrap()
        .to_vec()
}

/// Recomputes the CRC so corruption reaches the payload checks.
fn reseal(blob: &mut [u8]) {
    let n = blob.len() - CRC_LEN;
    let crc = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC).checksum(&blob[..n]);
    blob[n..].copy_from_slice(&crc.to_le_bytes());
}

#[test]
fn header_errors_are_specific() {
    let good = int8_blob();
    assert!(Int8Model::from_bytes(&good).is_ok());

    let mut b = good.clone();
    b[0] = b'X';
    assert_eq!(Int8Model::from_bytes(&b).err(), Some(Error::BadMagic));
    assert_eq!(
        Int8Model::from_bytes(b"PC")
            .err()
            .map(|e| matches!(e, Error::Truncated { .. })),
        Some(true)
    );
    assert_eq!(Int8Model::from_bytes(b"XY").err(), Some(Error::BadMagic));
    assert!(matches!(
        Int8Model::from_bytes(&[]),
        Err(Error::Truncated { .. })
    ));

    let mut b = good.clone();
    b[4..6].copy_from_slice(&(FORMAT_VERSION + 1).to_le_bytes());
    assert_eq!(
        Int8Model::from_bytes(&b).err(),
        Some(Error::UnsupportedVersion {
            found: FORMAT_VERSION + 1
        })
    );
    // A newer blob needs a newer library; an older one, re-exporting.
    let newer = Error::UnsupportedVersion {
        found: FORMAT_VERSION + 1,
    };
    assert!(
        newer.to_string().contains("newer than this build"),
        "{newer}"
    );
    let older = Error::UnsupportedVersion {
        found: FORMAT_VERSION - 1,
    };
    assert!(older.to_string().contains("re-export"), "{older}");

    assert_eq!(
        F32Model::from_bytes(&good).err(),
        Some(Error::WrongKind {
            expected: ModelKind::F32,
            found: 0
        })
    );
    assert_eq!(
        Int8Model::from_bytes(&f32_blob()).err(),
        Some(Error::WrongKind {
            expected: ModelKind::Int8,
            found: 1
        })
    );

    let mut b = good.clone();
    b.push(0);
    assert_eq!(
        Int8Model::from_bytes(&b).err(),
        Some(Error::TrailingData { extra: 1 })
    );

    let mut b = good.clone();
    let mid = HEADER_LEN + 10;
    b[mid] ^= 0x10;
    assert!(matches!(
        Int8Model::from_bytes(&b),
        Err(Error::BadCrc { .. })
    ));
}

#[test]
fn every_truncation_is_an_error() {
    for good in [int8_blob(), f32_blob()] {
        for n in 0..good.len() {
            let r8 = Int8Model::from_bytes(&good[..n]).err();
            let rf = F32Model::from_bytes(&good[..n]).err();
            assert!(r8.is_some() && rf.is_some(), "prefix of {n} bytes accepted");
            if n >= 4 {
                assert!(
                    matches!(
                        r8,
                        Some(Error::Truncated { .. }) | Some(Error::WrongKind { .. })
                    ),
                    "prefix {n}: {r8:?}"
                );
            }
        }
    }
}

#[test]
fn every_single_bit_flip_is_an_error() {
    for good in [int8_blob(), f32_blob()] {
        let kind_int8 = good[6] == 0;
        for byte in 0..good.len() {
            for bit in 0..8 {
                let mut b = good.clone();
                b[byte] ^= 1 << bit;
                let err = if kind_int8 {
                    Int8Model::from_bytes(&b).err()
                } else {
                    F32Model::from_bytes(&b).err()
                };
                assert!(err.is_some(), "flip of bit {bit} in byte {byte} accepted");
            }
        }
    }
}

/// With the CRC recomputed, corruption reaches the decoder and the
/// validation: the result may be a (different) valid model, but never a panic,
/// and a model that loads must run or fail cleanly.
#[test]
fn resealed_corruption_never_panics() {
    let mut rng = SplitMix64(77);
    let pts = [[0.1f32, 0.2, 0.3], [-0.5, 0.4, 0.0], [0.9, -0.9, 0.2]];
    for good in [int8_blob(), f32_blob()] {
        for _ in 0..3000 {
            let mut b = good.clone();
            let flips = 1 + rng.next_u64() % 4;
            for _ in 0..flips {
                let i = HEADER_LEN + (rng.next_u64() as usize % (b.len() - HEADER_LEN - CRC_LEN));
                b[i] ^= 1 << (rng.next_u64() % 8);
            }
            reseal(&mut b);
            if let Ok(m) = Int8Model::from_bytes(&b) {
                let mut s = vec![0i8; m.scratch_len(8)];
                let _ = m.network_pose(&pts, 1, 0.0, &mut s).map(|r| r.0);
            }
            if let Ok(m) = F32Model::from_bytes(&b) {
                let mut s = vec![0f32; m.scratch_len()];
                let _ = m.network_pose(&pts, 1, 0.0, &mut s).map(|r| r.0);
            }
        }
    }
}

#[test]
fn inconsistent_payloads_are_rejected() {
    let bad_shift = vec![40u8; 8];
    let huge_bias = [i32::MAX.to_le_bytes(); 8].concat();
    let good = int8_blob();
    let model = Int8Model::from_bytes(&good).unwrap();
    let mut p = model.payload().clone();
    p.template_feature = &p.template_feature[1..];
    assert!(matches!(
        Int8Model::from_payload(p, format::Trailer::default()),
        Err(Error::InconsistentDimensions { .. })
    ));
    let mut p = model.payload().clone();
    p.encoder[0].shift = &bad_shift;
    assert!(matches!(
        Int8Model::from_payload(p, format::Trailer::default()),
        Err(Error::InvalidParameter { .. })
    ));
    let mut p = model.payload().clone();
    p.encoder[0].bias = &huge_bias;
    assert!(matches!(
        Int8Model::from_payload(p, format::Trailer::default()),
        Err(Error::InvalidParameter { .. })
    ));
    let mut p = model.payload().clone();
    p.input_scale = f32::NAN;
    assert!(matches!(
        Int8Model::from_payload(p, format::Trailer::default()),
        Err(Error::InvalidParameter { .. })
    ));
    let mut p = model.payload().clone();
    p.arch.encoder[0] = 9;
    assert!(matches!(
        Int8Model::from_payload(p, format::Trailer::default()),
        Err(Error::InconsistentDimensions { .. })
    ));
    // Format 3: frame, trained passes and the template's points.
    let mut p = model.payload().clone();
    p.frame.scale = 0.0;
    assert!(matches!(
        Int8Model::from_payload(p, format::Trailer::default()),
        Err(Error::InvalidParameter { .. })
    ));
    let mut p = model.payload().clone();
    p.passes = 0;
    assert!(matches!(
        Int8Model::from_payload(p, format::Trailer::default()),
        Err(Error::InvalidParameter { .. })
    ));
    let mut p = model.payload().clone();
    p.template.points = &p.template.points[6..];
    assert!(matches!(
        Int8Model::from_payload(p, format::Trailer::default()),
        Err(Error::InconsistentDimensions { .. })
    ));
    assert_eq!(model.trained_passes(), 1);
}

#[test]
fn write_then_read_round_trips() {
    let good = int8_blob();
    let model = Int8Model::from_bytes(&good).unwrap();
    let mut out = vec![0u8; good.len()];
    let n = format::write_blob(
        ModelKind::Int8,
        model.payload(),
        &format::Trailer {
            table: model.template().table(),
            lk: model.lk_solver().map(|s| s.stored()),
            residual_floor: model.residual_floor(),
            up: model.up_axis(),
        },
        &mut out,
    )
    .unwrap();
    assert_eq!(&out[..n], &good[..]);
    let mut short = vec![0u8; good.len() - 1];
    assert_eq!(
        format::write_blob(
            ModelKind::Int8,
            model.payload(),
            &format::Trailer::default(),
            &mut short
        )
        .err(),
        Some(Error::BufferTooSmall {
            needed: good.len(),
            available: good.len() - 1
        })
    );
}

proptest! {
    #[test]
    fn arbitrary_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..512)) {
        let _ = Int8Model::from_bytes(&bytes);
        let _ = F32Model::from_bytes(&bytes);
        // Also behind a valid envelope, so the decoder sees them.
        let mut b = b"PCRN".to_vec();
        b.extend_from_slice(&FORMAT_VERSION.to_le_bytes());
        b.push(0);
        b.extend_from_slice(&(bytes.len() as u32).to_le_bytes());
        b.extend_from_slice(&bytes);
        b.extend_from_slice(&[0; 4]);
        reseal(&mut b);
        let _ = Int8Model::from_bytes(&b);
        b[6] = 1;
        reseal(&mut b);
        let _ = F32Model::from_bytes(&b);
    }
}

/// A blob without a head loads only with PointNetLK's solver: written
/// again without it, it is the typed dimensions error naming the solver.
#[test]
fn a_headless_blob_needs_its_solver() {
    let (mut arena, mut out) = (vec![0u8; 1 << 16], vec![0u8; 1 << 16]);
    let headless =
        pcrnet_core::testing::with_random_lk_solver(&int8_blob(), 3, true, &mut arena, &mut out)
            .unwrap()
            .to_vec();
    let model = Int8Model::from_bytes(&headless).unwrap();
    assert!(!model.has_head() && model.lk_solver().is_some());
    let trailer = format::Trailer {
        table: model.template().table(),
        ..format::Trailer::default()
    };
    let mut without = vec![0u8; format::blob_len(model.payload(), &trailer).unwrap()];
    format::write_blob(ModelKind::Int8, model.payload(), &trailer, &mut without).unwrap();
    assert_eq!(
        Int8Model::from_bytes(&without).err(),
        Some(Error::InconsistentDimensions {
            what: "a blob without a head needs PointNetLK's solver"
        })
    );
}

/// A blob of `payload` with `trailer`, written by this build.
fn with_trailer(model: &Int8Model<'_>, trailer: &format::Trailer<'_>) -> Vec<u8> {
    let mut out = vec![0u8; format::blob_len(model.payload(), trailer).unwrap()];
    format::write_blob(ModelKind::Int8, model.payload(), trailer, &mut out).unwrap();
    out
}

/// Format 6 carries the template's residual floor: a blob with one
/// recommends a verdict calibrated by it (the floor plus the noise
/// allowance, never below the default), one without keeps the default,
/// and a floor that is not finite or below 0 is refused by name.
#[test]
fn the_residual_floor_calibrates_the_recommended_verdict() {
    let good = int8_blob();
    let model = Int8Model::from_bytes(&good).unwrap();
    assert_eq!(model.residual_floor(), None);
    let default = pcrnet_core::Options::default().max_residual;
    assert_eq!(model.trained_options().max_residual, default);
    let floored = |floor: f32| format::Trailer {
        table: model.template().table(),
        residual_floor: Some(floor),
        ..format::Trailer::default()
    };
    let high = with_trailer(&model, &floored(0.02));
    let m = Int8Model::from_bytes(&high).unwrap();
    assert_eq!(m.residual_floor(), Some(0.02));
    let want = 0.02 + pcrnet_core::registration::NOISE_ALLOWANCE;
    assert_eq!(m.trained_options().max_residual, want);
    // A low floor leaves the default alone.
    let low = with_trailer(&model, &floored(0.001));
    let m = Int8Model::from_bytes(&low).unwrap();
    assert_eq!(m.trained_options().max_residual, default);
    // A floor of a noisy or cluttered file: capped, never near the
    // residual's own cap (the inlier distance).
    let huge = with_trailer(&model, &floored(0.2));
    let m = Int8Model::from_bytes(&huge).unwrap();
    assert_eq!(
        m.trained_options().max_residual,
        pcrnet_core::registration::MAX_CALIBRATED
    );
    for bad in [f32::NAN, f32::INFINITY, -0.01] {
        assert_eq!(
            Int8Model::from_bytes(&with_trailer(&model, &floored(bad))).err(),
            Some(Error::InconsistentDimensions {
                what: "the template's residual floor must be finite and at least 0"
            }),
            "{bad}"
        );
    }
}

/// A blob of format `version` with `trailer` written after the payload,
/// by hand as that format's exporter did.
fn older_blob(model: &Int8Model<'_>, version: u16, trailer: &impl serde::Serialize) -> Vec<u8> {
    let mut buffer = vec![0u8; 1 << 20];
    let payload = postcard::to_slice(model.payload(), &mut buffer)
        .unwrap()
        .to_vec();
    let mut rest = vec![0u8; 1 << 16];
    let trailer = postcard::to_slice(trailer, &mut rest).unwrap().to_vec();
    let mut blob = b"PCRN".to_vec();
    blob.extend_from_slice(&version.to_le_bytes());
    blob.push(ModelKind::Int8 as u8);
    blob.extend_from_slice(&((payload.len() + trailer.len()) as u32).to_le_bytes());
    blob.extend_from_slice(&payload);
    blob.extend_from_slice(&trailer);
    blob.extend_from_slice(&[0; 4]);
    reseal(&mut blob);
    blob
}

/// A format-5 blob (the table and the solver, no floor) still reads: no
/// floor, the default verdict; a format-6 blob (and the floor) reads with
/// its floor; neither has an up axis.
#[test]
fn format_5_and_6_blobs_still_read() {
    let good = int8_blob();
    let model = Int8Model::from_bytes(&good).unwrap();
    let table = model.template().table();
    let six = older_blob(
        &model,
        6,
        &(table, None::<format::LkSolver<'_>>, Some(0.02f32)),
    );
    let old = Int8Model::from_bytes(&six).unwrap();
    assert_eq!((old.residual_floor(), old.up_axis()), (Some(0.02), None));
    let blob = older_blob(&model, 5, &(table, None::<format::LkSolver<'_>>));
    let old = Int8Model::from_bytes(&blob).unwrap();
    assert_eq!(old.up_axis(), None);
    assert_eq!(old.residual_floor(), None);
    assert_eq!(
        old.trained_options().max_residual,
        pcrnet_core::Options::default().max_residual
    );
    assert_eq!(old.payload(), model.payload());
    assert_eq!(old.template().table(), model.template().table());
}

/// Format 7 carries the template's up axis: the model reports it and its
/// scene options sweep about it; an axis that is not a finite unit vector
/// is refused by name.
#[test]
fn the_up_axis_reaches_the_scene_options() {
    let good = int8_blob();
    let model = Int8Model::from_bytes(&good).unwrap();
    assert_eq!(model.up_axis(), None);
    assert_eq!(model.scene_options().up, None);
    let with_up = |up: [f32; 3]| {
        with_trailer(
            &model,
            &format::Trailer {
                table: model.template().table(),
                up: Some(up),
                ..format::Trailer::default()
            },
        )
    };
    let blob = with_up([0.0, -1.0, 0.0]);
    let m = Int8Model::from_bytes(&blob).unwrap();
    assert_eq!(m.up_axis(), Some([0.0, -1.0, 0.0]));
    let scene = m.scene_options();
    assert_eq!(scene.up, Some([0.0, -1.0, 0.0]));
    assert_eq!(
        pcrnet_core::scene::SceneOptions { up: None, ..scene },
        pcrnet_core::scene::SceneOptions::for_object(m.object_radius())
    );
    for bad in [[0.0, 0.0, 0.0], [0.0, 2.0, 0.0], [f32::NAN, 1.0, 0.0]] {
        assert_eq!(
            Int8Model::from_bytes(&with_up(bad)).err(),
            Some(Error::InconsistentDimensions {
                what: "the template's up axis must be a finite unit vector"
            }),
            "{bad:?}"
        );
    }
}

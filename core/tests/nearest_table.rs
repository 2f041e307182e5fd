//! The closest-point table changes nothing but the cost: the shipped
//! model registers, tracks and scores every source exactly as it does
//! without its table (grid search only), and as its format-3 twin (the same
//! payload under the old header) does.

mod common;

use common::{angle_deg, rotation, template};
use pcrnet_core::format::{self, CRC_LEN, HEADER_LEN, Int8Payload, MAGIC, ModelKind};
use pcrnet_core::pose::Pose;
use pcrnet_core::testing::SplitMix64;
use pcrnet_core::{Int8Model, Options};

const MODEL: &[u8] = include_bytes!("../../models/embedded-default-int8.pcrn");

/// The shipped blob (format 4) with its payload and no table: the current
/// format (`version` [`format::FORMAT_VERSION`]) or the format-3 header (`version` 3, written by hand as format 3's
/// exporter did: header, payload, CRC).
fn without_table(version: u16) -> Vec<u8> {
    let (payload, table): (Int8Payload<'_>, _) =
        format::decode_model(MODEL, ModelKind::Int8).unwrap();
    assert!(table.table.is_some(), "the shipped blob carries a table");
    if version == format::FORMAT_VERSION {
        let mut out = vec![0u8; format::blob_len(&payload, &format::Trailer::default()).unwrap()];
        let n = format::write_blob(
            ModelKind::Int8,
            &payload,
            &format::Trailer::default(),
            &mut out,
        )
        .unwrap();
        assert_eq!(n, out.len());
        return out;
    }
    let mut buffer = vec![0u8; MODEL.len()];
    let body = postcard::to_slice(&payload, &mut buffer).unwrap();
    let mut blob = MAGIC.to_vec();
    blob.extend_from_slice(&version.to_le_bytes());
    blob.push(ModelKind::Int8 as u8);
    blob.extend_from_slice(&(body.len() as u32).to_le_bytes());
    blob.extend_from_slice(body);
    let crc = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC).checksum(&blob);
    blob.extend_from_slice(&crc.to_le_bytes());
    assert_eq!(blob.len(), HEADER_LEN + body.len() + CRC_LEN);
    blob
}

/// Seeded sources: a random part of the template, turned up to 180
/// degrees about a random axis, moved, with noise and a few outliers.
fn sources(count: usize) -> Vec<Vec<[f32; 3]>> {
    let t = template();
    let mut rng = SplitMix64(29);
    (0..count)
        .map(|_| {
            let axis = [0; 3].map(|_: i32| rng.uniform(-1.0, 1.0));
            let truth = Pose {
                translation: [0; 3].map(|_: i32| rng.uniform(-0.3, 0.3)),
                ..rotation(axis, rng.uniform(0.0, 180.0))
            };
            let back = truth.inverse();
            let n = rng.int(40, 400) as usize;
            let sigma = rng.uniform(0.0, 0.02);
            (0..n)
                .map(|_| {
                    let p = back.transform_point(t[rng.int(0, t.len() as i32 - 1) as usize]);
                    let far = rng.int(0, 30) == 0;
                    p.map(|v| {
                        if far {
                            v * 3.0
                        } else {
                            v + rng.uniform(-sigma, sigma)
                        }
                    })
                })
                .collect()
        })
        .collect()
}

#[test]
fn the_table_changes_no_result() {
    let plain4 = without_table(format::FORMAT_VERSION);
    let plain3 = without_table(3);
    let tabled = Int8Model::from_bytes(MODEL).unwrap();
    let models = [
        Int8Model::from_bytes(&plain4).unwrap(),
        Int8Model::from_bytes(&plain3).unwrap(),
    ];
    assert!(tabled.template().table().is_some());
    assert!(models.iter().all(|m| m.template().table().is_none()));
    let mut scratch = vec![0i8; tabled.scratch_len(1)];
    let options = [
        Options::default(),
        Options {
            hypotheses: 1,
            ..Options::default()
        },
    ];
    let (mut reliable, mut tracked) = (0, 0);
    for (i, source) in sources(24).iter().enumerate() {
        let opts = &options[i % 2];
        let want = tabled.register(source, opts, &mut scratch).unwrap();
        reliable += usize::from(want.reliable);
        for m in &models {
            assert_eq!(
                m.register(source, opts, &mut scratch).unwrap(),
                want,
                "source {i}"
            );
        }
        // A tracking step from the registered pose, slightly turned.
        let start = rotation([0.3, 1.0, -0.2], 4.0).then(&want.pose);
        assert!((angle_deg(&start, &want.pose) - 4.0).abs() < 0.01);
        let step = tabled.track(source, &start, opts, &mut scratch).unwrap();
        tracked += usize::from(step.registration.reliable);
        for m in &models {
            assert_eq!(m.track(source, &start, opts, &mut scratch).unwrap(), step);
        }
    }
    // The sources are hard enough to take several paths of the pipeline.
    assert!((4..24).contains(&reliable), "{reliable} of 24 reliable");
    assert!(tracked > 0);
}

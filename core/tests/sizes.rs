//! `scratch_len_for`: the scratch size read from a blob in a `const` is the
//! loaded model's, and is exactly what `register` needs; anything that is
//! not a well-formed int8 blob header and architecture is `None`.

use pcrnet_core::format::{CRC_LEN, HEADER_LEN};
use pcrnet_core::testing::{SplitMix64, random_f32_blob_into, random_int8_blob_into};
use pcrnet_core::{Error, Int8Model, MAX_TILE, Options, scratch_len_for};

const SHIPPED: &[u8] = include_bytes!("../../models/embedded-default-int8.pcrn");
/// Evaluated by the compiler: the function is usable where firmware needs it.
const SHIPPED_SCRATCH: usize = scratch_len_for(SHIPPED, MAX_TILE).expect("not a pcrnet int8 blob");

/// A small cloud around the origin, in the random models' units.
fn cloud(seed: u64, n: usize) -> Vec<[f32; 3]> {
    let mut rng = SplitMix64(seed);
    (0..n)
        .map(|_| [0; 3].map(|_| rng.uniform(-0.5, 0.5)))
        .collect()
}

/// For every tile: the figure of the loaded model; and `register` runs
/// on exactly the one-point figure and fails one byte short of it.
fn check_blob(blob: &[u8], what: &str) {
    let model = Int8Model::from_bytes(blob).unwrap();
    for tile in 1..=MAX_TILE {
        assert_eq!(
            scratch_len_for(blob, tile),
            Some(model.scratch_len(tile)),
            "{what}, tile {tile}"
        );
    }
    assert_eq!(scratch_len_for(blob, 0), None, "{what}, tile 0");
    assert_eq!(scratch_len_for(blob, MAX_TILE + 1), None, "{what}, tile 9");

    let source = cloud(3, 40);
    let options = Options::default();
    let full = scratch_len_for(blob, MAX_TILE).unwrap();
    let want = model
        .register(&source, &options, &mut vec![0i8; full])
        .unwrap();
    let least = scratch_len_for(blob, 1).unwrap();
    let got = model
        .register(&source, &options, &mut vec![0i8; least])
        .unwrap();
    assert_eq!(got, want, "{what}: the same result at tile 1");
    assert!(Int8Model::load(blob, &vec![0i8; least]).is_ok(), "{what}");
    let short = model.register(&source, &options, &mut vec![0i8; least - 1]);
    assert!(
        matches!(short, Err(Error::ScratchTooSmall { .. })),
        "{what}: {short:?}"
    );
}

#[test]
fn shipped_model_matches_the_loaded_model() {
    let model = Int8Model::load(SHIPPED, &vec![0i8; SHIPPED_SCRATCH]).unwrap();
    assert_eq!(SHIPPED_SCRATCH, model.scratch_len(MAX_TILE));
    check_blob(SHIPPED, "shipped model");
}

#[test]
fn random_architectures_match_the_loaded_model() {
    let mut rng = SplitMix64(34);
    let (mut arena, mut out) = (vec![0u8; 1 << 20], vec![0u8; 1 << 20]);
    for case in 0..40 {
        // 1..=8 encoder layers, 0..=8 head layers, widths 1..=200 (some
        // wide enough for two-byte varints); the last case has the most
        // layers the format allows.
        let (ne, nh) = if case == 39 {
            (8, 8)
        } else {
            (rng.int(1, 5) as usize, rng.int(0, 4) as usize)
        };
        let width = |rng: &mut SplitMix64| rng.int(1, 200) as u16;
        let encoder: Vec<u16> = (0..ne).map(|_| width(&mut rng)).collect();
        let head: Vec<u16> = (0..nh).map(|_| width(&mut rng)).collect();
        let blob = random_int8_blob_into(case, &encoder, &head, &mut arena, &mut out).unwrap();
        check_blob(blob, &format!("encoder {encoder:?}, head {head:?}"));
    }
}

#[test]
fn malformed_headers_are_none() {
    let (mut arena, mut out) = (vec![0u8; 1 << 16], vec![0u8; 1 << 16]);
    let blob = random_int8_blob_into(5, &[8, 16], &[12], &mut arena, &mut out)
        .unwrap()
        .to_vec();
    assert!(scratch_len_for(&blob, MAX_TILE).is_some());

    // Every truncation (the header's length no longer matches), and one
    // byte too many.
    for n in 0..blob.len() {
        assert_eq!(scratch_len_for(&blob[..n], MAX_TILE), None, "{n} bytes");
    }
    for n in [1, 2, 4, 1000] {
        let mut long = blob.clone();
        long.resize(blob.len() + n, 0);
        assert_eq!(scratch_len_for(&long, MAX_TILE), None, "{n} extra bytes");
    }
    assert_eq!(
        scratch_len_for(&SHIPPED[..SHIPPED.len() / 2], MAX_TILE),
        None
    );

    // Magic, version, kind: each byte of the header's first seven (bit 6:
    // the low bit would turn format 5 into the readable format 4).
    for i in 0..7 {
        let mut bad = blob.clone();
        bad[i] ^= 0x40;
        assert_eq!(scratch_len_for(&bad, MAX_TILE), None, "header byte {i}");
    }
    // An f32 blob (kind 1) is not an int8 one.
    let f32_blob = random_f32_blob_into(6, &[8, 16], &[12], &mut arena, &mut out).unwrap();
    assert_eq!(scratch_len_for(f32_blob, MAX_TILE), None);
    assert!(Int8Model::from_bytes(f32_blob).is_err());
}

/// A blob of the current header around `payload` (CRC left zero: this
/// reads no further than the architecture and never checks it).
fn blob_of(payload: &[u8]) -> Vec<u8> {
    let mut b = b"PCRN".to_vec();
    b.extend_from_slice(&pcrnet_core::format::FORMAT_VERSION.to_le_bytes());
    b.push(0);
    b.extend_from_slice(&(payload.len() as u32).to_le_bytes());
    b.extend_from_slice(payload);
    b.extend_from_slice(&[0; CRC_LEN]);
    assert_eq!(b.len(), HEADER_LEN + payload.len() + CRC_LEN);
    b
}

#[test]
fn architectures_decode_as_postcard_does() {
    // Encoder [3, 300], head []: 300 = 0xAC 0x02.
    let ok = blob_of(&[2, 3, 0xAC, 0x02, 0]);
    let want = pcrnet_core::int8_scratch_len(&[3, 300], &[], 4);
    assert_eq!(scratch_len_for(&ok, 4), Some(want));
    // The widest width, 65535 = 0xFF 0xFF 0x03.
    let widest = blob_of(&[1, 0xFF, 0xFF, 0x03, 1, 0xFF, 0xFF, 0x03]);
    let want = pcrnet_core::int8_scratch_len(&[65535], &[65535], MAX_TILE);
    assert_eq!(scratch_len_for(&widest, MAX_TILE), Some(want));
    // Postcard takes a longer-than-needed encoding: 3 = 0x83 0x00.
    let long_form = blob_of(&[1, 0x83, 0x00, 0]);
    assert_eq!(
        scratch_len_for(&long_form, 1),
        Some(pcrnet_core::int8_scratch_len(&[3], &[], 1))
    );

    for (payload, what) in [
        (&[0u8, 0][..], "no encoder layer"),
        (&[1, 0, 0], "a width of 0"),
        (&[1, 4, 1, 0], "a head width of 0"),
        (&[9, 1, 1, 1, 1, 1, 1, 1, 1, 1, 0], "nine encoder layers"),
        (&[1, 4, 9, 1, 1, 1, 1, 1, 1, 1, 1, 1], "nine head layers"),
        (&[1, 0xFF, 0xFF, 0x04, 0], "a width past u16"),
        (
            &[1, 0x80, 0x80, 0x80, 0x00, 0],
            "a u16 varint of four bytes",
        ),
        (&[2, 4], "a missing width"),
        (&[1, 4], "a missing head"),
        (&[1, 0x84], "an unfinished varint"),
        (&[], "an empty payload"),
        (
            &[
                0x80, 0x80, 0x80, 0x80, 0x80, 0x80, 0x80, 0x80, 0x80, 0x80, 0x01,
            ],
            "a length varint too long",
        ),
    ] {
        assert_eq!(scratch_len_for(&blob_of(payload), 1), None, "{what}");
    }
}

/// The minimal C example's generated header holds the shipped model's
/// figures (as `pcrnet inspect MODEL --c-header` writes them).
#[test]
fn minimal_c_header_is_current() {
    let header = include_str!("../../examples/minimal-c/model_sizes.h");
    let define = |name: &str| -> usize {
        let line = header
            .lines()
            .find_map(|l| l.strip_prefix(&format!("#define {name} ")))
            .unwrap_or_else(|| panic!("no {name} in model_sizes.h"));
        line.trim().parse().unwrap()
    };
    assert_eq!(define("PCRNET_BLOB_SCRATCH_LEN"), SHIPPED_SCRATCH);
    assert_eq!(define("PCRNET_BLOB_LEN"), SHIPPED.len());
}

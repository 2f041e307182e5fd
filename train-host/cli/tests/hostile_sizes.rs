//! Files that declare more points than they hold, or than anyone needs:
//! every reader refuses them before allocating (issue 14: a 5 MB
//! `binary_compressed` PCD declaring 150 M points grew `pcrnet register` to
//! 2.2 GB and aborted under a 2 GB limit).

use std::path::PathBuf;
use std::process::Command;

use pcrnet_io::{DEFAULT_MAX_POINTS, Format, FormatError};

/// LZF data that decompresses to `total` zero bytes at the format's best
/// ratio: one literal byte, then back-references of up to 264 bytes.
fn lzf_zeros(total: usize) -> Vec<u8> {
    let mut out = vec![0x00, 0x00];
    let mut rest = total - 1;
    while rest > 0 {
        let mut len = rest.min(264);
        // A back-reference copies at least 3 bytes: never leave 1 or 2.
        if (1..3).contains(&(rest - len)) {
            len -= 3;
        }
        if len >= 9 {
            out.extend_from_slice(&[0xE0, (len - 9) as u8, 0x00]);
        } else {
            out.extend_from_slice(&[((len - 2) << 5) as u8, 0x00]);
        }
        rest -= len;
    }
    out
}

/// A `binary_compressed` PCD of one-byte x, y, z declaring `points`, with
/// `lzf` as its data.
fn compressed_pcd(points: usize, lzf: &[u8]) -> Vec<u8> {
    let mut out = format!(
        "VERSION .7\nFIELDS x y z\nSIZE 1 1 1\nTYPE U U U\nCOUNT 1 1 1\nWIDTH {points}\nHEIGHT 1\nPOINTS {points}\nDATA binary_compressed\n"
    )
    .into_bytes();
    out.extend_from_slice(&(lzf.len() as u32).to_le_bytes());
    out.extend_from_slice(&((3 * points) as u32).to_le_bytes());
    out.extend_from_slice(lzf);
    out
}

#[test]
fn the_lzf_generator_is_right() {
    let points = 1000;
    let cloud = Format::Pcd
        .parse(&compressed_pcd(points, &lzf_zeros(3 * points)))
        .unwrap();
    assert_eq!(cloud, vec![[0.0; 3]; points]);
}

#[test]
fn compressed_data_cannot_claim_more_than_lzf_expands_to() {
    // 10 kB cannot hold the 3 MB a million one-byte points take.
    let lzf = lzf_zeros(3 * 1_000_000);
    let e = Format::Pcd
        .parse(&compressed_pcd(1_000_000, &lzf[..10_000]))
        .unwrap_err();
    assert!(
        matches!(&e, FormatError::Data { message, .. } if message.contains("cannot hold")),
        "{e}"
    );
}

#[test]
fn every_reader_refuses_a_count_over_the_limit() {
    let xyz = "0 0 0\n1 1 1\n2 2 2\n";
    let ply = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nend_header\n0 0 0\n1 1 1\n2 2 2\n";
    let off = "OFF\n3 0 0\n0 0 0\n1 1 1\n2 2 2\n";
    let pcd = "FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 3\nHEIGHT 1\nPOINTS 3\nDATA ascii\n0 0 0\n1 1 1\n2 2 2\n";
    for (format, text) in [
        (Format::Xyz, xyz),
        (Format::Ply, ply),
        (Format::Off, off),
        (Format::Pcd, pcd),
    ] {
        let bytes = text.as_bytes();
        assert_eq!(format.parse_limited(bytes, 3).unwrap().len(), 3, "{format}");
        let e = format.parse_limited(bytes, 2).unwrap_err();
        assert!(
            matches!(
                e,
                FormatError::TooLarge {
                    declared: 3,
                    limit: 2,
                    ..
                }
            ),
            "{format}: {e}"
        );
    }
}

/// The file: about 5 MB declaring 150 M one-byte points, LZF at
/// its best ratio, so only the point limit stands between it and 2 GB.
/// `pcrnet register` must refuse it with the limit's message inside a
/// 1 GB address space, where the old reader aborted, and with the limit
/// raised, say it is out of memory instead of aborting.
#[test]
fn a_small_file_declaring_150m_points_fails_cleanly_under_an_address_space_limit() {
    let points = 150_000_000;
    let file = compressed_pcd(points, &lzf_zeros(3 * points));
    assert!(file.len() < 6 << 20, "{} bytes", file.len());
    let dir = std::env::temp_dir().join(format!("pcrnet-hostile-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("huge.pcd");
    std::fs::write(&path, &file).unwrap();
    let template = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../models/embedded-default-template.xyz");
    let run = |extra: &[&str]| {
        Command::new("sh")
            .arg("-c")
            .arg("ulimit -v 1048576 && exec \"$0\" \"$@\"")
            .arg(env!("CARGO_BIN_EXE_pcrnet"))
            .args(["register", "--method", "icp"])
            .args(extra)
            .arg(&template)
            .arg(&path)
            .output()
            .unwrap()
    };
    let refused = run(&[]);
    // With the limit raised, the 1.8 GB of points cannot be allocated in
    // 1 GB: an error, not an abort.
    let raised = run(&["--max-cloud-points", "200000000"]);
    let _ = std::fs::remove_dir_all(&dir);
    let stderr = String::from_utf8_lossy(&refused.stderr);
    assert_eq!(refused.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains(&format!(
            "PCD POINTS {points}, more than the limit of {DEFAULT_MAX_POINTS} points"
        )),
        "{stderr}"
    );
    assert!(stderr.contains("--max-cloud-points"), "{stderr}");
    let stderr = String::from_utf8_lossy(&raised.stderr);
    assert_eq!(raised.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains(&format!(
            "cannot allocate {points} points: not enough memory"
        )),
        "{stderr}"
    );
}

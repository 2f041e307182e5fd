//! Hostile input: randomly mutated files of every format may be refused
//! but never panic a reader (`READERS_FUZZ_ITERS` raises the count).

mod common;

use common::{PTS, UNIT_SQUARE, cat, compressed_body, lzf_compress, pcd_header, soa};
use pcrnet_io::Format;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

#[test]
fn mutated_files_never_panic() {
    let h = pcd_header("x y z rgb", "4 4 4 4", "F F F U", "1 1 1 1", 3, 1, "binary");
    let pcd_bin = cat(&[h.as_bytes(), &[7u8; 48]]);
    let h = pcd_header(
        "x y z",
        "4 4 4",
        "F F F",
        "1 1 1",
        3,
        1,
        "binary_compressed",
    );
    let data = soa(&PTS);
    let pcd_comp = cat(&[h.as_bytes(), &compressed_body(&data, &lzf_compress(&data))]);
    let ply_bin = {
        let h = "ply\nformat binary_big_endian 1.0\nelement vertex 2\nproperty float x\n\
                 property float y\nproperty float z\nelement face 1\n\
                 property list uchar int vertex_indices\nend_header\n";
        cat(&[h.as_bytes(), &[0u8; 24], &[3], &[0u8; 12]])
    };
    let samples: Vec<(Vec<u8>, Format)> = vec![
        (pcd_bin, Format::Pcd),
        (pcd_comp, Format::Pcd),
        (ply_bin, Format::Ply),
        (UNIT_SQUARE.as_bytes().to_vec(), Format::Off),
        (b"1 2 3\n4,5,6\n".to_vec(), Format::Xyz),
        (b"x,y,z\n1,2,3\n4,5,6\n".to_vec(), Format::Csv),
    ];
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let interesting = [b'0', b'9', b'\n', b' ', 0, 0xff, b'-', b'#', 0x80];
    // READERS_FUZZ_ITERS raises the count for a longer local run.
    let iters: usize = std::env::var("READERS_FUZZ_ITERS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(1500);
    for (orig, format) in &samples {
        for _ in 0..iters {
            let mut b = orig.clone();
            for _ in 0..rng.random_range(1..4) {
                let i = rng.random_range(0..b.len());
                match rng.random_range(0..4) {
                    0 => b[i] = rng.random(),
                    1 => b[i] = interesting[rng.random_range(0..interesting.len())],
                    2 => {
                        b.remove(i);
                    }
                    _ => b.insert(i, rng.random()),
                }
                if b.is_empty() {
                    break;
                }
            }
            // Only the absence of panics matters here.
            let _ = format.parse(&b);
        }
    }
}

//! What the firmware takes from `pcrnet`: `inspect --c-header` / `--rust`
//! model sizes and `convert` to the `.f32` cloud format.

mod common;

use std::path::PathBuf;

use common::{models, pcrnet};

/// `pcrnet inspect --c-header` writes exactly the header the minimal C
/// firmware commits (so a stale one is caught here), `--rust` the same
/// figures, and an f32 blob is refused naming why.
#[test]
fn inspect_writes_the_model_sizes_for_firmware() {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..");
    let run = |args: &[&str]| pcrnet().current_dir(&root).args(args).output().unwrap();
    let c = run(&["inspect", "models/embedded-default-int8.pcrn", "--c-header"]);
    assert_eq!(c.status.code(), Some(0));
    let committed = std::fs::read(root.join("examples/minimal-c/model_sizes.h")).unwrap();
    assert_eq!(
        String::from_utf8_lossy(&c.stdout),
        String::from_utf8_lossy(&committed),
        "examples/minimal-c/model_sizes.h is stale: regenerate it with pcrnet inspect --c-header"
    );
    let rust = run(&["inspect", "models/embedded-default-int8.pcrn", "--rust"]);
    let text = String::from_utf8_lossy(&rust.stdout);
    assert!(
        text.contains("pub const BLOB_LEN: usize = 272170;"),
        "{text}"
    );
    let f32 = run(&["inspect", "models/embedded-default-f32.pcrn", "--c-header"]);
    assert_eq!(f32.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&f32.stderr).contains("not an int8 model blob"));
}

/// `pcrnet convert` writes the shipped XYZ source as the very `.f32` the
/// firmware links, and reads it back to the same points.
#[test]
fn convert_writes_the_firmware_f32_format() {
    let m = models();
    let dir = std::env::temp_dir().join(format!("pcrnet-convert-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let (f32, back) = (dir.join("source.f32"), dir.join("back.xyz"));
    for (input, output) in [
        (m.join("embedded-default-source.xyz"), &f32),
        (f32.clone(), &back),
    ] {
        let out = pcrnet()
            .arg("convert")
            .arg(&input)
            .arg(output)
            .output()
            .unwrap();
        assert_eq!(
            out.status.code(),
            Some(0),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
    assert_eq!(
        std::fs::read(&f32).unwrap(),
        std::fs::read(m.join("embedded-default-source.f32")).unwrap()
    );
    let a = pcrnet_io::read_cloud(&m.join("embedded-default-source.xyz")).unwrap();
    assert_eq!(pcrnet_io::read_cloud(&back).unwrap(), a);
    std::fs::write(dir.join("bad.f32"), [0u8; 13]).unwrap();
    let out = pcrnet()
        .arg("convert")
        .arg(dir.join("bad.f32"))
        .arg(dir.join("x.xyz"))
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&out.stderr).contains("multiple of 12"));
    std::fs::remove_dir_all(&dir).unwrap();
}

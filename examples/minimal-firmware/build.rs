//! Build script: puts `memory.x` where cortex-m-rt's `link.x` finds it,
//! and turns the source cloud (an XYZ text file, one `x y z` line per
//! point) into a Rust array that `src/main.rs` includes.
use std::{env, fs, path::PathBuf};

/// The cloud to register (text; `#` lines and blank lines are skipped).
const SOURCE_XYZ: &str = "../../models/embedded-default-source.xyz";

fn main() {
    let out = PathBuf::from(env::var_os("OUT_DIR").expect("OUT_DIR is set by cargo"));
    fs::copy("memory.x", out.join("memory.x")).expect("copy memory.x");
    println!("cargo:rustc-link-search={}", out.display());

    let text = fs::read_to_string(SOURCE_XYZ).expect("read the source cloud");
    let mut points = String::new();
    let mut n = 0;
    for (i, line) in text.lines().map(str::trim).enumerate() {
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let p: Vec<f32> = line
            .split_whitespace()
            .map(|x| x.parse().expect("a number"))
            .collect();
        assert!(
            p.len() == 3 && p.iter().all(|x| x.is_finite()),
            "{SOURCE_XYZ}:{}: expected three finite numbers",
            i + 1
        );
        // `{:?}` writes each f32 so that it reads back to the same bits.
        points += &format!("    [{:?}, {:?}, {:?}],\n", p[0], p[1], p[2]);
        n += 1;
    }
    let rust = format!(
        "/// The source cloud from `{SOURCE_XYZ}`, x, y, z per point.\n\
         static SOURCE_POINTS: [[f32; 3]; {n}] = [\n{points}];\n"
    );
    fs::write(out.join("source.rs"), rust).expect("write source.rs");
    println!("cargo:rerun-if-changed=memory.x");
    println!("cargo:rerun-if-changed={SOURCE_XYZ}");
}

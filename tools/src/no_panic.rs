//! `cargo xtask no-panic`: the link-time proof that no panic is reachable
//! from the device entry points (`tests/no-panic`), on every Arm core we
//! support, and, when it fails, where the panics come from.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;
use std::process::Command;

/// Cores the proof links for: M4F/M7, M0/M0+, M3, M33. (RISC-V is left
/// out: the proof image uses the Cortex-M runtime; the code is the same
/// portable Rust the M0 build covers, without the DSP kernel.)
pub const TARGETS: [&str; 4] = [
    "thumbv7em-none-eabihf",
    "thumbv6m-none-eabi",
    "thumbv7m-none-eabi",
    "thumbv8m.main-none-eabihf",
];

/// One proven build: the target, the firmware's opt-level and, if set,
/// the opt-level `pcrnet-core` alone is built with.
struct Build {
    target: &'static str,
    opt: &'static str,
    core_opt: Option<&'static str>,
}

/// The builds proven: every target at the firmware's `opt-level = 3`; the
/// M0 and M3 (portable kernel) optimised for size (`"s"`); and an M4F
/// firmware optimised for size with `pcrnet-core` at 3, as the README
/// recommends (at `"s"` the DSP dot product's zipped `chunks_exact` is
/// outlined with a division check in it). `"z"` is not covered: it keeps
/// bounds checks in the eigen-solver and the blob header.
const BUILDS: [Build; 7] = [
    Build {
        target: "thumbv7em-none-eabihf",
        opt: "3",
        core_opt: None,
    },
    Build {
        target: "thumbv6m-none-eabi",
        opt: "3",
        core_opt: None,
    },
    Build {
        target: "thumbv7m-none-eabi",
        opt: "3",
        core_opt: None,
    },
    Build {
        target: "thumbv8m.main-none-eabihf",
        opt: "3",
        core_opt: None,
    },
    Build {
        target: "thumbv6m-none-eabi",
        opt: "s",
        core_opt: None,
    },
    Build {
        target: "thumbv7m-none-eabi",
        opt: "s",
        core_opt: None,
    },
    Build {
        target: "thumbv7em-none-eabihf",
        opt: "s",
        core_opt: Some("3"),
    },
];

impl Build {
    fn name(&self) -> String {
        match self.core_opt {
            None => format!("{} opt-level {}", self.target, self.opt),
            Some(c) => format!("{} opt-level {} (pcrnet-core {c})", self.target, self.opt),
        }
    }

    /// `cargo build --release` of the proof image (`prove`: with the panic
    /// handler that cannot link); whether it succeeded.
    fn cargo_build(&self, dir: &Path, prove: bool) -> Result<bool, String> {
        let mut cmd = Command::new(env!("CARGO"));
        cmd.current_dir(dir)
            .args(["build", "--release", "--target", self.target])
            .env("CARGO_PROFILE_RELEASE_OPT_LEVEL", self.opt);
        if let Some(c) = self.core_opt {
            cmd.arg("--config")
                .arg(format!("profile.release.package.pcrnet-core.opt-level={c}"));
        }
        if !prove {
            cmd.arg("--no-default-features");
        }
        Ok(cmd
            .status()
            .map_err(|e| format!("cannot run cargo: {e}"))?
            .success())
    }
}

/// Builds the proof image for every build. One whose link fails is
/// rebuilt without the proof and its calls into panic code are listed.
pub fn run(root: &Path) -> Result<(), String> {
    crate::ensure_targets(&TARGETS)?;
    let dir = root.join("tests/no-panic");
    let mut failed = Vec::new();
    for build in &BUILDS {
        if build.cargo_build(&dir, true)? {
            println!("no-panic: {}: links, no panic path reachable", build.name());
        } else {
            failed.push(build);
        }
    }
    if failed.is_empty() {
        return Ok(());
    }
    crate::ensure_apt("arm-none-eabi-objdump", &["binutils-arm-none-eabi"])?;
    for build in &failed {
        if !build.cargo_build(&dir, false)? {
            return Err(format!(
                "the no-panic image does not build: {}",
                build.name()
            ));
        }
        let elf = dir.join(format!("target/{}/release/pcrnet-no-panic", build.target));
        println!(
            "\nno-panic: {}: calls into panic code (innermost frame first):",
            build.name()
        );
        for site in panic_sites(&elf)? {
            println!("  {site}");
        }
    }
    let names: Vec<String> = failed.iter().map(|b| b.name()).collect();
    Err(format!(
        "a panic path is reachable on {}: remove each site above by construction \
         (checked arithmetic, `get` with a typed error, slices split so the compiler \
         sees the bounds)",
        names.join(", ")
    ))
}

/// Calls from outside `core::` into `core::` functions that reach the
/// panic handler, each with its inline chain (file:line per frame).
fn panic_sites(elf: &Path) -> Result<Vec<String>, String> {
    let dis = output("arm-none-eabi-objdump", &["-d", "--no-show-raw-insn"], elf)?;
    // Function name -> (start address, branch sites (address, target)).
    let mut functions: BTreeMap<u64, (String, Vec<(u64, u64)>)> = BTreeMap::new();
    let mut current = None;
    for line in dis.lines() {
        if let Some((addr, name)) = function_header(line) {
            let name = format!("{:#}", rustc_demangle::demangle(name));
            functions.insert(addr, (name, Vec::new()));
            current = Some(addr);
        } else if let (Some(f), Some(branch)) = (current, branch(line))
            && let Some((_, calls)) = functions.get_mut(&f)
        {
            calls.push(branch);
        }
    }
    // Functions of `core` that reach the handler: `core::panicking` (every
    // panic goes through its `panic_fmt`, which may have the handler
    // inlined) and, as a fixed point over the call graph, their callers
    // in `core` (bounds checks, `unwrap`, ...).
    let mut panicking: BTreeSet<u64> = functions
        .iter()
        .filter(|(_, (name, _))| {
            name.starts_with("core::panicking::") || name.ends_with("rust_begin_unwind")
        })
        .map(|(&a, _)| a)
        .collect();
    loop {
        let before = panicking.len();
        for (&addr, (name, calls)) in &functions {
            if name.starts_with("core::") && calls.iter().any(|(_, t)| panicking.contains(t)) {
                panicking.insert(addr);
            }
        }
        if panicking.len() == before {
            break;
        }
    }
    let mut sites = Vec::new();
    for (name, calls) in functions.values() {
        if name.starts_with("core::") || name.ends_with("rust_begin_unwind") {
            continue;
        }
        for &(at, target) in calls {
            if panicking.contains(&target) {
                let callee = functions.get(&target).map_or("?", |(n, _)| n.as_str());
                sites.push((at, callee.to_string()));
            }
        }
    }
    let chains = inline_chains(elf, sites.iter().map(|&(at, _)| at))?;
    Ok(sites
        .into_iter()
        .zip(chains)
        .map(|((at, callee), chain)| format!("{at:#x} -> {callee}: {chain}"))
        .collect())
}

/// `addr <name>:`
fn function_header(line: &str) -> Option<(u64, &str)> {
    let (addr, rest) = line.split_once(" <")?;
    let name = rest.strip_suffix(">:")?;
    Some((u64::from_str_radix(addr, 16).ok()?, name))
}

/// `  addr:  b<cond>[.w|.n]  target <symbol>`: the branch's address and target.
fn branch(line: &str) -> Option<(u64, u64)> {
    let (addr, rest) = line.trim_start().split_once(':')?;
    let mut words = rest.split_whitespace();
    let mnemonic = words.next()?;
    let target = words.next()?;
    if !mnemonic.starts_with('b') || words.next().is_none_or(|w| !w.starts_with('<')) {
        return None;
    }
    Some((
        u64::from_str_radix(addr, 16).ok()?,
        u64::from_str_radix(target, 16).ok()?,
    ))
}

/// For each address, `function (file:line) <- caller (file:line) <- ...`,
/// innermost first, from the debug information (`addr2line -i`).
fn inline_chains(elf: &Path, at: impl Iterator<Item = u64>) -> Result<Vec<String>, String> {
    let mut args = vec![
        "-a".to_string(),
        "-i".into(),
        "-f".into(),
        "-C".into(),
        "-e".into(),
    ];
    args.push(elf.display().to_string());
    args.extend(at.map(|a| format!("{a:#x}")));
    let out = Command::new("arm-none-eabi-addr2line")
        .args(&args)
        .output()
        .map_err(|e| format!("cannot run arm-none-eabi-addr2line: {e}"))?;
    let text = String::from_utf8_lossy(&out.stdout);
    // Each address: a `0x...` line, then (function, file:line) pairs.
    let mut chains: Vec<Vec<String>> = Vec::new();
    let mut lines = text.lines();
    while let Some(line) = lines.next() {
        if line.starts_with("0x") {
            chains.push(Vec::new());
        } else if let Some(chain) = chains.last_mut() {
            let name = line.rsplit("::").next().unwrap_or(line);
            let place = lines.next().unwrap_or("?");
            let place = place.rsplit('/').next().unwrap_or(place);
            chain.push(format!("{name} ({place})"));
        }
    }
    Ok(chains.into_iter().map(|c| c.join(" <- ")).collect())
}

fn output(program: &str, args: &[&str], file: &Path) -> Result<String, String> {
    let out = Command::new(program)
        .args(args)
        .arg(file)
        .output()
        .map_err(|e| format!("cannot run {program}: {e}"))?;
    if !out.status.success() {
        return Err(format!("{program} failed on {}", file.display()));
    }
    Ok(String::from_utf8_lossy(&out.stdout).into_owned())
}

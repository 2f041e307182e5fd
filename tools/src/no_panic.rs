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

/// Builds the proof image for every target. A target whose link fails is
/// rebuilt without the proof and its calls into panic code are listed.
pub fn run(root: &Path) -> Result<(), String> {
    crate::ensure_targets(&TARGETS)?;
    let dir = root.join("tests/no-panic");
    let mut failed = Vec::new();
    for target in TARGETS {
        let ok = Command::new(env!("CARGO"))
            .current_dir(&dir)
            .args(["build", "--release", "--target", target])
            .status()
            .map_err(|e| format!("cannot run cargo: {e}"))?
            .success();
        if ok {
            println!("no-panic: {target}: links, no panic path reachable");
        } else {
            failed.push(target);
        }
    }
    if failed.is_empty() {
        return Ok(());
    }
    crate::ensure_apt("arm-none-eabi-objdump", &["binutils-arm-none-eabi"])?;
    for target in &failed {
        crate::run_in(
            &dir,
            env!("CARGO"),
            &[
                "build",
                "--release",
                "--no-default-features",
                "--target",
                target,
            ],
        )?;
        let elf = dir.join(format!("target/{target}/release/pcrnet-no-panic"));
        println!("\nno-panic: {target}: calls into panic code (innermost frame first):");
        for site in panic_sites(&elf)? {
            println!("  {site}");
        }
    }
    Err(format!(
        "a panic path is reachable on {}: remove each site above by construction \
         (checked arithmetic, `get` with a typed error, slices split so the compiler \
         sees the bounds)",
        failed.join(", ")
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

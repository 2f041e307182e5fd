//! `cargo xtask profile`: where the device's instructions go.
//!
//! Runs the firmware example under QEMU with `-icount` and the logs
//! `in_asm` (each translated block's instructions, printed once) and
//! `exec,nochain` (a line per block execution, with the symbol QEMU
//! resolved), and weights every block's instruction count by its
//! executions. The log goes to QEMU's stderr and is counted as it streams
//! (a whole registration logs about 1.5 GB), so nothing is written to disk.
//! Counts are exact instructions, the same as the firmware's SysTick count
//! (plus start-up and output).

use std::collections::HashMap;
use std::io::{BufRead, BufReader};
use std::process::{Command, Stdio};

/// Instructions by symbol and by block, from a QEMU `in_asm,exec` log.
#[derive(Default)]
struct Profile {
    /// Instructions of the block starting at each address.
    size: HashMap<u32, u64>,
    /// Executed instructions per symbol.
    by_symbol: HashMap<String, u64>,
    /// Executed instructions per block, with its symbol.
    by_block: HashMap<u32, (u64, String)>,
    total: u64,
}

impl Profile {
    /// Reads the log line by line.
    fn read(log: impl BufRead) -> Result<Profile, String> {
        let mut p = Profile::default();
        // The block being listed (`IN:` section): its start and length.
        let mut listing: Option<(Option<u32>, u64)> = None;
        for line in log.lines() {
            let line = line.map_err(|e| format!("reading QEMU's log: {e}"))?;
            if line.starts_with("IN:") {
                listing = Some((None, 0));
            } else if let Some((start, n)) = listing.as_mut() {
                if let Some(addr) = line.strip_prefix("0x").and_then(|l| l.split(':').next()) {
                    if start.is_none() {
                        *start = u32::from_str_radix(addr, 16).ok();
                    }
                    *n += 1;
                } else if line.trim().is_empty() {
                    if let (Some(start), n) = (*start, *n) {
                        p.size.insert(start, n);
                    }
                    listing = None;
                }
            } else if let Some(rest) = line.strip_prefix("Trace ") {
                p.count(rest);
            }
        }
        Ok(p)
    }

    /// One `Trace` line: `0: 0xHOST [FLAGS/PC/.../...] symbol`.
    fn count(&mut self, rest: &str) {
        let mut words = rest.split_whitespace().skip(2);
        let pc = words
            .next()
            .and_then(|b| b.trim_start_matches('[').split('/').nth(1))
            .and_then(|pc| u32::from_str_radix(pc, 16).ok());
        // Readable names (`{:#}` leaves out the hash).
        let symbol = format!(
            "{:#}",
            rustc_demangle::demangle(words.next().unwrap_or("?"))
        );
        let Some(pc) = pc else { return };
        let n = self.size.get(&pc).copied().unwrap_or(0);
        self.total += n;
        *self.by_symbol.entry(symbol.clone()).or_default() += n;
        self.by_block.entry(pc).or_insert((0, symbol)).0 += n;
    }

    fn print(&self) {
        let pct = |n: u64| 100.0 * n as f64 / self.total.max(1) as f64;
        println!("{} instructions in all\n", self.total);
        println!("| instructions | share | function |\n|---|---|---|");
        let mut symbols: Vec<_> = self.by_symbol.iter().collect();
        symbols.sort_by_key(|s| std::cmp::Reverse(*s.1));
        for &(s, &n) in symbols.iter().take(20) {
            println!("| {n} | {:.1}% | `{s}` |", pct(n));
        }
        println!("\n| instructions | share | block | in |\n|---|---|---|---|");
        let mut blocks: Vec<_> = self.by_block.iter().collect();
        blocks.sort_by_key(|b| std::cmp::Reverse(b.1.0));
        for (pc, (n, s)) in blocks.iter().take(15) {
            println!("| {n} | {:.1}% | {pc:#x} | `{s}` |", pct(*n));
        }
    }
}

/// Builds the firmware example, runs it under QEMU with the logs on, and
/// prints the instructions per function and the hottest blocks (addresses
/// for `arm-none-eabi-objdump -d`).
pub fn run(root: &std::path::Path) -> Result<(), String> {
    let dir = root.join("firmware-example");
    let status = Command::new(env!("CARGO"))
        .args(["build", "--release"])
        .current_dir(&dir)
        .status()
        .map_err(|e| format!("cannot run cargo: {e}"))?;
    if !status.success() {
        return Err("building firmware-example failed".into());
    }
    let elf = dir.join("target/thumbv7em-none-eabihf/release/pcrnet-firmware-example");
    let mut child = Command::new("qemu-system-arm")
        .args(["-machine", "mps2-an386", "-cpu", "cortex-m4", "-nographic"])
        .args(["-monitor", "none", "-serial", "none"])
        .args(["-semihosting-config", "enable=on,target=native"])
        .args(["-icount", "shift=0,align=off,sleep=off"])
        .args(["-d", "in_asm,exec,nochain", "-kernel"])
        .arg(&elf)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .map_err(|e| format!("cannot start qemu-system-arm: {e}"))?;
    let log = child.stderr.take().ok_or("no QEMU log")?;
    let profile = Profile::read(BufReader::with_capacity(1 << 20, log))?;
    let status = child.wait().map_err(|e| format!("waiting for QEMU: {e}"))?;
    if !status.success() {
        return Err(format!("QEMU exited with {status}"));
    }
    profile.print();
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn blocks_are_weighted_by_their_executions() {
        let log = "----------------\nIN: main\n0x00000400:  f008 fe3d  bl #0x907e\n0x00000404:  480e  ldr r0, [pc]\n\n\
                   Trace 0: 0x7f00 [00800408/00000400/00000110/ff020200] main\n\
                   ----------------\nIN: leaf\n0x00000500:  4770  bx lr\n\n\
                   Trace 0: 0x7f10 [00800408/00000500/00000110/ff020200] leaf\n\
                   Trace 0: 0x7f00 [00800408/00000400/00000110/ff020200] main\n";
        let p = Profile::read(log.as_bytes()).unwrap();
        assert_eq!(p.total, 5);
        assert_eq!(p.by_symbol["main"], 4);
        assert_eq!(p.by_symbol["leaf"], 1);
        assert_eq!(p.by_block[&0x400].0, 4);
    }
}

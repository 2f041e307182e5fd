//! Flash and static RAM of a firmware image, from its ELF sections.

use std::path::Path;

use anyhow::Context;
use object::{Object, ObjectSection};

/// Section sizes that matter on the device.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Sizes {
    /// `.text` (code, including the vector table).
    pub text: u64,
    /// `.rodata` (constants, including an included model blob).
    pub rodata: u64,
    /// `.data` (initialised statics: in flash and copied to RAM).
    pub data: u64,
    /// `.bss` + `.uninit` (zeroed / uninitialised statics).
    pub bss: u64,
}

impl Sizes {
    /// Flash: `.vector_table + .text + .rodata + .data` (its load image).
    pub fn flash(&self) -> u64 {
        self.text + self.rodata + self.data
    }
    /// Static RAM: `.data + .bss`.
    pub fn static_ram(&self) -> u64 {
        self.data + self.bss
    }
}

/// Reads the sizes of an ELF file.
pub fn sizes(path: &Path) -> anyhow::Result<Sizes> {
    let bytes = std::fs::read(path).with_context(|| format!("reading {}", path.display()))?;
    let file =
        object::File::parse(&*bytes).with_context(|| format!("parsing {}", path.display()))?;
    let mut s = Sizes {
        text: 0,
        rodata: 0,
        data: 0,
        bss: 0,
    };
    for section in file.sections() {
        let size = section.size();
        match section.name().unwrap_or("") {
            ".vector_table" | ".text" => s.text += size,
            ".rodata" => s.rodata += size,
            ".data" => s.data += size,
            ".bss" | ".uninit" => s.bss += size,
            _ => {}
        }
    }
    Ok(s)
}

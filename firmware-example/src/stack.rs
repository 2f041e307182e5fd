//! Peak stack measurement by painting: fill the free RAM below the stack
//! pointer with a pattern, run, then find the lowest word that changed.

const PAINT: u32 = 0xC0DE_C0DE;

unsafe extern "C" {
    /// End of `.bss`/`.uninit`: the lowest address the stack may grow to
    /// (cortex-m-rt and riscv-rt both define it).
    static mut __sheap: u32;
    /// Initial stack pointer (top of RAM; both runtimes).
    static _stack_start: u32;
}

fn bounds() -> (usize, usize) {
    // Only the addresses of the linker symbols are taken, never their values.
    (
        core::ptr::addr_of!(__sheap) as usize,
        core::ptr::addr_of!(_stack_start) as usize,
    )
}

/// Paints the unused stack (from the end of static RAM up to just below the
/// current stack pointer) and returns that stack pointer, the baseline for
/// [`used_below`].
pub fn paint() -> usize {
    let (low, _) = bounds();
    let sp = crate::board::stack_pointer();
    let mut p = low;
    while p + 4 <= sp.saturating_sub(256) {
        // SAFETY: [low, sp - 256) is RAM that nothing uses (no heap; the
        // stack lives above sp).
        unsafe { core::ptr::write_volatile(p as *mut u32, PAINT) };
        p += 4;
    }
    sp
}

/// The lowest stack address written since [`paint`].
fn deepest() -> usize {
    let (low, top) = bounds();
    let mut p = low;
    // SAFETY: reads RAM inside [low, top).
    while p < top && unsafe { core::ptr::read_volatile(p as *const u32) } == PAINT {
        p += 4;
    }
    p
}

/// Bytes of stack used at the deepest point since [`paint`], counted from
/// the top of the stack (the whole program's stack).
pub fn peak() -> usize {
    bounds().1 - deepest()
}

/// Bytes of stack used below `baseline` (the value [`paint`] returned) at
/// the deepest point since: what the code called after `paint` needed.
pub fn used_below(baseline: usize) -> usize {
    baseline.saturating_sub(deepest())
}

/// Bytes of statically allocated RAM (`.data` + `.bss` + `.uninit`).
pub fn static_ram() -> usize {
    let (low, _) = bounds();
    low - crate::board::RAM_BASE
}

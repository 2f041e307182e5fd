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

/// Paints the unused stack (from the end of static RAM up to the caller's
/// stack pointer: no unpainted gap, so every byte a later call uses is
/// seen) and returns that stack pointer, the baseline for [`used_below`].
/// Inlined, so the painting loop runs in the caller's frame and the
/// baseline is the caller's own stack pointer.
#[inline(always)]
pub fn paint() -> usize {
    let (low, _) = bounds();
    let sp = crate::board::stack_pointer();
    let mut p = low;
    while p + 4 <= sp {
        // SAFETY: [low, sp) is RAM that nothing uses (no heap; the stack
        // lives at and above sp, and this loop keeps its state in
        // registers or above sp). An interrupt that pushes a frame while
        // this runs can only make a later measurement larger, never smaller.
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

/// Bytes of stack in use at `baseline` (a value [`paint`] returned),
/// counted from the top of the stack: the frames of the callers.
pub fn in_use(baseline: usize) -> usize {
    bounds().1.saturating_sub(baseline)
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

//! Instruction counting.
//!
//! QEMU run with `-icount shift=0,align=off,sleep=off` advances virtual time
//! by one nanosecond per instruction. On Cortex-M, SysTick runs on the
//! board's clock (25 MHz on most MPS2 boards: one tick every 40
//! instructions; see [`crate::board`]), deterministically and whatever the
//! host's load; its 24-bit counter wraps every 2^24 ticks, and the SysTick
//! exception counts the wraps so long measurements stay exact (to one
//! tick). On RISC-V, `minstret` counts the instructions themselves.

#[cfg(target_arch = "arm")]
pub use systick::Counter;

#[cfg(target_arch = "riscv32")]
pub use minstret::Counter;

/// The instruction counter, started (on Cortex-M it takes SysTick: `None`
/// if the core peripherals were already taken).
pub fn counter() -> Option<Counter> {
    #[cfg(target_arch = "arm")]
    {
        cortex_m::Peripherals::take().map(|p| Counter::start(p.SYST))
    }
    #[cfg(target_arch = "riscv32")]
    {
        Some(Counter::start())
    }
}

/// Executes exactly `2 * n` instructions (a countdown loop of two
/// instructions per turn), for checking the counter: `n >= 1`.
#[inline(always)]
pub fn calibration_loop(n: u32) {
    let mut n = n.max(1);
    // SAFETY: a register-only countdown loop.
    #[cfg(target_arch = "arm")]
    unsafe {
        core::arch::asm!("2:", "subs {0}, #1", "bne 2b", inout(reg) n)
    };
    // SAFETY: a register-only countdown loop.
    #[cfg(target_arch = "riscv32")]
    unsafe {
        core::arch::asm!("2:", "addi {0}, {0}, -1", "bnez {0}, 2b", inout(reg) n)
    };
    let _ = n;
}

#[cfg(target_arch = "riscv32")]
mod minstret {
    use crate::board::INSTRUCTIONS_PER_1000_TICKS;

    /// Instructions retired, from the `minstret` CSR pair.
    pub struct Counter {
        start: u64,
    }

    impl Counter {
        /// Starts counting from now.
        pub fn start() -> Self {
            Counter {
                start: riscv::register::minstret::read64(),
            }
        }

        /// Instructions executed since [`Counter::start`].
        pub fn instructions(&self) -> u64 {
            let ticks = riscv::register::minstret::read64().wrapping_sub(self.start);
            ticks * INSTRUCTIONS_PER_1000_TICKS / 1000
        }
    }
}

#[cfg(target_arch = "arm")]
mod systick {
    use core::sync::atomic::{AtomicU32, Ordering};

    use cortex_m::peripheral::{SCB, SYST, syst::SystClkSource};
    use cortex_m_rt::exception;

    use crate::board::INSTRUCTIONS_PER_1000_TICKS;

    const RELOAD: u32 = 0x00FF_FFFF;

    static WRAPS: AtomicU32 = AtomicU32::new(0);

    /// A free-running tick counter; owns SysTick.
    pub struct Counter {
        _syst: SYST,
    }

    impl Counter {
        /// Starts SysTick from zero on the processor clock.
        pub fn start(mut syst: SYST) -> Self {
            syst.disable_counter();
            syst.set_clock_source(SystClkSource::Core);
            syst.set_reload(RELOAD);
            syst.clear_current();
            WRAPS.store(0, Ordering::SeqCst);
            syst.enable_interrupt();
            syst.enable_counter();
            // The counter holds 0 until its first tick loads RELOAD (that load
            // is not a wrap): wait for it so counting starts from a clean state.
            while SYST::get_current() == 0 {}
            WRAPS.store(0, Ordering::SeqCst);
            Counter { _syst: syst }
        }

        /// Ticks since [`Counter::start`].
        ///
        /// QEMU takes a pending exception only at the end of a translation
        /// block, so the counter can have wrapped while the SysTick exception
        /// that counts the wrap is still pending: such a wrap is added here.
        pub fn ticks(&self) -> u64 {
            loop {
                let wraps = WRAPS.load(Ordering::SeqCst);
                let current = SYST::get_current();
                let pending = SCB::is_pendst_pending();
                let again = SYST::get_current();
                // Retry if the exception ran, or the counter wrapped between the reads.
                if WRAPS.load(Ordering::SeqCst) != wraps || again > current {
                    continue;
                }
                let wraps = wraps as u64 + pending as u64;
                return wraps * (RELOAD as u64 + 1) + (RELOAD - current) as u64;
            }
        }

        /// Instructions executed since [`Counter::start`].
        pub fn instructions(&self) -> u64 {
            self.ticks() * INSTRUCTIONS_PER_1000_TICKS / 1000
        }
    }

    #[exception]
    fn SysTick() {
        // Load and store, not fetch_add: the Cortex-M0 has no atomic
        // read-modify-write, and this handler is the only writer.
        WRAPS.store(
            WRAPS.load(Ordering::SeqCst).wrapping_add(1),
            Ordering::SeqCst,
        );
    }
}

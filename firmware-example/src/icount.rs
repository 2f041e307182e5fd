//! Instruction counting with SysTick.
//!
//! QEMU run with `-icount shift=0,align=off,sleep=off` advances virtual time
//! by one nanosecond per instruction, and the MPS2 SysTick runs at 25 MHz:
//! one tick every 40 instructions, deterministically and whatever the host's
//! load. The 24-bit counter wraps every 2^24 ticks; the SysTick exception
//! counts the wraps so long measurements stay exact (to one tick).

use core::sync::atomic::{AtomicU32, Ordering};

use cortex_m::peripheral::{syst::SystClkSource, SYST};
use cortex_m_rt::exception;

/// Instructions per SysTick tick under `-icount shift=0` at 25 MHz.
pub const INSTRUCTIONS_PER_TICK: u64 = 40;
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
        Counter { _syst: syst }
    }

    /// Ticks since [`Counter::start`].
    pub fn ticks(&self) -> u64 {
        loop {
            let before = WRAPS.load(Ordering::SeqCst);
            let current = SYST::get_current();
            if WRAPS.load(Ordering::SeqCst) == before {
                return before as u64 * (RELOAD as u64 + 1) + (RELOAD - current) as u64;
            }
        }
    }

    /// Instructions executed since [`Counter::start`] (40 per tick).
    pub fn instructions(&self) -> u64 {
        self.ticks() * INSTRUCTIONS_PER_TICK
    }
}

#[exception]
fn SysTick() {
    WRAPS.fetch_add(1, Ordering::SeqCst);
}

//! Instruction counting with SysTick. Under QEMU with `-icount shift=0`
//! (the runner in `.cargo/config.toml`) the virtual clock advances one ns
//! per instruction, so SysTick readings count instructions
//! deterministically; [`Calibration`] turns ticks into instructions with a
//! loop of known length.

use core::hint::black_box;
use core::ptr::{read_volatile, write_volatile};

/// SysTick control and status (ARMv7-M ARM B3.3.3).
const SYST_CSR: *mut u32 = 0xE000_E010 as *mut u32;
/// SysTick reload value.
const SYST_RVR: *mut u32 = 0xE000_E014 as *mut u32;
/// SysTick current value.
const SYST_CVR: *mut u32 = 0xE000_E018 as *mut u32;
/// The counter is 24 bits wide.
const MASK: u32 = 0x00FF_FFFF;

/// Start SysTick free-running from its largest reload, on the processor
/// clock, without interrupts.
pub fn start() {
    // SAFETY: the SysTick registers of the Cortex-M core; the images use
    // SysTick for nothing else.
    unsafe {
        write_volatile(SYST_RVR, MASK);
        write_volatile(SYST_CVR, 0);
        // Enable, processor clock, no interrupt.
        write_volatile(SYST_CSR, 0b101);
    }
}

/// The current counter value (it counts down).
#[inline]
pub fn now() -> u32 {
    // SAFETY: a read of the SysTick current-value register.
    unsafe { read_volatile(SYST_CVR) }
}

/// SysTick ticks `f` takes (the counter runs down, 24 bits: `f` must take
/// fewer than 2²⁴ ticks).
#[inline]
pub fn ticks(mut f: impl FnMut()) -> u64 {
    let t0 = now();
    f();
    let t1 = now();
    u64::from(t0.wrapping_sub(t1) & MASK)
}

/// A loop of exactly `2 n` instructions (`subs` + `bne`).
#[inline]
pub fn spin(n: u32) {
    // SAFETY: register arithmetic and a branch, no memory.
    unsafe {
        core::arch::asm!("2:", "subs {n}, #1", "bne 2b", n = inout(reg) n => _, options(nomem, nostack));
    }
}

/// Ticks against instructions, measured once per run on a loop of known
/// length.
#[derive(Clone, Copy, Debug)]
pub struct Calibration {
    /// Instructions of the calibration loop.
    pub instructions: u64,
    /// Ticks it took.
    pub ticks: u64,
}

impl Calibration {
    /// Iterations of the calibration loop: 400,000 instructions, well
    /// inside the 24-bit counter.
    const LOOPS: u32 = 200_000;

    /// Start SysTick ([`start`]) and time [`spin`] of a known length.
    pub fn measure() -> Self {
        start();
        let t = ticks(|| spin(black_box(Self::LOOPS)));
        Self {
            instructions: 2 * u64::from(Self::LOOPS),
            ticks: t,
        }
    }

    /// Instructions in `t` ticks (0 if the calibration measured none).
    pub fn instructions(&self, t: u64) -> u64 {
        t.saturating_mul(self.instructions)
            .checked_div(self.ticks)
            .unwrap_or(0)
    }

    /// Instructions ×100 per repetition of `reps` that took `t` ticks, less
    /// `base` ticks of loop overhead.
    pub fn per_rep_x100(&self, t: u64, base: u64, reps: u64) -> u64 {
        t.saturating_sub(base)
            .saturating_mul(self.instructions)
            .saturating_mul(100)
            .checked_div(self.ticks.saturating_mul(reps))
            .unwrap_or(0)
    }
}

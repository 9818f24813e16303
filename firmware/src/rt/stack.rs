//! Stack high-water mark by painting: fill the free stack with a pattern,
//! run, then find the lowest word that no longer holds it. The MCU has no
//! guard page, so the measured peak (printed by the test images) is how the
//! stack budget is checked (docs/design.md §5.4).

use core::ptr::{addr_of, read_volatile, write_volatile};

extern "C" {
    /// End of static RAM (.data/.bss/.uninit), from cortex-m-rt's link.x.
    static __sheap: u32;
    /// Initial stack pointer: top of RAM.
    static _stack_start: u32;
}

/// The fill pattern: unlikely as a saved register, address or float.
const PAINT: u32 = 0x5AA5_C33C;

/// Bytes just below the stack pointer left unpainted: the frame of
/// [`paint`] itself.
const MARGIN: usize = 64;

/// A painted stack, from which [`Painted::high_water`] reads the peak.
#[derive(Clone, Copy, Debug)]
pub struct Painted {
    floor: usize,
}

/// Fill the unused stack (from the end of statics up to just below the
/// current stack pointer) with the pattern. Everything the caller's frame
/// and its callers hold is above the paint, so the mark counts what runs
/// after this call.
pub fn paint() -> Painted {
    // The address of a linker symbol, not its value.
    let floor = addr_of!(__sheap) as usize;
    let sp: usize;
    // SAFETY: reads the stack pointer register, touches no memory.
    unsafe { core::arch::asm!("mov {}, sp", out(reg) sp) };
    let mut a = floor;
    while a.saturating_add(4) <= sp.saturating_sub(MARGIN) {
        // SAFETY: `a` is a word between the end of the statics and the
        // live stack, which nothing owns (there is no heap).
        unsafe { write_volatile(a as *mut u32, PAINT) };
        a += 4;
    }
    Painted { floor }
}

impl Painted {
    /// Bytes of stack ever used: top of RAM minus the lowest overwritten
    /// word.
    pub fn high_water(&self) -> usize {
        let top = addr_of!(_stack_start) as usize;
        let mut a = self.floor;
        // SAFETY: `a` stays inside RAM, between the statics and its top.
        while a < top && unsafe { read_volatile(a as *const u32) } == PAINT {
            a += 4;
        }
        top.saturating_sub(a)
    }
}

//! `log` records on USART2 (QEMU netduinoplus2's second `-serial`; PA2 on
//! a board), for the STM32F405 image, which must not use semihosting (a
//! semihosting call halts a board that has no debugger attached).
//!
//! The board configures USART2 (clock, pin, baud) before [`init`]. Each
//! byte waits for TXE at most [`SPINS_PER_BYTE`] polls, so a record costs
//! at most its length × 87 µs at 115 200 baud on a board and never hangs
//! when the UART is not clocked; log only at start-up and on rare events,
//! never per period.

use core::fmt::Write;

use stm32f4::stm32f405 as pac;

/// Polls of TXE per byte before the byte is dropped: one character at
/// 115 200 baud is ~14 700 cycles at 168 MHz, a poll a few cycles.
pub const SPINS_PER_BYTE: u32 = 20_000;

/// A writer of bytes to USART2's data register.
pub struct Usart2;

impl Write for Usart2 {
    fn write_str(&mut self, s: &str) -> core::fmt::Result {
        // SAFETY: USART2 belongs to this logger (the board only sets it up).
        let u = unsafe { &*pac::USART2::ptr() };
        for &b in s.as_bytes() {
            if (0..SPINS_PER_BYTE).any(|_| u.sr().read().txe().bit_is_set()) {
                u.dr().write(|w| w.dr().set(u16::from(b)));
            }
        }
        Ok(())
    }
}

struct SerialLogger;

impl log::Log for SerialLogger {
    fn enabled(&self, _: &log::Metadata) -> bool {
        true
    }

    fn log(&self, record: &log::Record) {
        // Whole records: an interrupt's record does not split a line.
        cortex_m::interrupt::free(|_| {
            let _ = write!(Usart2, "log {} {}\r\n", record.level(), record.args());
        });
    }

    fn flush(&self) {}
}

static LOGGER: SerialLogger = SerialLogger;

/// Route the `log` macros to USART2 at level `Info`. A second call
/// changes nothing.
pub fn init() {
    if log::set_logger(&LOGGER).is_ok() {
        log::set_max_level(log::LevelFilter::Info);
    }
}

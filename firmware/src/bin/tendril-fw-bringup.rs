//! Bring-up image (`tendril-fw-bringup`) of the STM32F405/F407 board (QEMU `-M netduinoplus2`, or
//! a board flashed with it: the same image). Over the board contract only
//! ([`tendril_firmware::board::Board`]) it echoes every received link byte
//! back in order and, every [`STATUS_EVERY`] ticks, sends a status line
//!
//! `\x1estatus tick <n> missed <m> overruns <o> rx <bytes> now_us <t>\n`
//!
//! (the leading ASCII record separator 0x1E marks it for a reader that also
//! receives echoed bytes; echo traffic that should stay parseable avoids
//! 0x1E). Link: USART1 (QEMU's first `-serial`); logs: USART2 (the second).
//! No semihosting: a board without a debugger runs it as QEMU does.
//!
//! It checks the board alone (tests/tests/mcu_board.rs: start-up, echo,
//! tick rate, link throughput); the controller is `tendril-fw-stm32`.
#![cfg_attr(target_os = "none", no_std, no_main)]
#![deny(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing,
    clippy::unreachable,
    clippy::todo,
    clippy::unimplemented
)]

#[cfg(not(target_os = "none"))]
fn main() {
    // MCU only: the host side of this image is tests/tests/mcu_board.rs.
}

/// Ticks between status lines (1 s at 1 kHz).
#[cfg(target_os = "none")]
const STATUS_EVERY: u32 = 1000;

#[cfg(target_os = "none")]
mod mcu {
    use core::fmt::Write;

    use cortex_m_rt::entry;
    use tendril_firmware::board::stm32f405::Stm32f405;
    use tendril_firmware::board::Board;
    use tendril_firmware::rt;

    use super::STATUS_EVERY;

    /// Bytes held for sending when the transmit queue is full: the echo
    /// reads no more than this per period, so nothing is dropped here
    /// (back-pressure shows up as receive overruns, which are counted).
    const HOLD: usize = 1024;

    /// The bring-up loop: echo, and a status line every [`STATUS_EVERY`]
    /// ticks. `overruns` reads the board's receive-overrun counter (not
    /// part of the contract: a board-specific statistic).
    pub fn run<B: Board>(board: &mut B, overruns: impl Fn(&B) -> u32) -> ! {
        let mut hold = [0u8; HOLD];
        let mut held = 0usize;
        let (mut tick, mut missed, mut rx, mut next_status) = (0u32, 0u32, 0u32, STATUS_EVERY);
        loop {
            let m = board.wait_tick();
            missed = missed.wrapping_add(m);
            tick = tick.wrapping_add(m).wrapping_add(1);
            // Send what is held, keep the rest at the front.
            let sent = board.link_write(hold.get(..held).unwrap_or(&[]));
            hold.copy_within(sent..held, 0);
            held -= sent;
            // Echo: read only what the hold can keep if it cannot be sent.
            if let Some(room) = hold.get_mut(held..) {
                let n = board.link_read(room);
                rx = rx.wrapping_add(n as u32);
                let end = held + n;
                let sent = board.link_write(hold.get(held..end).unwrap_or(&[]));
                hold.copy_within(held + sent..end, held);
                held = end - sent;
            }
            if tick.wrapping_sub(next_status) < u32::MAX / 2 {
                next_status = next_status.wrapping_add(STATUS_EVERY);
                let mut line: heapless::String<96> = heapless::String::new();
                let _ = writeln!(
                    line,
                    "\x1estatus tick {tick} missed {missed} overruns {} rx {rx} now_us {}",
                    overruns(board),
                    board.now_ns() / 1000
                );
                let bytes = line.as_bytes();
                if let Some(room) = hold.get_mut(held..held + bytes.len()) {
                    room.copy_from_slice(bytes);
                    held += bytes.len();
                }
            }
        }
    }

    #[entry]
    fn main() -> ! {
        match Stm32f405::take() {
            Some(mut board) => run(&mut board, |b| b.stats().rx_overruns),
            // Only if something took the peripherals before `main`.
            None => loop {
                cortex_m::asm::wfi();
            },
        }
    }

    // `rt` provides the fault and panic handlers and the USART2 logger.
    #[allow(unused_imports)]
    use rt as _;
}

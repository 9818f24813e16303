//! The controller image of the STM32F405/F407 (what a user flashes, and
//! what `tendril controller --mcu` runs under QEMU's `netduinoplus2`): the
//! controller node ([`tendril_firmware::node`]: the whole control period,
//! fed and read over the link) on the board ([`Stm32f405`]), the built-in
//! net in flash and one RAM slot for updates sent over the link.
//!
//! `main` is the thin shell: take the board, then one node tick per tick
//! of the board's timer. Link: USART1; log: USART2. No semihosting.
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
    // MCU only: the host runs the same period in `tendril controller`.
}

#[cfg(target_os = "none")]
mod mcu {
    use cortex_m_rt::entry;
    use tendril_firmware::board::stm32f405::{Stm32f405, PERIOD_HZ};
    use tendril_firmware::board::Board;
    use tendril_firmware::node::{Node, MCU_UPDATE_CAPACITY};
    use tendril_firmware::{rt, McuNet, McuSlots, DEFAULT_NET, DEFAULT_NET_CRC};

    #[entry]
    fn main() -> ! {
        // The hot-swap RAM slot and the node (with its update buffer) are
        // statics, not on the stack.
        static mut RAM_NET: McuNet = McuNet::empty();
        // (Its initial value is not all zeros — `Option`'s niche — so it
        // is in .data: 14.6 KB of flash for its initialiser, within budget.)
        static mut NODE: Node<MCU_UPDATE_CAPACITY> =
            Node::new(DEFAULT_NET_CRC, 1_000_000_000 / PERIOD_HZ);
        let Some(mut board) = Stm32f405::take() else {
            // Only if something took the peripherals before `main`.
            loop {
                cortex_m::asm::wfi();
            }
        };
        let mut store = McuSlots::new(&DEFAULT_NET, RAM_NET);
        loop {
            let missed = board.wait_tick();
            NODE.tick(&mut board, &mut store, missed);
        }
    }

    // `rt` provides the fault and panic handlers and the USART2 logger.
    #[allow(unused_imports)]
    use rt as _;
}

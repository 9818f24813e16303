//! The MCU shell every image shares (`target_os = "none"` only): the
//! semihosting console and `log` sink ([`console`], MPS2 test images), the
//! USART2 `log` sink of the STM32F405 image (`serial_log`, feature
//! `stm32f405`), stack painting ([`stack`]), instruction counting with
//! SysTick ([`cycles`]), the exit through semihosting ([`exit`]), and the
//! HardFault, DefaultHandler and panic handlers ([`fault`]). An image is its
//! `#[entry]` function over these and the hardware-independent core
//! (docs/design.md §5.4; the MCU binary is a thin shell around code that is
//! tested on the host).
//!
//! Nothing here allocates or panics; hardware access is confined to the
//! `unsafe` blocks of [`stack`] and [`cycles`].

pub mod console;
pub mod cycles;
pub mod fault;
#[cfg(feature = "stm32f405")]
pub mod serial_log;
pub mod stack;

pub use console::{init_logger, Console};

use cortex_m_semihosting::debug;

/// The start and end every MPS2 test image shares: route `log` to the
/// semihosting console, open the result [`Console`], run the image, write
/// what is buffered, and exit with its verdict ([`exit`]). The STM32F405
/// image does not use this (no semihosting there).
pub fn semihosted(run: impl FnOnce(&mut Console) -> bool) -> ! {
    init_logger();
    let mut out = Console::new();
    let ok = run(&mut out);
    out.flush();
    exit(ok)
}

/// End the run through semihosting with exit code 0 (`ok`) or 1, which
/// QEMU passes on as its own exit status (how the QEMU tests read the
/// verdict). Does not return; on a board without a debugger attached the
/// core parks in a loop.
pub fn exit(ok: bool) -> ! {
    debug::exit(if ok {
        debug::EXIT_SUCCESS
    } else {
        debug::EXIT_FAILURE
    });
    #[allow(clippy::empty_loop)]
    loop {}
}

//! The exception handlers and the panic handler every image shares, so no
//! image is left with cortex-m-rt's defaults (which spin forever: a QEMU
//! test would hang until its timeout, a board would sit dead).
//!
//! - MPS2 test images (semihosting): report `fault <what> pc <addr>` on the
//!   semihosting console and exit 1, which the QEMU tests read as failure.
//! - STM32F405 image (feature `stm32f405`, no semihosting): log the fault on
//!   USART2 and reset the chip (a controller that faults restarts into a
//!   known state instead of holding its last command).

use cortex_m_rt::{exception, ExceptionFrame};

/// End the image after a fault or a panic (does not return).
fn fatal(what: &str, pc: u32) -> ! {
    #[cfg(not(feature = "stm32f405"))]
    {
        use core::fmt::Write;
        if let Ok(mut h) = cortex_m_semihosting::hio::hstdout() {
            let _ = writeln!(h, "fault {what} pc {pc:#010x}");
        }
        super::exit(false)
    }
    #[cfg(feature = "stm32f405")]
    {
        log::error!("fault {what} pc {pc:#010x}: reset");
        cortex_m::peripheral::SCB::sys_reset()
    }
}

#[exception]
unsafe fn HardFault(frame: &ExceptionFrame) -> ! {
    fatal("HardFault", frame.pc())
}

#[exception]
unsafe fn DefaultHandler(irqn: i16) {
    // An interrupt or exception without a handler of its own.
    let _ = irqn;
    fatal("unhandled-interrupt", 0)
}

/// A panic ends the run as a failure: the images are checked to link no
/// panic path (scripts/check-panic-free), so this is the last resort, never
/// a controller's error handling.
#[panic_handler]
fn panic(_: &core::panic::PanicInfo) -> ! {
    fatal("panic", 0)
}

//! The robot controller's chip as the host sees it: an STM32F405 image
//! (`tendril-fw-stm32`, firmware crate feature `stm32f405`) running under
//! QEMU's `netduinoplus2` ([`Chip`]), and the serial link to it over a Unix
//! socket ([`McuLink`]): USART1 is QEMU's first `-serial`, the chip's log
//! (USART2) its second, written to a file ([`Chip::log`]).
//!
//! [`bridge`] puts the chip in the loop (`tendril controller --mcu`).
//!
//! [`locate_image`] builds the image; when QEMU or the Rust target is
//! missing it fails with one line saying what to install.

pub mod bridge;
mod chip;
mod chip_link;
mod link;
#[cfg(test)]
mod tests;
pub mod trace;

pub use chip::{
    build_image, cargo_build_firmware, check_tools, locate_bringup_image, locate_image, Chip, QEMU,
    TARGET,
};
pub use link::McuLink;

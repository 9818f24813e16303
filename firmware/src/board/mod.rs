//! The board contract: what a control period needs from the hardware, as
//! one small trait in the spirit of embassy's hardware traits (every
//! method's cost is bounded and stated; nothing allocates or panics).
//!
//! The controller's period logic is written over `&mut impl Board`, so the
//! same code runs on every chip that implements it
//! ([`stm32f405::Stm32f405`], cargo feature `stm32f405`, MCU builds only).
//! On the host the same period runs in the iceoryx2 controller process
//! (no board: its clock and transport stand in for one); the node's unit
//! tests and the trace replay drive the node through an in-process byte
//! board, the host build of the very code the chip runs.
//!
//! **Feedback comes over the link.** The chip has no sensor inputs in this
//! contract: measured tensions and the tip pose are measured by the plant
//! (the host, or later the robot's own sensor node) and reach the chip as
//! link messages read with [`Board::link_read`]; the chip's outputs are the
//! motor tensions ([`Board::set_tensions`]) and link messages
//! ([`Board::link_write`]).
//!
//! Why one trait and not one per peripheral (timer, motors, serial): the
//! period logic always needs all of them together, and one trait keeps the
//! node's signature `fn run(board: &mut impl Board) -> !`. A board that
//! later grows a sensor bus adds a method here.

#[cfg(all(target_os = "none", feature = "stm32f405"))]
pub mod stm32f405;

/// The hardware a control period runs on.
pub trait Board {
    /// Block until the next period tick and return how many ticks were
    /// missed since the previous return (0 = on time; the first call
    /// counts from the board's start).
    ///
    /// Sleeps (WFI) between interrupts, so it may return only after the
    /// interrupts that arrive meanwhile (link bytes) have been served; its
    /// own cost is a few register reads. A caller that overran the period
    /// returns at once with the count of ticks it missed; the tick counter
    /// is `u32` (49 days at 1 kHz), compared with wrapping arithmetic.
    fn wait_tick(&mut self) -> u32;

    /// Monotonic time since the board's start, ns, from the period timer
    /// (resolution: one timer count). `u64` ns never wraps in practice
    /// (584 years). Cost: a few register reads inside a short critical
    /// section.
    fn now_ns(&self) -> u64;

    /// Apply tensions (N) to the first `tensions.len()` motors; extra
    /// entries beyond the board's motor count are ignored. Never blocks
    /// (writes output registers: PWM compare values or a DAC).
    fn set_tensions(&mut self, tensions: &[f32]);

    /// Move up to `buf.len()` received link bytes into `buf`, oldest first,
    /// and return the count (0 when nothing arrived). Never blocks. While
    /// the receive queue is full the board stops taking bytes (flow control
    /// where the line has it, as QEMU's socket does; otherwise the UART
    /// overruns), and lost bytes are counted (see the board's overrun
    /// counter); the frame layer above resynchronises on its own
    /// delimiters.
    fn link_read(&mut self, buf: &mut [u8]) -> usize;

    /// Queue `bytes` for transmission and return how many were queued, a
    /// prefix of `bytes` (fewer when the transmit queue is full). Never
    /// blocks; the caller counts the rest as dropped (a frame layer sends
    /// whole frames only: check the free space first with a frame-sized
    /// write, or drop the frame).
    fn link_write(&mut self, bytes: &[u8]) -> usize;

    /// Received bytes the board had to drop (receive queue full or a
    /// hardware overrun) since start: reported in the node's telemetry. A
    /// board that cannot lose bytes keeps the default, 0.
    fn link_overruns(&self) -> u32 {
        0
    }
}

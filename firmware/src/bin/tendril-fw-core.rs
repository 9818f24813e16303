//! The firmware as a robot controller would flash it, for measuring the image
//! size without the test harness (`tendril-fw` also carries the test
//! vectors, the hot-swap test blobs, hex printing and the instruction
//! benchmarks): the built-in net in flash, one RAM slot for hot swaps, the
//! control step, the `.tnet` decoder and the semihosting logger.
//!
//! The "hardware" is four mailboxes in RAM (setpoint in, tension command
//! out, weight update in, update busy out) that a real board would fill from
//! its bus; here nothing fills them, so the loop runs `STEPS` steps on an
//! empty setpoint (the watchdog holds) and exits 0 through semihosting.
//!
//! Every period runs the control step, then one slice of the hot swap
//! ([`tendril_firmware::McuSwap`], docs/design.md §5.3): an offered update
//! is checked a bounded slice per period while the running net keeps
//! running, and written and selected in a slice of its own.
//!
//! `cargo build -p tendril-firmware --bin tendril-fw-core --release --target thumbv7em-none-eabihf`
//! then `llvm-size` on `target/thumbv7em-none-eabihf/release/tendril-fw-core`.
//! `scripts/check-panic-free` (run by CI) checks that this image links no
//! `core::panicking` symbol.
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
    // The host build has nothing to drive: see `tendril-fw` for the twin.
}

#[cfg(target_os = "none")]
mod mcu {
    use core::ptr::{addr_of, addr_of_mut, read_volatile, write_volatile};

    use cortex_m_rt::entry;
    use tendril_firmware::control::{control_step, ControlConfig, ControlState, Setpoint};
    use tendril_firmware::rt;
    use tendril_firmware::{
        McuNet, McuSlots, McuSwap, NetStore, StepInput, DEFAULT_NET, POSE_DIM, SWAP_SLICE_BYTES,
    };
    use tendril_shared::{CoContraction, TendonLimits, MAX_TENDONS};

    /// Steps to run before exiting (a real controller loops forever).
    const STEPS: u32 = 1000;
    /// Control period, ns.
    const PERIOD_NS: u64 = 1_000_000;

    /// Setpoint mailbox: sequence number (0 = none yet) and pose.
    static mut SETPOINT: (u64, [f32; POSE_DIM]) = (0, [0.0; POSE_DIM]);
    /// Command mailbox.
    static mut COMMAND: [f32; MAX_TENDONS] = [0.0; MAX_TENDONS];
    /// Weight-update mailbox: address and length of a received blob (0 =
    /// none). The loop takes it (and clears it) at the start of a period.
    static mut UPDATE: (usize, usize) = (0, 0);
    /// `true` while the last blob taken is still being checked: the bus
    /// driver keeps its buffer unchanged until this reads `false` or the
    /// mailbox has taken a newer blob (which supersedes it).
    static mut UPDATE_BUSY: bool = false;

    #[entry]
    fn main() -> ! {
        static mut RAM_NET: McuNet = McuNet::empty();
        rt::semihosted(|_| {
            let n = DEFAULT_NET.shape().outputs;
            // The seed robots' co-contraction sets: opposite pairs.
            let limits = TendonLimits::uniform(n, 10.0, 500.0)
                .and_then(|l| l.with_cocontraction(CoContraction::opposite_pairs(n)));
            let ok = match limits {
                Ok(limits) => {
                    let cfg = ControlConfig::new(limits);
                    let mut store = McuSlots::new(&DEFAULT_NET, &mut *RAM_NET);
                    let mut swap = McuSwap::new();
                    let mut state = ControlState::new(&cfg.limits, &[0.0; MAX_TENDONS], 0);
                    for k in 1..=STEPS {
                        // SAFETY: single-threaded; the mailboxes are plain data
                        // read and written whole, volatile so the compiler keeps
                        // the "bus" accesses.
                        let (update, (seq, pose)) = unsafe {
                            (
                                read_volatile(addr_of!(UPDATE)),
                                read_volatile(addr_of!(SETPOINT)),
                            )
                        };
                        if update.1 != 0 {
                            // SAFETY: the bus driver keeps the blob unchanged
                            // while UPDATE_BUSY reads true (or until it hands
                            // over a newer one), see the mailbox.
                            let blob: &'static [u8] = unsafe {
                                core::slice::from_raw_parts(update.0 as *const u8, update.1)
                            };
                            let _ = swap.offer(blob, (POSE_DIM, n));
                            unsafe { write_volatile(addr_of_mut!(UPDATE), (0, 0)) };
                        }
                        let input = StepInput {
                            now_ns: u64::from(k) * PERIOD_NS,
                            setpoint: (seq != 0).then_some(Setpoint {
                                seq,
                                pose,
                                tangent: None,
                            }),
                            feedback: None,
                        };
                        let (next, out) = control_step(&cfg, store.active(), &state, &input);
                        state = next;
                        unsafe { write_volatile(addr_of_mut!(COMMAND), out.command) };
                        // Between this step and the next: one bounded slice of
                        // an update in progress (the outcome is logged).
                        let _ = swap.slice(&mut store, SWAP_SLICE_BYTES);
                        unsafe { write_volatile(addr_of_mut!(UPDATE_BUSY), swap.busy()) };
                    }
                    true
                }
                Err(_) => false,
            };
            ok
        })
    }
}

//! MCU test image of the hot swap without a missed period (docs/design.md
//! §5.3): the control loop of an 8-tendon robot runs [`swap_demo::PERIODS`]
//! periods on the net in flash (build with `TENDRIL_FW_NET` = the 7-64-8
//! net of [`swap_demo::FLASH_SEED`]); the blobs of [`swap_demo::Offer`] are
//! offered at their periods and swapped in by one [`McuSwap`] slice per
//! period. Every period prints the instructions of its control step and of
//! its swap slice (SysTick under `-icount shift=0`, calibrated against a
//! loop of known length), the slice's outcome, and the running net's
//! inference of that period's setpoint as hex `f32` bits:
//!
//! `period <k> step <instr> slice <instr> <idle|working|swapped|rejected> infer <hex>×8`
//!
//! and at the end `stack_high_water <bytes>` (painted stack). The QEMU test
//! (`tests/tests/firmware_qemu.rs`) checks every period line against host
//! inference of the net that should be running and against the budget
//! [`tendril_firmware::SWAP_PERIOD_BUDGET`].
#![cfg_attr(target_os = "none", no_std, no_main)]

#[cfg(not(target_os = "none"))]
fn main() {
    // MCU only: the host side of this run is the QEMU test itself.
}

#[cfg(target_os = "none")]
mod mcu {
    use core::fmt::Write;
    use core::hint::black_box;
    use core::ptr::{addr_of, read_volatile, write_volatile};

    use cortex_m_rt::entry;
    use cortex_m_semihosting::{debug, hio};
    use tendril_firmware::control::{
        control_step, ControlConfig, ControlState, Setpoint, StepInput,
    };
    use tendril_firmware::swap_demo::{self, Offer, BLOB_LEN};
    use tendril_firmware::{
        infer, McuNet, McuSlots, McuSwap, NetStore, SwapEvent, DEFAULT_NET, POSE_DIM,
        SWAP_SLICE_BYTES,
    };
    use tendril_shared::MAX_TENDONS;

    /// `log` records as `log <level> <message>` lines (the test ignores them).
    struct SemihostingLogger;

    impl log::Log for SemihostingLogger {
        fn enabled(&self, _: &log::Metadata) -> bool {
            true
        }
        fn log(&self, record: &log::Record) {
            if let Ok(mut h) = hio::hstdout() {
                let _ = writeln!(h, "log {} {}", record.level(), record.args());
            }
        }
        fn flush(&self) {}
    }

    static LOGGER: SemihostingLogger = SemihostingLogger;

    extern "C" {
        /// End of static RAM (.data/.bss/.uninit), from cortex-m-rt's link.x.
        static __sheap: u32;
        /// Initial stack pointer: top of RAM.
        static _stack_start: u32;
    }

    const PAINT: u32 = 0x5AA5_C33C;

    /// Fill the unused stack (from the end of statics up to just below the
    /// current stack pointer) with a pattern; returns the painted floor.
    fn paint_stack() -> usize {
        let floor = addr_of!(__sheap) as usize;
        let sp: usize;
        unsafe { core::arch::asm!("mov {}, sp", out(reg) sp) };
        let mut a = floor;
        while a + 4 <= sp.saturating_sub(64) {
            unsafe { write_volatile(a as *mut u32, PAINT) };
            a += 4;
        }
        floor
    }

    /// Bytes of stack ever used: top of RAM minus the lowest overwritten word.
    fn stack_high_water(floor: usize) -> usize {
        let top = addr_of!(_stack_start) as usize;
        let mut a = floor;
        while a < top && unsafe { read_volatile(a as *const u32) } == PAINT {
            a += 4;
        }
        top - a
    }

    const SYST_CSR: *mut u32 = 0xE000_E010 as *mut u32;
    const SYST_RVR: *mut u32 = 0xE000_E014 as *mut u32;
    const SYST_CVR: *mut u32 = 0xE000_E018 as *mut u32;

    fn systick() -> u32 {
        unsafe { read_volatile(SYST_CVR) }
    }

    /// SysTick ticks `f` takes (the counter runs down, 24 bits).
    fn ticks(mut f: impl FnMut()) -> u64 {
        let t0 = systick();
        f();
        let t1 = systick();
        u64::from(t0.wrapping_sub(t1) & 0x00FF_FFFF)
    }

    /// A loop of exactly `2 n` instructions (`subs` + `bne`).
    fn spin(n: u32) {
        unsafe {
            core::arch::asm!("2:", "subs {n}, #1", "bne 2b", n = inout(reg) n => _, options(nomem, nostack));
        }
    }

    fn write_hex(out: &mut hio::HostStream, values: &[f32]) {
        for v in values {
            let _ = write!(out, " {:08x}", v.to_bits());
        }
    }

    #[entry]
    fn main() -> ! {
        static mut RAM_NET: McuNet = McuNet::empty();
        // The blobs as a bus driver would hold them: one receive buffer each.
        static mut BLOBS: [[u8; BLOB_LEN]; 4] = [[0; BLOB_LEN]; 4];
        if log::set_logger(&LOGGER).is_ok() {
            log::set_max_level(log::LevelFilter::Info);
        }
        let ok = match hio::hstdout() {
            Ok(mut out) => run(RAM_NET, BLOBS, &mut out),
            Err(()) => false,
        };
        debug::exit(if ok {
            debug::EXIT_SUCCESS
        } else {
            debug::EXIT_FAILURE
        });
        #[allow(clippy::empty_loop)]
        loop {}
    }

    /// The run; whether it completed.
    fn run(
        ram_net: &'static mut McuNet,
        blobs: &'static mut [[u8; BLOB_LEN]; 4],
        out: &mut hio::HostStream,
    ) -> bool {
        let mut lens = [0usize; 4];
        for ((offer, buf), len) in Offer::ALL.iter().zip(blobs.iter_mut()).zip(&mut lens) {
            match swap_demo::offer_blob(*offer, buf) {
                Ok(n) => *len = n,
                Err(e) => {
                    let _ = writeln!(out, "error blob {}: {e}", offer.name());
                    return false;
                }
            }
        }
        let blobs: &'static [[u8; BLOB_LEN]; 4] = blobs;
        // Paint after making the blobs (the synthetic-net encoder keeps its
        // weights on the stack), so the mark is the loop's: control steps,
        // inference, swap slices, the logger, and this image's printing.
        let floor = paint_stack();
        unsafe {
            write_volatile(SYST_RVR, 0x00FF_FFFF);
            write_volatile(SYST_CVR, 0);
            write_volatile(SYST_CSR, 0b101);
        }
        const CAL: u32 = 200_000;
        let cal_ticks = ticks(|| spin(black_box(CAL)));
        let cal_instr = 2 * u64::from(CAL);
        let instr = |t: u64| (t * cal_instr).checked_div(cal_ticks).unwrap_or(0);
        let _ = writeln!(
            out,
            "calibration {cal_instr} instructions {cal_ticks} ticks"
        );
        let s = DEFAULT_NET.shape();
        let _ = writeln!(
            out,
            "net {} {} {} {}",
            s.inputs,
            s.hidden,
            s.outputs,
            s.macs()
        );
        let Ok(limits) = swap_demo::limits() else {
            let _ = writeln!(out, "error limits");
            return false;
        };
        let want = (POSE_DIM, limits.n_tendons());
        let cfg = ControlConfig::new(limits);
        let mut store = McuSlots::new(&DEFAULT_NET, ram_net);
        let mut swap = McuSwap::new();
        let mut state = ControlState::new(&cfg.limits, &[0.0; MAX_TENDONS], 0);
        for k in 1..=swap_demo::PERIODS {
            for ((offer, blob), len) in Offer::ALL.iter().zip(blobs).zip(lens) {
                if offer.period() == k {
                    let r = swap.offer(blob.get(..len).unwrap_or(&[]), want);
                    let _ = writeln!(
                        out,
                        "offer {k} {} {}",
                        offer.name(),
                        if r.is_ok() {
                            "started"
                        } else {
                            "superseded-previous"
                        }
                    );
                }
            }
            let pose = swap_demo::pose(k);
            let input = StepInput {
                now_ns: u64::from(k) * 1_000_000,
                setpoint: Some(Setpoint {
                    seq: u64::from(k),
                    pose,
                    tangent: None,
                }),
                feedback: None,
            };
            let mut step = None;
            let t_step = ticks(|| step = Some(control_step(&cfg, store.active(), &state, &input)));
            if let Some((next, cmd)) = step {
                state = next;
                black_box(cmd);
            }
            // The inference the step ran, again, for the test (not timed).
            let y = infer(store.active(), &pose);
            let mut event = SwapEvent::Idle;
            let t_slice = ticks(|| event = swap.slice(&mut store, SWAP_SLICE_BYTES));
            let name = match event {
                SwapEvent::Idle => "idle",
                SwapEvent::Working => "working",
                SwapEvent::Swapped => "swapped",
                SwapEvent::Rejected(_) => "rejected",
            };
            let _ = write!(
                out,
                "period {k} step {} slice {} {name} infer",
                instr(t_step),
                instr(t_slice)
            );
            write_hex(out, &y);
            let _ = writeln!(out);
        }
        let _ = writeln!(out, "stack_high_water {}", stack_high_water(floor));
        let _ = writeln!(out, "done {}", swap_demo::PERIODS);
        true
    }

    #[panic_handler]
    fn panic(_: &core::panic::PanicInfo) -> ! {
        debug::exit(debug::EXIT_FAILURE);
        #[allow(clippy::empty_loop)]
        loop {}
    }
}

//! The MCU binary (Cortex-M4F, `thumbv7em-none-eabihf`, QEMU `mps2-an386`):
//! runs the embedded test vectors through inference, the control step and
//! hot swaps, prints every result over semihosting as hex `f32` bits, then
//! measures instructions per inference of the built-in net (SysTick under
//! `-icount shift=0`) and the stack high-water mark (painted stack), and
//! exits 0 (ok) or 1 via semihosting.
//!
//! The running net starts as [`tendril_firmware::DEFAULT_NET`], a `static` in
//! flash that `firmware/build.rs` generates from `firmware/vectors/default.tnet`
//! (or from the file named by `TENDRIL_FW_NET` at build time, absolute or
//! relative to the workspace root: `TENDRIL_FW_NET=out/model.tnet cargo fw`); hot-swapped
//! updates go to one RAM slot ([`tendril_firmware::McuSlots`]).
//!
//! On the host the same file builds a twin that runs the same vectors
//! through the same code and prints the same lines (minus measurements), so
//! `cargo test --workspace` and `cargo clippy --all-targets` work unchanged.
//!
//! Embedded files, refreshed from the net the main job exports
//! (`cargo run --release` writes `out/model.tnet`) with
//! `cargo run -p tendril-firmware --features vector-gen --example gen_vectors -- --tnet out/model.tnet`:
//! `default.tnet` (that net), `inputs.bin` (control-loop inputs inside its
//! input box), `swap.tnet` and `swap_nan.tnet` (a small update and a
//! corrupted copy, for the hot-swap steps), all in `firmware/vectors/`.
#![cfg_attr(target_os = "none", no_std, no_main)]

/// The embedded test vectors (`firmware/vectors/`, or the directory `TENDRIL_FW_VECTORS` names at
/// build time; build.rs copies them into `OUT_DIR`).
static VECTORS: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/inputs.bin"));
/// The hot-swap update blob.
static SWAP: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/swap.tnet"));
/// The update blob with a NaN weight under a valid CRC.
static SWAP_NAN: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/swap_nan.tnet"));

/// The swap blobs of the vector run.
const BLOBS: tendril_firmware::vectors::SwapBlobs<'static> = tendril_firmware::vectors::SwapBlobs {
    good: SWAP,
    nan: SWAP_NAN,
};

#[cfg(not(target_os = "none"))]
fn main() {
    use tendril_firmware::{McuNet, McuSlots, DEFAULT_NET};
    let mut ram = Box::new(McuNet::empty());
    let mut store = McuSlots::new(&DEFAULT_NET, &mut ram);
    let mut out = String::new();
    match tendril_firmware::vectors::run(&mut store, &BLOBS, VECTORS, &mut out) {
        Ok(_) => print!("{out}"),
        Err(e) => {
            print!("{out}");
            eprintln!("tendril-fw: {e}");
            std::process::exit(1);
        }
    }
}

#[cfg(target_os = "none")]
mod mcu {
    use core::fmt::Write;
    use core::hint::black_box;
    use core::ptr::{addr_of, read_volatile, write_volatile};

    use cortex_m_rt::entry;
    use cortex_m_semihosting::{debug, hio};
    use tendril_firmware::control::{control_step, ControlState, Setpoint, StepInput};
    use tendril_firmware::infer::{dot8, infer};
    use tendril_firmware::vectors::{self, HAS_SETPOINT};
    use tendril_firmware::{McuNet, McuSlots, DEFAULT_NET, POSE_DIM};
    use tendril_shared::{Activation, MAX_TENDONS};

    use super::{BLOBS, SWAP, VECTORS};

    /// Semihosting stdout, buffered per line (one host call per line).
    struct Out {
        host: Option<hio::HostStream>,
        buf: [u8; 200],
        len: usize,
    }

    impl Out {
        fn flush(&mut self) {
            if let (Some(h), Some(bytes)) = (self.host.as_mut(), self.buf.get(..self.len)) {
                let _ = h.write_all(bytes);
            }
            self.len = 0;
        }
    }

    impl Write for Out {
        fn write_str(&mut self, s: &str) -> core::fmt::Result {
            for &b in s.as_bytes() {
                if let Some(slot) = self.buf.get_mut(self.len) {
                    *slot = b;
                    self.len += 1;
                }
                if b == b'\n' || self.len == self.buf.len() {
                    self.flush();
                }
            }
            Ok(())
        }
    }

    // ---- log facade over semihosting -----------------------------------------

    /// `log` records as `log <level> <message>` lines on the semihosting
    /// console (the parity test ignores them).
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

    // ---- stack painting -----------------------------------------------------

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

    // ---- SysTick instruction counting (QEMU -icount shift=0) ----------------

    const SYST_CSR: *mut u32 = 0xE000_E010 as *mut u32;
    const SYST_RVR: *mut u32 = 0xE000_E014 as *mut u32;
    const SYST_CVR: *mut u32 = 0xE000_E018 as *mut u32;

    fn systick_start() {
        unsafe {
            write_volatile(SYST_RVR, 0x00FF_FFFF);
            write_volatile(SYST_CVR, 0);
            // Enable, processor clock, no interrupt.
            write_volatile(SYST_CSR, 0b101);
        }
    }

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

    /// Instructions ×100 per repetition, from ticks and the calibration.
    fn per_rep_x100(t: u64, base: u64, reps: u64, cal_instr: u64, cal_ticks: u64) -> u64 {
        (t.saturating_sub(base) * cal_instr * 100)
            .checked_div(cal_ticks * reps)
            .unwrap_or(0)
    }

    /// Measurement vectors for the dot-product figure (statics: off the stack).
    static DOT_W: [f32; 64] = [0.25; 64];
    static DOT_A: [f32; 64] = [0.5; 64];

    #[inline(never)]
    fn bench(net: &McuNet, spare: &mut McuNet, out: &mut Out) {
        systick_start();
        const CAL: u32 = 200_000;
        let cal_ticks = ticks(|| spin(black_box(CAL)));
        let cal_instr = 2 * u64::from(CAL);
        let _ = writeln!(
            out,
            "bench calibration {cal_instr} instructions {cal_ticks} ticks"
        );

        // Poses from the vectors (real inputs, not constants the compiler sees).
        let mut poses = [[0.0f32; POSE_DIM]; 16];
        let mut k = 0;
        if let Ok((_, recs)) = vectors::parse(VECTORS) {
            for r in
                recs.filter(|r| r.flags & HAS_SETPOINT != 0 && r.pose.iter().all(|v| v.is_finite()))
            {
                if let Some(p) = poses.get_mut(k) {
                    *p = r.pose;
                    k += 1;
                }
            }
        }
        let k = k.max(1);
        const REPS: u64 = 256;
        let base = ticks(|| {
            for i in 0..REPS as usize {
                black_box(poses.get(i % k));
            }
        });
        let t_inf = ticks(|| {
            for i in 0..REPS as usize {
                if let Some(p) = poses.get(i % k) {
                    black_box(infer(net, black_box(p)));
                }
            }
        });
        let shape = net.shape();
        let infer_x100 = per_rep_x100(t_inf, base, REPS, cal_instr, cal_ticks);
        let budget_x100 = 250 * shape.macs() as u64 + 4500 * shape.hidden as u64;
        let _ = writeln!(
            out,
            "bench infer_x100 {infer_x100} macs {} sigmoids {} budget_x100 {budget_x100}",
            shape.macs(),
            shape.hidden
        );

        let t_sig = ticks(|| {
            for i in 0..REPS {
                let x = (i as f32) * (8.0 / REPS as f32) - 4.0;
                black_box(Activation::SymmetricSigmoid.apply(black_box(x)));
            }
        });
        let base_sig = ticks(|| {
            for i in 0..REPS {
                let x = (i as f32) * (8.0 / REPS as f32) - 4.0;
                black_box(black_box(x));
            }
        });
        let _ = writeln!(
            out,
            "bench sigmoid_x100 {}",
            per_rep_x100(t_sig, base_sig, REPS, cal_instr, cal_ticks)
        );

        let (w, a) = (&DOT_W, &DOT_A);
        let base_dot = ticks(|| {
            for _ in 0..REPS {
                black_box((black_box(w), black_box(a)));
            }
        });
        let t_dot = ticks(|| {
            for _ in 0..REPS {
                black_box(dot8(black_box(w), black_box(a)));
            }
        });
        let _ = writeln!(
            out,
            "bench dot64_per_mac_x100 {}",
            per_rep_x100(t_dot, base_dot, REPS * 64, cal_instr, cal_ticks)
        );

        if let Ok((header, _)) = vectors::parse(VECTORS) {
            if let Ok(cfg) = header.config() {
                let st = ControlState::new(&cfg.limits, &[0.0; MAX_TENDONS], 0);
                let t_step = ticks(|| {
                    for i in 0..REPS as usize {
                        if let Some(p) = poses.get(i % k) {
                            let input = StepInput {
                                now_ns: 1_000_000,
                                setpoint: Some(Setpoint {
                                    seq: 1,
                                    pose: *p,
                                    tangent: None,
                                }),
                                feedback: None,
                            };
                            black_box(control_step(&cfg, net, black_box(&st), &input));
                        }
                    }
                });
                let _ = writeln!(
                    out,
                    "bench control_step_x100 {}",
                    per_rep_x100(t_step, base, REPS, cal_instr, cal_ticks)
                );
            }
        }

        // Hot swap: full validation alone, and validation + decode into the
        // RAM slot, of the update blob.
        const DREPS: u64 = 8;
        let t_val = ticks(|| {
            for _ in 0..DREPS {
                let _ = black_box(McuNet::validate(black_box(SWAP)));
            }
        });
        let t_dec = ticks(|| {
            for _ in 0..DREPS {
                let _ = black_box(spare.decode_into(black_box(SWAP)));
            }
        });
        let _ = writeln!(
            out,
            "bench swap_bytes {} validate_x100 {} decode_x100 {}",
            SWAP.len(),
            per_rep_x100(t_val, 0, DREPS, cal_instr, cal_ticks),
            per_rep_x100(t_dec, 0, DREPS, cal_instr, cal_ticks)
        );
    }

    #[entry]
    fn main() -> ! {
        // The hot-swap RAM slot: all zeros, so it sits in .bss.
        static mut RAM_NET: McuNet = McuNet::empty();
        let floor = paint_stack();
        if log::set_logger(&LOGGER).is_ok() {
            log::set_max_level(log::LevelFilter::Info);
        }
        let mut out = Out {
            host: hio::hstdout().ok(),
            buf: [0; 200],
            len: 0,
        };
        let ok = {
            let mut store = McuSlots::new(&DEFAULT_NET, &mut *RAM_NET);
            match vectors::run(&mut store, &BLOBS, VECTORS, &mut out) {
                Ok(_) => true,
                Err(e) => {
                    let _ = writeln!(out, "error {e}");
                    false
                }
            }
        };
        // Stack of the run itself (control steps, inference, printing).
        let _ = writeln!(out, "stack_run {}", stack_high_water(floor));
        if ok {
            bench(&DEFAULT_NET, RAM_NET, &mut out);
        }
        let _ = writeln!(out, "stack_total {}", stack_high_water(floor));
        out.flush();
        debug::exit(if ok {
            debug::EXIT_SUCCESS
        } else {
            debug::EXIT_FAILURE
        });
        #[allow(clippy::empty_loop)]
        loop {}
    }

    #[panic_handler]
    fn panic(_: &core::panic::PanicInfo) -> ! {
        debug::exit(debug::EXIT_FAILURE);
        #[allow(clippy::empty_loop)]
        loop {}
    }
}

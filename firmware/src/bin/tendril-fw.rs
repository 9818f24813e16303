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

    use cortex_m_rt::entry;
    use tendril_firmware::control::{control_step, ControlSetpoint, ControlState, StepInput};
    use tendril_firmware::infer::{dot8, infer};
    use tendril_firmware::rt::{self, cycles::ticks, cycles::Calibration, Console};
    use tendril_firmware::vectors::{self, HAS_SETPOINT};
    use tendril_firmware::{McuNet, McuSlots, DEFAULT_NET, POSE_DIM};
    use tendril_shared::{Activation, MAX_TENDONS};

    use super::{BLOBS, SWAP, VECTORS};

    /// Measurement vectors for the dot-product figure (statics: off the stack).
    static DOT_W: [f32; 64] = [0.25; 64];
    static DOT_A: [f32; 64] = [0.5; 64];

    #[inline(never)]
    fn bench(net: &McuNet, spare: &mut McuNet, out: &mut Console) {
        let cal = Calibration::measure();
        let _ = writeln!(
            out,
            "bench calibration {} instructions {} ticks",
            cal.instructions, cal.ticks
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
        let infer_x100 = cal.per_rep_x100(t_inf, base, REPS);
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
            cal.per_rep_x100(t_sig, base_sig, REPS)
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
            cal.per_rep_x100(t_dot, base_dot, REPS * 64)
        );

        if let Ok((header, _)) = vectors::parse(VECTORS) {
            if let Ok(cfg) = header.config() {
                let st = ControlState::new(&cfg.limits, &[0.0; MAX_TENDONS], 0);
                let t_step = ticks(|| {
                    for i in 0..REPS as usize {
                        if let Some(p) = poses.get(i % k) {
                            let input = StepInput {
                                now_ns: 1_000_000,
                                setpoint: Some(ControlSetpoint {
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
                    cal.per_rep_x100(t_step, base, REPS)
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
            cal.per_rep_x100(t_val, 0, DREPS),
            cal.per_rep_x100(t_dec, 0, DREPS)
        );
    }

    #[entry]
    fn main() -> ! {
        // The hot-swap RAM slot: all zeros, so it sits in .bss.
        static mut RAM_NET: McuNet = McuNet::empty();
        rt::semihosted(|out| {
            let stack = rt::stack::paint();
            let ok = {
                let mut store = McuSlots::new(&DEFAULT_NET, &mut *RAM_NET);
                match vectors::run(&mut store, &BLOBS, VECTORS, out) {
                    Ok(_) => true,
                    Err(e) => {
                        let _ = writeln!(out, "error {e}");
                        false
                    }
                }
            };
            // Stack of the run itself (control steps, inference, printing).
            let _ = writeln!(out, "stack_run {}", stack.high_water());
            if ok {
                bench(&DEFAULT_NET, RAM_NET, out);
            }
            let _ = writeln!(out, "stack_total {}", stack.high_water());
            ok
        })
    }
}

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

    use cortex_m_rt::entry;
    use tendril_firmware::control::{
        control_step, ControlConfig, ControlSetpoint, ControlState, StepInput,
    };
    use tendril_firmware::rt::{self, cycles::ticks, cycles::Calibration, Console};
    use tendril_firmware::swap_demo::{self, Offer, BLOB_LEN};
    use tendril_firmware::{
        infer, McuNet, McuSlots, McuSwap, NetStore, SwapEvent, DEFAULT_NET, POSE_DIM,
        SWAP_SLICE_BYTES,
    };
    use tendril_shared::MAX_TENDONS;

    fn write_hex(out: &mut Console, values: &[f32]) {
        for v in values {
            let _ = write!(out, " {:08x}", v.to_bits());
        }
    }

    #[entry]
    fn main() -> ! {
        static mut RAM_NET: McuNet = McuNet::empty();
        // The blobs as a bus driver would hold them: one receive buffer each.
        static mut BLOBS: [[u8; BLOB_LEN]; 4] = [[0; BLOB_LEN]; 4];
        rt::semihosted(|out| run(RAM_NET, BLOBS, out))
    }

    /// The run; whether it completed.
    fn run(
        ram_net: &'static mut McuNet,
        blobs: &'static mut [[u8; BLOB_LEN]; 4],
        out: &mut Console,
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
        let stack = rt::stack::paint();
        let cal = Calibration::measure();
        let _ = writeln!(
            out,
            "calibration {} instructions {} ticks",
            cal.instructions, cal.ticks
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
                setpoint: Some(ControlSetpoint {
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
                cal.instructions(t_step),
                cal.instructions(t_slice)
            );
            write_hex(out, &y);
            let _ = writeln!(out);
        }
        let _ = writeln!(out, "stack_high_water {}", stack.high_water());
        let _ = writeln!(out, "done {}", swap_demo::PERIODS);
        true
    }
}

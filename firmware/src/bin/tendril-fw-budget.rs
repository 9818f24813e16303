//! MCU budget image (issue 25): the real controller node
//! ([`tendril_firmware::node::Node`], the code `tendril-fw-stm32` runs) on
//! QEMU's `mps2-an386`, where `-icount shift=0` makes SysTick count
//! instructions (the STM32F405 model has no cycle counter worth the name).
//!
//! The node gets its link bytes from a small in-image board whose queues
//! have the STM32F405 board's sizes and the same per-byte queue work; the
//! bytes are frames this image encodes with the link's own encoder:
//!
//! 1. a `Down::Setup` built as the host's `setup_for` makes it (`node::setup_of`)
//!    for the seed robot (4 tendons, 0–10 N, slew 200 N/s, 100 Hz, ki 4,
//!    lead 20.5 ms, stuck-motor detection on);
//! 2. [`PERIODS`] periods in lock-step, each one node tick with the bytes
//!    of that period: a setpoint on a circle (velocity and a tangent that
//!    turns with it, sent every period: the most bytes a setpoint has), the
//!    feedback of a first-order motor following the last command, perhaps
//!    one weight-update chunk, and the `Down::Step` that runs the period;
//! 3. two weight updates in [`tendril_shared::link::wire::MAX_CHUNK`]
//!    chunks, one chunk per period: the largest net the buffer takes
//!    (7-64-8, refused at install: the robot has 4 tendons, after every
//!    check slice) and then the largest net this robot runs (7-64-4,
//!    checked and installed, so the install slice is measured too, and the
//!    periods after it infer through 64 hidden units).
//!
//! Every tick's instructions are measured (SysTick, calibrated), the stack
//! is repainted before each tick and its high-water mark read after, and
//! the node's output frames are decoded so the run proves the periods ran
//! the whole control step. Output (semihosting), one line each:
//!
//! `period <k> <instructions> <chunk 0|1> <slice 0|1> <stack bytes below the
//! tick's call>` per period, then
//! `budget <name> <value>` lines, then `done`.
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
    // MCU only: the host side of this run is tests/tests/mcu_budget.rs.
}

/// Periods in lock-step (3 s at 100 Hz).
#[cfg(target_os = "none")]
const PERIODS: u32 = 400;

#[cfg(target_os = "none")]
mod mcu {
    use core::fmt::Write;
    use core::ptr::addr_of;

    use cortex_m_rt::entry;
    use heapless::spsc::{Consumer, Producer, Queue};
    use tendril_firmware::board::Board;
    use tendril_firmware::control::{ControlConfig, IntegralConfig, SafeHold};
    use tendril_firmware::node::{self, Node, MCU_UPDATE_CAPACITY, RX_FRAME, TX_FRAME};
    use tendril_firmware::period::event;
    use tendril_firmware::period::{PeriodConfig, StuckConfig};
    use tendril_firmware::rt::{self, cycles::ticks, cycles::Calibration, Console};
    use tendril_firmware::synth::{synthetic_blob, INPUT_HI, INPUT_LO};
    use tendril_firmware::{McuNet, McuSlots, DEFAULT_NET, DEFAULT_NET_CRC};
    use tendril_shared::link::wire::{
        Down, Feedback, LinkSetpoint, LinkTangent, Setup, Up, WirePose, MAX_CHUNK,
    };
    use tendril_shared::link::{encode, FrameDecoder};
    use tendril_shared::{CoContraction, TendonLimits, MAX_TENDONS};

    use super::PERIODS;

    /// The STM32F405 board's receive and transmit queue sizes
    /// (`board::stm32f405::{RX_QUEUE, TX_QUEUE}`, which exist only in that
    /// board's build).
    const RX_QUEUE: usize = 512;
    const TX_QUEUE: usize = 512;
    /// The board's tick: 1 kHz, as on the STM32F405.
    const TICK_NS: u32 = 1_000_000;
    /// The control period: 100 Hz.
    const PERIOD_NS: u32 = 10_000_000;
    const TENDONS: usize = 4;
    const MAX_TENSION: f32 = 10.0;
    /// The two updates start at these periods.
    const UPDATE_8_AT: u32 = 100;
    const UPDATE_4_AT: u32 = 200;
    /// Seeds of the synthetic nets.
    const SEED_8: u64 = 0x7E57_0008;
    const SEED_4: u64 = 0x7E57_0004;

    /// The board: the node's ends of two byte queues, like the STM32F405
    /// board's (whose other ends are its USART1 interrupt; here the driver
    /// below). Its clock advances one tick per node tick.
    struct BudgetBoard {
        rx: Consumer<'static, u8>,
        tx: Producer<'static, u8>,
        now_ns: u64,
        tensions: [f32; MAX_TENDONS],
    }

    impl Board for BudgetBoard {
        fn wait_tick(&mut self) -> u32 {
            0
        }

        fn now_ns(&self) -> u64 {
            self.now_ns
        }

        fn set_tensions(&mut self, tensions: &[f32]) {
            for (slot, t) in self.tensions.iter_mut().zip(tensions) {
                *slot = *t;
            }
        }

        fn link_read(&mut self, buf: &mut [u8]) -> usize {
            let mut n = 0;
            for slot in buf.iter_mut() {
                match self.rx.dequeue() {
                    Some(b) => {
                        *slot = b;
                        n += 1;
                    }
                    None => break,
                }
            }
            n
        }

        fn link_write(&mut self, bytes: &[u8]) -> usize {
            let mut n = 0;
            for &b in bytes {
                if self.tx.enqueue(b).is_err() {
                    break;
                }
                n += 1;
            }
            n
        }
    }

    /// The host's side: frames into the node's receive queue, frames out
    /// of its transmit queue, and what they said.
    struct Host {
        to_node: Producer<'static, u8>,
        from_node: Consumer<'static, u8>,
        up: FrameDecoder<TX_FRAME>,
        /// The last command: its seq and tensions.
        last_seq: u32,
        last_tensions: [f32; MAX_TENDONS],
        /// The simulated motors' tensions (first order, τ = 20 ms).
        motors: [f32; MAX_TENDONS],
        commands: u32,
        telemetry: u32,
        hellos: u32,
        setup_error: Option<u8>,
        events_seen: u32,
        swapped: u32,
        rejected: u32,
        /// Events of the last command.
        last_events: u32,
        bad: u32,
    }

    impl Host {
        /// Frame `msg` into the node's receive queue; whether it all fit.
        fn send(&mut self, msg: &Down<'_>) -> bool {
            let mut buf = [0u8; RX_FRAME];
            let Ok(frame) = encode(msg, &mut buf) else {
                return false;
            };
            frame.iter().all(|&b| self.to_node.enqueue(b).is_ok())
        }

        /// Decode what the node sent.
        fn receive(&mut self) {
            while let Some(b) = self.from_node.dequeue() {
                let Some(frame) = self.up.push_raw(b) else {
                    continue;
                };
                match frame.map(postcard::from_bytes::<Up>) {
                    Ok(Ok(Up::Command(c))) => {
                        self.commands += 1;
                        self.last_seq = c.seq;
                        for (d, s) in self.last_tensions.iter_mut().zip(&c.tensions) {
                            *d = *s;
                        }
                        self.events_seen |= c.events;
                        self.last_events = c.events;
                        if c.events & event::WEIGHTS_SWAPPED != 0 {
                            self.swapped += 1;
                        }
                        if c.events & event::WEIGHTS_REJECTED != 0 {
                            self.rejected += 1;
                        }
                    }
                    Ok(Ok(Up::Telemetry(_))) => self.telemetry += 1,
                    Ok(Ok(Up::Hello(h))) => {
                        self.hellos += 1;
                        if h.setup_hash != 0 {
                            self.setup_error = Some(h.setup_error);
                        }
                    }
                    _ => self.bad += 1,
                }
            }
        }
    }

    /// The seed robot's configuration as the host's controller sets it up
    /// (`ControllerConfig`'s defaults at 100 Hz: ki 4 /s with its filter
    /// and error map, the stuck-motor check on), flattened for the link by
    /// the one mapping the host's bridge uses (`node::setup_of`):
    /// antagonistic pairs (0, 2) and (1, 3) at equal offsets.
    /// None if the limits do not validate.
    fn setup() -> Option<Setup> {
        let sets: [u8; TENDONS] = core::array::from_fn(|i| (i % 2) as u8);
        let limits = TendonLimits::new(&[MAX_TENSION; TENDONS], &[200.0; TENDONS])
            .and_then(|l| l.with_cocontraction(CoContraction::new(&sets, &[1.0; TENDONS])?))
            .ok()?;
        let period = u64::from(PERIOD_NS);
        let mut control = ControlConfig::new(limits);
        // 2.5 periods.
        control.watchdog_ns = period * 5 / 2;
        control.max_dt_ns = 5 * period;
        control.quaternion_tolerance = 1e-2;
        control.box_margin = 0.05;
        control.safe_hold = SafeHold::Freeze;
        // The host's default correction (design §6.3): the filter and the
        // error map run in every period, so their cost is counted.
        control.integral = IntegralConfig {
            ki: 4.0,
            limit: 0.02,
            feedback_timeout_ns: 25 * period,
            window: 0.02,
            filter_tau_s: 0.08,
            map_gain: 2.0,
            map_scale: 0.01,
            map_limit: 0.5,
        };
        Some(node::setup_of(&PeriodConfig {
            control,
            period_ns: period,
            lead_s: 0.0205,
            plant_stale_ns: 20 * period,
            stuck: StuckConfig {
                enabled: true,
                // 1 − exp(−T/τ), T = 10 ms, τ = 20 ms.
                model_gain: 1.0 - libm::expf(-0.5),
                tension_error_n: 0.5,
                persist_ns: 100_000_000,
            },
            swap_slice_bytes: tendril_firmware::SWAP_SLICE_BYTES,
            jump_m: 1e-3,
            settle_after_jump_ns: 300_000_000,
            commands_in_flight: node::LINK_COMMANDS_IN_FLIGHT,
        }))
    }

    /// The circle: centre and radius inside both nets' input boxes.
    struct Circle {
        centre: [f32; 7],
        radius: f32,
    }

    impl Circle {
        fn new() -> Circle {
            let (lo, hi) = (DEFAULT_NET.input_lo(), DEFAULT_NET.input_hi());
            let mut centre = [0.0f32; 7];
            let mut half = [0.0f32; 7];
            let bounds = lo.iter().zip(hi).zip(INPUT_LO.iter().zip(&INPUT_HI));
            for ((c, h), ((&l0, &h0), (&l1, &h1))) in centre.iter_mut().zip(&mut half).zip(bounds) {
                let (a, b) = (l0.max(l1), h0.min(h1));
                *c = 0.5 * (a + b);
                *h = 0.5 * (b - a);
            }
            // A unit quaternion.
            let [_, _, _, w, x, y, z] = centre;
            let norm = libm::sqrtf(w * w + x * x + y * y + z * z).max(1e-6);
            for q in centre.iter_mut().skip(3) {
                *q /= norm;
            }
            Circle {
                centre,
                radius: 0.3 * half[0].min(half[1]),
            }
        }

        /// Period `k`'s pose and velocity (one turn in 2 s).
        fn at(&self, k: u32) -> ([f32; 7], [f32; 7]) {
            let omega = core::f32::consts::PI; // rad/s
            let th = omega * k as f32 * (PERIOD_NS as f32 * 1e-9);
            let (s, c) = (libm::sinf(th), libm::cosf(th));
            let mut pose = self.centre;
            pose[0] += self.radius * c;
            pose[1] += self.radius * s;
            let mut vel = [0.0f32; 7];
            vel[0] = -self.radius * omega * s;
            vel[1] = self.radius * omega * c;
            (pose, vel)
        }
    }

    /// Bytes of `blob` for period `k` of an update that starts at `start`:
    /// one chunk per period.
    fn chunk_of(blob: &[u8], start: u32, k: u32) -> Option<(u32, &[u8])> {
        let i = k.checked_sub(start)? as usize;
        let off = i.checked_mul(MAX_CHUNK)?;
        let end = off.saturating_add(MAX_CHUNK).min(blob.len());
        blob.get(off..end)
            .filter(|b| !b.is_empty())
            .map(|b| (off as u32, b))
    }

    #[entry]
    fn main() -> ! {
        // As in tendril-fw-stm32: the RAM slot and the node are statics.
        static mut RAM_NET: McuNet = McuNet::empty();
        static mut NODE: Node<MCU_UPDATE_CAPACITY> = Node::new(DEFAULT_NET_CRC, TICK_NS);
        static mut RX_Q: Queue<u8, RX_QUEUE> = Queue::new();
        static mut TX_Q: Queue<u8, TX_QUEUE> = Queue::new();
        // The two update blobs, as the host would hold them.
        static mut BLOB_8: [u8; MCU_UPDATE_CAPACITY] = [0; MCU_UPDATE_CAPACITY];
        static mut BLOB_4: [u8; MCU_UPDATE_CAPACITY] = [0; MCU_UPDATE_CAPACITY];
        static mut INSTR: [u32; PERIODS as usize] = [0; PERIODS as usize];
        let (rx_in, rx_out) = RX_Q.split();
        let (tx_in, tx_out) = TX_Q.split();
        let board = BudgetBoard {
            rx: rx_out,
            tx: tx_in,
            now_ns: 0,
            tensions: [0.0; MAX_TENDONS],
        };
        let host = Host {
            to_node: rx_in,
            from_node: tx_out,
            up: FrameDecoder::new(),
            last_seq: 0,
            last_tensions: [0.0; MAX_TENDONS],
            motors: [0.0; MAX_TENDONS],
            commands: 0,
            telemetry: 0,
            hellos: 0,
            setup_error: None,
            events_seen: 0,
            swapped: 0,
            rejected: 0,
            last_events: 0,
            bad: 0,
        };
        let run_args = Run {
            node: NODE,
            ram_net: RAM_NET,
            board,
            host,
            blob_8: BLOB_8,
            blob_4: BLOB_4,
            instr: INSTR,
        };
        rt::semihosted(|out| run(run_args, out))
    }

    struct Run {
        node: &'static mut Node<MCU_UPDATE_CAPACITY>,
        ram_net: &'static mut McuNet,
        board: BudgetBoard,
        host: Host,
        blob_8: &'static mut [u8; MCU_UPDATE_CAPACITY],
        blob_4: &'static mut [u8; MCU_UPDATE_CAPACITY],
        instr: &'static mut [u32; PERIODS as usize],
    }

    extern "C" {
        /// Top of RAM (cortex-m-rt's link.x): where the stack starts.
        static _stack_start: u32;
    }

    /// The stack pointer.
    #[inline(always)]
    fn stack_pointer() -> usize {
        let sp: usize;
        // SAFETY: reads the stack pointer register, touches no memory.
        unsafe { core::arch::asm!("mov {}, sp", out(reg) sp) };
        sp
    }

    /// The run; whether it completed and the node did what it should.
    fn run(r: Run, out: &mut Console) -> bool {
        let Run {
            node,
            ram_net,
            mut board,
            mut host,
            blob_8,
            blob_4,
            instr,
        } = r;
        // The blobs first: the synthetic-net encoder keeps its weights on
        // the stack, which is not the node's.
        let Ok(len_8) = synthetic_blob(SEED_8, 64, 8, MAX_TENSION, blob_8) else {
            let _ = writeln!(out, "error blob 7-64-8");
            return false;
        };
        let Ok(len_4) = synthetic_blob(SEED_4, 64, TENDONS, MAX_TENSION, blob_4) else {
            let _ = writeln!(out, "error blob 7-64-4");
            return false;
        };
        let blob_8 = blob_8.get(..len_8).unwrap_or(&[]);
        let blob_4 = blob_4.get(..len_4).unwrap_or(&[]);
        let cal = Calibration::measure();
        let _ = writeln!(
            out,
            "calibration {} instructions {} ticks",
            cal.instructions, cal.ticks
        );
        let mut store = McuSlots::new(&DEFAULT_NET, ram_net);
        let top = addr_of!(_stack_start) as usize;
        let circle = Circle::new();
        let Some(cfg) = setup() else {
            let _ = writeln!(out, "error setup limits");
            return false;
        };
        let gain = cfg.stuck_model_gain;

        // The Setup tick (not a period: lock-step starts with the first Step).
        if !host.send(&Down::Setup(cfg)) {
            let _ = writeln!(out, "error setup frame");
            return false;
        }
        board.now_ns += u64::from(TICK_NS);
        // Its stack counts too: a Setup configures the period (in place),
        // on any tick a host sends one.
        let paint = rt::stack::paint();
        let sp_at_call = stack_pointer();
        let t_setup = ticks(|| node.tick(&mut board, &mut store, 0));
        let setup_stack = paint
            .high_water()
            .saturating_sub(top.saturating_sub(sp_at_call));
        host.receive();
        if host.setup_error != Some(0) {
            let _ = writeln!(out, "error setup refused {:?}", host.setup_error);
            return false;
        }
        let _ = writeln!(
            out,
            "budget setup_tick_instructions {}",
            cal.instructions(t_setup)
        );

        let mut worst = 0u64;
        let mut worst_slice = 0u64;
        let mut worst_chunk = 0u64;
        let mut worst_plain = 0u64;
        // The period whose slice installed the 7-64-4 net.
        let mut install = 0u64;
        let mut slice_periods = 0u32;
        let mut chunk_periods = 0u32;
        let mut stack_high = 0usize;
        let mut node_stack = setup_stack;
        // A check runs from the period of an update's last chunk until a
        // command says it ended (swapped or refused).
        let mut checking = false;
        for (k, slot) in (1..=PERIODS).zip(instr.iter_mut()) {
            let now_ns = u64::from(k) * u64::from(PERIOD_NS);
            let (pose, vel) = circle.at(k);
            let th = k as f32 * 0.0314;
            let tilt = 0.1 * libm::cosf(th);
            let tangent = LinkTangent {
                dim: 2,
                columns: [
                    [1.0, 0.0, 0.0, 0.0, 0.0, tilt, 0.0],
                    [0.0, 1.0, 0.0, 0.0, -tilt, 0.0, 0.0],
                    [0.0; 7],
                ],
                axes: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0; 3]],
            };
            let sp = Down::Setpoint(LinkSetpoint {
                seq: k,
                count: 1,
                superseded_nonfinite: 0,
                pose: WirePose::from_pose(&pose),
                velocity: Some(LinkSetpoint::wire_velocity(&vel)),
                tangent: Some(tangent),
                age_us: 4_000,
            });
            // The motors follow the last command with τ = 20 ms; the tip
            // lags the setpoint by 0.5 mm (inside the correction window).
            for (m, c) in host.motors.iter_mut().zip(host.last_tensions) {
                *m += gain * (c - *m);
            }
            let mut tensions = heapless::Vec::new();
            for m in host.motors.iter().take(TENDONS) {
                let _ = tensions.push(tendril_shared::link::wire::units::to_i32(
                    *m,
                    tendril_shared::link::wire::units::TENSION_N,
                ));
            }
            let tip = [pose[0] - 0.0005, pose[1], pose[2]]
                .map(|v| tendril_shared::link::wire::units::to_i32(v, 1e-6));
            let fb = Down::Feedback(Feedback {
                seq: k,
                count: 1,
                command_seq: host.last_seq,
                tensions,
                tip,
                // A new frame every period, 5 ms old: the integration and
                // the map update run in every period (the worst case).
                tip_seq: k + 1,
                tip_age_us: 5_000,
            });
            let chunk = chunk_of(blob_8, UPDATE_8_AT, k)
                .map(|c| (c, blob_8.len()))
                .or_else(|| chunk_of(blob_4, UPDATE_4_AT, k).map(|c| (c, blob_4.len())));
            let mut sent = host.send(&sp) && host.send(&fb);
            if let Some(((offset, bytes), total)) = chunk {
                sent &= host.send(&Down::Chunk {
                    offset,
                    total: total as u32,
                    bytes,
                });
                chunk_periods += 1;
                if offset as usize + bytes.len() == total {
                    checking = true;
                }
            }
            sent &= host.send(&Down::Step { now_ns });
            if !sent {
                let _ = writeln!(out, "error period {k}: receive queue full");
                return false;
            }
            let slice = checking;
            // Repaint below this frame: the mark after the tick is the
            // tick's own (plus this frame and its callers).
            let paint = rt::stack::paint();
            let sp_at_call = stack_pointer();
            board.now_ns = now_ns;
            let commands = host.commands;
            let t = ticks(|| node.tick(&mut board, &mut store, 0));
            let n = cal.instructions(t);
            let hw = paint.high_water();
            let below = hw.saturating_sub(top.saturating_sub(sp_at_call));
            stack_high = stack_high.max(hw);
            node_stack = node_stack.max(below);
            host.receive();
            if host.commands != commands + 1 {
                let _ = writeln!(out, "error period {k}: no command");
                return false;
            }
            if host.last_events & (event::WEIGHTS_SWAPPED | event::WEIGHTS_REJECTED) != 0 {
                checking = false;
            }
            if host.last_events & event::WEIGHTS_SWAPPED != 0 {
                install = n;
            }
            *slot = n.min(u64::from(u32::MAX)) as u32;
            worst = worst.max(n);
            if slice {
                worst_slice = worst_slice.max(n);
                slice_periods += 1;
            }
            if chunk.is_some() {
                worst_chunk = worst_chunk.max(n);
            }
            if !slice && chunk.is_none() {
                worst_plain = worst_plain.max(n);
            }
            let _ = writeln!(
                out,
                "period {k} {n} {} {} {below}",
                u8::from(chunk.is_some()),
                u8::from(slice)
            );
        }
        instr.sort_unstable();
        let p50 = instr.get(instr.len() / 2).copied().unwrap_or(0);
        let lines: [(&str, u64); 22] = [
            ("periods", u64::from(PERIODS)),
            ("worst_period_instructions", worst),
            ("p50_period_instructions", u64::from(p50)),
            ("worst_swap_slice_period_instructions", worst_slice),
            ("install_period_instructions", install),
            ("worst_chunk_period_instructions", worst_chunk),
            ("worst_plain_period_instructions", worst_plain),
            ("swap_slice_periods", u64::from(slice_periods)),
            ("chunk_periods", u64::from(chunk_periods)),
            ("stack_bytes", stack_high as u64),
            ("node_stack_bytes", node_stack as u64),
            ("setup_tick_stack_bytes", setup_stack as u64),
            ("update_8_bytes", blob_8.len() as u64),
            ("update_4_bytes", blob_4.len() as u64),
            ("commands", u64::from(host.commands)),
            ("telemetry", u64::from(host.telemetry)),
            ("swapped", u64::from(host.swapped)),
            ("rejected", u64::from(host.rejected)),
            ("bad_frames", u64::from(host.bad)),
            ("events_seen", u64::from(host.events_seen)),
            ("node_static_bytes", core::mem::size_of_val(&*node) as u64),
            ("ram_net_bytes", core::mem::size_of::<McuNet>() as u64),
        ];
        for (name, v) in lines {
            let _ = writeln!(out, "budget {name} {v}");
        }
        let _ = writeln!(out, "done");
        true
    }

    // `rt` provides the fault and panic handlers.
    #[allow(unused_imports)]
    use rt as _;
}

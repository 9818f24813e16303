//! The controller node: the whole control period ([`crate::period`]) on a
//! [`Board`], fed and read over the link (docs/design.md §5.6). One
//! [`Node::tick`] per tick of the board's timer:
//!
//! 1. drain the link's received bytes (bounded by the receive queue) into
//!    the frame decoder; act on every whole message: a Hello is answered,
//!    a Setup configures (or, if it is the running configuration, keeps)
//!    the controller, the newest setpoint and feedback wait for the
//!    period, an update chunk goes into the period's update buffer;
//! 2. run the period (once configured) and apply its tensions;
//! 3. send the command, and every [`TELEMETRY_EVERY`] ticks the counters.
//!
//! **Lock-step mode** (docs/design.md §5.7): a [`Down::Step`] runs one
//! period at once, at the Step's time, on what arrived before it, and
//! from then on the timer runs no periods (until a new Setup). The first
//! Step since a Setup starts the period afresh at its time (keeping any
//! update chunks): what the timer ran before it is dropped, so no input of
//! a period comes from the chip's own clock.
//!
//! Before a configuration arrives the motors get nothing and the node
//! announces itself with a Hello every [`TELEMETRY_EVERY`] ticks. Garbage,
//! truncated, oversized or undecodable frames are counted and dropped by
//! the frame layer and here; none of them costs more than its bytes.

use serde::Deserialize;
use tendril_shared::link::wire::{
    Down, EventDetail, Feedback, Hello, LinkCommand, LinkSetpoint, Setup, Telemetry, Up,
    MAX_DOWN_PAYLOAD, MAX_UP_PAYLOAD, PROTOCOL_VERSION, TELEMETRY_EVERY,
};
use tendril_shared::link::{encode, max_frame_len, FrameCounters, FrameDecoder};
use tendril_shared::{MAX_HIDDEN, MAX_TENDONS, MAX_WEIGHTS, POSE_DIM};

use crate::board::Board;
use crate::control::ControlTangent;
use crate::period::{FeedbackIn, Inputs, Period, SetpointIn, Update};
use crate::swap::NetStore;

mod setup;
pub use setup::{period_config, setup_error, setup_of, LINK_COMMANDS_IN_FLIGHT};

/// Receive frame buffer: the largest host → chip frame.
pub const RX_FRAME: usize = max_frame_len(MAX_DOWN_PAYLOAD);
/// Transmit frame buffer: the largest chip → host frame (plus the 0x00
/// sent ahead of a frame after a partial write).
pub const TX_FRAME: usize = max_frame_len(MAX_UP_PAYLOAD) + 1;

/// The chip's weight-update buffer: the largest net file a controller
/// accepts ([`tendril_shared::MAX_NET_FILE`]: 7 inputs and as many hidden
/// units and outputs as fit the weight store, with its provenance), no
/// more: RAM is the chip's scarcest resource.
pub const MCU_UPDATE_CAPACITY: usize = tendril_shared::MAX_NET_FILE;

/// Bytes of a weight update's check per period on the chip.
pub const SWAP_SLICE_BYTES: usize = crate::SWAP_SLICE_BYTES;

/// What arrived since the last period.
#[derive(Clone, Copy, Debug, Default)]
struct Pending {
    inputs: Inputs,
    hello_asked: bool,
    /// When the newest feedback arrived, ns on the board's clock: on the
    /// timer it waits up to a period for it, and ages meanwhile.
    feedback_received_ns: u64,
    /// When the newest setpoint arrived, ns on the board's clock (likewise).
    setpoint_received_ns: u64,
}

/// The node's state besides the frame decoder (split so a decoded payload,
/// borrowed from the decoder, can be acted on).
#[derive(Debug)]
struct Core<const U: usize> {
    period: Option<Period>,
    /// The weight update being received and checked (the chip's largest
    /// buffer: never moved, never on the stack).
    update: Update<U>,
    setup_hash: u32,
    setup_error: u8,
    net_hash: u32,
    pending: Pending,
    last_tangent: Option<ControlTangent>,
    /// Events of refused chunks, for the next command.
    refused_events: u32,
    bad_messages: u32,
    chunks_refused: u32,
    tx_dropped: u32,
    tx_broken: bool,
    ticks: u32,
    /// The board's tick, ns.
    tick_ns: u32,
    /// Ticks since the last period.
    since_period: u32,
    worst_period_ns: u64,
    last_hold_tick: u32,
    last_hold_silence_us: u32,
    last_telemetry_tick: u32,
    /// A Step came since the last Setup: the timer runs no periods.
    lockstep: bool,
}

/// The controller node; `U` is the weight-update buffer's size, bytes.
pub struct Node<const U: usize> {
    rx: FrameDecoder<RX_FRAME>,
    core: Core<U>,
}

fn tangent_in(t: &tendril_shared::link::wire::LinkTangent) -> ControlTangent {
    ControlTangent {
        dim: usize::from(t.dim),
        columns: t.columns,
        axes: t.axes,
    }
}

impl<const U: usize> Node<U> {
    /// Unconfigured; `net_hash` identifies the built-in net (CRC-32 of
    /// its `.tnet`) in the Hello until an update swaps in another, whose
    /// hash the Hello gives from then on; the board ticks every `tick_ns`. The
    /// link is served every tick; the period runs every
    /// `period_ns / tick_ns` ticks (the Setup's period, a whole number of
    /// ticks: a 100 Hz loop on a 1 kHz board).
    pub const fn new(net_hash: u32, tick_ns: u32) -> Self {
        Node {
            rx: FrameDecoder::new(),
            core: Core {
                period: None,
                update: Update::new(),
                setup_hash: 0,
                setup_error: 0,
                net_hash,
                pending: Pending {
                    inputs: Inputs {
                        now_ns: 0,
                        missed_ticks: 0,
                        setpoint: None,
                        setpoints: 0,
                        superseded_nonfinite: 0,
                        feedback: None,
                        feedbacks: 0,
                    },
                    hello_asked: false,
                    feedback_received_ns: 0,
                    setpoint_received_ns: 0,
                },
                last_tangent: None,
                refused_events: 0,
                bad_messages: 0,
                chunks_refused: 0,
                tx_dropped: 0,
                tx_broken: false,
                ticks: 0,
                tick_ns,
                since_period: 0,
                worst_period_ns: 0,
                last_hold_tick: 0,
                last_hold_silence_us: 0,
                last_telemetry_tick: 0,
                lockstep: false,
            },
        }
    }

    /// Whether the node is in lock-step mode (a [`Down::Step`] came since
    /// the last Setup).
    pub fn lockstep(&self) -> bool {
        self.core.lockstep
    }

    /// The running period, once configured.
    pub fn period(&self) -> Option<&Period> {
        self.core.period.as_ref()
    }

    /// One tick: `missed` ticks were missed before it (from
    /// [`Board::wait_tick`]); `store` holds the running net.
    pub fn tick<B, S>(&mut self, board: &mut B, store: &mut S, missed: u32)
    where
        B: Board,
        S: NetStore<POSE_DIM, MAX_HIDDEN, MAX_TENDONS, MAX_WEIGHTS> + ?Sized,
    {
        let t0 = board.now_ns();
        let core = &mut self.core;
        core.ticks = core.ticks.wrapping_add(1).wrapping_add(missed);
        // 1. The link: every byte that arrived, bounded by the queue size.
        let mut buf = [0u8; 64];
        loop {
            let n = board.link_read(&mut buf);
            for &b in buf.get(..n).unwrap_or(&[]) {
                let mut step = None;
                if let Some(Ok(payload)) = self.rx.push_raw(b) {
                    step = core.receive(payload, t0);
                }
                // Run at once, so the messages after the Step (already in
                // this read) go to the next period, as the host meant.
                if let Some(now_ns) = step {
                    core.step(board, store, now_ns, self.rx.counters());
                }
            }
            if n < buf.len() {
                break;
            }
        }
        if core.pending.hello_asked || (core.period.is_none() && core.ticks % TELEMETRY_EVERY == 1)
        {
            core.pending.hello_asked = false;
            core.send_hello(board);
        }
        // 2. The period, every `per` ticks (none in lock-step mode).
        core.timed_period(board, store, missed, self.rx.counters(), t0);
    }
}

impl<const U: usize> Core<U> {
    /// The timer's period, when `per` ticks have passed since the last (none
    /// in lock-step mode or before a configuration).
    // Not inlined, like `step`: what it needs takes stack only while it
    // runs, not in `tick`'s frame under a lock-step period (tests/tests/
    // mcu_budget.rs measures the stack).
    #[inline(never)]
    fn timed_period<B, S>(
        &mut self,
        board: &mut B,
        store: &mut S,
        missed: u32,
        frames: FrameCounters,
        t0: u64,
    ) where
        B: Board,
        S: NetStore<POSE_DIM, MAX_HIDDEN, MAX_TENDONS, MAX_WEIGHTS> + ?Sized,
    {
        let Some(period) = self.period.as_ref() else {
            self.pending.inputs = Inputs::default();
            return;
        };
        if self.lockstep {
            return;
        }
        let per =
            (period.config().period_ns / u64::from(self.tick_ns.max(1))).clamp(1, 1 << 16) as u32;
        self.since_period = self.since_period.saturating_add(1).saturating_add(missed);
        if self.since_period < per {
            return;
        }
        let missed_periods = self.since_period / per - 1;
        self.since_period %= per;
        // The period reads the pending inputs where they are: a copy of
        // them (312 B) would sit on the stack under the whole period.
        let input = &mut self.pending.inputs;
        input.now_ns = t0;
        input.missed_ticks = missed_periods;
        if let Some(f) = input.feedback.as_mut() {
            // The host gave the tracker frame's age when it sent it; the
            // frame has since waited here for this period (up to a period:
            // 10 ms at 100 Hz, 0.19 mm on the 30 mm circle). Without it the
            // loop compares the tip with the path where the robot was
            // later than the frame shows, and integrates the difference.
            let waited = t0.saturating_sub(self.pending.feedback_received_ns);
            f.tip_age_ns = f.tip_age_ns.saturating_add(waited);
        }
        if let Some(s) = input.setpoint.as_mut() {
            // The setpoint likewise: the period leads it by its age.
            let waited = t0.saturating_sub(self.pending.setpoint_received_ns);
            s.age_ns = s.age_ns.saturating_add(waited);
        }
        self.run_pending(board, store, frames, t0);
    }

    /// A [`Down::Step`]: one period now, at `now_ns`.
    // Not inlined: what it needs then takes stack only while it runs, not
    // in `tick`'s frame through the whole period (tests/tests/
    // mcu_budget.rs measures the stack: 19 KB → 6 KB with the update buffer
    // out of the period, less with these).
    #[inline(never)]
    fn step<B, S>(&mut self, board: &mut B, store: &mut S, now_ns: u64, frames: FrameCounters)
    where
        B: Board,
        S: NetStore<POSE_DIM, MAX_HIDDEN, MAX_TENDONS, MAX_WEIGHTS> + ?Sized,
    {
        let t0 = board.now_ns();
        let Some(period) = self.period.as_mut() else {
            // Nothing to step before a configuration.
            self.bad_messages = self.bad_messages.wrapping_add(1);
            return;
        };
        if !self.lockstep {
            // The Setup configured the period at the chip's clock, and the
            // timer may have run periods since, neither of which the host
            // knows: start afresh at the Step's time instead, keeping any
            // update chunks that came meanwhile. In place: a new period
            // built on the stack would be 1.2 KB.
            period.restart(now_ns);
        }
        self.lockstep = true;
        self.since_period = 0;
        let input = &mut self.pending.inputs;
        input.now_ns = now_ns;
        input.missed_ticks = 0;
        self.run_pending(board, store, frames, t0);
    }

    /// Run the period on the pending inputs (then forgotten), apply and
    /// send its command, and now and then the counters; `t0` is when the
    /// work began (the board's clock).
    fn run_pending<B, S>(&mut self, board: &mut B, store: &mut S, frames: FrameCounters, t0: u64)
    where
        B: Board,
        S: NetStore<POSE_DIM, MAX_HIDDEN, MAX_TENDONS, MAX_WEIGHTS> + ?Sized,
    {
        let core = self;
        let Some(period) = core.period.as_mut() else {
            core.pending.inputs = Inputs::default();
            return;
        };
        let out = period.run(store, &mut core.update, &core.pending.inputs);
        core.pending.inputs = Inputs::default();
        if out.events.has(crate::period::event::WEIGHTS_SWAPPED) {
            // The Hello names the net that runs, so that a host which
            // reconnects sees whether its net is on the chip.
            if let Some(hash) = core.update.blob_hash() {
                core.net_hash = hash;
            }
        }
        if out.events.has(crate::period::event::WATCHDOG_HOLD) {
            core.last_hold_tick = core.ticks;
            core.last_hold_silence_us = (out.events.hold_silence_ns / 1000) as u32;
        }
        let c = &out.command;
        board.set_tensions(c.tensions.get(..c.count).unwrap_or(&[]));
        // 3. The command, and now and then the counters.
        core.send_command(board, &out);
        if core.ticks.wrapping_sub(core.last_telemetry_tick) >= TELEMETRY_EVERY {
            core.send_telemetry(board, frames);
        }
        let took = board.now_ns().saturating_sub(t0);
        core.worst_period_ns = core.worst_period_ns.max(took);
    }

    // The senders are not inlined: each message (up to 152 B) and its
    // frame buffer then take stack only while it is sent, not in the
    // caller's frame through the whole period (tests/tests/mcu_budget.rs
    // measures the stack: 19 KB → 6 KB with the update buffer out of the
    // period, 3.8 KB → 1.8 KB with no message, inputs or period copied
    // under it, issue 43).
    #[inline(never)]
    fn send_command<B: Board>(&mut self, board: &mut B, out: &crate::period::Outputs) {
        let c = &out.command;
        let cmd = Up::Command(LinkCommand {
            seq: c.seq as u32,
            setpoint_seq: c.setpoint_seq as u32,
            status: c.status,
            events: out.events.bits | self.refused_events,
            detail: detail_of(&out.events),
            tensions: heapless::Vec::from_slice(c.tensions.get(..c.count).unwrap_or(&[]))
                .unwrap_or_default(),
        });
        self.refused_events = 0;
        self.send(board, &cmd);
    }

    #[inline(never)]
    fn send_hello<B: Board>(&mut self, board: &mut B) {
        let hello = Up::Hello(Hello {
            protocol: PROTOCOL_VERSION,
            net_hash: self.net_hash,
            setup_hash: self.setup_hash,
            setup_error: self.setup_error,
        });
        self.send(board, &hello);
    }

    #[inline(never)]
    fn send_telemetry<B: Board>(&mut self, board: &mut B, frames: FrameCounters) {
        let counters = self
            .period
            .as_ref()
            .map(|p| *p.counters())
            .unwrap_or_default();
        self.last_telemetry_tick = self.ticks;
        let t = Up::Telemetry(Telemetry {
            counters,
            frames,
            rx_overruns: board.link_overruns(),
            tx_dropped: self.tx_dropped,
            ticks: self.ticks,
            tick_ns: self.tick_ns,
            bad_messages: self.bad_messages,
            chunks_refused: self.chunks_refused,
            worst_period_us: (self.worst_period_ns / 1000) as u32,
            last_hold_tick: self.last_hold_tick,
            last_hold_silence_us: self.last_hold_silence_us,
        });
        self.send(board, &t);
    }

    /// Decode one frame's payload and act on it; a Step's time is returned
    /// (the caller runs the period at once).
    #[inline(never)]
    fn receive(&mut self, payload: &[u8], now_ns: u64) -> Option<u64> {
        // `Down::deserialize` itself, matched by reference: `from_bytes`
        // (`?` then `Ok`) and a by-value match each made a second copy of
        // the message (up to 240 B) in this frame.
        let mut de = postcard::Deserializer::from_bytes(payload);
        match &Down::deserialize(&mut de) {
            Ok(Down::Step { now_ns: at }) => Some(*at),
            Ok(msg) => {
                self.handle(msg, now_ns);
                None
            }
            Err(_) => {
                self.bad_messages = self.bad_messages.wrapping_add(1);
                None
            }
        }
    }

    fn handle(&mut self, msg: &Down<'_>, now_ns: u64) {
        match msg {
            Down::Hello { .. } => self.pending.hello_asked = true,
            Down::Setup(s) => self.configure(s, now_ns),
            Down::Setpoint(s) => self.setpoint(s, now_ns),
            // Taken by `Node::tick`, which has the board and the store.
            Down::Step { .. } => {}
            Down::Feedback(f) => self.feedback(f, now_ns),
            Down::Chunk {
                offset,
                total,
                bytes,
            } => {
                let Some(period) = self.period.as_mut() else {
                    self.chunks_refused = self.chunks_refused.wrapping_add(1);
                    return;
                };
                if let Err(e) = self.update.chunk(*offset as usize, *total as usize, bytes) {
                    self.chunks_refused = self.chunks_refused.wrapping_add(1);
                    self.refused_events |= period.refuse_update(e).bits;
                }
            }
        }
    }

    /// A Setup: configure (or, if it is the running configuration, keep)
    /// the controller.
    // Not inlined: its configuration (328 B) and the validation's
    // temporaries take stack only while a Setup is handled, not in
    // `receive`'s frame at every message.
    #[inline(never)]
    fn configure(&mut self, s: &Setup, now_ns: u64) {
        self.pending.hello_asked = true;
        let hash = setup_hash(s);
        if self.period.is_some() && hash == self.setup_hash {
            // The running configuration: keep the loop (and forget a
            // refusal before it: the last Setup was not refused).
            self.setup_error = 0;
            return;
        }
        // `period_config` in its two steps, so neither runs on top of the
        // other; matched by reference: a moved copy of the configuration
        // would be a second one (328 B) in this frame.
        match &setup::limits_of(s).and_then(|limits| setup::config_with(s, limits)) {
            Ok(cfg) => {
                // In place: a new period built on the stack and moved here
                // would be 1.2 KB of it.
                Period::configure(&mut self.period, cfg, now_ns);
                self.update.reset();
                self.since_period = 0;
                self.setup_hash = hash;
                self.setup_error = 0;
                self.last_tangent = None;
                self.lockstep = false;
            }
            Err(e) => self.setup_error = *e,
        }
    }

    // `setpoint` and `feedback` are not inlined: what they build (up to
    // 200 B) would otherwise sit in `receive`'s frame under a Setup too.
    #[inline(never)]
    fn setpoint(&mut self, s: &LinkSetpoint, now_ns: u64) {
        self.pending.setpoint_received_ns = now_ns;
        if let Some(t) = &s.tangent {
            self.last_tangent = Some(tangent_in(t));
        }
        let i = &mut self.pending.inputs;
        // Several in one period: the newest is taken, the others counted.
        i.setpoints = i.setpoints.saturating_add(u32::from(s.count.max(1)));
        i.superseded_nonfinite = i
            .superseded_nonfinite
            .saturating_add(u32::from(s.superseded_nonfinite));
        if let Some(prev) = &i.setpoint {
            if prev.pose.iter().any(|v| !v.is_finite()) {
                i.superseded_nonfinite = i.superseded_nonfinite.saturating_add(1);
            }
        }
        i.setpoint = Some(SetpointIn {
            seq: u64::from(s.seq),
            pose: s.pose.pose(),
            velocity: s.velocity(),
            tangent: self.last_tangent,
            age_ns: u64::from(s.age_us) * 1000,
        });
    }

    #[inline(never)]
    fn feedback(&mut self, f: &Feedback, now_ns: u64) {
        self.pending.feedback_received_ns = now_ns;
        let i = &mut self.pending.inputs;
        i.feedbacks = i.feedbacks.saturating_add(u32::from(f.count.max(1)));
        i.feedback = Some(FeedbackIn {
            seq: u64::from(f.seq),
            command_seq: u64::from(f.command_seq),
            tensions: f.tensions_n(),
            tip: f.tip_m(),
            tip_seq: f.tip_seq,
            tip_age_ns: u64::from(f.tip_age_us) * 1000,
        });
    }

    /// Frame and queue one message; a frame the queue cannot take whole is
    /// dropped and counted, and the next frame starts with a 0x00 so the
    /// host drops the fragment instead of the next frame.
    // Not inlined: its frame buffer takes stack only while it runs.
    #[inline(never)]
    fn send<B: Board>(&mut self, board: &mut B, msg: &Up) {
        let mut buf = [0u8; TX_FRAME];
        let (lead, rest) = buf.split_at_mut(1);
        let Ok(frame) = encode(msg, rest) else {
            self.tx_dropped = self.tx_dropped.wrapping_add(1);
            return;
        };
        let len = frame.len();
        let start = if self.tx_broken {
            if let Some(b) = lead.first_mut() {
                *b = 0;
            }
            0
        } else {
            1
        };
        let out = buf.get(start..1 + len).unwrap_or(&[]);
        let sent = board.link_write(out);
        self.tx_broken = sent < out.len();
        if self.tx_broken {
            self.tx_dropped = self.tx_dropped.wrapping_add(1);
        }
    }
}

/// [`Setup::hash`], not inlined: its 256-byte buffer then takes no stack
/// in [`Core::configure`]'s frame while the configuration is validated.
#[inline(never)]
fn setup_hash(s: &Setup) -> u32 {
    s.hash()
}

/// The values of `e` for the wire (saturated to `u32`).
fn detail_of(e: &crate::period::Events) -> EventDetail {
    let sat = |v: u64| u32::try_from(v).unwrap_or(u32::MAX);
    EventDetail {
        setpoints_lost: sat(e.setpoints_lost),
        plant_states_lost: sat(e.plant_states_lost),
        commands_behind: sat(e.commands_behind),
        stuck: e.stuck,
        hold_silence_us: sat(e.hold_silence_ns / 1000),
    }
}

#[cfg(test)]
mod tests;

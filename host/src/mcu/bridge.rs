//! The bridge: the controller process with the chip in the loop
//! (`tendril controller --mcu`, `tendril sim --controller mcu`). The chip
//! runs the whole control period on its own timer; the bridge maps the
//! iceoryx2 services to link frames and back:
//!
//! planner → setpoint → frame → chip → command frame → tension command → plant
//!
//! and the plant's state → feedback frame → chip. It forwards the newest
//! setpoint and plant state as soon as they arrive (polling every
//! [`POLL_US`] µs), a weight update as chunks, and publishes every command
//! the chip sends, raising the plant's event. It decides nothing: every
//! rule runs on the chip, and the report's counts are the chip's own
//! (telemetry), its fault list built from the events each command carries.

use std::time::Duration;

use anyhow::Result;
use tendril_firmware::period::{event, Counters, Events};
use tendril_shared::link::wire::{Down, LinkCommand, Telemetry, Up, MAX_CHUNK};
use tendril_shared::messages::{
    Header, PlantState, Setpoint, TensionCommand, WeightUpdate, MAX_TENDONS,
};

use super::{locate_image, Chip, McuLink};
use crate::ipc::clock::now_ns;
use crate::ipc::controller::{
    log_header, ControllerConfig, ControllerStats, FaultLog, McuOptions, MoveQuiet,
};
use crate::ipc::process::{self, Stepped};
use crate::ipc::stats::{CsvLog, Histogram};
use crate::ipc::transport::{self, Services};
use crate::ipc::IpcError;

/// The loop's rate with the chip in the loop unless told otherwise, Hz:
/// QEMU 7.2's STM32 USART takes one received byte at a time (12.6 kB/s
/// with multi-threaded TCG, 74 kB/s single-threaded in an echo test, about
/// 10–12 kB/s usable in a loaded closed loop); a setpoint and a feedback
/// frame take ~70 bytes, so 100 periods a second use about two thirds of
/// it and leave room for weight-update chunks and tangents. At 1 kHz the
/// link saturates (measured: the chip missed periods and its stuck-motor
/// rule fired on stale feedback). A real board at 2 Mbaud carries 1 kHz.
pub const MCU_RATE_HZ: f64 = 100.0;

/// The chip's tick, Hz: its period is a whole number of ticks.
pub const CHIP_TICK_HZ: f64 = 1000.0;

/// Check that the chip can run its period at `rate_hz`: a whole number of
/// its 1 ms ticks (1000, 500, 333.33…, 250, … Hz). Otherwise the chip would
/// silently run the nearest slower whole period (`--rate 300` ran at
/// 333 Hz, `--rate 20000` at 1 kHz); the error names the rates near it.
pub fn check_chip_rate(rate_hz: f64) -> Result<(), String> {
    let ticks = CHIP_TICK_HZ / rate_hz;
    if rate_hz.is_finite() && ticks >= 1.0 - 1e-9 && (ticks - ticks.round()).abs() < 1e-6 {
        return Ok(());
    }
    let k = ticks.floor().clamp(1.0, 1e6);
    Err(format!(
        "--rate {}: the chip's period is a whole number of its 1 ms ticks, so its rate is \
         1000/k Hz (the nearest: {:.4} and {:.4} Hz)",
        crate::units::given(rate_hz),
        CHIP_TICK_HZ / (k + 1.0),
        CHIP_TICK_HZ / k
    ))
}

/// How long the bridge holds the planner's setpoints back while the chip
/// installs the run's net at the start, ns (the upload takes ~1 s idle,
/// ~3.5 s behind a loaded loop's traffic).
const FIRST_NET_WAIT_NS: u64 = 8_000_000_000;

/// Bytes of a weight-update chunk the bridge sends. A chunk goes only
/// when the link has no backlog ([`CHUNK_MAX_BACKLOG`]) and at most every
/// [`CHUNK_EVERY_MS`]: setpoints and feedback never wait behind an update
/// (with fixed pacing alone, a loaded sim's setpoint-to-command p99 grew
/// to 26 periods while an update went through). A 12 kB net takes a few
/// seconds; the chip checks it in slices once it is whole.
pub const CHUNK_BYTES: usize = 192;
/// See [`CHUNK_BYTES`].
pub const CHUNK_EVERY_MS: u64 = 20;
/// Bytes the link may still hold unread for a chunk to be sent (~3 ms of
/// the emulated link).
pub const CHUNK_MAX_BACKLOG: usize = 256;

/// A link backlog this large (bytes) means the loop's rate is more than
/// the link carries: said once.
pub const BACKLOG_WARN_BYTES: usize = 2048;

/// Bytes the link may still hold unread for a new setpoint or plant state
/// to be sent (about two periods of the loop's traffic at 100 Hz).
pub const SEND_MAX_BACKLOG: usize = 192;

/// How often the bridge looks for messages, µs.
pub const POLL_US: u64 = 100;

pub use crate::ipc::controller::LinkStats;

pub use super::chip_link::{link_feedback, link_setpoint, setup_for, setup_of, ChipLink};

/// Run the controller process with the chip in the loop until stopped:
/// the same checks as the host's ([`crate::ipc::controller::load`]) and the
/// same process skeleton, with the chip's period behind the link.
pub fn run(cfg: &ControllerConfig) -> Result<ControllerStats, IpcError> {
    let Some(mcu) = &cfg.mcu else {
        return Err(IpcError::Config(
            "the bridge needs the chip's options (controller --mcu)".into(),
        ));
    };
    // The chip's period runs on the chip: no scheduling for this process
    // (QEMU's threads get the real-time priority instead).
    process::run(
        &crate::ipc::controller::process(cfg, false),
        || connect(cfg, mcu),
        |connected, services| Bridge::open(mcu, connected, services),
    )
}

/// The chip, running the run's configuration, and what the bridge sends it
/// first.
struct Connected {
    /// QEMU when this bridge started it (kept for the run's length).
    chip_process: Option<Chip>,
    chip: ChipLink,
    n_tendons: usize,
    period_ns: u64,
    /// The tracker's frame → the model's base frame (its `[base]`).
    to_base: crate::robot::RigidMap,
    /// The run's net, when the chip runs another.
    first_net: Option<Vec<u8>>,
}

/// The controller's checks, then the chip: started here, or already
/// running behind a socket, and configured over the link.
fn connect(cfg: &ControllerConfig, mcu: &McuOptions) -> Result<Connected, IpcError> {
    let (robot, model) = crate::ipc::controller::load(cfg)?;
    let other = |e: anyhow::Error| IpcError::Other(format!("{e:#}"));
    let setup = setup_for(cfg, &robot)?;
    let (chip_process, socket) = match &mcu.socket {
        Some(s) => (None, s.clone()),
        None => {
            let image = match &mcu.image {
                Some(i) => i.clone(),
                None => locate_image().map_err(other)?,
            };
            let socket =
                std::env::temp_dir().join(format!("tendril-chip-{}.sock", std::process::id()));
            let chip = Chip::start(&image, &socket).map_err(other)?;
            if cfg.realtime {
                chip.make_realtime(crate::ipc::clock::CONTROLLER_PRIORITY);
            }
            (Some(chip), socket)
        }
    };
    let link = McuLink::connect(&socket, Duration::from_secs(10)).map_err(other)?;
    let chip = ChipLink::open(link, &setup).map_err(other)?;
    let first_net =
        (chip.hello.net_hash != tendril_shared::tnet::net_hash(&model)).then_some(model);
    Ok(Connected {
        chip_process,
        chip,
        n_tendons: robot.n_tendons(),
        period_ns: u64::from(setup.period_ns),
        to_base: robot.base.to_base(),
        first_net,
    })
}

/// The bridge as a [`process::Task`]: each step polls the services and the
/// link once ([`POLL_US`]).
struct Bridge {
    _chip_process: Option<Chip>,
    chip: ChipLink,
    n: usize,
    period_ns: u64,
    /// Setpoints and tracker frames come in the tracker's frame, the chip
    /// works in the model's base frame (`docs/design.md` §2.4).
    to_base: crate::robot::RigidMap,
    garbage_every_ms: Option<u64>,
    setpoints: transport::Sub<Setpoint>,
    states: transport::Sub<PlantState>,
    weights: transport::Sub<WeightUpdate>,
    commands: transport::Pub<TensionCommand>,
    notifier: iceoryx2::port::notifier::Notifier<transport::Svc>,
    start: u64,
    faults: FaultLog,
    stats: LinkStats,
    latency: Histogram,
    /// The weight update being sent: its bytes, how far, its sequence.
    update: Option<(Vec<u8>, usize, u64)>,
    update_seq: u64,
    /// Until the chip runs the run's net, no setpoint goes to it: it would
    /// be answered by the net already on the chip, made for another robot
    /// or another fit (a robot of other tendon counts is held, one of the
    /// same count driven by the wrong net). The planner's settle hold
    /// covers the upload (12 kB in about a second on an idle link); the
    /// setpoints that came meanwhile are counted with the first one
    /// forwarded. Should the chip neither swap nor refuse within
    /// [`FIRST_NET_WAIT_NS`], the loop goes on with what it has, and says so.
    first_net_pending: bool,
    last_tangent: Option<tendril_shared::link::wire::LinkTangent>,
    tip_shift: [f32; 3],
    quiet: MoveQuiet,
    /// Setpoints forwarded and not yet seen in a command: (seq, sent at).
    in_flight: std::collections::VecDeque<(u32, u64)>,
    last_cmd_seq: u32,
    counters: Counters,
    last_garbage: u64,
    last_chunk: u64,
    backlog_warned: bool,
    /// The newest plant state not yet sent and how many it stands for.
    pending_state: Option<(PlantState, usize)>,
    /// The newest setpoint not yet sent, with the count of setpoints it
    /// stands for and the non-finite ones among those it superseded.
    pending_setpoint: Option<(Setpoint, usize, usize)>,
    last_feedback: u64,
    /// The plant state's sequence number last seen (the log's column).
    last_state_seq: u64,
    row: Vec<f64>,
    /// The chip's messages of one poll (kept for its capacity).
    received: Vec<Up>,
}

impl Bridge {
    fn open(mcu: &McuOptions, c: Connected, services: &Services) -> Result<Bridge, IpcError> {
        let start = now_ns();
        Ok(Bridge {
            _chip_process: c.chip_process,
            chip: c.chip,
            n: c.n_tendons,
            period_ns: c.period_ns,
            to_base: c.to_base,
            garbage_every_ms: mcu.garbage_every_ms,
            setpoints: transport::subscriber(&services.setpoint)?,
            states: transport::subscriber(&services.plant_state)?,
            weights: transport::subscriber(&services.weights)?,
            commands: transport::publisher(&services.tension_cmd)?,
            notifier: transport::notifier(&services.tension_cmd_event)?,
            start,
            faults: FaultLog::new(start),
            stats: LinkStats::default(),
            latency: Histogram::default(),
            first_net_pending: c.first_net.is_some(),
            update: c.first_net.map(|bytes| (bytes, 0, 0)),
            update_seq: 0,
            last_tangent: None,
            tip_shift: [0.0; 3],
            quiet: MoveQuiet::new(crate::ipc::controller::correction::QUIET_AFTER_MOVE_S),
            in_flight: Default::default(),
            last_cmd_seq: 0,
            counters: Counters::default(),
            last_garbage: start,
            last_chunk: 0,
            backlog_warned: false,
            pending_state: None,
            pending_setpoint: None,
            last_feedback: 0,
            last_state_seq: 0,
            row: vec![0.0; 6 + c.n_tendons],
            received: Vec::with_capacity(16),
        })
    }

    /// Take the newest setpoint and forward it when the link is free and
    /// the run's net is in; returns whether one arrived.
    fn forward_setpoint(&mut self, now: u64, link_free: bool) -> Result<bool, IpcError> {
        let mut nonfinite = 0;
        let (sp, n_sp) = transport::latest_inspecting(&self.setpoints, |s: &Setpoint| {
            if s.pose.iter().any(|v| !v.is_finite()) {
                nonfinite += 1;
            }
        })?;
        let sp = sp.map(|s| crate::ipc::frame::setpoint(&self.to_base, &s));
        if let Some(s) = &sp {
            self.quiet.setpoint(s, now_ns());
            // A setpoint that cannot go now is superseded by a newer one:
            // what it superseded is counted with it.
            let mut count = n_sp;
            if let Some((old, old_count, old_nonfinite)) = self.pending_setpoint.take() {
                if old.pose.iter().any(|v| !v.is_finite()) {
                    nonfinite += 1;
                }
                nonfinite += old_nonfinite;
                count += old_count;
            }
            self.pending_setpoint = Some((*s, count, nonfinite));
        }
        if self.first_net_pending && now.saturating_sub(self.start) > FIRST_NET_WAIT_NS {
            self.first_net_pending = false;
            log::warn!(
                "controller: the chip has not installed the run's net after {} s: \
                 setpoints go to the net it runs",
                FIRST_NET_WAIT_NS / 1_000_000_000
            );
        }
        if let (Some((s, count, superseded)), true, false) =
            (self.pending_setpoint, link_free, self.first_net_pending)
        {
            // The newest is forwarded (its own NaN is the chip's to find);
            // `superseded` counted only the ones it superseded. The
            // dynamic offset is applied here, as the host controller does.
            let (s, shift) = crate::ipc::controller::with_dynamic_offset(&s);
            self.tip_shift = shift;
            let msg = link_setpoint(&s, count, superseded, &mut self.last_tangent, now);
            self.chip.send(&Down::Setpoint(msg)).map_err(other)?;
            self.in_flight.push_back((msg.seq, now));
            if self.in_flight.len() > 64 {
                self.in_flight.pop_front();
            }
            self.pending_setpoint = None;
        }
        Ok(sp.is_some())
    }

    /// Take the newest plant state and forward it at most once per chip
    /// period: the chip uses one frame per period, and the plant publishes
    /// on every command and idle tick (about twice a period), which with
    /// protocol 3's longer feedback took the loop past what the emulated
    /// link carries (~104 of ~100 bytes a period at 100 Hz). Returns
    /// whether one arrived.
    fn forward_state(&mut self, now: u64, link_free: bool) -> Result<bool, IpcError> {
        let (st, n_st): (Option<PlantState>, usize) = transport::latest(&self.states)?;
        let st = st.map(|f| crate::ipc::frame::state(&self.to_base, &f));
        if let Some(f) = &st {
            self.last_state_seq = f.header.seq;
            let count = self.pending_state.map_or(0, |(_, c)| c) + n_st;
            self.pending_state = Some((*f, count));
        }
        let due = link_free && now.saturating_sub(self.last_feedback) >= self.period_ns * 3 / 4;
        if let (Some((f, count)), true) = (self.pending_state, due) {
            let t = now_ns();
            let f = crate::ipc::controller::tip_shifted(&self.quiet.state(&f, t), self.tip_shift);
            self.chip
                .send(&Down::Feedback(link_feedback(&f, count, self.n, t)))
                .map_err(other)?;
            self.last_feedback = t;
            self.pending_state = None;
        }
        Ok(st.is_some())
    }

    /// Take a new weight update and send the next chunk of the one in
    /// flight: paced to the link's spare bandwidth, not more. Before the
    /// first setpoint nothing else needs the link: the run's net goes as
    /// fast as the link takes it (the backlog bound alone).
    fn send_weights(&mut self, now: u64) -> Result<(), IpcError> {
        let (w, _): (Option<WeightUpdate>, usize) = transport::latest(&self.weights)?;
        if let Some(w) = w {
            self.update_seq = w.header.seq;
            match w.payload() {
                Some(bytes) => self.update = Some((bytes.to_vec(), 0, w.header.seq)),
                None => log::warn!(
                    "controller: weight update #{} has a bad length: not sent",
                    w.header.seq
                ),
            }
        }
        let pace_ns = if self.first_net_pending {
            0
        } else {
            CHUNK_EVERY_MS * 1_000_000
        };
        let due = now.saturating_sub(self.last_chunk) >= pace_ns
            && self.chip.backlog() <= CHUNK_MAX_BACKLOG;
        if let (true, Some((blob, at, _))) = (due, &mut self.update) {
            self.last_chunk = now;
            let end = (*at + CHUNK_BYTES.min(MAX_CHUNK)).min(blob.len());
            let chunk = Down::Chunk {
                offset: *at as u32,
                total: blob.len() as u32,
                bytes: &blob[*at..end],
            };
            self.chip.send(&chunk).map_err(other)?;
            self.stats.chunks_sent += 1;
            if *at == 0 {
                self.stats.updates_sent += 1;
            }
            *at = end;
            if end >= blob.len() {
                self.update = None;
            }
        }
        Ok(())
    }

    /// The fault test's garbage on the link, and the warning when the link
    /// falls behind.
    fn load_the_link(&mut self, now: u64) -> Result<(), IpcError> {
        if let Some(every) = self.garbage_every_ms {
            if now.saturating_sub(self.last_garbage) >= every * 1_000_000 {
                self.last_garbage = now;
                // Bytes a noisy line might carry: the decoder drops them
                // at their 0x00 and counts them; no period is missed.
                // It ends in a 0x00, as garbage between two frames does
                // on a line (a burst inside a frame corrupts that frame: it
                // is dropped and counted like this one, and a lost chunk
                // abandons its update; docs/design.md §5.6).
                let burst = [0x55u8, 0xAA, 0x13, 0x00, 0xFF, 0x02, 0x99, 0x42, 0x07, 0x00];
                self.chip.send_raw(&burst).map_err(other)?;
                self.stats.garbage_bytes_sent += burst.len() as u64;
            }
        }
        let backlog = self.chip.backlog();
        if backlog > BACKLOG_WARN_BYTES && !self.backlog_warned {
            self.backlog_warned = true;
            let cause = match self.garbage_every_ms {
                // The garbage is the test's own load, not the rate's fault.
                Some(ms) => format!(
                    "garbage injected every {ms} ms (--link-garbage-every-ms) shares the link"
                ),
                None => "lower --rate".to_string(),
            };
            log::warn!(
                "controller: the link to the chip is falling behind ({backlog} bytes waiting): \
                 at {:.0} Hz the loop needs ~{:.0} kB/s, the emulated link carries ~10 kB/s \
                 ({cause})",
                1e9 / self.period_ns as f64,
                70.0 * 1e9 / self.period_ns as f64 / 1e3
            );
        }
        Ok(())
    }

    /// Publish every command the chip sent, log it and list its events;
    /// keep its telemetry. Returns whether a command was published.
    fn receive(&mut self, log: &mut CsvLog) -> Result<bool, IpcError> {
        let t_rx = now_ns();
        let mut published = false;
        // The chip's messages move to a buffer the bridge keeps (they are
        // handled with `&mut self`), so a poll allocates nothing.
        let mut received = std::mem::take(&mut self.received);
        received.extend(self.chip.drain());
        for msg in received.drain(..) {
            match msg {
                Up::Command(c) => {
                    self.command(&c, t_rx)?;
                    published = true;
                    self.row[0] = t_rx as f64;
                    self.row[3] = f64::from(c.status);
                    self.row[4] = f64::from(c.setpoint_seq);
                    self.row[5] = self.last_state_seq as f64;
                    for (d, t) in self.row[6..].iter_mut().zip(c.tensions.iter()) {
                        *d = f64::from(*t);
                    }
                    log.row(&self.row)?;
                }
                Up::Telemetry(t) => {
                    self.counters = t.counters;
                    if self.stats.chip_at_connect.is_none() {
                        self.stats.chip_at_connect = Some(t);
                        report_past(&mut self.faults, &t, t_rx, self.start, self.period_ns);
                    }
                    self.stats.chip = Some(t);
                }
                Up::Hello(_) => {}
            }
        }
        self.received = received;
        if published {
            self.notifier
                .notify()
                .map_err(|e| IpcError::Send(format!("tension_cmd event: {e:?}")))?;
        }
        Ok(published)
    }

    /// One command from the chip: counted, timed against its setpoint,
    /// published, its events listed.
    fn command(&mut self, c: &LinkCommand, t_rx: u64) -> Result<(), IpcError> {
        if c.events & (event::WEIGHTS_SWAPPED | event::WEIGHTS_REJECTED) != 0 {
            // Swapped, or refused (the refusal is a fault the report
            // lists): either way the wait is over.
            self.first_net_pending = false;
        }
        if self.last_cmd_seq > 0 && c.seq > self.last_cmd_seq + 1 {
            self.stats.commands_lost += u64::from(c.seq - self.last_cmd_seq - 1);
        }
        self.last_cmd_seq = c.seq;
        self.stats.commands += 1;
        while let Some(&(seq, t)) = self.in_flight.front() {
            if seq > c.setpoint_seq {
                break;
            }
            self.in_flight.pop_front();
            if seq == c.setpoint_seq {
                self.latency.record(t_rx.saturating_sub(t));
            }
        }
        publish(&self.commands, c, self.n)?;
        let d = c.detail;
        let ev = Events {
            bits: c.events,
            setpoints_lost: u64::from(d.setpoints_lost),
            plant_states_lost: u64::from(d.plant_states_lost),
            commands_behind: u64::from(d.commands_behind),
            stuck: d.stuck,
            hold_silence_ns: u64::from(d.hold_silence_us) * 1000,
            update_error: None,
        };
        self.faults
            .report(&ev, &self.counters, t_rx, self.period_ns, self.update_seq);
        Ok(())
    }
}

impl process::Task for Bridge {
    type Stats = ControllerStats;

    fn log_header(&self) -> String {
        log_header(self.n)
    }

    fn start_ns(&self) -> u64 {
        self.start
    }

    fn step(&mut self, log: &mut CsvLog) -> Result<Stepped, IpcError> {
        let now = now_ns();
        // Nothing new goes while the link still holds a backlog (the chip
        // uses only the newest setpoint and state; queueing old ones behind
        // a slow link only delays the new ones — at start-up the chip reads
        // nothing until it is configured). The newest goes once it drained.
        let link_free = self.chip.backlog() <= SEND_MAX_BACKLOG;
        let setpoint = self.forward_setpoint(now, link_free)?;
        let state = self.forward_state(now, link_free)?;
        self.send_weights(now)?;
        self.load_the_link(now)?;
        self.chip.poll(Duration::from_micros(POLL_US));
        self.receive(log)?;
        Ok(Stepped {
            t_ns: now_ns(),
            heard: setpoint || state,
        })
    }

    fn silence(&self) -> &'static str {
        crate::ipc::controller::SILENT_PEERS
    }

    fn finish(mut self, _: &Result<(), IpcError>) -> Result<ControllerStats, IpcError> {
        // The chip's last counts.
        self.chip.poll(Duration::from_millis(250));
        for msg in self.chip.drain() {
            if let Up::Telemetry(t) = msg {
                self.stats.chip = Some(t);
            }
        }
        let mut stats = self.stats;
        let mut report = ControllerStats::default();
        if let Some(t) = &stats.chip {
            report.fill_counters(&t.counters);
            report.cycles = u64::from(t.counters.periods);
            report.skipped = u64::from(t.counters.missed_ticks);
            stats.frames_down = t.frames;
        }
        self.faults.fill(&mut report);
        stats.frames_up = self.chip.counters();
        (stats.bytes_down, stats.bytes_up) = self.chip.bytes();
        stats.setpoint_to_command_us = self.latency.summary();
        let per = self.period_ns as f64 * 1e-3;
        stats.setpoint_to_command_periods = (
            stats.setpoint_to_command_us.p50 / per,
            stats.setpoint_to_command_us.p99 / per,
        );
        report.link = Some(stats);
        Ok(report)
    }
}

fn other(e: anyhow::Error) -> IpcError {
    IpcError::Other(format!("{e:#}"))
}

/// A hold the chip made before this bridge connected (the link was cut):
/// listed at its time on the host clock, estimated from the chip's ticks.
fn report_past(faults: &mut FaultLog, t: &Telemetry, t_rx: u64, start: u64, period_ns: u64) {
    if t.last_hold_tick == 0 || t.counters.watchdog_trips == 0 {
        return;
    }
    let ago = u64::from(t.ticks.wrapping_sub(t.last_hold_tick)) * u64::from(t.tick_ns);
    let at = t_rx.saturating_sub(ago);
    if at >= start {
        return; // this bridge's own time: its commands carry it
    }
    let periods = f64::from(t.last_hold_silence_us) * 1e3 / period_ns.max(1) as f64;
    log::warn!(
        "controller: the chip went to a safe hold {:.1} s before this bridge connected, \
         {periods:.1} periods after its last setpoint (the link was cut)",
        ago as f64 * 1e-9
    );
    faults.detect(
        crate::ipc::controller::FaultKind::WatchdogHold,
        at,
        None,
        periods,
        "the chip held on its own while no bridge was connected (link cut)",
    );
}

fn publish(
    commands: &transport::Pub<TensionCommand>,
    c: &LinkCommand,
    n: usize,
) -> Result<(), IpcError> {
    let mut tensions = [0.0f32; MAX_TENDONS];
    for (d, &t) in tensions.iter_mut().zip(c.tensions.iter()) {
        *d = t;
    }
    let cmd = TensionCommand {
        header: Header {
            seq: u64::from(c.seq),
            stamp_ns: now_ns(),
        },
        setpoint_seq: u64::from(c.setpoint_seq),
        count: n as u32,
        status: c.status,
        tensions,
        pad: Default::default(),
    };
    transport::send(commands, cmd)
}

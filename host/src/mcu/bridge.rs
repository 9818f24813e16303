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
use crate::ipc::controller::{log_header, ControllerConfig, ControllerStats, FaultLog};
use crate::ipc::stats::{CsvLog, Histogram};
use crate::ipc::transport::{self, Services};
use crate::ipc::{IpcError, PeerWatch, StopWatch};

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

pub use crate::ipc::controller::{LinkStats, McuOptions};

pub use super::chip_link::{link_feedback, link_setpoint, setup_for, setup_of, ChipLink};

/// Run the controller process with the chip in the loop until stopped:
/// the same checks as the host's ([`crate::ipc::controller::load`]), then
/// the bridge.
pub fn run(cfg: &ControllerConfig) -> Result<ControllerStats, IpcError> {
    let Some(mcu) = &cfg.mcu else {
        return Err(IpcError::Config(
            "the bridge needs the chip's options (controller --mcu)".into(),
        ));
    };
    let (robot, model) = crate::ipc::controller::load(cfg)?;
    let (robot, model) = (&robot, model.as_slice());
    let other = |e: anyhow::Error| IpcError::Other(format!("{e:#}"));
    let setup = setup_for(cfg, robot)?;
    // The chip: started here, or already running behind a socket.
    let (_chip, socket) = match &mcu.socket {
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
    let mut chip = ChipLink::open(link, &setup).map_err(other)?;
    let model_hash = tendril_shared::tnet::net_hash(model);
    let mut update: Option<(Vec<u8>, usize, u64)> =
        (chip.hello.net_hash != model_hash).then(|| (model.to_vec(), 0, 0));
    // Until the chip runs the run's net, no setpoint goes to it: it would
    // be answered by the net already on the chip, made for another robot or
    // another fit (a robot of other tendon counts is held, one of the same
    // count driven by the wrong net). The planner's settle hold covers the
    // upload (12 kB in about a second on an idle link); the setpoints that
    // came meanwhile are counted with the first one forwarded. Should the
    // chip neither swap nor refuse within `FIRST_NET_WAIT_NS`, the loop
    // goes on with what it has, and says so.
    let mut first_net_pending = update.is_some();

    let node = transport::node("tendril-controller")?;
    let _orphan = transport::ReleaseIfOrphaned(&node);
    let services = Services::open_or_create(&node, &cfg.prefix)?;
    let setpoints = transport::subscriber(&services.setpoint)?;
    let states = transport::subscriber(&services.plant_state)?;
    let weights = transport::subscriber(&services.weights)?;
    let commands = transport::publisher(&services.tension_cmd)?;
    let notifier = transport::notifier(&services.tension_cmd_event)?;
    let stop = StopWatch::new(&services)?;
    let n = robot.n_tendons();
    let mut log = CsvLog::create(cfg.log.as_deref(), &log_header(n))?;

    let period_ns = u64::from(setup.period_ns);
    let start = now_ns();
    let mut faults = FaultLog::new(start);
    let mut stats = LinkStats::default();
    let mut latency = Histogram::default();
    let mut peers = PeerWatch::new(cfg.peer_timeout_s, cfg.peer_start_grace_s, start);
    let mut last_tangent = None;
    let mut tip_shift = [0.0f32; 3];
    let mut quiet = crate::ipc::controller::MoveQuiet::new(
        crate::ipc::controller::correction::SETTLE_AFTER_JUMP_S,
    );
    // Setpoints forwarded and not yet seen in a command: (seq, sent at).
    let mut in_flight: std::collections::VecDeque<(u32, u64)> = Default::default();
    let mut last_cmd_seq = 0u32;
    let mut counters = Counters::default();
    let mut update_seq = 0u64;
    let mut last_garbage = start;
    let mut last_chunk = 0u64;
    let mut backlog_warned = false;
    let mut last_flush = start;
    let mut pending_state: Option<PlantState> = None;
    // The newest setpoint not yet sent, with the count of setpoints it
    // stands for and the non-finite ones among those it superseded.
    let mut pending_setpoint: Option<(Setpoint, usize, usize)> = None;
    let mut pending_count = 0usize;
    let mut last_feedback = 0u64;
    let mut row = vec![0.0f64; 6 + n];
    let outcome: Result<(), IpcError> = loop {
        let now = now_ns();
        let mut nonfinite = 0;
        let (sp, n_sp) = transport::latest_inspecting(&setpoints, |s: &Setpoint| {
            if s.pose.iter().any(|v| !v.is_finite()) {
                nonfinite += 1;
            }
        })?;
        if let Some(s) = &sp {
            quiet.setpoint(s, now_ns());
            // A setpoint that cannot go now is superseded by a newer one:
            // what it superseded is counted with it.
            let mut count = n_sp;
            if let Some((old, old_count, old_nonfinite)) = pending_setpoint.take() {
                if old.pose.iter().any(|v| !v.is_finite()) {
                    nonfinite += 1;
                }
                nonfinite += old_nonfinite;
                count += old_count;
            }
            pending_setpoint = Some((*s, count, nonfinite));
        }
        // Nothing new goes while the link still holds a backlog (the chip
        // uses only the newest setpoint and state; queueing old ones behind
        // a slow link only delays the new ones — at start-up the chip reads
        // nothing until it is configured). The newest goes once it drained.
        let link_free = chip.backlog() <= SEND_MAX_BACKLOG;
        if first_net_pending && now.saturating_sub(start) > FIRST_NET_WAIT_NS {
            first_net_pending = false;
            log::warn!(
                "controller: the chip has not installed the run's net after {} s: \
                 setpoints go to the net it runs",
                FIRST_NET_WAIT_NS / 1_000_000_000
            );
        }
        if let (Some((s, count, superseded)), true, false) =
            (pending_setpoint, link_free, first_net_pending)
        {
            // The newest is forwarded (its own NaN is the chip's to find);
            // `superseded` counted only the ones it superseded.
            // The dynamic offset applied here, as the host controller does.
            let (s, shift) = crate::ipc::controller::with_dynamic_offset(&s);
            tip_shift = shift;
            let msg = link_setpoint(&s, count, superseded, &mut last_tangent);
            chip.send(&Down::Setpoint(msg)).map_err(other)?;
            in_flight.push_back((msg.seq, now));
            if in_flight.len() > 64 {
                in_flight.pop_front();
            }
            pending_setpoint = None;
        }
        // The newest plant state, at most once per chip period: the chip
        // uses one frame per period, and the plant publishes on every
        // command and idle tick (about twice a period), which with protocol
        // 3's longer feedback took the loop past what the emulated link
        // carries (~104 of ~100 bytes a period at 100 Hz).
        let (st, n_st): (Option<PlantState>, usize) = transport::latest(&states)?;
        if let Some(f) = &st {
            pending_state = Some(*f);
            pending_count += n_st;
        }
        let feedback_due = link_free && now.saturating_sub(last_feedback) >= period_ns * 3 / 4;
        if let (Some(f), true) = (&pending_state, feedback_due) {
            let t = now_ns();
            let f = crate::ipc::controller::tip_shifted(&quiet.state(f, t), tip_shift);
            chip.send(&Down::Feedback(link_feedback(&f, pending_count, n, t)))
                .map_err(other)?;
            last_feedback = t;
            pending_state = None;
            pending_count = 0;
        }
        let (w, _): (Option<WeightUpdate>, usize) = transport::latest(&weights)?;
        if let Some(w) = w {
            update_seq = w.header.seq;
            match w.payload() {
                Some(bytes) => update = Some((bytes.to_vec(), 0, w.header.seq)),
                None => log::warn!(
                    "controller: weight update #{} has a bad length: not sent",
                    w.header.seq
                ),
            }
        }
        // Paced chunks: the link's spare bandwidth, not more.
        // Before the first setpoint nothing else needs the link: the run's
        // net goes as fast as the link takes it (the backlog bound alone).
        let pace_ns = if first_net_pending {
            0
        } else {
            CHUNK_EVERY_MS * 1_000_000
        };
        let chunk_due =
            now.saturating_sub(last_chunk) >= pace_ns && chip.backlog() <= CHUNK_MAX_BACKLOG;
        if let (true, Some((blob, at, _))) = (chunk_due, &mut update) {
            last_chunk = now;
            let end = (*at + CHUNK_BYTES.min(MAX_CHUNK)).min(blob.len());
            let chunk = Down::Chunk {
                offset: *at as u32,
                total: blob.len() as u32,
                bytes: &blob[*at..end],
            };
            chip.send(&chunk).map_err(other)?;
            stats.chunks_sent += 1;
            if *at == 0 {
                stats.updates_sent += 1;
            }
            *at = end;
            if end >= blob.len() {
                update = None;
            }
        }
        if let Some(every) = mcu.garbage_every_ms {
            if now.saturating_sub(last_garbage) >= every * 1_000_000 {
                last_garbage = now;
                // Bytes a noisy line might carry: the decoder drops them
                // at their 0x00 and counts them; no period is missed.
                // It ends in a 0x00, as garbage between two frames does
                // on a line (a burst inside a frame corrupts that frame: it
                // is dropped and counted like this one, and a lost chunk
                // abandons its update; docs/design.md §5.6).
                let burst = [0x55u8, 0xAA, 0x13, 0x00, 0xFF, 0x02, 0x99, 0x42, 0x07, 0x00];
                chip.send_raw(&burst).map_err(other)?;
                stats.garbage_bytes_sent += burst.len() as u64;
            }
        }

        let backlog = chip.backlog();
        if backlog > BACKLOG_WARN_BYTES && !backlog_warned {
            backlog_warned = true;
            let cause = match mcu.garbage_every_ms {
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
                1e9 / period_ns as f64,
                70.0 * 1e9 / period_ns as f64 / 1e3
            );
        }
        chip.poll(Duration::from_micros(POLL_US));
        let t_rx = now_ns();
        let mut published = false;
        for msg in chip.drain() {
            match msg {
                Up::Command(c) => {
                    if c.events & (event::WEIGHTS_SWAPPED | event::WEIGHTS_REJECTED) != 0 {
                        // Swapped, or refused (the refusal is a fault the
                        // report lists): either way the wait is over.
                        first_net_pending = false;
                    }
                    if last_cmd_seq > 0 && c.seq > last_cmd_seq + 1 {
                        stats.commands_lost += u64::from(c.seq - last_cmd_seq - 1);
                    }
                    last_cmd_seq = c.seq;
                    stats.commands += 1;
                    while let Some(&(seq, t)) = in_flight.front() {
                        if seq > c.setpoint_seq {
                            break;
                        }
                        in_flight.pop_front();
                        if seq == c.setpoint_seq {
                            latency.record(t_rx.saturating_sub(t));
                        }
                    }
                    publish(&commands, &c, n)?;
                    published = true;
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
                    faults.report(&ev, &counters, t_rx, period_ns, update_seq);
                    row[0] = t_rx as f64;
                    row[3] = f64::from(c.status);
                    row[4] = f64::from(c.setpoint_seq);
                    row[5] = st.as_ref().map_or(0.0, |s| s.header.seq as f64);
                    for (d, t) in row[6..].iter_mut().zip(c.tensions.iter()) {
                        *d = f64::from(*t);
                    }
                    log.row(&row)?;
                }
                Up::Telemetry(t) => {
                    counters = t.counters;
                    if stats.chip_at_connect.is_none() {
                        stats.chip_at_connect = Some(t);
                        report_past(&mut faults, &t, t_rx, start, period_ns);
                    }
                    stats.chip = Some(t);
                }
                Up::Hello(_) => {}
            }
        }
        if published {
            notifier
                .notify()
                .map_err(|e| IpcError::Send(format!("tension_cmd event: {e:?}")))?;
        }
        let t_done = now_ns();
        if t_done - last_flush > 100_000_000 {
            log.flush()?;
            last_flush = t_done;
        }
        if stop.requested()
            || cfg
                .duration_s
                .is_some_and(|d| (t_done - start) as f64 * 1e-9 >= d)
        {
            break Ok(());
        }
        if sp.is_some() || st.is_some() {
            peers.heard(t_done);
        } else if peers.lost(t_done) {
            break Err(IpcError::PeersLost(format!(
                "controller: no setpoint and no plant state for {:.1} s",
                peers.silence_s(t_done)
            )));
        }
    };
    log.close()?;
    // The chip's last counts.
    chip.poll(Duration::from_millis(250));
    for msg in chip.drain() {
        if let Up::Telemetry(t) = msg {
            stats.chip = Some(t);
        }
    }
    let mut report = ControllerStats::default();
    if let Some(t) = &stats.chip {
        report.fill_counters(&t.counters);
        report.cycles = u64::from(t.counters.periods);
        report.skipped = u64::from(t.counters.missed_ticks);
        stats.frames_down = t.frames;
    }
    faults.fill(&mut report);
    stats.frames_up = chip.counters();
    (stats.bytes_down, stats.bytes_up) = chip.bytes();
    stats.setpoint_to_command_us = latency.summary();
    let per = period_ns as f64 * 1e-3;
    stats.setpoint_to_command_periods = (
        stats.setpoint_to_command_us.p50 / per,
        stats.setpoint_to_command_us.p99 / per,
    );
    report.link = Some(stats);
    if let Some(path) = &cfg.stats {
        let json =
            serde_json::to_vec_pretty(&report).map_err(|e| IpcError::Other(e.to_string()))?;
        crate::ipc::write_file(path, &json)?;
    }
    outcome.map(|()| report)
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

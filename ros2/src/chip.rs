//! `drive --controller mcu`: the STM32F405 image under QEMU as the drive's
//! controller (`docs/design.md` §13).
//!
//! The chip runs the whole control period on its own timer, as in `tendril
//! sim --controller mcu`; its bridge ([`tendril::mcu::bridge::run`]: QEMU
//! started, the link configured, the run's net installed, setpoints and
//! feedback forwarded, the chip's commands published) runs unchanged on a
//! thread of this process, and the drive talks to it over the loop's
//! iceoryx2 services as the planner and the plant do: each period's
//! setpoint and the robot's newest feedback go in (the tracker's frame),
//! the chip's commands come out and go to the robot. One bridge, the one
//! every chip run uses: no second copy of the link's rules.

use std::thread::JoinHandle;

use tendril::ipc::clock::now_ns;
use tendril::ipc::controller::{ControllerConfig, ControllerStats, McuOptions};
use tendril::ipc::transport::{self, IpcNode, Pub, Services, Sub};
use tendril::ipc::IpcError;
use tendril_shared::messages::{command_status, Control, PlantState, Setpoint, TensionCommand};

use crate::Ros2Error;

/// How long the chip may take to answer its first setpoint (QEMU's start,
/// the link's configuration, the run's net installed: 1–4 s here), s.
pub const CHIP_START_S: f64 = 20.0;

/// The chip behind its bridge, and the drive's ends of the loop's services.
pub struct ChipController {
    setpoints: Pub<Setpoint>,
    states: Pub<PlantState>,
    control: Pub<Control>,
    commands: Sub<TensionCommand>,
    bridge: Option<JoinHandle<Result<ControllerStats, IpcError>>>,
    // Last: the ports above are the node's.
    _node: IpcNode,
}

impl ChipController {
    /// Open the services under a prefix of this run's own and start the
    /// bridge on a thread: it starts QEMU with `cfg.mcu`'s image (or the
    /// image this checkout builds — the drive builds it before it joins the
    /// graph, so neither the robot's wait nor [`ChipController::wait_ready`]'s
    /// start counts the build).
    pub fn start(cfg: &ControllerConfig) -> Result<Self, Ros2Error> {
        let ipc = |e: IpcError| Ros2Error::Chip(e.to_string());
        tendril::mcu::bridge::check_chip_rate(cfg.rate_hz).map_err(Ros2Error::Config)?;
        let mut cfg = cfg.clone();
        cfg.prefix = format!("{}-ros2", tendril::ipc::sim::unique_prefix());
        let image = cfg.mcu.take().and_then(|m| m.image);
        cfg.mcu = Some(McuOptions {
            socket: None,
            image,
            garbage_every_ms: None,
        });
        // The drive stops it (a STOP on the control service) or dies with it.
        cfg.duration_s = None;
        cfg.peer_timeout_s = None;
        cfg.supervised = false;
        cfg.log = None;
        cfg.stats = None;
        let node = transport::node("tendril-ros2-drive").map_err(ipc)?;
        let services = Services::open_or_create(&node, &cfg.prefix).map_err(ipc)?;
        // The drive's ports exist before the bridge publishes anything.
        let chip = ChipController {
            setpoints: transport::publisher(&services.setpoint).map_err(ipc)?,
            states: transport::publisher(&services.plant_state).map_err(ipc)?,
            control: transport::publisher(&services.control).map_err(ipc)?,
            commands: transport::subscriber(&services.tension_cmd).map_err(ipc)?,
            bridge: Some(
                std::thread::Builder::new()
                    .name("chip-bridge".into())
                    .spawn(move || tendril::mcu::bridge::run(&cfg))
                    .map_err(|e| Ros2Error::Chip(format!("starting the bridge: {e}")))?,
            ),
            _node: node,
        };
        Ok(chip)
    }

    /// Forward a setpoint (the tracker's frame, as the planner sends it).
    /// A bridge that ended (QEMU gone, the link lost) is an error.
    pub fn offer(&mut self, setpoint: &Setpoint) -> Result<(), Ros2Error> {
        self.check_bridge()?;
        transport::send(&self.setpoints, *setpoint).map_err(|e| Ros2Error::Chip(e.to_string()))
    }

    /// Forward the robot's state (the tracker's frame, as a plant sends it).
    pub fn offer_state(&mut self, state: &PlantState) -> Result<(), Ros2Error> {
        transport::send(&self.states, *state).map_err(|e| Ros2Error::Chip(e.to_string()))
    }

    /// The chip's newest command since the last call, if any.
    pub fn take_command(&mut self) -> Result<Option<TensionCommand>, Ros2Error> {
        let (cmd, _) =
            transport::latest(&self.commands).map_err(|e| Ros2Error::Chip(e.to_string()))?;
        if cmd.is_none() {
            self.check_bridge()?;
        }
        Ok(cmd)
    }

    /// An error if the bridge has ended, saying why.
    fn check_bridge(&mut self) -> Result<(), Ros2Error> {
        if !self.bridge.as_ref().is_some_and(|b| b.is_finished()) {
            return Ok(());
        }
        let why = match self.bridge.take().map(JoinHandle::join) {
            Some(Ok(Err(e))) => e.to_string(),
            Some(Err(_)) => "its thread panicked".into(),
            _ => "it stopped".into(),
        };
        Err(Ros2Error::Chip(format!("the chip's bridge ended: {why}")))
    }

    /// Wait for the chip's first command that answers a setpoint, unheld,
    /// while sending `setpoint` and `state` each `period_ns` (the chip
    /// installs the run's net first); returns the seconds it took and the
    /// sequence number it reached (the drive's messages go on from it).
    pub fn wait_ready(
        &mut self,
        setpoint: &Setpoint,
        state: &PlantState,
        period_ns: u64,
        stop: &std::sync::atomic::AtomicBool,
    ) -> Result<(f64, u64), Ros2Error> {
        let start = now_ns();
        let mut seq = 0;
        loop {
            if stop.load(std::sync::atomic::Ordering::Relaxed) {
                return Err(Ros2Error::Interrupted("while the chip started".into()));
            }
            let waited = (now_ns() - start) as f64 * 1e-9;
            if waited > CHIP_START_S {
                return Err(Ros2Error::Chip(format!(
                    "the chip answered no setpoint within {CHIP_START_S} s of its start \
                     (QEMU's start, the link, the run's net installed)"
                )));
            }
            seq += 1;
            let mut s = *setpoint;
            s.header.seq = seq;
            s.header.stamp_ns = now_ns();
            let mut f = *state;
            f.header.seq = seq;
            f.header.stamp_ns = s.header.stamp_ns;
            self.offer(&s)?;
            self.offer_state(&f)?;
            // Its first commands answer no setpoint yet (and turn into its
            // watchdog's hold): ready when one answers a setpoint, unheld.
            if self
                .take_command()?
                .is_some_and(|c| c.setpoint_seq > 0 && c.status & command_status::SAFE_HOLD == 0)
            {
                return Ok((waited, seq));
            }
            std::thread::sleep(std::time::Duration::from_nanos(period_ns));
        }
    }

    /// Stop the bridge (a STOP on the loop's control service) and return
    /// the chip's own counts (its telemetry: periods, holds, stale
    /// periods, missed ticks).
    pub fn finish(mut self) -> Result<ControllerStats, Ros2Error> {
        let _ = tendril::ipc::send_stop(&self.control);
        match self.bridge.take().map(JoinHandle::join) {
            Some(Ok(stats)) => stats.map_err(|e| Ros2Error::Chip(e.to_string())),
            Some(Err(_)) => Err(Ros2Error::Chip("the bridge's thread panicked".into())),
            None => Err(Ros2Error::Chip("the bridge had ended".into())),
        }
    }
}

impl Drop for ChipController {
    /// A drive that ends by an error (the chip never ready, the robot
    /// silent) stops the bridge too, and with it QEMU; `finish` has sent
    /// this already on the ordinary path.
    fn drop(&mut self) {
        if self.bridge.is_some() {
            let _ = tendril::ipc::send_stop(&self.control);
        }
    }
}

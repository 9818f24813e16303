//! The closed loop as separate OS processes over iceoryx2 shared memory
//! (`docs/design.md` §6): planner → `setpoint` → controller → `tension_cmd` →
//! plant → `plant_state` → controller and planner, plus `weights` (hot swap)
//! and `control` (stop). `sim` launches the three and writes a report.
//!
//! Each process is a library function taking a config struct, so the CLI
//! files stay thin and tests can reason about the same code. The config
//! structs are serde types: a launcher writes one as JSON and starts the
//! process with `--config FILE` ([`read_config`]).
//!
//! Nothing holds the robot forever: a supervised process dies with its
//! launcher ([`die_with_parent`]), and every process stops with
//! [`IpcError::PeersLost`] when its peers fall silent ([`PeerWatch`]).

pub mod clock;
pub mod controller;
pub mod following;
pub mod frame;
pub mod planner;
pub mod plant;
pub mod process;
pub mod rehearsal;
pub mod sim;
pub mod stats;
pub mod transport;

use tendril_shared::messages::{control_command, Control};

pub use transport::DEFAULT_PREFIX;

/// What can go wrong in the IPC processes.
#[derive(Debug, thiserror::Error)]
pub enum IpcError {
    /// A service or node name is not acceptable to iceoryx2.
    #[error("bad name: {0}")]
    BadName(String),
    /// A service could not be created or opened.
    #[error("iceoryx2 service: {0}")]
    Service(String),
    /// A port (publisher, subscriber, notifier, listener) could not be created.
    #[error("iceoryx2 port: {0}")]
    Port(String),
    /// Publishing failed.
    #[error("iceoryx2 send: {0}")]
    Send(String),
    /// Receiving failed.
    #[error("iceoryx2 receive: {0}")]
    Receive(String),
    /// Bad configuration (argument values).
    #[error("{0}")]
    Config(String),
    /// A file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: std::path::PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// A trajectory the robot cannot follow, or a point it cannot take.
    #[error(transparent)]
    Plan(#[from] crate::plan::PlanError),
    /// The plant's physics could not be made (its parameters, its reality).
    #[error(transparent)]
    Plant(#[from] crate::plant::PlantError),
    /// Anything from the layers below (robot file, statics, model file).
    #[error("{0}")]
    Other(String),
    /// The process's peers fell silent (or its launcher is gone): it stops
    /// rather than hold the robot with nobody listening.
    #[error("peers lost: {0}")]
    PeersLost(String),
}

/// Environment variable a launcher sets on the processes it starts: they
/// then die with it ([`die_with_parent`]). Its value may be the launcher's
/// pid, which the child then checks against its parent.
pub const SUPERVISED_ENV: &str = "TENDRIL_SUPERVISED";

/// The launcher's pid once [`die_with_parent`] has tied this process to it
/// (0: not supervised).
static LAUNCHER: std::sync::atomic::AtomicI32 = std::sync::atomic::AtomicI32::new(0);

/// If `supervised` (a config flag) or [`SUPERVISED_ENV`] says so, ask the
/// kernel to send this process SIGTERM when its parent exits
/// (`PR_SET_PDEATHSIG`), so a killed `tendril sim` leaves no child holding
/// the robot at real-time priority. Returns whether it did. A parent that
/// died before the request (the child was re-parented already) is an error.
///
/// SIGTERM, not SIGKILL (issue 31): a child killed outright cannot release
/// its iceoryx2 resources, and with the launcher dead by SIGKILL nobody
/// would release the launcher's either until the next sim. iceoryx2's
/// signal handler (installed here) turns the SIGTERM into a stop request
/// that every loop checks each period ([`StopWatch::requested`], which also
/// notices the launcher's death itself through [`launcher_gone`], so a
/// signal swallowed anywhere cannot keep a child running); the child then
/// leaves its loop and [`transport::ReleaseIfOrphaned`] removes the dead
/// launcher's node and, with the last child, the run's services.
pub fn die_with_parent(supervised: bool) -> Result<bool, IpcError> {
    let env = std::env::var(SUPERVISED_ENV).ok();
    if !supervised && env.is_none() {
        return Ok(false);
    }
    // Catch SIGTERM before asking for it (no signal can have arrived yet:
    // the default action would have ended the process).
    crate::interrupt::install(None)
        .map_err(|e| IpcError::Config(format!("signal handling: {e}")))?;
    // SAFETY: PR_SET_PDEATHSIG takes a signal number and touches no memory.
    let rc = unsafe {
        libc::prctl(
            libc::PR_SET_PDEATHSIG,
            libc::SIGTERM as libc::c_ulong,
            0,
            0,
            0,
        )
    };
    if rc != 0 {
        return Err(IpcError::Config(format!(
            "PR_SET_PDEATHSIG: {}",
            std::io::Error::last_os_error()
        )));
    }
    // SAFETY: getppid has no preconditions.
    let parent = unsafe { libc::getppid() };
    let expected = env.and_then(|v| v.trim().parse::<libc::pid_t>().ok());
    if parent == 1 || expected.is_some_and(|p| p != parent) {
        return Err(IpcError::PeersLost(
            "the launching process exited before this one started".into(),
        ));
    }
    LAUNCHER.store(parent, std::sync::atomic::Ordering::Relaxed);
    Ok(true)
}

/// Whether this process was tied to a launcher ([`die_with_parent`]) that
/// has since died (this process was re-parented). One `getppid` call.
pub fn launcher_gone() -> bool {
    let launcher = LAUNCHER.load(std::sync::atomic::Ordering::Relaxed);
    // SAFETY: getppid has no preconditions.
    launcher != 0 && unsafe { libc::getppid() } != launcher
}

/// Read a process configuration written as JSON (`--config FILE`).
pub fn read_config<T: serde::de::DeserializeOwned>(path: &std::path::Path) -> Result<T, IpcError> {
    let text = std::fs::read_to_string(path).map_err(|source| IpcError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    serde_json::from_str(&text).map_err(|e| IpcError::Config(format!("{}: {e}", path.display())))
}

/// How long a peer that has never been heard from may take to appear:
/// start-up (loading a robot, lifting a trajectory) is slower than any
/// silence in a running loop.
pub const PEER_START_GRACE_S: f64 = 10.0;

/// The "peers lost" rule: silence longer than a timeout (or, before the
/// first message, longer than [`PEER_START_GRACE_S`] or the timeout,
/// whichever is longer) means the peers are gone.
#[derive(Clone, Copy, Debug)]
pub struct PeerWatch {
    timeout_ns: Option<u64>,
    grace_ns: u64,
    last_ns: u64,
    heard: bool,
}

impl PeerWatch {
    /// Start watching at `now_ns`; `timeout_s` `None` never declares the
    /// peers lost. Before the first message the limit is `start_grace_s`
    /// (default [`PEER_START_GRACE_S`]) or the timeout, whichever is longer:
    /// a user who asks for a 1 s timeout gets 1 s from the start by passing
    /// it as the grace too (the CLI does, issue 31).
    pub fn new(timeout_s: Option<f64>, start_grace_s: Option<f64>, now_ns: u64) -> PeerWatch {
        let timeout_ns = timeout_s.map(|t| (t.max(0.0) * 1e9) as u64);
        let grace_ns = (start_grace_s.unwrap_or(PEER_START_GRACE_S).max(0.0) * 1e9) as u64;
        PeerWatch {
            timeout_ns,
            grace_ns: timeout_ns.map_or(0, |t| t.max(grace_ns)),
            last_ns: now_ns,
            heard: false,
        }
    }

    /// A peer spoke at `now_ns`.
    pub fn heard(&mut self, now_ns: u64) {
        self.last_ns = now_ns;
        self.heard = true;
    }

    /// Silence so far at `now_ns`, s.
    pub fn silence_s(&self, now_ns: u64) -> f64 {
        now_ns.saturating_sub(self.last_ns) as f64 * 1e-9
    }

    /// Whether the peers count as lost at `now_ns`.
    pub fn lost(&self, now_ns: u64) -> bool {
        let Some(timeout) = self.timeout_ns else {
            return false;
        };
        let limit = if self.heard { timeout } else { self.grace_ns };
        now_ns.saturating_sub(self.last_ns) > limit
    }
}

/// Why a process should stop: a `STOP` on the control service (the
/// launcher's clean shutdown), SIGTERM/SIGINT, or its launcher's death.
pub struct StopWatch {
    control: transport::Sub<Control>,
}

impl StopWatch {
    /// Watch the control service of `services`.
    pub fn new(services: &transport::Services) -> Result<StopWatch, IpcError> {
        Ok(StopWatch {
            control: transport::subscriber(&services.control)?,
        })
    }

    /// Whether a stop was requested since the last call (cheap: one
    /// shared-memory poll and an atomic read).
    pub fn requested(&self) -> bool {
        if crate::interrupt::stop_requested() || launcher_gone() {
            return true;
        }
        let mut stop = false;
        while let Ok(Some(sample)) = self.control.receive() {
            if sample.payload().0.command == control_command::STOP {
                stop = true;
            }
        }
        stop
    }
}

/// Ask every process of the loop to stop: a `STOP` on its control service,
/// what [`StopWatch::requested`] sees (the launcher's clean shutdown).
pub fn send_stop(control: &transport::Pub<Control>) -> Result<(), IpcError> {
    transport::send(
        control,
        Control {
            header: tendril_shared::messages::Header {
                seq: 1,
                stamp_ns: clock::now_ns(),
            },
            command: control_command::STOP,
            reserved: 0,
        },
    )
}

/// Write `bytes` to `path` atomically, mapping the error.
pub(crate) fn write_file(path: &std::path::Path, bytes: &[u8]) -> Result<(), IpcError> {
    crate::fsutil::write_atomic(path, bytes)
        .map_err(|e| IpcError::Other(format!("{}: {e}", path.display())))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn peers_count_as_lost_after_the_timeout_and_a_longer_start_grace() {
        let s = 1_000_000_000u64;
        let mut w = PeerWatch::new(Some(2.0), None, 0);
        assert!(!w.lost(9 * s), "start grace is 10 s");
        assert!(w.lost(11 * s));
        w.heard(11 * s);
        assert!(!w.lost(13 * s));
        assert!(w.lost(13 * s + 1));
        assert!(!PeerWatch::new(None, None, 0).lost(u64::MAX));
        // A grace given as the timeout itself: lost after the timeout from the start.
        let w = PeerWatch::new(Some(1.0), Some(1.0), 0);
        assert!(!w.lost(s) && w.lost(s + 1));
        // A grace never shortens the timeout.
        assert!(!PeerWatch::new(Some(3.0), Some(1.0), 0).lost(2 * s));
    }

    /// The planner knows how close its path comes to the tendons' limits:
    /// the two-segment robot's circle at the bottom of its reachable band
    /// (392 mm: a tendon at its limit) has no headroom, the one at the
    /// default height (the headroom band's middle) keeps the built-in
    /// paths' share (`plan::headroom`).
    #[test]
    fn the_planner_reports_how_close_its_path_comes_to_the_limits() {
        let robot =
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../robots/tdcr-2seg.toml");
        let circle = |height_m| crate::plan::PathShape::Circle {
            center_m: [0.0, 0.0],
            radius_m: 0.01,
            freq_hz: 0.2,
            height_m,
        };
        let headroom = |height_m| {
            let cfg = planner::PlannerConfig::new(robot.clone(), circle(height_m));
            planner::plan(&cfg).unwrap().headroom.unwrap()
        };
        let low = headroom(Some(0.392));
        assert!(low.fraction < 0.01, "{low:?}");
        let limit = crate::robot::Robot::load(&robot).unwrap().max_tensions()[low.tendon];
        assert!((low.tension_n - limit).abs() < 0.01 * limit, "{low:?}");
        let default = headroom(None);
        assert!(
            default.fraction >= crate::plan::TENSION_HEADROOM - 0.01,
            "{default:?}"
        );
    }

    #[test]
    fn process_configs_round_trip_through_json_with_named_units() {
        let ctl = controller::ControllerConfig::new("r.toml".into(), "m.tnet".into());
        let text = serde_json::to_string(&ctl).unwrap();
        assert!(text.contains("\"lead_s\":0.0205") && text.contains("\"ki_per_s\""));
        assert_eq!(
            serde_json::from_str::<controller::ControllerConfig>(&text).unwrap(),
            ctl
        );
        let planner = planner::PlannerConfig {
            robot: "r.toml".into(),
            prefix: "p".into(),
            shape: crate::plan::PathShape::Circle {
                center_m: [0.0, 0.01],
                radius_m: 0.015,
                freq_hz: 0.2,
                height_m: Some(0.3),
            },
            step_shaping: crate::plan::ShapingChoice::Designed(crate::plan::StepShaping {
                mode_hz: 3.6,
                damping_ratio: 0.05,
                move_s: 0.14,
            }),
            start_from_rest: true,
            dynamic_offset: true,
            learning: crate::plan::LearningChoice::Off,
            adapt_stiffness: true,
            net_error_offset: true,
            model: Some("m.tnet".into()),
            turning_offset: Some(crate::plan::TurningOffset {
                center_m: [0.0, 0.01],
                period_s: 5.0,
                harmonics: vec![[[1e-4, 0.0], [-2e-5, 0.0], [0.0, 0.0]], [[3e-5, -1e-5]; 3]],
                learned_for: Some(crate::plan::LearnedFor {
                    robot: [7; 32],
                    shape: crate::plan::PathShape::default_circle(),
                }),
                start: Some(crate::plan::StartOffset {
                    step_s: 0.15,
                    bumps: vec![[1e-5, -2e-5, 3e-6]; 2],
                }),
                expected: Some(crate::plan::ExpectedError {
                    bin_s: 0.05,
                    start: vec![[2e-5, 0.0, -1e-6]; 3],
                    harmonics: vec![[[4e-5, 0.0], [0.0, 1e-6], [0.0; 2]]],
                }),
            }),
            controller_gains: Some(crate::plan::IntegralGains {
                ki_per_s: 4.0,
                filter_tau_s: 0.08,
                map_gain_per_s: 2.0,
                map_scale_m: 0.01,
            }),
            loop_delay_s: Some(0.0),
            rate_hz: 1000.0,
            settle_s: 2.0,
            duration_s: None,
            inject: planner::Injections::default(),
            peer_timeout_s: Some(2.0),
            peer_start_grace_s: None,
            supervised: true,
            log: None,
            realtime: false,
            cpu: None,
        };
        let text = serde_json::to_string(&planner).unwrap();
        assert!(text.contains("\"kind\":\"circle\""), "{text}");
        assert_eq!(
            serde_json::from_str::<planner::PlannerConfig>(&text).unwrap(),
            planner
        );
        let mut plant = plant::PlantConfig::default();
        plant.params.faults.stuck = Some(plant::StuckFault {
            tendon: 2,
            at_s: 2.0,
        });
        let text = serde_json::to_string(&plant).unwrap();
        assert!(
            text.contains("\"stuck\":{\"tendon\":2,\"at_s\":2.0}"),
            "{text}"
        );
        assert_eq!(
            serde_json::from_str::<plant::PlantConfig>(&text).unwrap(),
            plant
        );
        // A misspelt field is an error, not a silent default.
        let err = serde_json::from_str::<plant::PlantConfig>("{\"robott\": \"x\"}").unwrap_err();
        assert!(err.to_string().contains("robott"), "{err}");
    }
}

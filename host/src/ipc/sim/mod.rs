//! `tendril sim`: the closed loop as three processes (docs/design.md §6).
//!
//! [`run`] takes a typed [`SimConfig`], creates the services under a unique
//! prefix, writes each child's typed configuration as JSON and starts
//! `tendril plant|controller|planner --config FILE`
//! ([`supervisor`]: children that die with the launcher), plays the fault
//! script ([`faults`]), stops everything, turns the logs into numbers
//! ([`analysis`]) and returns a typed [`SimReport`] ([`report`]), also
//! written as `report.json`, `report.md` and `sim.png`.
//!
//! The run works in `OUT/.sim-run/` and moves its files into `OUT` only
//! when it completes, so an interrupted run leaves the previous outputs as
//! they were.

pub mod analysis;
pub mod assess;
pub mod budget;
mod config;
pub mod faults;
pub mod model_learning;
pub mod oscillation;
pub mod realtime;
pub mod report;
mod sample;
pub mod supervisor;
pub mod workdir;

use std::path::PathBuf;
use std::time::Duration;

use tendril_shared::messages::Header;

pub use self::config::{unique_prefix, ModelSource, SimConfig, SimMcu};
pub use self::faults::SimFaults;
use self::faults::{weight_update, Action};
use self::report::{ModelUsed, SimReport};
use self::supervisor::{Children, ProcessEnd, Role};
use self::workdir::{write_json, Configs, RunDir};
use super::clock::now_ns;
use super::transport::{self, Services};
use super::IpcError;
use crate::interrupt::stop_requested as interrupted;
use crate::statics::Statics;

/// The firmware's built-in net: what `tendril sim` runs when no model is
/// given and none has been trained (the very file the MCU build embeds).
pub const BUILT_IN_NET: &[u8] = include_bytes!("../../../../firmware/vectors/default.tnet");

/// The circle's offset learned on the model, in the run's directory
/// (`--model-learning on`; read back with `--turning-offset`).
pub const TURNING_OFFSET_FILE: &str = "turning-offset.json";

/// Integral gain of the correction when it is on, 1/s.
pub const DEFAULT_KI_PER_S: f64 = crate::ipc::controller::correction::KI_PER_S;

/// Default bound on the RMS tracking error of a clean run, mm: twice the
/// millimetre the nominal circle is held to (tests/tests/hil_loop.rs), far
/// below what a wrong net or an unstable loop gives (51 mm, issue 31).
pub const DEFAULT_MAX_RMS_MM: f64 = 2.0;

/// The run log's file name in the output directory (docs/design.md §12).
pub const RUN_MCAP: &str = "run.mcap";

/// Name of the working directory inside the output directory.
pub const RUN_DIR: &str = ".sim-run";

/// How long a planner may take to send its first setpoint (it lifts the
/// whole trajectory through the statics first).
const FIRST_SETPOINT_TIMEOUT_S: f64 = 60.0;

/// What can stop a sim before it has a report.
#[derive(Debug, thiserror::Error)]
pub enum SimError {
    /// A configuration value is out of range.
    #[error("{0}")]
    Config(String),
    /// A file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// The transport or a log failed.
    #[error(transparent)]
    Ipc(#[from] IpcError),
    /// A child process ended before the loop ran.
    #[error("{role} exited before the loop started ({end}); its error is above")]
    ChildFailedAtStart {
        /// Which process.
        role: &'static str,
        /// How it ended.
        end: String,
    },
    /// The planner never sent a setpoint.
    #[error("no setpoint from the planner within {0} s")]
    NoSetpoint(f64),
    /// SIGINT or SIGTERM: the processes were stopped, the run's work
    /// directory (its logs so far) removed, the outputs left as they were:
    /// an interrupted run has no report to stand behind its logs
    /// (PROBES.md: an interrupted run leaves exactly the previous outputs).
    #[error(
        "interrupted: stopped planner, controller and plant; this run's logs were discarded \
         and the previous outputs left as they were"
    )]
    Interrupted,
}

/// How the timed part of a run ended.
enum Ending {
    /// At the configured end.
    Completed,
    /// A process died on its own: stopped at once.
    ProcessDied,
    /// SIGINT/SIGTERM.
    Interrupted,
}

/// Sleep until `t_ns` in short slices, watching the children and the
/// interrupt latch.
fn wait_until(t_ns: u64, children: &mut Children, deaths: &mut Vec<String>) -> Option<Ending> {
    loop {
        if interrupted() {
            return Some(Ending::Interrupted);
        }
        let gone = children.poll(false);
        if !gone.is_empty() {
            deaths.extend(
                gone.iter()
                    .map(|(role, end)| format!("{} {}", role.name(), end.describe())),
            );
            return Some(Ending::ProcessDied);
        }
        let now = now_ns();
        if now >= t_ns {
            return None;
        }
        super::clock::sleep_until(now + (t_ns - now).min(10_000_000), 0);
    }
}

/// An event the launcher caused, for the fault analysis.
pub struct Event {
    /// When (monotonic ns).
    pub t_ns: u64,
    /// What.
    pub action: Action,
    /// The pid killed, for a kill.
    pub pid: Option<u32>,
}

/// Run the loop and return its report (also written to `out/report.json`,
/// `report.md`, `sim.png`). A run whose processes did not all finish
/// cleanly (an injected kill excepted) still returns its report, with
/// `verdict.clean == false` and the reasons.
pub fn run(cfg: &SimConfig) -> Result<SimReport, SimError> {
    cfg.validate()?;
    // A shape the robot cannot follow is one line now, not a planner that
    // dies after the net was fitted.
    let robot =
        crate::robot::Robot::load(&cfg.robot).map_err(|e| SimError::Config(e.to_string()))?;
    let statics = Statics::new(&robot, crate::statics::SolverSettings::default());
    let family = crate::plan::Family::of(&statics).map_err(IpcError::from)?;
    cfg.planner.shape.check(&family).map_err(IpcError::from)?;
    if let Some(table) = &cfg.planner.turning_offset {
        crate::ipc::planner::check_turning_offset(table, &cfg.planner.shape, &robot)
            .map_err(|e| SimError::Config(e.to_string()))?;
    }
    // The step shaping is designed once, here, so the report can say what
    // the planner used (`docs/design.md` §6.4).
    let shaping = cfg
        .planner
        .step_shaping
        .resolve(&robot, &cfg.planner.shape)
        .map_err(|e| SimError::Config(e.to_string()))?;
    let mut resolved = cfg.clone();
    resolved.planner.step_shaping = match shaping {
        Some(s) => crate::plan::ShapingChoice::Designed(s),
        None => crate::plan::ShapingChoice::Off,
    };
    resolved.planner.learning = learning(cfg, &robot, shaping)?;
    resolved.planner.controller_gains = Some(cfg.controller.integral_gains(&robot));
    resolved.planner.loop_delay_s = Some(crate::ipc::controller::loop_delay_s(cfg.mcu.is_some()));
    let cfg = &resolved;
    budget::check(
        cfg,
        robot.max_tensions().len(),
        budget::free_bytes(&cfg.out),
    )?;
    check_model(cfg)?;
    let dir = RunDir::create(&cfg.out)?;
    let result = run_in(cfg, &dir);
    match result {
        Ok(report) => {
            dir.publish()?;
            Ok(report)
        }
        Err(e) => {
            dir.discard();
            Err(e)
        }
    }
}

/// The learning the planner is to use, designed here with the
/// controller's own gains (scaled to the mode as the controller scales
/// them) so the report can say what was learned with. A learning the
/// convergence check refuses is off, with a warning; the run goes on.
fn learning(
    cfg: &SimConfig,
    robot: &crate::robot::Robot,
    shaping: Option<crate::plan::StepShaping>,
) -> Result<crate::plan::LearningChoice, SimError> {
    use crate::plan::LearningChoice;
    let gains = cfg.controller.integral_gains(robot);
    match cfg
        .planner
        .learning
        .resolve(shaping, cfg.planner.shape.period_s(), gains)
    {
        Ok(Some(design)) => Ok(LearningChoice::Designed(design)),
        Ok(None) => Ok(LearningChoice::Off),
        Err(e) if matches!(cfg.planner.learning, LearningChoice::Designed(_)) => {
            Err(SimError::Config(e.to_string()))
        }
        Err(e) => {
            log::warn!("learning off: {e}");
            Ok(LearningChoice::Off)
        }
    }
}

/// Refuse a `--model` file trained for another robot before anything is
/// created or started (the controller checks again, for `tendril
/// controller` alone).
fn check_model(cfg: &SimConfig) -> Result<(), SimError> {
    let ModelSource::File(path) = &cfg.model else {
        return Ok(());
    };
    let robot =
        crate::robot::Robot::load(&cfg.robot).map_err(|e| SimError::Config(e.to_string()))?;
    let (_, provenance) =
        crate::net::read_model(path).map_err(|e| SimError::Config(e.to_string()))?;
    crate::net::check_model_robot(
        path,
        provenance.as_ref(),
        &robot,
        cfg.controller.allow_robot_mismatch,
        crate::net::CLI_OVERRIDE,
    )
    .map_err(|e| SimError::Config(e.to_string()))?;
    Ok(())
}

fn model_file(cfg: &SimConfig, dir: &RunDir) -> Result<(PathBuf, Vec<u8>, ModelUsed), SimError> {
    let write = |name: &str, bytes: &[u8]| -> Result<PathBuf, SimError> {
        let path = dir.file(name);
        crate::fsutil::write_atomic(&path, bytes).map_err(|source| SimError::Io {
            path: path.clone(),
            source,
        })?;
        Ok(path)
    };
    Ok(match &cfg.model {
        ModelSource::File(path) => {
            let bytes =
                crate::fsutil::read_capped(path, crate::net::MAX_TNET_BYTES).map_err(|source| {
                    SimError::Io {
                        path: path.clone(),
                        source,
                    }
                })?;
            let used = ModelUsed {
                path: cfg.shown(path),
                built_in: false,
            };
            (path.clone(), bytes, used)
        }
        ModelSource::BuiltIn => {
            let path = write("default.tnet", BUILT_IN_NET)?;
            let used = ModelUsed {
                path: cfg.shown(&cfg.out.join("default.tnet")),
                built_in: true,
            };
            (path, BUILT_IN_NET.to_vec(), used)
        }
        ModelSource::Quick => {
            let robot = crate::robot::Robot::load(&cfg.robot)
                .map_err(|e| SimError::Config(e.to_string()))?;
            let statics =
                crate::statics::Statics::new(&robot, crate::statics::SolverSettings::default());
            let blob = crate::plan::stand_in::quick_net_for(&statics, 2000, 48, 7)
                .map_err(|e| SimError::Config(e.to_string()))?;
            // Fitted for this robot: say so, so the controller can check it.
            let provenance =
                tendril_shared::Provenance::new(robot.fingerprint(), &robot.name, None);
            let blob = tendril_shared::stamp_provenance(&blob, &provenance)
                .map_err(|e| SimError::Config(format!("the quick net: {e}")))?;
            let path = write("quick.tnet", &blob)?;
            let used = ModelUsed {
                path: cfg.shown(&cfg.out.join("quick.tnet")),
                built_in: false,
            };
            (path, blob, used)
        }
    })
}

fn run_in(cfg: &SimConfig, dir: &RunDir) -> Result<SimReport, SimError> {
    let (model_path, model_bytes, model_used) = model_file(cfg, dir)?;
    let learned = model_learning::before_run(cfg, &model_path, &model_bytes)?;
    let with_offset;
    let (cfg, model_learning) = match learned {
        Some((offset, report)) => {
            write_json(&dir.file(TURNING_OFFSET_FILE), &offset)?;
            let mut c = cfg.clone();
            c.planner.turning_offset = Some(offset);
            with_offset = c;
            (&with_offset, Some(report))
        }
        None => (cfg, None),
    };
    let prefix = cfg.prefix.clone().unwrap_or_else(unique_prefix);
    let cpus = if cfg.pin {
        let cpus = super::clock::allowed_cpus();
        match (cpus.first(), cpus.last()) {
            (Some(&first), Some(&last)) => (Some(last), (first != last).then_some(first)),
            _ => (None, None),
        }
    } else {
        (None, None)
    };
    // The chip, owned by the launcher: a link cut kills the bridge, not the chip.
    let chip = match &cfg.mcu {
        Some(m) => {
            let image = match &m.image {
                Some(i) => i.clone(),
                None => {
                    crate::mcu::locate_image().map_err(|e| SimError::Config(format!("{e:#}")))?
                }
            };
            let socket = std::env::temp_dir().join(format!("{prefix}.chip.sock"));
            let chip = crate::mcu::Chip::start(&image, &socket)
                .map_err(|e| SimError::Config(format!("starting the chip: {e:#}")))?;
            if cfg.realtime && chip.make_realtime(super::clock::CONTROLLER_PRIORITY) == 0 {
                log::warn!(
                    "sim: SCHED_FIFO refused for the chip (QEMU), running it with normal priority"
                );
            }
            Some(chip)
        }
        None => None,
    };
    let configs = Configs {
        cfg,
        dir,
        prefix: prefix.clone(),
        model: model_path,
        cpus,
        chip_socket: chip.as_ref().map(|c| c.socket().to_path_buf()),
    };

    // Services first, then the peers (see the module docs of `transport`).
    let nodes_before = transport::node_entry_names();
    let node = transport::node("tendril-sim")?;
    let services = Services::open_or_create(&node, &prefix)?;
    let control = transport::publisher(&services.control)?;
    let weights = transport::publisher(&services.weights)?;
    let watch = transport::subscriber(&services.setpoint)?;

    let mut children = Children::new(&cfg.exe, &dir.file("pids"));
    let started = now_ns();
    let steal_before = super::clock::cpu_steal_ms();
    let stop_now = |children: &mut Children| {
        children.stop_all(Duration::from_millis(500));
        node.try_cleanup_dead_nodes();
        transport::remove_orphan_node_entries(&children.ended_pids());
        transport::remove_broken_node_entries(&nodes_before);
    };
    for role in [Role::Plant, Role::Controller, Role::Planner] {
        let spawned = configs
            .write(role, 0)
            .and_then(|path| children.spawn(role, &path));
        if let Err(e) = spawned {
            stop_now(&mut children);
            return Err(e);
        }
    }

    // The run's clock starts with the planner's first setpoint (lifting the
    // trajectory takes the planner a moment).
    let t0 = loop {
        if let (Some(_), _) = transport::latest(&watch)? {
            break now_ns();
        }
        if interrupted() {
            stop_now(&mut children);
            return Err(SimError::Interrupted);
        }
        if let Some((role, end)) = children.poll(false).into_iter().next() {
            stop_now(&mut children);
            return Err(SimError::ChildFailedAtStart {
                role: role.name(),
                end: end.describe(),
            });
        }
        if (now_ns() - started) as f64 * 1e-9 > FIRST_SETPOINT_TIMEOUT_S {
            stop_now(&mut children);
            return Err(SimError::NoSetpoint(FIRST_SETPOINT_TIMEOUT_S));
        }
        std::thread::sleep(Duration::from_millis(5));
    };
    drop(watch);

    let end_s = cfg.planner.settle_s + cfg.duration_s;
    let at = |t: f64| t0 + (t * 1e9) as u64;
    let mut events: Vec<Event> = Vec::new();
    let mut deaths: Vec<String> = Vec::new();
    let mut weight_seq = 0;
    let mut ending = Ending::Completed;
    for (t, action) in cfg.faults.script(end_s) {
        if let Some(e) = wait_until(at(t), &mut children, &mut deaths) {
            ending = e;
            break;
        }
        let pid = match action {
            Action::Kill(role) => children.kill_as_fault(role),
            Action::Restart(role) => {
                let generation = children.started(role);
                let path = configs.write(role, generation)?;
                children.spawn(role, &path)?;
                None
            }
            Action::Weights { corrupt } => {
                weight_seq += 1;
                let header = Header {
                    seq: weight_seq,
                    stamp_ns: now_ns(),
                };
                transport::send(&weights, weight_update(&model_bytes, header, corrupt)?)?;
                None
            }
        };
        log::info!("sim: {action} at {t:.3} s");
        events.push(Event {
            t_ns: now_ns(),
            action,
            pid,
        });
    }
    if matches!(ending, Ending::Completed) {
        if let Some(e) = wait_until(at(end_s), &mut children, &mut deaths) {
            ending = e;
        }
    }
    let stopped_ns = now_ns();
    let steal_ms = steal_before
        .zip(super::clock::cpu_steal_ms())
        .map(|(b, a)| super::clock::steal_between(&b, &a, cpus.0));
    match ending {
        Ending::Interrupted => {
            stop_now(&mut children);
            return Err(SimError::Interrupted);
        }
        Ending::ProcessDied => {
            log::error!(
                "sim: {} at {:.3} s: stopping the run",
                deaths.join(", "),
                (stopped_ns - t0) as f64 * 1e-9
            );
            children.stop_all(Duration::from_secs(2));
        }
        Ending::Completed => {
            super::send_stop(&control)?;
            children.reap(Duration::from_secs(10), ProcessEnd::KilledAtShutdown);
        }
    }
    node.try_cleanup_dead_nodes();
    transport::remove_orphan_node_entries(&children.ended_pids());
    transport::remove_broken_node_entries(&nodes_before);
    if interrupted() {
        return Err(SimError::Interrupted);
    }

    let mut report = assess::build_report(
        cfg,
        dir,
        t0,
        &children,
        &events,
        &prefix,
        model_used,
        realtime::MachineTook {
            steal_ms,
            planner_on_another_cpu: cpus.0.is_some() && cpus.1.is_some(),
            shared_stall_periods: None,
        },
    )?;
    report.model_learning = model_learning;
    write_json(&dir.file("report.json"), &report)?;
    crate::fsutil::write_atomic(&dir.file("report.md"), report.markdown().as_bytes()).map_err(
        |source| SimError::Io {
            path: dir.file("report.md"),
            source,
        },
    )?;
    let figure = crate::plot::sim::SimFigure {
        desired_mm: (report.series.path.iter())
            .map(|p| (p.desired_mm[0], p.desired_mm[1]))
            .collect(),
        actual_mm: (report.series.path.iter())
            .map(|p| (p.actual_mm[0], p.actual_mm[1]))
            .collect(),
        tensions: (report.series.tensions.iter())
            .map(|r| crate::plot::sim::TensionSample {
                t_s: r.t_s,
                commanded: &r.commanded,
                actual: &r.actual,
            })
            .collect(),
        tendons: report.tendons,
    };
    crate::plot::sim::draw(&dir.file("sim.png"), &figure)
        .map_err(|e| SimError::Config(format!("sim figure: {e}")))?;
    if cfg.plant.runlog.mcap.is_some() {
        finish_run_log(dir, &report)?;
    }
    Ok(report)
}

/// Give `run.mcap` the report's summary as metadata. A plant killed
/// mid-run left its file under `run.mcap.partial`, readable up to its last
/// chunk: it becomes `run.mcap` too.
fn finish_run_log(dir: &RunDir, report: &SimReport) -> Result<(), SimError> {
    let path = dir.file(RUN_MCAP);
    let partial = crate::fsutil::partial_path(&path);
    let source = if path.exists() {
        path.clone()
    } else if partial.exists() {
        partial.clone()
    } else {
        log::warn!("sim: the plant wrote no {RUN_MCAP}");
        return Ok(());
    };
    let summary = report_metadata(report);
    crate::runlog::finalize::add_metadata(&source, &path, "report", summary)
        .map_err(|e| SimError::Config(format!("run log: {e}")))?;
    if source == partial {
        // Its contents are in run.mcap now.
        let _ = std::fs::remove_file(&partial);
    }
    Ok(())
}

/// The report's scalar fields (and its verdict's) as metadata strings.
fn report_metadata(report: &SimReport) -> std::collections::BTreeMap<String, String> {
    let mut out = std::collections::BTreeMap::new();
    let Ok(serde_json::Value::Object(top)) = serde_json::to_value(report) else {
        return out;
    };
    let scalar = |v: &serde_json::Value| match v {
        serde_json::Value::String(s) => Some(s.clone()),
        serde_json::Value::Number(_) | serde_json::Value::Bool(_) => Some(v.to_string()),
        _ => None,
    };
    for (key, value) in &top {
        match value {
            serde_json::Value::Object(inner) if key == "verdict" || key == "model" => {
                for (k, v) in inner {
                    if let Some(s) = scalar(v) {
                        out.insert(format!("{key}.{k}"), s);
                    }
                }
            }
            v => {
                if let Some(s) = scalar(v) {
                    out.insert(key.clone(), s);
                }
            }
        }
    }
    out
}

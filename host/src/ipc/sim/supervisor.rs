//! The sim's child processes: start them so they can never outlive the
//! launcher, record how each one ends, and stop them on every exit path.
//!
//! Three layers keep orphans away (docs/design.md §6):
//! - every child runs with `PR_SET_PDEATHSIG = SIGKILL` set between fork and
//!   exec, so the kernel kills it when the launcher dies, even by SIGKILL;
//! - the children share one process group of their own, so a Ctrl-C at the
//!   terminal reaches only the launcher, which stops them in order, and one
//!   `killpg` reaches them all;
//! - SIGINT/SIGTERM to the launcher are latched ([`interrupted`]) and end
//!   the run early; `Drop` kills whatever still runs.

use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::time::{Duration, Instant};

use serde::{Deserialize, Serialize};

use super::SimError;
use crate::ipc::clock::now_ns;

/// The three processes of the loop.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Role {
    /// Streams setpoints.
    Planner,
    /// Runs the control step.
    Controller,
    /// Simulates motors and robot.
    Plant,
}

impl Role {
    /// The subcommand (and file-name stem) of the role.
    pub fn name(self) -> &'static str {
        match self {
            Role::Planner => "planner",
            Role::Controller => "controller",
            Role::Plant => "plant",
        }
    }
}

/// How a process ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", tag = "kind")]
pub enum ProcessEnd {
    /// Exit status 0.
    Clean,
    /// A non-zero exit status.
    Failed {
        /// The status.
        code: i32,
    },
    /// Exited with status 0 before the launcher asked it to stop.
    QuitUnasked,
    /// Killed by a signal nobody in the sim sent.
    Signalled {
        /// The signal number.
        signal: i32,
    },
    /// Killed by the launcher as an injected fault.
    KilledByFault,
    /// Did not stop when told to: killed at shutdown.
    KilledAtShutdown,
    /// Stopped by the launcher because the run was interrupted or failed.
    StoppedEarly,
}

impl ProcessEnd {
    fn from_status(status: ExitStatus) -> ProcessEnd {
        use std::os::unix::process::ExitStatusExt;
        match (status.code(), status.signal()) {
            (Some(0), _) => ProcessEnd::Clean,
            (Some(code), _) => ProcessEnd::Failed { code },
            (None, Some(signal)) => ProcessEnd::Signalled { signal },
            (None, None) => ProcessEnd::Failed { code: -1 },
        }
    }

    /// Whether this end is fine for the run's verdict (a process stopped
    /// early is not a cause: whatever made the launcher stop it is).
    pub fn acceptable(self) -> bool {
        matches!(
            self,
            ProcessEnd::Clean | ProcessEnd::KilledByFault | ProcessEnd::StoppedEarly
        )
    }

    /// One phrase for the report.
    pub fn describe(self) -> String {
        match self {
            ProcessEnd::Clean => "exited cleanly".into(),
            ProcessEnd::QuitUnasked => "exited (status 0) before the run's end".into(),
            ProcessEnd::Failed { code } => format!("exited with status {code}"),
            ProcessEnd::Signalled { signal } => format!("killed by signal {signal}"),
            ProcessEnd::KilledByFault => "killed (injected fault)".into(),
            ProcessEnd::KilledAtShutdown => "did not stop: killed at shutdown".into(),
            ProcessEnd::StoppedEarly => "stopped early by the launcher".into(),
        }
    }
}

/// One process of the run, for the report.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct ProcessRecord {
    /// Its role.
    pub role: Role,
    /// 0 for the first of its role, 1 for a restart, …
    pub generation: usize,
    /// OS process id.
    pub pid: u32,
    /// Start, s since the first setpoint (negative: before it).
    pub started_s: f64,
    /// End, s since the first setpoint.
    pub ended_s: Option<f64>,
    /// How it ended.
    pub end: ProcessEnd,
}

struct Running {
    role: Role,
    generation: usize,
    child: Child,
    started_ns: u64,
}

/// A process that has ended.
struct Ended {
    role: Role,
    generation: usize,
    pid: u32,
    started_ns: u64,
    ended_ns: u64,
    end: ProcessEnd,
}

/// The launcher's children.
pub struct Children {
    exe: PathBuf,
    pids_file: PathBuf,
    group: Option<libc::pid_t>,
    running: Vec<Running>,
    ended: Vec<Ended>,
    generations: [usize; 3],
}

fn role_index(role: Role) -> usize {
    match role {
        Role::Planner => 0,
        Role::Controller => 1,
        Role::Plant => 2,
    }
}

/// Between fork and exec: die with the launcher. Only async-signal-safe
/// calls here (no allocation: the launcher is multi-threaded). SIGTERM, as
/// the child asks again itself ([`crate::ipc::die_with_parent`]): until the
/// child installs its handler the default action ends it as surely as
/// SIGKILL; after, it stops its loop and releases its and the launcher's
/// iceoryx2 resources.
fn die_with_parent(parent: libc::pid_t) -> std::io::Result<()> {
    // SAFETY: prctl with these arguments and getppid only set and read
    // process attributes; both are async-signal-safe.
    unsafe {
        if libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGTERM) != 0 {
            return Err(std::io::Error::last_os_error());
        }
        // The launcher may have died before the prctl took effect.
        if libc::getppid() != parent {
            return Err(std::io::Error::from_raw_os_error(libc::ESRCH));
        }
    }
    Ok(())
}

impl Children {
    /// No children yet; `pids_file` lists the running ones (`role generation pid`).
    pub fn new(exe: &Path, pids_file: &Path) -> Children {
        Children {
            exe: exe.to_path_buf(),
            pids_file: pids_file.to_path_buf(),
            group: None,
            running: Vec::new(),
            ended: Vec::new(),
            generations: [0; 3],
        }
    }

    fn command(&self, role: Role, config: &Path, group: libc::pid_t) -> Command {
        let mut cmd = Command::new(&self.exe);
        cmd.arg(role.name())
            .arg("--config")
            .arg(config)
            .stdin(Stdio::null())
            .env(crate::ipc::SUPERVISED_ENV, std::process::id().to_string())
            .process_group(group);
        // The children's routine lines (net loaded, tracking resumed) are
        // detail for a sim user: they log warnings and errors unless the
        // launcher itself was asked for more (`-v`) or RUST_LOG says otherwise.
        if std::env::var_os("RUST_LOG").is_none() {
            let spec = match log::max_level() {
                log::LevelFilter::Debug => "warn,tendril=debug",
                log::LevelFilter::Trace => "warn,tendril=trace",
                _ => "warn",
            };
            cmd.env("RUST_LOG", spec);
        }
        let parent = std::process::id() as libc::pid_t;
        // SAFETY: the closure calls only async-signal-safe functions.
        unsafe {
            cmd.pre_exec(move || die_with_parent(parent));
        }
        cmd
    }

    /// Start `tendril ROLE --config CONFIG`; returns the generation it got.
    pub fn spawn(&mut self, role: Role, config: &Path) -> Result<usize, SimError> {
        let spawn_io = |source| SimError::Io {
            path: self.exe.clone(),
            source,
        };
        let child = match self.group {
            None => self.command(role, config, 0).spawn().map_err(spawn_io)?,
            // The group lives while any member does; if all are gone, a new one.
            Some(g) => match self.command(role, config, g).spawn() {
                Ok(c) => c,
                Err(_) => {
                    self.group = None;
                    self.command(role, config, 0).spawn().map_err(spawn_io)?
                }
            },
        };
        let pid = child.id();
        if self.group.is_none() {
            self.group = Some(pid as libc::pid_t);
        }
        let generation = self.generations[role_index(role)];
        self.generations[role_index(role)] += 1;
        log::debug!("sim: started {} {generation} (pid {pid})", role.name());
        self.running.push(Running {
            role,
            generation,
            child,
            started_ns: now_ns(),
        });
        self.write_pids()?;
        Ok(generation)
    }

    fn write_pids(&self) -> Result<(), SimError> {
        let text: String = self
            .running
            .iter()
            .map(|r| format!("{} {} {}\n", r.role.name(), r.generation, r.child.id()))
            .collect();
        crate::fsutil::write_atomic(&self.pids_file, text.as_bytes()).map_err(|source| {
            SimError::Io {
                path: self.pids_file.clone(),
                source,
            }
        })
    }

    fn finish(&mut self, i: usize, end: Option<ProcessEnd>) {
        let mut r = self.running.remove(i);
        let pid = r.child.id();
        let status = r.child.wait().ok();
        let end = end
            .or(status.map(ProcessEnd::from_status))
            .unwrap_or(ProcessEnd::Failed { code: -1 });
        self.ended.push(Ended {
            role: r.role,
            generation: r.generation,
            pid,
            started_ns: r.started_ns,
            ended_ns: now_ns(),
            end,
        });
        let _ = self.write_pids();
    }

    /// SIGKILL the newest `role` as an injected fault; its pid.
    pub fn kill_as_fault(&mut self, role: Role) -> Option<u32> {
        let i = self.running.iter().rposition(|r| r.role == role)?;
        let pid = self.running[i].child.id();
        let _ = self.running[i].child.kill();
        self.finish(i, Some(ProcessEnd::KilledByFault));
        Some(pid)
    }

    /// Children that ended since the last call (role, how); `asked` says
    /// whether they were told to stop (else even status 0 is premature).
    pub fn poll(&mut self, asked: bool) -> Vec<(Role, ProcessEnd)> {
        let mut gone = Vec::new();
        let mut i = 0;
        while i < self.running.len() {
            match self.running[i].child.try_wait() {
                Ok(Some(status)) => {
                    let end = match ProcessEnd::from_status(status) {
                        ProcessEnd::Clean if !asked => ProcessEnd::QuitUnasked,
                        end => end,
                    };
                    gone.push((self.running[i].role, end));
                    self.finish(i, Some(end));
                }
                _ => i += 1,
            }
        }
        gone
    }

    /// After a stop request: wait up to `timeout` for every child, then
    /// SIGKILL the stragglers.
    pub fn reap(&mut self, timeout: Duration, late: ProcessEnd) {
        let deadline = Instant::now() + timeout;
        while !self.running.is_empty() && Instant::now() < deadline {
            self.poll(true);
            std::thread::sleep(Duration::from_millis(5));
        }
        while let Some(r) = self.running.last_mut() {
            let _ = r.child.kill();
            let i = self.running.len() - 1;
            self.finish(i, Some(late));
        }
    }

    /// Stop everything now (interrupt, failure): SIGTERM the group — each
    /// child's stop watch ends its loop and removes its iceoryx2 node —
    /// then SIGKILL whatever is left after `grace`.
    pub fn stop_all(&mut self, grace: Duration) {
        if let Some(g) = self.group {
            // SAFETY: sends a signal to our own children's process group.
            unsafe {
                libc::killpg(g, libc::SIGTERM);
            }
        }
        let deadline = Instant::now() + grace;
        while !self.running.is_empty() && Instant::now() < deadline {
            let mut i = 0;
            while i < self.running.len() {
                if let Ok(Some(_)) = self.running[i].child.try_wait() {
                    self.finish(i, Some(ProcessEnd::StoppedEarly));
                } else {
                    i += 1;
                }
            }
            std::thread::sleep(Duration::from_millis(5));
        }
        while let Some(r) = self.running.last_mut() {
            let _ = r.child.kill();
            let i = self.running.len() - 1;
            self.finish(i, Some(ProcessEnd::StoppedEarly));
        }
    }

    /// Process ids of every child that has ended (and been reaped).
    pub fn ended_pids(&self) -> Vec<u32> {
        self.ended.iter().map(|e| e.pid).collect()
    }

    /// Whether any child still runs.
    pub fn any_running(&self) -> bool {
        !self.running.is_empty()
    }

    /// Generations started per role so far (planner, controller, plant).
    pub fn started(&self, role: Role) -> usize {
        self.generations[role_index(role)]
    }

    /// Every process that has ended, times in s since `t0_ns`.
    pub fn records(&self, t0_ns: u64) -> Vec<ProcessRecord> {
        let secs = |t: u64| (t as f64 - t0_ns as f64) * 1e-9;
        let mut v: Vec<ProcessRecord> = self
            .ended
            .iter()
            .map(|e| ProcessRecord {
                role: e.role,
                generation: e.generation,
                pid: e.pid,
                started_s: secs(e.started_ns),
                ended_s: Some(secs(e.ended_ns)),
                end: e.end,
            })
            .collect();
        v.sort_by(|a, b| a.started_s.total_cmp(&b.started_s));
        v
    }
}

impl Drop for Children {
    /// Every exit path of the launcher (an error included) stops the children.
    fn drop(&mut self) {
        if !self.running.is_empty() {
            self.stop_all(Duration::from_millis(300));
        }
    }
}

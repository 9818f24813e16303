//! The files of one run: a work directory inside the output directory
//! (moved into place only when the run completes) and each child's typed
//! configuration written there as JSON.

use std::path::{Path, PathBuf};

use serde::Serialize;

use super::supervisor::Role;
use super::{SimConfig, SimError, RUN_DIR};

/// Paths of one run, and its lock on the output directory.
pub struct RunDir {
    out: PathBuf,
    /// The work directory.
    pub work: PathBuf,
    /// Whether this run created `out` (then a run that publishes nothing
    /// removes it again).
    created_out: bool,
    /// Outputs in `out` that are written through (devices, FIFOs), opened
    /// when the run starts: a FIFO without a reader is refused before the
    /// run, not after it.
    through: std::sync::Mutex<Vec<(std::ffi::OsString, std::fs::File)>>,
    /// Held until the run's files are published or discarded: a second
    /// run on the same directory fails at once instead of mixing its files
    /// with this one's.
    _lock: crate::fsutil::DirLock,
}

impl RunDir {
    /// Create and lock `out` (see [`crate::fsutil::DirLock`]), and make a
    /// fresh work directory in it.
    pub fn create(out: &Path) -> Result<RunDir, SimError> {
        let io = |path: &Path| {
            let path = path.to_path_buf();
            move |source| SimError::Io { path, source }
        };
        let created_out = std::fs::symlink_metadata(out).is_err();
        let lock =
            crate::fsutil::DirLock::acquire(out).map_err(|e| SimError::Config(e.to_string()))?;
        let work = out.join(RUN_DIR);
        // A launcher killed with SIGKILL leaves its work directory behind.
        if work.exists() {
            std::fs::remove_dir_all(&work).map_err(io(&work))?;
        }
        let mut through = Vec::new();
        for entry in std::fs::read_dir(out).map_err(io(out))? {
            let entry = entry.map_err(io(out))?;
            let path = entry.path();
            let name = entry.file_name();
            let ours = [".json", ".csv", ".md", ".png", ".mcap", ".tnet"]
                .iter()
                .any(|e| name.to_string_lossy().ends_with(e));
            if !ours {
                continue;
            }
            // Not a regular output nor a directory: a node written through.
            if let Ok(false) = crate::fsutil::is_regular_output(&path) {
                let node = crate::fsutil::open_through(&path).map_err(io(&path))?;
                through.push((name, node));
            }
        }
        std::fs::create_dir(&work).map_err(io(&work))?;
        Ok(RunDir {
            out: out.to_path_buf(),
            work,
            created_out,
            through: std::sync::Mutex::new(through),
            _lock: lock,
        })
    }

    /// A file in the work directory.
    pub fn file(&self, name: &str) -> PathBuf {
        self.work.join(name)
    }

    /// Move every file of the run into the output directory, after
    /// removing the process logs of a previous run (a previous run may
    /// have had more generations). An output that is a symlink stays a
    /// link and its target is replaced; a device or FIFO is written
    /// through ([`crate::fsutil::move_into_place`], the policy of every
    /// output). The outputs written through go first, each opened before
    /// any is written (a FIFO without a reader, a full device): if one
    /// fails, no regular file has been touched and the run's files are
    /// removed with the work directory. Signals wait until it is done.
    pub fn publish(self) -> Result<(), SimError> {
        let _deferred = crate::fsutil::Publishing::start();
        let result = self.publish_files();
        if result.is_err() {
            self.remove_work();
        }
        result
    }

    fn publish_files(&self) -> Result<(), SimError> {
        let io = |path: PathBuf| move |source| SimError::Io { path, source };
        let mut regular = Vec::new();
        let mut through = Vec::new();
        for entry in std::fs::read_dir(&self.work).map_err(io(self.work.clone()))? {
            let entry = entry.map_err(io(self.work.clone()))?;
            let name = entry.file_name();
            if name == "pids" {
                continue;
            }
            let to = self.out.join(&name);
            if crate::fsutil::is_regular_output(&to).map_err(io(to.clone()))? {
                regular.push((entry.path(), to));
            } else {
                let opened = self.take_opened(&name);
                let node = match opened {
                    Some(node) => node,
                    None => crate::fsutil::open_through(&to).map_err(io(to.clone()))?,
                };
                through.push((entry.path(), to, node));
            }
        }
        for (from, to, mut node) in through {
            let mut src = std::fs::File::open(&from).map_err(io(from.clone()))?;
            std::io::copy(&mut src, &mut node).map_err(io(to.clone()))?;
            std::io::Write::flush(&mut node).map_err(io(to))?;
            std::fs::remove_file(&from).map_err(io(from))?;
        }
        for entry in std::fs::read_dir(&self.out).map_err(io(self.out.clone()))? {
            let entry = entry.map_err(io(self.out.clone()))?;
            let name = entry.file_name().to_string_lossy().into_owned();
            let process_file = ["planner-", "plant-", "controller.", "controller-"]
                .iter()
                .any(|p| name.starts_with(p))
                && [".csv", ".json", ".mcap"].iter().any(|e| name.ends_with(e));
            // A run without a log must not leave the previous run's.
            // Nor the previous run's table learned on the model.
            let process_file =
                process_file || name == super::RUN_MCAP || name == super::TURNING_OFFSET_FILE;
            if process_file && entry.path().is_file() {
                std::fs::remove_file(entry.path()).map_err(io(entry.path()))?;
            }
        }
        for (from, to) in regular {
            crate::fsutil::move_into_place(&from, &to).map_err(io(to))?;
        }
        std::fs::remove_dir_all(&self.work).map_err(io(self.work.clone()))
    }

    /// The node `name` in `out` opened when the run started, if it was.
    fn take_opened(&self, name: &std::ffi::OsStr) -> Option<std::fs::File> {
        let mut list = self.through.lock().ok()?;
        let k = list.iter().position(|(n, _)| n == name)?;
        Some(list.swap_remove(k).1)
    }

    /// Drop the run's files (interrupted or failed before the loop ran).
    pub fn discard(self) {
        self.remove_work();
    }

    /// Remove the work directory; and an output directory this run
    /// created, if the run leaves nothing else in it (a refused run
    /// leaves no directory holding only its lock).
    fn remove_work(&self) {
        let _ = std::fs::remove_dir_all(&self.work);
        if self.created_out {
            let only_lock = std::fs::read_dir(&self.out)
                .map(|entries| {
                    entries
                        .filter_map(Result::ok)
                        .all(|e| e.file_name() == crate::fsutil::DirLock::FILE)
                })
                .unwrap_or(false);
            if only_lock {
                let _ = std::fs::remove_file(self.out.join(crate::fsutil::DirLock::FILE));
                let _ = std::fs::remove_dir(&self.out);
            }
        }
    }
}

/// Write `value` as pretty JSON, atomically.
pub fn write_json<T: Serialize>(path: &Path, value: &T) -> Result<(), SimError> {
    let bytes = serde_json::to_vec_pretty(value)
        .map_err(|e| SimError::Config(format!("{}: {e}", path.display())))?;
    crate::fsutil::write_atomic(path, &bytes).map_err(|source| SimError::Io {
        path: path.to_path_buf(),
        source,
    })
}

/// The per-process configurations of one run.
pub struct Configs<'a> {
    /// The run's configuration.
    pub cfg: &'a SimConfig,
    /// Where the files go.
    pub dir: &'a RunDir,
    /// Service-name prefix.
    pub prefix: String,
    /// The net file the controller loads.
    pub model: PathBuf,
    /// CPUs for controller and plant, and for the planner.
    pub cpus: (Option<usize>, Option<usize>),
    /// The chip's link socket, when the chip is in the loop.
    pub chip_socket: Option<PathBuf>,
}

/// File stem of a process's config, log and statistics: `plant-1`,
/// `planner-0`, and `controller` (a restarted bridge, after a link cut:
/// `controller-1`).
pub fn stem(role: Role, generation: usize) -> String {
    match role {
        Role::Controller if generation == 0 => "controller".into(),
        _ => format!("{}-{generation}", role.name()),
    }
}

impl Configs<'_> {
    /// Write the configuration of `role`'s `generation` and return its path.
    pub fn write(&self, role: Role, generation: usize) -> Result<PathBuf, SimError> {
        let stem = stem(role, generation);
        let path = self.dir.file(&format!("{stem}.config.json"));
        let log = Some(self.dir.file(&format!("{stem}.csv")));
        let stats = Some(self.dir.file(&format!("{stem}.json")));
        let (loop_cpu, planner_cpu) = self.cpus;
        match role {
            Role::Plant => {
                let mut c = self.cfg.plant.clone();
                c.robot = self
                    .cfg
                    .plant_robot
                    .as_ref()
                    .unwrap_or(&self.cfg.robot)
                    .clone();
                c.prefix = self.prefix.clone();
                c.log = log;
                c.stats = stats;
                // On the controller's CPU: above the controller when
                // quasi-static, below it when dynamic (the plant process
                // picks its priority, `clock::plant_priority`).
                c.cpu = loop_cpu;
                c.realtime = self.cfg.realtime;
                c.supervised = true;
                c.duration_s = None;
                if c.runlog.mcap.is_some() {
                    // A restarted plant logs beside the first one's file.
                    let name = match generation {
                        0 => super::RUN_MCAP.to_string(),
                        g => format!("plant-{g}.mcap"),
                    };
                    c.runlog.mcap = Some(self.dir.file(&name));
                }
                if generation > 0 {
                    // One live server: the first plant's port is taken.
                    c.runlog.live = None;
                }
                write_json(&path, &c)?;
            }
            Role::Controller => {
                let mut c = self.cfg.controller.clone();
                c.robot = self.cfg.robot.clone();
                c.model = self.model.clone();
                c.prefix = self.prefix.clone();
                c.log = log;
                c.stats = stats;
                c.cpu = loop_cpu;
                c.realtime = self.cfg.realtime;
                c.supervised = true;
                c.duration_s = None;
                if let Some(socket) = &self.chip_socket {
                    c.mcu = Some(crate::ipc::controller::McuOptions {
                        socket: Some(socket.clone()),
                        image: None,
                        garbage_every_ms: self.cfg.mcu.as_ref().and_then(|m| m.garbage_every_ms),
                    });
                }
                write_json(&path, &c)?;
            }
            Role::Planner => {
                let mut c = self.cfg.planner.clone();
                c.robot = self.cfg.robot.clone();
                c.model = Some(self.model.clone());
                c.prefix = self.prefix.clone();
                c.log = log;
                c.cpu = planner_cpu;
                c.realtime = self.cfg.realtime;
                c.supervised = true;
                c.duration_s = None;
                if generation > 0 {
                    // A restarted planner holds briefly where the robot is
                    // going; the robot is not at rest then.
                    c.settle_s = 0.5;
                    c.start_from_rest = false;
                }
                write_json(&path, &c)?;
            }
        }
        Ok(path)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn publish_replaces_the_previous_run_and_discard_leaves_it_alone() {
        let tmp = tempfile::tempdir().unwrap();
        let out = tmp.path().join("out");
        std::fs::create_dir_all(&out).unwrap();
        std::fs::write(out.join("report.json"), "old").unwrap();
        std::fs::write(out.join("plant-1.csv"), "old generation").unwrap();
        std::fs::write(out.join("notes.txt"), "the user's").unwrap();

        let dir = RunDir::create(&out).unwrap();
        std::fs::write(dir.file("report.json"), "new").unwrap();
        std::fs::write(dir.file("pids"), "plant 0 1").unwrap();
        dir.discard();
        assert_eq!(
            std::fs::read_to_string(out.join("report.json")).unwrap(),
            "old"
        );
        assert!(out.join("plant-1.csv").exists());
        assert!(!out.join(RUN_DIR).exists());

        let dir = RunDir::create(&out).unwrap();
        std::fs::write(dir.file("report.json"), "new").unwrap();
        std::fs::write(dir.file("plant-0.csv"), "new").unwrap();
        std::fs::write(dir.file("pids"), "plant 0 1").unwrap();
        dir.publish().unwrap();
        assert_eq!(
            std::fs::read_to_string(out.join("report.json")).unwrap(),
            "new"
        );
        assert_eq!(
            std::fs::read_to_string(out.join("plant-0.csv")).unwrap(),
            "new"
        );
        assert!(!out.join("plant-1.csv").exists(), "a stale log survived");
        assert!(!out.join("pids").exists());
        assert_eq!(
            std::fs::read_to_string(out.join("notes.txt")).unwrap(),
            "the user's"
        );
        assert!(!out.join(RUN_DIR).exists());
    }

    #[test]
    fn a_second_run_on_a_locked_directory_fails_at_once_and_touches_nothing() {
        let tmp = tempfile::tempdir().unwrap();
        let out = tmp.path().join("out");
        let first = RunDir::create(&out).unwrap();
        std::fs::write(first.file("report.json"), "first").unwrap();
        let err = RunDir::create(&out).err().expect("the directory is locked");
        let msg = err.to_string();
        assert!(msg.contains("is in use by another tendril run"), "{msg}");
        assert!(
            msg.contains(&format!("pid {}", std::process::id())),
            "{msg}"
        );
        assert_eq!(
            std::fs::read_to_string(first.file("report.json")).unwrap(),
            "first",
            "the second run removed the first one's work directory"
        );
        first.publish().unwrap();
        let again = RunDir::create(&out).expect("released when the first run ended");
        again.discard();
    }

    /// `dir/run.mcap` as a full device: a node like /dev/full (1, 7) where
    /// this process may make one that opens, else a link to /dev/full
    /// (written through all the same).
    #[cfg(target_os = "linux")]
    fn full_device(dir: &Path) -> PathBuf {
        use std::os::unix::ffi::OsStrExt;
        let path = dir.join(super::super::RUN_MCAP);
        let c = std::ffi::CString::new(path.as_os_str().as_bytes()).unwrap();
        // SAFETY: a valid NUL-terminated path; makedev(1, 7) is /dev/full's.
        let rc = unsafe { libc::mknod(c.as_ptr(), libc::S_IFCHR | 0o600, libc::makedev(1, 7)) };
        if rc != 0 || std::fs::OpenOptions::new().write(true).open(&path).is_err() {
            let _ = std::fs::remove_file(&path);
            std::os::unix::fs::symlink("/dev/full", &path).unwrap();
        }
        path
    }

    #[cfg(target_os = "linux")]
    #[test]
    fn a_publish_that_fails_on_a_full_device_touches_no_regular_output() {
        let tmp = tempfile::tempdir().unwrap();
        let out = tmp.path().join("out");
        std::fs::create_dir(&out).unwrap();
        let full = full_device(&out);
        std::fs::write(out.join("report.json"), "old").unwrap();
        std::fs::write(out.join("plant-1.csv"), "old generation").unwrap();
        let dir = RunDir::create(&out).unwrap();
        std::fs::write(dir.file("report.json"), "new").unwrap();
        std::fs::write(dir.file("sim.png"), "new").unwrap();
        std::fs::write(dir.file(super::super::RUN_MCAP), vec![7u8; 100_000]).unwrap();
        let err = dir.publish().expect_err("a full device fails");
        let msg = err.to_string();
        assert!(msg.contains("No space left on device"), "{msg}");
        assert_eq!(msg.matches("No space left").count(), 1, "{msg}");
        assert_eq!(
            std::fs::read_to_string(out.join("report.json")).unwrap(),
            "old"
        );
        assert!(
            out.join("plant-1.csv").exists(),
            "the old run was half removed"
        );
        assert!(!out.join("sim.png").exists(), "half published");
        assert!(!out.join(RUN_DIR).exists(), "the work directory was left");
        use std::os::unix::fs::FileTypeExt;
        assert!(std::fs::symlink_metadata(&full)
            .unwrap()
            .file_type()
            .is_char_device());
    }

    #[cfg(unix)]
    #[test]
    fn a_fifo_output_without_a_reader_is_refused_when_the_run_starts() {
        let tmp = tempfile::tempdir().unwrap();
        let out = tmp.path().join("out");
        std::fs::create_dir(&out).unwrap();
        let fifo = out.join(super::super::RUN_MCAP);
        use std::os::unix::ffi::OsStrExt;
        let c = std::ffi::CString::new(fifo.as_os_str().as_bytes()).unwrap();
        // SAFETY: a valid NUL-terminated path.
        assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o600) }, 0);
        let err = RunDir::create(&out).err().expect("no reader: refused");
        assert!(err.to_string().contains("no reader"), "{err}");
        assert!(!out.join(RUN_DIR).exists());
        // With a reader it is written through when the run is published.
        let reader = {
            let fifo = fifo.clone();
            std::thread::spawn(move || std::fs::read(fifo).unwrap())
        };
        let dir = RunDir::create(&out).unwrap();
        std::fs::write(dir.file(super::super::RUN_MCAP), b"log").unwrap();
        dir.publish().unwrap();
        assert_eq!(reader.join().unwrap(), b"log");
    }

    #[test]
    fn a_run_that_publishes_nothing_removes_the_directory_it_created() {
        let tmp = tempfile::tempdir().unwrap();
        let out = tmp.path().join("new");
        RunDir::create(&out).unwrap().discard();
        assert!(!out.exists(), "a directory holding only the lock was left");
        let kept = tmp.path().join("kept");
        std::fs::create_dir(&kept).unwrap();
        RunDir::create(&kept).unwrap().discard();
        assert!(kept.exists(), "the user's directory was removed");
    }
}

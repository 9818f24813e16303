//! The skeleton's rules on a toy task over real iceoryx2 services.

use std::sync::atomic::{AtomicUsize, Ordering};

use super::*;
use crate::ipc::clock::now_ns;

/// A task that steps every millisecond, hears a peer only when told, and
/// can fail a step or its finish.
struct Toy {
    start: u64,
    steps: u64,
    heard: bool,
    fail_at_step: Option<u64>,
    fail_finish: bool,
    finished_with: std::sync::Arc<std::sync::Mutex<Option<bool>>>,
}

impl Task for Toy {
    type Stats = u64;
    fn log_header(&self) -> String {
        "t_ns,step".into()
    }
    fn start_ns(&self) -> u64 {
        self.start
    }
    fn step(&mut self, log: &mut CsvLog) -> Result<Stepped, IpcError> {
        std::thread::sleep(std::time::Duration::from_millis(1));
        self.steps += 1;
        if self.fail_at_step == Some(self.steps) {
            return Err(IpcError::Other("the toy's step failed".into()));
        }
        let t_ns = now_ns();
        log.row(&[t_ns as f64, self.steps as f64])?;
        Ok(Stepped {
            t_ns,
            heard: self.heard,
        })
    }
    fn silence(&self) -> &'static str {
        "no word"
    }
    fn finish(self, outcome: &Result<(), IpcError>) -> Result<u64, IpcError> {
        *self.finished_with.lock().unwrap() = Some(outcome.is_ok());
        if self.fail_finish {
            return Err(IpcError::Other("the toy's finish failed".into()));
        }
        Ok(self.steps)
    }
}

struct Case {
    dir: tempfile::TempDir,
    prefix: String,
    log: std::path::PathBuf,
    stats: std::path::PathBuf,
    finished_with: std::sync::Arc<std::sync::Mutex<Option<bool>>>,
}

static CASES: AtomicUsize = AtomicUsize::new(0);

impl Case {
    fn new() -> Case {
        let dir = tempfile::tempdir().unwrap();
        Case {
            log: dir.path().join("log.csv"),
            stats: dir.path().join("stats.json"),
            dir,
            prefix: format!(
                "tendril-test-process-{}-{}",
                std::process::id(),
                CASES.fetch_add(1, Ordering::SeqCst)
            ),
            finished_with: Default::default(),
        }
    }

    fn process(&self) -> Process<'_> {
        Process {
            name: "toy",
            prefix: &self.prefix,
            supervised: false,
            duration_s: None,
            peer_timeout_s: None,
            peer_start_grace_s: None,
            log: Some(&self.log),
            stats: Some(&self.stats),
            scheduling: None,
        }
    }

    fn toy(&self, heard: bool) -> Toy {
        Toy {
            start: now_ns(),
            steps: 0,
            heard,
            fail_at_step: None,
            fail_finish: false,
            finished_with: self.finished_with.clone(),
        }
    }

    fn log_rows(&self) -> usize {
        let (header, rows) = crate::ipc::stats::read_log(&self.log).unwrap();
        assert_eq!(header, ["t_ns", "step"]);
        rows.len()
    }

    fn stats(&self) -> Option<u64> {
        std::fs::read(&self.stats)
            .ok()
            .map(|b| serde_json::from_slice(&b).unwrap())
    }
}

/// The duration ends the run cleanly: the stats come back and are written,
/// the log holds every step's row.
#[test]
fn a_run_ends_at_its_duration_with_its_log_and_stats_written() {
    let case = Case::new();
    let process = Process {
        duration_s: Some(0.1),
        peer_timeout_s: Some(0.05),
        ..case.process()
    };
    let toy = case.toy(true);
    let steps = run(&process, || Ok(()), |(), _| Ok(toy)).unwrap();
    // That the loop ran and counted, not its cadence (the real-time tests
    // measure that): the unit tests run beside CPU-bound ones (the
    // calibration's 20-repetition coverage takes both cores for 3 s).
    assert!(steps >= 3, "{steps} steps in 0.1 s of 1 ms steps");
    assert_eq!(case.stats(), Some(steps));
    assert_eq!(case.log_rows() as u64, steps);
    assert_eq!(*case.finished_with.lock().unwrap(), Some(true));
}

/// Silent peers end the run with `PeersLost`, named after the process and
/// what it missed; the task is still finished and its stats written.
#[test]
fn silent_peers_end_the_run_as_lost_and_the_task_is_still_finished() {
    let case = Case::new();
    let process = Process {
        peer_timeout_s: Some(0.05),
        peer_start_grace_s: Some(0.05),
        ..case.process()
    };
    let toy = case.toy(false);
    let t0 = std::time::Instant::now();
    let err = run(&process, || Ok(()), |(), _| Ok(toy)).unwrap_err();
    assert!(
        matches!(&err, IpcError::PeersLost(why) if why.starts_with("toy: no word for")),
        "{err}"
    );
    assert!(t0.elapsed().as_secs_f64() < 2.0);
    assert_eq!(*case.finished_with.lock().unwrap(), Some(false));
    // The task stepped before its peers were lost, and its stats and log
    // were written. Not how often: the loss is told by the wall clock, and
    // a unit test beside CPU-bound ones may get the CPU only a few times
    // in the 0.1 s (CI once saw fewer than three steps).
    let steps = case.stats().expect("the stats were written");
    assert!(steps >= 1);
    assert_eq!(case.log_rows() as u64, steps);
}

/// A STOP on the loop's control service (what `tendril sim` sends) ends
/// the run cleanly.
#[test]
fn a_stop_on_the_control_service_ends_the_run() {
    let case = Case::new();
    let process = case.process();
    let prefix = case.prefix.clone();
    let toy = case.toy(true);
    let stopper = std::thread::spawn(move || {
        let node = transport::node("tendril-test-stopper").unwrap();
        let services = Services::open_or_create(&node, &prefix).unwrap();
        let control = transport::publisher(&services.control).unwrap();
        std::thread::sleep(std::time::Duration::from_millis(150));
        crate::ipc::send_stop(&control).unwrap();
        // Keep the publisher until the run has seen it.
        std::thread::sleep(std::time::Duration::from_millis(300));
    });
    let t0 = std::time::Instant::now();
    let steps = run(&process, || Ok(()), |(), _| Ok(toy)).unwrap();
    stopper.join().unwrap();
    assert!(steps > 50, "{steps}");
    assert!(t0.elapsed().as_secs_f64() < 5.0);
    assert_eq!(case.stats(), Some(steps));
}

/// A step's error ends the run; a failed finish after it is added to the
/// first error's message, not lost, and nothing half-written is left as
/// the stats.
#[test]
fn a_failing_step_and_a_failing_finish_are_both_reported() {
    let case = Case::new();
    let process = case.process();
    let toy = Toy {
        fail_at_step: Some(5),
        fail_finish: true,
        ..case.toy(true)
    };
    let err = run(&process, || Ok(()), |(), _| Ok(toy)).unwrap_err();
    let text = err.to_string();
    assert!(
        text.contains("the toy's step failed") && text.contains("the toy's finish failed"),
        "{text}"
    );
    assert_eq!(case.stats(), None);
    assert_eq!(case.log_rows(), 4);
}

/// A load that fails stops before any shared memory is touched: `open`
/// never runs.
#[test]
fn a_failed_load_never_opens_the_task() {
    let case = Case::new();
    let err = run(
        &case.process(),
        || -> Result<(), IpcError> { Err(IpcError::Config("bad robot".into())) },
        |(), _| -> Result<Toy, IpcError> { panic!("opened after a failed load") },
    )
    .unwrap_err();
    assert_eq!(err.to_string(), "bad robot");
    assert!(!case.log.exists() && case.dir.path().exists());
}

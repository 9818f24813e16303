//! An interrupted `tendril run` leaves exactly the previous run's outputs
//! (`docs/design.md` §7, issue 31): after a complete run into a directory, a
//! second run into it stopped by SIGINT, SIGTERM or SIGHUP — early, while
//! generating its dataset, while training — must leave every file
//! byte-identical, no temporary or staging directory anywhere, exit 130 and
//! say so truthfully. A small robot, a few hundred samples, no parity or
//! closed-loop stage: the stages that write are all still there.

use std::collections::BTreeMap;
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use tendril_tests::{robot, tendril_bin};

/// Every entry under `dir`: relative path → file bytes, link target or `dir`.
fn snapshot(dir: &Path) -> BTreeMap<PathBuf, Vec<u8>> {
    let mut all = BTreeMap::new();
    let mut todo = vec![dir.to_path_buf()];
    while let Some(d) = todo.pop() {
        for entry in std::fs::read_dir(&d).unwrap() {
            let path = entry.unwrap().path();
            let rel = path.strip_prefix(dir).unwrap().to_path_buf();
            let meta = std::fs::symlink_metadata(&path).unwrap();
            let value = if meta.file_type().is_symlink() {
                let mut v = b"link:".to_vec();
                v.extend(std::fs::read_link(&path).unwrap().to_string_lossy().bytes());
                v
            } else if meta.is_dir() {
                todo.push(path.clone());
                b"dir".to_vec()
            } else {
                std::fs::read(&path).unwrap()
            };
            all.insert(rel, value);
        }
    }
    all
}

fn run_args(dir: &Path, samples: &str) -> Vec<String> {
    [
        "run",
        "--robot",
        robot("seed-1t.toml").to_str().unwrap(),
        "--out",
        dir.to_str().unwrap(),
        "--quick",
        "--samples",
        samples,
        "--no-parity",
        "--no-closed-loop",
    ]
    .iter()
    .map(|s| s.to_string())
    .collect()
}

/// When to send the signal: at once, or this long after stderr shows a
/// line with this text.
enum When {
    Early,
    After(&'static str, u64),
}

/// Start a run of `samples` (another count than the complete run's, so it
/// generates its own dataset), signal it at `when`, and return (exit code,
/// stderr).
fn interrupted_run(dir: &Path, samples: &str, signal: i32, when: When) -> (Option<i32>, String) {
    let mut child = Command::new(tendril_bin())
        .args(run_args(dir, samples))
        .env("RUST_LOG", "info")
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn tendril run");
    let pid = child.id() as i32;
    let stderr = child.stderr.take().unwrap();
    let (tx, rx) = std::sync::mpsc::channel::<String>();
    let reader = std::thread::spawn(move || {
        for line in BufReader::new(stderr).lines().map_while(Result::ok) {
            let _ = tx.send(line);
        }
    });
    let mut log = String::new();
    let deadline = Instant::now() + Duration::from_secs(300);
    match when {
        When::Early => std::thread::sleep(Duration::from_millis(300)),
        When::After(marker, ms) => loop {
            let line = rx
                .recv_timeout(deadline.saturating_duration_since(Instant::now()))
                .unwrap_or_else(|_| panic!("no `{marker}` on stderr:\n{log}"));
            log.push_str(&line);
            log.push('\n');
            if line.contains(marker) {
                // Inside the stage, not at its first instruction.
                std::thread::sleep(Duration::from_millis(ms));
                break;
            }
        },
    }
    // SAFETY: signalling the child this test started.
    assert_eq!(unsafe { libc::kill(pid, signal) }, 0);
    let status = child.wait().unwrap();
    reader.join().unwrap();
    log.extend(rx.try_iter().map(|l| l + "\n"));
    (status.code(), log)
}

/// Every file but the lock's, whose content is the pid of the last run that
/// held it (for the "in use by pid" message), not an output.
fn assert_unchanged(dir: &Path, before: &BTreeMap<PathBuf, Vec<u8>>, what: &str, log: &str) {
    let mut after = snapshot(dir);
    let lock = Path::new(".tendril.lock");
    assert!(after.contains_key(lock));
    after.insert(lock.to_path_buf(), before[lock].clone());
    let added: Vec<_> = after.keys().filter(|k| !before.contains_key(*k)).collect();
    let removed: Vec<_> = before.keys().filter(|k| !after.contains_key(*k)).collect();
    let changed: Vec<_> = before
        .iter()
        .filter(|(k, v)| after.get(*k).is_some_and(|a| a != *v))
        .map(|(k, _)| k)
        .collect();
    assert!(
        added.is_empty() && removed.is_empty() && changed.is_empty(),
        "{what}: added {added:?}, removed {removed:?}, changed {changed:?}\n{log}"
    );
}

/// A first run interrupted early leaves no output directory at all.
#[test]
fn an_interrupted_first_run_leaves_no_directory() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("fresh");
    let (code, log) = interrupted_run(&dir, "1500", libc::SIGINT, When::Early);
    assert_eq!(code, Some(130), "{log}");
    assert!(!dir.exists(), "left {:?}\n{log}", snapshot(&dir).keys());
}

#[test]
fn an_interrupted_run_leaves_exactly_the_previous_outputs() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("out");
    let first = Command::new(tendril_bin())
        .args(run_args(&dir, "300"))
        .arg("-q")
        .output()
        .expect("run tendril run");
    assert!(
        first.status.success(),
        "first run failed:\n{}",
        String::from_utf8_lossy(&first.stderr)
    );
    let before = snapshot(&dir);
    for name in [
        "report.md",
        "data.csv",
        "model.tnet",
        "workspace.png",
        "compare",
    ] {
        assert!(
            before.contains_key(Path::new(name)),
            "the first run wrote no {name}: {:?}",
            before.keys()
        );
    }

    // The dataset stage of 200,000 samples takes tens of seconds; 3,000
    // samples reach training in about a second, and the comparison (the
    // longest stage, after the net, its report and the figures were
    // written) a little later.
    let cases = [
        ("1500", libc::SIGINT, When::Early, "SIGINT at once"),
        (
            "200000",
            libc::SIGTERM,
            When::After("dataset: generating", 400),
            "SIGTERM generating",
        ),
        (
            "3000",
            libc::SIGHUP,
            When::After("training the cascade", 50),
            "SIGHUP training",
        ),
        (
            "3000",
            libc::SIGINT,
            When::After("comparing with six", 400),
            "SIGINT comparing",
        ),
    ];
    for (samples, signal, when, what) in cases {
        let (code, log) = interrupted_run(&dir, samples, signal, when);
        // 130 for each signal (interrupt.rs); the message names it.
        assert_eq!(code, Some(130), "{what}: exit status\n{log}");
        let name = match signal {
            libc::SIGINT => "SIGINT",
            libc::SIGTERM => "SIGTERM",
            _ => "SIGHUP",
        };
        assert!(
            log.contains(&format!("interrupted by {name}"))
                && log.contains("no output was written or changed"),
            "{what}: no truthful message\n{log}"
        );
        assert_unchanged(&dir, &before, what, &log);
    }

    // A run that completes replaces the outputs and leaves no staging
    // directory behind; its report names the published files.
    let run = Command::new(tendril_bin())
        .args(run_args(&dir, "250"))
        .arg("-q")
        .output()
        .expect("run tendril run");
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let all = snapshot(&dir);
    let report = String::from_utf8(all[Path::new("report.md")].clone()).unwrap();
    assert!(report.contains("(250 requested)"), "{report}");
    assert!(!report.contains(".tendril-staging"), "{report}");
    let stray: Vec<_> = all
        .keys()
        .filter(|k| k.to_string_lossy().contains(".tendril-") && !k.ends_with(".tendril.lock"))
        .collect();
    assert!(stray.is_empty(), "left behind: {stray:?}");
}

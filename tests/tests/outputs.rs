//! Issue 31, "Outputs": an output path that is a device, a FIFO or a symlink
//! is written through (or its target written), never replaced; `-` is
//! stdout; SIGTERM and SIGHUP leave no temporary file; a run's output
//! directory is locked against a second run.

#![cfg(unix)]

use std::os::unix::fs::FileTypeExt;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use tendril_tests::{one_loop_at_a_time, robot, stderr, tendril_bin, workspace_root};

/// Three rows of tensions for `fk --input` on seed-4t.
fn rows_csv(dir: &Path) -> PathBuf {
    let path = dir.join("rows.csv");
    std::fs::write(&path, "t0,t1,t2,t3\n0,0,0,0\n1,0,0,0\n0,2,0,0\n").unwrap();
    path
}

fn fk_batch(input: &Path, output: &Path) -> Command {
    let mut cmd = Command::new(tendril_bin());
    cmd.arg("fk")
        .arg("--robot")
        .arg(robot("seed-4t.toml"))
        .arg("--input")
        .arg(input)
        .arg("--output")
        .arg(output)
        .current_dir(workspace_root());
    cmd
}

/// Files whose names say they are our temporaries.
fn temporaries(dir: &Path) -> Vec<String> {
    std::fs::read_dir(dir)
        .unwrap()
        .filter_map(|e| e.ok())
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with(".tendril-") && n.ends_with(".tmp"))
        .collect()
}

/// A full device to write to: a copy of /dev/full's node (1, 7) in `dir`
/// when this process may make one, so a regression replaces only the copy;
/// else /dev/full itself (a user who cannot make nodes cannot replace it).
fn full_device(dir: &Path) -> PathBuf {
    let copy = dir.join("full");
    let made = Command::new("mknod")
        .arg(&copy)
        .args(["c", "1", "7"])
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success());
    // A nodev mount makes the copy unopenable: then it proves nothing.
    if made && std::fs::OpenOptions::new().write(true).open(&copy).is_ok() {
        copy
    } else {
        PathBuf::from("/dev/full")
    }
}

#[test]
fn fk_into_a_full_device_fails_and_the_device_stays_a_device() {
    let dir = tempfile::tempdir().unwrap();
    let input = rows_csv(dir.path());
    let full = full_device(dir.path());
    let o = fk_batch(&input, &full).output().unwrap();
    assert!(
        !o.status.success(),
        "exit 0 writing into {}",
        full.display()
    );
    assert!(
        stderr(&o).contains("No space left on device"),
        "{}",
        stderr(&o)
    );
    let kind = std::fs::symlink_metadata(&full).unwrap().file_type();
    assert!(kind.is_char_device(), "{} was replaced", full.display());
    assert!(temporaries(dir.path()).is_empty());
}

#[test]
fn fk_into_a_fifo_writes_through_to_its_reader_and_the_fifo_stays() {
    let dir = tempfile::tempdir().unwrap();
    let input = rows_csv(dir.path());
    let fifo = dir.path().join("rows.fifo");
    assert!(Command::new("mkfifo")
        .arg(&fifo)
        .status()
        .unwrap()
        .success());
    // The reader is a process with a time limit: a writer that replaced
    // the FIFO instead of opening it would leave a reader thread blocked
    // for ever.
    let reader = Command::new("timeout")
        .arg("30")
        .arg("cat")
        .arg(&fifo)
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    let o = fk_batch(&input, &fifo).output().unwrap();
    let text = String::from_utf8(reader.wait_with_output().unwrap().stdout).unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(text.lines().count(), 4, "{text}");
    assert!(text.starts_with("t0,t1,t2,t3,px"), "{text}");
    let kind = std::fs::symlink_metadata(&fifo).unwrap().file_type();
    assert!(kind.is_fifo(), "the FIFO was replaced");
    assert!(temporaries(dir.path()).is_empty());
}

#[test]
fn fk_through_a_symlink_writes_its_target_and_the_link_stays() {
    let dir = tempfile::tempdir().unwrap();
    let input = rows_csv(dir.path());
    std::fs::create_dir(dir.path().join("results")).unwrap();
    let target = dir.path().join("results").join("poses.csv");
    std::fs::write(&target, "old").unwrap();
    let link = dir.path().join("poses.csv");
    std::os::unix::fs::symlink("results/poses.csv", &link).unwrap();
    let o = fk_batch(&input, &link).output().unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    let kind = std::fs::symlink_metadata(&link).unwrap().file_type();
    assert!(kind.is_symlink(), "the link was replaced by a file");
    let text = std::fs::read_to_string(&target).unwrap();
    assert_eq!(text.lines().count(), 4, "{text}");
}

#[test]
fn fk_output_dash_is_stdout_and_writes_no_file_named_dash() {
    let dir = tempfile::tempdir().unwrap();
    let input = rows_csv(dir.path());
    let o = fk_batch(&input, Path::new("-"))
        .current_dir(dir.path())
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    let text = String::from_utf8(o.stdout).unwrap();
    assert_eq!(text.lines().count(), 4, "{text}");
    assert!(text.starts_with("t0,t1,t2,t3,px"), "{text}");
    assert!(!dir.path().join("-").exists());
}

#[test]
fn a_directory_output_refuses_dash() {
    let dir = tempfile::tempdir().unwrap();
    let o = Command::new(tendril_bin())
        .args(["sim", "--out", "-"])
        .current_dir(dir.path())
        .output()
        .unwrap();
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("--out -: names a directory"),
        "{}",
        stderr(&o)
    );
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
}

/// Start a long `generate`, wait for its temporary file, send `sig`, and
/// check it exits non-zero leaving no temporary and no dataset.
fn generate_stopped_by(sig: &str) {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("data.csv");
    let mut child: Child = Command::new(tendril_bin())
        .args(["generate", "--quiet", "--samples", "500000", "--out"])
        .arg(&out)
        .arg("--robot")
        .arg(robot("seed-4t.toml"))
        .current_dir(workspace_root())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let start = Instant::now();
    while temporaries(dir.path()).is_empty() {
        assert!(
            start.elapsed() < Duration::from_secs(30),
            "no temporary file appeared"
        );
        if let Some(status) = child.try_wait().unwrap() {
            panic!("generate ended before the signal: {status}");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    // Let it write some rows, so the temporary is a real partial file.
    std::thread::sleep(Duration::from_millis(300));
    let sent = Command::new("kill")
        .arg(format!("-{sig}"))
        .arg(child.id().to_string())
        .status()
        .unwrap();
    assert!(sent.success());
    let deadline = Instant::now() + Duration::from_secs(30);
    let status = loop {
        if let Some(s) = child.try_wait().unwrap() {
            break s;
        }
        if Instant::now() > deadline {
            let _ = child.kill();
            panic!("generate did not stop within 30 s of SIG{sig}");
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    let o = child.wait_with_output().unwrap();
    assert!(!status.success(), "exit 0 after SIG{sig}");
    // 130 for each signal (scripts test one number); the message names it.
    assert_eq!(status.code(), Some(130), "{status}: {}", stderr(&o));
    assert!(
        stderr(&o).contains(&format!("interrupted by SIG{sig}")),
        "the signal is not named: {}",
        stderr(&o)
    );
    assert_eq!(temporaries(dir.path()), Vec::<String>::new());
    assert!(!out.exists(), "a dataset was written after SIG{sig}");
}

#[test]
fn sigterm_during_generate_leaves_no_temporary_and_exits_non_zero() {
    generate_stopped_by("TERM");
}

#[test]
fn sighup_during_generate_leaves_no_temporary_and_exits_non_zero() {
    generate_stopped_by("HUP");
}

#[test]
fn a_second_sim_on_the_same_directory_fails_at_once_and_the_first_completes() {
    let _one = one_loop_at_a_time();
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("sim");
    let sim = |extra: &[&str]| {
        let mut cmd = Command::new(tendril_bin());
        cmd.arg("sim")
            .arg("--robot")
            .arg(robot("seed-4t.toml"))
            .arg("--out")
            .arg(&out)
            .args(["--settle", "0.5", "--duration", "1.5"])
            .args(extra)
            // A fresh directory: the built-in net, not some out/model.tnet.
            .current_dir(dir.path());
        cmd
    };
    let first = sim(&[])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let lock = out.join(".tendril.lock");
    let start = Instant::now();
    while std::fs::read_to_string(&lock)
        .map(|s| s.trim().is_empty())
        .unwrap_or(true)
    {
        assert!(start.elapsed() < Duration::from_secs(30), "no lock taken");
        std::thread::sleep(Duration::from_millis(10));
    }
    let t = Instant::now();
    let second = sim(&[]).output().unwrap();
    assert!(!second.status.success(), "the second sim succeeded");
    assert!(
        t.elapsed() < Duration::from_secs(5),
        "the second sim did not fail fast"
    );
    let msg = stderr(&second);
    assert!(
        msg.contains(&format!(
            "{} is in use by another tendril run (pid {})",
            out.display(),
            first.id()
        )),
        "{msg}"
    );
    let first = first.wait_with_output().unwrap();
    assert!(first.status.success(), "{}", stderr(&first));
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap();
    assert_eq!(report["verdict"]["clean"], true, "{}", report["verdict"]);
    for log in ["controller.csv", "planner-0.csv", "plant-0.csv"] {
        assert!(out.join(log).is_file(), "{log} missing");
    }
}

/// A node like /dev/null (1, 3) in `dir` when this process may make one
/// that opens, so a regression replaces only the copy; else /dev/null
/// itself (a user who cannot make nodes cannot replace it).
fn null_device(dir: &Path) -> PathBuf {
    let copy = dir.join("null");
    let made = Command::new("mknod")
        .arg(&copy)
        .args(["c", "1", "3"])
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success());
    if made && std::fs::OpenOptions::new().write(true).open(&copy).is_ok() {
        copy
    } else {
        PathBuf::from("/dev/null")
    }
}

/// Any of our temporaries in `dir`, whatever their extension (a figure's
/// is `.tendril-*.tmp.png`).
fn any_temporaries(dir: &Path) -> Vec<String> {
    std::fs::read_dir(dir)
        .unwrap()
        .filter_map(|e| e.ok())
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with(".tendril-") || n.contains(".tmp."))
        .collect()
}

/// A 30-row dataset in `dir` for `workspace --data`.
fn small_dataset(dir: &Path) -> PathBuf {
    let data = dir.join("data.csv");
    let o = Command::new(tendril_bin())
        .args(["generate", "--quiet", "--samples", "30", "--out"])
        .arg(&data)
        .arg("--robot")
        .arg(robot("seed-4t.toml"))
        .current_dir(workspace_root())
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    data
}

fn workspace_figure(data: &Path, out: &Path) -> Command {
    let mut cmd = Command::new(tendril_bin());
    cmd.arg("workspace")
        .arg("--robot")
        .arg(robot("seed-4t.toml"))
        .arg("--data")
        .arg(data)
        .arg("--out")
        .arg(out)
        .current_dir(workspace_root());
    cmd
}

const PNG_MAGIC: &[u8] = b"\x89PNG";

#[test]
fn workspace_through_a_symlink_draws_its_target_and_the_link_stays() {
    let dir = tempfile::tempdir().unwrap();
    let data = small_dataset(dir.path());
    std::fs::create_dir(dir.path().join("figures")).unwrap();
    let target = dir.path().join("figures").join("workspace.png");
    std::fs::write(&target, "old").unwrap();
    let link = dir.path().join("workspace.png");
    std::os::unix::fs::symlink("figures/workspace.png", &link).unwrap();
    let o = workspace_figure(&data, &link).output().unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    let kind = std::fs::symlink_metadata(&link).unwrap().file_type();
    assert!(kind.is_symlink(), "the link was replaced by a file");
    assert!(std::fs::read(&target).unwrap().starts_with(PNG_MAGIC));
    assert_eq!(any_temporaries(dir.path()), Vec::<String>::new());
    assert_eq!(
        any_temporaries(&dir.path().join("figures")),
        Vec::<String>::new()
    );
}

#[test]
fn workspace_into_a_device_or_a_fifo_writes_through_and_the_node_stays() {
    let dir = tempfile::tempdir().unwrap();
    let data = small_dataset(dir.path());
    let null = null_device(dir.path());
    let o = workspace_figure(&data, &null).output().unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    let kind = std::fs::symlink_metadata(&null).unwrap().file_type();
    assert!(kind.is_char_device(), "{} was replaced", null.display());

    let fifo = dir.path().join("workspace.png");
    assert!(Command::new("mkfifo")
        .arg(&fifo)
        .status()
        .unwrap()
        .success());
    // A reader with a time limit: a FIFO replaced by a file would leave it
    // waiting for a writer for ever. Its output is drained at once (a PNG
    // is larger than a pipe's buffer).
    let reader = Command::new("timeout")
        .arg("30")
        .arg("cat")
        .arg(&fifo)
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    let reader = std::thread::spawn(move || reader.wait_with_output().unwrap().stdout);
    let o = workspace_figure(&data, &fifo).output().unwrap();
    let png = reader.join().unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    let kind = std::fs::symlink_metadata(&fifo).unwrap().file_type();
    assert!(kind.is_fifo(), "the FIFO was replaced");
    assert!(png.starts_with(PNG_MAGIC), "the reader got no PNG");
    assert_eq!(any_temporaries(dir.path()), Vec::<String>::new());
}

#[test]
fn generate_into_a_device_is_refused_and_no_sidecar_is_made_beside_it() {
    let dir = tempfile::tempdir().unwrap();
    let null = null_device(dir.path());
    let o = Command::new(tendril_bin())
        .args(["generate", "--quiet", "--samples", "30", "--out"])
        .arg(&null)
        .arg("--robot")
        .arg(robot("seed-4t.toml"))
        .current_dir(workspace_root())
        .output()
        .unwrap();
    assert!(
        !o.status.success(),
        "exit 0 generating into {}",
        null.display()
    );
    assert!(
        stderr(&o).contains("is a device, FIFO or descriptor, not a regular file"),
        "{}",
        stderr(&o)
    );
    assert!(
        !null.with_extension("json").exists(),
        "a sidecar was written beside the device"
    );
    let kind = std::fs::symlink_metadata(&null).unwrap().file_type();
    assert!(kind.is_char_device(), "{} was replaced", null.display());
}

/// `tendril plant` alone, its run log at `mcap`: with no controller it
/// stops after a second without commands (exit 1, "peers lost") and then
/// publishes its log.
fn plant_with_log(mcap: &Path, prefix: &str) -> std::process::Output {
    Command::new(tendril_bin())
        .args(["plant", "--peer-timeout", "1", "--prefix", prefix, "--mcap"])
        .arg(mcap)
        .current_dir(workspace_root())
        .output()
        .unwrap()
}

#[test]
fn a_run_log_into_a_full_device_fails_and_the_device_stays_a_device() {
    let dir = tempfile::tempdir().unwrap();
    let full = full_device(dir.path());
    let o = plant_with_log(&full, &format!("outlog{}a", std::process::id()));
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("No space left on device"),
        "the log's failure is not reported: {}",
        stderr(&o)
    );
    let kind = std::fs::symlink_metadata(&full).unwrap().file_type();
    assert!(kind.is_char_device(), "{} was replaced", full.display());
}

#[test]
fn a_run_log_through_a_symlink_writes_its_target_and_the_link_stays() {
    let dir = tempfile::tempdir().unwrap();
    let link = dir.path().join("run.mcap");
    std::os::unix::fs::symlink("real.mcap", &link).unwrap();
    let o = plant_with_log(&link, &format!("outlog{}b", std::process::id()));
    assert!(stderr(&o).contains("peers lost"), "{}", stderr(&o));
    let meta = std::fs::symlink_metadata(&link).unwrap();
    assert!(meta.file_type().is_symlink(), "the link was replaced");
    let bytes = std::fs::read(dir.path().join("real.mcap")).unwrap();
    assert!(bytes.starts_with(b"\x89MCAP0\r\n"), "the target is no MCAP");
    let names: Vec<String> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert_eq!(names.len(), 2, "left beside them: {names:?}");
}

#[test]
fn a_run_log_into_a_directory_or_a_fifo_without_reader_is_refused_before_the_run() {
    let dir = tempfile::tempdir().unwrap();
    let sub = dir.path().join("logs");
    std::fs::create_dir(&sub).unwrap();
    let o = plant_with_log(&sub, &format!("outlog{}c", std::process::id()));
    assert!(!o.status.success());
    assert!(stderr(&o).contains("is a directory"), "{}", stderr(&o));
    assert!(!stderr(&o).contains("peers lost"), "the run went on");
    assert!(!dir.path().join("logs.partial").exists());

    let fifo = dir.path().join("run.fifo");
    assert!(Command::new("mkfifo")
        .arg(&fifo)
        .status()
        .unwrap()
        .success());
    let started = Instant::now();
    let o = plant_with_log(&fifo, &format!("outlog{}d", std::process::id()));
    assert!(!o.status.success());
    assert!(stderr(&o).contains("no reader"), "{}", stderr(&o));
    // Refused after the wait for a reader, not after a hung open.
    assert!(started.elapsed() < Duration::from_secs(20));
    let kind = std::fs::symlink_metadata(&fifo).unwrap().file_type();
    assert!(kind.is_fifo(), "the FIFO was replaced");
}

#[test]
fn dynamics_with_its_run_log_on_a_full_device_exits_non_zero_and_keeps_the_device() {
    let dir = tempfile::tempdir().unwrap();
    let full = full_device(dir.path());
    let out = dir.path().join("dyn");
    std::fs::create_dir(&out).unwrap();
    std::os::unix::fs::symlink(&full, out.join("run.mcap")).unwrap();
    let o = Command::new(tendril_bin())
        .args([
            "dynamics",
            "--tensions-step",
            "0,0,0,0:2,0,0,0@0.05",
            "--duration",
            "0.1",
            "--out",
        ])
        .arg(&out)
        .current_dir(workspace_root())
        .output()
        .unwrap();
    assert!(!o.status.success(), "exit 0 with its log lost");
    assert!(
        stderr(&o).contains("No space left on device"),
        "{}",
        stderr(&o)
    );
    let kind = std::fs::symlink_metadata(&full).unwrap().file_type();
    assert!(kind.is_char_device(), "{} was replaced", full.display());
    assert!(std::fs::symlink_metadata(out.join("run.mcap"))
        .unwrap()
        .file_type()
        .is_symlink());
}

#[test]
fn fk_reads_its_rows_from_stdin_for_input_dash() {
    use std::io::Write;
    let mut child = Command::new(tendril_bin())
        .args(["fk", "--robot"])
        .arg(robot("seed-4t.toml"))
        .args(["--input", "-", "--output", "-"])
        .current_dir(workspace_root())
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    child
        .stdin
        .take()
        .unwrap()
        .write_all(b"t0,t1,t2,t3\n0,0,0,0\n1,0,0,0\n")
        .unwrap();
    let o = child.wait_with_output().unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    let text = String::from_utf8(o.stdout).unwrap();
    assert_eq!(text.lines().count(), 3, "{text}");
    assert!(text.starts_with("t0,t1,t2,t3,px"), "{text}");
}

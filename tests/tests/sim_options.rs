//! The numeric options of `sim`, `controller`, `plant` and `planner` as a
//! careless user types them (issue 31): a NaN, an infinity or a value out of
//! range is refused at once with the flag's name — not passed to a child as
//! `null` in an internal JSON file — and `--peer-timeout` means what it says.

use std::process::Command;
use std::time::{Duration, Instant};

use tendril_tests::{robot, tendril_bin, workspace_root};

#[test]
fn bad_numeric_sim_options_are_refused_by_flag_name_before_anything_starts() {
    let cases: &[(&[&str], &str)] = &[
        (&["--ki", "NaN"], "--ki NaN"),
        (&["--ki=-5"], "--ki -5"),
        (&["--rate", "inf"], "--rate inf"),
        (&["--rate", "0"], "--rate 0"),
        (&["--slew", "NaN"], "--slew NaN"),
        (&["--lead-ms", "NaN"], "--lead-ms NaN"),
        (&["--spin-us", "NaN"], "--spin-us NaN"),
        (&["--watchdog-periods", "NaN"], "--watchdog-periods NaN"),
        (
            &["--correction-limit-mm", "NaN"],
            "--correction-limit-mm NaN",
        ),
        (&["--correction-window-mm=-1"], "--correction-window-mm -1"),
        (&["--motor-tau-ms", "NaN"], "--motor-tau-ms NaN"),
        (&["--motor-tau-ms", "0"], "--motor-tau-ms 0"),
        (&["--compliance-tau-ms", "NaN"], "--compliance-tau-ms NaN"),
        (&["--noise-mm", "inf"], "--noise-mm inf"),
        (&["--statics-steps", "0"], "--statics-steps 0"),
        (&["--planner-rate", "0"], "--planner-rate 0"),
        (&["--radius-mm", "NaN"], "--radius-mm NaN"),
        (&["--freq", "NaN"], "--freq NaN"),
        (&["--dwell", "NaN"], "--dwell NaN"),
        (&["--stuck", "1@NaN"], "--stuck time NaN"),
    ];
    let dir = tempfile::tempdir().unwrap();
    let mut wrong = Vec::new();
    for (args, expected) in cases {
        let out = dir.path().join("out");
        let start = Instant::now();
        let o = Command::new(tendril_bin())
            .arg("sim")
            .arg("--robot")
            .arg(robot("seed-4t.toml"))
            .args(["--model", "firmware/vectors/default.tnet"])
            .args(["--settle", "0.2", "--duration", "0.5"])
            .args(*args)
            .arg("--out")
            .arg(&out)
            .current_dir(workspace_root())
            .output()
            .expect("spawn tendril sim");
        let err = String::from_utf8_lossy(&o.stderr).into_owned();
        let took = start.elapsed();
        let ok = !o.status.success()
            && err.contains(expected)
            && !err.contains("config.json")
            && !out.join("report.json").exists()
            && !out.join(".sim-run").exists()
            && took < Duration::from_secs(5);
        if !ok {
            wrong.push(format!(
                "{args:?}: status {:?} in {took:?}, stderr: {}",
                o.status.code(),
                err.trim()
            ));
        }
    }
    assert!(
        wrong.is_empty(),
        "not refused by name:\n{}",
        wrong.join("\n")
    );
}

#[test]
fn the_processes_refuse_a_nan_by_flag_name_too() {
    for (role, args, expected) in [
        ("controller", &["--ki", "NaN"][..], "--ki NaN"),
        ("plant", &["--noise-mm", "NaN"][..], "--noise-mm NaN"),
        ("planner", &["--freq", "NaN"][..], "--freq NaN"),
        (
            "plant",
            &["--peer-timeout", "NaN"][..],
            "--peer-timeout NaN",
        ),
    ] {
        let o = Command::new(tendril_bin())
            .arg(role)
            .args(args)
            .current_dir(workspace_root())
            .output()
            .expect("spawn");
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(
            !o.status.success() && err.contains(expected),
            "{role} {args:?}: {err}"
        );
    }
}

/// `plant --peer-timeout 1` with no controller: it stops after about 1 s
/// (it used to wait the 10 s start grace regardless).
#[test]
fn an_explicit_peer_timeout_holds_from_the_start() {
    for (role, extra) in [
        ("plant", &[][..]),
        (
            "controller",
            &["--model", "firmware/vectors/default.tnet"][..],
        ),
    ] {
        let prefix = format!("t31peer{}{role}", std::process::id());
        let start = Instant::now();
        let o = Command::new(tendril_bin())
            .arg(role)
            .args(["--peer-timeout", "1", "--prefix", &prefix])
            .args(extra)
            .current_dir(workspace_root())
            .output()
            .expect("spawn");
        let took = start.elapsed();
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success(), "{role}: {err}");
        assert!(err.contains("peers lost"), "{role}: {err}");
        assert!(
            took >= Duration::from_millis(900) && took < Duration::from_secs(4),
            "{role} --peer-timeout 1 stopped after {took:?}: {err}"
        );
    }
}

/// `sim --duration 100000` would log ≈ 97 GB: refused at once with its cost
/// and the flag that raises the cap, nothing started or written (it used to
/// run, growing its logs by ≈ 2.5 GB an hour).
#[test]
fn an_absurd_duration_is_refused_with_its_cost_before_anything_starts() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let mut child = Command::new(tendril_bin())
        .arg("sim")
        .arg("--robot")
        .arg(robot("seed-4t.toml"))
        .args(["--model", "firmware/vectors/default.tnet"])
        .args(["--duration", "100000", "--out"])
        .arg(&out)
        .current_dir(workspace_root())
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("spawn tendril sim");
    let deadline = Instant::now() + Duration::from_secs(10);
    while child.try_wait().unwrap().is_none() && Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(50));
    }
    let running = child.try_wait().unwrap().is_none();
    if running {
        // SIGTERM: the sim stops its children and removes its work directory.
        let _ = Command::new("kill").arg(child.id().to_string()).status();
    }
    let o = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!running, "sim --duration 100000 started: {err}");
    assert!(!o.status.success(), "{err}");
    // The three CSV logs alone are ≈ 69 GB; the run log (run.mcap, on by
    // default) adds its scenes.
    let gb: f64 = err
        .split("≈ ")
        .nth(1)
        .and_then(|r| r.split(" GB").next())
        .and_then(|g| g.parse().ok())
        .unwrap_or_else(|| panic!("no size in: {err}"));
    assert!(
        (69.0..200.0).contains(&gb) && err.contains("--max-log-gb"),
        "{err}"
    );
    assert!(!out.join(".sim-run").exists() && !out.join("report.json").exists());
}

//! `tendril sim` as a hostile user meets it: killed, interrupted, started
//! without a model, given impossible durations, with a child that fails
//! or dies. Real processes over real iceoryx2 services, observed from
//! outside: exit codes, `/proc`, the files left behind.

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

use serde_json::Value;
use tendril_tests::{robot, stderr, tendril_bin, workspace_root};

/// The default exported net, relative to the workspace root.
const DEFAULT_NET: &str = "firmware/vectors/default.tnet";

/// Held by the tests that leave dead iceoryx2 nodes on purpose (SIGKILL)
/// and by the one that counts node entries, so they never overlap.
static NODE_ENTRIES: std::sync::Mutex<()> = std::sync::Mutex::new(());

/// One sim at a time, on the whole machine: each is three real-time
/// processes pinned like the others, and two at once starve each other's
/// planner (spurious watchdog holds, then a run that is rightly judged not
/// clean).
fn one_sim_at_a_time() -> tendril_tests::LoopGuard {
    tendril_tests::one_loop_at_a_time()
}

/// Short runs: these tests are about processes, not accuracy.
const SHORT: [&str; 4] = ["--settle", "0.5", "--duration", "1.5"];

fn sim_command(out: &Path, args: &[&str]) -> Command {
    let mut cmd = Command::new(tendril_bin());
    cmd.arg("sim")
        .arg("--robot")
        .arg(robot("seed-4t.toml"))
        .arg("--out")
        .arg(out)
        .args(args)
        .current_dir(workspace_root());
    cmd
}

fn run_sim(out: &Path, args: &[&str]) -> Output {
    sim_command(out, args).output().expect("spawn tendril sim")
}

fn report(out: &Path) -> Value {
    let text = std::fs::read_to_string(out.join("report.json")).expect("report.json");
    serde_json::from_str(&text).expect("report is JSON")
}

/// Whether `pid` is a live process (a zombie counts as gone: it runs nothing).
fn alive(pid: u32) -> bool {
    match std::fs::read_to_string(format!("/proc/{pid}/stat")) {
        Ok(stat) => {
            // The state follows the parenthesised command name.
            let state = stat
                .rsplit_once(") ")
                .and_then(|(_, rest)| rest.chars().next());
            !matches!(state, Some('Z') | Some('X') | None)
        }
        Err(_) => false,
    }
}

/// The children's pids the running sim lists in `OUT/.sim-run/pids`,
/// once all three have started and are alive.
fn wait_for_children(out: &Path, sim: &mut Child) -> Vec<u32> {
    let pids_file = out.join(".sim-run").join("pids");
    let deadline = Instant::now() + Duration::from_secs(60);
    loop {
        assert!(
            sim.try_wait().expect("poll sim").is_none(),
            "sim exited before its children were up"
        );
        if let Ok(text) = std::fs::read_to_string(&pids_file) {
            let pids: Vec<u32> = text
                .lines()
                .filter_map(|l| l.split_whitespace().nth(2)?.parse().ok())
                .collect();
            if pids.len() == 3 && pids.iter().all(|&p| alive(p)) {
                return pids;
            }
        }
        assert!(Instant::now() < deadline, "children never came up");
        std::thread::sleep(Duration::from_millis(50));
    }
}

fn signal(pid: u32, sig: &str) {
    let ok = Command::new("kill")
        .arg(format!("-{sig}"))
        .arg(pid.to_string())
        .status()
        .expect("kill")
        .success();
    assert!(ok, "kill -{sig} {pid} failed");
}

/// Wait up to `limit` for all `pids` to be gone; the ones still alive.
fn survivors(pids: &[u32], limit: Duration) -> Vec<u32> {
    let deadline = Instant::now() + limit;
    loop {
        let left: Vec<u32> = pids.iter().copied().filter(|&p| alive(p)).collect();
        if left.is_empty() || Instant::now() >= deadline {
            return left;
        }
        std::thread::sleep(Duration::from_millis(10));
    }
}

fn kill_sim_and_check_children(sig: &str) -> (Output, tempfile::TempDir, Vec<u32>) {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let mut sim = sim_command(
        &out,
        &[
            "--model",
            DEFAULT_NET,
            "--settle",
            "0.5",
            "--duration",
            "60",
        ],
    )
    .stdout(Stdio::piped())
    .stderr(Stdio::piped())
    .spawn()
    .expect("spawn tendril sim");
    let children = wait_for_children(&out, &mut sim);
    signal(sim.id(), sig);
    let left = survivors(&children, Duration::from_secs(1));
    // Clean up before asserting, so a failure does not leave them running.
    for &p in &left {
        signal(p, "KILL");
    }
    assert!(
        left.is_empty(),
        "children {left:?} of {children:?} still running 1 s after SIG{sig} to the sim"
    );
    let output = sim.wait_with_output().expect("wait sim");
    (output, dir, children)
}

#[test]
fn sigkill_of_the_sim_takes_its_children_down_within_a_second() {
    let _one = one_sim_at_a_time();
    let _entries = NODE_ENTRIES.lock().unwrap_or_else(|e| e.into_inner());
    let (output, _dir, _) = kill_sim_and_check_children("KILL");
    assert!(!output.status.success());
}

#[test]
fn sigterm_and_sigint_stop_the_children_exit_non_zero_and_keep_old_outputs() {
    let _one = one_sim_at_a_time();
    // SIGHUP too (issue 31: it used to kill the launcher where it stood,
    // exit 129, leaving its work directory and partial logs).
    for sig in ["TERM", "INT", "HUP"] {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("out");
        std::fs::create_dir_all(&out).unwrap();
        let old = b"{\"previous\": \"run\"}\n";
        std::fs::write(out.join("report.json"), old).unwrap();
        let mut sim = sim_command(
            &out,
            &[
                "--model",
                DEFAULT_NET,
                "--settle",
                "0.5",
                "--duration",
                "60",
            ],
        )
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn tendril sim");
        let children = wait_for_children(&out, &mut sim);
        let signalled = Instant::now();
        signal(sim.id(), sig);
        let left = survivors(&children, Duration::from_secs(1));
        for &p in &left {
            signal(p, "KILL");
        }
        assert!(left.is_empty(), "SIG{sig}: children {left:?} still running");
        let output = sim.wait_with_output().expect("wait sim");
        assert!(
            signalled.elapsed() < Duration::from_secs(5),
            "SIG{sig}: the sim took {:?} to stop",
            signalled.elapsed()
        );
        assert_eq!(
            output.status.code(),
            Some(130),
            "SIG{sig}: exit status {:?} (130 for an interrupt)",
            output.status
        );
        assert!(
            stderr(&output).contains(&format!("interrupted by SIG{sig}"))
                && stderr(&output).contains("this run's logs were discarded"),
            "SIG{sig}: {}",
            stderr(&output)
        );
        assert_eq!(
            std::fs::read(out.join("report.json")).unwrap(),
            old,
            "SIG{sig}: the previous report was touched"
        );
        assert!(
            !out.join("plant-0.csv").exists(),
            "SIG{sig}: partial logs published"
        );
        assert!(
            !out.join(".sim-run").exists(),
            "SIG{sig}: work directory left"
        );
    }
}

/// Node entries iceoryx2 keeps for this machine's processes.
fn iceoryx2_nodes() -> Vec<PathBuf> {
    match std::fs::read_dir("/tmp/iceoryx2/nodes") {
        Ok(dir) => dir.filter_map(|e| Some(e.ok()?.path())).collect(),
        Err(_) => Vec::new(),
    }
}

/// The process a node entry belongs to, while it runs: the entry's node id
/// (its directory, or the digits of its monitor files' names) names a
/// directory whose `iox2_node.details` says `process = PID`. None for an
/// entry whose process is gone (a leak) or that says no process.
fn live_owner(entry: &std::path::Path) -> Option<u32> {
    let name = entry.file_name()?.to_str()?;
    let id: String = name
        .trim_start_matches("iox2_")
        .chars()
        .take_while(|c| c.is_ascii_digit())
        .collect();
    let details =
        std::fs::read_to_string(entry.with_file_name(id).join("iox2_node.details")).ok()?;
    let pid: u32 = details.lines().find_map(|l| {
        l.trim()
            .strip_prefix("process")?
            .trim()
            .strip_prefix('=')?
            .trim()
            .parse()
            .ok()
    })?;
    std::path::Path::new(&format!("/proc/{pid}"))
        .exists()
        .then_some(pid)
}

#[test]
fn a_child_that_fails_at_start_fails_the_run_and_leaves_no_iceoryx2_nodes() {
    let _one = one_sim_at_a_time();
    let _entries = NODE_ENTRIES.lock().unwrap_or_else(|e| e.into_inner());
    let dir = tempfile::tempdir().unwrap();
    // A net `sim` lets through (another robot's, allowed) that the
    // controller cannot load (six outputs for four tendons): the child fails
    // after the launcher made its services. (A file that is no net at all is
    // refused by `sim` itself, before any child starts.)
    let bad = tendril_tests::workspace_root().join("firmware/vectors/tdcr-2seg.tnet");
    let before = iceoryx2_nodes();
    let out = dir.path().join("out");
    let o = run_sim(
        &out,
        &[
            "--model",
            bad.to_str().unwrap(),
            "--allow-robot-mismatch",
            "--duration",
            "2",
        ],
    );
    assert!(!o.status.success());
    let err = stderr(&o);
    assert!(
        err.contains("controller exited before the loop started"),
        "{err}"
    );
    // Other tests may run sims at the same time (the second real-time
    // stream of `scripts/test`, whose sims last up to a minute): only
    // entries that appeared during this run, are still there a little
    // later, and whose process is gone count.
    let new: Vec<PathBuf> = iceoryx2_nodes()
        .into_iter()
        .filter(|p| !before.contains(p))
        .collect();
    std::thread::sleep(Duration::from_secs(3));
    let left: Vec<&PathBuf> = new
        .iter()
        .filter(|p| p.exists() && live_owner(p).is_none())
        .collect();
    assert!(
        left.is_empty(),
        "iceoryx2 node entries left by no live process: {left:?}"
    );
    assert!(!out.join(".sim-run").exists(), "work directory left");
}

#[test]
fn a_child_killed_from_outside_fails_the_run_and_the_report_names_it() {
    let _one = one_sim_at_a_time();
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let mut sim = sim_command(
        &out,
        &[
            "--model",
            DEFAULT_NET,
            "--settle",
            "0.5",
            "--duration",
            "20",
        ],
    )
    .stdout(Stdio::piped())
    .stderr(Stdio::piped())
    .spawn()
    .expect("spawn tendril sim");
    let children = wait_for_children(&out, &mut sim);
    // Let the loop run (the planner logs its setpoints), then kill the
    // plant (listed first).
    let planner_log = out.join(".sim-run").join("planner-0.csv");
    let deadline = Instant::now() + Duration::from_secs(60);
    while std::fs::read_to_string(&planner_log).map_or(0, |t| t.lines().count()) < 100 {
        assert!(Instant::now() < deadline, "the loop never ran");
        std::thread::sleep(Duration::from_millis(50));
    }
    std::thread::sleep(Duration::from_secs(1));
    let plant = children[0];
    signal(plant, "INT");
    let started = Instant::now();
    let output = sim.wait_with_output().expect("wait sim");
    assert!(
        started.elapsed() < Duration::from_secs(10),
        "the sim ran on after the plant died"
    );
    assert!(!output.status.success(), "a dead plant gave exit status 0");
    let r = report(&out);
    assert_eq!(r["verdict"]["clean"], false);
    let plant_record = r["processes"]
        .as_array()
        .unwrap()
        .iter()
        .find(|p| p["pid"] == plant)
        .unwrap_or_else(|| panic!("plant {plant} not in {}", r["processes"]));
    assert_eq!(plant_record["role"], "plant");
    assert!(plant_record["ended_s"].as_f64().is_some());
    let problems = r["verdict"]["problems"].to_string();
    assert!(problems.contains("plant 0"), "{problems}");
    assert!(stderr(&output).contains("plant"), "{}", stderr(&output));
}

#[test]
fn impossible_durations_are_rejected_before_anything_starts() {
    let _one = one_sim_at_a_time();
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    for bad in ["inf", "NaN", "-1", "0"] {
        let t = Instant::now();
        let o = run_sim(&out, &["--model", DEFAULT_NET, "--duration", bad]);
        assert!(!o.status.success(), "--duration {bad} accepted");
        let err = stderr(&o);
        assert!(err.contains("--duration"), "--duration {bad}: {err}");
        assert_eq!(err.trim().lines().count(), 1, "--duration {bad}: {err}");
        assert!(
            t.elapsed() < Duration::from_secs(5),
            "--duration {bad} started a run"
        );
    }
    // Faults the run would never reach (it ends at 2 s settle + 3 s).
    for bad in [
        &["--inject-nan-at", "100"][..],
        &["--kill-plant-at", "50"],
        &["--kill-plant-at", "1", "--restart-plant-after", "100"],
        &["--stuck", "1@30"],
    ] {
        let mut args = vec!["--model", DEFAULT_NET, "--duration", "3"];
        args.extend(bad);
        let o = run_sim(&out, &args);
        assert!(!o.status.success(), "{bad:?} accepted");
        assert!(
            stderr(&o).contains("would never happen"),
            "{bad:?}: {}",
            stderr(&o)
        );
    }
    assert!(!out.exists(), "a rejected run created its output directory");
}

#[test]
fn without_a_model_the_sim_runs_the_built_in_net_and_says_so() {
    let _one = one_sim_at_a_time();
    // A fresh directory: no out/model.tnet, no --model.
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out").join("sim");
    let o = sim_command(&out, &SHORT)
        .current_dir(dir.path())
        .output()
        .expect("spawn");
    let err = stderr(&o);
    assert!(o.status.success(), "{err}");
    let mentions = err.lines().filter(|l| l.contains("built-in net")).count();
    assert_eq!(mentions, 1, "{err}");
    let r = report(&out);
    assert_eq!(r["model"]["built_in"], true);
    assert_eq!(
        std::fs::read(out.join("default.tnet")).unwrap(),
        std::fs::read(workspace_root().join(DEFAULT_NET)).unwrap()
    );
    assert!(r["tracking_samples"].as_u64().unwrap() > 500);
    assert!(r["rms_tracking_error_mm"].as_f64().unwrap() < 5.0);
}

#[test]
fn counts_print_as_integers_and_every_statistic_says_what_it_covers() {
    let _one = one_sim_at_a_time();
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let o = run_sim(&out, &[&["--model", DEFAULT_NET][..], &SHORT[..]].concat());
    assert!(o.status.success(), "{}", stderr(&o));
    let r = report(&out);
    assert!(r["controller"]["cycles"].is_u64(), "{}", r["controller"]);
    assert!(r["tracking_samples"].is_u64());
    let md = std::fs::read_to_string(out.join("report.md")).unwrap();
    let cycles_line = md
        .lines()
        .find(|l| l.starts_with("| controller cycles |"))
        .unwrap_or_else(|| panic!("{md}"));
    let value = cycles_line.split('|').nth(2).unwrap().trim();
    assert!(
        value.parse::<u64>().is_ok(),
        "controller cycles printed as {value:?}"
    );
    // The range check says how many commands it checked.
    let checked = r["plant"]["commands_checked"].as_u64().unwrap();
    assert!(checked > 500, "{checked} commands checked");
    assert!(md.contains(&format!("0 of {checked} checked")), "{md}");
    assert!(r["ipc_latency_us"]["count"].as_u64().unwrap() > 500);
    assert_eq!(r["verdict"]["clean"], true, "{}", r["verdict"]);
}

#[test]
fn a_plant_killed_without_restart_is_reported_as_such_and_the_statistics_cover_the_run_before_it() {
    let _one = one_sim_at_a_time();
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let o = run_sim(
        &out,
        &[
            "--model",
            DEFAULT_NET,
            "--settle",
            "0.5",
            "--duration",
            "3",
            "--kill-plant-at",
            "2",
        ],
    );
    assert!(
        o.status.success(),
        "an injected kill failed the run: {}",
        stderr(&o)
    );
    let r = report(&out);
    let kill = r["faults"]
        .as_array()
        .unwrap()
        .iter()
        .find(|f| f["kind"] == "plant_killed")
        .expect("plant_killed in faults");
    assert_eq!(kill["restart_configured"], false);
    assert!(kill["detail"].as_str().unwrap().contains("not restarted"));
    assert_eq!(kill["detected"], true, "{kill}");
    let rms = r["rms_tracking_error_mm"].as_f64();
    assert!(rms.is_some_and(f64::is_finite), "RMS {rms:?}");
    let window_end = r["tracking_window_s"][1].as_f64().unwrap();
    let killed_at = kill["t_s"].as_f64().unwrap();
    assert!(window_end <= killed_at + 0.06, "tracking ran past the kill");
}

#[test]
fn injected_nan_setpoints_and_dropped_commands_appear_in_faults_with_detection() {
    let _one = one_sim_at_a_time();
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let o = run_sim(
        &out,
        &[
            "--model",
            DEFAULT_NET,
            "--settle",
            "0.5",
            "--duration",
            "2.5",
            "--inject-nan-at",
            "1.5",
            "--drop",
            "0.3@2..2.5",
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let r = report(&out);
    let faults = r["faults"].as_array().unwrap();
    let find = |kind: &str| {
        faults
            .iter()
            .find(|f| f["kind"] == kind)
            .unwrap_or_else(|| panic!("no {kind} in {}", r["faults"]))
    };
    let nan = find("nan_setpoint");
    assert_eq!(nan["detected"], true, "{nan}");
    let latency = nan["detection_latency_s"].as_f64().unwrap();
    assert!(
        (0.0..0.01).contains(&latency),
        "NaN detected after {latency} s"
    );
    let drop = find("dropped_commands");
    assert_eq!(drop["detected"], true, "{drop}");
}

#[test]
fn a_stuck_motor_is_in_faults_and_an_undetected_one_fails_the_run() {
    let _one = one_sim_at_a_time();
    // Tendon 2 carries 1–3 N on the default circle, so a stuck motor there
    // has an effect to detect (the stuck time is plant time: the plant
    // starts before the loop). A fault with no effect is reported latent.
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let o = run_sim(
        &out,
        &[
            "--model",
            DEFAULT_NET,
            "--settle",
            "1",
            "--duration",
            "5",
            "--stuck",
            "2@3",
        ],
    );
    let r = report(&out);
    let stuck = r["faults"]
        .as_array()
        .unwrap()
        .iter()
        .find(|f| f["kind"] == "stuck_motor")
        .unwrap_or_else(|| panic!("no stuck_motor in {}", r["faults"]))
        .clone();
    assert!(stuck["t_s"].as_f64().is_some(), "{stuck}");
    match stuck["detected"].as_bool() {
        Some(true) => {
            let latency = stuck["detection_latency_s"].as_f64().unwrap();
            assert!(
                (0.0..1.0).contains(&latency),
                "stuck motor detected after {latency} s"
            );
            assert!(o.status.success(), "{}", stderr(&o));
        }
        Some(false) => {
            assert!(!o.status.success(), "an undetected stuck motor exited 0");
            assert!(
                r["verdict"]["problems"].to_string().contains("StuckMotor"),
                "{}",
                r["verdict"]
            );
        }
        None => {
            assert!(
                stuck["detail"].as_str().unwrap_or("").contains("latent"),
                "stuck motor without a detection verdict: {stuck}"
            );
            assert!(o.status.success(), "{}", stderr(&o));
        }
    }
}

#[test]
fn a_planner_stopped_for_a_moment_trips_the_watchdog_and_is_counted_as_late() {
    // SIGSTOP the planner for 50 periods, then let it go on: its setpoints
    // stop, the controller's watchdog holds, and when they come back in
    // sequence the trip is counted as a late planner, not a silent one —
    // how a clean run on a starved machine shows its watchdog trips.
    let _one = one_sim_at_a_time();
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let mut sim = sim_command(
        &out,
        &["--model", DEFAULT_NET, "--settle", "0.5", "--duration", "3"],
    )
    .stdout(Stdio::piped())
    .stderr(Stdio::piped())
    .spawn()
    .expect("spawn tendril sim");
    wait_for_children(&out, &mut sim);
    let pids = std::fs::read_to_string(out.join(".sim-run").join("pids")).unwrap();
    let planner: u32 = pids
        .lines()
        .find(|l| l.starts_with("planner "))
        .and_then(|l| l.split_whitespace().nth(2)?.parse().ok())
        .expect("planner in the pids file");
    let planner_log = out.join(".sim-run").join("planner-0.csv");
    let deadline = Instant::now() + Duration::from_secs(60);
    while std::fs::read_to_string(&planner_log).map_or(0, |t| t.lines().count()) < 100 {
        assert!(Instant::now() < deadline, "the loop never ran");
        std::thread::sleep(Duration::from_millis(50));
    }
    std::thread::sleep(Duration::from_millis(800));
    signal(planner, "STOP");
    std::thread::sleep(Duration::from_millis(50));
    signal(planner, "CONT");
    let output = sim.wait_with_output().expect("wait sim");
    assert!(output.status.success(), "{}", stderr(&output));
    let text = std::fs::read_to_string(out.join("controller.json")).expect("controller.json");
    let c: Value = serde_json::from_str(&text).unwrap();
    let trips = c["watchdog_trips"].as_u64().unwrap();
    let late = c["watchdog_trips_late_planner"]
        .as_u64()
        .expect("watchdog_trips_late_planner");
    assert!(trips >= 1, "a 50 ms silence did not trip the watchdog");
    assert_eq!(late, trips, "a late planner's trip counted as a silent one");
    assert_eq!(c["stuck_motor_holds"], 0);
}

#[test]
fn an_interrupted_robustness_table_leaves_exactly_the_previous_table() {
    let _one = one_sim_at_a_time();
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("table");
    std::fs::create_dir_all(out.join("ideal/sim")).unwrap();
    std::fs::write(out.join("robustness.md"), "old table").unwrap();
    std::fs::write(out.join("ideal/sim/report.json"), "old run").unwrap();
    let mut child = Command::new(tendril_bin())
        .args(["robustness", "--model", DEFAULT_NET, "--corrected-only"])
        .args(["--realities", "ideal,em-tracker", "--quick", "0.5", "--out"])
        .arg(&out)
        .current_dir(workspace_root())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // The first run is finished (in the staging directory) before the signal.
    let staged = out.join(".tendril-staging/ideal/sim/report.json");
    let deadline = Instant::now() + Duration::from_secs(120);
    while !staged.exists() {
        assert!(Instant::now() < deadline, "the first run never finished");
        assert!(child.try_wait().unwrap().is_none(), "the table ended early");
        std::thread::sleep(Duration::from_millis(50));
    }
    signal(child.id(), "INT");
    let o = child.wait_with_output().unwrap();
    assert_eq!(o.status.code(), Some(130), "{}", stderr(&o));
    assert!(stderr(&o).contains("left as it was"), "{}", stderr(&o));
    assert_eq!(
        std::fs::read_to_string(out.join("robustness.md")).unwrap(),
        "old table"
    );
    assert_eq!(
        std::fs::read_to_string(out.join("ideal/sim/report.json")).unwrap(),
        "old run",
        "a finished run of the interrupted table replaced the previous one"
    );
    assert!(!out.join(".tendril-staging").exists());
}

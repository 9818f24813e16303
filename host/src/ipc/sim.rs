//! `tendril sim`: create the services, launch plant, controller and planner
//! as child processes under a unique prefix, inject process-level faults
//! (kill / restart, corrupted weight updates), stop everything cleanly, and
//! turn the processes' logs into a report (JSON, markdown, figure).
//!
//! The tracking error is computed from two independent records: the
//! planner's log of what it asked for and the plant's log of where the
//! simulated tip really was (no sensor noise), joined by the shared
//! monotonic clock.

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::Duration;

use serde::{Deserialize, Serialize};
use serde_json::{json, Value};
use tendril_shared::messages::{
    command_status, control_command, setpoint_flags, Control, Header, WeightUpdate,
};

use super::clock::now_ns;
use super::controller::ControllerStats;
use super::planner::LOG_INJECTED;
use super::plant::PlantStats;
use super::stats::{column, read_log};
use super::transport::{self, Services};
use super::IpcError;

/// Process-level faults the launcher injects (times in s after the planner's
/// first setpoint).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct SimFaults {
    /// SIGKILL the planner at this time.
    pub kill_planner_at: Option<f64>,
    /// Start a new planner this long after the kill.
    pub restart_planner_after: Option<f64>,
    /// SIGKILL the plant at this time.
    pub kill_plant_at: Option<f64>,
    /// Start a new plant this long after the kill.
    pub restart_plant_after: Option<f64>,
    /// Publish a corrupted weight update (bad CRC) at these times.
    pub corrupt_weights_at: Vec<f64>,
    /// Publish the model again (a valid hot swap) at these times.
    pub swap_weights_at: Vec<f64>,
}

/// Everything the launcher needs.
#[derive(Clone, Debug)]
pub struct SimConfig {
    /// The `tendril` executable to spawn (normally the running one).
    pub exe: PathBuf,
    /// Robot file.
    pub robot: PathBuf,
    /// Model file.
    pub model: PathBuf,
    /// Output directory.
    pub out: PathBuf,
    /// Service-name prefix (unique per run).
    pub prefix: String,
    /// Seconds of trajectory after the settle hold.
    pub duration: f64,
    /// Initial hold, s.
    pub settle: f64,
    /// Controller rate (Hz), for period-based figures.
    pub rate: f64,
    /// Extra arguments for the planner (trajectory options).
    pub planner_args: Vec<String>,
    /// Extra arguments for the controller (tuning).
    pub controller_args: Vec<String>,
    /// Extra arguments for the plant (model, plant-side faults).
    pub plant_args: Vec<String>,
    /// Process-level faults.
    pub faults: SimFaults,
    /// Free-form description of the run for the report.
    pub label: String,
}

/// A unique service prefix for one run: parallel sims and tests never share services.
pub fn unique_prefix() -> String {
    format!(
        "tendril-sim-{}-{}",
        std::process::id(),
        now_ns() % 1_000_000_000_000
    )
}

struct Kids {
    children: Vec<(String, Child)>,
}

impl Kids {
    fn spawn(&mut self, cfg: &SimConfig, role: &str, args: Vec<String>) -> Result<(), IpcError> {
        let child = Command::new(&cfg.exe)
            .arg(role)
            .args(&args)
            .stdin(Stdio::null())
            .spawn()
            .map_err(|source| IpcError::Io {
                path: cfg.exe.clone(),
                source,
            })?;
        log::info!("sim: started {role} (pid {})", child.id());
        self.children.push((role.to_string(), child));
        Ok(())
    }

    fn kill(&mut self, role: &str) -> Option<u32> {
        let i = self.children.iter().rposition(|(r, _)| r == role)?;
        let (_, mut child) = self.children.remove(i);
        let pid = child.id();
        let _ = child.kill(); // SIGKILL
        let _ = child.wait();
        Some(pid)
    }

    /// Wait up to `timeout` for every child; SIGKILL the stragglers and name them.
    fn reap(&mut self, timeout: Duration) -> Vec<String> {
        let deadline = std::time::Instant::now() + timeout;
        let mut forced = Vec::new();
        for (role, child) in &mut self.children {
            loop {
                match child.try_wait() {
                    Ok(Some(status)) => {
                        if !status.success() {
                            forced.push(format!("{role} exited with {status}"));
                        }
                        break;
                    }
                    Ok(None) if std::time::Instant::now() < deadline => {
                        std::thread::sleep(Duration::from_millis(10))
                    }
                    _ => {
                        let _ = child.kill();
                        let _ = child.wait();
                        forced.push(format!("{role} did not stop: killed"));
                        break;
                    }
                }
            }
        }
        self.children.clear();
        forced
    }
}

impl Drop for Kids {
    fn drop(&mut self) {
        for (_, child) in &mut self.children {
            let _ = child.kill();
            let _ = child.wait();
        }
    }
}

/// A launcher event for the report.
#[derive(Clone, Debug, Serialize)]
struct Event {
    t_s: f64,
    t_ns: u64,
    kind: String,
}

/// Run the whole loop and write `out/report.json`, `report.md`, `sim.png`.
pub fn run(cfg: &SimConfig) -> Result<Value, IpcError> {
    std::fs::create_dir_all(&cfg.out).map_err(|source| IpcError::Io {
        path: cfg.out.clone(),
        source,
    })?;
    let model_bytes = std::fs::read(&cfg.model).map_err(|source| IpcError::Io {
        path: cfg.model.clone(),
        source,
    })?;
    let out = |name: &str| cfg.out.join(name).display().to_string();
    let common = |extra: &[String]| {
        let mut a = vec![
            "--robot".to_string(),
            cfg.robot.display().to_string(),
            "--prefix".into(),
            cfg.prefix.clone(),
        ];
        a.extend(extra.iter().cloned());
        a
    };

    // Services first, then the peers (see the module docs of `transport`).
    let node = transport::node("tendril-sim")?;
    let services = Services::open_or_create(&node, &cfg.prefix)?;
    let control = transport::publisher(&services.control)?;
    let weights = transport::publisher(&services.weights)?;
    let watch = transport::subscriber(&services.setpoint)?;

    let mut kids = Kids {
        children: Vec::new(),
    };
    let mut plant_gen = 0;
    let plant_args = |gen: usize| {
        let mut a = common(&cfg.plant_args);
        a.extend(["--log".into(), out(&format!("plant-{gen}.csv"))]);
        a.extend(["--stats".into(), out(&format!("plant-{gen}.json"))]);
        a
    };
    let mut planner_gen = 0;
    let planner_args = |gen: usize, settle: f64| {
        let mut a = common(&cfg.planner_args);
        a.push(format!("--settle={settle}"));
        a.extend(["--log".into(), out(&format!("planner-{gen}.csv"))]);
        a
    };
    let mut controller_args = common(&cfg.controller_args);
    controller_args.extend(["--model".into(), cfg.model.display().to_string()]);
    controller_args.extend(["--log".into(), out("controller.csv")]);
    controller_args.extend(["--stats".into(), out("controller.json")]);

    kids.spawn(cfg, "plant", plant_args(plant_gen))?;
    kids.spawn(cfg, "controller", controller_args)?;
    kids.spawn(cfg, "planner", planner_args(planner_gen, cfg.settle))?;

    // The run's clock starts with the planner's first setpoint (lifting the
    // trajectory takes the planner a moment).
    let wait_start = now_ns();
    let t0 = loop {
        if let (Some(_), _) = transport::latest(&watch)? {
            break now_ns();
        }
        if now_ns() - wait_start > 60_000_000_000 {
            return Err(IpcError::Other(
                "sim: no setpoint from the planner within 60 s".into(),
            ));
        }
        for (role, child) in &mut kids.children {
            if let Ok(Some(status)) = child.try_wait() {
                return Err(IpcError::Other(format!(
                    "sim: {role} exited early ({status})"
                )));
            }
        }
        std::thread::sleep(Duration::from_millis(5));
    };
    drop(watch);

    // Timeline of launcher actions.
    enum Act {
        KillPlanner,
        StartPlanner,
        KillPlant,
        StartPlant,
        Corrupt,
        Swap,
    }
    let f = &cfg.faults;
    let mut plan: Vec<(f64, Act)> = Vec::new();
    if let Some(t) = f.kill_planner_at {
        plan.push((t, Act::KillPlanner));
        if let Some(d) = f.restart_planner_after {
            plan.push((t + d, Act::StartPlanner));
        }
    }
    if let Some(t) = f.kill_plant_at {
        plan.push((t, Act::KillPlant));
        if let Some(d) = f.restart_plant_after {
            plan.push((t + d, Act::StartPlant));
        }
    }
    plan.extend(f.corrupt_weights_at.iter().map(|&t| (t, Act::Corrupt)));
    plan.extend(f.swap_weights_at.iter().map(|&t| (t, Act::Swap)));
    plan.sort_by(|a, b| a.0.total_cmp(&b.0));

    let end = cfg.settle + cfg.duration;
    let mut events: Vec<Event> = Vec::new();
    let mut weight_seq = 0;
    let mut note = |kind: String| {
        let t = now_ns();
        log::info!("sim: {kind}");
        events.push(Event {
            t_s: (t - t0) as f64 * 1e-9,
            t_ns: t,
            kind,
        });
    };
    for (at, act) in plan.into_iter().filter(|(at, _)| *at < end) {
        sleep_to(t0 + (at * 1e9) as u64);
        match act {
            Act::KillPlanner => {
                if let Some(pid) = kids.kill("planner") {
                    note(format!("planner_killed pid {pid}"));
                }
            }
            Act::StartPlanner => {
                planner_gen += 1;
                kids.spawn(cfg, "planner", planner_args(planner_gen, 0.5))?;
                note("planner_restarted".into());
            }
            Act::KillPlant => {
                if let Some(pid) = kids.kill("plant") {
                    note(format!("plant_killed pid {pid}"));
                }
            }
            Act::StartPlant => {
                plant_gen += 1;
                kids.spawn(cfg, "plant", plant_args(plant_gen))?;
                note("plant_restarted".into());
            }
            Act::Corrupt | Act::Swap => {
                weight_seq += 1;
                let header = Header {
                    seq: weight_seq,
                    stamp_ns: now_ns(),
                };
                let mut msg = WeightUpdate::from_bytes(header, &model_bytes)
                    .ok_or_else(|| IpcError::Other("model too large for a weight update".into()))?;
                let corrupt = matches!(act, Act::Corrupt);
                if corrupt {
                    // Flip one bit in the middle of the weights: the CRC must catch it.
                    let mid = msg.len as usize / 2;
                    msg.bytes[mid] ^= 0x10;
                }
                transport::send(&weights, msg)?;
                note(
                    if corrupt {
                        "weights_corrupted_sent"
                    } else {
                        "weights_valid_sent"
                    }
                    .into(),
                );
            }
        }
    }
    sleep_to(t0 + (end * 1e9) as u64);
    transport::send(
        &control,
        Control {
            header: Header {
                seq: 1,
                stamp_ns: now_ns(),
            },
            command: control_command::STOP,
            reserved: 0,
        },
    )?;
    let forced = kids.reap(Duration::from_secs(10));
    for f in &forced {
        log::warn!("sim: {f}");
    }

    let report = report(cfg, t0, &events, &forced, planner_gen, plant_gen)?;
    let json_text =
        serde_json::to_vec_pretty(&report).map_err(|e| IpcError::Other(e.to_string()))?;
    super::write_file(&cfg.out.join("report.json"), &json_text)?;
    super::write_file(&cfg.out.join("report.md"), markdown(&report).as_bytes())?;
    Ok(report)
}

fn sleep_to(t_ns: u64) {
    super::clock::sleep_until(t_ns, 0);
}

/// One plant-log sample joined with the setpoint in force.
#[derive(Clone, Copy, Debug)]
pub struct Sample {
    /// Seconds since the run's start.
    pub t: f64,
    /// Desired tip position (m).
    pub desired: [f64; 3],
    /// True tip position (m).
    pub actual: [f64; 3],
    /// Whether the planner was in its settle hold (or a restart's hold).
    pub hold: bool,
}

/// Percentile of a float slice (sorted copy), nearest rank.
fn pct(v: &[f64], p: f64) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    let rank = ((p / 100.0) * s.len() as f64).ceil() as usize;
    s[rank.clamp(1, s.len()) - 1]
}

/// A CSV log: header and numeric rows.
type Log = (Vec<String>, Vec<Vec<f64>>);

/// One plant step: time (ns), true tip (m), commanded and actual tensions (N).
type PlantRow = (f64, [f64; 3], Vec<f64>, Vec<f64>);

fn read_rows(dir: &Path, stem: &str, gens: usize) -> Result<Vec<Log>, IpcError> {
    let mut all = Vec::new();
    for g in 0..=gens {
        let path = dir.join(format!("{stem}-{g}.csv"));
        if path.exists() {
            all.push(read_log(&path)?);
        }
    }
    Ok(all)
}

fn report(
    cfg: &SimConfig,
    t0: u64,
    events: &[Event],
    forced: &[String],
    planner_gens: usize,
    plant_gens: usize,
) -> Result<Value, IpcError> {
    let secs = |t_ns: f64| (t_ns - t0 as f64) * 1e-9;
    // Planner: (t_ns, flags, pose) of every logged setpoint, all generations.
    let mut sp: Vec<(f64, u32, [f64; 3])> = Vec::new();
    for (h, rows) in read_rows(&cfg.out, "planner", planner_gens)? {
        let p = cfg.out.join("planner");
        let (it, ifl, ix) = (
            column(&h, "t_ns", &p)?,
            column(&h, "flags", &p)?,
            column(&h, "px", &p)?,
        );
        sp.extend(
            rows.iter()
                .map(|r| (r[it], r[ifl] as u32, [r[ix], r[ix + 1], r[ix + 2]])),
        );
    }
    sp.sort_by(|a, b| a.0.total_cmp(&b.0));

    // Plant: true tip and tensions at every step, all generations.
    let mut plant_rows: Vec<PlantRow> = Vec::new();
    let mut n = 0;
    for (h, rows) in read_rows(&cfg.out, "plant", plant_gens)? {
        let p = cfg.out.join("plant");
        let it = column(&h, "t_ns", &p)?;
        let ix = column(&h, "px", &p)?;
        let ic = column(&h, "cmd0", &p)?;
        let ia = column(&h, "tau0", &p)?;
        n = ia - ic;
        plant_rows.extend(rows.iter().map(|r| {
            (
                r[it],
                [r[ix], r[ix + 1], r[ix + 2]],
                r[ic..ic + n].to_vec(),
                r[ia..ia + n].to_vec(),
            )
        }));
    }
    plant_rows.sort_by(|a, b| a.0.total_cmp(&b.0));

    // Join: setpoint in force at each plant step (none if the planner has
    // been silent for over 50 ms).
    let mut samples = Vec::new();
    let mut j = 0;
    for (t, actual, _, _) in &plant_rows {
        while j + 1 < sp.len() && sp[j + 1].0 <= *t {
            j += 1;
        }
        if sp.is_empty() || sp[j].0 > *t || *t - sp[j].0 > 50e6 {
            continue;
        }
        let (_, flags, desired) = sp[j];
        samples.push(Sample {
            t: secs(*t),
            desired,
            actual: *actual,
            hold: flags & setpoint_flags::HOLD != 0 || flags & LOG_INJECTED != 0,
        });
    }
    let err_mm = |s: &Sample| {
        ((s.desired[0] - s.actual[0]).powi(2)
            + (s.desired[1] - s.actual[1]).powi(2)
            + (s.desired[2] - s.actual[2]).powi(2))
        .sqrt()
            * 1e3
    };
    let tracking: Vec<f64> = samples.iter().filter(|s| !s.hold).map(err_mm).collect();
    let rms = if tracking.is_empty() {
        f64::NAN
    } else {
        (tracking.iter().map(|e| e * e).sum::<f64>() / tracking.len() as f64).sqrt()
    };
    let max = tracking.iter().copied().fold(0.0, f64::max);

    // Steady state: every stretch of ≥ 1 s with a constant desired position;
    // mean true error over its last 0.5 s.
    let mut steady = Vec::new();
    let mut k = 0;
    while k < samples.len() {
        let mut e = k;
        while e + 1 < samples.len() && samples[e + 1].desired == samples[k].desired {
            e += 1;
        }
        if samples[e].t - samples[k].t >= 1.0 {
            let tail: Vec<f64> = samples[k..=e]
                .iter()
                .filter(|s| s.t >= samples[e].t - 0.5)
                .map(err_mm)
                .collect();
            let mean = tail.iter().sum::<f64>() / tail.len().max(1) as f64;
            steady.push(json!({
                "t_s": samples[k].t,
                "target_mm": [samples[k].desired[0] * 1e3, samples[k].desired[1] * 1e3],
                "error_mm": mean,
            }));
        }
        k = e + 1;
    }
    let steady_max = steady
        .iter()
        .filter_map(|s| s["error_mm"].as_f64())
        .fold(f64::NAN, |a: f64, b| if a.is_nan() { b } else { a.max(b) });

    let ctrl: ControllerStats = read_json(&cfg.out.join("controller.json")).unwrap_or_default();
    let mut plant_stats: Vec<PlantStats> = Vec::new();
    for g in 0..=plant_gens {
        if let Some(s) = read_json(&cfg.out.join(format!("plant-{g}.json"))) {
            plant_stats.push(s);
        }
    }
    let latency = plant_stats
        .first()
        .map(|s| s.latency_us)
        .unwrap_or_default();
    let plant_step = plant_stats.first().map(|s| s.step_us).unwrap_or_default();
    let out_of_range: u64 = plant_stats.iter().map(|s| s.out_of_range_commands).sum();

    // Fault analysis from the controller's per-period log.
    let faults = analyse_faults(cfg, t0, events, forced, &samples)?;

    let tension_series: Vec<Value> = plant_rows
        .iter()
        .step_by(10)
        .map(|(t, _, c, a)| json!([secs(*t), c, a]))
        .collect();
    let report = json!({
        "label": cfg.label,
        "prefix": cfg.prefix,
        "duration_s": cfg.duration,
        "settle_s": cfg.settle,
        "tendons": n,
        "rms_tracking_error_mm": rms,
        "max_tracking_error_mm": max,
        "p95_tracking_error_mm": pct(&tracking, 95.0),
        "tracking_samples": tracking.len(),
        "steady_state": steady,
        "max_steady_state_error_mm": steady_max,
        "controller": {
            "cycles": ctrl.cycles,
            "overruns": ctrl.overruns,
            "skipped": ctrl.skipped,
            "overrun_fraction": ctrl.overrun_fraction,
            "lateness_us": ctrl.lateness_us,
            "step_us": ctrl.step_us,
            "setpoint_age_us": ctrl.setpoint_age_us,
            "rejected_nonfinite": ctrl.rejected_nonfinite,
            "rejected_quaternion": ctrl.rejected_quaternion,
            "rejected_workspace": ctrl.rejected_workspace,
            "watchdog_trips": ctrl.watchdog_trips,
            "hold_cycles": ctrl.hold_cycles,
            "weight_swaps": ctrl.weight_swaps,
            "weight_rejections": ctrl.weight_rejections,
            "planner_restarts": ctrl.planner_restarts,
            "plant_restarts": ctrl.plant_restarts,
            "plant_stale_cycles": ctrl.plant_stale_cycles,
            "plant_recoveries": ctrl.plant_recoveries,
        },
        "ipc_latency_us": latency,
        "plant": {
            "step_us": plant_step,
            "out_of_range_commands": out_of_range,
            "generations": plant_stats,
        },
        "faults": faults,
        "series": {
            "path_mm": samples.iter().step_by(10).map(|s| json!([s.t, s.desired[0]*1e3, s.desired[1]*1e3, s.actual[0]*1e3, s.actual[1]*1e3, s.hold])).collect::<Vec<_>>(),
            "tensions": tension_series,
        },
    });
    crate::plot::sim::draw(&cfg.out.join("sim.png"), &report)
        .map_err(|e| IpcError::Other(format!("sim figure: {e}")))?;
    Ok(report)
}

fn read_json<T: for<'de> Deserialize<'de>>(path: &Path) -> Option<T> {
    let text = std::fs::read(path).ok()?;
    serde_json::from_slice(&text).ok()
}

/// For each launcher event, what the controller did about it, from its
/// per-period log.
fn analyse_faults(
    cfg: &SimConfig,
    t0: u64,
    events: &[Event],
    forced: &[String],
    samples: &[Sample],
) -> Result<Vec<Value>, IpcError> {
    let period_ns = 1e9 / cfg.rate;
    let path = cfg.out.join("controller.csv");
    let (h, rows) = if path.exists() {
        read_log(&path)?
    } else {
        (Vec::new(), Vec::new())
    };
    let (it, ist, isp, ips) = if rows.is_empty() {
        (0, 0, 0, 0)
    } else {
        (
            column(&h, "t_ns", &path)?,
            column(&h, "status", &path)?,
            column(&h, "sp_seq", &path)?,
            column(&h, "state_seq", &path)?,
        )
    };
    let secs = |t: f64| (t - t0 as f64) * 1e-9;
    let rms_between = |a: f64, b: f64| {
        let e: Vec<f64> = samples
            .iter()
            .filter(|s| !s.hold && s.t >= a && s.t < b)
            .map(|s| {
                ((s.desired[0] - s.actual[0]).powi(2) + (s.desired[1] - s.actual[1]).powi(2)).sqrt()
                    * 1e3
            })
            .collect();
        if e.is_empty() {
            Value::Null
        } else {
            json!((e.iter().map(|x| x * x).sum::<f64>() / e.len() as f64).sqrt())
        }
    };
    let end = cfg.settle + cfg.duration;
    let mut out = Vec::new();
    for ev in events {
        let te = ev.t_ns as f64;
        let mut v = json!({ "t_s": ev.t_s, "kind": ev.kind });
        if ev.kind.starts_with("planner_killed") && !rows.is_empty() {
            // Last period that saw a new setpoint before the kill, first period in hold after it.
            let before: Vec<&Vec<f64>> = rows.iter().filter(|r| r[it] <= te).collect();
            let last_new = before
                .windows(2)
                .rev()
                .find(|w| w[1][isp] != w[0][isp])
                .map(|w| w[1][it]);
            let hold = rows
                .iter()
                .find(|r| r[it] > te && (r[ist] as u32) & command_status::SAFE_HOLD != 0)
                .map(|r| r[it]);
            if let (Some(a), Some(b)) = (last_new, hold) {
                v["hold_periods_after_last_setpoint"] = json!(((b - a) / period_ns).round());
                v["hold_periods_after_kill"] = json!(((b - te) / period_ns).ceil());
            }
            v["entered_hold"] = json!(hold.is_some());
        }
        if ev.kind == "planner_restarted" && !rows.is_empty() {
            let resumed = rows
                .iter()
                .find(|r| r[it] > te && (r[ist] as u32) & command_status::SAFE_HOLD == 0)
                .map(|r| r[it]);
            v["resumed_after_s"] = json!(resumed.map(|r| (r - te) * 1e-9));
            v["rms_after_recovery_mm"] = rms_between(ev.t_s + 1.5, end);
        }
        if ev.kind.starts_with("plant_killed") && !rows.is_empty() {
            // The controller sees the state sequence stop advancing.
            let last_state = rows.iter().rev().find(|r| r[it] <= te).map(|r| r[ips]);
            let frozen_until = rows
                .iter()
                .filter(|r| r[it] > te)
                .find(|r| Some(r[ips]) != last_state)
                .map(|r| secs(r[it]));
            v["state_resumed_at_s"] = json!(frozen_until);
            let stale = rows
                .iter()
                .filter(|r| r[it] > te)
                .any(|r| (r[ist] as u32) & command_status::PLANT_STALE != 0);
            v["controller_flagged_stale"] = json!(stale);
        }
        if ev.kind == "plant_restarted" {
            v["rms_after_recovery_mm"] = rms_between(ev.t_s + 1.5, end);
        }
        if ev.kind.starts_with("weights_") && !rows.is_empty() {
            let bit = if ev.kind.contains("corrupted") {
                command_status::WEIGHTS_REJECTED
            } else {
                command_status::WEIGHTS_SWAPPED
            };
            let seen = rows
                .iter()
                .find(|r| r[it] > te - period_ns && (r[ist] as u32) & bit != 0)
                .map(|r| (r[it] - te) * 1e-9);
            v["controller_reacted_after_s"] = json!(seen);
        }
        out.push(v);
    }
    for f in forced {
        out.push(json!({ "kind": "shutdown", "detail": f }));
    }
    Ok(out)
}

fn markdown(r: &Value) -> String {
    let f = |v: &Value| v.as_f64().map_or("–".to_string(), |x| format!("{x:.3}"));
    let mut s = String::new();
    s.push_str(&format!(
        "# tendril sim report\n\n{}\n\n",
        r["label"].as_str().unwrap_or("")
    ));
    s.push_str("| quantity | value |\n|---|---|\n");
    for (name, v) in [
        ("RMS tracking error (mm)", &r["rms_tracking_error_mm"]),
        ("max tracking error (mm)", &r["max_tracking_error_mm"]),
        ("p95 tracking error (mm)", &r["p95_tracking_error_mm"]),
        (
            "max steady-state error (mm)",
            &r["max_steady_state_error_mm"],
        ),
        ("controller cycles", &r["controller"]["cycles"]),
        ("controller overruns", &r["controller"]["overruns"]),
        ("lateness p50 (µs)", &r["controller"]["lateness_us"]["p50"]),
        ("lateness p99 (µs)", &r["controller"]["lateness_us"]["p99"]),
        ("IPC latency p50 (µs)", &r["ipc_latency_us"]["p50"]),
        ("IPC latency p99 (µs)", &r["ipc_latency_us"]["p99"]),
        ("plant step median (µs)", &r["plant"]["step_us"]["p50"]),
        (
            "out-of-range commands at the plant",
            &r["plant"]["out_of_range_commands"],
        ),
    ] {
        s.push_str(&format!("| {name} | {} |\n", f(v)));
    }
    if let Some(steps) = r["steady_state"].as_array() {
        if !steps.is_empty() {
            s.push_str("\n## Steady state\n\n| from (s) | target x, y (mm) | error (mm) |\n|---|---|---|\n");
            for st in steps {
                s.push_str(&format!(
                    "| {} | {}, {} | {} |\n",
                    f(&st["t_s"]),
                    f(&st["target_mm"][0]),
                    f(&st["target_mm"][1]),
                    f(&st["error_mm"])
                ));
            }
        }
    }
    if let Some(faults) = r["faults"].as_array() {
        if !faults.is_empty() {
            s.push_str("\n## Faults\n\n");
            for fault in faults {
                s.push_str(&format!("- `{}`\n", fault));
            }
        }
    }
    s.push_str("\nFigure: `sim.png` (desired vs actual tip path, tensions over time).\n");
    s
}

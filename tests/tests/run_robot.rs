//! `tendril run --robot` end to end on the paper's literal one-tendon robot
//! (`robots/seed-1t.toml`), a real process: the `--quick` pipeline must
//! complete every stage — dataset, workspace figure, net, the comparison
//! with the six baselines, firmware parity under QEMU, and the closed loop
//! the robot can follow (a one-tendon robot reaches a curve, so it tracks a
//! 1-D sweep, docs/design.md §6) — and the numbers must hold against
//! held-out data and the plant's true tip.
//!
//! Needs `qemu-system-arm` and the `thumbv7em-none-eabihf` target for the
//! parity stage (`scripts/test` lists this test among the QEMU tests).

use std::path::Path;

use serde_json::Value;
use tendril::pipeline::run_dir;
use tendril::plan::default_loop_runs;
use tendril::statics::repo_statics;
use tendril_tests::{robot, tendril};

fn json(path: &Path) -> Value {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

fn number(v: &Value, path: &[&str]) -> f64 {
    let mut v = v;
    for key in path {
        v = &v[*key];
    }
    v.as_f64()
        .unwrap_or_else(|| panic!("{} is not a number: {v}", path.join(".")))
}

#[test]
fn the_pipeline_runs_end_to_end_on_the_one_tendon_robot() {
    let file = robot("seed-1t.toml");
    let out = tempfile::tempdir().expect("temp dir");
    let dir = out.path().join("seed-1t");
    let run = tendril(&[
        "run",
        "--robot",
        file.to_str().expect("utf-8 path"),
        "--out",
        dir.to_str().expect("utf-8 path"),
        "--quick",
        "-q",
    ]);
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(run.status.success(), "tendril run failed:\n{stderr}");

    // Every stage's section, in order.
    let report = std::fs::read_to_string(dir.join("report.md")).expect("report.md");
    let mut at = 0;
    for heading in [
        "## 1. Dataset",
        "## 2. Workspace",
        "## 3. Cascade-correlation IK net",
        "## 4. Comparison with six baselines",
        "## 4b. Firmware parity",
        "## 5. Closed loop",
    ] {
        let found = report[at..]
            .find(heading)
            .unwrap_or_else(|| panic!("report lacks `{heading}` after byte {at}:\n{report}"));
        at += found + heading.len();
    }
    for figure in ["workspace.png", "learning_curve.png", "compare/compare.png"] {
        let len = std::fs::metadata(dir.join(figure)).map_or(0, |m| m.len());
        assert!(len > 1000, "{figure}: {len} bytes");
    }

    // The net on held-out poses, through the statics: the one-tendon
    // robot's IK is a smooth 1-D map, learned to well under 0.1 mm.
    let eval = json(&dir.join("evaluation.json"));
    let p95 = number(&eval, &["position_mm", "p95"]);
    assert!(p95 <= 0.1, "held-out tip error p95 {p95} mm");
    assert_eq!(number(&eval, &["failed_solves"]), 0.0);

    // All seven learners compared on the same split.
    let table = std::fs::read_to_string(dir.join("compare/compare.csv")).expect("compare.csv");
    assert_eq!(table.lines().count(), 1 + 7, "{table}");

    // The MCU ran the one-output net bit-identically.
    let parity = json(&dir.join("parity.json"));
    let shape = &parity["net"];
    assert_eq!(shape[2].as_u64(), Some(1), "one tendon: {parity}");
    assert_eq!(parity["lines"], parity["bit_identical"], "{parity}");

    // The closed loop with the correction tracks the robot's runs to 0.1 mm.
    let statics = repo_statics("seed-1t.toml");
    let runs = default_loop_runs(&statics).expect("loop runs");
    assert!(
        !runs.is_empty(),
        "no closed-loop run for the one-tendon robot"
    );
    // The chip's run: the run's net goes over the link before any setpoint
    // (the chip boots with the default robot's net, whose box the
    // one-tendon robot's poses are outside of), so no setpoint meets the
    // wrong net, and the loop is clean.
    let chip_dir = format!("{}-mcu", run_dir(&runs[0], true));
    let chip = json(&dir.join(&chip_dir).join("controller.json"));
    assert_eq!(number(&chip, &["weight_swaps"]), 1.0, "{chip_dir}: {chip}");
    assert_eq!(number(&chip, &["rejected_workspace"]), 0.0, "{chip_dir}");
    let sim = json(&dir.join(&chip_dir).join("report.json"));
    assert_eq!(
        sim["verdict"]["clean"],
        Value::Bool(true),
        "{chip_dir}: {sim}"
    );
    // The run on the rod with mass: the planner designed its shaping for
    // the robot's first mode, sent the dynamic offset, and the loop is
    // clean and within half a millimetre.
    let mass_dir = format!("{}-mass", run_dir(&runs[0], true));
    let mass = json(&dir.join(&mass_dir).join("report.json"));
    assert_eq!(
        mass["verdict"]["clean"],
        Value::Bool(true),
        "{mass_dir}: {mass}"
    );
    assert!(
        number(&mass, &["step_shaping", "mode_hz"]) > 0.0,
        "{mass_dir}: no shaping"
    );
    assert_eq!(mass["dynamic_offset"], Value::Bool(true), "{mass_dir}");
    let rms = number(&mass, &["rms_tracking_error_mm"]);
    assert!(rms <= 0.5, "{mass_dir}: RMS {rms} mm");
    for run in runs {
        let sub = run_dir(&run, true);
        let sim = json(&dir.join(&sub).join("report.json"));
        assert_eq!(sim["verdict"]["clean"], Value::Bool(true), "{sub}: {sim}");
        let rms = number(&sim, &["rms_tracking_error_mm"]);
        assert!(rms <= 0.1, "{} with correction: RMS {rms} mm", run.label);
    }
}

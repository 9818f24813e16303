//! The closed loop against realities (docs/design.md §6.2, §6.3): planner,
//! controller and a plant that is *not* the model — its tracker slow, late
//! and jittery, its tendons rubbing in their guides, its backbone stiffer
//! and its tendons off, its rod swinging — as three real processes over
//! iceoryx2, all with the controller's default gains. The numbers are the
//! issue's targets: every reality's circle ≤ 0.5 mm RMS, the steps' steady
//! state ≤ 2× the reality's tracker jitter; `everything`'s circle ≤ 1 mm. (Its
//! steps are not asserted: on the lightly damped dynamic rod a 10 mm step
//! rings for seconds, with the net alone as with the correction — see
//! BENCHMARKS.md.)

use tendril_tests::{run_sim, sim_report};

/// The default exported net (what the MCU build embeds).
const DEFAULT_NET: &str = "firmware/vectors/default.tnet";

/// Run a sim against `reality` with `args`; its report.
fn against(reality: &str, args: &[&str]) -> serde_json::Value {
    let mut all = vec!["--model", DEFAULT_NET, "--reality", reality];
    all.extend_from_slice(args);
    let (dir, _) = run_sim(&all);
    sim_report(dir.path())
}

fn mm(report: &serde_json::Value, key: &str) -> f64 {
    report[key]
        .as_f64()
        .unwrap_or_else(|| panic!("report has no {key}: {report}"))
}

/// The circle (radius 15 mm, 0.2 Hz) for `seconds` after a 1.5 s settle:
/// clean (no oscillation) and within `bound_mm` RMS. One revolution (5 s)
/// on the quasi-static plants, whose circles sit at a tenth of the bound;
/// two where the correction must learn the error's map on the first
/// (`stiffer-10pct`) or the rod swings (`everything`: one 5 s run of it
/// failed here, its reason not captured; a short run also gives the
/// oscillation test few 2 s windows).
fn circle_within(reality: &str, bound_mm: f64, seconds: &str) -> serde_json::Value {
    let r = against(
        reality,
        &[
            "--trajectory",
            "circle",
            "--settle",
            "1.5",
            "--duration",
            seconds,
        ],
    );
    let rms = mm(&r, "rms_tracking_error_mm");
    eprintln!(
        "{reality}: circle RMS {rms:.3} mm, max {:.3} mm",
        mm(&r, "max_tracking_error_mm")
    );
    assert_eq!(r["verdict"]["clean"], true, "{reality}: {}", r["verdict"]);
    assert_eq!(
        r["oscillation"]["detected"], false,
        "{reality}: {}",
        r["oscillation"]
    );
    assert!(
        rms <= bound_mm,
        "{reality}: circle RMS {rms:.3} mm > {bound_mm} mm"
    );
    r
}

/// The four 10 mm step targets: every steady state within `bound_mm`.
fn steps_within(reality: &str, bound_mm: f64) {
    let r = against(reality, &["--trajectory", "steps"]);
    let worst = mm(&r, "max_steady_state_error_mm");
    eprintln!("{reality}: steps, worst steady state {worst:.3} mm");
    assert!(
        r["steady_state"].as_array().is_some_and(|s| s.len() >= 4),
        "{reality}: steady states {}",
        r["steady_state"]
    );
    assert_eq!(r["verdict"]["clean"], true, "{reality}: {}", r["verdict"]);
    assert!(
        worst <= bound_mm,
        "{reality}: steady state {worst:.3} mm > {bound_mm} mm"
    );
}

#[test]
fn an_em_tracker_at_40_hz_late_and_jittery_still_holds_the_circle() {
    circle_within("em-tracker", 0.5, "5");
}

#[test]
fn an_em_tracker_steady_state_is_within_twice_its_jitter() {
    steps_within("em-tracker", 2.0 * 0.14);
}

#[test]
fn tendon_friction_and_drive_play_still_hold_the_circle() {
    circle_within("friction", 0.5, "5");
}

#[test]
fn everything_at_once_holds_the_circle_within_a_millimetre() {
    circle_within("everything", 1.0, "10");
}

/// The net alone is off by ≈ 1.4 mm around the circle on this robot
/// (half a revolution shows it); the corrected loop without the stiffness
/// adaptation (`--adapt-stiffness off`) learns the error's map, within
/// 0.5 mm. By default the planner's stiffness adaptation (docs/design.md
/// §6.5) finds the backbone's stiffness: a linear-elastic deflection goes
/// with 1/E, so a backbone 10 % stiffer moves the tip by the fraction
/// 1 − 1/1.1 = 0.091 of g, which is what κ̂ estimates (the loop model
/// leaves the error map and the motors out: 0.087–0.100 measured); and the
/// circle then follows within 0.2 mm, where the loop alone left 0.32 mm.
#[test]
fn a_stiffer_robot_than_its_model_is_corrected_along_the_circle() {
    let alone = against(
        "stiffer-10pct",
        &[
            "--trajectory",
            "circle",
            "--correction",
            "off",
            "--settle",
            "1.5",
            "--duration",
            "2.5",
        ],
    );
    let rms_alone = mm(&alone, "rms_tracking_error_mm");
    assert!(
        alone["stiffness_adapted"].is_null(),
        "{}",
        alone["stiffness_adapted"]
    );
    let circle = [
        "--trajectory",
        "circle",
        "--settle",
        "1.5",
        "--duration",
        "10",
    ];
    let unadapted = against(
        "stiffer-10pct",
        &[&circle[..], &["--adapt-stiffness", "off"]].concat(),
    );
    let rms_unadapted = mm(&unadapted, "rms_tracking_error_mm");
    eprintln!("stiffer-10pct, not adapted: circle RMS {rms_unadapted:.3} mm");
    assert_eq!(
        unadapted["verdict"]["clean"], true,
        "{}",
        unadapted["verdict"]
    );
    assert!(unadapted["stiffness_adapted"].is_null());
    assert!(rms_unadapted <= 0.5, "circle RMS {rms_unadapted:.3} mm");
    let adapted = against("stiffer-10pct", &circle);
    let rms = mm(&adapted, "rms_tracking_error_mm");
    eprintln!("stiffer-10pct, adapted: circle RMS {rms:.3} mm");
    assert_eq!(adapted["verdict"]["clean"], true, "{}", adapted["verdict"]);
    assert!(rms <= 0.2, "adapted circle RMS {rms:.3} mm > 0.2 mm");
    let kappa = mm(&adapted, "stiffness_adapted");
    assert!(
        (0.07..=0.12).contains(&kappa),
        "estimated κ̂ {kappa:.4} for a backbone 10 % stiffer (0.091)"
    );
    assert!(
        rms_alone > 1.0,
        "the net alone was already within {rms_alone:.3} mm"
    );
}

/// `sim --plant-robot`: the plant moves another robot file than the one the
/// planner, controller and net use (a net trained on a calibrated file, run
/// on the robot it was calibrated to). The calibration benchmark's real
/// robot as a file (the text edits of scripts/calibration-benchmark) and as
/// the nominal file under the `calibration-truth` reality are one plant:
/// the net alone is as far off on either, and far off (scripts/calibration-loop
/// relies on both).
#[test]
fn a_plant_robot_file_moves_the_plant_like_the_calibration_truth_reality() {
    let root = tendril_tests::workspace_root();
    let text = std::fs::read_to_string(root.join("robots/seed-4t.toml")).unwrap();
    let real = text
        .replace("youngs_modulus = 207e9", "youngs_modulus = 227.7e9")
        .replace("density = 39317.0 ", "density = 45214.55 ");
    let mut parts = real.split("offset = 0.019\n");
    let mut file = parts.next().unwrap().to_string();
    for (o, p) in ["0.0195", "0.0185", "0.0194", "0.0187"].iter().zip(parts) {
        file.push_str(&format!("offset = {o}\n{p}"));
    }
    assert!(file.contains("227.7e9") && file.contains("45214.55") && !file.contains("= 0.019\n"));
    // Where its tracker sees it: the reality's base_translation_delta_mm.
    file.push_str("\n[base]\ntranslation = [0.0015, -0.001, 0.0008]\n");
    let dir = tempfile::tempdir().unwrap();
    let real_toml = dir.path().join("real.toml");
    std::fs::write(&real_toml, file).unwrap();
    let real_toml = real_toml.to_str().unwrap();
    let alone = [
        "--model",
        DEFAULT_NET,
        "--trajectory",
        "circle",
        "--correction",
        "off",
        "--duration",
        "2.5",
        "--max-rms-mm",
        "100",
    ];
    let rms = |extra: &[&str]| {
        let mut args = alone.to_vec();
        args.extend_from_slice(extra);
        let (d, _) = run_sim(&args);
        mm(&sim_report(d.path()), "rms_tracking_error_mm")
    };
    let by_file = rms(&["--plant-robot", real_toml]);
    let by_reality = rms(&["--reality", "robots/realities/calibration-truth.toml"]);
    eprintln!("net alone: plant robot file {by_file:.3} mm, reality {by_reality:.3} mm");
    assert!(
        by_file > 2.0,
        "the plant robot was not moved: {by_file:.3} mm"
    );
    assert!(
        (by_file - by_reality).abs() < 0.05 * by_reality,
        "{by_file:.3} mm against {by_reality:.3} mm"
    );
    // A plant robot with other tendons than the model is refused at once.
    let o = std::process::Command::new(tendril_tests::tendril_bin())
        .args([
            "sim",
            "--plant-robot",
            "robots/seed-1t.toml",
            "--model",
            DEFAULT_NET,
        ])
        .arg("--out")
        .arg(dir.path().join("refused"))
        .current_dir(&root)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && err.contains("--plant-robot has 1 tendon but --robot has 4"),
        "{err}"
    );
}

/// A robot file whose `[base]` puts the robot 0.37 m from the tracker's
/// origin and turned by 0.62 rad (docs/design.md §2.4): the planner
/// publishes and logs its setpoints in the tracker's frame, the plant
/// reports the tip there, the controller maps both back to the base frame
/// its net was trained in (the default net: the frame is not part of the
/// robot's fingerprint). One map wrong anywhere and the tip is metres off;
/// all right, the circle is the ideal plant's (0.045 mm without a frame).
/// The independent fact: the logged setpoints, mapped back here with the
/// rotation built from the file's numbers, lie on the rod's reach (a
/// circle of 15 mm about the axis, near the tip's rest height).
#[test]
fn a_robot_seen_from_a_tracker_elsewhere_tracks_its_circle_in_the_trackers_frame() {
    use nalgebra::{Rotation3, Vector3};
    let root = tendril_tests::workspace_root();
    let text = std::fs::read_to_string(root.join("robots/seed-4t.toml")).unwrap();
    let (t, r) = ([0.3, -0.2, 0.1], [0.2, -0.5, 0.3]);
    let turned = format!(
        "{text}\n[base]\ntranslation = [{}, {}, {}]\nrotation = [{}, {}, {}]\n",
        t[0], t[1], t[2], r[0], r[1], r[2]
    );
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("turned.toml");
    std::fs::write(&file, turned).unwrap();
    let (out, _) = run_sim(&[
        "--robot",
        file.to_str().unwrap(),
        "--model",
        DEFAULT_NET,
        "--trajectory",
        "circle",
        "--duration",
        "4",
    ]);
    let report = sim_report(out.path());
    let rms = mm(&report, "rms_tracking_error_mm");
    eprintln!("circle seen from a turned tracker: RMS {rms:.3} mm");
    assert_eq!(report["verdict"]["clean"], true, "{}", report["verdict"]);
    assert!(rms < 0.1, "RMS {rms:.3} mm");
    let (head, rows) = tendril_tests::csv(&out.path().join("planner-0.csv"));
    let at = |name: &str| tendril_tests::col(&head, name);
    let (px, py, pz) = (at("px"), at("py"), at("pz"));
    let back = Rotation3::new(Vector3::from(r)).inverse();
    for row in &rows {
        let p = Vector3::new(row[px], row[py], row[pz]);
        let b = back * (p - Vector3::from(t));
        // The log is in the tracker's frame, not the base frame.
        assert!((p - b).norm() > 0.1, "{p:?} is a base-frame point");
        let lateral = b.x.hypot(b.y);
        assert!(
            (0.005..0.05).contains(&lateral) && (0.35..0.40).contains(&b.z),
            "a setpoint at {b:?} in the base frame is not on the rod's reach"
        );
    }
}

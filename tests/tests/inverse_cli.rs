//! `tendril ik --exact` through the real binary (docs/design.md §4.1, §7):
//! the printed tensions reach the target under `tendril fk`, the batch
//! writes one checked row per target, bad input fails with one line and
//! writes nothing.

use std::path::{Path, PathBuf};
use std::process::Command;

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn tendril(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_tendril"))
        .args(args)
        .current_dir(root())
        .output()
        .expect("run tendril")
}

fn json(out: &std::process::Output) -> serde_json::Value {
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).expect("one JSON object")
}

fn fk_pose(tensions: &str) -> Vec<f64> {
    let v = json(&tendril(&["fk", "--tensions", tensions, "--json"]));
    v["position"]
        .as_array()
        .unwrap()
        .iter()
        .chain(v["quaternion"].as_array().unwrap())
        .map(|x| x.as_f64().unwrap())
        .collect()
}

fn join(v: &[f64]) -> String {
    v.iter().map(f64::to_string).collect::<Vec<_>>().join(",")
}

#[test]
fn exact_single_pose_reaches_the_target_under_forward_statics() {
    let pose = fk_pose("4,3,0,0");
    let v = json(&tendril(&[
        "ik",
        "--exact",
        "--pose",
        &join(&pose),
        "--json",
    ]));
    assert_eq!(v["reachable"], true);
    let tau: Vec<f64> = v["tensions"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect();
    // Independent check: the statics of the printed tensions.
    let reached = fk_pose(&join(&tau));
    let err = (0..3)
        .map(|k| (reached[k] - pose[k]).powi(2))
        .sum::<f64>()
        .sqrt();
    assert!(err <= 1e-6, "tip {err:e} m from the target");
    assert!(v["orientation_error"].as_f64().unwrap() <= 1e-5);

    // Position only, beyond reach: the closest pose is printed, exit non-zero.
    let out = tendril(&[
        "ik",
        "--exact",
        "--position-only",
        "--pose",
        "0.3,0,0.2,1,0,0,0",
        "--json",
    ]);
    assert!(!out.status.success());
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["reachable"], false);
    assert!(v["position_error"].as_f64().unwrap() > 0.01);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("out of reach"), "{stderr}");
}

#[test]
fn exact_batch_writes_checked_rows_and_refuses_bad_input() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("poses.csv");
    let output = dir.path().join("tensions.csv");
    let a = fk_pose("2,0,0,0");
    let b = fk_pose("0,5,1,0");
    std::fs::write(
        &input,
        format!("px,py,pz,qw,qx,qy,qz\n{}\n{}\n", join(&a), join(&b)),
    )
    .unwrap();
    let (i, o) = (input.to_str().unwrap(), output.to_str().unwrap());
    let out = tendril(&[
        "ik",
        "--exact",
        "--position-only",
        "--input",
        i,
        "--output",
        o,
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = std::fs::read_to_string(&output).unwrap();
    let mut lines = text.lines();
    assert_eq!(
        lines.next().unwrap(),
        "t0,t1,t2,t3,px,py,pz,qw,qx,qy,qz,position_error,orientation_error,reachable"
    );
    for (line, pose) in lines.zip([&a, &b]) {
        let cells: Vec<&str> = line.split(',').collect();
        assert_eq!(cells[13], "1");
        let reached = fk_pose(&cells[..4].join(","));
        let err = (0..3)
            .map(|k| (reached[k] - pose[k]).powi(2))
            .sum::<f64>()
            .sqrt();
        assert!(err <= 1e-6, "{line}: tip {err:e} m from the target");
    }

    // A non-unit quaternion on line 3: one line naming it, nothing written.
    let bad_out = dir.path().join("bad.csv");
    std::fs::write(
        &input,
        format!("px,py,pz,qw,qx,qy,qz\n{}\n0.1,0,0.3,0.5,0,0,0\n", join(&a)),
    )
    .unwrap();
    let out = tendril(&[
        "ik",
        "--exact",
        "--input",
        i,
        "--output",
        bad_out.to_str().unwrap(),
    ]);
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(stderr.trim().lines().count(), 1, "{stderr}");
    assert!(
        stderr.contains("line 3") && stderr.contains("norm"),
        "{stderr}"
    );
    assert!(!bad_out.exists());
}

#[test]
fn evaluate_reports_net_alone_and_exact_refinement_side_by_side() {
    // The firmware's test-vector net was trained on the default robot.
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("d.csv");
    let json_out = dir.path().join("e.json");
    let d = data.to_str().unwrap();
    let gen = tendril(&[
        "generate",
        "--samples",
        "30",
        "--seed",
        "5",
        "--out",
        d,
        "--quiet",
    ]);
    assert!(
        gen.status.success(),
        "{}",
        String::from_utf8_lossy(&gen.stderr)
    );
    let out = tendril(&[
        "evaluate",
        "--model",
        "firmware/vectors/default.tnet",
        "--data",
        d,
        "--json-out",
        json_out.to_str().unwrap(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json_out).unwrap()).unwrap();
    let r = &v["refinement"];
    assert_eq!(r["rows"], 30);
    // Every row is a solved pose of the robot: reachable, and refined to a micron.
    assert_eq!(r["unreachable"], 0);
    assert_eq!(r["failed"], 0);
    let refined = r["refined_tip_error_mm"]["max"].as_f64().unwrap();
    let net = r["net_tip_error_mm"]["mean"].as_f64().unwrap();
    assert!(refined <= 1e-3, "refined max {refined} mm");
    assert!(net > refined, "net alone {net} mm vs refined {refined} mm");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(stdout.contains("net + exact IK"), "{stdout}");
}

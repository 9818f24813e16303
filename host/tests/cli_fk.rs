//! The `tendril fk` command-line contract of DESIGN §7, driven through the
//! real binary.

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

#[test]
fn fk_json_has_the_contract_keys_and_bends_toward_the_pulled_tendon() {
    let out = tendril(&[
        "fk",
        "--robot",
        "robots/seed-4t.toml",
        "--tensions",
        "2,0,0,0",
        "--json",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).expect("one JSON object");
    let p = v["position"].as_array().unwrap();
    let q = v["quaternion"].as_array().unwrap();
    assert_eq!(p.len(), 3);
    assert_eq!(q.len(), 4);
    assert_eq!(v["converged"], true);
    assert!(v["residual"].as_f64().unwrap() < 1e-9);
    assert!(v["iterations"].as_u64().is_some());
    // Tendon 0 at +x, gravity along +x: tip toward +x, rotation about +y.
    assert!(p[0].as_f64().unwrap() > 0.03);
    assert!(q[0].as_f64().unwrap() >= 0.0 && q[2].as_f64().unwrap() > 0.0);
    let norm: f64 = q.iter().map(|x| x.as_f64().unwrap().powi(2)).sum();
    assert!((norm - 1.0).abs() < 1e-12);
}

#[test]
fn fk_shape_reports_n_points_from_base_to_tip() {
    let out = tendril(&["fk", "--tensions", "0,3,0,0", "--json", "--shape", "5"]);
    assert!(out.status.success());
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let shape = v["shape"].as_array().unwrap();
    assert_eq!(shape.len(), 5);
    assert_eq!(shape[0], serde_json::json!([0.0, 0.0, 0.0]));
    let tip: Vec<f64> = shape[4]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect();
    let pos: Vec<f64> = v["position"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect();
    let d: f64 = tip
        .iter()
        .zip(&pos)
        .map(|(a, b)| (a - b).powi(2))
        .sum::<f64>()
        .sqrt();
    assert!(d < 1e-7, "shape tip {tip:?} vs position {pos:?}");
}

#[test]
fn fk_batch_adds_pose_columns_and_agrees_with_single_solves() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("t.csv");
    let output = dir.path().join("p.csv");
    std::fs::write(&input, "t0,t1,t2,t3\n2,0,0,0\n0,0,5,5\n").unwrap();
    let out = tendril(&[
        "fk",
        "--input",
        input.to_str().unwrap(),
        "--output",
        output.to_str().unwrap(),
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
        "t0,t1,t2,t3,px,py,pz,qw,qx,qy,qz,converged"
    );
    for (line, tensions) in lines.zip(["2,0,0,0", "0,0,5,5"]) {
        let fields: Vec<&str> = line.split(',').collect();
        assert_eq!(fields.len(), 12);
        assert_eq!(fields[11], "true");
        let single = tendril(&["fk", "--tensions", tensions, "--json"]);
        let v: serde_json::Value = serde_json::from_slice(&single.stdout).unwrap();
        for k in 0..3 {
            let batch: f64 = fields[4 + k].parse().unwrap();
            assert!((batch - v["position"][k].as_f64().unwrap()).abs() < 1e-9);
        }
    }
}

#[test]
fn bad_input_exits_non_zero_with_one_line_reason() {
    let cases: [&[&str]; 5] = [
        &["fk", "--tensions", "2,0,0"],
        &["fk", "--tensions", "2,0,-1,0"],
        &["fk", "--tensions", "2,0,nan,0"],
        &["fk", "--tensions", "2,x,0,0"],
        &["fk", "--robot", "robots/missing.toml", "--tensions", "1"],
    ];
    for args in cases {
        let out = tendril(args);
        assert!(!out.status.success(), "{args:?} succeeded");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.starts_with("tendril: error:"), "{args:?}: {err}");
        assert_eq!(err.trim_end().lines().count(), 1, "{args:?}: {err}");
        assert!(out.stdout.is_empty());
    }
}

#[test]
fn malformed_robot_file_error_names_file_and_field() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bent.toml");
    let text = std::fs::read_to_string(root().join("robots/seed-4t.toml")).unwrap();
    std::fs::write(
        &path,
        text.replacen("radius = 0.0009", "radius = -0.0009", 1),
    )
    .unwrap();
    let out = tendril(&[
        "fk",
        "--robot",
        path.to_str().unwrap(),
        "--tensions",
        "1,0,0,0",
    ]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("bent.toml") && err.contains("backbone.radius") && err.contains("positive"),
        "{err}"
    );
}

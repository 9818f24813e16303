//! `tendril calibrate` end to end on a tiny case (docs/design.md §11):
//! synthetic measurements of a heavier robot seen from an offset tracker,
//! the fit, the robot file other commands take, the planner, a bad input.

use std::path::Path;

use tendril_tests::{tendril, workspace_root as root};

fn ok(out: &std::process::Output) {
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

#[test]
fn calibrate_recovers_a_heavier_robot_and_writes_a_robot_file_fk_takes() {
    let dir = tempfile::tempdir().unwrap();
    let d = |f: &str| dir.path().join(f).to_str().unwrap().to_string();
    let nominal = root().join("robots/seed-4t.toml");
    let text = std::fs::read_to_string(&nominal).unwrap();
    // The "real" robot: 15 % heavier.
    let real = text.replace("density = 39317.0", "density = 45214.55");
    assert_ne!(real, text);
    std::fs::write(d("real.toml"), real).unwrap();
    ok(&tendril(&[
        "generate",
        "--robot",
        &d("real.toml"),
        "--samples",
        "60",
        "--noise-mm",
        "0.05",
        "--frame-offset-mm",
        "2,0,-1",
        "--out",
        &d("measured.csv"),
        "--quiet",
    ]));
    ok(&tendril(&[
        "calibrate",
        "--robot",
        nominal.to_str().unwrap(),
        "--data",
        &d("measured.csv"),
        "--fit",
        "density,base_t",
        "--positions-only",
        "--out",
        &d("cal.toml"),
    ]));
    for f in ["cal.toml", "cal.report.json", "cal.report.md", "cal.png"] {
        assert!(Path::new(&d(f)).exists(), "{f} missing");
    }
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d("cal.report.json")).unwrap()).unwrap();
    let density = report["parameters"]
        .as_array()
        .unwrap()
        .iter()
        .find(|p| p["name"] == "density")
        .unwrap();
    let fitted = density["fitted"].as_f64().unwrap();
    let hw = density["half_width_95"].as_f64().unwrap();
    assert!((fitted - 45214.55).abs() < 2.0 * hw, "{density}");
    let before = report["held_out_before"]["rms_m"].as_f64().unwrap();
    let after = report["held_out_after"]["rms_m"].as_f64().unwrap();
    // Jitter 0.05 mm per axis is 0.087 mm as a 3-D norm.
    assert!(
        before > 1e-3 && after < 1.5 * 0.087e-3,
        "{before} -> {after}"
    );
    // The calibrated file is a robot file every command takes.
    ok(&tendril(&[
        "fk",
        "--robot",
        &d("cal.toml"),
        "--tensions",
        "2,0,0,0",
        "--json",
    ]));
    // The planner proposes tension sets within the limits.
    ok(&tendril(&[
        "calibrate",
        "--plan",
        "5",
        "--robot",
        nominal.to_str().unwrap(),
        "--fit",
        "density,offsets",
        "--out",
        &d("plan.csv"),
    ]));
    let plan = std::fs::read_to_string(d("plan.csv")).unwrap();
    assert_eq!(plan.lines().count(), 6, "{plan}");
    assert!(plan.starts_with("t0,t1,t2,t3\n"));
}

#[test]
fn calibrate_names_a_missing_column() {
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("m.csv");
    std::fs::write(&csv, "t0,t1,t2,t3,px,py\n1,0,0,0,0,0\n").unwrap();
    let out = tendril(&[
        "calibrate",
        "--data",
        csv.to_str().unwrap(),
        "--out",
        dir.path().join("c.toml").to_str().unwrap(),
    ]);
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("m.csv") && err.contains("missing column pz"),
        "{err}"
    );
    assert!(!dir.path().join("c.toml").exists());
}

//! The `tendril fk` command-line contract of docs/design.md §7, driven through the
//! real binary.

use std::path::Path;
use std::process::Command;

use tendril_tests::{tendril, tendril_bin, workspace_root as root};

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

fn json_position(out: &std::process::Output) -> [f64; 3] {
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).expect("one JSON object");
    let p = v["position"].as_array().unwrap();
    [0, 1, 2].map(|k| p[k].as_f64().unwrap())
}

fn assert_one_line_error(args: &[&str], words: &str) {
    let out = tendril(args);
    assert!(!out.status.success(), "{args:?} succeeded");
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(err.trim_end().lines().count(), 1, "{args:?}: {err}");
    assert!(err.contains(words), "{args:?}: {err}");
    assert!(out.stdout.is_empty(), "{args:?}");
}

#[test]
fn two_segment_robot_tip_matches_the_tdcr_modeling_benchmark() {
    // docs/design.md §2.1: the public benchmark's Cosserat model, 6 digits.
    let p = json_position(&tendril(&[
        "fk",
        "--robot",
        "robots/tdcr-2seg.toml",
        "--tensions",
        "4,0,0,0,2,0",
        "--json",
    ]));
    let expected = [0.127608, 0.143467, 0.336407];
    for k in 0..3 {
        assert!((p[k] - expected[k]).abs() < 1e-6, "{p:?} vs {expected:?}");
    }
}

#[test]
fn tip_force_deflects_the_weightless_rod_as_a_cantilever() {
    // δ = F L³ / (3 E I) for a small force; tdcr-2seg has no gravity.
    let (e, r, l) = (54e9_f64, 0.0007_f64, 0.4_f64);
    let ei = e * std::f64::consts::PI * r.powi(4) / 4.0;
    let f = 1e-4;
    let p = json_position(&tendril(&[
        "fk",
        "--robot",
        "robots/tdcr-2seg.toml",
        "--tensions",
        "0,0,0,0,0,0",
        "--tip-force",
        "0,-1e-4,0",
        "--json",
    ]));
    let beam = f * l.powi(3) / (3.0 * ei);
    assert!((p[1] + beam).abs() / beam < 2e-3, "{p:?} vs -{beam}");
    // A tip moment about −x turns the tip toward +y: δ = M L² / (2 E I).
    let m = 1e-5;
    let p = json_position(&tendril(&[
        "fk",
        "--robot",
        "robots/tdcr-2seg.toml",
        "--tensions",
        "0,0,0,0,0,0",
        "--tip-moment",
        "-1e-5,0,0",
        "--json",
    ]));
    let beam = m * l.powi(2) / (2.0 * ei);
    assert!((p[1] - beam).abs() / beam < 2e-3, "{p:?} vs {beam}");
}

#[test]
fn bad_tip_loads_steps_and_tensions_give_one_line_errors() {
    assert_one_line_error(
        &["fk", "--tensions", "1,0,0,0", "--tip-force", "1,2"],
        "--tip-force: expected 3 numbers",
    );
    assert_one_line_error(
        &["fk", "--tensions", "1,0,0,0", "--tip-moment", "0,nan,0"],
        "--tip-moment: NaN is not a finite number",
    );
    assert_one_line_error(
        &["fk", "--tensions", "1,0,0,0", "--tip-force", "0,x,0"],
        "--tip-force: \"x\" is not a number",
    );
    // A leading minus is a value, rejected as a negative tension.
    assert_one_line_error(&["fk", "--tensions", "-1,0,0,0"], "negative");
    assert_one_line_error(&["fk", "--tensions", "1,0,0,0", "--steps", "0"], "--steps");
    assert_one_line_error(
        &["fk", "--tensions", "1,0,0,0", "--steps", "100000000"],
        "--steps",
    );
}

#[test]
fn tip_force_reaches_the_solution() {
    let plain = json_position(&tendril(&["fk", "--tensions", "2,0,0,0", "--json"]));
    let pushed = json_position(&tendril(&[
        "fk",
        "--tensions",
        "2,0,0,0",
        "--tip-force",
        "-0.5,0,0",
        "--json",
    ]));
    assert!(pushed[0] < plain[0] - 1e-3, "{pushed:?} vs {plain:?}");
}

fn run_batch(dir: &Path, input_text: &str, threads: &str) -> (bool, String, String) {
    let input = dir.join(format!("in-{threads}.csv"));
    let output = dir.join(format!("out-{threads}.csv"));
    std::fs::write(&input, input_text).unwrap();
    let out = Command::new(tendril_bin())
        .args([
            "fk",
            "--input",
            input.to_str().unwrap(),
            "--output",
            output.to_str().unwrap(),
        ])
        .env("RAYON_NUM_THREADS", threads)
        .current_dir(root())
        .output()
        .unwrap();
    (
        out.status.success(),
        std::fs::read_to_string(&output).unwrap_or_default(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn batch_results_do_not_depend_on_row_order_or_threads() {
    let dir = tempfile::tempdir().unwrap();
    // 150 rows on a scrambled lattice (deterministic, no RNG needed).
    let rows: Vec<String> = (0..150)
        .map(|k: u64| {
            let t = |m: u64| ((k * m + 7) % 101) as f64 / 10.1;
            format!("{},{},{},{}", t(37), t(53), t(71) * 0.3, t(89) * 0.2)
        })
        .collect();
    let forward = format!("t0,t1,t2,t3\n{}\n", rows.join("\n"));
    let mut reversed_rows = rows.clone();
    reversed_rows.reverse();
    let reversed = format!("t0,t1,t2,t3\n{}\n", reversed_rows.join("\n"));
    let (ok1, a, e1) = run_batch(dir.path(), &forward, "1");
    let (ok2, b, e2) = run_batch(dir.path(), &reversed, "2");
    assert!(ok1 && ok2, "{e1}{e2}");
    let mut a_lines: Vec<&str> = a.lines().collect();
    let mut b_lines: Vec<&str> = b.lines().collect();
    assert_eq!(a_lines.len(), 151);
    a_lines.sort_unstable();
    b_lines.sort_unstable();
    assert_eq!(
        a_lines, b_lines,
        "same rows, other order or threads, other bits"
    );
}

#[test]
fn batch_overwrites_pose_columns_and_reads_tip_loads() {
    let dir = tempfile::tempdir().unwrap();
    let input = "t0,t1,t2,t3,fx,fy,fz,mx,my,mz,px,py,pz,qw,qx,qy,qz,converged\n\
                 2,0,0,0,-0.5,0,0,0,0,0,9,9,9,9,9,9,9,false\n";
    let (ok, text, err) = run_batch(dir.path(), input, "1");
    assert!(ok, "{err}");
    let mut lines = text.lines();
    assert_eq!(
        lines.next().unwrap(),
        "t0,t1,t2,t3,fx,fy,fz,mx,my,mz,px,py,pz,qw,qx,qy,qz,converged"
    );
    let fields: Vec<&str> = lines.next().unwrap().split(',').collect();
    assert_eq!(fields.len(), 18);
    assert_eq!(fields[17], "true");
    let single = json_position(&tendril(&[
        "fk",
        "--tensions",
        "2,0,0,0",
        "--tip-force",
        "-0.5,0,0",
        "--json",
    ]));
    for k in 0..3 {
        let batch: f64 = fields[10 + k].parse().unwrap();
        assert!((batch - single[k]).abs() < 1e-9, "{batch} vs {single:?}");
    }
}

#[test]
fn batch_rejects_ambiguous_columns_and_single_pose_flags() {
    let dir = tempfile::tempdir().unwrap();
    let (ok, _, err) = run_batch(dir.path(), "t0,t1,t0,t2,t3\n1,0,2,0,0\n", "1");
    assert!(!ok && err.contains("column t0 appears twice"), "{err}");
    let input = dir.path().join("in-1.csv");
    let output = dir.path().join("o.csv");
    for flag in ["--json", "--shape=5", "--tip-force=1,0,0"] {
        let out = tendril(&[
            "fk",
            "--input",
            input.to_str().unwrap(),
            "--output",
            output.to_str().unwrap(),
            flag,
        ]);
        assert!(!out.status.success(), "{flag} accepted with --input");
        assert!(!output.exists());
    }
    let (ok, _, err) = run_batch(dir.path(), "t0,t1,t2\n1,0,2\n", "1");
    assert!(!ok && err.contains("(the robot has 4 tendons)"), "{err}");
}

/// A robot file with `[base]` (docs/design.md §2.4): `fk` gives the tip in
/// the tracker's frame — the plain file's tip moved by the rotation and
/// translation built here from the file's numbers — and `--base-frame`
/// gives the plain file's; `ik` (net and exact) takes a target in the
/// tracker's frame and answers with the plain file's tensions for the
/// base-frame target, the exact IK's reached pose back in the tracker's frame.
#[test]
fn a_base_pose_moves_fk_and_ik_into_the_trackers_frame() {
    use nalgebra::{Rotation3, UnitQuaternion, Vector3};
    let dir = tempfile::tempdir().unwrap();
    let text = std::fs::read_to_string(root().join("robots/seed-4t.toml")).unwrap();
    let (t, r) = (Vector3::new(0.2, 0.05, -0.1), Vector3::new(-0.3, 0.4, 1.0));
    let turned = dir.path().join("turned.toml");
    std::fs::write(
        &turned,
        format!(
            "{text}\n[base]\ntranslation = [{}, {}, {}]\nrotation = [{}, {}, {}]\n",
            t.x, t.y, t.z, r.x, r.y, r.z
        ),
    )
    .unwrap();
    let turned = turned.to_str().unwrap();
    let fk = |robot: &str, extra: &[&str]| -> (Vector3<f64>, UnitQuaternion<f64>) {
        let mut args = vec!["fk", "--robot", robot, "--tensions", "2,0.5,0,0", "--json"];
        args.extend_from_slice(extra);
        let out = tendril(&args);
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        let n = |a: &serde_json::Value, k: usize| a[k].as_f64().unwrap();
        let (p, q) = (&v["position"], &v["quaternion"]);
        (
            Vector3::new(n(p, 0), n(p, 1), n(p, 2)),
            UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(
                n(q, 0),
                n(q, 1),
                n(q, 2),
                n(q, 3),
            )),
        )
    };
    let (p_base, q_base) = fk("robots/seed-4t.toml", &[]);
    let (p, q) = fk(turned, &[]);
    let rot = Rotation3::new(r);
    assert!((p - (rot * p_base + t)).norm() < 1e-12, "{p} vs {p_base}");
    let q_expect = UnitQuaternion::from_rotation_matrix(&rot) * q_base;
    assert!(q.angle_to(&q_expect) < 1e-9);
    assert!(q.quaternion().w >= 0.0);
    let (p_flag, _) = fk(turned, &["--base-frame"]);
    assert_eq!(p_flag, p_base);

    let pose = |p: Vector3<f64>, q: UnitQuaternion<f64>| {
        let q = q.quaternion();
        format!("{},{},{},{},{},{},{}", p.x, p.y, p.z, q.w, q.i, q.j, q.k)
    };
    let tensions = |out: std::process::Output| -> Vec<f64> {
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        v["tensions"]
            .as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_f64().unwrap())
            .collect()
    };
    let net = "firmware/vectors/default.tnet";
    let (in_tracker, in_base) = (pose(p, q), pose(p_base, q_base));
    let by_net = tensions(tendril(&[
        "ik",
        "--model",
        net,
        "--robot",
        turned,
        "--pose",
        &in_tracker,
        "--json",
    ]));
    let by_net_base = tensions(tendril(&[
        "ik",
        "--model",
        net,
        "--robot",
        "robots/seed-4t.toml",
        "--pose",
        &in_base,
        "--json",
    ]));
    for (a, b) in by_net.iter().zip(&by_net_base) {
        assert!((a - b).abs() < 1e-4, "{by_net:?} vs {by_net_base:?}");
    }
    let exact = tendril(&[
        "ik",
        "--exact",
        "--position-only",
        "--robot",
        turned,
        "--pose",
        &in_tracker,
        "--json",
    ]);
    assert!(
        exact.status.success(),
        "{}",
        String::from_utf8_lossy(&exact.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&exact.stdout).unwrap();
    let reached: Vec<f64> = v["reached"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect();
    let got = Vector3::new(reached[0], reached[1], reached[2]);
    assert!((got - p).norm() < 1e-6, "reached {got} for {p}");
}

//! `tendril ik` never hands out an impossible tension: the cases of a hostile
//! probe (a non-unit quaternion, w < 0, a pose far outside the workspace,
//! px = 1e39, a zero quaternion, outputs beyond the tendon limits), driven
//! through the real binary with the firmware's built-in net for the seed robot.

use tendril_tests::{tendril, workspace_root};

const MODEL: &str = "firmware/vectors/default.tnet";
/// A pose from a generated dataset row (t = 0, 0, 2.19, 2.84 N).
const REACHABLE: [f64; 7] = [
    -0.0017361729555610112,
    -0.040367970340843176,
    0.3971615897926132,
    0.9944566157206342,
    0.10108433112606939,
    -0.028940347157138543,
    0.0006736146396597819,
];
/// Limit of every tendon of the seed robot, N.
const MAX_TENSION: f64 = 10.0;

fn pose_arg(p: &[f64]) -> String {
    let s: Vec<String> = p.iter().map(|x| x.to_string()).collect();
    format!("--pose={}", s.join(","))
}

/// Run `ik --json` on `pose`; (exit ok, parsed stdout if any, stderr).
fn ik(pose: &[f64], extra: &[&str]) -> (bool, Option<serde_json::Value>, String) {
    let arg = pose_arg(pose);
    let mut args = vec!["ik", "--model", MODEL, "--json", arg.as_str()];
    args.extend_from_slice(extra);
    let out = tendril(&args);
    let json = serde_json::from_slice(&out.stdout).ok();
    (
        out.status.success(),
        json,
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// What the firmware's command stage commands for the net's `raw` output on
/// the seed robot (co-contraction shift, then the clip).
fn staged(raw: &[f64]) -> Vec<f64> {
    let robot = tendril::robot::Robot::load(&workspace_root().join("robots/seed-4t.toml")).unwrap();
    let limits = tendril::command_stage::limits_for(&robot, 1.0).unwrap();
    tendril::command_stage::command_for(&limits, raw)
}

/// `a` and `b` agree to 1e-9 N (serde_json's float parsing may miss the
/// last bit).
fn same(a: &[f64], b: &[f64]) -> bool {
    a.len() == b.len() && a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-9)
}

fn numbers(v: &serde_json::Value) -> Vec<f64> {
    v.as_array()
        .expect("an array")
        .iter()
        .map(|x| x.as_f64().expect("a finite number"))
        .collect()
}

#[test]
fn a_reachable_pose_gets_tensions_within_the_limits_and_the_raw_output() {
    let (ok, json, err) = ik(&REACHABLE, &[]);
    assert!(ok, "{err}");
    let json = json.unwrap();
    let (t, raw) = (numbers(&json["tensions"]), numbers(&json["raw"]));
    assert_eq!((t.len(), raw.len()), (4, 4));
    assert!(t.iter().all(|a| (0.0..=MAX_TENSION).contains(a)), "{t:?}");
    assert!(same(&t, &staged(&raw)), "{t:?} vs {raw:?}");
    // The row was made by pulling tendons 2 and 3 (2.19 N, 2.84 N).
    assert!(
        (t[2] - 2.19).abs() < 0.5 && (t[3] - 2.84).abs() < 0.5,
        "{t:?}"
    );
}

#[test]
fn a_quaternion_with_negative_w_is_the_same_rotation() {
    let mut flipped = REACHABLE;
    for q in &mut flipped[3..] {
        *q = -*q;
    }
    let (ok_a, a, _) = ik(&REACHABLE, &[]);
    let (ok_b, b, err) = ik(&flipped, &[]);
    assert!(ok_a && ok_b, "{err}");
    assert_eq!(a.unwrap()["raw"], b.unwrap()["raw"]);
}

#[test]
fn non_unit_and_zero_quaternions_are_refused() {
    // The README's old example: |q| = 0.9963.
    let readme = [0.02, 0.01, 0.39, 0.99, -0.05, 0.1, 0.0];
    let zero = [0.0, 0.0, 0.4, 0.0, 0.0, 0.0, 0.0];
    for pose in [readme, zero] {
        let (ok, json, err) = ik(&pose, &["--allow-extrapolation"]);
        assert!(!ok && json.is_none(), "accepted {pose:?}");
        assert!(
            err.contains("not 1") && err.contains("unit quaternion"),
            "{err}"
        );
    }
}

#[test]
fn a_pose_far_outside_the_training_range_is_refused_or_clamped_when_allowed() {
    let far = [0.3, 0.0, 0.2, 1.0, 0.0, 0.0, 0.0];
    let (ok, _, err) = ik(&far, &[]);
    assert!(!ok);
    assert!(
        err.contains("px = 0.3 is outside the net's training range"),
        "{err}"
    );
    let (ok, json, err) = ik(&far, &["--allow-extrapolation"]);
    assert!(ok, "{err}");
    assert!(err.contains("extrapolates"), "{err}");
    let json = json.unwrap();
    let (t, raw) = (numbers(&json["tensions"]), numbers(&json["raw"]));
    assert!(t.iter().all(|x| (0.0..=MAX_TENSION).contains(x)), "{t:?}");
    // The net's own answer is impossible (hundreds of N, some negative): that is why it is clamped.
    assert!(
        raw.iter().any(|x| !(0.0..=MAX_TENSION).contains(x)),
        "{raw:?}"
    );
}

#[test]
fn outputs_beyond_the_tendon_limit_are_shifted_into_range_beside_the_raw_value() {
    // Just past the training range in px: the net asks for ~31 N of a 10 N
    // tendon and ~22 N of its opposite; the command stage lowers the pair
    // together (keeping its bend) instead of clipping one.
    let pose = [
        0.17,
        -0.08,
        0.34,
        0.9021620048402939,
        0.1901972676422696,
        0.3872051799119095,
        0.0009300824385327374,
    ];
    let (ok, json, err) = ik(&pose, &["--allow-extrapolation"]);
    assert!(ok, "{err}");
    let json = json.unwrap();
    let (t, raw) = (numbers(&json["tensions"]), numbers(&json["raw"]));
    assert!(raw.iter().any(|&x| x > MAX_TENSION), "{raw:?}");
    assert!(t.iter().all(|x| (0.0..=MAX_TENSION).contains(x)), "{t:?}");
    assert!(same(&t, &staged(&raw)), "{t:?} vs {raw:?}");
    assert!(
        ((t[0] - t[2]) - (raw[0] - raw[2])).abs() < 1e-5 && t[0] == MAX_TENSION,
        "{t:?} vs {raw:?}"
    );
    assert!(!err.contains("clipped"), "{err}");
    // Plain output prints the staged tensions.
    let arg = pose_arg(&pose);
    let out = tendril(&["ik", "--model", MODEL, "--allow-extrapolation", &arg]);
    let plain: Vec<f64> = String::from_utf8_lossy(&out.stdout)
        .trim()
        .split(',')
        .map(|s| s.parse().unwrap())
        .collect();
    assert_eq!(plain, t);
}

#[test]
fn a_huge_coordinate_never_gives_a_non_finite_tension() {
    let huge = [1e39, 0.0, 0.4, 1.0, 0.0, 0.0, 0.0];
    for extra in [&[][..], &["--allow-extrapolation"][..]] {
        let (ok, json, err) = ik(&huge, extra);
        assert!(!ok, "exit 0 for px = 1e39 ({extra:?})");
        assert!(json.is_none(), "printed {json:?}");
        assert!(err.starts_with("tendril: error:"), "{err}");
    }
    let (_, _, err) = ik(&[f64::NAN, 0.0, 0.4, 1.0, 0.0, 0.0, 0.0], &[]);
    assert!(err.contains("px = NaN is not a finite number"), "{err}");
}

#[test]
fn batch_output_has_clamped_and_raw_columns_and_refuses_bad_rows() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("poses.csv");
    let output = dir.path().join("t.csv");
    let row = |p: &[f64]| {
        p.iter()
            .map(|x| x.to_string())
            .collect::<Vec<_>>()
            .join(",")
    };
    std::fs::write(
        &input,
        format!("px,py,pz,qw,qx,qy,qz\n{}\n", row(&REACHABLE)),
    )
    .unwrap();
    let (i, o) = (input.to_str().unwrap(), output.to_str().unwrap());
    let out = tendril(&["ik", "--model", MODEL, "--input", i, "--output", o]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(String::from_utf8_lossy(&out.stderr).contains("(1 row,"));
    let text = std::fs::read_to_string(&output).unwrap();
    let mut lines = text.lines();
    assert_eq!(
        lines.next(),
        Some("t0,t1,t2,t3,raw_t0,raw_t1,raw_t2,raw_t3")
    );
    let cells: Vec<f64> = lines
        .next()
        .unwrap()
        .split(',')
        .map(|s| s.parse().unwrap())
        .collect();
    assert_eq!(cells[..4], staged(&cells[4..]));
    // A zero quaternion on line 3 fails the batch and keeps the old output.
    std::fs::write(
        &input,
        format!(
            "px,py,pz,qw,qx,qy,qz\n{}\n0,0,0.4,0,0,0,0\n",
            row(&REACHABLE)
        ),
    )
    .unwrap();
    let out = tendril(&["ik", "--model", MODEL, "--input", i, "--output", o]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("line 3") && err.contains("norm 0"), "{err}");
    assert_eq!(std::fs::read_to_string(&output).unwrap(), text);
    // The output may not be the input.
    let out = tendril(&["ik", "--model", MODEL, "--input", i, "--output", i]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("overwrite the input"));
}

#[test]
fn a_truncated_model_is_reported_once() {
    let dir = tempfile::tempdir().unwrap();
    let bytes = std::fs::read(workspace_root().join(MODEL)).unwrap();
    let model = dir.path().join("cut.tnet");
    std::fs::write(&model, &bytes[..100]).unwrap();
    let arg = pose_arg(&REACHABLE);
    let out = tendril(&["ik", "--model", model.to_str().unwrap(), &arg]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(err.matches("truncated").count(), 1, "{err}");
}

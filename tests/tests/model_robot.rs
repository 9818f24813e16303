//! A net knows its robot (issue 31, docs/design.md §5.1): `tendril train`
//! records the robot's fingerprint and the split in the `.tnet`; `ik`,
//! `evaluate`, `sim` and `controller` refuse a net trained for another
//! robot (a warning with `--allow-robot-mismatch`); `train` trains only for
//! the robot the data was generated with, and refuses data a net cannot
//! learn from.

use std::path::{Path, PathBuf};

use tendril_tests::{assert_ok, robot, stderr, tendril_in};

/// The seed robot with `edit` applied to its text, written to `dir/name`.
fn robot_variant(dir: &Path, name: &str, edit: impl Fn(String) -> String) -> PathBuf {
    let text = std::fs::read_to_string(robot("seed-4t.toml")).unwrap();
    let edited = edit(text.clone());
    let path = dir.join(name);
    std::fs::write(&path, edited).unwrap();
    path
}

/// The seed robot with Young's modulus halved (a rod half as stiff).
fn soft_robot(dir: &Path) -> PathBuf {
    robot_variant(dir, "soft.toml", |t| {
        let t = t.replace("name = \"seed-4t\"", "name = \"seed-4t-soft\"");
        let edited = t.replace("youngs_modulus = 207e9", "youngs_modulus = 103.5e9");
        assert_ne!(edited, t, "the seed robot's modulus line moved");
        edited
    })
}

/// A small dataset for the seed robot and a small net trained on it
/// (seed 1): `dir/d.csv`, `dir/m.tnet`.
fn data_and_net(dir: &Path) -> (PathBuf, PathBuf) {
    let seed = robot("seed-4t.toml");
    let o = tendril_in(
        dir,
        &[
            "generate",
            "--robot",
            seed.to_str().unwrap(),
            "--samples",
            "400",
            "--out",
            "d.csv",
        ],
    );
    assert_ok(&o, "generate");
    let o = tendril_in(dir, &train_args(&[]));
    assert_ok(&o, "train");
    (dir.join("d.csv"), dir.join("m.tnet"))
}

/// `tendril train` on `d.csv` → `m.tnet`, small and fast, plus `extra`.
fn train_args<'a>(extra: &[&'a str]) -> Vec<&'a str> {
    let mut a = vec![
        "train",
        "--data",
        "d.csv",
        "--out",
        "m.tnet",
        "--max-hidden",
        "2",
        "--pool",
        "2",
        "--threads",
        "1",
        "--seed",
        "1",
    ];
    a.extend_from_slice(extra);
    a
}

/// The pose of the first row of a dataset, as `--pose` text.
fn first_pose(data: &Path) -> String {
    let text = std::fs::read_to_string(data).unwrap();
    let row: Vec<&str> = text.lines().nth(1).unwrap().split(',').collect();
    row[row.len() - 7..].join(",")
}

#[test]
fn the_trained_net_records_its_robot_and_split() {
    let dir = tempfile::tempdir().unwrap();
    let (_, model) = data_and_net(dir.path());
    let bytes = std::fs::read(&model).unwrap();
    assert_eq!(bytes[4], 2, "a trained net is a version-2 .tnet");
    let p = tendril_shared::read_provenance(&bytes).unwrap().unwrap();
    let seed = tendril::robot::repo_robot("seed-4t.toml");
    assert_eq!(p.robot_sha256, seed.fingerprint());
    assert_eq!(p.robot_name(), "seed-4t");
    let split = p.split.unwrap();
    assert_eq!((split.seed, split.test_fraction), (1, 0.03));
}

#[test]
fn ik_refuses_a_net_for_a_robot_half_as_stiff_unless_allowed() {
    let dir = tempfile::tempdir().unwrap();
    let (data, _) = data_and_net(dir.path());
    let soft = soft_robot(dir.path());
    let pose = first_pose(&data);
    let ik = |robot: &Path, extra: &[&str]| {
        let mut a = vec![
            "ik",
            "--model",
            "m.tnet",
            "--robot",
            robot.to_str().unwrap(),
            "--pose",
            &pose,
            "--allow-extrapolation",
        ];
        a.extend_from_slice(extra);
        tendril_in(dir.path(), &a)
    };
    let refused = ik(&soft, &[]);
    let e = stderr(&refused);
    assert!(!refused.status.success(), "accepted: {e}");
    assert!(refused.stdout.is_empty(), "printed tensions anyway");
    for part in [
        "m.tnet",
        "robot seed-4t (",
        "robot seed-4t-soft (",
        "--allow-robot-mismatch",
    ] {
        assert!(e.contains(part), "{part:?} missing from: {e}");
    }
    let allowed = ik(&soft, &["--allow-robot-mismatch"]);
    assert_ok(&allowed, "ik --allow-robot-mismatch");
    assert!(
        stderr(&allowed).contains("trained for robot seed-4t"),
        "no warning: {}",
        stderr(&allowed)
    );
    // The right robot, and the same robot restyled (comments, spacing,
    // number spelling): accepted without a word.
    let restyled = robot_variant(dir.path(), "restyled.toml", |t| {
        format!(
            "# a copy\n\n{}",
            t.replace("youngs_modulus = 207e9", "youngs_modulus=2.07e11 # Pa")
        )
    });
    for r in [robot("seed-4t.toml"), restyled] {
        let o = ik(&r, &[]);
        assert_ok(&o, "ik with the net's robot");
        let e = stderr(&o);
        assert!(
            !e.contains("trained for robot") && !e.contains("does not record"),
            "{e}"
        );
    }
}

#[test]
fn sim_and_controller_refuse_a_net_for_another_robot_before_starting() {
    let dir = tempfile::tempdir().unwrap();
    data_and_net(dir.path());
    let soft = soft_robot(dir.path());
    let soft = soft.to_str().unwrap();
    let sim = tendril_in(
        dir.path(),
        &[
            "sim",
            "--robot",
            soft,
            "--model",
            "m.tnet",
            "--out",
            "sim",
            "--duration",
            "1",
        ],
    );
    let e = stderr(&sim);
    assert!(!sim.status.success(), "sim accepted it: {e}");
    assert!(
        e.contains("seed-4t-soft") && e.contains("--allow-robot-mismatch"),
        "{e}"
    );
    assert!(
        !dir.path().join("sim").exists(),
        "sim left an output directory"
    );
    let controller = tendril_in(
        dir.path(),
        &[
            "controller",
            "--robot",
            soft,
            "--model",
            "m.tnet",
            "--duration",
            "0.1",
            "--prefix",
            &format!("tendril-model-robot-{}", std::process::id()),
        ],
    );
    let e = stderr(&controller);
    assert!(!controller.status.success(), "controller accepted it: {e}");
    assert!(
        e.contains("seed-4t-soft") && e.contains("--allow-robot-mismatch"),
        "{e}"
    );
}

#[test]
fn evaluate_takes_the_nets_split_and_refuses_another_seed() {
    let dir = tempfile::tempdir().unwrap();
    data_and_net(dir.path());
    let seed = robot("seed-4t.toml");
    let eval = |extra: &[&str]| {
        let mut a = vec![
            "evaluate",
            "--model",
            "m.tnet",
            "--data",
            "d.csv",
            "--robot",
            seed.to_str().unwrap(),
            "--rows",
            "test",
        ];
        a.extend_from_slice(extra);
        tendril_in(dir.path(), &a)
    };
    let refused = eval(&["--seed", "2"]);
    let e = stderr(&refused);
    assert!(
        !refused.status.success(),
        "scored training rows as test rows: {e}"
    );
    assert!(
        e.contains("--seed 2") && e.contains("trained with (1)"),
        "{e}"
    );
    assert!(!dir.path().join("m.eval.json").exists());
    let refused = eval(&["--test-fraction", "0.2"]);
    assert!(!refused.status.success(), "{}", stderr(&refused));
    // The net's own split, taken from the net or given again.
    for extra in [&[][..], &["--seed", "1", "--test-fraction", "0.03"][..]] {
        let o = eval(extra);
        assert_ok(&o, "evaluate --rows test");
        let json: serde_json::Value =
            serde_json::from_slice(&std::fs::read(dir.path().join("m.eval.json")).unwrap())
                .unwrap();
        assert_eq!(json["rows"], "test");
    }
}

#[test]
fn train_refuses_a_robot_that_is_not_the_datas() {
    let dir = tempfile::tempdir().unwrap();
    data_and_net(dir.path());
    let soft = soft_robot(dir.path());
    let o = tendril_in(
        dir.path(),
        &train_args(&["--robot", soft.to_str().unwrap()]),
    );
    let e = stderr(&o);
    assert!(!o.status.success(), "trained for the wrong robot: {e}");
    assert!(
        e.contains("soft.toml") && e.contains("SHA-256") && e.contains("--allow-robot-mismatch"),
        "{e}"
    );
    let o = tendril_in(
        dir.path(),
        &train_args(&["--robot", soft.to_str().unwrap(), "--allow-robot-mismatch"]),
    );
    assert_ok(&o, "train --allow-robot-mismatch");
    assert!(stderr(&o).contains("not the robot the dataset was generated with"));
}

#[test]
fn train_resolves_the_recorded_robot_beside_the_sidecar_and_never_falls_back() {
    let dir = tempfile::tempdir().unwrap();
    let (gen, data, elsewhere) = (
        dir.path().join("gen"),
        dir.path().join("data"),
        dir.path().join("elsewhere"),
    );
    for d in [&gen, &data, &elsewhere] {
        std::fs::create_dir(d).unwrap();
    }
    // A robot other than the built-in default (the seed robot, half as
    // stiff), recorded by a relative path ("bot.toml").
    let soft = soft_robot(&gen);
    std::fs::rename(&soft, gen.join("bot.toml")).unwrap();
    let o = tendril_in(
        &gen,
        &[
            "generate",
            "--robot",
            "bot.toml",
            "--samples",
            "300",
            "--out",
            "../data/d.csv",
        ],
    );
    assert_ok(&o, "generate");
    let train = |extra: &[&str]| {
        let mut a = vec![
            "train",
            "--data",
            "../data/d.csv",
            "--out",
            "m.tnet",
            "--max-hidden",
            "1",
            "--pool",
            "1",
            "--threads",
            "1",
        ];
        a.extend_from_slice(extra);
        tendril_in(&elsewhere, &a)
    };
    // Not in the current directory, not beside the sidecar: refused, named.
    let o = train(&[]);
    let e = stderr(&o);
    assert!(!o.status.success(), "fell back to another robot: {e}");
    assert!(
        e.contains("bot.toml") && e.contains("does not exist"),
        "{e}"
    );
    assert!(!elsewhere.join("m.tnet").exists());
    // Beside the sidecar: found, and the net records it.
    std::fs::copy(gen.join("bot.toml"), data.join("bot.toml")).unwrap();
    assert_ok(&train(&[]), "train with the robot beside the sidecar");
    let bytes = std::fs::read(elsewhere.join("m.tnet")).unwrap();
    let p = tendril_shared::read_provenance(&bytes).unwrap().unwrap();
    assert_eq!(p.robot_name(), "seed-4t-soft");
    // Changed since the data was generated: the recorded SHA-256 catches it.
    let text = std::fs::read_to_string(data.join("bot.toml")).unwrap();
    std::fs::write(
        data.join("bot.toml"),
        text.replace("max_tension = 10.0", "max_tension = 12.0"),
    )
    .unwrap();
    std::fs::remove_file(elsewhere.join("m.tnet")).unwrap();
    let o = train(&[]);
    let e = stderr(&o);
    assert!(!o.status.success(), "trained for a changed robot: {e}");
    assert!(
        e.contains("has changed since the dataset was generated"),
        "{e}"
    );
    assert!(!elsewhere.join("m.tnet").exists());
}

#[test]
fn train_refuses_constant_tension_columns_naming_them() {
    let dir = tempfile::tempdir().unwrap();
    let (data, _) = data_and_net(dir.path());
    let text = std::fs::read_to_string(&data).unwrap();
    let zeroed: Vec<String> = text
        .lines()
        .enumerate()
        .map(|(i, line)| {
            if i == 0 {
                return line.to_string();
            }
            let mut cells: Vec<&str> = line.split(',').collect();
            cells[..4].fill("0");
            cells.join(",")
        })
        .collect();
    std::fs::write(dir.path().join("zero.csv"), zeroed.join("\n") + "\n").unwrap();
    let o = tendril_in(
        dir.path(),
        &[
            "train",
            "--data",
            "zero.csv",
            "--robot",
            robot("seed-4t.toml").to_str().unwrap(),
            "--out",
            "z.tnet",
            "--max-hidden",
            "1",
            "--pool",
            "1",
        ],
    );
    let e = stderr(&o);
    assert!(!o.status.success(), "trained on all-zero tensions: {e}");
    assert!(
        e.contains("t0 (always 0 N), t1 (always 0 N), t2 (always 0 N), t3"),
        "{e}"
    );
    assert!(!dir.path().join("z.tnet").exists());
}

#[test]
fn train_pool_zero_says_so_once() {
    let dir = tempfile::tempdir().unwrap();
    data_and_net(dir.path());
    let mut args = train_args(&[]);
    let at = args.iter().position(|&a| a == "--pool").unwrap();
    args[at + 1] = "0";
    let o = tendril_in(dir.path(), &args);
    let e = stderr(&o);
    assert!(!o.status.success());
    assert_eq!(e.matches("must be at least 1").count(), 1, "{e}");
}

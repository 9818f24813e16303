//! Bounded work and no quiet surprises (issue 31, `docs/design.md` §7):
//! sizes and durations are checked against their cost before work starts,
//! endless inputs are refused, big inputs stream, and a request that would
//! do nothing or ignore part of what was asked is refused by name.

use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};

use tendril_tests::{stderr, tendril_bin};

fn robot() -> PathBuf {
    tendril_tests::robot("seed-4t.toml")
}

fn tendril(dir: &Path, args: &[&str]) -> Output {
    Command::new(tendril_bin())
        .args(args)
        .current_dir(dir)
        .output()
        .expect("run tendril")
}

/// `tendril args` under a 2 GB address-space limit, so a regression that
/// reads or allocates without bound fails here instead of taking the machine.
fn tendril_capped(dir: &Path, args: &[&str]) -> Output {
    let mut cmd = Command::new("bash");
    cmd.arg("-c")
        .arg("ulimit -v 2000000; exec \"$0\" \"$@\"")
        .arg(tendril_bin())
        .args(args)
        .current_dir(dir);
    cmd.output().expect("run tendril under ulimit")
}

/// Exit 1 (a refusal, not a crash) with a message containing every `needle`.
fn refused(out: &Output, needles: &[&str]) {
    let err = stderr(out);
    assert_eq!(out.status.code(), Some(1), "{}: {err}", out.status);
    assert!(!err.contains("panicked"), "{err}");
    for n in needles {
        assert!(err.contains(n), "no `{n}` in: {err}");
    }
}

#[test]
fn a_dynamics_run_too_long_to_hold_is_refused_with_its_cost() {
    let dir = tempfile::tempdir().unwrap();
    let r = robot();
    for (duration, dt) in [("1e6", "0.001"), ("3", "1e-9")] {
        let out = tendril_capped(
            dir.path(),
            &[
                "dynamics",
                "--robot",
                r.to_str().unwrap(),
                "--tensions-step",
                "0,0,0,0:2,0,0,0@0.1",
                "--duration",
                duration,
                "--dt",
                dt,
                "--out",
                "dyn",
            ],
        );
        refused(&out, &["time steps; at most 2000000", "MB", "--duration"]);
        assert!(!dir.path().join("dyn/tip.csv").exists());
    }
}

#[test]
fn a_dynamics_step_after_the_end_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let out = tendril(
        dir.path(),
        &[
            "dynamics",
            "--robot",
            robot().to_str().unwrap(),
            "--tensions-step",
            "0,0,0,0:2,0,0,0@0.5",
            "--duration",
            "0.05",
            "--out",
            "dyn",
        ],
    );
    refused(&out, &["step at 0.5 s", "--duration 0.05 s"]);
    assert!(!dir.path().join("dyn/tip.csv").exists());
}

#[test]
fn an_endless_or_huge_robot_file_is_refused_without_reading_it_all() {
    let dir = tempfile::tempdir().unwrap();
    let out = tendril_capped(
        dir.path(),
        &["fk", "--robot", "/dev/zero", "--tensions", "1,0,0,0"],
    );
    refused(&out, &["/dev/zero", "not a regular file"]);
    let big = dir.path().join("big.toml");
    let file = std::fs::File::create(&big).unwrap();
    file.set_len(64 << 20).unwrap(); // sparse: 64 MiB of zeros
    let out = tendril_capped(
        dir.path(),
        &["fk", "--robot", "big.toml", "--tensions", "1,0,0,0"],
    );
    refused(&out, &["big.toml", "MiB"]);
}

/// Nets, pose tables and IK inputs that are endless or huge: refused (not a
/// regular file, too large, a line over 1 MiB) before memory runs out. The
/// careless-user pass had `ik --model /dev/zero` and `sim --poses /dev/zero`
/// killed by the kernel at 24 GB, and `ik --input /dev/zero` abort.
#[test]
fn endless_nets_pose_tables_and_ik_inputs_are_refused_without_reading_them_all() {
    let dir = tempfile::tempdir().unwrap();
    let net = tendril_tests::workspace_root().join("firmware/vectors/default.tnet");
    let net = net.to_str().unwrap();
    let pose = "0,0,0.38,1,0,0,0";
    let cases: [&[&str]; 6] = [
        &["ik", "--model", "/dev/zero", "--pose", pose],
        &[
            "sim",
            "--model",
            "/dev/zero",
            "--duration",
            "1",
            "--out",
            "s",
        ],
        &[
            "sim",
            "--trajectory",
            "csv",
            "--poses",
            "/dev/zero",
            "--duration",
            "1",
            "--out",
            "s",
        ],
        &[
            "ik",
            "--model",
            net,
            "--input",
            "/dev/zero",
            "--output",
            "o.csv",
        ],
        &["ik", "--exact", "--input", "/dev/zero", "--output", "o.csv"],
        &["evaluate", "--model", "/dev/zero", "--data", "d.csv"],
    ];
    for args in cases {
        let out = tendril_capped(dir.path(), args);
        refused(&out, &["/dev/zero"]);
        let err = stderr(&out);
        assert!(
            err.contains("not a regular file") || err.contains("longer than 1 MiB"),
            "{args:?}: {err}"
        );
    }
    let big = dir.path().join("big.tnet");
    std::fs::File::create(&big)
        .unwrap()
        .set_len(64 << 20)
        .unwrap();
    let out = tendril_capped(dir.path(), &["ik", "--model", "big.tnet", "--pose", pose]);
    refused(&out, &["big.tnet", "MiB"]);
}

/// `train --out /dev/full` wrote its learning curve into /dev
/// (`/dev/full.curve.png`) in the careless-user pass.
#[test]
fn train_to_a_device_names_where_its_companions_go_and_writes_nothing_beside_it() {
    let dir = tempfile::tempdir().unwrap();
    let out = tendril(
        dir.path(),
        &[
            "generate",
            "--robot",
            robot().to_str().unwrap(),
            "--samples",
            "200",
            "--out",
            "d.csv",
        ],
    );
    assert!(out.status.success(), "{}", stderr(&out));
    let out = tendril(
        dir.path(),
        &[
            "train",
            "--data",
            "d.csv",
            "--out",
            "/dev/full",
            "--max-hidden",
            "1",
        ],
    );
    refused(&out, &["/dev/full", "--plot"]);
    assert!(!Path::new("/dev/full.curve.png").exists());
    assert!(!Path::new("/dev/full.log.csv").exists());
}

#[test]
fn generate_refuses_the_test_fractions_train_refuses() {
    let dir = tempfile::tempdir().unwrap();
    for t in ["0", "0.9"] {
        let out = tendril(
            dir.path(),
            &[
                "generate",
                "--robot",
                robot().to_str().unwrap(),
                "--samples",
                "10",
                "--test-fraction",
                t,
                "--out",
                "d.csv",
            ],
        );
        refused(&out, &["--test-fraction must be in (0, 0.5]"]);
        assert!(!dir.path().join("d.csv").exists());
    }
}

#[test]
fn fk_with_tensions_writes_the_pose_to_output() {
    let dir = tempfile::tempdir().unwrap();
    let out = tendril(
        dir.path(),
        &[
            "fk",
            "--robot",
            robot().to_str().unwrap(),
            "--tensions",
            "2,0,0,0",
            "--output",
            "x.csv",
        ],
    );
    assert!(out.status.success(), "{}", stderr(&out));
    let text = std::fs::read_to_string(dir.path().join("x.csv")).expect("x.csv written");
    let mut lines = text.lines();
    let head: Vec<&str> = lines.next().unwrap().split(',').collect();
    assert_eq!(
        head,
        [
            "t0",
            "t1",
            "t2",
            "t3",
            "px",
            "py",
            "pz",
            "qw",
            "qx",
            "qy",
            "qz",
            "converged"
        ]
    );
    let row: Vec<&str> = lines.next().unwrap().split(',').collect();
    assert_eq!(row[0], "2");
    assert_eq!(row[11], "true");
    // The same pose as the batch path gives for the same row.
    std::fs::write(dir.path().join("in.csv"), "t0,t1,t2,t3\n2,0,0,0\n").unwrap();
    let batch = tendril(
        dir.path(),
        &[
            "fk",
            "--robot",
            robot().to_str().unwrap(),
            "--input",
            "in.csv",
            "--output",
            "b.csv",
        ],
    );
    assert!(batch.status.success(), "{}", stderr(&batch));
    assert_eq!(
        std::fs::read_to_string(dir.path().join("b.csv")).unwrap(),
        text
    );
}

#[test]
fn an_extra_tension_column_is_refused_by_name() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("in.csv"), "t0,t1,t2,t3,t4\n1,0,0,0,5\n").unwrap();
    let out = tendril(
        dir.path(),
        &[
            "fk",
            "--robot",
            robot().to_str().unwrap(),
            "--input",
            "in.csv",
            "--output",
            "o.csv",
        ],
    );
    refused(&out, &["in.csv", "t4", "4 tendons"]);
    assert!(!dir.path().join("o.csv").exists());
}

/// Peak resident set of `tendril fk --input` on `rows` rows, KiB.
fn fk_peak_rss_kib(dir: &Path, rows: usize) -> i64 {
    let input = dir.join(format!("in{rows}.csv"));
    let mut text = String::from("t0,t1,t2,t3\n");
    for k in 0..rows {
        // Distinct rows spread over the tension box.
        let a = (k % 97) as f64 * 0.02;
        let b = (k / 97 % 89) as f64 * 0.02;
        text.push_str(&format!("{a},{b},0,{}\n", (k % 7) as f64 * 0.1));
    }
    std::fs::write(&input, text).unwrap();
    // Reaped by wait4 below, which also returns its resource usage.
    #[allow(clippy::zombie_processes)]
    let child = Command::new(tendril_bin())
        .args(["fk", "--robot", robot().to_str().unwrap(), "--input"])
        .arg(&input)
        .arg("--output")
        .arg(dir.join(format!("out{rows}.csv")))
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let mut status = 0;
    // SAFETY: plain C structs filled by wait4 for the child this test started.
    let mut usage: libc::rusage = unsafe { std::mem::zeroed() };
    let pid = unsafe { libc::wait4(child.id() as i32, &mut status, 0, &mut usage) };
    assert_eq!(pid, child.id() as i32);
    assert!(libc::WIFEXITED(status) && libc::WEXITSTATUS(status) == 0);
    let lines = std::fs::read_to_string(dir.join(format!("out{rows}.csv")))
        .unwrap()
        .lines()
        .count();
    assert_eq!(lines, rows + 1);
    #[allow(clippy::unnecessary_cast)]
    let kib = usage.ru_maxrss as i64;
    kib
}

/// `fk --input` streams: its peak memory does not grow with the row count
/// (it used to hold every row, ≈ 390 bytes each: +15 MB here).
#[test]
fn fk_batch_memory_does_not_grow_with_the_rows() {
    let dir = tempfile::tempdir().unwrap();
    let small = fk_peak_rss_kib(dir.path(), 2_000);
    let large = fk_peak_rss_kib(dir.path(), 40_000);
    assert!(
        large < small + 5 * 1024,
        "peak RSS {small} KiB on 2,000 rows but {large} KiB on 40,000"
    );
}

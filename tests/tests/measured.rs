//! Learning from measured rows (issue 30 item 3, docs/design.md §3.1), with
//! real CLI processes at small size: a measured CSV (no sidecar) trains and
//! reports its outliers and noise floor; impossible rows are refused naming
//! line and column; leaving outliers out beats fitting them, judged on
//! held-out rows against the noiseless truth.

use std::path::{Path, PathBuf};
use std::process::Output;

use tendril_tests::{
    assert_ok, held_out_tip_mean_mm, json, robot, stderr, tendril_in, tip_mean_mm_on,
};

fn seed_robot() -> PathBuf {
    robot("seed-4t.toml")
}

/// `n` rows of the seed robot into `dir/clean.csv`, and the same rows seen
/// through a tracker (jitter `sigma_mm`, `outliers` of them 5 mm off) into
/// `dir/noisy.csv` without a sidecar, as measured rows come.
fn clean_and_noisy(dir: &Path, n: usize, sigma_mm: &str, outliers: &str) {
    let seed = seed_robot();
    let base = [
        "generate",
        "--robot",
        seed.to_str().unwrap(),
        "--samples",
        &n.to_string(),
        "--seed",
        "5",
        "--quiet",
    ];
    let o = tendril_in(dir, &[&base[..], &["--out", "clean.csv"]].concat());
    assert_ok(&o, "generate clean");
    let o = tendril_in(
        dir,
        &[
            &base[..],
            &[
                "--out",
                "noisy.csv",
                "--noise-mm",
                sigma_mm,
                "--outlier-fraction",
                outliers,
                "--outlier-mm",
                "5",
            ],
        ]
        .concat(),
    );
    assert_ok(&o, "generate noisy");
    std::fs::remove_file(dir.join("noisy.json")).unwrap();
}

/// Rows (0-based) whose tip in `noisy.csv` is more than 2 mm from
/// `clean.csv`'s: the injected outliers.
fn injected_outliers(dir: &Path) -> Vec<usize> {
    let (h, clean) = tendril_tests::csv(&dir.join("clean.csv"));
    let (_, noisy) = tendril_tests::csv(&dir.join("noisy.csv"));
    let px = tendril_tests::col(&h, "px");
    (0..clean.len())
        .filter(|&i| {
            let d: f64 = (0..3)
                .map(|k| (clean[i][px + k] - noisy[i][px + k]).powi(2))
                .sum();
            d.sqrt() > 2e-3
        })
        .collect()
}

fn train(dir: &Path, out: &str, extra: &[&str]) -> Output {
    let seed = seed_robot();
    let args = [
        &[
            "train",
            "--data",
            "noisy.csv",
            "--robot",
            seed.to_str().unwrap(),
            "--out",
            out,
            "--max-hidden",
            "12",
            "--test-fraction",
            "0.1",
            "--threads",
            "2",
        ][..],
        extra,
    ]
    .concat();
    tendril_in(dir, &args)
}

#[test]
fn a_measured_csv_without_a_sidecar_trains_and_finds_its_outliers_and_noise() {
    let dir = tempfile::tempdir().unwrap();
    let dir = dir.path();
    clean_and_noisy(dir, 600, "0.14", "0.02");
    let injected = injected_outliers(dir);
    assert_eq!(injected.len(), 12);

    // No sidecar: the robot is not guessed.
    let o = tendril_in(
        dir,
        &[
            "train",
            "--data",
            "noisy.csv",
            "--out",
            "m.tnet",
            "--max-hidden",
            "1",
        ],
    );
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(stderr(&o).contains("--robot"), "{}", stderr(&o));
    assert!(!dir.join("m.tnet").exists());

    assert_ok(&train(dir, "m.tnet", &[]), "train on measured rows");
    let report = json(&dir.join("m.train.json"));
    let m = &report["measured"];
    assert_eq!(m["outliers_rejected"], true, "{m}");
    // Every injected outlier among the training rows is found, and few
    // honest rows with it (test rows are never examined for the fit).
    let (_, test) = tendril::dataset::split_indices(600, 0.1, 1);
    let lines: Vec<usize> = m["outlier_lines"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_u64().unwrap() as usize)
        .collect();
    for i in injected.iter().filter(|i| !test.contains(i)) {
        assert!(
            lines.contains(&(i + 2)),
            "row {i} (line {}) not found: {lines:?}",
            i + 2
        );
    }
    assert!(
        lines.len() <= injected.len() + 3,
        "{lines:?} vs {injected:?}"
    );
    // The jitter estimated from the rows alone (0.14 mm was injected).
    let f = &m["noise_floor"];
    let sigma = f["noise_sigma_mm"].as_f64().unwrap();
    assert!((0.10..0.19).contains(&sigma), "{f}");
    assert_eq!(f["noise_source"], "local-fit", "{f}");
    // Judged against measured tips, the jitter dominates: a good net sits
    // near the floor (below it only by following the jitter it is asked
    // for), not far above it.
    let (rms, floor) = (
        f["held_out_rms_mm"].as_f64().unwrap(),
        f["floor_rms_mm"].as_f64().unwrap(),
    );
    assert!(rms >= 0.5 * floor && rms < 3.0 * floor, "{f}");

    // A given noise is used as given.
    assert_ok(
        &train(dir, "g.tnet", &["--noise-mm", "0.2"]),
        "train with --noise-mm",
    );
    let f = &json(&dir.join("g.train.json"))["measured"]["noise_floor"];
    assert_eq!(f["noise_source"], "given", "{f}");
    assert_eq!(f["noise_sigma_mm"].as_f64(), Some(0.2), "{f}");
}

/// `train` and `compare` refuse `text` (a dataset with one bad row),
/// naming `needles` (line and column).
fn refused(text: &str, needles: &[&str]) {
    let dir = tempfile::tempdir().unwrap();
    let dir = dir.path();
    std::fs::write(dir.join("bad.csv"), text).unwrap();
    let seed = seed_robot();
    let seed = seed.to_str().unwrap();
    for args in [
        &[
            "train", "--data", "bad.csv", "--robot", seed, "--out", "m.tnet",
        ][..],
        &[
            "compare", "--data", "bad.csv", "--robot", seed, "--out", "o",
        ][..],
    ] {
        let o = tendril_in(dir, args);
        let err = stderr(&o);
        assert_eq!(o.status.code(), Some(1), "{args:?}: {err}");
        for n in needles {
            assert!(err.contains(n), "{args:?}: expected {n:?} in {err}");
        }
        assert!(!err.contains("panicked"), "{err}");
        assert!(!dir.join("m.tnet").exists() && !dir.join("o").exists());
    }
}

#[test]
fn impossible_rows_are_refused_naming_line_and_column() {
    let head = "t0,t1,t2,t3,px,py,pz,qw,qx,qy,qz\n";
    let good = "1,2,0,0,0.01,0.002,0.39,1,0,0,0\n";
    let with = |bad: &str| format!("{head}{good}{good}{bad}{good}");
    refused(
        &with("1,2,0,0,NaN,0.002,0.39,1,0,0,0\n"),
        &["line 4", "px", "not finite"],
    );
    refused(
        &with("1,2,0,0,0.01,0.002,0.39,1,0,0\n"),
        &["line 4", "10 fields", "11"],
    );
    refused(
        &with("1,2,0,0,0.01,0.002,0.39,1,0,0,0,7\n"),
        &["line 4", "12 fields"],
    );
    refused(
        &with("1,-0.5,0,0,0.01,0.002,0.39,1,0,0,0\n"),
        &["line 4", "t1", "negative"],
    );
    refused(
        &with("1,2,0,11,0.01,0.002,0.39,1,0,0,0\n"),
        &["line 4", "t3", "max_tension"],
    );
    refused(
        &with("1,2,0,0,0.01,0.002,0.39,0.7,0,0,0\n"),
        &["line 4", "qw,qx,qy,qz", "norm"],
    );
}

/// Held-out tip error (mean, mm) of `model` against the noiseless rows, on
/// the robot that made them.
fn held_out_against_truth(dir: &Path, model: &str) -> f64 {
    held_out_tip_mean_mm(dir, model, "clean.csv", &seed_robot())
}

#[test]
fn leaving_outliers_out_beats_fitting_them_on_held_out_truth() {
    let dir = tempfile::tempdir().unwrap();
    let dir = dir.path();
    // 5 % of the rows 5 mm off, little jitter: the outliers dominate what
    // a plain fit gets wrong.
    clean_and_noisy(dir, 1000, "0.05", "0.05");
    assert_ok(
        &train(dir, "keep.tnet", &["--outliers", "keep"]),
        "train keeping outliers",
    );
    assert_ok(
        &train(dir, "reject.tnet", &["--outliers", "reject"]),
        "train rejecting outliers",
    );
    let keep = held_out_against_truth(dir, "keep.tnet");
    let reject = held_out_against_truth(dir, "reject.tnet");
    eprintln!(
        "held-out tip mean against the truth: plain fit {keep:.3} mm, robust fit {reject:.3} mm"
    );
    assert!(
        reject < 0.8 * keep,
        "robust fit {reject} mm vs plain fit {keep} mm (held-out mean, against the truth)"
    );
}

#[test]
fn rows_below_the_robots_floors_a_stale_sidecar_and_copied_rows_are_not_taken_at_face_value() {
    let dir = tempfile::tempdir().unwrap();
    let dir = dir.path();
    clean_and_noisy(dir, 200, "0.1", "0");
    // The seed robot's rows (tensions from 0 N) for a robot whose floors
    // are 5 N: refused, naming the floor.
    let paper = robot("seed-paper.toml");
    let o = tendril_in(
        dir,
        &[
            "train",
            "--data",
            "noisy.csv",
            "--robot",
            paper.to_str().unwrap(),
            "--out",
            "p.tnet",
        ],
    );
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(stderr(&o).contains("min_tension"), "{}", stderr(&o));
    assert!(!dir.join("p.tnet").exists());

    // Measured rows saved over a generated CSV, its sidecar left beside:
    // the rows are measured, and the warning says why.
    std::fs::copy(dir.join("noisy.csv"), dir.join("stale.csv")).unwrap();
    std::fs::copy(dir.join("clean.json"), dir.join("stale.json")).unwrap();
    let seed = seed_robot();
    let seed = seed.to_str().unwrap();
    let o = tendril_in(
        dir,
        &[
            "train",
            "--data",
            "stale.csv",
            "--robot",
            seed,
            "--out",
            "s.tnet",
            "--max-hidden",
            "2",
        ],
    );
    assert_ok(&o, "train beside a stale sidecar");
    assert!(stderr(&o).contains("stale sidecar"), "{}", stderr(&o));
    assert!(json(&dir.join("s.train.json"))["measured"].is_object());

    // The file twice over: the copies are dropped, not read as repeats
    // (which would give a noise floor of 0).
    let text = std::fs::read_to_string(dir.join("noisy.csv")).unwrap();
    let body: String = text.lines().skip(1).map(|l| format!("{l}\n")).collect();
    std::fs::write(dir.join("twice.csv"), format!("{text}{body}")).unwrap();
    let o = tendril_in(
        dir,
        &[
            "train",
            "--data",
            "twice.csv",
            "--robot",
            seed,
            "--out",
            "t.tnet",
            "--max-hidden",
            "2",
        ],
    );
    assert_ok(&o, "train on a doubled file");
    assert!(
        stderr(&o).contains("200 rows copy an earlier row"),
        "{}",
        stderr(&o)
    );
    let f = &json(&dir.join("t.train.json"))["measured"]["noise_floor"];
    assert_ne!(f["noise_source"], "repeated-rows", "{f}");
}

/// `train --init` (docs/design.md §4, "Fine-tune on measured rows"): the
/// default net of the seed robot's file, polished on 600 measured rows of a
/// robot 8 % softer than that file, is closer to that robot on rows it never
/// saw (judged against the noiseless truth through the real robot's own
/// statics) than the net it started from; a start net for another robot is
/// refused naming both.
#[test]
fn a_net_fine_tuned_on_a_real_robots_rows_beats_the_net_it_started_from() {
    let dir = tempfile::tempdir().unwrap();
    let dir = dir.path();
    let text = std::fs::read_to_string(seed_robot()).unwrap();
    let real = text.replace("youngs_modulus = 207e9", "youngs_modulus = 190.44e9");
    assert_ne!(real, text, "the robot file's modulus line moved");
    std::fs::write(dir.join("real.toml"), real).unwrap();
    let base = [
        "generate",
        "--robot",
        "real.toml",
        "--samples",
        "600",
        "--seed",
        "5",
        "--quiet",
    ];
    assert_ok(
        &tendril_in(dir, &[&base[..], &["--out", "clean.csv"]].concat()),
        "generate clean",
    );
    assert_ok(
        &tendril_in(
            dir,
            &[&base[..], &["--out", "noisy.csv", "--noise-mm", "0.05"]].concat(),
        ),
        "generate noisy",
    );
    std::fs::remove_file(dir.join("noisy.json")).unwrap();
    // A copy in the test's directory: what is written beside a model (the
    // evaluation's JSON) stays out of the checkout.
    std::fs::copy(
        tendril_tests::workspace_root().join("firmware/vectors/default.tnet"),
        dir.join("start.tnet"),
    )
    .unwrap();
    let start = "start.tnet";
    let o = train(dir, "tuned.tnet", &["--init", start, "--polish", "300"]);
    assert_ok(&o, "fine-tune");
    let report = json(&dir.join("tuned.train.json"));
    assert!(
        report["report"]["polish"]["iterations"].as_u64().unwrap() > 0,
        "{}",
        report["report"]
    );
    // Both nets on the same rows, which neither saw: fresh draws of the
    // real robot (the start net learned the seed robot's own data, the
    // tuned one the noisy rows of seed 5).
    assert_ok(
        &tendril_in(
            dir,
            &[
                "generate",
                "--robot",
                "real.toml",
                "--samples",
                "200",
                "--seed",
                "6",
                "--quiet",
                "--out",
                "fresh.csv",
            ],
        ),
        "generate fresh",
    );
    let real = dir.join("real.toml");
    let on_fresh = |model: &str| {
        tip_mean_mm_on(
            dir,
            model,
            "fresh.csv",
            &real,
            "all",
            &["--allow-robot-mismatch"],
        )
    };
    let (before, after) = (on_fresh(start), on_fresh("tuned.tnet"));
    eprintln!(
        "held-out tip mean on the real robot: start {before:.3} mm, fine-tuned {after:.3} mm"
    );
    assert!(before > 0.3, "the start net is already within {before} mm");
    assert!(
        after < 0.5 * before,
        "fine-tuned {after} mm vs the start {before} mm"
    );

    // A start net for another robot is refused, naming both.
    let o = tendril_in(
        dir,
        &[
            "train",
            "--data",
            "noisy.csv",
            "--robot",
            "real.toml",
            "--init",
            start,
            "--out",
            "refused.tnet",
        ],
    );
    let err = stderr(&o);
    assert!(!o.status.success(), "{err}");
    assert!(
        err.contains("seed-4t") && err.contains("allow-robot-mismatch"),
        "{err}"
    );
    assert!(!dir.join("refused.tnet").exists());
}

//! `tendril train`, `evaluate`, `compare` and `robustness` refuse requests
//! that cannot give a meaningful result or would destroy a file — with a one-line error,
//! a non-zero exit, and every existing file as it was (`docs/design.md` §7).

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

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

/// A temporary directory with `data.csv` (`rows` rows of the seed robot).
fn with_data(rows: usize) -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    let out = tendril(
        dir.path(),
        &[
            "generate",
            "--robot",
            robot().to_str().unwrap(),
            "--samples",
            &rows.to_string(),
            "--out",
            "data.csv",
        ],
    );
    assert!(out.status.success(), "{}", stderr(&out));
    dir
}

/// `data.csv` plus a small trained `m.tnet` beside it.
fn with_model() -> tempfile::TempDir {
    let dir = with_data(300);
    let out = tendril(
        dir.path(),
        &[
            "train",
            "--data",
            "data.csv",
            "--out",
            "m.tnet",
            "--max-hidden",
            "2",
        ],
    );
    assert!(out.status.success(), "{}", stderr(&out));
    dir
}

fn refused(out: &Output, needle: &str) {
    let err = stderr(out);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.contains(needle), "expected {needle:?} in: {err}");
    assert!(!err.contains("panicked"), "{err}");
}

#[test]
fn train_on_too_few_rows_is_refused_and_writes_nothing() {
    let dir = with_data(30);
    let out = tendril(
        dir.path(),
        &["train", "--data", "data.csv", "--out", "m.tnet"],
    );
    refused(&out, "at least 50");
    assert!(!dir.path().join("m.tnet").exists());
    assert!(!dir.path().join("m.log.csv").exists());
}

#[test]
fn train_test_fraction_outside_its_range_is_refused() {
    let dir = with_data(100);
    for bad in ["0.99", "0.6", "0", "NaN"] {
        let out = tendril(
            dir.path(),
            &[
                "train",
                "--data",
                "data.csv",
                "--out",
                "m.tnet",
                "--test-fraction",
                bad,
            ],
        );
        refused(&out, "--test-fraction must be in (0, 0.5]");
    }
    assert!(!dir.path().join("m.tnet").exists());
}

#[test]
fn train_polish_settings_no_polish_can_run_with_are_refused() {
    let dir = with_data(100);
    for (flag, bad, needle) in [
        ("--polish-memory", "0", "--polish-memory must be at least 1"),
        (
            "--polish-robust",
            "-1",
            "--polish-robust must be a finite number",
        ),
        (
            "--polish-robust",
            "NaN",
            "--polish-robust must be a finite number",
        ),
    ] {
        let out = tendril(
            dir.path(),
            &["train", "--data", "data.csv", "--out", "m.tnet", flag, bad],
        );
        refused(&out, needle);
    }
    assert!(!dir.path().join("m.tnet").exists());
}

#[test]
fn train_log_over_its_own_model_is_refused_and_the_model_kept() {
    let dir = with_model();
    let model = std::fs::read(dir.path().join("m.tnet")).unwrap();
    for (flag, target) in [
        ("--log", "m.tnet"),
        ("--report", "./m.tnet"),
        ("--plot", "data.csv"),
    ] {
        let out = tendril(
            dir.path(),
            &[
                "train", "--data", "data.csv", "--out", "m.tnet", flag, target,
            ],
        );
        refused(&out, "refusing to overwrite");
        assert_eq!(std::fs::read(dir.path().join("m.tnet")).unwrap(), model);
    }
    let out = tendril(
        dir.path(),
        &["train", "--data", "data.csv", "--out", "data.csv"],
    );
    refused(&out, "--out data.csv is the same file as --data");
}

#[test]
fn evaluate_json_over_its_model_or_data_is_refused() {
    let dir = with_model();
    let model = std::fs::read(dir.path().join("m.tnet")).unwrap();
    let data = std::fs::read(dir.path().join("data.csv")).unwrap();
    let r = robot();
    for target in ["m.tnet", "data.csv"] {
        let out = tendril(
            dir.path(),
            &[
                "evaluate",
                "--model",
                "m.tnet",
                "--data",
                "data.csv",
                "--robot",
                r.to_str().unwrap(),
                "--json-out",
                target,
            ],
        );
        refused(&out, "refusing to overwrite");
    }
    assert_eq!(std::fs::read(dir.path().join("m.tnet")).unwrap(), model);
    assert_eq!(std::fs::read(dir.path().join("data.csv")).unwrap(), data);
}

#[test]
fn evaluate_test_fraction_above_one_half_is_refused() {
    let dir = with_model();
    let r = robot();
    let out = tendril(
        dir.path(),
        &[
            "evaluate",
            "--model",
            "m.tnet",
            "--data",
            "data.csv",
            "--robot",
            r.to_str().unwrap(),
            "--rows",
            "test",
            "--test-fraction",
            "1.5",
        ],
    );
    refused(&out, "--test-fraction must be in (0, 0.5]");
    assert!(!dir.path().join("m.eval.json").exists());
}

/// One row and `--rows test`: the split holds no row. It used to print
/// RMSE 0.0000 and "NaN ns/query" and exit 0.
#[test]
fn evaluate_with_no_row_to_evaluate_is_an_error() {
    let dir = with_model();
    let text = std::fs::read_to_string(dir.path().join("data.csv")).unwrap();
    let one: String = text.lines().take(2).map(|l| format!("{l}\n")).collect();
    std::fs::write(dir.path().join("one.csv"), one).unwrap();
    let r = robot();
    let out = tendril(
        dir.path(),
        &[
            "evaluate",
            "--model",
            "m.tnet",
            "--data",
            "one.csv",
            "--robot",
            r.to_str().unwrap(),
            "--rows",
            "test",
        ],
    );
    refused(&out, "no rows to evaluate");
    assert!(!String::from_utf8_lossy(&out.stdout).contains("NaN"));
    assert!(!dir.path().join("m.eval.json").exists());
}

#[test]
fn compare_output_over_its_data_is_refused() {
    let dir = with_data(60);
    std::fs::create_dir(dir.path().join("cmp")).unwrap();
    std::fs::copy(
        dir.path().join("data.csv"),
        dir.path().join("cmp/compare.csv"),
    )
    .unwrap();
    let before = std::fs::read(dir.path().join("cmp/compare.csv")).unwrap();
    let r = robot();
    let out = tendril(
        dir.path(),
        &[
            "compare",
            "--data",
            "cmp/compare.csv",
            "--robot",
            r.to_str().unwrap(),
            "--out",
            "cmp",
        ],
    );
    refused(&out, "refusing to overwrite");
    assert_eq!(
        std::fs::read(dir.path().join("cmp/compare.csv")).unwrap(),
        before
    );
}

/// A reality file named `name` in `dir`, the `ideal` reality otherwise.
fn reality_file(dir: &Path, file: &str, name: &str) -> PathBuf {
    let path = dir.join(file);
    std::fs::write(&path, format!("name = {name:?}\n")).unwrap();
    path
}

#[test]
fn a_reality_named_like_a_path_is_refused_and_nothing_is_made_outside_out() {
    let dir = tempfile::tempdir().unwrap();
    for (i, name) in ["../escaped", "/tmp/tendril-escaped-abs"]
        .iter()
        .enumerate()
    {
        let file = reality_file(dir.path(), &format!("r{i}.toml"), name);
        let out = tendril(
            dir.path(),
            &[
                "robustness",
                "--realities",
                file.to_str().unwrap(),
                "--out",
                "s/t",
            ],
        );
        refused(&out, "name");
        assert!(stderr(&out).contains("'/'"), "{}", stderr(&out));
    }
    assert!(!dir.path().join("escaped").exists());
    assert!(
        !dir.path().join("s").exists(),
        "a refused table left its directory"
    );
    assert!(!Path::new("/tmp/tendril-escaped-abs").exists());
}

#[test]
fn two_realities_of_one_name_and_an_out_that_is_a_file_are_refused_before_any_run() {
    let dir = tempfile::tempdir().unwrap();
    let a = reality_file(dir.path(), "a.toml", "same");
    let b = reality_file(dir.path(), "b.toml", "same");
    let list = format!("{},{}", a.display(), b.display());
    let out = tendril(
        dir.path(),
        &["robustness", "--realities", &list, "--out", "s"],
    );
    refused(&out, "both named \"same\"");
    assert!(!dir.path().join("s").exists());

    std::fs::write(dir.path().join("table.md"), "mine").unwrap();
    let started = std::time::Instant::now();
    let out = tendril(
        dir.path(),
        &["robustness", "--realities", "ideal", "--out", "table.md"],
    );
    refused(&out, "not a directory");
    assert!(
        started.elapsed() < std::time::Duration::from_secs(10),
        "ran first"
    );
    assert_eq!(
        std::fs::read_to_string(dir.path().join("table.md")).unwrap(),
        "mine"
    );
}

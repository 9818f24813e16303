//! Helpers for the process-level tests in `tests/tests/`: locating the
//! `tendril` binary that `cargo test` built, running it, and reading the
//! numeric CSV logs its processes write.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// Root of the workspace (where `robots/` lives).
pub fn workspace_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("tests/ sits inside the workspace")
        .to_path_buf()
}

/// Path of the `tendril` binary built by the same `cargo test` invocation.
///
/// Cargo builds a package's binaries whenever that package's integration
/// tests are built (`host/tests/` guarantees this for `cargo test --workspace`),
/// and puts them next to the `deps/` directory holding this test executable.
pub fn tendril_bin() -> PathBuf {
    let exe = std::env::current_exe().expect("current test executable");
    let dir = exe
        .parent()
        .and_then(Path::parent)
        .expect("test executable lives in target/<profile>/deps");
    let bin = dir.join(format!("tendril{}", std::env::consts::EXE_SUFFIX));
    assert!(
        bin.exists(),
        "{} not built: run `cargo test --workspace` (or `cargo build -p tendril`) first",
        bin.display()
    );
    bin
}

/// Run `tendril` with `args` from the workspace root and capture its output.
pub fn tendril(args: &[&str]) -> Output {
    Command::new(tendril_bin())
        .args(args)
        .current_dir(workspace_root())
        .output()
        .expect("spawn tendril")
}

/// Path of a robot file in `robots/`.
pub fn robot(name: &str) -> PathBuf {
    workspace_root().join("robots").join(name)
}

/// Rows of a numeric CSV log with its header. Rows that do not parse as
/// numbers, or have the wrong width, are left out (a log cut by a kill).
pub fn csv(path: &Path) -> (Vec<String>, Vec<Vec<f64>>) {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let mut lines = text.lines();
    let header: Vec<String> = lines
        .next()
        .expect("header")
        .split(',')
        .map(str::to_string)
        .collect();
    let rows = lines
        .filter_map(|l| {
            l.split(',')
                .map(|x| x.parse::<f64>().ok())
                .collect::<Option<Vec<_>>>()
        })
        .filter(|r| r.len() == header.len())
        .collect();
    (header, rows)
}

/// Index of column `name` in a CSV header.
pub fn col(header: &[String], name: &str) -> usize {
    header
        .iter()
        .position(|h| h == name)
        .unwrap_or_else(|| panic!("no column {name}"))
}

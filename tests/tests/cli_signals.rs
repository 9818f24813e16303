//! Process-level contract of the `tendril` binary under signals
//! (`docs/design.md` §7): a closed stdout ends it quietly, and the first
//! Ctrl-C stops a training run without touching its existing outputs.

use std::io::{BufRead, BufReader};
use std::path::PathBuf;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use tendril_tests::tendril_bin;

fn robot() -> PathBuf {
    tendril_tests::robot("seed-4t.toml")
}

fn tendril() -> Command {
    Command::new(tendril_bin())
}

/// `tendril fk … | head`: the reader leaves after one byte of a long
/// output, so the next write meets a broken pipe. The process must end
/// without a panic (it used to exit 101, "failed printing to stdout").
#[test]
fn fk_piped_into_head_exits_without_a_panic() {
    let script = format!(
        "{} fk --robot {} --tensions 2,0,0,0 --json --shape 5000 | head -c 1 >/dev/null; exit ${{PIPESTATUS[0]}}",
        tendril_bin().display(),
        robot().display()
    );
    let out = Command::new("bash")
        .args(["-c", &script])
        .output()
        .expect("run bash");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_ne!(out.status.code(), Some(101), "{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
}

/// Ctrl-C once during `tendril train`: exit 130, and the model, log, curve
/// and report that were there before are byte-identical, with no temporary
/// file left beside them.
#[test]
fn first_ctrl_c_stops_training_and_keeps_existing_outputs() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data.csv");
    let gen = tendril()
        .args(["generate", "--samples", "3000", "--out"])
        .arg(&data)
        .arg("--robot")
        .arg(robot())
        .output()
        .expect("run tendril generate");
    assert!(
        gen.status.success(),
        "{}",
        String::from_utf8_lossy(&gen.stderr)
    );

    let model = dir.path().join("m.tnet");
    let siblings = ["m.tnet", "m.log.csv", "m.curve.png", "m.train.json"];
    for (i, name) in siblings.iter().enumerate() {
        std::fs::write(dir.path().join(name), format!("earlier output {i}")).unwrap();
    }
    let before: Vec<Vec<u8>> = siblings
        .iter()
        .map(|n| std::fs::read(dir.path().join(n)).unwrap())
        .collect();

    // Slow settings (all rows for every candidate, a large pool, one thread)
    // so that training is still running when the signal arrives; `-v`
    // prints a line per installed unit, which tells us it is.
    let mut child = tendril()
        .args([
            "-v",
            "train",
            "--threads",
            "1",
            "--pool",
            "16",
            "--cand-patterns",
            "0",
        ])
        .args(["--valid-patience", "64", "--pilot-units", "6", "--data"])
        .arg(&data)
        .arg("--out")
        .arg(&model)
        .stderr(Stdio::piped())
        .stdout(Stdio::null())
        .spawn()
        .expect("start tendril train");
    let mut stderr = BufReader::new(child.stderr.take().unwrap());
    let mut log = String::new();
    let mut line = String::new();
    while stderr.read_line(&mut line).unwrap() > 0 {
        log.push_str(&line);
        if line.contains(" unit ") {
            break;
        }
        line.clear();
    }
    assert!(
        log.contains(" unit "),
        "training never started a unit:\n{log}"
    );
    let pid = i32::try_from(child.id()).unwrap();
    // SAFETY: plain kill(2) on our own child's pid.
    assert_eq!(unsafe { libc::kill(pid, libc::SIGINT) }, 0);
    let started = Instant::now();
    let rest = std::thread::spawn(move || {
        let mut s = String::new();
        std::io::Read::read_to_string(&mut stderr, &mut s).unwrap();
        s
    });
    let status = loop {
        if let Some(s) = child.try_wait().unwrap() {
            break s;
        }
        if started.elapsed() > Duration::from_secs(120) {
            child.kill().unwrap();
            panic!("train did not stop within 120 s of Ctrl-C");
        }
        std::thread::sleep(Duration::from_millis(50));
    };
    let tail = rest.join().unwrap();
    assert_eq!(status.code(), Some(130), "{log}{tail}");
    assert!(tail.contains("interrupted"), "{tail}");
    for (name, old) in siblings.iter().zip(&before) {
        let now = std::fs::read(dir.path().join(name)).unwrap();
        assert_eq!(&now, old, "{name} changed after Ctrl-C");
    }
    let leftovers: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .filter_map(Result::ok)
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.ends_with(".tmp") || n.ends_with(".tmp.png"))
        .collect();
    assert!(leftovers.is_empty(), "temporary files left: {leftovers:?}");
}

//! `kill -9` of `tendril sim` mid-run (issue 31): its children must go, and
//! so must every iceoryx2 resource of the run — the shared-memory segments
//! in `/dev/shm` and the entries in iceoryx2's node and service directories
//! — without waiting for the next sim to clean them.
//!
//! Other tests (and other users' sims) may run at the same time, so the
//! resources are attributed to this run by name, read while it runs: the
//! services whose static configuration names the run's prefix, the nodes
//! whose details name one of the run's processes, and the ports those nodes
//! tag. A file left afterwards whose name holds one of those identifiers is
//! this run's leak.

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use tendril_tests::{robot, tendril_bin, workspace_root};

/// iceoryx2's default root, node and service directories, and file-name
/// prefix (iceoryx2's built-in configuration; host/src/ipc/transport.rs
/// reads the same from `Config::global_config()`).
const ROOT: &str = "/tmp/iceoryx2";
const SHM: &str = "/dev/shm";
const PREFIX: &str = "iox2_";

fn alive(pid: u32) -> bool {
    match std::fs::read_to_string(format!("/proc/{pid}/stat")) {
        Ok(stat) => {
            let state = stat
                .rsplit_once(") ")
                .and_then(|(_, rest)| rest.chars().next());
            !matches!(state, Some('Z') | Some('X') | None)
        }
        Err(_) => false,
    }
}

fn names(dir: &Path) -> Vec<String> {
    std::fs::read_dir(dir)
        .map(|d| {
            d.flatten()
                .map(|e| e.file_name().to_string_lossy().into_owned())
                .collect()
        })
        .unwrap_or_default()
}

/// The identifiers of the run's iceoryx2 resources: service hashes, node
/// ids, port ids.
#[derive(Debug, Default)]
struct RunIds {
    services: Vec<String>,
    nodes: Vec<String>,
    ports: Vec<String>,
}

impl RunIds {
    fn read(service_prefix: &str, pids: &[u32]) -> RunIds {
        let mut ids = RunIds::default();
        let services = Path::new(ROOT).join("services");
        for name in names(&services) {
            let Some(hash) = name
                .strip_prefix(PREFIX)
                .and_then(|n| n.strip_suffix(".service"))
            else {
                continue;
            };
            let text = std::fs::read_to_string(services.join(&name)).unwrap_or_default();
            if text.contains(&format!("service_name = \"{service_prefix}/")) {
                ids.services.push(hash.to_string());
            }
        }
        let nodes = Path::new(ROOT).join("nodes");
        for name in names(&nodes) {
            let dir = nodes.join(&name);
            let details = std::fs::read_to_string(dir.join(format!("{PREFIX}node.details")))
                .unwrap_or_default();
            let pid = details
                .lines()
                .find_map(|l| l.trim().strip_prefix("process = "))
                .and_then(|v| v.trim().parse::<u32>().ok());
            if !pid.is_some_and(|p| pids.contains(&p)) {
                continue;
            }
            ids.nodes.push(name.clone());
            ids.ports.extend(names(&dir).into_iter().filter_map(|f| {
                Some(
                    f.strip_prefix(PREFIX)?
                        .strip_suffix(".port_tag")?
                        .to_string(),
                )
            }));
        }
        ids
    }

    fn all(&self) -> impl Iterator<Item = &String> {
        self.services.iter().chain(&self.nodes).chain(&self.ports)
    }

    /// Every file or directory in `/dev/shm` and iceoryx2's directories
    /// whose name holds one of the identifiers.
    fn left(&self) -> Vec<PathBuf> {
        let dirs = [
            PathBuf::from(SHM),
            Path::new(ROOT).join("nodes"),
            Path::new(ROOT).join("services"),
        ];
        let mut left = Vec::new();
        for dir in dirs {
            for name in names(&dir) {
                if self.all().any(|id| name.contains(id.as_str())) {
                    left.push(dir.join(name));
                }
            }
        }
        left
    }
}

/// The children's pids once all three are up and the loop runs (the
/// controller has logged periods).
fn wait_for_loop(out: &Path, sim: &mut Child) -> Vec<u32> {
    let work = out.join(".sim-run");
    let deadline = Instant::now() + Duration::from_secs(90);
    loop {
        assert!(
            sim.try_wait().expect("poll sim").is_none(),
            "sim exited before its loop ran"
        );
        let pids: Vec<u32> = std::fs::read_to_string(work.join("pids"))
            .unwrap_or_default()
            .lines()
            .filter_map(|l| l.split_whitespace().nth(2)?.parse().ok())
            .collect();
        let logged = std::fs::metadata(work.join("controller.csv")).is_ok_and(|m| m.len() > 4096);
        if pids.len() == 3 && pids.iter().all(|&p| alive(p)) && logged {
            return pids;
        }
        assert!(Instant::now() < deadline, "the loop never started");
        std::thread::sleep(Duration::from_millis(50));
    }
}

fn kill(pid: u32, sig: &str) {
    let _ = Command::new("kill")
        .arg(format!("-{sig}"))
        .arg(pid.to_string())
        .status();
}

#[test]
fn sigkill_of_the_sim_leaves_no_children_and_no_iceoryx2_resources_of_its_run() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let prefix = format!(
        "t31kill{}x{}",
        std::process::id(),
        std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .unwrap()
            .subsec_nanos()
    );
    let mut sim = Command::new(tendril_bin())
        .arg("sim")
        .arg("--robot")
        .arg(robot("seed-4t.toml"))
        .args(["--model", "firmware/vectors/default.tnet"])
        .args(["--settle", "0.5", "--duration", "60", "--prefix", &prefix])
        .arg("--out")
        .arg(&out)
        .current_dir(workspace_root())
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("spawn tendril sim");
    let children = wait_for_loop(&out, &mut sim);
    let mut pids = children.clone();
    pids.push(sim.id());
    // Every process has its node once the planner sends setpoints (it lifts
    // the trajectory before it creates its node).
    let deadline = Instant::now() + Duration::from_secs(30);
    let ids = loop {
        let ids = RunIds::read(&prefix, &pids);
        if ids.nodes.len() == 4 || Instant::now() >= deadline {
            break ids;
        }
        std::thread::sleep(Duration::from_millis(50));
    };

    kill(sim.id(), "KILL");
    let _ = sim.wait();
    let deadline = Instant::now() + Duration::from_secs(5);
    let (survivors, left) = loop {
        let survivors: Vec<u32> = children.iter().copied().filter(|&p| alive(p)).collect();
        let left = ids.left();
        if (survivors.is_empty() && left.is_empty()) || Instant::now() >= deadline {
            break (survivors, left);
        }
        std::thread::sleep(Duration::from_millis(50));
    };
    for &p in &survivors {
        kill(p, "KILL");
    }
    // The attribution must have found the run's resources, or the check
    // below could not fail.
    assert_eq!(ids.services.len(), 6, "the run's services: {ids:?}");
    assert_eq!(ids.nodes.len(), 4, "the run's nodes: {ids:?}");
    assert!(!ids.ports.is_empty(), "the run's ports: {ids:?}");
    assert!(
        survivors.is_empty(),
        "children {survivors:?} still running 5 s after SIGKILL of the sim"
    );
    assert!(
        left.is_empty(),
        "{} iceoryx2 files of the killed run still there 5 s after SIGKILL: {left:?}",
        left.len()
    );
}

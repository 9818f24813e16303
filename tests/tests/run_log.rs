//! Run logs (docs/design.md §12): every sim leaves `run.mcap`, read back
//! here with the `mcap` crate's own reader (not tendril's): the channels
//! and schemas Foxglove needs, message counts equal to what the report
//! says was written, a scene whose backbone has the configured points and
//! ends at the tip, the report as metadata; a plant killed mid-run still
//! leaves a readable log; `--live` serves the same channels over the
//! Foxglove WebSocket protocol to a real client.

use std::collections::BTreeMap;
use std::net::TcpListener;
use std::path::Path;
use std::time::{Duration, Instant};

use foxglove::Decode;
use tendril_tests::{run_sim, sim_report, tendril, tendril_bin, workspace_root};

const NET: &str = "firmware/vectors/default.tnet";

/// Topic → (schema name, message count), metadata by name: read with
/// `mcap::MessageStream` (a complete file) or leniently (a cut one).
struct Log {
    topics: BTreeMap<String, (String, u64)>,
    metadata: BTreeMap<String, BTreeMap<String, String>>,
    scenes: Vec<(u64, Vec<u8>)>,
    tf: Vec<(u64, Vec<u8>)>,
}

fn read(path: &Path) -> Log {
    let bytes = std::fs::read(path).expect("run.mcap");
    let mut log = Log {
        topics: BTreeMap::new(),
        metadata: BTreeMap::new(),
        scenes: vec![],
        tf: vec![],
    };
    for m in mcap::MessageStream::new(&bytes).expect("an MCAP file") {
        let m = m.expect("a whole message");
        let schema = m
            .channel
            .schema
            .as_ref()
            .map_or(String::new(), |s| s.name.clone());
        let e = log
            .topics
            .entry(m.channel.topic.clone())
            .or_insert((schema, 0));
        e.1 += 1;
        match m.channel.topic.as_str() {
            "/robot/scene" => log.scenes.push((m.log_time, m.data.to_vec())),
            "/tf" => log.tf.push((m.log_time, m.data.to_vec())),
            _ => {}
        }
    }
    let summary = mcap::Summary::read(&bytes)
        .expect("summary")
        .expect("a summary");
    for index in &summary.metadata_indexes {
        let m = mcap::read::metadata(&bytes, index).expect("metadata");
        log.metadata.insert(m.name, m.metadata);
    }
    log
}

#[test]
fn a_sim_leaves_a_run_log_foxglove_opens_and_the_report_counts_it() {
    let (dir, _) = run_sim(&["--model", NET, "--duration", "2", "--backbone-points", "21"]);
    let report = sim_report(dir.path());
    let log = read(&dir.path().join("run.mcap"));
    let schemas: BTreeMap<&str, &str> = log
        .topics
        .iter()
        .map(|(t, (s, _))| (t.as_str(), s.as_str()))
        .collect();
    assert_eq!(
        schemas,
        BTreeMap::from([
            ("/log", "foxglove.Log"),
            ("/robot/scene", "foxglove.SceneUpdate"),
            ("/status", "tendril.Status"),
            ("/tensions", "tendril.Tensions"),
            ("/tf", "foxglove.FrameTransforms"),
            ("/tracking", "tendril.Tracking"),
        ])
    );
    // What the plant's writer says it wrote is what is in the file.
    let written = &report["plant"]["generations"][0]["runlog"];
    assert_eq!(written["dropped"], 0, "{written}");
    for (topic, (_, n)) in &log.topics {
        assert_eq!(
            written["messages"][topic].as_u64(),
            Some(*n),
            "{topic}: file has {n}, report {written}"
        );
    }
    // One tension and one tracking message per plant step.
    let steps = report["plant"]["generations"][0]["steps"].as_u64().unwrap();
    assert_eq!(log.topics["/tensions"].1, steps);
    assert_eq!(log.topics["/tracking"].1, steps);
    // ~30 scenes per second over a run of ≥ 2 s.
    assert!(log.topics["/robot/scene"].1 >= 50, "{:?}", log.topics);

    // The backbone has the configured points, starts at the base and ends
    // at the tip the same instant's frame transform reports.
    let tips: BTreeMap<u64, [f64; 3]> = log
        .tf
        .iter()
        .map(|(t, bytes)| {
            let tf = foxglove::messages::FrameTransforms::decode(bytes.as_slice()).unwrap();
            // Everything hangs off the tracker's frame; the robot's base is
            // a child of it (the identity here: seed-4t has no [base]).
            assert!(tf.transforms.iter().all(|f| f.parent_frame_id == "tracker"));
            let base = tf
                .transforms
                .iter()
                .find(|f| f.child_frame_id == "base")
                .and_then(|f| f.translation)
                .expect("a base transform");
            assert_eq!([base.x, base.y, base.z], [0.0; 3]);
            let tip = tf
                .transforms
                .iter()
                .find(|f| f.child_frame_id == "tip")
                .and_then(|f| f.translation)
                .expect("a tip transform");
            (*t, [tip.x, tip.y, tip.z])
        })
        .collect();
    let mut checked = 0;
    for (t, bytes) in &log.scenes {
        let scene = foxglove::messages::SceneUpdate::decode(bytes.as_slice()).unwrap();
        let robot = scene
            .entities
            .iter()
            .find(|e| e.id == "robot")
            .expect("the robot entity");
        let backbone = &robot.lines[0].points;
        assert_eq!(backbone.len(), 21);
        let base = &backbone[0];
        assert!(
            base.x.abs() + base.y.abs() + base.z.abs() < 1e-12,
            "{base:?}"
        );
        let last = backbone.last().unwrap();
        let tip = tips[t];
        let d = ((last.x - tip[0]).powi(2) + (last.y - tip[1]).powi(2) + (last.z - tip[2]).powi(2))
            .sqrt();
        assert!(
            d < 1e-6,
            "scene at {t}: backbone ends {d:.2e} m from the tip"
        );
        // Four tendons beside it.
        assert_eq!(robot.lines.len(), 5, "backbone and 4 tendons");
        checked += 1;
    }
    assert!(checked >= 50);

    // The report's summary is the file's metadata.
    let meta = &log.metadata["report"];
    let rms: f64 = meta["rms_tracking_error_mm"].parse().unwrap();
    let want = report["rms_tracking_error_mm"].as_f64().unwrap();
    assert!((rms - want).abs() <= 1e-12 * want, "{rms} against {want}");
    assert_eq!(meta["verdict.clean"], "true");

    // `tendril plot` redraws the figure from the log alone.
    let png = dir.path().join("again.png");
    let out = tendril(&[
        "plot",
        dir.path().join("run.mcap").to_str().unwrap(),
        "--out",
        png.to_str().unwrap(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(std::fs::metadata(&png).unwrap().len() > 10_000);

    // A log cut short (a killed plant's) reads up to its last whole chunk.
    let bytes = std::fs::read(dir.path().join("run.mcap")).unwrap();
    let whole = tendril::runlog::RunLogFile::from_bytes(Path::new("whole"), &bytes).unwrap();
    assert!(!whole.truncated);
    let cut = &bytes[..bytes.len() * 2 / 3];
    let part = tendril::runlog::RunLogFile::from_bytes(Path::new("cut"), cut).unwrap();
    assert!(part.truncated);
    let (w, p) = (
        whole.messages("/tensions").len(),
        part.messages("/tensions").len(),
    );
    assert!(p > 0 && p < w, "cut file: {p} of {w} tension messages");
}

#[test]
fn a_plant_killed_mid_run_leaves_a_readable_log() {
    let (dir, _) = run_sim(&[
        "--model",
        NET,
        "--duration",
        "4",
        "--kill-plant-at",
        "4",
        "--max-rms-mm",
        "1000",
    ]);
    let report = sim_report(dir.path());
    assert!(
        report["plant"]["generations"][0]["runlog"].is_null(),
        "a killed plant wrote no statistics: {}",
        report["plant"]
    );
    // The killed plant's file, readable up to its last chunk, was given
    // the report's metadata and a footer.
    let log = read(&dir.path().join("run.mcap"));
    let n = log.topics.get("/tensions").map_or(0, |(_, n)| *n);
    // The plant ran ~4 s at 1 kHz before the kill; a chunk is ~0.3 s.
    assert!(n > 2500, "only {n} tension messages before the kill");
    assert!(log.metadata.contains_key("report"));
    assert!(!dir.path().join("run.mcap.partial").exists());
}

/// A free local port (bound, then released for the server).
fn free_port() -> u16 {
    TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

/// Start `tendril sim --live` for `seconds`, connect a Foxglove WebSocket
/// client, subscribe to every channel and read until the sim ends (or,
/// with `enough`, until that many scene and tension messages came).
/// Returns the sim's output directory and the messages per topic.
fn watch_live(
    seconds: &str,
    enough: Option<(u64, u64)>,
) -> (tempfile::TempDir, BTreeMap<String, u64>) {
    use tungstenite::client::IntoClientRequest;
    use tungstenite::Message;

    let _one = tendril_tests::one_loop_at_a_time();
    let port = free_port();
    let out = tempfile::tempdir().unwrap();
    let mut sim = std::process::Command::new(tendril_bin())
        .args(["sim", "--model", NET, "--duration", seconds, "--no-mcap"])
        .arg("--live")
        .arg(format!("127.0.0.1:{port}"))
        .arg("--out")
        .arg(out.path())
        .current_dir(workspace_root())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let url = format!("ws://127.0.0.1:{port}");
    let mut request = url.as_str().into_client_request().unwrap();
    request
        .headers_mut()
        .insert("Sec-WebSocket-Protocol", "foxglove.sdk.v1".parse().unwrap());
    let started = Instant::now();
    let (mut ws, _) = loop {
        match tungstenite::connect(request.clone()) {
            Ok(c) => break c,
            Err(_) if started.elapsed() < Duration::from_secs(60) => {
                std::thread::sleep(Duration::from_millis(100));
            }
            Err(e) => {
                let _ = sim.kill();
                panic!("no live server on {url}: {e}");
            }
        }
    };
    if let tungstenite::stream::MaybeTlsStream::Plain(s) = ws.get_mut() {
        s.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
    }
    // Advertisements name the channels; subscribe to each as it comes and
    // count the binary message frames (opcode 1: subscription id, time,
    // payload) per topic.
    let mut topics: BTreeMap<u64, String> = BTreeMap::new();
    let mut got: BTreeMap<String, u64> = BTreeMap::new();
    let limit = Duration::from_secs(seconds.parse::<u64>().unwrap_or(10) + 90);
    while started.elapsed() < limit {
        let Ok(msg) = ws.read() else { break };
        match msg {
            Message::Text(text) => {
                let v: serde_json::Value = serde_json::from_str(&text).unwrap();
                if v["op"] != "advertise" {
                    continue;
                }
                let mut subs = vec![];
                for c in v["channels"].as_array().unwrap() {
                    let id = c["id"].as_u64().unwrap();
                    topics.insert(id, c["topic"].as_str().unwrap().into());
                    subs.push(serde_json::json!({"id": id, "channelId": id}));
                }
                let sub = serde_json::json!({"op": "subscribe", "subscriptions": subs});
                ws.send(Message::text(sub.to_string())).unwrap();
            }
            Message::Binary(b) if b.first() == Some(&1) && b.len() >= 13 => {
                let sub = u64::from(u32::from_le_bytes(b[1..5].try_into().unwrap()));
                let topic = topics.get(&sub).cloned().unwrap_or_default();
                *got.entry(topic).or_default() += 1;
                if let Some((scenes, tensions)) = enough {
                    let n = |t: &str| got.get(t).copied().unwrap_or(0);
                    if n("/robot/scene") >= scenes && n("/tensions") >= tensions {
                        break;
                    }
                }
            }
            _ => {}
        }
    }
    let _ = ws.close(None);
    let status = sim.wait().unwrap();
    assert!(status.success(), "the sim with a client failed: {status}");
    (out, got)
}

#[test]
fn a_live_run_serves_the_scene_and_tensions_to_a_foxglove_client() {
    let (_, got) = watch_live("6", Some((10, 100)));
    let n = |t: &str| got.get(t).copied().unwrap_or(0);
    assert!(n("/robot/scene") >= 10, "scene messages: {got:?}");
    assert!(n("/tensions") >= 100, "tension messages: {got:?}");
}

/// The live target, too long for CI (`--ignored`): a client
/// subscribed to every channel through a 60 s run. The controller must
/// skip no more periods than in the same run without the live view, one
/// right after the other (this shared 2-core VM skips a few dozen of
/// 62,000 periods with no logging at all: BENCHMARKS.md, run logs).
#[test]
#[ignore = "2 × 60 s; run with --ignored (BENCHMARKS.md, run logs)"]
fn a_live_client_through_a_60_s_run_costs_the_controller_no_period() {
    let skipped = |dir: &Path| -> u64 {
        let stats: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(dir.join("controller.json")).unwrap())
                .unwrap();
        eprintln!(
            "controller skipped {}, overruns {}, p99 lateness {} us",
            stats["skipped"], stats["overruns"], stats["lateness_us"]["p99"]
        );
        stats["skipped"].as_u64().unwrap()
    };
    let (base, _) = run_sim(&["--model", NET, "--duration", "60", "--no-mcap"]);
    let without = skipped(base.path());
    let (dir, got) = watch_live("60", None);
    eprintln!("live client got {got:?}");
    let with = skipped(dir.path());
    assert!(
        got.get("/tensions").copied().unwrap_or(0) > 50_000,
        "{got:?}"
    );
    // 0.05 % of the run's periods on top of the run without a client.
    assert!(
        with <= without + 31,
        "skipped {with} periods with a live client, {without} without"
    );
}

#[test]
fn a_dynamics_run_logs_the_swinging_rod() {
    // `tendril dynamics` (faster than real time: nothing is dropped) logs
    // every time step and a scene at 30 Hz of simulated time whose
    // backbone ends at the tip the same step's transform reports.
    let dir = tempfile::tempdir().unwrap();
    let out = tendril(&[
        "dynamics",
        "--tensions-step",
        "0,0,0,0:2,0,0,0@0.05",
        "--duration",
        "0.3",
        "--out",
        dir.path().to_str().unwrap(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let log = read(&dir.path().join("run.mcap"));
    let rows = std::fs::read_to_string(dir.path().join("tip.csv"))
        .unwrap()
        .lines()
        .count()
        - 1;
    assert_eq!(
        log.topics["/tensions"].1 as usize, rows,
        "one per time step"
    );
    assert!(
        log.scenes.len() >= 9,
        "{} scenes in 0.3 s",
        log.scenes.len()
    );
    let tips: BTreeMap<u64, foxglove::messages::Vector3> = log
        .tf
        .iter()
        .map(|(t, b)| {
            let tf = foxglove::messages::FrameTransforms::decode(b.as_slice()).unwrap();
            let tip = tf.transforms.iter().find(|f| f.child_frame_id == "tip");
            (*t, tip.expect("a tip transform").translation.unwrap())
        })
        .collect();
    let mut moved = 0.0f64;
    for (t, bytes) in &log.scenes {
        let scene = foxglove::messages::SceneUpdate::decode(bytes.as_slice()).unwrap();
        let backbone = &scene.entities[0].lines[0].points;
        assert_eq!(backbone.len(), 41);
        let (last, tip) = (backbone.last().unwrap(), tips[t]);
        let d =
            ((last.x - tip.x).powi(2) + (last.y - tip.y).powi(2) + (last.z - tip.z).powi(2)).sqrt();
        assert!(
            d < 1e-9,
            "at {t} ns the backbone ends {d:.2e} m from the tip"
        );
        moved = moved.max(tip.x.abs());
    }
    assert!(moved > 1e-3, "the rod never swung: {moved:.2e} m");
}

//! Parity of the firmware core on the MCU and on the host: build
//! the `thumbv7em-none-eabihf` binary, run it in QEMU (`mps2-an386`,
//! Cortex-M4F), and compare every printed inference and control command with
//! the host build of the same code on the same files, to ≤ 1e-6 relative
//! (the code is written to be bit-identical; the tolerance is the
//! contract, docs/design.md §5).
//!
//! The MCU runs the net its build script compiled into flash
//! (`firmware/vectors/default.tnet`, the default exported net, 7-64-4); the
//! host side decodes the same file at run time, so the test also checks the
//! build-time path against the run-time decoder. Every MCU inference is
//! also checked against the net the hot-swap flags say must be running
//! (flash default, or the update after an accepted swap; never a rejected
//! blob). A second test builds the binary with `TENDRIL_FW_NET` pointing at
//! another file and checks that net is the one that runs.
//!
//! A third builds the two-segment robot's six-tendon net
//! (`firmware/vectors/tdcr-2seg.tnet`) into flash with vectors made for it
//! (`TENDRIL_FW_VECTORS`), a fourth the three-segment robot's nine-tendon
//! net (`firmware/vectors/tdcr-3seg.tnet`). A fifth runs the hot-swap image
//! `tendril-fw-swap` (docs/design.md §5.3): the largest net the MCU accepts (7-64-8) swapped in while the
//! control loop runs, every period's instruction count against the budget
//! and every period's inference against the net that should be running.
//!
//! Without `qemu-system-arm` or the target these tests fail with a
//! one-line "install …" message: a test that cannot run does not pass.
//! `scripts/test` checks both first and, when one is missing and cannot be
//! installed, runs every other test and reports them as not run
//! (non-zero exit); CI installs both (`.ci/run`).

use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::time::Duration;

use tendril::firmware_parity::{self as parity, ParityError};
use tendril_firmware::swap_demo::{self, Offer, BLOB_LEN, FLASH_SEED};
use tendril_firmware::vectors::{self, HAS_SETPOINT, SWAP_GOOD, SWAP_REVERT};
use tendril_firmware::{infer, McuNet, SWAP_PERIOD_BUDGET};
use tendril_tests::workspace_root;

/// Builds share one target directory (and the ELF path): one at a time.
static BUILD: Mutex<()> = Mutex::new(());

/// The target directory of the MCU builds: its own (the outer `cargo test`
/// holds the lock on the normal one).
fn mcu_target_dir(root: &Path) -> PathBuf {
    std::env::var_os("CARGO_TARGET_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| root.join("target"))
        .join("thumbv7em-parity")
}

/// Build the MCU binary with `TENDRIL_FW_NET` set to `net` or unset, and
/// `TENDRIL_FW_VECTORS` to `vectors` or unset (the committed vectors).
fn build_mcu_binary(
    root: &Path,
    net: Option<&Path>,
    vectors: Option<&Path>,
    label: &str,
) -> PathBuf {
    let _guard = BUILD.lock().unwrap_or_else(|e| e.into_inner());
    parity::build_mcu_bin(
        root,
        "tendril-fw",
        net,
        vectors,
        &mcu_target_dir(root),
        label,
    )
    .unwrap_or_else(|e| panic!("{e}"))
}

fn bits(word: &str) -> f32 {
    f32::from_bits(u32::from_str_radix(word, 16).expect("hex bits"))
}

fn close(a: f32, b: f32) -> bool {
    if a.is_nan() || b.is_nan() {
        return a.is_nan() && b.is_nan();
    }
    (a - b).abs() <= 1e-6 * a.abs().max(b.abs())
}

/// Run the MCU binary built with `flash_net` (the file; `env` = whether via
/// `TENDRIL_FW_NET`) and the vectors in `vectors` (`None`: the committed
/// `firmware/vectors/`, via the build's default) and compare it with the
/// host run of the same files; returns the MCU output.
fn check_parity(flash_net: &Path, env: bool, vectors: Option<&Path>, label: &str) -> String {
    let root = workspace_root();
    let committed = root.join("firmware").join("vectors");
    let vectors_dir = vectors.unwrap_or(&committed);
    let elf = build_mcu_binary(&root, env.then_some(flash_net), vectors, label);
    let (ok, mcu_out) =
        parity::run_qemu(&elf, Duration::from_secs(120)).unwrap_or_else(|e| panic!("{e}"));
    assert!(ok, "MCU binary exited with failure; output:\n{mcu_out}");
    let host_out = parity::host_run(vectors_dir, flash_net).unwrap_or_else(|e| panic!("{e}"));
    let (lines, identical, worst) =
        parity::compare_outputs(&mcu_out, &host_out, 1e-6).unwrap_or_else(|e| panic!("{e}"));
    assert!(lines > 100, "too few result lines: {lines}");
    let mcu = parity::result_lines(&mcu_out);
    let flash = Box::new(
        McuNet::decode(&std::fs::read(flash_net).expect("flash net")).expect("flash net decodes"),
    );
    let update = Box::new(
        McuNet::decode(&std::fs::read(vectors_dir.join("swap.tnet")).expect("swap.tnet"))
            .expect("swap.tnet decodes"),
    );
    let vecs = std::fs::read(vectors_dir.join("inputs.bin")).expect("inputs.bin");
    let s = flash.shape();
    assert_eq!(
        mcu[0],
        format!("net {} {} {} {}", s.inputs, s.hidden, s.outputs, s.macs()),
        "the MCU does not run {}",
        flash_net.display()
    );

    // Which net must have run each inference: the flash net, or the update
    // from an accepted swap until a revert (rejected blobs change nothing).
    let (_, records) = vectors::parse(&vecs).expect("vectors parse");
    let mut on_update = false;
    let mut checked = 0;
    let mut on_update_count = 0;
    let infers: std::collections::HashMap<usize, &str> = mcu
        .iter()
        .filter_map(|l| {
            let mut w = l.splitn(3, ' ');
            (w.next() == Some("infer")).then(|| {
                let i = w.next().expect("index").parse().expect("index");
                (i, w.next().expect("values"))
            })
        })
        .collect();
    for (i, r) in records.enumerate() {
        if r.flags & SWAP_GOOD != 0 {
            on_update = true;
        }
        if r.flags & SWAP_REVERT != 0 {
            on_update = false;
        }
        if r.flags & HAS_SETPOINT == 0 || !r.pose.iter().all(|v| v.is_finite()) {
            continue;
        }
        let net = if on_update { &update } else { &flash };
        let want = infer(net, &r.pose);
        let got: Vec<f32> = infers[&i].split(' ').map(bits).collect();
        for (o, (g, w)) in got.iter().zip(&want).enumerate() {
            assert!(
                close(*g, *w),
                "record {i} output {o}: MCU {g}, expected {w} from the {} net",
                if on_update { "update" } else { "flash" }
            );
        }
        checked += 1;
        on_update_count += usize::from(on_update);
    }
    assert!(
        checked > 50 && on_update_count >= 5,
        "{checked} {on_update_count}"
    );
    eprintln!(
        "firmware parity ({label}): {lines} lines compared, {identical} bit-identical (worst relative difference {worst:e}); {checked} inferences checked against the expected net"
    );
    let done = mcu.last().copied().unwrap_or("");
    assert!(done.starts_with("done "), "MCU output ends with `{done}`");
    mcu_out
}

/// Fail (not pass) when the test cannot run, naming what to install.
fn require_prerequisites() {
    match parity::prerequisites() {
        Ok(()) => {}
        Err(ParityError::Unavailable(what)) => {
            panic!("firmware QEMU parity test cannot run: {what}")
        }
        Err(e) => panic!("firmware QEMU parity test cannot run: {e}"),
    }
}

#[test]
fn mcu_build_under_qemu_matches_host_build() {
    require_prerequisites();
    let default = workspace_root().join("firmware/vectors/default.tnet");
    let out = check_parity(&default, false, None, "default");
    // The default exported net: 7 inputs, 64 hidden units, 4 tendons.
    assert!(out.lines().any(|l| l == "net 7 64 4 2816"), "{out}");
}

#[test]
fn tendril_fw_net_selects_the_flash_net() {
    require_prerequisites();
    // Any valid net for the same robot will do: the 7-12-4 update blob.
    let other = workspace_root().join("firmware/vectors/swap.tnet");
    let out = check_parity(&other, true, None, "env");
    assert!(out.lines().any(|l| l == "net 7 12 4 242"), "{out}");
}

/// The two-segment robot's exported net (six tendons, `tendril run --robot
/// robots/tdcr-2seg.toml`, committed as `firmware/vectors/tdcr-2seg.tnet`)
/// in flash, with vectors made for it: the MCU image takes any tendon count
/// up to `MAX_TENDONS`.
#[test]
fn two_segment_robot_net_runs_bit_identically_on_the_mcu() {
    robot_net_runs_bit_identically("tdcr-2seg", 6);
}

/// The committed net `firmware/vectors/<name>.tnet` of a robot with
/// `tendons` tendons in flash, with vectors made for it: parity, and the
/// MCU reports running a net with that many outputs.
fn robot_net_runs_bit_identically(name: &str, tendons: usize) {
    require_prerequisites();
    let root = workspace_root();
    let net = root.join(format!("firmware/vectors/{name}.tnet"));
    let vectors =
        parity::write_vectors(&net, &mcu_target_dir(&root).join(format!("vectors-{name}")))
            .unwrap_or_else(|e| panic!("{e}"));
    let out = check_parity(&net, true, Some(&vectors), name);
    let shape = McuNet::decode(&std::fs::read(&net).expect("net"))
        .expect("decodes")
        .shape();
    assert_eq!(shape.outputs, tendons, "{name} has {tendons} tendons");
    let outputs = tendons.to_string();
    assert!(
        out.lines()
            .any(|l| l.starts_with("net 7 ") && l.split(' ').nth(3) == Some(outputs.as_str())),
        "{out}"
    );
}

/// The three-segment robot's exported net (nine tendons, 7-63-9: the
/// robust-polished net of `tendril run --robot robots/tdcr-3seg.toml`,
/// committed as `firmware/vectors/tdcr-3seg.tnet`) in flash, with vectors
/// made for it: the most tendons the MCU takes, on the largest net a robot
/// file has produced.
#[test]
fn three_segment_robot_net_runs_bit_identically_on_the_mcu() {
    robot_net_runs_bit_identically("tdcr-3seg", 9);
}

/// One `period` line of the hot-swap image.
struct Period {
    k: u32,
    step: u64,
    slice: u64,
    event: String,
    infer: Vec<f32>,
}

fn parse_period(line: &str) -> Option<Period> {
    let w: Vec<&str> = line.split(' ').collect();
    match w.as_slice() {
        ["period", k, "step", step, "slice", slice, event, "infer", values @ ..] => Some(Period {
            k: k.parse().ok()?,
            step: step.parse().ok()?,
            slice: slice.parse().ok()?,
            event: (*event).to_string(),
            infer: values.iter().map(|v| bits(v)).collect(),
        }),
        _ => None,
    }
}

fn demo_net(seed: u64) -> Box<McuNet> {
    let mut buf = vec![0u8; BLOB_LEN];
    let n = swap_demo::net_blob(seed, &mut buf).expect("synthetic 7-64-8 net");
    Box::new(McuNet::decode(&buf[..n]).expect("synthetic net decodes"))
}

#[test]
fn hot_swap_of_the_largest_net_misses_no_period() {
    require_prerequisites();
    let root = workspace_root();
    let base = std::env::var_os("CARGO_TARGET_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| root.join("target"))
        .join("thumbv7em-parity");
    // The image runs the 7-64-8 net of FLASH_SEED from flash.
    std::fs::create_dir_all(&base).expect("target dir");
    let flash_file = base.join("swap-flash.tnet");
    let mut buf = vec![0u8; BLOB_LEN];
    let n = swap_demo::net_blob(FLASH_SEED, &mut buf).expect("flash net");
    std::fs::write(&flash_file, &buf[..n]).expect("write the flash net");
    let elf = {
        let _guard = BUILD.lock().unwrap_or_else(|e| e.into_inner());
        parity::build_mcu_bin(
            &root,
            "tendril-fw-swap",
            Some(&flash_file),
            None,
            &base,
            "swap",
        )
        .unwrap_or_else(|e| panic!("{e}"))
    };
    let (ok, out) =
        parity::run_qemu(&elf, Duration::from_secs(120)).unwrap_or_else(|e| panic!("{e}"));
    assert!(ok, "swap image exited with failure; output:\n{out}");
    let flash = demo_net(FLASH_SEED);
    let first = demo_net(Offer::First.seed());
    let last = demo_net(Offer::Last.seed());
    let s = flash.shape();
    assert_eq!((s.inputs, s.hidden, s.outputs), (7, 64, 8));
    assert!(
        out.lines().any(|l| l == format!("net 7 64 8 {}", s.macs())),
        "{out}"
    );
    assert!(
        out.lines()
            .any(|l| l == format!("offer {} last superseded-previous", Offer::Last.period())),
        "the last blob did not supersede the one in progress:\n{out}"
    );

    let periods: Vec<Period> = out.lines().filter_map(parse_period).collect();
    assert_eq!(periods.len(), swap_demo::PERIODS as usize, "{out}");
    // Which net must run each period: the flash net, then the first update
    // from the period after its swap slice, then the last one. The
    // corrupted blob and the superseded one must never run.
    let mut running: &McuNet = &flash;
    let mut swaps = Vec::new();
    let mut rejections = Vec::new();
    let (mut max_step, mut max_slice, mut max_total) = (0, 0, 0);
    for p in &periods {
        let total = p.step + p.slice;
        assert!(
            total <= SWAP_PERIOD_BUDGET,
            "period {}: control step {} + swap slice {} = {total} instructions, over the budget {SWAP_PERIOD_BUDGET}",
            p.k,
            p.step,
            p.slice
        );
        (max_step, max_slice, max_total) = (
            max_step.max(p.step),
            max_slice.max(p.slice),
            max_total.max(total),
        );
        let pose = swap_demo::pose(p.k);
        let want = infer(running, &pose);
        assert_eq!(p.infer.len(), tendril_shared::MAX_TENDONS);
        for (o, (g, w)) in p.infer.iter().zip(&want).enumerate() {
            assert!(
                close(*g, *w),
                "period {} output {o}: MCU {g}, expected {w}",
                p.k
            );
        }
        match p.event.as_str() {
            "swapped" => {
                running = match swaps.len() {
                    0 => &first,
                    1 => &last,
                    _ => panic!("period {}: a third swap", p.k),
                };
                swaps.push(p.k);
            }
            "rejected" => rejections.push(p.k),
            "working" | "idle" => {}
            other => panic!("period {}: unknown event {other}", p.k),
        }
    }
    // The nets differ, so the inference check tells them apart.
    let pose = swap_demo::pose(1);
    assert_ne!(infer(&flash, &pose), infer(&first, &pose));
    assert_ne!(infer(&first, &pose), infer(&last, &pose));
    // The schedule: the first update lands before the corrupted blob is
    // offered, the corrupted one is refused before the next offer, and the
    // last one lands after it was offered; each check took several periods
    // (the work really is spread out).
    assert_eq!(swaps.len(), 2, "swaps at {swaps:?}");
    assert_eq!(rejections.len(), 1, "rejections at {rejections:?}");
    assert!(
        swaps[0] >= Offer::First.period() + 3 && swaps[0] < Offer::Corrupted.period(),
        "{swaps:?}"
    );
    assert!(
        rejections[0] >= Offer::Corrupted.period() + 2
            && rejections[0] < Offer::Superseded.period()
    );
    assert!(swaps[1] >= Offer::Last.period() + 3, "{swaps:?}");
    let idle_step = periods
        .iter()
        .filter(|p| p.event == "idle")
        .map(|p| p.step)
        .max()
        .unwrap_or(0);
    eprintln!(
        "hot swap 7-64-8 under QEMU: swaps at periods {swaps:?}, rejection at {rejections:?}; per period max: control step {max_step}, swap slice {max_slice}, step + slice {max_total} instructions (budget {SWAP_PERIOD_BUDGET}); control step alone when idle: max {idle_step}"
    );
}

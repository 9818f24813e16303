//! Firmware parity for any exported net: build the Cortex-M4F binary with
//! that net in flash (`TENDRIL_FW_NET`), run it under QEMU (`mps2-an386`),
//! run the host build of the same `no_std` core on the same net and test
//! vectors, and compare every inference and control-step line (≤ 1e-6
//! relative; the code is written to be bit-identical). Also reads the
//! binary's own measurements: instructions per inference (SysTick under
//! `-icount shift=0`) against its budget (2.5 per multiply-accumulate + 45
//! per sigmoid), and the painted stack.
//!
//! The main job runs this on `out/model.tnet`; the QEMU test in `tests/`
//! runs it on the committed default net. It needs the source checkout (to
//! build the MCU binary), `qemu-system-arm` and the `thumbv7em-none-eabihf`
//! target; without them it says which is missing ([`ParityError::Unavailable`]).
//! The host half needs the firmware's test harness, compiled only with this
//! crate's feature `parity` (a default); built without it, every entry point
//! reports [`ParityError::Unavailable`].

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use serde::Serialize;
#[cfg(feature = "parity")]
use tendril_firmware::vectors::{self, SwapBlobs};
#[cfg(feature = "parity")]
use tendril_firmware::{McuNet, McuSlots};

/// The MCU target triple.
pub const TARGET: &str = "thumbv7em-none-eabihf";

/// Why a parity run did not happen or did not pass.
#[derive(Debug, thiserror::Error)]
pub enum ParityError {
    /// A prerequisite is missing (not a parity failure).
    #[error("firmware parity skipped: {0}")]
    Unavailable(String),
    /// Building, running or reading something failed.
    #[error("firmware parity: {0}")]
    Run(String),
    /// The MCU and host outputs differ.
    #[error("firmware parity failed: {0}")]
    Mismatch(String),
}

/// What a passing parity run measured.
#[derive(Clone, Debug, Serialize)]
pub struct ParityReport {
    /// The net the MCU ran: inputs, hidden units, outputs, multiply-accumulates.
    pub net: [usize; 4],
    /// Result lines compared (`net`, `infer`, `step`, `done`).
    pub lines: usize,
    /// Of those, identical to the last bit.
    pub bit_identical: usize,
    /// Largest relative difference of any compared number.
    pub max_relative_difference: f64,
    /// M4F instructions per inference (QEMU `-icount shift=0`), if printed.
    pub instructions_per_inference: Option<f64>,
    /// The instruction budget: 2.5 per multiply-accumulate + 45 per sigmoid.
    pub instruction_budget: Option<f64>,
    /// Stack high-water mark of the vector run (bytes, painted stack).
    pub stack_bytes: Option<u64>,
}

/// The workspace root of the checkout this binary was built from, if it is
/// still there (the MCU binary is built from source).
pub fn workspace_root() -> Option<PathBuf> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()?
        .to_path_buf();
    root.join("firmware")
        .join("Cargo.toml")
        .exists()
        .then_some(root)
}

/// `qemu-system-arm` runs and the MCU target is installed, or which is not.
pub fn prerequisites() -> Result<(), ParityError> {
    if !cfg!(feature = "parity") {
        return Err(without_harness());
    }
    // The one check, shared with the chip in the loop.
    crate::mcu::check_tools().map_err(|e| ParityError::Unavailable(e.to_string()))
}

/// Build the MCU binary with `net` in flash (the committed default net if
/// `None`) into `target_dir`; returns the ELF, copied to a name of its own
/// (`tendril-fw-<label>`) so later builds don't overwrite it.
pub fn build_mcu_binary(
    root: &Path,
    net: Option<&Path>,
    target_dir: &Path,
    label: &str,
) -> Result<PathBuf, ParityError> {
    build_mcu_bin(root, "tendril-fw", net, None, target_dir, label)
}

/// [`build_mcu_binary`] for the firmware binary `bin` (`tendril-fw`, or the
/// hot-swap run `tendril-fw-swap`), with the test vectors of `vectors` (the
/// committed `firmware/vectors/` if `None`); the copy is named `<bin>-<label>`.
pub fn build_mcu_bin(
    root: &Path,
    bin: &str,
    net: Option<&Path>,
    vectors: Option<&Path>,
    target_dir: &Path,
    label: &str,
) -> Result<PathBuf, ParityError> {
    let elf = crate::mcu::cargo_build_firmware(
        root,
        bin,
        "harness",
        target_dir,
        &[("TENDRIL_FW_NET", net), ("TENDRIL_FW_VECTORS", vectors)],
    )
    .map_err(ParityError::Run)?;
    let copy = target_dir.join(format!("{bin}-{label}"));
    std::fs::copy(&elf, &copy)
        .map_err(|e| ParityError::Run(format!("copying {}: {e}", elf.display())))?;
    Ok(copy)
}

/// Run `elf` under QEMU (the `cargo fw` command line) with a time limit;
/// returns whether it exited 0 and its semihosting output.
pub fn run_qemu(elf: &Path, limit: Duration) -> Result<(bool, String), ParityError> {
    let mut child = Command::new("qemu-system-arm")
        .args(["-M", "mps2-an386", "-cpu", "cortex-m4", "-nographic"])
        .args(["-semihosting-config", "enable=on,target=native"])
        .args(["-icount", "shift=0", "-kernel"])
        .arg(elf)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit())
        .spawn()
        .map_err(|e| ParityError::Run(format!("starting qemu-system-arm: {e}")))?;
    let mut stdout = child
        .stdout
        .take()
        .ok_or_else(|| ParityError::Run("no QEMU stdout".into()))?;
    let reader = std::thread::spawn(move || {
        let mut s = String::new();
        std::io::Read::read_to_string(&mut stdout, &mut s).map(|_| s)
    });
    let deadline = Instant::now() + limit;
    let status = loop {
        match child.try_wait() {
            Ok(Some(st)) => break st,
            Ok(None) if Instant::now() > deadline => {
                let _ = child.kill();
                let _ = child.wait();
                return Err(ParityError::Run(format!(
                    "QEMU did not exit within {} s (firmware hung?)",
                    limit.as_secs()
                )));
            }
            Ok(None) => std::thread::sleep(Duration::from_millis(20)),
            Err(e) => return Err(ParityError::Run(format!("waiting for QEMU: {e}"))),
        }
    };
    let out = reader
        .join()
        .map_err(|_| ParityError::Run("QEMU reader thread panicked".into()))?
        .map_err(|e| ParityError::Run(format!("QEMU output: {e}")))?;
    Ok((status.success(), out))
}

/// The host build of the firmware core on the same files: `flash_net` as
/// the running net, the vectors and swap blobs in `vectors_dir` (the
/// committed ones are `firmware/vectors/` of the checkout).
#[cfg(feature = "parity")]
pub fn host_run(vectors_dir: &Path, flash_net: &Path) -> Result<String, ParityError> {
    let dir = vectors_dir;
    let read =
        |p: &Path| std::fs::read(p).map_err(|e| ParityError::Run(format!("{}: {e}", p.display())));
    let flash_blob = read(flash_net)?;
    let (good, nan) = (
        read(&dir.join("swap.tnet"))?,
        read(&dir.join("swap_nan.tnet"))?,
    );
    let vecs = read(&dir.join("inputs.bin"))?;
    let flash = Box::new(
        McuNet::decode(&flash_blob)
            .map_err(|e| ParityError::Run(format!("{}: {e}", flash_net.display())))?,
    );
    let mut ram = Box::new(McuNet::empty());
    let mut store = McuSlots::new(&flash, &mut ram);
    let blobs = SwapBlobs {
        good: &good,
        nan: &nan,
    };
    let mut out = String::new();
    vectors::run(&mut store, &blobs, &vecs, &mut out)
        .map_err(|e| ParityError::Run(format!("host run of the vectors: {e}")))?;
    Ok(out)
}

/// [`host_run`] of a build without the feature `parity`.
#[cfg(not(feature = "parity"))]
pub fn host_run(_vectors_dir: &Path, _flash_net: &Path) -> Result<String, ParityError> {
    Err(without_harness())
}

/// Why a build without the feature `parity` cannot check parity.
fn without_harness() -> ParityError {
    ParityError::Unavailable(
        "this tendril was built without the firmware's test harness \
         (cargo feature `parity`, on by default)"
            .into(),
    )
}

/// The comparable lines: `net`, `infer`, `step`, `done` (measurements and
/// log lines differ by design).
pub fn result_lines(out: &str) -> Vec<&str> {
    out.lines()
        .filter(|l| matches!(l.split(' ').next(), Some("net" | "infer" | "step" | "done")))
        .collect()
}

/// An `f32` printed as its hex bits.
fn bits(word: &str) -> Option<f32> {
    u32::from_str_radix(word, 16).ok().map(f32::from_bits)
}

/// Relative difference of two printed values; NaN matches only NaN.
fn relative_difference(a: f32, b: f32) -> f64 {
    if a.is_nan() || b.is_nan() {
        return if a.is_nan() && b.is_nan() {
            0.0
        } else {
            f64::INFINITY
        };
    }
    if a == b {
        return 0.0;
    }
    f64::from((a - b).abs()) / f64::from(a.abs().max(b.abs()))
}

/// Compare MCU and host output line by line: kinds, indices and status
/// words equal, numbers within `tolerance` relative. Returns (lines,
/// bit-identical lines, largest relative difference).
pub fn compare_outputs(
    mcu: &str,
    host: &str,
    tolerance: f64,
) -> Result<(usize, usize, f64), ParityError> {
    let (m, h) = (result_lines(mcu), result_lines(host));
    if m.len() != h.len() {
        return Err(ParityError::Mismatch(format!(
            "{} result lines from the MCU, {} from the host",
            m.len(),
            h.len()
        )));
    }
    let (mut identical, mut worst) = (0, 0.0f64);
    for (a, b) in m.iter().zip(&h) {
        if a == b {
            identical += 1;
            continue;
        }
        let (at, bt): (Vec<&str>, Vec<&str>) = (a.split(' ').collect(), b.split(' ').collect());
        // kind, index and (for step lines) the status word must be equal.
        let fixed = if at.first() == Some(&"step") { 3 } else { 2 };
        if at.len() != bt.len() || at.len() < fixed || at[..fixed] != bt[..fixed] {
            return Err(ParityError::Mismatch(format!("MCU `{a}` vs host `{b}`")));
        }
        for (x, y) in at[fixed..].iter().zip(&bt[fixed..]) {
            let (Some(x), Some(y)) = (bits(x), bits(y)) else {
                return Err(ParityError::Mismatch(format!("MCU `{a}` vs host `{b}`")));
            };
            let d = relative_difference(x, y);
            if d > tolerance {
                return Err(ParityError::Mismatch(format!(
                    "MCU `{a}` vs host `{b}`: {x} vs {y}"
                )));
            }
            worst = worst.max(d);
        }
    }
    Ok((m.len(), identical, worst))
}

/// The value after `key` on the MCU's `bench infer_x100 …` line.
fn bench_field(out: &str, key: &str) -> Option<f64> {
    let line = out.lines().find(|l| l.starts_with("bench infer_x100 "))?;
    let words: Vec<&str> = line.split(' ').collect();
    let i = words.iter().position(|w| *w == key)?;
    words.get(i + 1)?.parse().ok()
}

/// Vector files made for `net` (any tendon count; `tendril_firmware::vector_gen`)
/// in `dir`, written atomically; returns `dir` made absolute.
#[cfg(feature = "parity")]
pub fn write_vectors(net: &Path, dir: &Path) -> Result<PathBuf, ParityError> {
    let blob =
        std::fs::read(net).map_err(|e| ParityError::Run(format!("{}: {e}", net.display())))?;
    let g = tendril_firmware::vector_gen::generate(&blob)
        .map_err(|e| ParityError::Run(format!("test vectors for {}: {e}", net.display())))?;
    std::fs::create_dir_all(dir)
        .map_err(|e| ParityError::Run(format!("{}: {e}", dir.display())))?;
    for (file, bytes) in [
        ("inputs.bin", &g.inputs),
        ("swap.tnet", &g.swap),
        ("swap_nan.tnet", &g.swap_nan),
    ] {
        let path = dir.join(file);
        crate::fsutil::write_atomic(&path, bytes)
            .map_err(|e| ParityError::Run(format!("{}: {e}", path.display())))?;
    }
    std::fs::canonicalize(dir).map_err(|e| ParityError::Run(format!("{}: {e}", dir.display())))
}

/// [`write_vectors`] of a build without the feature `parity`.
#[cfg(not(feature = "parity"))]
pub fn write_vectors(_net: &Path, _dir: &Path) -> Result<PathBuf, ParityError> {
    Err(without_harness())
}

/// Build, run and compare for `net` (see the module doc): the vectors are
/// made for `net`, so a net for any robot (1–9 tendons) is checked.
pub fn check(root: &Path, net: &Path, target_dir: &Path) -> Result<ParityReport, ParityError> {
    prerequisites()?;
    let net = std::fs::canonicalize(net)
        .map_err(|e| ParityError::Run(format!("{}: {e}", net.display())))?;
    let vectors = write_vectors(&net, &target_dir.join("parity-vectors"))?;
    let elf = build_mcu_bin(
        root,
        "tendril-fw",
        Some(&net),
        Some(&vectors),
        target_dir,
        "parity",
    )?;
    let (ok, mcu) = run_qemu(&elf, Duration::from_secs(120))?;
    if !ok {
        return Err(ParityError::Mismatch(format!(
            "the MCU binary exited with failure:\n{mcu}"
        )));
    }
    // The host run replays the firmware's test vectors, corrupt weight blobs
    // included: the core's own "blob rejected" warnings are expected there and
    // would only alarm a reader of the console. Muted for the host run only
    // (milliseconds): the main job runs other stages beside this one.
    let level = log::max_level();
    log::set_max_level(level.min(log::LevelFilter::Error));
    let host = host_run(&vectors, &net);
    log::set_max_level(level);
    let host = host?;
    let (lines, bit_identical, worst) = compare_outputs(&mcu, &host, 1e-6)?;
    let net_line: Vec<usize> = result_lines(&mcu)
        .first()
        .and_then(|l| l.strip_prefix("net "))
        .map(|l| l.split(' ').filter_map(|w| w.parse().ok()).collect())
        .unwrap_or_default();
    let net_shape: [usize; 4] = net_line
        .try_into()
        .map_err(|_| ParityError::Mismatch("no `net` line in the MCU output".into()))?;
    let stack_bytes = mcu
        .lines()
        .find_map(|l| l.strip_prefix("stack_run "))
        .and_then(|v| v.trim().parse().ok());
    Ok(ParityReport {
        net: net_shape,
        lines,
        bit_identical,
        max_relative_difference: worst,
        instructions_per_inference: bench_field(&mcu, "infer_x100").map(|v| v / 100.0),
        instruction_budget: bench_field(&mcu, "budget_x100").map(|v| v / 100.0),
        stack_bytes,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn outputs_compare_by_value_and_reject_changed_structure() {
        let one = format!("{:08x}", 1.0f32.to_bits());
        let near = format!("{:08x}", (1.0f32 + f32::EPSILON).to_bits());
        let far = format!("{:08x}", 1.001f32.to_bits());
        let host = format!("net 7 2 4 40\ninfer 0 {one}\nstep 1 10 {one}\ndone 2\n");
        // Identical, and a 1-ulp difference within 1e-6.
        assert_eq!(compare_outputs(&host, &host, 1e-6).unwrap(), (4, 4, 0.0));
        let mcu = host.replacen(&format!("infer 0 {one}"), &format!("infer 0 {near}"), 1);
        let (n, same, worst) = compare_outputs(&mcu, &host, 1e-6).unwrap();
        assert_eq!((n, same), (4, 3));
        assert!(worst > 0.0 && worst < 1e-6);
        // A value off by 1e-3, a different status word, a missing line.
        let off = host.replacen(&format!("infer 0 {one}"), &format!("infer 0 {far}"), 1);
        assert!(compare_outputs(&off, &host, 1e-6).is_err());
        let status = host.replacen("step 1 10", "step 1 11", 1);
        assert!(compare_outputs(&status, &host, 1e-6).is_err());
        let short = host.replacen("done 2\n", "", 1);
        assert!(compare_outputs(&short, &host, 1e-6).is_err());
        // Measurements and logs are not compared.
        let noisy = format!("{host}bench infer_x100 5 macs 1 sigmoids 1 budget_x100 9\nlog x\n");
        assert_eq!(compare_outputs(&noisy, &host, 1e-6).unwrap().0, 4);
        assert_eq!(bench_field(&noisy, "infer_x100"), Some(5.0));
        assert_eq!(bench_field(&noisy, "budget_x100"), Some(9.0));
    }
}

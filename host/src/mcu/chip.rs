//! Start and stop QEMU with the chip image; build the image.

use std::fs;
use std::io::Read;
use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};

/// The emulator binary.
pub const QEMU: &str = "qemu-system-arm";
/// The chip's Rust target.
pub const TARGET: &str = "thumbv7em-none-eabihf";
/// The chip's log line once the board is up (`Stm32f405::take`).
const READY_LINE: &str = "board stm32f405";
/// How long QEMU may take to create the link socket.
const SOCKET_WAIT: Duration = Duration::from_secs(5);

/// A running QEMU `netduinoplus2` with a chip image. Dropping it kills
/// and reaps QEMU and removes the socket and the log file; QEMU also dies
/// with the process that started it (`PR_SET_PDEATHSIG`), so a killed test
/// leaves no emulator running.
pub struct Chip {
    child: Child,
    socket: PathBuf,
    log: PathBuf,
}

/// Whether `program` is on `PATH`.
fn on_path(program: &str) -> bool {
    std::env::var_os("PATH")
        .is_some_and(|paths| std::env::split_paths(&paths).any(|dir| dir.join(program).is_file()))
}

/// One line saying what to install, if QEMU is missing.
fn check_qemu() -> Result<()> {
    if !on_path(QEMU) {
        bail!("{QEMU} not found: install it with `apt-get install qemu-system-arm`");
    }
    Ok(())
}

/// The one check that this machine can build and run the firmware under
/// QEMU (the parity stage, the chip in the loop): `qemu-system-arm` on the
/// `PATH` and the Rust target installed; otherwise one line saying what to
/// install.
pub fn check_tools() -> Result<()> {
    check_qemu()?;
    let rustc = std::env::var_os("RUSTC").unwrap_or_else(|| "rustc".into());
    let sysroot = Command::new(&rustc)
        .args(["--print", "sysroot"])
        .output()
        .context("running rustc --print sysroot")?;
    let sysroot = PathBuf::from(String::from_utf8_lossy(&sysroot.stdout).trim());
    if !sysroot.join("lib/rustlib").join(TARGET).is_dir() {
        bail!("Rust target {TARGET} not installed: install it with `rustup target add {TARGET}`");
    }
    Ok(())
}

/// Remove the link sockets (and their `.log` files) that runs killed by
/// SIGKILL left in `dir`: names `tendril-…<pid>…` with `.sock` in them
/// whose pid (the first number in the name) is no live process.
pub fn remove_stale_sockets(dir: &Path) {
    let Ok(entries) = fs::read_dir(dir) else {
        return;
    };
    for entry in entries.filter_map(std::result::Result::ok) {
        let name = entry.file_name().to_string_lossy().into_owned();
        if !(name.starts_with("tendril-") && name.contains(".sock")) {
            continue;
        }
        let pid = name
            .split(|c: char| !c.is_ascii_digit())
            .find(|s| !s.is_empty())
            .and_then(|s| s.parse::<u32>().ok());
        if let Some(pid) = pid {
            if !Path::new(&format!("/proc/{pid}")).exists() {
                let _ = fs::remove_file(entry.path());
            }
        }
    }
}

impl Chip {
    /// Start `qemu-system-arm -M netduinoplus2 -nographic -kernel IMAGE`
    /// with USART1 on a listening Unix socket at `socket` (a stale file
    /// there is removed first) and USART2 (the chip's log) written to
    /// `socket` + `.log`. Returns once the socket exists; connect with
    /// [`super::McuLink::connect`]. Until a client connects, what the chip
    /// sends is dropped (QEMU's `wait=off`).
    pub fn start(image: &Path, socket: &Path) -> Result<Chip> {
        check_qemu()?;
        if !image.is_file() {
            bail!("chip image {} not found", image.display());
        }
        check_arm_elf(image)?;
        if let Some(dir) = socket.parent() {
            remove_stale_sockets(dir);
        }
        if fs::symlink_metadata(socket).is_ok() {
            fs::remove_file(socket)
                .with_context(|| format!("removing stale socket {}", socket.display()))?;
        }
        let mut log = socket.as_os_str().to_owned();
        log.push(".log");
        let log = PathBuf::from(log);
        let mut serial = std::ffi::OsString::from("unix:");
        serial.push(socket);
        serial.push(",server=on,wait=off");
        let mut log_serial = std::ffi::OsString::from("file:");
        log_serial.push(&log);
        let mut cmd = Command::new(QEMU);
        // Single-threaded TCG: the vCPU runs in QEMU's main loop, so each
        // received byte needs no hand-off between a vCPU thread and the
        // I/O thread (the USART model takes one byte at a time). Measured
        // with tests/tests/mcu_board.rs: 74 kB/s instead of 12.6 kB/s
        // host → chip → host, 64-byte round trip p50 1.0 ms instead of 5.0.
        cmd.args(["-M", "netduinoplus2", "-accel", "tcg,thread=single"])
            .args(["-nographic", "-monitor", "none"])
            .arg("-kernel")
            .arg(image)
            .arg("-serial")
            .arg(&serial)
            .arg("-serial")
            .arg(&log_serial)
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::piped());
        // SAFETY: prctl is async-signal-safe; nothing else runs between
        // fork and exec.
        unsafe {
            cmd.pre_exec(|| {
                if libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGKILL) != 0 {
                    return Err(std::io::Error::last_os_error());
                }
                // The parent may have died before the prctl took effect.
                if libc::getppid() == 1 {
                    return Err(std::io::Error::other("parent exited"));
                }
                Ok(())
            });
        }
        let child = cmd.spawn().with_context(|| format!("starting {QEMU}"))?;
        let mut chip = Chip {
            child,
            socket: socket.to_path_buf(),
            log,
        };
        let t0 = Instant::now();
        while !socket.exists() {
            if let Some(status) = chip.child.try_wait()? {
                let mut err = String::new();
                if let Some(mut e) = chip.child.stderr.take() {
                    let _ = e.read_to_string(&mut err);
                }
                bail!(
                    "{QEMU} exited ({status}) before opening its socket: {}",
                    err.trim()
                );
            }
            if t0.elapsed() > SOCKET_WAIT {
                bail!(
                    "{QEMU} did not create {} within {SOCKET_WAIT:?}",
                    socket.display()
                );
            }
            std::thread::sleep(Duration::from_millis(5));
        }
        Ok(chip)
    }

    /// Run every QEMU thread under `SCHED_FIFO` at `priority` (needs root
    /// or CAP_SYS_NICE): the emulated chip is the loop's controller, and on
    /// a busy 2-core machine a normal-priority QEMU is starved by the
    /// loop's real-time processes and anything else (measured: setpoint →
    /// command p50 went from 0.7 to 3.8 periods with a compile running).
    /// The chip sleeps in WFI between ticks, so QEMU does not spin. Returns
    /// how many threads it could set.
    pub fn make_realtime(&self, priority: i32) -> usize {
        let param = libc::sched_param {
            sched_priority: priority,
        };
        let tasks = format!("/proc/{}/task", self.child.id());
        let Ok(dir) = fs::read_dir(&tasks) else {
            return 0;
        };
        dir.filter_map(|e| e.ok()?.file_name().to_str()?.parse::<i32>().ok())
            // SAFETY: plain syscall on a thread id of our own child.
            .filter(|&tid| unsafe { libc::sched_setscheduler(tid, libc::SCHED_FIFO, &param) == 0 })
            .count()
    }

    /// The link socket's path.
    pub fn socket(&self) -> &Path {
        &self.socket
    }

    /// What the chip logged on USART2 so far (`log <level> <message>`
    /// lines; empty if nothing yet).
    pub fn log(&self) -> String {
        fs::read_to_string(&self.log).unwrap_or_default()
    }

    /// Wait until the chip has brought its board up (its log has the
    /// board's start-up line, written once USART1 receives), at most
    /// `timeout`. Bytes sent before that are lost: QEMU's USART drops what
    /// arrives while the UART is not enabled yet.
    pub fn wait_ready(&mut self, timeout: Duration) -> Result<()> {
        let t0 = Instant::now();
        while !self.log().contains(READY_LINE) {
            if !self.is_running() {
                bail!(
                    "{QEMU} exited before the chip came up; log: {}",
                    self.log().trim()
                );
            }
            if t0.elapsed() > timeout {
                bail!(
                    "the chip did not come up within {timeout:?}; log: {}",
                    self.log().trim()
                );
            }
            std::thread::sleep(Duration::from_millis(2));
        }
        Ok(())
    }

    /// Whether QEMU is still running.
    pub fn is_running(&mut self) -> bool {
        matches!(self.child.try_wait(), Ok(None))
    }
}

impl Drop for Chip {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
        let _ = fs::remove_file(&self.socket);
        let _ = fs::remove_file(&self.log);
    }
}

/// Refuse what is not a 32-bit ARM ELF executable (QEMU would load any
/// file as raw code and the chip would simply never answer).
fn check_arm_elf(image: &Path) -> Result<()> {
    let mut head = [0u8; 20];
    let read = fs::File::open(image)
        .and_then(|mut f| f.read_exact(&mut head))
        .with_context(|| format!("reading chip image {}", image.display()));
    let ok = read.is_ok()
        && head.starts_with(b"\x7fELF")
        && head[4] == 1 // 32-bit
        && u16::from_le_bytes([head[18], head[19]]) == 40; // EM_ARM
    if !ok {
        bail!(
            "{} is not an ARM ELF image (build the controller with `cargo build -p \
             tendril-firmware --features stm32f405 --bin tendril-fw-stm32 --release --target {TARGET}`)",
            image.display()
        );
    }
    Ok(())
}

/// Build the controller image (`tendril-fw-stm32`, release): see
/// [`build_image`].
pub fn locate_image() -> Result<PathBuf> {
    build_image("tendril-fw-stm32")
}

/// Build the board's bring-up image (`tendril-fw-bringup`: echo and
/// status lines, tests/tests/mcu_board.rs).
pub fn locate_bringup_image() -> Result<PathBuf> {
    build_image("tendril-fw-bringup")
}

/// Build the chip image `bin` (release) into
/// `$CARGO_TARGET_DIR` (or `<workspace>/target`) + `/thumbv7em-chip` — a
/// target directory of its own, so a build from inside `cargo test` does
/// not wait on the outer build's lock — and return its path. Fails with
/// one line naming what to install when QEMU or the Rust target is
/// missing.
pub fn build_image(bin: &str) -> Result<PathBuf> {
    check_tools()?;
    let workspace = Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .context("host crate has no parent directory")?
        .to_path_buf();
    let base = std::env::var_os("CARGO_TARGET_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| workspace.join("target"));
    let dir = base.join("thumbv7em-chip");
    if !workspace.join("firmware").join("Cargo.toml").is_file() {
        bail!(
            "no chip image given and no source checkout to build one at {} (this tendril was \
             built there): build the image and give it with --mcu-image",
            workspace.display()
        );
    }
    // Said, not done silently: it compiles in the checkout this binary was
    // built from, whatever the current directory (a minute the first time).
    static SAID: std::sync::Once = std::sync::Once::new();
    SAID.call_once(|| {
        log::info!(
            "building the chip image {bin} in {} (cargo build --release; give --mcu-image to \
             use one you built)",
            workspace.display()
        );
    });
    cargo_build_firmware(
        &workspace,
        bin,
        "stm32f405",
        &dir,
        &[("TENDRIL_FW_NET", None)],
    )
    .map_err(|e| anyhow::anyhow!("building {bin} failed: {e}"))
}

/// The one build of a firmware binary: `cargo build --release` of `bin`
/// from the firmware crate with `features`, for the chip's target, into
/// `target_dir`, with `env` set (`None`: removed, so the calling build's
/// value does not leak in). Plain rustc compiles it whatever wrapper the
/// calling build uses: the image is measured (instruction counts) and
/// compared bit for bit, and CI lints its test build through
/// clippy-driver, which turns MIR optimisations off (a swap slice came out
/// 25 % longer) and would make this a second build. Cargo's progress lines
/// are not the user's business; its first error line is the error.
/// Returns the ELF's path.
pub fn cargo_build_firmware(
    workspace: &Path,
    bin: &str,
    features: &str,
    target_dir: &Path,
    env: &[(&str, Option<&Path>)],
) -> Result<PathBuf, String> {
    let cargo = std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into());
    let mut cmd = Command::new(cargo);
    cmd.current_dir(workspace)
        .args(["build", "-p", "tendril-firmware", "--features", features])
        .args(["--bin", bin, "--release", "--target", TARGET])
        .env("CARGO_TARGET_DIR", target_dir)
        .env_remove("RUSTC_WORKSPACE_WRAPPER")
        .env_remove("RUSTC_WRAPPER");
    for (name, value) in env {
        match value {
            Some(v) => cmd.env(name, v),
            None => cmd.env_remove(name),
        };
    }
    let out = cmd
        .stdin(Stdio::null())
        .output()
        .map_err(|e| format!("starting cargo build: {e}"))?;
    if !out.status.success() {
        return Err(format!(
            "cargo build of {bin} failed ({}): {}",
            out.status,
            first_error_line(&out.stderr)
        ));
    }
    let elf = target_dir.join(TARGET).join("release").join(bin);
    if !elf.is_file() {
        return Err(format!("cargo built no {}", elf.display()));
    }
    Ok(elf)
}

/// The first `error` line of a cargo build's captured stderr: what a
/// message about a failed build quotes, instead of cargo's whole output.
fn first_error_line(stderr: &[u8]) -> String {
    String::from_utf8_lossy(stderr)
        .lines()
        .find(|l| l.starts_with("error"))
        .unwrap_or("(no error line)")
        .to_string()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_the_sockets_of_dead_runs_are_removed() {
        let dir = tempfile::tempdir().unwrap();
        let me = std::process::id();
        // A pid above any kernel's pid_max (at most 2^22) is never alive.
        let dead = 4_000_000_000u32;
        let names = [
            format!("tendril-sim-{dead}-123.chip.sock"),
            format!("tendril-sim-{dead}-123.chip.sock.log"),
            format!("tendril-chip-{me}.sock"),
            "other-9.sock".to_string(),
        ];
        for n in &names {
            fs::write(dir.path().join(n), b"").unwrap();
        }
        remove_stale_sockets(dir.path());
        let left: Vec<bool> = names.iter().map(|n| dir.path().join(n).exists()).collect();
        assert_eq!(left, [false, false, true, true]);
    }

    #[test]
    fn the_chip_runs_only_whole_tick_periods_and_says_which_rates_are_near() {
        use crate::mcu::bridge::check_chip_rate;
        for ok in [1000.0, 500.0, 100.0, 1000.0 / 3.0, 1.0] {
            assert_eq!(check_chip_rate(ok), Ok(()), "{ok}");
        }
        let err = check_chip_rate(300.0).unwrap_err();
        assert!(err.contains("250.0000 and 333.3333 Hz"), "{err}");
        assert!(check_chip_rate(20_000.0).is_err());
        assert!(check_chip_rate(f64::NAN).is_err());
    }
}

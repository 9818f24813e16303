//! Regenerate the files the MCU binary embeds, in `firmware/vectors/`:
//! - `default.tnet`: the built-in net (build.rs turns it into the flash
//!   `DEFAULT_NET`): a copy of `--tnet FILE`, normally the net the main job
//!   exports (`cargo run --release` writes `out/model.tnet`, deterministic
//!   with seed 1), or with `--synthetic` a deterministic 7-12-4 net;
//! - `inputs.bin`: control-loop inputs inside that net's input box, plus
//!   NaN/∞/out-of-box/stale/clock-fault/watchdog/hot-swap cases;
//! - `swap.tnet`: a small synthetic update (7-12-O, same input box and output
//!   ranges) that the hot-swap steps load into the RAM slot;
//! - `swap_nan.tnet`: the same with its last weight NaN and the CRC
//!   recomputed (rejected only by the value checks).
//!
//! ```text
//! cargo run --release                                                        # writes out/model.tnet
//! cargo run -p tendril-firmware --features vector-gen --example gen_vectors -- --tnet out/model.tnet
//! cargo run -p tendril-firmware --features vector-gen --example gen_vectors                        # re-derive from default.tnet
//! cargo run -p tendril-firmware --features vector-gen --example gen_vectors -- --synthetic        # synthetic default net
//! ```
//! Options: `--tnet FILE` (default: the current `default.tnet`),
//! `--synthetic`, `--out-dir DIR` (default `firmware/vectors`).

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use tendril_firmware::synth::synthetic_blob;
use tendril_firmware::vector_gen::generate;

fn write_atomic(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    let tmp = path.with_extension("tmp");
    std::fs::write(&tmp, bytes)?;
    std::fs::rename(&tmp, path)
}

fn run() -> Result<(), String> {
    let mut tnet: Option<PathBuf> = None;
    let mut synthetic = false;
    let mut out_dir = PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/vectors"));
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--tnet" => tnet = Some(args.next().ok_or("--tnet needs a file")?.into()),
            "--synthetic" => synthetic = true,
            "--out-dir" => out_dir = args.next().ok_or("--out-dir needs a directory")?.into(),
            "-h" | "--help" => {
                println!("usage: gen_vectors [--tnet FILE | --synthetic] [--out-dir DIR]");
                return Ok(());
            }
            other => return Err(format!("unknown argument {other:?}")),
        }
    }

    let blob = if synthetic {
        let mut buf = vec![0u8; 8192];
        let n = synthetic_blob(20_261_122, 12, 4, 10.0, &mut buf)
            .map_err(|e| format!("synthetic net: {e}"))?;
        buf.truncate(n);
        buf
    } else {
        let path = tnet.unwrap_or_else(|| out_dir.join("default.tnet"));
        std::fs::read(&path).map_err(|e| format!("{}: {e}", path.display()))?
    };
    let g = generate(&blob)?;
    if g.outside > 0 {
        eprintln!(
            "gen_vectors: warning: {} path poses fall outside the net's input box",
            g.outside
        );
    }
    std::fs::create_dir_all(&out_dir).map_err(|e| format!("{}: {e}", out_dir.display()))?;
    let tnet_path = out_dir.join("default.tnet");
    let vec_path = out_dir.join("inputs.bin");
    for (path, bytes) in [
        (tnet_path.clone(), &blob),
        (vec_path.clone(), &g.inputs),
        (out_dir.join("swap.tnet"), &g.swap),
        (out_dir.join("swap_nan.tnet"), &g.swap_nan),
    ] {
        write_atomic(&path, bytes).map_err(|e| format!("{}: {e}", path.display()))?;
    }
    eprintln!(
        "gen_vectors: wrote {} ({} bytes, net {}-{}-{}), {} ({} steps), swap.tnet, swap_nan.tnet",
        tnet_path.display(),
        blob.len(),
        g.shape[0],
        g.shape[1],
        g.shape[2],
        vec_path.display(),
        g.steps
    );
    Ok(())
}

fn main() -> ExitCode {
    match run() {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("gen_vectors: {e}");
            ExitCode::FAILURE
        }
    }
}

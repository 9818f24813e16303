//! For the MCU build only (`target_os = "none"`): put the workspace's
//! `memory.x` where cortex-m-rt's `link.x` finds it and link the binary with
//! `link.x` (as cortex-m-quickstart does). Host builds need nothing.

use std::env;
use std::fs;
use std::path::PathBuf;

fn main() {
    let manifest = PathBuf::from(env::var_os("CARGO_MANIFEST_DIR").unwrap_or_default());
    let memory_x = manifest.join("..").join("memory.x");
    println!("cargo:rerun-if-changed={}", memory_x.display());
    println!("cargo:rerun-if-changed=build.rs");
    if env::var("CARGO_CFG_TARGET_OS").as_deref() != Ok("none") {
        return;
    }
    let out = PathBuf::from(env::var_os("OUT_DIR").unwrap_or_default());
    if let Err(e) = fs::copy(&memory_x, out.join("memory.x")) {
        panic!("cannot copy {} to OUT_DIR: {e}", memory_x.display());
    }
    println!("cargo:rustc-link-search={}", out.display());
    println!("cargo:rustc-link-arg-bins=-Tlink.x");
}

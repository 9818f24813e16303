//! Empty on purpose: this test target exists so that cargo builds the
//! `tendril` binary, which the process-level tests in `tests/` run (see the
//! `[[test]]` entry in host/Cargo.toml).

fn main() {}

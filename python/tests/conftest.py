"""Shared fixtures: the workspace root and the `tendril` CLI binary the
results are compared with (scripts/python-test builds it)."""

import contextlib
import fcntl
import os
import pathlib
import subprocess
import tempfile

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]


@pytest.fixture(scope="session")
def root() -> pathlib.Path:
    return ROOT


@pytest.fixture(scope="session")
def cli() -> pathlib.Path:
    """The CLI built from this checkout: $TENDRIL_BIN, else target/debug/tendril.
    A missing binary is an error, not a skip: these tests exist to compare."""
    path = pathlib.Path(os.environ.get("TENDRIL_BIN", ROOT / "target" / "debug" / "tendril"))
    if not path.is_file():
        pytest.fail(f"{path}: no tendril binary; run `cargo build --bin tendril` or set TENDRIL_BIN")
    return path


def run_cli(cli: pathlib.Path, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [str(cli), *args], cwd=ROOT, capture_output=True, text=True, check=False
    )


@contextlib.contextmanager
def one_loop_at_a_time():
    """Hold the lock the Rust tests' closed loops take on the CPU a loop
    started from here runs on, the last one this process may use
    (tests/src/lib.rs, `loop_lock_path`: the same file, flock'ed):
    scripts/test runs these tests beside the Rust real-time ones, and two
    closed loops must not share a CPU (each measures its own periods)."""
    cpu = max(os.sched_getaffinity(0), default=0)
    path = pathlib.Path(tempfile.gettempdir()) / f"tendril-realtime-tests-cpu{cpu}.lock"
    with open(path, "a") as f:
        fcntl.flock(f, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(f, fcntl.LOCK_UN)


"""Shared fixtures: the workspace root and the `tendril` CLI binary the
results are compared with (scripts/python-test builds it)."""

import os
import pathlib
import subprocess

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

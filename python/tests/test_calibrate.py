"""Robot.calibrate: the library call of `tendril calibrate` (docs/design.md §11)
gives the CLI's robot file and report."""

import json

import pytest

import tendril
from conftest import run_cli


def heavier_measurements(tmp_path, root, cli):
    text = (root / "robots" / "seed-4t.toml").read_text()
    real = text.replace("density = 39317.0", "density = 45214.55")
    assert real != text
    (tmp_path / "real.toml").write_text(real)
    done = run_cli(cli, "generate", "--robot", str(tmp_path / "real.toml"), "--samples", "60",
                   "--noise-mm", "0.05", "--frame-offset-mm", "2,0,-1", "--quiet",
                   "--out", str(tmp_path / "m.csv"))
    assert done.returncode == 0, done.stderr
    return tmp_path / "m.csv"


def test_calibrate_matches_the_cli(tmp_path, root, cli):
    data = heavier_measurements(tmp_path, root, cli)
    nominal = tendril.Robot.load(root / "robots" / "seed-4t.toml")
    robot, report = nominal.calibrate(data, fit="density,base_t", positions_only=True)
    done = run_cli(cli, "calibrate", "--robot", str(root / "robots" / "seed-4t.toml"),
                   "--data", str(data), "--fit", "density,base_t", "--positions-only",
                   "--out", str(tmp_path / "cal.toml"))
    assert done.returncode == 0, done.stderr
    assert robot.toml == (tmp_path / "cal.toml").read_text()
    cli_report = json.loads((tmp_path / "cal.report.json").read_text())
    for key in ("parameters", "unidentifiable", "held_out_after", "downweighted"):
        assert report[key] == cli_report[key], key
    density = next(p for p in report["parameters"] if p["name"] == "density")
    assert abs(density["fitted"] - 45214.55) < 2 * density["half_width_95"]


def test_calibrate_bad_input_is_a_value_error(tmp_path):
    (tmp_path / "m.csv").write_text("t0,t1,t2,t3,px,py\n1,0,0,0,0,0\n")
    with pytest.raises(ValueError, match="missing column pz"):
        tendril.Robot.default().calibrate(tmp_path / "m.csv")
    with pytest.raises(ValueError, match="unknown parameter"):
        tendril.Robot.default().calibrate(tmp_path / "m.csv", fit="E,stiffness")

"""Robot.calibrate: the library call of `tendril calibrate` (docs/design.md §11)
gives the CLI's robot file and report."""

import json
import math

import numpy as np
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


def test_calibration_plan_matches_the_cli(tmp_path, root, cli):
    """Robot.calibration_plan is `calibrate --plan N --plan-tip-mass-g G`:
    the same rows, the hung mass's weight along the file's gravity."""
    robot = tendril.Robot.load(root / "robots" / "seed-4t.toml")
    tensions, forces = robot.calibration_plan(12, tip_mass_g=50.0)
    assert tensions.shape == (12, 4) and forces.shape == (12, 3)
    done = run_cli(cli, "calibrate", "--robot", str(root / "robots" / "seed-4t.toml"),
                   "--plan", "12", "--plan-tip-mass-g", "50", "--out", str(tmp_path / "plan.csv"))
    assert done.returncode == 0, done.stderr
    rows = np.loadtxt(tmp_path / "plan.csv", delimiter=",", skiprows=1)
    assert np.array_equal(rows[:, :4], tensions)
    assert np.array_equal(rows[:, 4:], forces)
    hung = forces[np.any(forces != 0.0, axis=1)]
    assert len(hung) > 0
    # 50 g under g = 9.81 m/s² along +x (the file's gravity).
    assert np.allclose(hung, [0.05 * 9.81, 0.0, 0.0])
    with pytest.raises(ValueError, match="tip_mass_g"):
        robot.calibration_plan(12, tip_mass_g=-1.0)


def test_fit_step_recovers_a_damped_sinusoid_and_matches_the_cli(tmp_path, cli):
    """tendril.fit_step on the closed form of a ringing tip: x(t) = a e^(-ζωt)
    cos(ω_d t) about its rest, sampled at 400 Hz with 20 µm of jitter; the
    intervals cover the f and ζ it was made with, and the dict is the CLI's
    `calibrate --step` "fit"."""
    f, zeta = 3.4, 0.05
    w = 2 * math.pi * f
    wd = w * math.sqrt(1 - zeta**2)
    t = np.arange(0, 3, 1 / 400)
    rng = np.random.default_rng(7)
    x = 0.03 + 0.002 * np.exp(-zeta * w * t) * np.cos(wd * t) + rng.normal(0, 2e-5, t.size)
    trace = tmp_path / "step.csv"
    with open(trace, "w") as out:
        out.write("t_s,x_m,y_m,z_m\n")
        for row in zip(t, x):
            out.write(f"{float(row[0])!r},{float(row[1])!r},0.0,0.39\n")
    fit = tendril.fit_step(trace)
    lo, hi = fit["freq_hz"]["interval_95"]
    assert lo <= f <= hi, fit["freq_hz"]
    lo, hi = fit["damping_ratio"]["interval_95"]
    assert lo <= zeta <= hi, fit["damping_ratio"]
    done = run_cli(cli, "calibrate", "--step", str(trace), "--out", "-")
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout)["fit"] == fit
    with pytest.raises(ValueError):
        tendril.fit_step(tmp_path / "missing.csv")


def test_base_is_the_files_frame():
    plain = tendril.Robot.default()
    t, r = plain.base
    assert np.array_equal(t, np.zeros(3)) and np.array_equal(r, np.zeros(3))
    turned = tendril.Robot.from_toml(plain.toml + "\n[base]\ntranslation = [0.1, 0.0, 0.0]\n")
    t, r = turned.base
    assert np.array_equal(t, [0.1, 0.0, 0.0]) and np.array_equal(r, np.zeros(3))


def test_fit_residual_gives_the_rows_of_generate_residual_from(tmp_path, root, cli):
    """tendril.fit_residual + Residual.apply on generate's rows are the rows of
    `tendril generate --residual-from`, and those move like the real robot
    (a robot 8 % softer than its file) where the file's own rows do not."""
    text = (root / "robots" / "seed-4t.toml").read_text()
    real = text.replace("youngs_modulus = 207e9", "youngs_modulus = 190.44e9")
    assert real != text
    (tmp_path / "real.toml").write_text(real)
    done = run_cli(cli, "generate", "--robot", str(tmp_path / "real.toml"), "--samples", "300",
                   "--seed", "3", "--noise-mm", "0.05", "--quiet", "--out", str(tmp_path / "m.csv"))
    assert done.returncode == 0, done.stderr
    (tmp_path / "m.json").unlink()
    rows = np.loadtxt(tmp_path / "m.csv", delimiter=",", skiprows=1)
    nominal = tendril.Robot.load(root / "robots" / "seed-4t.toml")
    residual = tendril.fit_residual(nominal, rows[:, :4], rows[:, 4:])
    report = residual.report
    assert report["rows"] == 300
    assert report["valid_position_rms_mm"][1] < 0.2 * report["valid_position_rms_mm"][0]

    tensions, model = tendril.generate(nominal, 100, seed=9)
    moved = residual.apply(tensions, model)
    done = run_cli(cli, "generate", "--robot", str(root / "robots" / "seed-4t.toml"), "--samples",
                   "100", "--seed", "9", "--residual-from", str(tmp_path / "m.csv"), "--quiet",
                   "--out", str(tmp_path / "r.csv"))
    assert done.returncode == 0, done.stderr
    cli_rows = np.loadtxt(tmp_path / "r.csv", delimiter=",", skiprows=1)
    assert np.allclose(cli_rows[:, 4:], moved, rtol=0, atol=1e-12)
    truth, _ = tendril.Robot.load(tmp_path / "real.toml").fk(tensions)
    off = lambda p: np.max(np.linalg.norm(p[:, :3] - truth[:, :3], axis=1))
    assert off(model) > 2e-3
    assert off(moved) < 0.1 * off(model)

    with pytest.raises(ValueError, match="tensions: expected shape"):
        tendril.fit_residual(tendril.Robot.load(root / "robots" / "seed-1t.toml"),
                             rows[:, :4], rows[:, 4:])

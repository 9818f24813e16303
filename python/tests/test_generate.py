"""generate: the library's job, the same rows as `tendril generate`, and the
round trip generate → fk."""

import json

import numpy as np

import tendril
from conftest import run_cli


def read_dataset(path, k):
    data = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
    return data[:, :k], data[:, k:]


def test_generate_writes_the_cli_dataset_and_returns_its_rows(tmp_path, root, cli):
    robot = tendril.Robot.load(root / "robots" / "seed-4t.toml")
    tensions, poses = tendril.generate(robot, 300, seed=5, sampler="uniform", path=tmp_path / "py.csv")
    assert tensions.shape == (300, 4) and poses.shape == (300, 7)
    sidecar = json.loads((tmp_path / "py.json").read_text())
    assert sidecar["count"] == 300 and sidecar["seed"] == 5 and sidecar["sampler"] == "uniform"

    done = run_cli(cli, "generate", "--samples", "300", "--seed", "5", "--sampler", "uniform",
                   "--quiet", "--out", str(tmp_path / "cli.csv"))
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "py.csv").read_bytes() == (tmp_path / "cli.csv").read_bytes()
    # The returned arrays are the file's values exactly.
    file_t, file_p = read_dataset(tmp_path / "py.csv", 4)
    assert np.array_equal(tensions, file_t) and np.array_equal(poses, file_p)
    # Without a path: the same rows, nothing written.
    t2, p2 = tendril.generate(tendril.Robot.default(), 300, seed=5, sampler="uniform")
    assert np.array_equal(t2, tensions) and np.array_equal(p2, poses)


def test_generated_rows_round_trip_through_fk(tmp_path):
    robot = tendril.Robot.default()
    tensions, poses = tendril.generate(robot, 200, seed=3)
    # Adjacent sampler: exactly two neighbouring tendons pull.
    assert ((tensions > 0).sum(axis=1) <= 2).all()
    assert ((tensions >= 0) & (tensions <= robot.max_tensions)).all()
    again, converged = robot.fk(tensions)
    assert converged.all()
    # generate warm-starts along a chain, fk solves each row cold: the two
    # agree to the solver tolerance, not bit for bit.
    assert np.abs(again[:, :3] - poses[:, :3]).max() < 1e-8  # m
    assert np.abs(again[:, 3:] - poses[:, 3:]).max() < 1e-8


def test_a_robot_from_text_generates_in_memory():
    robot = tendril.Robot.from_toml(tendril.Robot.default().toml.replace("seed-4t", "copy"))
    t, p = tendril.generate(robot, 50, seed=2)
    t0, p0 = tendril.generate(tendril.Robot.default(), 50, seed=2)
    assert np.array_equal(t, t0) and np.array_equal(p, p0)

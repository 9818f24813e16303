"""robot.fk / robot.shape against the CLI (bit for bit) and closed forms."""

import csv
import math

import numpy as np
import pytest

import tendril
from conftest import run_cli


def write_csv(path, header, rows):
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(header)
        # repr is Python's shortest round-trip text: the CLI reads the same doubles.
        w.writerows([[repr(float(x)) for x in row] for row in rows])


def read_cli_poses(path):
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    cols = ["px", "py", "pz", "qw", "qx", "qy", "qz"]
    poses = np.array([[float(r[c]) if r[c] else np.nan for c in cols] for r in rows])
    converged = np.array([r["converged"] == "true" for r in rows])
    return poses, converged


def random_tensions(robot, n, seed):
    rng = np.random.default_rng(seed)
    t = rng.uniform(0.0, 1.0, (n, robot.n_tendons)) * robot.max_tensions
    t[5] = t[4]  # a repeated row: warm-started in the batch, as in the CLI
    t[6] = 0.0
    return t


def test_fk_is_bit_identical_to_cli_batch(tmp_path, cli):
    robot = tendril.Robot.default()
    tensions = random_tensions(robot, 150, seed=7)
    header = [f"t{i}" for i in range(robot.n_tendons)]
    write_csv(tmp_path / "in.csv", header, tensions)
    done = run_cli(cli, "fk", "--input", str(tmp_path / "in.csv"), "--output", str(tmp_path / "out.csv"))
    assert done.returncode == 0, done.stderr
    cli_poses, cli_converged = read_cli_poses(tmp_path / "out.csv")

    poses, converged = robot.fk(tensions)
    assert poses.shape == (150, 7) and converged.shape == (150,)
    assert converged.all() and cli_converged.all()
    assert np.array_equal(poses, cli_poses)


def test_fk_with_tip_wrench_is_bit_identical_to_cli(tmp_path, cli):
    robot = tendril.Robot.default()
    tensions = random_tensions(robot, 40, seed=3)
    rng = np.random.default_rng(4)
    force = rng.uniform(-0.05, 0.05, (40, 3))
    moment = rng.uniform(-0.002, 0.002, (40, 3))
    header = [f"t{i}" for i in range(robot.n_tendons)] + ["fx", "fy", "fz", "mx", "my", "mz"]
    write_csv(tmp_path / "in.csv", header, np.hstack([tensions, force, moment]))
    done = run_cli(cli, "fk", "--input", str(tmp_path / "in.csv"), "--output", str(tmp_path / "out.csv"))
    assert done.returncode == 0, done.stderr
    cli_poses, _ = read_cli_poses(tmp_path / "out.csv")

    poses, converged = robot.fk(tensions, tip_force=force, tip_moment=moment)
    assert converged.all()
    assert np.array_equal(poses, cli_poses)
    # A tip load changes the answer (the arguments are not ignored).
    unloaded, _ = robot.fk(tensions)
    assert np.abs(unloaded - poses).max() > 1e-4


def test_rows_do_not_depend_on_their_order_or_neighbours():
    robot = tendril.Robot.default()
    tensions = random_tensions(robot, 100, seed=11)
    poses, _ = robot.fk(tensions)
    perm = np.random.default_rng(0).permutation(100)
    shuffled, _ = robot.fk(tensions[perm])
    assert np.array_equal(shuffled, poses[perm])
    one, ok = robot.fk(tensions[17])
    assert one.shape == (7,) and ok is True
    assert np.array_equal(one, poses[17])


def test_one_tendon_without_gravity_bends_into_the_closed_form_arc():
    """A straight tendon at offset d pulling with T on a weightless rod: constant
    moment T d, so curvature u = T d / (E I) per reference length, and axial
    compression T / (E A): the tip lies on a circular arc of angle u L with
    chord 2 sin(u L / 2) / u * (1 - T / (E A))."""
    E, G, r, L, d, T = 200e9, 80e9, 0.001, 0.3, 0.01, 3.0
    robot = tendril.Robot.from_toml(f"""
name = "arc"
[backbone]
length = {L}
radius = {r}
youngs_modulus = {E}
shear_modulus = {G}
density = 8000.0
[environment]
gravity = [0.0, 0.0, 0.0]
[[tendon]]
offset = {d}
angle_deg = 0.0
max_tension = 10.0
routing = "straight"
""")
    pose, ok = robot.fk([T])
    assert ok
    I, A = math.pi * r**4 / 4, math.pi * r**2
    u = T * d / (E * I)
    theta = u * L
    chord = 2 * math.sin(theta / 2) / u * (1 - T / (E * A))
    assert np.linalg.norm(pose[:3]) == pytest.approx(chord, rel=1e-7)
    assert 2 * math.acos(min(1.0, pose[3])) == pytest.approx(theta, rel=1e-7)
    shape = robot.shape([T], points=11)
    assert shape.shape == (11, 3)
    assert np.allclose(shape[0], 0.0) and np.allclose(shape[-1], pose[:3], atol=1e-12)
    # Every backbone point lies on the same circle: equal distance to its centre.
    centre = np.array([1.0 / u * (1 - T / (E * A)), 0.0, 0.0]) * np.sign(pose[0])
    radii = np.linalg.norm(shape - centre, axis=1)
    assert np.allclose(radii, radii[0], rtol=1e-7)


def test_poses_have_unit_quaternions_with_nonnegative_w():
    robot = tendril.Robot.default()
    poses, _ = robot.fk(random_tensions(robot, 50, seed=5))
    assert np.allclose(np.linalg.norm(poses[:, 3:], axis=1), 1.0, atol=1e-12)
    assert (poses[:, 3] >= 0).all()


def test_a_base_pose_puts_fk_shape_and_ik_in_the_trackers_frame(tmp_path, cli):
    """A robot file with [base] (docs/design.md §2.4): fk, shape and ik work in
    the tracker's frame, x_tracker = R x_base + t with R built here from the
    rotation vector by Rodrigues' formula; fk agrees with the CLI bit for bit."""
    plain = tendril.Robot.default()
    t = np.array([0.2, -0.05, 0.1])
    rv = np.array([0.3, -0.2, 0.8])
    listed = lambda v: ", ".join(repr(float(x)) for x in v)  # noqa: E731
    text = plain.toml + f"\n[base]\ntranslation = [{listed(t)}]\nrotation = [{listed(rv)}]\n"
    turned = tendril.Robot.from_toml(text)
    angle = np.linalg.norm(rv)
    k = rv / angle
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    R = np.eye(3) + math.sin(angle) * K + (1 - math.cos(angle)) * K @ K
    tau = [2.0, 0.5, 0.0, 0.0]
    base_pose, ok = plain.fk(tau)
    pose, ok_turned = turned.fk(tau)
    assert ok and ok_turned
    assert np.allclose(pose[:3], R @ base_pose[:3] + t, atol=1e-12)
    assert pose[3] >= 0.0 and abs(np.linalg.norm(pose[3:]) - 1.0) < 1e-12
    shape = turned.shape(tau, points=5)
    assert np.allclose(shape[0], t, atol=1e-15)
    assert np.allclose(shape[-1], pose[:3], atol=1e-12)
    # The CLI on the same file gives the same bits.
    robot_file = tmp_path / "turned.toml"
    robot_file.write_text(text)
    write_csv(tmp_path / "t.csv", [f"t{i}" for i in range(4)], [tau])
    done = run_cli(cli, "fk", "--robot", str(robot_file), "--input", str(tmp_path / "t.csv"),
                   "--output", str(tmp_path / "p.csv"))
    assert done.returncode == 0, done.stderr
    cli, _ = read_cli_poses(tmp_path / "p.csv")
    assert np.array_equal(cli[0], pose)
    # ik takes the target in the tracker's frame and reaches it there.
    tensions, reached, error, reachable = turned.ik(pose, position_only=True)[:4]
    assert reachable and error < 1e-6
    assert np.allclose(reached[:3], pose[:3], atol=1e-6)
    assert np.allclose(tensions, tau, atol=1e-3)

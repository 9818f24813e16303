"""Net.predict against `tendril ik --model` on the same poses."""

import csv
import math

import numpy as np
import pytest

import tendril
from conftest import run_cli


def test_predict_equals_cli_ik_bit_for_bit(tmp_path, root, cli):
    robot = tendril.Robot.default()
    model = root / "firmware" / "vectors" / "default.tnet"
    _, poses = tendril.generate(robot, 60, seed=9)
    cols = ["px", "py", "pz", "qw", "qx", "qy", "qz"]
    with open(tmp_path / "poses.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(cols)
        w.writerows([[repr(float(x)) for x in p] for p in poses])
    done = run_cli(cli, "ik", "--model", str(model), "--allow-extrapolation",
                   "--input", str(tmp_path / "poses.csv"), "--output", str(tmp_path / "t.csv"))
    assert done.returncode == 0, done.stderr
    with open(tmp_path / "t.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    k = robot.n_tendons
    cli_tensions = np.array([[float(r[f"t{i}"]) for i in range(k)] for r in rows])
    cli_raw = np.array([[float(r[f"raw_t{i}"]) for i in range(k)] for r in rows])

    net = tendril.Net.load(model, robot, allow_extrapolation=True)
    tensions, raw = net.predict(poses)
    assert tensions.shape == (60, k) and raw.shape == (60, k)
    assert np.array_equal(tensions, cli_tensions)
    assert np.array_equal(raw, cli_raw)
    # The firmware's command stage: in the robot's limits; each opposite pair
    # (0, 2), (1, 3) is only shifted together, so its differential is kept
    # wherever it fits the range (f32 arithmetic on the MCU).
    assert ((tensions >= 0) & (tensions <= robot.max_tensions)).all()
    for a, b in ((0, 2), (1, 3)):
        fits = np.abs(raw[:, a] - raw[:, b]) <= robot.max_tensions[a]
        assert fits.any()
        np.testing.assert_allclose((tensions[:, a] - tensions[:, b])[fits],
                                   (raw[:, a] - raw[:, b])[fits], atol=1e-5)
    one, one_raw = net.predict(poses[3])
    assert np.array_equal(one, tensions[3]) and np.array_equal(one_raw, raw[3])


def test_predict_refuses_bad_poses(root):
    net = tendril.Net.load(root / "firmware" / "vectors" / "default.tnet", allow_extrapolation=True)
    pose = np.array([0.0, 0.0, 0.4, 1.0, 0.0, 0.0, 0.0])
    bad = np.vstack([pose, pose])
    bad[1, 0] = np.nan
    with pytest.raises(ValueError, match="poses: row 1: pose px = NaN is not a finite number"):
        net.predict(bad)
    with pytest.raises(ValueError, match="poses: row 0: quaternion .* has norm 2"):
        net.predict([0.0, 0.0, 0.4, 2.0, 0.0, 0.0, 0.0])
    with pytest.raises(ValueError, match=r"poses: expected shape \(7,\) or \(n, 7\)"):
        net.predict(np.zeros((2, 6)))


def test_net_for_another_tendon_count_is_refused(root):
    one_tendon = tendril.Robot.load(root / "robots" / "seed-1t.toml")
    net = root / "firmware" / "vectors" / "default.tnet"
    # The net records its robot (seed-4t): refused for that first ...
    with pytest.raises(ValueError, match="trained for robot seed-4t"):
        tendril.Net.load(net, one_tendon)
    # ... and, with the robot check overridden, for its tendon count.
    with pytest.raises(ValueError, match="tendon count"):
        tendril.Net.load(net, one_tendon, allow_robot_mismatch=True)
    with pytest.raises(OSError, match="nothing.tnet"):
        tendril.Net.load(root / "nothing.tnet")


def test_a_net_for_another_robot_is_refused_unless_allowed(tmp_path, root, cli):
    # A small net trained for the seed robot records its fingerprint (.tnet version 2).
    seed = root / "robots" / "seed-4t.toml"
    data, model = tmp_path / "d.csv", tmp_path / "m.tnet"
    done = run_cli(cli, "generate", "--robot", str(seed), "--samples", "300", "--out", str(data))
    assert done.returncode == 0, done.stderr
    done = run_cli(cli, "train", "--data", str(data), "--out", str(model),
                   "--max-hidden", "1", "--pool", "1", "--threads", "1")
    assert done.returncode == 0, done.stderr
    soft = tmp_path / "soft.toml"
    soft.write_text(seed.read_text().replace("youngs_modulus = 207e9", "youngs_modulus = 103.5e9"))
    tendril.Net.load(model, tendril.Robot.load(seed))
    with pytest.raises(ValueError, match=r"trained for robot seed-4t .*allow_robot_mismatch=True"):
        tendril.Net.load(model, tendril.Robot.load(soft))
    net = tendril.Net.load(model, tendril.Robot.load(soft), allow_robot_mismatch=True)
    assert net.n_tendons == 4


def test_a_net_takes_poses_in_the_trackers_frame_of_the_robots_base(root):
    """With a robot whose file has [base], Net.predict takes the pose in the
    tracker's frame, as `tendril ik` does: the same tensions as the plain
    robot's net for the pose mapped back by hand (Rodrigues' formula)."""
    net_path = root / "firmware" / "vectors" / "default.tnet"
    plain = tendril.Robot.default()
    t, rv = np.array([0.1, -0.2, 0.05]), np.array([0.0, 0.4, 0.3])
    turned = tendril.Robot.from_toml(
        plain.toml + f"\n[base]\ntranslation = [{', '.join(repr(float(x)) for x in t)}]\n"
        f"rotation = [{', '.join(repr(float(x)) for x in rv)}]\n")
    pose_base, ok = plain.fk([2.0, 1.0, 0.0, 0.0])
    assert ok
    angle = np.linalg.norm(rv)
    k = rv / angle
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    R = np.eye(3) + math.sin(angle) * K + (1 - math.cos(angle)) * K @ K
    pose_tracker, _ = turned.fk([2.0, 1.0, 0.0, 0.0])
    assert np.allclose(pose_tracker[:3], R @ pose_base[:3] + t, atol=1e-12)
    by_plain, _ = tendril.Net.load(net_path, plain).predict(pose_base)
    by_turned, _ = tendril.Net.load(net_path, turned).predict(pose_tracker)
    assert np.allclose(by_turned, by_plain, atol=1e-4)

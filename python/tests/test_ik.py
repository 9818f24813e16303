"""robot.ik: the exact IK round trip, the least-tension rule, unreachable targets."""

import numpy as np
import pytest

import tendril


def test_round_trip_fk_ik_fk_reaches_every_target_to_a_micron():
    robot = tendril.Robot.default()
    rng = np.random.default_rng(3)
    tensions = np.zeros((12, robot.n_tendons))
    for r in range(12):  # two adjacent tendons, as the default sampler
        i = r % robot.n_tendons
        tensions[r, i] = rng.uniform(0.5, 9.5)
        tensions[r, (i + 1) % robot.n_tendons] = rng.uniform(0.0, 9.5)
    poses, ok = robot.fk(tensions)
    assert ok.all()
    found, reached, error, reachable = robot.ik(poses, position_only=True)
    assert reachable.all()
    assert (error <= 1e-6).all(), error
    assert (found >= robot.min_tensions - 1e-12).all()
    assert (found <= robot.max_tensions + 1e-12).all()
    again, ok = robot.fk(found)
    assert ok.all()
    assert np.abs(again[:, :3] - poses[:, :3]).max() <= 1e-6
    np.testing.assert_allclose(again, reached, rtol=0, atol=1e-9)


def test_net_guess_gives_the_same_reach_and_one_row_works(root):
    robot = tendril.Robot.default()
    net = tendril.Net.load(root / "firmware" / "vectors" / "default.tnet", robot)
    pose, _ = robot.fk(np.array([3.0, 1.0, 0.0, 0.0]))
    t, reached, error, reachable = robot.ik(pose, position_only=True, net=net)
    assert t.shape == (robot.n_tendons,) and reached.shape == (7,)
    assert reachable and error <= 1e-6
    # Least total tension: only the two tendons facing the target pull.
    assert t[2] == pytest.approx(0.0, abs=1e-9) and t[3] == pytest.approx(0.0, abs=1e-9)


def test_an_unreachable_target_gives_the_closest_pose_and_says_so():
    robot = tendril.Robot.default()
    far = np.array([0.3, 0.0, 0.1, 1.0, 0.0, 0.0, 0.0])
    t, reached, error, reachable = robot.ik(far, position_only=True)
    assert not reachable
    assert error > 0.01
    assert np.linalg.norm(reached[:3] - far[:3]) == pytest.approx(error, rel=1e-9)
    assert (t <= robot.max_tensions + 1e-12).all()


def test_strict_ik_raises_for_an_unreachable_target_and_names_it():
    robot = tendril.Robot.default()
    near, _ = robot.fk(np.array([2.0, 1.0, 0.0, 0.0]))
    far = np.array([0.3, 0.0, 0.1, 1.0, 0.0, 0.0, 0.0])
    robot.ik(near, position_only=True, strict=True)  # reachable: no exception
    with pytest.raises(ValueError, match=r"row 1: unreachable: .* m away"):
        robot.ik(np.stack([near, far]), position_only=True, strict=True)


def test_bad_targets_raise_value_error_naming_the_row():
    robot = tendril.Robot.default()
    bad = np.array([[0.0, 0.0, 0.4, 1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 0.4, 2.0, 0.0, 0.0, 0.0]])
    with pytest.raises(ValueError, match="row 1"):
        robot.ik(bad)
    with pytest.raises(ValueError, match="targets"):
        robot.ik(np.zeros((2, 6)))

"""robot.fk against an independent implementation of the same equations: the
pure-numpy model in python/bench/numpy_model.py (no code shared with tendril;
Newton with a finite-difference Jacobian instead of the exact one). Same
discretisation, so the tips agree to the solvers' tolerance, not just to the
discretisation error."""

import pathlib
import sys

import numpy as np

import tendril

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "bench"))
from numpy_model import NumpyRod  # noqa: E402


def test_fk_agrees_with_the_pure_numpy_model_to_a_nanometre():
    robot = tendril.Robot.default()
    rod = NumpyRod(robot.toml, steps=16)
    tensions = np.array([[0.0, 0.0, 0.0, 0.0], [2.0, 0.0, 0.0, 0.0],
                         [3.3, 7.1, 0.0, 0.0], [9.0, 2.0, 0.5, 4.0]])
    poses, converged = robot.fk(tensions)
    assert converged.all()
    for t, pose in zip(tensions, poses):
        tip = rod.solve(t)
        assert np.abs(pose[:3] - tip).max() < 1e-9, (t, pose[:3], tip)
    # Not a vacuous agreement: the tips differ from each other by centimetres.
    assert np.ptp(poses[:, 0]) > 0.05

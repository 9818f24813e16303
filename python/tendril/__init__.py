"""tendril: Cosserat-rod statics, datasets and learned inverse kinematics of
tendon-driven continuum robots, from the same Rust code as the ``tendril`` CLI.

>>> import numpy as np, tendril
>>> robot = tendril.Robot.default()
>>> poses, converged = robot.fk(np.array([[2.0, 0.0, 0.0, 0.0]]))

Units: m, N, N m; poses are px, py, pz, qw, qx, qy, qz (unit quaternion, w >= 0).
"""

from ._tendril import Net, Residual, Robot, __version__, fit_residual, fit_step, generate

__all__ = ["Net", "Residual", "Robot", "fit_residual", "fit_step", "generate", "__version__"]

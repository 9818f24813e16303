"""Type stubs of the compiled module (see the docstrings for units)."""

import os
import pathlib
from typing import Any, Dict, Optional, Sequence, Tuple, Union

import numpy as np
import numpy.typing as npt

__version__: str

_Array = npt.NDArray[np.float64]
_ArrayLike = Union[npt.ArrayLike, Sequence[float], Sequence[Sequence[float]]]
_Path = Union[str, "os.PathLike[str]"]

class Robot:
    """A tendon-driven continuum robot (TOML schema of docs/design.md §2)."""

    @staticmethod
    def load(path: _Path) -> "Robot":
        """Load a robot file; OSError if unreadable, ValueError naming the field if invalid."""
    @staticmethod
    def from_toml(text: str) -> "Robot":
        """Parse robot TOML text; ValueError naming the field if invalid."""
    @staticmethod
    def default() -> "Robot":
        """The built-in default robot (robots/seed-4t.toml)."""
    @property
    def name(self) -> str: ...
    @property
    def n_tendons(self) -> int:
        """Number of tendons k."""
    @property
    def length(self) -> float:
        """Backbone reference length, m."""
    @property
    def max_tensions(self) -> _Array:
        """(k,) largest tensions, N."""
    @property
    def min_tensions(self) -> _Array:
        """(k,) pretension floors, N."""
    @property
    def file(self) -> Optional[pathlib.Path]:
        """The robot file's path, or None (made from text or built in)."""
    @property
    def toml(self) -> str: ...
    @property
    def base(self) -> Tuple[_Array, _Array]:
        """The file's [base]: (translation (3,) m, rotation vector (3,) rad) in the tracker's frame."""
    def calibration_plan(
        self,
        n: int,
        fit: str = "E,density,length,offsets,angles,base",
        seed: int = 1,
        tip_mass_g: Optional[float] = None,
    ) -> Tuple[_Array, _Array]:
        """Tension sets to measure (tendril calibrate --plan): (tensions (n, k) N, tip forces (n, 3) N)."""
    def calibrate(
        self,
        data: _Path,
        fit: str = "E,density,length,offsets,angles,base",
        holdout: float = 0.2,
        seed: int = 1,
        positions_only: bool = False,
        mm_per_deg: float = 1.7453292519943295,
        tension_noise_n: float = 0.0,
    ) -> Tuple["Robot", Dict[str, Any]]:
        """Fit this robot to a measured CSV (tendril calibrate) -> (calibrated robot, report dict)."""
    def fk(
        self,
        tensions: _ArrayLike,
        tip_force: Optional[_ArrayLike] = None,
        tip_moment: Optional[_ArrayLike] = None,
        steps: int = 16,
    ) -> Tuple[_Array, Union[npt.NDArray[np.bool_], bool]]:
        """Tip poses for tensions (n, k) [N] -> (poses (n, 7), converged (n,));
        a (k,) input gives ((7,), bool). NaN poses where a solve did not converge."""
    def ik(
        self,
        targets: _ArrayLike,
        position_only: bool = False,
        net: Optional["Net"] = None,
        strict: bool = False,
    ) -> Tuple[_Array, _Array, Union[_Array, float], Union[npt.NDArray[np.bool_], bool]]:
        """Exact IK: targets (n, 7) poses -> (tensions (n, k) N, reached poses (n, 7),
        position error (n,) m, reachable (n,) bool); least total tension above the
        floors among the answers; an unreachable target gives the closest pose, or
        with strict=True raises ValueError naming its row, distance and binding limits."""
    def shape(
        self,
        tensions: _ArrayLike,
        points: int = 50,
        tip_force: Optional[_ArrayLike] = None,
        tip_moment: Optional[_ArrayLike] = None,
        steps: int = 16,
    ) -> _Array:
        """Backbone points (points, 3), m, base to tip, for tensions (k,) [N]."""

class Net:
    """A trained .tnet inverse-kinematics net for one robot."""

    @staticmethod
    def load(
        path: _Path,
        robot: Optional[Robot] = None,
        allow_extrapolation: bool = False,
        allow_robot_mismatch: bool = False,
    ) -> "Net": ...
    @property
    def n_tendons(self) -> int: ...
    def predict(self, poses: _ArrayLike) -> Tuple[_Array, _Array]:
        """Poses (n, 7) -> (tensions (n, k) the firmware's command stage commands,
        raw net output (n, k): tensions up to co-contraction), N."""

def generate(
    robot: Robot,
    samples: int,
    seed: int = 1,
    sampler: Optional[str] = None,
    path: Optional[_Path] = None,
    *,
    steps: int = 16,
    max_failure_fraction: float = 0.001,
    test_fraction: float = 0.03,
    progress: bool = False,
) -> Tuple[_Array, _Array]:
    """Sample tensions, solve each: (tensions (n, k) N, poses (n, 7)); CSV + sidecar at path."""

def fit_step(trace: _Path, skip_s: float = 0.1) -> Dict[str, Any]:
    """The first bending mode from a step's tracker trace (tendril calibrate --step): the fit as a dict."""

class Residual:
    """A fitted residual of measured rows against a robot file's statics (design §11.5)."""

    def apply(self, tensions: _ArrayLike, poses: _ArrayLike) -> _Array:
        """The model's poses (n, 7) at tensions (n, k), moved by the residual."""
    @property
    def report(self) -> Dict[str, Any]:
        """The fit: rows, outliers, degree, lambda, validation RMS without and with it."""

def fit_residual(robot: Robot, tensions: _ArrayLike, poses: _ArrayLike, seed: int = 1) -> Residual:
    """The residual measured rows (tracker frame) show against robot's statics at their tensions."""

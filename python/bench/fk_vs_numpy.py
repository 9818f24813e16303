"""robot.fk against the pure-numpy model of the same statics (numpy_model.py),
per cold solve on one thread, same rows, same run (issue 15 target: >= 50x).
Prints one line of JSON.

    RAYON_NUM_THREADS=1 python python/bench/fk_vs_numpy.py [--rows 20] [--fk-rows 2000]

Build the package in release first (`maturin develop --release`). RAYON_NUM_THREADS=1
keeps robot.fk on one thread, so the ratio is per solve, not per core. The numpy
time is the mean over `--rows` rows; the robot.fk time is the mean over the same rows
solved one call per row (each a cold solve) and over `--fk-rows` rows in one batch.
The tips are checked to agree.
"""

import argparse
import json
import os
import pathlib
import sys
import time

import numpy as np

import tendril

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from numpy_model import NumpyRod  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--rows", type=int, default=20)
    parser.add_argument("--fk-rows", type=int, default=2000)
    args = parser.parse_args()

    robot = tendril.Robot.default()
    rod = NumpyRod(robot.toml, steps=16)
    rng = np.random.default_rng(7)
    tensions = rng.uniform(0.0, 1.0, (args.rows, robot.n_tendons)) * robot.max_tensions

    start = time.perf_counter()
    numpy_tips = np.array([rod.solve(t) for t in tensions])
    numpy_s = (time.perf_counter() - start) / args.rows

    start = time.perf_counter()
    rows = [robot.fk(t[None, :]) for t in tensions]
    fk_single_s = (time.perf_counter() - start) / args.rows
    fk_tips = np.array([poses[0, :3] for poses, _ in rows])

    batch = rng.uniform(0.0, 1.0, (args.fk_rows, robot.n_tendons)) * robot.max_tensions
    start = time.perf_counter()
    robot.fk(batch)
    fk_batch_s = (time.perf_counter() - start) / args.fk_rows

    print(json.dumps({
        "numpy_ms_per_solve": round(1e3 * numpy_s, 2),
        "fk_ms_per_solve_one_call_per_row": round(1e3 * fk_single_s, 4),
        "fk_ms_per_row_batch": round(1e3 * fk_batch_s, 4),
        "numpy_over_fk": round(numpy_s / fk_single_s, 1),
        "numpy_over_fk_batch": round(numpy_s / fk_batch_s, 1),
        "max_tip_difference_m": float(np.abs(numpy_tips - fk_tips).max()),
        "rayon_threads": os.environ.get("RAYON_NUM_THREADS", "all cores"),
    }))


if __name__ == "__main__":
    main()

"""robot.fk on N rows vs `tendril fk --input` on the same rows, same run
(issue 15 target: Python within 1.2x of the CLI). Prints one line of JSON.

    python python/bench/fk_vs_cli.py --cli target/release/tendril [--rows 10000] [--repeats 3]

Build the package in release first (`maturin develop --release`). The CLI
time is the wall time of the whole process (start, CSV in, solve, CSV out);
the Python time is the `robot.fk` call. Each is the best of the repeats,
alternating, and the poses are checked to be bit-identical.
"""

import argparse
import csv
import json
import os
import subprocess
import tempfile
import time

import numpy as np

import tendril


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--cli", required=True)
    parser.add_argument("--rows", type=int, default=10_000)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()

    robot = tendril.Robot.default()
    tensions = np.random.default_rng(1).uniform(0.0, 1.0, (args.rows, robot.n_tendons)) * robot.max_tensions
    with tempfile.TemporaryDirectory() as tmp:
        src, dst = os.path.join(tmp, "in.csv"), os.path.join(tmp, "out.csv")
        with open(src, "w", newline="") as f:
            w = csv.writer(f)
            w.writerow([f"t{i}" for i in range(robot.n_tendons)])
            w.writerows([[repr(float(x)) for x in row] for row in tensions])
        cli_s, py_s = [], []
        for _ in range(args.repeats):
            start = time.perf_counter()
            subprocess.run([args.cli, "fk", "--input", src, "--output", dst], check=False,
                           stderr=subprocess.DEVNULL)
            cli_s.append(time.perf_counter() - start)
            start = time.perf_counter()
            poses, converged = robot.fk(tensions)
            py_s.append(time.perf_counter() - start)
        with open(dst, newline="") as f:
            rows = list(csv.DictReader(f))
        cols = ["px", "py", "pz", "qw", "qx", "qy", "qz"]
        cli_poses = np.array([[float(r[c]) if r[c] else np.nan for c in cols] for r in rows])
    identical = bool(np.array_equal(poses, cli_poses, equal_nan=True))
    print(json.dumps({
        "rows": args.rows,
        "converged": int(converged.sum()),
        "cli_s": round(min(cli_s), 4),
        "python_s": round(min(py_s), 4),
        "python_over_cli": round(min(py_s) / min(cli_s), 3),
        "python_ms_per_row": round(1000 * min(py_s) / args.rows, 4),
        "bit_identical": identical,
        "threads": os.cpu_count(),
    }))


if __name__ == "__main__":
    main()

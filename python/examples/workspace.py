"""The seed paper's Figure 1: the reachable workspace of the default robot as
a cloud of tip positions; beside it, learned against exact IK: how far a
trained net's tensions, and the exact IK's, put the tip from the poses asked
for, and what each costs per query.

    pip install ./python matplotlib
    python python/examples/workspace.py [--model firmware/vectors/default.tnet] [--out workspace.png]
"""

import argparse
import time

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import tendril  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=5000)
    parser.add_argument("--model", default="firmware/vectors/default.tnet")
    parser.add_argument("--queries", type=int, default=300)
    parser.add_argument("--out", default="workspace.png")
    args = parser.parse_args()

    robot = tendril.Robot.default()
    tensions, poses = tendril.generate(robot, args.samples, seed=1, sampler="uniform")
    positions = poses[:, :3] * 1000.0  # mm

    fig = plt.figure(figsize=(11, 5))
    cloud = fig.add_subplot(1, 2, 1, projection="3d")
    cloud.scatter(*positions.T, c=tensions.sum(axis=1), s=2, cmap="viridis")
    cloud.set(xlabel="x [mm]", ylabel="y [mm]", zlabel="z [mm]",
              title=f"{robot.name}: {len(poses)} tip positions (uniform tensions)")

    # Learned vs exact IK on poses of the sampler the nets are trained with
    # (adjacent): tensions from the net, or from the exact IK warm-started by
    # the net; then the statics say where the tip goes.
    net = tendril.Net.load(args.model, robot, allow_extrapolation=True)
    _, held_out = tendril.generate(robot, args.queries, seed=2)
    start = time.perf_counter()
    predicted, _ = net.predict(held_out)
    net_s = time.perf_counter() - start
    start = time.perf_counter()
    exact, _, _, reachable = robot.ik(held_out, position_only=True, net=net)
    exact_s = time.perf_counter() - start
    bins = np.logspace(-7, 1, 50)  # mm
    hist = fig.add_subplot(1, 2, 2)
    for label, tensions_used, seconds in (("net", predicted, net_s), ("exact IK", exact, exact_s)):
        reached, converged = robot.fk(tensions_used)
        error_mm = np.linalg.norm(reached[converged, :3] - held_out[converged, :3], axis=1) * 1000.0
        hist.hist(np.maximum(error_mm, bins[0]), bins=bins, alpha=0.6,
                  label=f"{label}: median {np.median(error_mm):.2g} mm, "
                        f"{1e3 * seconds / len(held_out):.2g} ms/query")
    hist.set(xscale="log", xlabel="tip position error [mm]", ylabel="poses",
             title=f"learned vs exact IK, {len(held_out)} held-out poses "
                   f"({int(reachable.sum())} reachable)")
    hist.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(args.out, dpi=120)
    print(args.out)


if __name__ == "__main__":
    main()

"""The seed paper's Figure 1: the reachable workspace of the default robot as
a cloud of tip positions, and how far a trained net's tensions land from the
poses asked for.

    pip install ./python matplotlib
    python python/examples/workspace.py [--model firmware/vectors/default.tnet] [--out workspace.png]
"""

import argparse

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import tendril  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=5000)
    parser.add_argument("--model", default="firmware/vectors/default.tnet")
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

    # Learned IK on poses of the sampler the nets are trained with (adjacent):
    # tensions from the net, then the statics say where the tip goes.
    net = tendril.Net.load(args.model, robot, allow_extrapolation=True)
    _, held_out = tendril.generate(robot, 500, seed=2)
    predicted, _ = net.predict(held_out)
    reached, converged = robot.fk(predicted)
    error_mm = np.linalg.norm(reached[converged, :3] - held_out[converged, :3], axis=1) * 1000.0
    hist = fig.add_subplot(1, 2, 2)
    hist.hist(error_mm, bins=40)
    hist.set(xlabel="tip position error [mm]", ylabel="poses",
             title=f"net → statics: median {np.median(error_mm):.2f} mm")
    fig.tight_layout()
    fig.savefig(args.out, dpi=120)
    print(args.out)


if __name__ == "__main__":
    main()

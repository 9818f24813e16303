"""`tendril-ros2 drive` against a Cyclone DDS robot on this machine (the
tests' StaticsRobot: drives with a 20 ms lag, the statics' tip as its
tracker): the seconds from joining to the robot's first answer (discovery),
the circle's tracking error, and the command's one-way latency (the drive's
stamp, taken as it publishes `tendon_controller/commanded`, → the peer's
reception, which blocks on a WaitSet; one clock, one machine; includes the
Python binding's deserialisation).

    python python/bench/ros2_latency.py [--bin target/release/tendril-ros2] [--seconds 10] [--peer-first 2] [-- DRIVE FLAGS]
"""

import argparse
import json
import os
import pathlib
import sys
import tempfile
import time

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "python" / "tests"))
from ros2_peer import Peer, StaticsRobot, start_drive  # noqa: E402

import tendril  # noqa: E402


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--bin", help="tendril-ros2 binary (default: $TENDRIL_ROS2_BIN or target/debug)")
    ap.add_argument("--seconds", type=float, default=10.0)
    ap.add_argument("--domain", type=int, default=150)
    ap.add_argument("--peer-first", type=float, default=None, metavar="SECONDS",
                    help="the robot joins the graph this long before the drive (default: just after)")
    ap.add_argument("drive_args", nargs="*", help="more flags for the drive, after --: -- --controller mcu")
    a = ap.parse_args()
    if a.bin:
        os.environ["TENDRIL_ROS2_BIN"] = a.bin
    stats = pathlib.Path(tempfile.mkdtemp()) / "drive.json"
    model = tendril.Robot.load(ROOT / "robots" / "seed-4t.toml")
    if a.peer_first is not None:
        robot = StaticsRobot(Peer(a.domain), model)
        time.sleep(a.peer_first)
    drive = start_drive(a.domain, "--robot", "robots/seed-4t.toml", "--model", "firmware/vectors/default.tnet",
                        "--duration", str(a.seconds), "--stats", str(stats), *a.drive_args)
    if a.peer_first is None:
        robot = StaticsRobot(Peer(a.domain), model)
    robot.serve(a.seconds + 30, until_done=drive)
    out, err = drive.communicate(timeout=30)
    if drive.returncode != 0:
        sys.exit(f"drive failed: {err}")
    s = json.loads(stats.read_text())
    lat = 1e3 * np.array(robot.latencies_s[len(robot.latencies_s) // 10:])
    print(f"joining → the robot's first answer: {s['first_feedback_s']:.2f} s")
    print(f"circle: tracking {s['tracking_rms_mm']:.3f} mm RMS, max {s['tracking_max_mm']:.3f} mm over "
          f"{s['tracked_frames']} frames; {s['periods']} periods, {s['overruns']} overruns, "
          f"{s['hold_periods']} holds, {s['stale_periods']} stale")
    if s.get("chip_start_s") is not None:
        print(f"chip: first command {s['chip_start_s']:.2f} s after its start, {s['chip_periods']} periods")
    print(f"verdicts: {s['verdicts']['problems'] or 'clean'}")
    print(f"command → peer: p50 {np.percentile(lat, 50):.3f} ms, p99 {np.percentile(lat, 99):.3f} ms, "
          f"max {lat.max():.3f} ms ({len(lat)} commands)")


if __name__ == "__main__":
    main()

"""`tendril-ros2 drive` against a Cyclone DDS robot on this machine (the
tests' StaticsRobot: drives with a 20 ms lag, the statics' tip as its
tracker): the seconds from joining to the robot's first answer (discovery),
the circle's tracking error, and the command's one-way latency (the drive's
stamp, taken as it publishes `tendon_controller/commanded`, → the peer's
reception, which blocks on a WaitSet over both; one clock, one machine;
includes the Python binding's wake-up and deserialisation).

    python python/bench/ros2_latency.py [--bin target/release/tendril-ros2] [--seconds 10] [--peer-first 2] [-- DRIVE FLAGS]
    python python/bench/ros2_latency.py --baseline
"""

import argparse
import json
import os
import pathlib
import subprocess
import sys
import tempfile
import time

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "python" / "tests"))
from ros2_peer import RELIABLE, Header, JointState, Peer, StaticsRobot, Time, start_drive, valid  # noqa: E402

import tendril  # noqa: E402


def stamped_joint_state():
    now = time.time()
    return JointState(header=Header(stamp=Time(sec=int(now), nanosec=int((now % 1) * 1e9))),
                      name=[f"tendon_{i}" for i in range(4)], effort=[1.0, 2.0, 3.0, 4.0])


def baseline(domain: int, seconds: float, publish: bool):
    """The peer's own floor: the same stamped JointState, Cyclone DDS from
    Python on both sides (another process publishing every 5 ms), received
    as the robot receives tendril's."""
    topic = "tendon_controller/commanded"
    if publish:
        writer = Peer(domain).writer(topic, JointState, RELIABLE)
        time.sleep(2.0)
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            writer.write(stamped_joint_state())
            time.sleep(0.005)
        return
    from cyclonedds.core import InstanceState, ReadCondition, SampleState, ViewState, WaitSet
    from cyclonedds.util import duration
    peer = Peer(domain)
    reader = peer.reader(topic, JointState, RELIABLE)
    waitset = WaitSet(peer.dp)
    waitset.attach(ReadCondition(reader, SampleState.Any | ViewState.Any | InstanceState.Any))
    pub = subprocess.Popen([sys.executable, __file__, "--baseline-publisher", "--seconds", str(seconds),
                            "--domain", str(domain)])
    lat = []
    while pub.poll() is None:
        for s in valid(reader.take(N=100)):
            lat.append(time.time() - (s.header.stamp.sec + 1e-9 * s.header.stamp.nanosec))
        waitset.wait(duration(milliseconds=2))
    lat = 1e3 * np.array(lat[len(lat) // 10:])
    print(f"Cyclone DDS (Python) → Cyclone DDS (Python), the same message: p50 {np.percentile(lat, 50):.3f} ms, "
          f"p99 {np.percentile(lat, 99):.3f} ms ({len(lat)} messages)")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--bin", help="tendril-ros2 binary (default: $TENDRIL_ROS2_BIN or target/debug)")
    ap.add_argument("--seconds", type=float, default=10.0)
    ap.add_argument("--domain", type=int, default=150)
    ap.add_argument("--peer-first", type=float, default=None, metavar="SECONDS",
                    help="the robot joins the graph this long before the drive (default: just after)")
    ap.add_argument("--baseline", action="store_true",
                    help="instead: the peer's own latency floor, Cyclone DDS from Python on both sides")
    ap.add_argument("--baseline-publisher", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("drive_args", nargs="*", help="more flags for the drive, after --: -- --controller mcu")
    a = ap.parse_args()
    if a.baseline or a.baseline_publisher:
        return baseline(a.domain, a.seconds, a.baseline_publisher)
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

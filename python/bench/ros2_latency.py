"""tendril-ros2 plant against a Cyclone DDS peer on this machine: discovery
(plant start → the peer's first joint state; → the plant's first command)
and the one-way latency of the joint states (the plant's stamp, taken as it
publishes, → the peer's reception; one clock, one machine).

    python python/bench/ros2_latency.py [--bin target/release/tendril-ros2] [--seconds 10]
"""

import argparse
import json
import os
import pathlib
import sys
import tempfile
import time

import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "tests"))
from ros2_peer import RELIABLE, SENSOR, Float64MultiArray, JointState, Peer, start_plant  # noqa: E402


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--bin", help="tendril-ros2 binary (default: $TENDRIL_ROS2_BIN or target/debug)")
    ap.add_argument("--seconds", type=float, default=10.0)
    ap.add_argument("--rate", type=float, default=200.0)
    ap.add_argument("--domain", type=int, default=150)
    a = ap.parse_args()
    if a.bin:
        os.environ["TENDRIL_ROS2_BIN"] = a.bin
    stats = pathlib.Path(tempfile.mkdtemp()) / "stats.json"
    t0 = time.time()
    plant = start_plant(a.domain, "--rate", str(a.rate), "--duration", str(a.seconds + 4),
                        "--noise-mm", "0", "--stats", str(stats))
    peer = Peer(a.domain)
    cmd = peer.writer("tendon_controller/commands", Float64MultiArray, RELIABLE)
    js = peer.reader("joint_states", JointState, SENSOR)
    first, lat = None, []
    end = time.time() + a.seconds + 2
    while time.time() < end:
        cmd.write(Float64MultiArray(data=[4.0, 3.0, 0.0, 0.0]))
        for s in js.take(N=1000):
            now = time.time()
            if first is None:
                first = now - t0
            lat.append(now - (s.header.stamp.sec + 1e-9 * s.header.stamp.nanosec))
        time.sleep(0.002)
    plant.communicate(timeout=30)
    st = json.loads(stats.read_text())
    lat_ms = 1e3 * np.array(lat[len(lat) // 10:])  # after the first tenth: matched and warm
    print(f"plant start → peer's first joint state: {first:.2f} s; → plant's first command: {st['first_command_s']:.2f} s")
    print(f"joint states received: {len(lat)} ({st['steps']} steps); latency p50 {np.percentile(lat_ms, 50):.3f} ms, "
          f"p99 {np.percentile(lat_ms, 99):.3f} ms, max {lat_ms.max():.3f} ms; plant overruns {st['overruns']}")


if __name__ == "__main__":
    main()

"""tendril-ros2 on a real DDS graph: an independent Cyclone DDS peer
(ros2_peer.py) plays a lab's controller against `tendril-ros2 plant`. The
tip it reads back is checked against tendril's statics through the Python
package, the tensions against what it commanded, and bad commands are
refused and counted."""

import json
import math
import os
import time

import numpy as np
import pytest

import tendril
from ros2_peer import (
    LATCHED,
    RELIABLE,
    SENSOR,
    DiagnosticArray,
    Float64MultiArray,
    JointState,
    Path,
    Peer,
    PoseStamped,
    TFMessage,
    ros2_bin,
    start_plant,
    until,
)

# Discovery over loopback takes a few seconds (SPDP announcements); the
# plant runs long enough for that and for both commands to settle.
PLANT_SECONDS = 14


@pytest.fixture
def domain():
    """A domain of this test's own, so that concurrent runs do not meet."""
    return 100 + os.getpid() % 100


@pytest.fixture(scope="module")
def binary():
    path = ros2_bin()
    if not path.is_file():
        pytest.fail(f"{path}: no tendril-ros2 binary; run `cargo test --workspace --no-run`")
    return path


def settle(cmd_writer, js_reader, tensions, timeout_s):
    """Send `tensions` every 20 ms until the joint states report them."""
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        cmd_writer.write(Float64MultiArray(data=[float(t) for t in tensions]))
        states = js_reader.take(N=1000)
        if states and np.allclose(states[-1].effort, tensions, atol=1e-9):
            return states[-1]
        time.sleep(0.02)
    return None


def tip_after(tip_reader, cmd_writer, tensions, n=5):
    """The next `n` tip poses (still commanding `tensions`), as (n, 3) m."""
    got = []
    tip_reader.take(N=1000)  # drop the poses from before the settle

    def poll():
        cmd_writer.write(Float64MultiArray(data=[float(t) for t in tensions]))
        for s in tip_reader.take(N=1000):
            p = s.pose.position
            got.append([p.x, p.y, p.z])
        return len(got) >= n

    assert until(5.0, poll), f"only {len(got)} tip poses in 5 s"
    return np.array(got)


def test_a_cyclone_dds_controller_drives_the_plant_and_reads_the_statics_tip(
    tmp_path, binary, domain, root
):
    robot = tendril.Robot.load(root / "robots" / "seed-4t.toml")
    stats_path = tmp_path / "stats.json"
    plant = start_plant(
        domain,
        "--robot", "robots/seed-4t.toml",
        "--noise-mm", "0",
        "--duration", str(PLANT_SECONDS),
        "--stats", str(stats_path),
    )
    try:
        peer = Peer(domain)
        cmd = peer.writer("tendon_controller/commands", Float64MultiArray, RELIABLE)
        js = peer.reader("joint_states", JointState, SENSOR)
        tip = peer.reader("tip_pose", PoseStamped, SENSOR)
        backbone = peer.reader("backbone", Path, SENSOR)
        tf = peer.reader("/tf", TFMessage, RELIABLE)
        tf_static = peer.reader("/tf_static", TFMessage, LATCHED)
        diagnostics = peer.reader("/diagnostics", DiagnosticArray, RELIABLE)

        for tensions in ([4.0, 3.0, 0.0, 0.0], [0.0, 1.5, 3.0, 5.0]):
            state = settle(cmd, js, tensions, timeout_s=6.0)
            assert state is not None, f"the joint states never reported {tensions} N"
            assert list(state.name) == [f"tendon_{i}" for i in range(4)]
            measured = tip_after(tip, cmd, tensions)
            poses, converged = robot.fk(np.array([tensions]))
            assert bool(np.all(converged))
            # The plant's statics are one-pass warm solves (a final chord
            # step ≤ 1 µm); the tracker is noiseless here.
            err = np.linalg.norm(measured - poses[0, :3], axis=1)
            assert err.max() < 5e-6, f"tip {measured[-1]} against statics {poses[0, :3]}: {err.max()} m"

        # Bad commands: refused and counted, and the tensions stay.
        cmd.write(Float64MultiArray(data=[1.0, 2.0]))
        cmd.write(Float64MultiArray(data=[math.nan, 0.0, 0.0, 0.0]))
        time.sleep(0.5)
        states = js.take(N=1000)
        assert states and np.allclose(states[-1].effort, [0.0, 1.5, 3.0, 5.0], atol=1e-9)

        # What RViz and the diagnostics aggregator read.
        paths = until(3.0, lambda: backbone.take(N=100))
        assert paths, "no backbone"
        line = np.array([[p.pose.position.x, p.pose.position.y, p.pose.position.z] for p in paths[-1].poses])
        assert line.shape == (32, 3) and paths[-1].header.frame_id == "tracker"
        assert np.allclose(line[0], 0.0, atol=1e-12), "the backbone starts at the base"
        assert np.linalg.norm(line[-1] - measured[-1]) < 5e-6, "… and ends at the tip"
        transforms = until(3.0, lambda: tf.take(N=100))
        assert transforms and transforms[-1].transforms[0].child_frame_id == "tip"
        assert transforms[-1].transforms[0].header.frame_id == "base_link"
        statics = until(3.0, lambda: tf_static.take(N=10))
        assert statics, "no /tf_static"
        base = statics[-1].transforms[0]
        assert (base.header.frame_id, base.child_frame_id) == ("tracker", "base_link")
        status = until(3.0, lambda: diagnostics.take(N=10))
        assert status, "no /diagnostics"
        counters = {kv.key: int(kv.value) for kv in status[-1].status[0].values}
        assert counters["refused_length"] == 1 and counters["refused_not_finite"] == 1
        assert status[-1].status[0].level == 1, "refused commands make the status a warning"
    finally:
        out, err = plant.communicate(timeout=PLANT_SECONDS + 10)
    assert plant.returncode == 0, err
    stats = json.loads(stats_path.read_text())
    assert stats["refused_length"] == 1 and stats["refused_not_finite"] == 1, stats
    assert stats["commands"] > 50 and stats["overruns"] == 0, stats
    assert "2 refused" in err, err


def test_bad_settings_are_refused_before_joining_the_graph(binary, domain):
    for args, named in [
        (["--rate", "0"], "--rate"),
        (["--robot", "no-such-robot.toml"], "no-such-robot.toml"),
        (["--reality", "no-such-reality"], "no-such-reality"),
        (["--noise-mm=-1"], "--noise-mm"),
    ]:
        p = start_plant(domain, *args, "--duration", "1")
        out, err = p.communicate(timeout=20)
        assert p.returncode != 0 and named in err, (args, err)
    p = start_plant("233", "--duration", "1")
    out, err = p.communicate(timeout=20)
    assert p.returncode != 0 and "ROS_DOMAIN_ID" in err and "0..=232" in err, err
    p = start_plant(domain, "--duration", "1")
    out, err = p.communicate(timeout=20)
    assert p.returncode == 0, err

"""An independent ROS 2 peer for tendril-ros2's tests: Eclipse Cyclone DDS
(one of ROS 2's own middlewares, from PyPI) with common_interfaces' types
written as IDL structs under ROS 2's wire conventions: topics prefixed
`rt/`, types named `pkg::msg::dds_::Type_`. Nothing here comes from tendril.
"""

import math
import os
import pathlib
import subprocess
import time
from dataclasses import dataclass, field
from typing import List

import numpy as np

from cyclonedds.core import InstanceState, ReadCondition, SampleState, ViewState, WaitSet
from cyclonedds.domain import DomainParticipant
from cyclonedds.idl import IdlStruct
from cyclonedds.idl.types import float64, int32, sequence, uint8, uint32
from cyclonedds.pub import DataWriter
from cyclonedds.qos import Policy, Qos
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from cyclonedds.util import duration

ROOT = pathlib.Path(__file__).resolve().parents[2]


@dataclass
class Time(IdlStruct, typename="builtin_interfaces::msg::dds_::Time_"):
    sec: int32 = 0
    nanosec: uint32 = 0


@dataclass
class Header(IdlStruct, typename="std_msgs::msg::dds_::Header_"):
    stamp: Time = field(default_factory=Time)
    frame_id: str = ""


@dataclass
class JointState(IdlStruct, typename="sensor_msgs::msg::dds_::JointState_"):
    header: Header = field(default_factory=Header)
    name: sequence[str] = field(default_factory=list)
    position: sequence[float64] = field(default_factory=list)
    velocity: sequence[float64] = field(default_factory=list)
    effort: sequence[float64] = field(default_factory=list)


@dataclass
class MultiArrayDimension(IdlStruct, typename="std_msgs::msg::dds_::MultiArrayDimension_"):
    label: str = ""
    size: uint32 = 0
    stride: uint32 = 0


@dataclass
class MultiArrayLayout(IdlStruct, typename="std_msgs::msg::dds_::MultiArrayLayout_"):
    dim: sequence[MultiArrayDimension] = field(default_factory=list)
    data_offset: uint32 = 0


@dataclass
class Float64MultiArray(IdlStruct, typename="std_msgs::msg::dds_::Float64MultiArray_"):
    layout: MultiArrayLayout = field(default_factory=MultiArrayLayout)
    data: sequence[float64] = field(default_factory=list)


@dataclass
class Point(IdlStruct, typename="geometry_msgs::msg::dds_::Point_"):
    x: float64 = 0.0
    y: float64 = 0.0
    z: float64 = 0.0


@dataclass
class Quaternion(IdlStruct, typename="geometry_msgs::msg::dds_::Quaternion_"):
    x: float64 = 0.0
    y: float64 = 0.0
    z: float64 = 0.0
    w: float64 = 1.0


@dataclass
class Pose(IdlStruct, typename="geometry_msgs::msg::dds_::Pose_"):
    position: Point = field(default_factory=Point)
    orientation: Quaternion = field(default_factory=Quaternion)


@dataclass
class PoseStamped(IdlStruct, typename="geometry_msgs::msg::dds_::PoseStamped_"):
    header: Header = field(default_factory=Header)
    pose: Pose = field(default_factory=Pose)


@dataclass
class PointStamped(IdlStruct, typename="geometry_msgs::msg::dds_::PointStamped_"):
    header: Header = field(default_factory=Header)
    point: Point = field(default_factory=Point)


@dataclass
class Vector3(IdlStruct, typename="geometry_msgs::msg::dds_::Vector3_"):
    x: float64 = 0.0
    y: float64 = 0.0
    z: float64 = 0.0


@dataclass
class Transform(IdlStruct, typename="geometry_msgs::msg::dds_::Transform_"):
    translation: Vector3 = field(default_factory=Vector3)
    rotation: Quaternion = field(default_factory=Quaternion)


@dataclass
class TransformStamped(IdlStruct, typename="geometry_msgs::msg::dds_::TransformStamped_"):
    header: Header = field(default_factory=Header)
    child_frame_id: str = ""
    transform: Transform = field(default_factory=Transform)


@dataclass
class TFMessage(IdlStruct, typename="tf2_msgs::msg::dds_::TFMessage_"):
    transforms: sequence[TransformStamped] = field(default_factory=list)


@dataclass
class Path(IdlStruct, typename="nav_msgs::msg::dds_::Path_"):
    header: Header = field(default_factory=Header)
    poses: sequence[PoseStamped] = field(default_factory=list)


@dataclass
class KeyValue(IdlStruct, typename="diagnostic_msgs::msg::dds_::KeyValue_"):
    key: str = ""
    value: str = ""


@dataclass
class DiagnosticStatus(IdlStruct, typename="diagnostic_msgs::msg::dds_::DiagnosticStatus_"):
    level: uint8 = 0
    name: str = ""
    message: str = ""
    hardware_id: str = ""
    values: sequence[KeyValue] = field(default_factory=list)


@dataclass
class DiagnosticArray(IdlStruct, typename="diagnostic_msgs::msg::dds_::DiagnosticArray_"):
    header: Header = field(default_factory=Header)
    status: sequence[DiagnosticStatus] = field(default_factory=list)


# A wrong type on the commands' topic name: a peer that sends one must be
# refused, not obeyed (same topic name, another type name: DDS itself does
# not match it) — so the malformed case is a Float64MultiArray whose bytes
# do not parse, which DDS cannot tell apart; see test_ros2.py.

# ROS 2's QoS profiles (rmw_qos_profile_sensor_data, the default, tf_static).
SENSOR = Qos(Policy.Reliability.BestEffort, Policy.History.KeepLast(5), Policy.Durability.Volatile)
RELIABLE = Qos(
    Policy.Reliability.Reliable(duration(milliseconds=100)),
    Policy.History.KeepLast(10),
    Policy.Durability.Volatile,
)
LATCHED = Qos(
    Policy.Reliability.Reliable(duration(milliseconds=100)),
    Policy.History.KeepLast(1),
    Policy.Durability.TransientLocal,
)


def ros2_bin() -> pathlib.Path:
    """tendril-ros2 built from this checkout: $TENDRIL_ROS2_BIN, else target/debug."""
    return pathlib.Path(os.environ.get("TENDRIL_ROS2_BIN", ROOT / "target" / "debug" / "tendril-ros2"))


class Peer:
    """One Cyclone DDS participant in `domain` with ROS 2's topic names."""

    def __init__(self, domain: int):
        self.dp = DomainParticipant(domain)

    def reader(self, name: str, kind, qos):
        return DataReader(self.dp, Topic(self.dp, "rt/" + name.lstrip("/"), kind), qos=qos)

    def writer(self, name: str, kind, qos):
        return DataWriter(self.dp, Topic(self.dp, "rt/" + name.lstrip("/"), kind), qos=qos)


def start_plant(domain: int, *args: str) -> subprocess.Popen:
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain))
    env.pop("RUST_LOG", None)
    return subprocess.Popen(
        [str(ros2_bin()), "plant", *args],
        cwd=ROOT,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )


def until(deadline_s: float, poll):
    """Call `poll` every 10 ms until it returns a truthy value or time runs out."""
    end = time.monotonic() + deadline_s
    while time.monotonic() < end:
        got = poll()
        if got:
            return got
        time.sleep(0.01)
    return None


def valid(samples) -> List:
    """The samples with data (Cyclone also hands out an InvalidSample when
    a writer goes away)."""
    return [s for s in samples if not type(s).__name__ == "InvalidSample"]


@dataclass
class NotAnArray(IdlStruct, typename="std_msgs::msg::dds_::Float64MultiArray_"):
    """Another layout under the commands' type name: DDS matches type names,
    not layouts (RustDDS sends no type information), so its bytes reach the
    plant and must fail to parse there."""

    text: str = ""


class StaticsRobot:
    """A robot on the graph, played by the peer: drives that follow the
    command as a first-order lag of `motor_tau_s` (tendril's plant's default
    motors; 0: ideal), a noiseless tracker at the tip of tendril's statics
    for the drives' tensions (`tendril.Robot.fk`, the Python package), in
    the robot's base frame as `tracker`. It answers each command as it
    arrives."""

    def __init__(self, peer: "Peer", robot, *, motor_tau_s=0.02):
        self.robot = robot
        self.motor_tau_s = motor_tau_s
        self.motors = None
        self.last = None
        self.last_tip = None
        self.commands = peer.reader("tendon_controller/commands", Float64MultiArray, RELIABLE)
        self.commanded = peer.reader("tendon_controller/commanded", JointState, RELIABLE)
        self.joint_states = peer.writer("joint_states", JointState, SENSOR)
        self.tip = peer.writer("tip_pose", PoseStamped, SENSOR)
        self.received = 0
        self.latencies_s = []
        self.silent_commands = []
        # Block until a command arrives (a poll-and-sleep loop would add
        # its sleep to every latency this peer measures).
        self.waitset = WaitSet(peer.dp)
        any_sample = SampleState.Any | ViewState.Any | InstanceState.Any
        self.waitset.attach(ReadCondition(self.commands, any_sample))
        # ... or a stamped copy (`commanded`, sent just before the command):
        # its latency is measured from its own arrival, not the next message's.
        self.waitset.attach(ReadCondition(self.commanded, any_sample))

    def serve(self, seconds: float, until_done=None, silent_after_first_s=None, silent_until_s=None,
              tip_silent_after_first_s=None, events=()):
        """Answer commands for `seconds`, or until the process `until_done`
        ends; from `silent_after_first_s` after the first command (until
        `silent_until_s`, if given), take them and say nothing (a robot
        whose driver and tracker died, or stalled); the commands taken in
        that silence are kept in `silent_commands`; from
        `tip_silent_after_first_s` on, the drives answer and the tracker does
        not. `events` are (seconds after the first command, callable) run
        once each from the loop."""
        end = time.monotonic() + seconds
        first = None
        pending = sorted(events, key=lambda e: e[0])
        while time.monotonic() < end and (until_done is None or until_done.poll() is None):
            while first is not None and pending and time.monotonic() - first >= pending[0][0]:
                pending.pop(0)[1]()
            for s in valid(self.commanded.take(N=1000)):
                stamp = s.header.stamp.sec + 1e-9 * s.header.stamp.nanosec
                self.latencies_s.append(time.time() - stamp)
            got = valid(self.commands.take(N=1000))
            if not got:
                self.waitset.wait(duration(milliseconds=2))
                continue
            first = first or time.monotonic()
            self.received += len(got)
            since = time.monotonic() - first
            if silent_after_first_s is not None and since > silent_after_first_s and (
                    silent_until_s is None or since < silent_until_s):
                self.silent_commands.extend((since, list(c.data)) for c in got)
                continue
            self.answer(got[-1].data, tip=tip_silent_after_first_s is None or since < tip_silent_after_first_s)

    def answer(self, command, tip=True):
        """Move the drives towards `command` and publish their tensions and
        the tip of the statics for them."""
        cmd = np.array(command, dtype=float)
        if len(cmd) != self.robot.n_tendons:
            return
        now_m = time.monotonic()
        if self.motors is None or self.motor_tau_s == 0:
            self.motors = cmd
        else:
            a = 1.0 - math.exp(-(now_m - self.last) / self.motor_tau_s)
            self.motors = self.motors + (cmd - self.motors) * a
        self.last = now_m
        poses, _ = self.robot.fk(self.motors[np.newaxis, :])
        now = time.time()
        stamp = Time(sec=int(now), nanosec=int((now % 1) * 1e9))
        self.joint_states.write(JointState(header=Header(stamp=stamp),
                                           name=[f"tendon_{i}" for i in range(len(cmd))],
                                           effort=[float(v) for v in self.motors]))
        p = poses[0]
        self.last_tip = p
        if not tip:
            return
        self.tip.write(PoseStamped(header=Header(stamp=stamp, frame_id="tracker"),
                                   pose=Pose(position=Point(x=p[0], y=p[1], z=p[2]),
                                             orientation=Quaternion(x=p[4], y=p[5], z=p[6], w=p[3]))))


def start_drive(domain, *args: str) -> subprocess.Popen:
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain))
    env.pop("RUST_LOG", None)
    return subprocess.Popen([str(ros2_bin()), "drive", *args], cwd=ROOT, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)

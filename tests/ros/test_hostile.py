"""`ocu-ros` attacked through its topics (issue 19, item 8), read from what the simulator
received: huge values are bounded, bad messages refused briefly, a second scan publisher
cannot hide a wall, the creep and /odom keep their documented times, and a restarted master
ends the node with zeros sent and a non-zero status.

The node runs as a child process against a real roscore; the other publishers are this
process and, where a second node is needed, `rostopic pub` children.
"""

from __future__ import annotations

import math
import os
import shutil
import subprocess
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from ocu.control.commands import VelocityLimits
from ocu.nav.geometry import Pose
from ocu.nav.world import parse_world
from ocu.profile import RobotProfile
from ocu.protocol.mapping import CommandMapper, scan_frame
from ocu.records import ScanFrame
from ocu.ros.master import RosMaster
from ocu.ros.node import EXIT_MASTER_RESTARTED
from ocu.sim.faults import FaultConfig
from ocu.sim.rangefinder import RangeSensor, RangeSensorConfig
from ocu.sim.simulator import ReceivedRcp, RobotSimulator
from tests.ros.conftest import ROSPY_WARNINGS, Collector, NodeProcess, needs_ros, wait_for
from tests.ros.test_navigation import path_message

pytestmark = [pytest.mark.slow, *ROSPY_WARNINGS]

ARM = ("waist", "shoulder", "elbow", "neck")
LINEAR = "drive_linear"
# A scan of nothing (every beam beyond range_max), as a second node publishes it.
CLEAR_SCAN_YAML = (
    "{header: {frame_id: base_link}, angle_min: -3.14, angle_increment: 0.785, "
    "range_min: 0.1, range_max: 5.0, ranges: [9, 9, 9, 9, 9, 9, 9, 9]}"
)


def twist(linear_x: float) -> Any:
    from geometry_msgs.msg import Twist

    message = Twist()
    message.linear.x = linear_x
    return message


def speeds(profile: RobotProfile, rcps: list[ReceivedRcp], channel: str) -> list[float]:
    mapper = CommandMapper(profile)
    return [mapper.to_command(r.packet).velocity(channel) for r in rcps]


def publisher(topic: str, message_type: Any) -> Any:
    import rospy

    return rospy.Publisher(topic, message_type, queue_size=10)


def laser_message(frame: ScanFrame, frame_id: str = "base_link") -> Any:
    import rospy
    from sensor_msgs.msg import LaserScan

    message = LaserScan()
    message.header.frame_id = frame_id
    message.header.stamp = rospy.Time.now()
    message.angle_min = frame.angle_min_rad
    message.angle_increment = frame.angle_increment_rad
    message.angle_max = frame.angle_min_rad + frame.angle_increment_rad * (len(frame.ranges_m) - 1)
    message.range_min, message.range_max = frame.range_min_m, frame.range_max_m
    message.ranges = list(frame.ranges_m)
    return message


class Streamer:
    """Publishes a message made by `make()` at a fixed pace on its own thread until stop()."""

    def __init__(self, publish: Any, make: Any, period_s: float) -> None:
        self.publish, self.make, self.period_s = publish, make, period_s
        self.last_at = 0.0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="streamer", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            self.publish(self.make())
            self.last_at = time.monotonic()
            self._stop.wait(self.period_s)  # the sensor's or planner's pace

    def stop(self) -> float:
        """Stop; returns when the last message was published."""
        self._stop.set()
        self._thread.join(5.0)
        return self.last_at


def rostopic_pub(topic: str, message_type: str, yaml: str, rate_hz: float, **env: str) -> Any:
    """`rostopic pub -r RATE`: another node publishing (its own callerid)."""
    command = shutil.which("rostopic")
    assert command is not None
    return subprocess.Popen(
        [command, "pub", "-r", str(rate_hz), topic, message_type, yaml],
        stdin=subprocess.DEVNULL,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        env=dict(os.environ, **env),
    )


def stop_process(process: Any) -> None:
    process.terminate()
    try:
        process.wait(10.0)
    except subprocess.TimeoutExpired:
        process.kill()
        process.wait()


def bridge_values(message: Any) -> dict[str, str]:
    return {kv.key: kv.value for kv in message.status[1].values}


# ---- huge and malformed values ------------------------------------------------------------


@pytest.fixture
def arm_sim(profile: RobotProfile) -> Iterator[RobotSimulator]:
    needs_ros()
    assert profile.arm is not None
    simulator = RobotSimulator(
        profile, telemetry_hz=20.0, video_fps=0.0, initial_joints=profile.arm.poses["ready"]
    )
    simulator.start()
    yield simulator
    simulator.stop()


def test_hostile_values_are_bounded_and_the_node_keeps_serving(
    profile: RobotProfile,
    arm_sim: RobotSimulator,
    ros_master: RosMaster,
    ros_client: None,
    tmp_path: Path,
) -> None:
    from geometry_msgs.msg import Twist, TwistStamped
    from nav_msgs.msg import Path as PathMessage
    from std_msgs.msg import String

    sim = arm_sim
    limits = VelocityLimits(profile)
    cmd_vel = publisher("cmd_vel", Twist)
    arm_twist = publisher("arm/twist_cmd", TwistStamped)
    follow = publisher("follow_path", PathMessage)
    named = publisher("arm/named_pose", String)
    process = NodeProcess(tmp_path, sim.address)
    try:
        for each in (cmd_vel, arm_twist, follow, named):
            process.wait_connected(each)

        # cmd_vel linear.x = 1e308: the maximum (0.3 m/s), not a stop, with a log line.
        since = time.monotonic()
        cmd_vel.publish(twist(1e308))
        assert sim.wait_until(lambda s: s.commanded_velocities[LINEAR] != 0.0, 5.0), (
            process.output()
        )
        driven = speeds(profile, [r for r in sim.received_commands() if r.time_s > since], LINEAR)
        assert max(driven) == pytest.approx(0.3, abs=0.002)
        assert wait_for(lambda: "above the maxima (0.30 m/s" in process.output(), 5.0)
        cmd_vel.publish(twist(0.0))
        assert sim.wait_until(lambda s: s.commanded_velocities[LINEAR] == 0.0, 5.0)

        # An arm twist of 1e308 m/s: bounded to 0.15 m/s; the control loop lives on.
        since = time.monotonic()
        message = TwistStamped()
        message.header.frame_id = "base_link"
        message.twist.linear.x = 1e308
        for _ in range(6):
            arm_twist.publish(message)
            time.sleep(0.05)  # a planner's 20 Hz, not a synchronisation
        assert sim.wait_until(lambda s: all(s.velocities[j] == 0.0 for j in ARM), 5.0)
        assert process.process.poll() is None, process.output()
        moved = [r for r in sim.received_commands() if r.time_s > since]
        for joint in ARM:
            assert max(map(abs, speeds(profile, moved, joint))) <= limits.get(joint) + 1e-3
        assert wait_for(lambda: "arm twist above the maxima (0.150 m/s" in process.output(), 5.0)

        # A path through 1e308: refused with the reason, no traceback.
        follow.publish(path_message([(1.0, 0.0), (1e308, 0.0)]))
        assert wait_for(lambda: "is not within 10000 m of the origin" in process.output(), 5.0)

        # A 1 MB pose name, three times: one short line (throttled), not 1 MB twice each.
        for _ in range(3):
            named.publish(String(data="x" * 1_000_000))
        assert wait_for(lambda: "named pose rejected" in process.output(), 5.0)

        # Still serving: an ordinary cmd_vel drives.
        cmd_vel.publish(twist(0.25))
        assert sim.wait_until(lambda s: s.commanded_velocities[LINEAR] != 0.0, 5.0)
        assert "Traceback" not in process.output()
    finally:
        for each in (cmd_vel, arm_twist, follow, named):
            each.unregister()
        code = process.stop()
    output = process.output()
    assert code == 0, output
    assert output.count("named pose rejected") == 1
    assert len(output) < 50_000
    assert "Traceback" not in output


# ---- the safety zones with two scan publishers --------------------------------------------


def test_a_second_scan_publisher_cannot_hide_a_wall(
    profile: RobotProfile, ros_master: RosMaster, ros_client: None, tmp_path: Path
) -> None:
    from diagnostic_msgs.msg import DiagnosticArray
    from geometry_msgs.msg import Twist
    from sensor_msgs.msg import LaserScan

    needs_ros()
    # A wall 2 cm ahead of the footprint (the simulated sensor measures 5 cm short).
    world = parse_world({"wall": [{"from_m": [0.69, -3.0], "to_m": [0.69, 3.0]}]})
    sim = RobotSimulator(profile, world=world, telemetry_hz=10.0, video_fps=0.0)
    sim.start()
    sensor = RangeSensor(world, RangeSensorConfig(noise_m=0.0))
    scan_pub = publisher("scan", LaserScan)
    cmd_vel = publisher("cmd_vel", Twist)
    diagnostics = Collector("/diagnostics", DiagnosticArray)
    process = NodeProcess(tmp_path, sim.address)
    ghost: Any = None
    streams: list[Streamer] = []

    def true_scan() -> Any:
        return laser_message(scan_frame(sensor.sweep(Pose(*sim.state().pose), 0), 0, 0))

    try:
        process.wait_connected(scan_pub)
        process.wait_connected(cmd_vel)
        # A scan in a frame nobody placed is refused, with the reason.
        scan_pub.publish(laser_message(scan_frame(sensor.sweep(Pose(0, 0, 0), 0), 0, 0), "nowhere"))
        assert wait_for(lambda: "frame 'nowhere' is unknown" in process.output(), 5.0)
        # The robot's laser (this node) and a second node that sees nothing, both base_link.
        streams.append(Streamer(scan_pub.publish, true_scan, 0.1))
        ghost = rostopic_pub("/scan", "sensor_msgs/LaserScan", CLEAR_SCAN_YAML, 20.0)
        diagnostics.wait(
            lambda m: bridge_values(m).get("scan sources", "").count(" in ") == 2, 20.0
        )
        since = time.monotonic()
        streams.append(Streamer(cmd_vel.publish, lambda: twist(0.3), 0.05))
        time.sleep(3.0)  # three seconds of a planner driving at the wall: a duration
        received = [r for r in sim.received_commands() if r.time_s > since]
    finally:
        for stream in streams:
            stream.stop()
        if ghost is not None:
            stop_process(ghost)
        for each in (scan_pub, cmd_vel):
            each.unregister()
        diagnostics.close()
        code = process.stop()
        sim.stop()
    assert code == 0, process.output()
    forward = [v for v in speeds(profile, received, LINEAR) if v > 0.0]
    assert len(received) > 10
    assert forward == [], f"{len(forward)} of {len(received)} RCPs drove toward the wall"
    assert sim.state().collisions == 0


# ---- the documented times: the creep after 0.5 s without scans, /odom at 20 Hz ------------


def test_the_creep_starts_0_5_s_after_the_last_scan_and_odom_is_20_hz(
    profile: RobotProfile, ros_master: RosMaster, ros_client: None, tmp_path: Path
) -> None:
    from geometry_msgs.msg import Twist
    from nav_msgs.msg import Odometry
    from sensor_msgs.msg import LaserScan

    needs_ros()
    latency_s = 0.15  # each way: the round trip the node measures is 0.3 s
    sim = RobotSimulator(
        profile, telemetry_hz=20.0, video_fps=0.0, faults=FaultConfig(latency_ms=latency_s * 1e3)
    )
    sim.start()
    clear = ScanFrame(-math.pi, math.tau / 8, 0.1, 5.0, (math.inf,) * 8, 0.0, 0.0)
    scan_pub = publisher("scan", LaserScan)
    cmd_vel = publisher("cmd_vel", Twist)
    odom = Collector("odom", Odometry)
    odom_rate = Collector("odom", Odometry)
    process = NodeProcess(tmp_path, sim.address)
    streams: list[Streamer] = []
    try:
        process.wait_connected(scan_pub)
        process.wait_connected(cmd_vel)
        odom.wait(lambda m: True, 10.0)
        scans = Streamer(scan_pub.publish, lambda: laser_message(clear), 0.1)
        streams.append(scans)
        # Speeds that change, so the link's echo-based delay estimate converges.
        phase = [0]

        def planner() -> Any:
            phase[0] += 1
            return twist(0.3 if phase[0] % 10 < 5 else 0.28)

        streams.append(Streamer(cmd_vel.publish, planner, 0.05))
        # /odom over 3 s of this.
        counted_from = odom_rate.count()
        start = time.monotonic()
        time.sleep(3.0)  # the window the rate is counted over: a duration
        rate_hz = (odom_rate.count() - counted_from) / (time.monotonic() - start)
        last_scan = scans.stop()
        creep = profile.navigation.zones.max_linear_m_s[0]
        assert sim.wait_until(
            lambda s: 0.0 < s.commanded_velocities[LINEAR] <= creep + 1e-3, 5.0
        ), process.output()
        after = [r for r in sim.received_commands() if r.time_s > last_scan]
        first = next(
            r
            for r, v in zip(after, speeds(profile, after, LINEAR), strict=True)
            if 0.0 < v <= creep + 1e-3
        )
        # When the node sent it: the simulator received it one latency later.
        sent_after_s = first.time_s - latency_s - last_scan
    finally:
        for stream in streams:
            stream.stop()
        for each in (scan_pub, cmd_vel):
            each.unregister()
        odom.close()
        odom_rate.close()
        code = process.stop()
        sim.stop()
    assert code == 0, process.output()
    stale_s = profile.navigation.scan_stale_after_s
    # Not before 0.5 s (it was 0.35 s: the 0.15 s one-way delay taken off); after it, within
    # the node's loop (20 ms), the last scan's local delivery and a loaded machine's lag.
    assert stale_s - 0.01 <= sent_after_s <= stale_s + 0.3, sent_after_s
    # It was 16.7 Hz at most (every third tick of the 50 Hz loop).
    assert 18.0 <= rate_hz <= 21.0, rate_hz


# ---- a restarted master -------------------------------------------------------------------


def test_a_restarted_master_ends_the_node_with_zeros_and_a_status(
    profile: RobotProfile, ros_client: None, tmp_path: Path
) -> None:
    needs_ros()
    sim = RobotSimulator(profile, telemetry_hz=10.0, video_fps=0.0)
    sim.start()
    master = RosMaster(tmp_path / "first")
    planner: Any = None
    process: NodeProcess | None = None
    try:
        process = NodeProcess(tmp_path, sim.address, env=master.env)
        # Another node streams cmd_vel; its connection to ocu-ros outlives the master.
        planner = rostopic_pub(
            "/cmd_vel", "geometry_msgs/Twist", "{linear: {x: 0.25}}", 10.0, **master.env
        )
        assert sim.wait_until(lambda s: s.commanded_velocities[LINEAR] != 0.0, 30.0), (
            process.output()
        )
        master.stop()
        master = RosMaster(tmp_path / "second", port=master.port)
        code = process.wait_exit(20.0)
    finally:
        if planner is not None:
            stop_process(planner)
        if process is not None:
            process.stop()
        master.stop()
        sim.stop()
    output = process.output()
    assert code == EXIT_MASTER_RESTARTED, output
    assert "restarted (pid" in output
    assert "no longer knows" in output
    assert "link shut down, zeros sent last" in output
    last = sim.received_commands()[-1]
    assert speeds(profile, [last], LINEAR) == [0.0]
    assert sim.state().commanded_velocities[LINEAR] == 0.0

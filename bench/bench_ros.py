"""ROS node latency: a cmd_vel published to the datagram at the robot's socket, p50/p99.

    .venv/bin/python bench/bench_ros.py              # 500 messages
    .venv/bin/python bench/bench_ros.py --count 1000

Starts a private roscore on a free port and `python -m ocu.ros.node` against a bare UDP socket
on 127.0.0.1 that plays the robot: it answers with an empty telemetry packet twice a second,
so the link stays connected (the node refuses cmd_vel while the link is LOST). Each message
carries a new linear speed, so the node's link sends it at once; its arrival is matched by
the drive axis value. The baseline, measured in
the same run against the same socket, is LinkCore.set_velocities called directly.
"""

from __future__ import annotations

import argparse
import logging
import os
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from ocu.link.core import LinkCore
from ocu.profile import RobotProfile, load_profile
from ocu.protocol import ProtocolError, RemoteControlPacket, TelemetryPacket
from ocu.protocol.wire import make_codec
from ocu.ros.environment import missing_ros
from ocu.ros.master import RosMaster

WARMUP = 20
PAUSE_S = 0.01
ARRIVAL_TIMEOUT_S = 2.0
NODE_NAME = "ocu_ros_bench"
# Well within the link's 3 s LINK LOST, and light next to the cmd_vel stream measured.
TELEMETRY_PERIOD_S = 0.5
MAX_LINEAR_M_S = 0.45


def percentile(values: list[float], q: float) -> float:
    """The q-th percentile (0-100) by linear interpolation."""
    return float(np.percentile(values, q))


class Robot:
    """A bare socket on 127.0.0.1: timestamps the first RCP carrying each drive axis value
    and keeps its sender's link connected with empty telemetry packets."""

    def __init__(self, profile: RobotProfile) -> None:
        self.codec = make_codec(profile)
        self.axis = profile.channels["drive_linear"].axis
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.settimeout(0.2)
        self.address: tuple[str, int] = self.sock.getsockname()
        self.first_seen: dict[int, float] = {}
        self._telemetry_due: dict[tuple[str, int], float] = {}
        self._tick = 0
        self.cond = threading.Condition()
        self._stop = False
        self.thread = threading.Thread(target=self._run, name="bench-robot")
        self.thread.start()

    def _run(self) -> None:
        while not self._stop:
            try:
                data, sender = self.sock.recvfrom(65536)
            except TimeoutError:
                continue
            arrived = time.perf_counter()
            try:
                packet = self.codec.decode(data)
            except ProtocolError:
                continue  # the node's link may probe with extension hellos
            if isinstance(packet, RemoteControlPacket):
                with self.cond:
                    self.first_seen.setdefault(packet.axes[self.axis], arrived)
                    self.cond.notify_all()
                self._answer(sender, arrived)

    def _answer(self, sender: tuple[str, int], now: float) -> None:
        if now < self._telemetry_due.get(sender, 0.0):
            return
        self._telemetry_due[sender] = now + TELEMETRY_PERIOD_S
        self._tick += 1
        self.sock.sendto(self.codec.encode(TelemetryPacket(tick=self._tick)), sender)

    def wait_for(self, axis_value: int) -> float:
        with self.cond:
            if not self.cond.wait_for(lambda: axis_value in self.first_seen, ARRIVAL_TIMEOUT_S):
                raise TimeoutError(f"axis value {axis_value} never arrived")
            return self.first_seen[axis_value]

    def forget(self) -> None:
        with self.cond:
            self.first_seen.clear()

    def close(self) -> None:
        self._stop = True
        self.thread.join()
        self.sock.close()


def speeds(count: int) -> list[float]:
    """Distinct linear speeds at or above the 0.2 m/s minimum, so none is lifted."""
    return [0.2 + 0.2 * i / count for i in range(count)]


def measure(
    profile: RobotProfile, robot: Robot, count: int, send: Callable[[float], None]
) -> list[float]:
    """Latency (s) of each send to its datagram's arrival, after a warm-up."""
    per_unit = profile.channels["drive_linear"].axis_per_unit
    latencies = []
    for index, speed in enumerate(speeds(count + WARMUP)):
        axis_value = round(speed * per_unit)
        start = time.perf_counter()
        send(speed)
        arrived = robot.wait_for(axis_value)
        if index >= WARMUP:
            latencies.append(arrived - start)
        time.sleep(PAUSE_S)
    return latencies


def direct(profile: RobotProfile, robot: Robot, count: int) -> list[float]:
    """The baseline: LinkCore.set_velocities in this process."""
    link = LinkCore(profile, robot.address, gui_alive_timeout_s=None)
    link.set_max_velocity("drive_linear", MAX_LINEAR_M_S)
    link.start()
    try:
        return measure(profile, robot, count, lambda v: link.set_velocities(drive_linear=v))
    finally:
        link.shutdown()


def through_ros(profile: RobotProfile, robot: Robot, count: int, work_dir: Path) -> list[float]:
    """cmd_vel published here, through the ocu-ros node child, to the socket."""
    with RosMaster(work_dir) as master:
        os.environ.update(master.env)
        import rospy
        from geometry_msgs.msg import Twist

        from ocu.ros.rosbridge import init_node

        init_node("ocu_bench", anonymous=True)
        node_log = (work_dir / "node.log").open("wb")
        node = subprocess.Popen(
            [
                sys.executable,
                "-m",
                "ocu.ros.node",
                f"__name:={NODE_NAME}",
                f"_robot:={robot.address[0]}:{robot.address[1]}",
                f"_max_linear:={MAX_LINEAR_M_S}",
            ],
            stdout=node_log,
            stderr=subprocess.STDOUT,
        )
        publisher: Any = rospy.Publisher("cmd_vel", Twist, queue_size=10)
        try:
            deadline = time.monotonic() + 30.0
            while not publisher.impl.has_connection(f"/{NODE_NAME}"):
                if time.monotonic() > deadline or node.poll() is not None:
                    raise RuntimeError(f"the node did not subscribe; see {work_dir}/node.log")
                time.sleep(0.05)

            def send(speed: float) -> None:
                message = Twist()
                message.linear.x = speed
                publisher.publish(message)

            return measure(profile, robot, count, send)
        finally:
            publisher.unregister()
            node.send_signal(signal.SIGTERM)
            node.wait(15)
            node_log.close()
            rospy.signal_shutdown("benchmark finished")


def report(label: str, latencies: list[float]) -> None:
    p50, p99 = percentile(latencies, 50) * 1e3, percentile(latencies, 99) * 1e3
    print(f"{label:<42} p50 {p50:6.3f} ms   p99 {p99:6.3f} ms   max {max(latencies) * 1e3:6.3f} ms")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--count", type=int, default=500, help="messages measured (default 500)")
    args = parser.parse_args()
    reason = missing_ros()
    if reason is not None:
        print(f"bench_ros: {reason}", file=sys.stderr)
        return 1
    # The bare socket never answers: both links report LINK LOST after 3 s, which is harmless.
    logging.basicConfig(level=logging.ERROR)
    profile = load_profile()
    robot = Robot(profile)
    try:
        baseline = direct(profile, robot, args.count)
        robot.forget()
        with tempfile.TemporaryDirectory(prefix="bench_ros_") as work:
            ros = through_ros(profile, robot, args.count, Path(work))
    finally:
        robot.close()
    print(f"{args.count} messages each, {WARMUP} warm-up messages discarded")
    report("LinkCore.set_velocities -> datagram", baseline)
    report("cmd_vel -> ocu-ros node -> datagram", ros)
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""ROS node latency: a cmd_vel published to the datagram at the robot's socket, p50/p99.

    .venv/bin/python bench/bench_ros.py              # 500 messages
    .venv/bin/python bench/bench_ros.py --count 1000

Starts a private roscore on a free port and `python -m ocu.ros.node` against a bare UDP socket
on 127.0.0.1 that plays the robot: it answers with an empty telemetry packet twice a second,
so the link stays connected (the node refuses cmd_vel while the link is LOST). Each message
carries a new linear speed, so the node's link sends it at once; its arrival is matched by
the drive axis value. The baseline, measured in
the same run against the same socket, is UdpLink.set_velocities called directly.
"""

from __future__ import annotations

import argparse
import logging
import os
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from common import StampingRobot, percentile

from ocu.link.live import UdpLink
from ocu.profile import RobotProfile, load_profile
from ocu.ros.environment import missing_ros
from ocu.ros.master import RosMaster

WARMUP = 20
PAUSE_S = 0.01
ARRIVAL_TIMEOUT_S = 2.0
NODE_NAME = "ocu_ros_bench"
# Well within the link's 3 s LINK LOST, and light next to the cmd_vel stream measured.
TELEMETRY_PERIOD_S = 0.5
MAX_LINEAR_M_S = 0.45


def speeds(count: int) -> list[float]:
    """Distinct linear speeds at or above the 0.2 m/s minimum, so none is lifted."""
    return [0.2 + 0.2 * i / count for i in range(count)]


def measure(
    profile: RobotProfile, robot: StampingRobot, count: int, send: Callable[[float], None]
) -> list[float]:
    """Latency (s) of each send to its datagram's arrival, after a warm-up."""
    per_unit = profile.channels["drive_linear"].axis_per_unit
    latencies = []
    for index, speed in enumerate(speeds(count + WARMUP)):
        axis_value = round(speed * per_unit)
        start = time.perf_counter()
        send(speed)
        arrived = robot.wait_for(axis_value, ARRIVAL_TIMEOUT_S)
        if index >= WARMUP:
            latencies.append(arrived - start)
        time.sleep(PAUSE_S)
    return latencies


def direct(profile: RobotProfile, robot: StampingRobot, count: int) -> list[float]:
    """The baseline: the link's set_velocities in this process."""
    link = UdpLink(profile, robot.address, gui_alive_timeout_s=None)
    link.start()
    try:
        return measure(profile, robot, count, lambda v: link.set_velocities(drive_linear=v))
    finally:
        link.shutdown()


def through_ros(
    profile: RobotProfile, robot: StampingRobot, count: int, work_dir: Path
) -> list[float]:
    """cmd_vel published here, through the ocu-ros node child, to the socket."""
    with RosMaster(work_dir) as master:
        os.environ.update(master.env)
        import rospy
        from geometry_msgs.msg import Twist

        from ocu.ros.topics import init_node

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
    # The bare robot answers with empty telemetry only: the links stay CONNECTED.
    logging.basicConfig(level=logging.ERROR)
    profile = load_profile()
    robot = StampingRobot(profile, "drive_linear", telemetry_period_s=TELEMETRY_PERIOD_S)
    try:
        baseline = direct(profile, robot, args.count)
        robot.forget()
        with tempfile.TemporaryDirectory(prefix="bench_ros_") as work:
            ros = through_ros(profile, robot, args.count, Path(work))
    finally:
        robot.close()
    print(f"{args.count} messages each, {WARMUP} warm-up messages discarded")
    report("UdpLink.set_velocities -> datagram", baseline)
    report("cmd_vel -> ocu-ros node -> datagram", ros)
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""The rospy side's fixed parts: topic names and rates, the node's start, the message
helpers and the bridge's publishers (ocu.ros.rosbridge subscribes and runs the loop). Qt-free."""

from __future__ import annotations

import logging
from typing import Any

from ocu.profile import RobotProfile
from ocu.ros.diagnostics import DiagnosticReport
from ocu.ros.environment import ensure_ros_path

ensure_ros_path()

import rospy  # noqa: E402
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue  # noqa: E402
from geometry_msgs.msg import (  # noqa: E402
    PoseStamped,
)
from nav_msgs.msg import Odometry  # noqa: E402
from sensor_msgs.msg import CompressedImage, JointState, LaserScan  # noqa: E402
from tf2_msgs.msg import TFMessage  # noqa: E402

CMD_VEL_TOPIC = "cmd_vel"
JOINT_GOALS_TOPIC = "joint_goals"
JOINT_STATES_TOPIC = "joint_states"
CAMERA_TOPIC = "camera/compressed"
CAMERA_TOPIC_PER_CAMERA = "camera/{name}/image/compressed"
DIAGNOSTICS_TOPIC = "/diagnostics"
POSE_GOAL_TOPIC = "arm/pose_goal"
TWIST_CMD_TOPIC = "arm/twist_cmd"
NAMED_POSE_TOPIC = "arm/named_pose"
TOOL_POSE_TOPIC = "arm/tool_pose"
TF_TOPIC = "/tf"
TF_STATIC_TOPIC = "/tf_static"
ODOM_TOPIC = "odom"
SCAN_TOPIC = "scan"
FOLLOW_PATH_TOPIC = "follow_path"
ODOM_PERIOD_S = 0.05
DIAGNOSTICS_PERIOD_S = 1.0
STOP_JOIN_TIMEOUT_S = 5.0


def init_node(
    name: str, *, anonymous: bool = False, argv: list[str] | None = None, keep_logging: bool = True
) -> None:
    """rospy.init_node without rospy's signal handlers; blocks until the master answers.

    rospy reconfigures the root logger (handlers, level); `keep_logging` puts it back, so a
    host application (the console, pytest) keeps its own logging. Call once per process.
    """
    root = logging.getLogger()
    handlers, level = list(root.handlers), root.level
    rospy.init_node(name, argv=argv, anonymous=anonymous, disable_signals=True)
    if keep_logging:
        for handler in root.handlers:
            if handler not in handlers:
                handler.close()
        root.handlers[:] = handlers
        root.setLevel(level)


class Schedule:
    """A periodic task on a faster loop: due once per period on average. Moving the next
    time from the last one (not from `now`) keeps the rate when the loop's tick does not
    divide the period (a 20 Hz topic on a 50 Hz loop was 16.7 Hz: every third tick)."""

    def __init__(self, period_s: float, start: float) -> None:
        self.period_s = period_s
        self._next = start

    def due(self, now: float) -> bool:
        if now < self._next:
            return False
        # After a stall, start again from now rather than firing a burst to catch up.
        self._next = max(self._next + self.period_s, now - self.period_s / 2.0)
        return True


def publisher_of(message: Any) -> str:
    """The node that published a message (its connection header's callerid)."""
    header = getattr(message, "_connection_header", None) or {}
    return str(header.get("callerid", ""))


def ros_time(wall_time: float) -> Any:
    return rospy.Time.from_sec(wall_time)


def diagnostic_status(report: DiagnosticReport) -> Any:
    status = DiagnosticStatus()
    status.level = int(report.level)
    status.name = report.name
    status.message = report.message
    status.hardware_id = report.hardware_id
    status.values = [KeyValue(key=key, value=value) for key, value in report.values]
    return status


class Publishers:
    """The bridge's publishers; replaced as a whole on start and stop."""

    def __init__(self, profile: RobotProfile) -> None:
        self.joint_states = rospy.Publisher(JOINT_STATES_TOPIC, JointState, queue_size=10)
        self.camera = rospy.Publisher(CAMERA_TOPIC, CompressedImage, queue_size=2)
        self.cameras = {
            name: rospy.Publisher(
                CAMERA_TOPIC_PER_CAMERA.format(name=name), CompressedImage, queue_size=2
            )
            for name in profile.link.camera_names
        }
        self.diagnostics = rospy.Publisher(DIAGNOSTICS_TOPIC, DiagnosticArray, queue_size=2)
        self.tool_pose: Any = None
        # /tf carries base_link -> tool0 (the arm) and odom -> base_link (navigation).
        self.tf: Any = None
        if profile.arm is not None:
            self.tool_pose = rospy.Publisher(TOOL_POSE_TOPIC, PoseStamped, queue_size=10)
            self.tf = rospy.Publisher(TF_TOPIC, TFMessage, queue_size=10)
        self.navigation: list[Any] = []
        self.odom: Any = None
        self.scan: Any = None

    def add_navigation(self) -> None:
        self.odom = rospy.Publisher(ODOM_TOPIC, Odometry, queue_size=10)
        if self.tf is None:
            self.tf = rospy.Publisher(TF_TOPIC, TFMessage, queue_size=10)
        self.scan = rospy.Publisher(SCAN_TOPIC, LaserScan, queue_size=2)
        self.navigation = [self.odom, self.scan]

    def unregister(self) -> None:
        for publisher in (
            self.joint_states,
            self.camera,
            self.diagnostics,
            *self.cameras.values(),
            *self.navigation,
        ):
            publisher.unregister()
        for publisher in (self.tool_pose, self.tf):
            if publisher is not None:
                publisher.unregister()

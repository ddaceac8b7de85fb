"""The rospy side of the bridge: topics in and out around `BridgeCore`. Qt-free.

`RosBridge` is what both the `ocu-ros` node and the console host. It subscribes to cmd_vel
and joint goals, publishes joint states, camera images and diagnostics, and runs one thread
("ocu-ros-bridge") for the cmd_vel timeout, position control and diagnostics.

Topics (relative names resolve in the node's namespace; /diagnostics is global):

- in  `cmd_vel`        geometry_msgs/Twist (or TwistStamped with twist_stamped)
- in  `joint_goals`    sensor_msgs/JointState: name[] with position[] in radians
- out `joint_states`   sensor_msgs/JointState: radians, rad/s, effort = motor current (A)
- out `camera/compressed` and `camera/<name>/image/compressed`  sensor_msgs/CompressedImage
- out `/diagnostics`   diagnostic_msgs/DiagnosticArray: link health (with the battery when
                        the robot reports one) and the bridge's state;
  for a UR also its controller's robot mode, safety mode and stop flags

The arm (docs/arm.md), when the profile has an [arm] table:

- in  `arm/pose_goal`  geometry_msgs/PoseStamped in base_link: tool0's position; the pitch
  from the orientation (an arm of six joints or more, a UR: the whole orientation)
- in  `arm/twist_cmd`  geometry_msgs/TwistStamped in base_link: tool0's linear velocity and
  the angular velocity about its pitch axis; the arm stops 0.1 s after the last one
- in  `arm/named_pose` std_msgs/String: a stored pose (stow, ready, ... or the operator's)
- out `arm/tool_pose`  geometry_msgs/PoseStamped: tool0 from each telemetry packet
- out `/tf`            tf2_msgs/TFMessage: base_link -> tool0

With a Navigator (driving with a map, ocu.nav.navigator):

- out `odom` nav_msgs/Odometry (frame `odom`, child `base_link`) and `/tf` odom -> base_link
- out `scan` sensor_msgs/LaserScan, when the robot sends range scans
- in  `scan` other nodes' LaserScans for the safety zones, each publisher and frame a source
  of its own, placed by its frame (`base_link`, or a frame linked to it on /tf, /tf_static)
- in  `/tf`, `/tf_static` other nodes' transforms, to place their scans
- in  `follow_path` nav_msgs/Path in `odom`: handed to the host (`on_path`), whose model
  runs the path mode (Samson's controller); a cmd_vel, the operator, LINK LOST or stale
  odometry ends it
"""

from __future__ import annotations

import logging
import math
import pathlib
import threading
import time
from collections.abc import Callable
from typing import Any

from ocu.control.commands import VelocityLimits
from ocu.control.position import PositionError
from ocu.kinematics.arm import ArmError, ToolPose
from ocu.link.base import Link
from ocu.link.ur import UrLink
from ocu.nav.navigator import Navigator
from ocu.profile import RobotProfile
from ocu.records import (
    CommandSent,
    LinkEvent,
    LinkState,
    LinkStateChanged,
    LinkStats,
    ScanFrame,
    StatusFrame,
    TelemetryFrame,
    VideoFrame,
)
from ocu.ros.bridge import BridgeCore, StateCallback, VelocitySink
from ocu.ros.convert import (
    BridgeError,
    BridgeSettings,
    Throttle,
    camera_name,
    joint_state,
    quaternion_xyzw,
    quoted,
)
from ocu.ros.diagnostics import BridgeState, bridge_report, controller_report, link_report
from ocu.ros.environment import ensure_ros_path
from ocu.ros.navigation import (
    FrameTree,
    NavigationError,
    laser_scan_data,
    odometry_data,
    path_points,
    scan_from_ros,
)
from ocu.ros.topics import (
    CMD_VEL_TOPIC,
    DIAGNOSTICS_PERIOD_S,
    FOLLOW_PATH_TOPIC,
    JOINT_GOALS_TOPIC,
    NAMED_POSE_TOPIC,
    ODOM_PERIOD_S,
    POSE_GOAL_TOPIC,
    SCAN_TOPIC,
    STOP_JOIN_TIMEOUT_S,
    TF_STATIC_TOPIC,
    TF_TOPIC,
    TWIST_CMD_TOPIC,
    Publishers,
    Schedule,
    diagnostic_status,
    publisher_of,
    ros_time,
)

ensure_ros_path()

import rospy  # noqa: E402
from diagnostic_msgs.msg import DiagnosticArray, KeyValue  # noqa: E402
from geometry_msgs.msg import (  # noqa: E402
    PoseStamped,
    TransformStamped,
    Twist,
    TwistStamped,
)
from nav_msgs.msg import Odometry, Path  # noqa: E402
from sensor_msgs.msg import CompressedImage, JointState, LaserScan  # noqa: E402
from std_msgs.msg import String  # noqa: E402
from tf2_msgs.msg import TFMessage  # noqa: E402

log = logging.getLogger("ocu.ros")


class RosBridge:
    """cmd_vel and joint goals in, joint states, images and diagnostics out; Qt-free.

    `start(link)` subscribes and begins commanding; `stop()` unsubscribes and zeroes what
    ROS was moving. `override()` hands control to the operator at once without sending
    anything; `enable()` gives it back. `on_state_changed(state, text)` runs on a bridge or
    rospy thread and must not block (emit a queued Qt signal).
    """

    def __init__(
        self,
        profile: RobotProfile,
        settings: BridgeSettings | None = None,
        *,
        hardware_id: str = "",
        on_step: Callable[[], None] | None = None,
        on_state_changed: StateCallback | None = None,
        arm_poses_path: pathlib.Path | None = None,
        navigator: Navigator | None = None,
        feed_navigator: bool = True,
        on_path: Callable[[list[tuple[float, float]]], None] | None = None,
        on_cmd_vel: Callable[[], None] | None = None,
    ) -> None:
        """`navigator` adds odom, tf and scan. `feed_navigator`: the bridge feeds it the
        link's events; a console model (the window's, `ocu-ros`'s) feeds its own. `on_path`
        takes a /follow_path (subscribed only with it) to the host's path mode; `on_cmd_vel`
        runs on each cmd_vel before it is obeyed (`ocu-ros` ends a path there)."""
        self.profile = profile
        self.navigator = navigator
        self.feed_navigator = feed_navigator
        self.on_path = on_path
        self.on_cmd_vel = on_cmd_vel
        self.core = BridgeCore(
            profile, settings, on_state_changed=on_state_changed, arm_poses_path=arm_poses_path
        )
        self.settings = self.core.settings
        self.hardware_id = hardware_id
        # Called each step of the bridge thread: the host watches it (ocu-ros stops what ROS
        # moves when it falls silent); the link's heartbeat is the control thread's.
        self.on_step = on_step
        self._life_lock = threading.Lock()
        self._link: Link | None = None
        self._battery_v: float | None = None  # the newest status report's, for /diagnostics
        self._subscribers: list[Any] = []
        self._publishers: Publishers | None = None
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        # Set when the bridge thread died; the node then exits (the console shows "off").
        self.failed = threading.Event()
        self._throttle = Throttle()
        # Other nodes' transforms, to place their scans by frame.
        self.frames = FrameTree()

    # ---- life --------------------------------------------------------------------------

    def start(self, link: Link, limits: VelocityLimits, sink: VelocitySink | None = None) -> None:
        """Subscribe to `link`, advertise and command it; rospy.init_node must have run.

        Commands go to `sink` when given (a console model), else to the link itself;
        `limits` are the velocity maxima ROS is held to.
        """
        with self._life_lock:
            if self._link is not None:
                raise RuntimeError("the ROS bridge is already started")
            self._link = link
            self._publishers = Publishers(self.profile)
            target: VelocitySink = sink if sink is not None else link
            navigator = self.navigator
            if navigator is not None:
                self._publishers.add_navigation()
            link.subscribe(self._on_link_event)
            self.core.attach(target, limits, link_state=lambda: link.state)
            if self.settings.twist_stamped:
                twist = rospy.Subscriber(
                    CMD_VEL_TOPIC, TwistStamped, self._on_twist_stamped, queue_size=1
                )
            else:
                twist = rospy.Subscriber(CMD_VEL_TOPIC, Twist, self._on_twist, queue_size=1)
            goals = rospy.Subscriber(JOINT_GOALS_TOPIC, JointState, self._on_joint_goal)
            self._subscribers = [twist, goals]
            if self.core.arm_available:
                self._subscribers += [
                    rospy.Subscriber(POSE_GOAL_TOPIC, PoseStamped, self._on_pose_goal),
                    rospy.Subscriber(
                        TWIST_CMD_TOPIC, TwistStamped, self._on_arm_twist, queue_size=1
                    ),
                    rospy.Subscriber(NAMED_POSE_TOPIC, String, self._on_named_pose),
                ]
            if navigator is not None:
                self._subscribers += [
                    rospy.Subscriber(SCAN_TOPIC, LaserScan, self._on_scan, queue_size=10),
                    rospy.Subscriber(TF_TOPIC, TFMessage, self._on_tf, queue_size=50),
                    rospy.Subscriber(TF_STATIC_TOPIC, TFMessage, self._on_tf, queue_size=50),
                ]
            if navigator is not None and self.on_path is not None:
                self._subscribers.append(
                    rospy.Subscriber(FOLLOW_PATH_TOPIC, Path, self._on_follow_path, queue_size=1)
                )
            self._stop.clear()
            self.failed.clear()
            self._thread = threading.Thread(target=self._run, name="ocu-ros-bridge", daemon=True)
            self._thread.start()
        log.info(
            "ROS bridge started: %s (%s), %s, min %.2f m/s / %.2f rad/s, timeout %.2f s",
            CMD_VEL_TOPIC,
            "TwistStamped" if self.settings.twist_stamped else "Twist",
            JOINT_GOALS_TOPIC,
            self.settings.min_linear_m_s,
            self.settings.min_angular_rad_s,
            self.settings.cmd_vel_timeout_s,
        )

    def stop(self, *, stop_motion: bool = True) -> None:
        """Unsubscribe, stop the thread and (with stop_motion) zero what ROS moved; idempotent."""
        with self._life_lock:
            if self._link is None:
                return
            for subscriber in self._subscribers:
                subscriber.unregister()
            self._subscribers = []
            self._stop.set()
            thread, self._thread = self._thread, None
            if thread is not None and thread is not threading.current_thread():
                thread.join(STOP_JOIN_TIMEOUT_S)
            # After detach the core refuses callbacks still in flight on rospy threads.
            self.core.detach(stop=stop_motion)
            self._link.unsubscribe(self._on_link_event)
            publishers, self._publishers = self._publishers, None
            self._link = None
        if publishers is not None:
            publishers.unregister()
        log.info("ROS bridge stopped")

    def override(self, reason: str = "operator") -> bool:
        """The operator takes over; True if ROS had control. Sends nothing: the caller then
        sends the operator's command, which replaces everything ROS commanded."""
        return self.core.override(reason)

    def enable(self) -> None:
        """Give control back to ROS after an override."""
        self.core.enable()

    @property
    def state(self) -> BridgeState:
        """off, listening, commanding or overridden."""
        return self.core.state

    @property
    def started(self) -> bool:
        """Whether start() ran and stop() did not."""
        with self._life_lock:
            return self._link is not None

    # ---- link events (any thread) ------------------------------------------------------

    def _on_link_event(self, event: LinkEvent) -> None:
        if isinstance(event, LinkStateChanged):
            # A lost link stops what ROS moves, whatever cmd_vel says next.
            self.core.on_link_state(event.state, event.reason)
        elif isinstance(event, TelemetryFrame):
            self.on_telemetry(event)
        elif isinstance(event, VideoFrame):
            self.on_video_frame(event)
        elif isinstance(event, ScanFrame):
            self.on_robot_scan(event)
        elif isinstance(event, StatusFrame) and event.voltage_v is not None:
            self._battery_v = event.voltage_v
        navigator = self.navigator
        if navigator is None or not self.feed_navigator:
            return
        if isinstance(event, TelemetryFrame):
            navigator.on_telemetry(event)
        elif isinstance(event, StatusFrame):
            navigator.on_status(event)
        elif isinstance(event, CommandSent):
            navigator.on_command(event.command, event.sent_at)
        elif isinstance(event, LinkStats):
            navigator.on_round_trip(event.delay_s)

    # ---- driving with a map ------------------------------------------------------------

    def on_robot_scan(self, scan: ScanFrame) -> None:
        """The robot's own scan: to the navigator (the node) and on `scan`."""
        if self.navigator is not None and self.feed_navigator:
            self.navigator.on_scan(scan)
        publishers = self._publishers
        if publishers is None or publishers.scan is None:
            return
        data = laser_scan_data(scan)
        message = LaserScan()
        message.header.stamp = ros_time(scan.wall_time)
        message.header.frame_id = data.frame_id
        message.angle_min = data.angle_min
        message.angle_max = data.angle_max
        message.angle_increment = data.angle_increment
        message.scan_time = data.scan_time
        message.range_min = data.range_min
        message.range_max = data.range_max
        message.ranges = list(data.ranges)
        self._publish(publishers.scan, message)

    def _on_scan(self, message: Any) -> None:
        """Another node's scan: a source of its own (publisher and frame) for the zones,
        placed on the chassis by its frame."""
        navigator = self.navigator
        if navigator is None:
            return
        caller = publisher_of(message)
        if caller == rospy.get_name():
            return  # our own robot's scan coming back
        frame = str(message.header.frame_id)
        try:
            mount = self.frames.mount(frame)
            scan = scan_from_ros(
                angle_min=float(message.angle_min),
                angle_increment=float(message.angle_increment),
                range_min=float(message.range_min),
                range_max=float(message.range_max),
                ranges=[float(r) for r in message.ranges],
                received_at=time.monotonic(),
                wall_time=message.header.stamp.to_sec() or time.time(),
            )
        except NavigationError as err:
            if self._throttle.allow(f"scan {caller[:80]}"):
                log.warning("scan from %s ignored: %s", quoted(caller), err)
            return
        source = f"{caller or 'an unnamed publisher'} in {frame.lstrip('/')[:80]}"
        navigator.on_scan(mount.place(scan), source=source, mount_xy_m=(mount.x_m, mount.y_m))

    def _on_tf(self, message: Any) -> None:
        """Other nodes' transforms (our own odom and tool0 are not needed to place scans)."""
        if publisher_of(message) == rospy.get_name():
            return
        for transform in message.transforms:
            t, r = transform.transform.translation, transform.transform.rotation
            try:
                self.frames.set(
                    str(transform.header.frame_id),
                    str(transform.child_frame_id),
                    (t.x, t.y, t.z),
                    (r.x, r.y, r.z, r.w),
                )
            except NavigationError as err:
                if self._throttle.allow("tf"):
                    log.warning("transform from %s ignored: %s", quoted(publisher_of(message)), err)

    def _on_follow_path(self, message: Any) -> None:
        try:
            points = path_points(
                str(message.header.frame_id),
                [(p.pose.position.x, p.pose.position.y) for p in message.poses],
            )
        except NavigationError as err:
            if self._throttle.allow("follow_path"):
                log.error("%s", err)
            return
        if self.on_path is not None:
            self.on_path(points)

    def publish_odometry(self) -> None:
        """The navigator's pose on `odom` and as the tf odom -> base_link."""
        publishers, navigator = self._publishers, self.navigator
        if publishers is None or navigator is None or publishers.odom is None:
            return
        data = odometry_data(navigator.estimate())
        stamp = rospy.Time.now()
        odom = Odometry()
        odom.header.stamp = stamp
        odom.header.frame_id = data.frame_id
        odom.child_frame_id = data.child_frame_id
        pose = odom.pose.pose
        pose.position.x, pose.position.y, pose.position.z = data.position
        o = pose.orientation
        o.x, o.y, o.z, o.w = data.orientation_xyzw
        odom.pose.covariance = list(data.pose_covariance)
        twist = odom.twist.twist
        twist.linear.x, twist.linear.y, twist.linear.z = data.linear
        twist.angular.x, twist.angular.y, twist.angular.z = data.angular
        odom.twist.covariance = list(data.twist_covariance)
        self._publish(publishers.odom, odom)
        transform = TransformStamped()
        transform.header.stamp = stamp
        transform.header.frame_id = data.frame_id
        transform.child_frame_id = data.child_frame_id
        t = transform.transform
        t.translation.x, t.translation.y, t.translation.z = data.position
        t.rotation.x, t.rotation.y, t.rotation.z, t.rotation.w = data.orientation_xyzw
        self._publish(publishers.tf, TFMessage(transforms=[transform]))

    def on_telemetry(self, frame: TelemetryFrame) -> None:
        """Feed the position controller and publish joint_states."""
        publishers = self._publishers
        if publishers is None:
            return
        self.core.on_telemetry(frame.readings, frame.received_at, frame.delay_s)
        data = joint_state(self.profile, frame.readings)
        message = JointState()
        message.header.stamp = ros_time(frame.wall_time)
        message.name = list(data.names)
        message.position = list(data.positions_rad)
        message.velocity = list(data.velocities_rad_s)
        message.effort = list(data.currents_a)
        self._publish(publishers.joint_states, message)
        self._publish_tool(publishers, frame)

    def _publish_tool(self, publishers: Publishers, frame: TelemetryFrame) -> None:
        """tool0 on arm/tool_pose and on /tf, from the packet's readings."""
        arm = self.profile.arm
        if arm is None or publishers.tool_pose is None:
            return
        pose = self.core.arm_tool_matrix(frame.readings)
        if pose is None:
            return
        stamp = ros_time(frame.wall_time)
        x, y, z, w = quaternion_xyzw(pose)
        message = PoseStamped()
        message.header.stamp = stamp
        message.header.frame_id = arm.base_link
        message.pose.position.x, message.pose.position.y, message.pose.position.z = (
            float(v) for v in pose[:3, 3]
        )
        orientation = message.pose.orientation
        orientation.x, orientation.y, orientation.z, orientation.w = x, y, z, w
        self._publish(publishers.tool_pose, message)
        if publishers.tf is not None:
            transform = TransformStamped()
            transform.header.stamp = stamp
            transform.header.frame_id = arm.base_link
            transform.child_frame_id = arm.tool_link
            translation = transform.transform.translation
            translation.x, translation.y, translation.z = (float(v) for v in pose[:3, 3])
            rotation = transform.transform.rotation
            rotation.x, rotation.y, rotation.z, rotation.w = x, y, z, w
            self._publish(publishers.tf, TFMessage(transforms=[transform]))

    def on_video_frame(self, frame: VideoFrame) -> None:
        """Publish a JPEG on camera/compressed and on its camera's own topic."""
        publishers = self._publishers
        if publishers is None:
            return
        name = camera_name(self.profile, frame.camera)
        targets = [publishers.camera]
        if name in publishers.cameras:
            targets.append(publishers.cameras[name])
        targets = [p for p in targets if p.get_num_connections() > 0]
        if not targets:
            return
        message = CompressedImage()
        message.header.stamp = ros_time(frame.wall_time)
        message.header.frame_id = name
        message.format = "jpeg"
        message.data = frame.jpeg
        for publisher in targets:
            self._publish(publisher, message)

    def on_link_state(self, state: LinkState, reason: str) -> None:
        """The link's state: LINK LOST stops ROS's motion and refuses cmd_vel until recovery."""
        self.core.on_link_state(state, reason)

    def publish_diagnostics(self) -> None:
        """Publish the link's and the bridge's health on /diagnostics."""
        publishers, link = self._publishers, self._link
        if publishers is None or link is None:
            return
        message = DiagnosticArray()
        message.header.stamp = rospy.Time.now()
        bridge = diagnostic_status(bridge_report(self.core.status(), self.hardware_id))
        if self.navigator is not None:
            # What the safety zones do now ("zones off: no range data", "slowed: ...").
            bridge.values.append(KeyValue(key="safety zones", value=self.navigator.zones.text))
            sources = ", ".join(self.navigator.scan_sources()) or "none"
            bridge.values.append(KeyValue(key="scan sources", value=sources))
        link_status = diagnostic_status(link_report(link.state, link.stats(), self.hardware_id))
        if self._battery_v is not None:
            link_status.values.append(KeyValue(key="battery", value=f"{self._battery_v:.2f} V"))
        message.status = [link_status, bridge]
        if isinstance(link, UrLink):
            # The UR's robot and safety modes: what the controller lets move (docs/ur.md).
            report = controller_report(link.robot_status, self.hardware_id)
            message.status.append(diagnostic_status(report))
        self._publish(publishers.diagnostics, message)

    def _publish(self, publisher: Any, message: Any) -> None:
        try:
            publisher.publish(message)
        except rospy.ROSException as err:
            # Unregistered by stop() or rospy shutting down meanwhile.
            log.debug("not published: %s", err)

    # ---- ROS callbacks (rospy threads) -------------------------------------------------

    def _on_twist(self, message: Any) -> None:
        self._cmd_vel(message)

    def _on_twist_stamped(self, message: Any) -> None:
        self._cmd_vel(message.twist)

    def _cmd_vel(self, twist: Any) -> None:
        if self.on_cmd_vel is not None:
            self.on_cmd_vel()
        linear, angular = twist.linear, twist.angular
        ignored = (float(linear.y), float(linear.z), float(angular.x), float(angular.y))
        try:
            drive = self.core.on_cmd_vel(float(linear.x), float(angular.z), ignored)
        except BridgeError as err:
            if self._throttle.allow("cmd_vel"):
                stopped = ", tracks stopped" if self.settings.drive is not None else ""
                log.warning("cmd_vel rejected%s: %s", stopped, err)
            return
        if drive is None and self._throttle.allow("cmd_vel ignored"):
            log.info("cmd_vel ignored: %s", self.core.refusal() or "ROS control changed")

    def _on_joint_goal(self, message: Any) -> None:
        try:
            goals = self.core.set_goals(list(message.name), list(message.position))
        except PositionError as err:
            log.error("joint goal rejected: %s", err)
            return
        if goals:
            log.info(
                "joint goal: %s",
                ", ".join(f"{j} -> {a:.4f} rad ({math.degrees(a):.1f}°)" for j, a in goals.items()),
            )
        else:
            log.info("joint goals cancelled")

    def _frame_ok(self, header: Any, topic: str) -> bool:
        base = self.profile.arm.base_link if self.profile.arm is not None else ""
        frame = str(header.frame_id).lstrip("/")
        if frame and frame != base:
            if self._throttle.allow(topic):
                log.error(
                    "%s rejected: frame %s, only %r is understood", topic, quoted(frame), base
                )
            return False
        return True

    def _on_pose_goal(self, message: Any) -> None:
        if not self._frame_ok(message.header, POSE_GOAL_TOPIC):
            return
        position, orientation = message.pose.position, message.pose.orientation
        try:
            target = self.core.goal_from_pose(
                (position.x, position.y, position.z),
                (orientation.x, orientation.y, orientation.z, orientation.w),
            )
            goal = self.core.on_pose_goal(target)
        except ArmError as err:
            log.error("pose goal rejected: %s", err)
            return
        if isinstance(target, ToolPose):
            what = target.describe()
        else:
            q = orientation
            what = (
                f"x {position.x * 1e3:.0f} y {position.y * 1e3:.0f} z {position.z * 1e3:.0f} mm, "
                f"orientation ({q.x:.3f}, {q.y:.3f}, {q.z:.3f}, {q.w:.3f})"
            )
        log.info(
            "pose goal %s: %s",
            what,
            ", ".join(f"{j} {math.degrees(a):.1f}°" for j, a in goal.items()),
        )

    def _on_named_pose(self, message: Any) -> None:
        name = str(message.data)
        try:
            self.core.on_named_pose(name)
        except ArmError as err:
            if self._throttle.allow(NAMED_POSE_TOPIC):
                log.error("named pose rejected: %s", err)
            return
        log.info("moving the arm to %s", name)

    def _on_arm_twist(self, message: Any) -> None:
        if not self._frame_ok(message.header, TWIST_CMD_TOPIC):
            return
        linear, angular = message.twist.linear, message.twist.angular
        try:
            obeyed = self.core.on_arm_twist(
                (linear.x, linear.y, linear.z), (angular.x, angular.y, angular.z)
            )
        except ArmError as err:
            if self._throttle.allow(TWIST_CMD_TOPIC):
                log.warning("arm twist rejected: %s", err)
            return
        if not obeyed and self._throttle.allow("arm twist ignored"):
            log.info("arm twist ignored: %s", self.core.refusal() or "the link is not up")

    # ---- bridge thread -----------------------------------------------------------------

    def _run(self) -> None:
        try:
            self._loop()
        except Exception:
            # Without this loop nothing enforces the cmd_vel timeout: stop what ROS moves
            # and take ROS off the robot (the host's watch on this thread stops the rest).
            log.exception("ROS bridge loop failed: ROS control stopped")
            self.failed.set()
            self.core.detach(stop=True)

    def _loop(self) -> None:
        period_s = 1.0 / self.settings.rate_hz
        next_step = time.monotonic()
        next_diagnostics = next_step
        odometry = Schedule(ODOM_PERIOD_S, next_step)
        while not self._stop.is_set():
            now = time.monotonic()
            if self.on_step is not None:
                self.on_step()
            try:
                for text in self.core.step(now):
                    log.info("%s", text)
                if odometry.due(now):
                    self.publish_odometry()
            except Exception as err:
                # One failing step halts what ROS moves, with the reason; the loop (the
                # cmd_vel timeout, the host's watch) and the node go on serving.
                reason = f"{type(err).__name__}: {err}"
                if self._throttle.allow("loop"):
                    log.exception("ROS bridge step failed (%s)", reason)
                self.core.halt(f"the bridge's step failed: {reason}")
            if now >= next_diagnostics:
                next_diagnostics = now + DIAGNOSTICS_PERIOD_S
                try:
                    self.publish_diagnostics()
                except Exception:
                    log.exception("diagnostics failed")
            next_step = max(next_step + period_s, now)
            self._stop.wait(max(next_step - time.monotonic(), 0.0))

"""What the ROS bridge decides, without ROS or Qt: drive scaling, timeouts, link loss, goals.

`BridgeCore` turns velocity commands (cmd_vel) and joint position goals into channel
velocities for a velocity sink (a `Link`, or the console model), and stops what it started
when cmd_vel stops coming or the link is lost. The rospy wrapper (`ocu.ros.rosbridge`) only
converts messages and calls it; the console can host the same core and take control back
from ROS at once (`override`). Its pure conversions are in `ocu.ros.convert`, its reports in
`ocu.ros.diagnostics` (every public name of both is importable from here too).

Link loss: while the link is LOST the bridge sends zeros whatever cmd_vel says; once it is
CONNECTED again, cmd_vel must have been zero or silent for the cmd_vel timeout before a
non-zero one drives again, so a planner still streaming its old command does not restart
the robot the moment the link comes back (the console's rule: nothing resumes by itself).

The arm (ocu.control.arm): a pose goal or a stored pose is one synchronized move; a twist
jogs tool0 and stops `twist_timeout_s` after the last. They share the position controller's
prediction and stop with everything else (link lost, ROS overridden, the bridge detached).
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Protocol

import numpy as np

from ocu.console.poses import MAX_NAME_LENGTH, PoseError, PoseStore
from ocu.control.arm import ArmController
from ocu.control.commands import VelocityLimits
from ocu.control.position import PositionController, PositionError
from ocu.kinematics.arm import ArmError, ArmKinematics, ToolPose, pitch_axis
from ocu.model.tree import Matrix
from ocu.model.urdf import UrdfError, load_urdf, profile_urdf_path
from ocu.profile import RobotProfile
from ocu.records import JointReading, LinkState

# Every public name of the two modules is importable from here too (the bridge's API).
from ocu.ros.convert import *  # noqa: F403
from ocu.ros.convert import (
    NO_DRIVE,
    BridgeError,
    BridgeSettings,
    CmdVelTimeout,
    Throttle,
    bound_arm_twist,
    bound_drive,
    drive_bounds,
    parse_joint_goal,
    quoted,
    rotation_of,
    twist_to_drive,
)
from ocu.ros.diagnostics import *  # noqa: F403
from ocu.ros.diagnostics import STATE_TEXT, BridgeState, BridgeStatus, LinkGate, gate_text

log = logging.getLogger("ocu.ros")


class VelocitySink(Protocol):
    """Where the bridge sends velocities: a Link (ocu-ros), or the console model (the window)."""

    def set_velocities(self, **velocities: float) -> None: ...


StateCallback = Callable[[BridgeState, str], None]


class BridgeCore:
    """cmd_vel and joint goals to channel velocities; thread-safe, no ROS, no Qt.

    Every entry point takes one lock, and velocities are sent while holding it: once
    `override()` or `detach()` has returned, the bridge sends nothing more, so an operator
    command sent afterwards is never replaced by a late ROS command. The link's state
    arrives through `on_link_state` (the link thread): see `LinkGate`.
    """

    def __init__(
        self,
        profile: RobotProfile,
        settings: BridgeSettings | None = None,
        *,
        clock: Callable[[], float] = time.monotonic,
        on_state_changed: StateCallback | None = None,
        arm: ArmKinematics | None = None,
        arm_poses_path: Path | None = None,
        source: str = "ROS",
    ) -> None:
        self.profile = profile
        # Who commands through it, in its messages: ROS, or a live client (ocu.live.goals).
        self.source = source
        self.settings = settings if settings is not None else BridgeSettings.from_profile(profile)
        self.clock = clock
        # Runs under the bridge's lock on the calling thread: it must not block.
        self.on_state_changed = on_state_changed
        self._lock = threading.RLock()
        self._sink: VelocitySink | None = None
        self._limits = VelocityLimits(profile)
        self._controller = PositionController(profile, self._limits)
        self._timeout = CmdVelTimeout(self.settings.cmd_vel_timeout_s)
        self._state = BridgeState.OFF
        self._drive = self.settings.drive_zero
        self._goal_channels: set[str] = set()
        self._cmd_vel_count = 0
        self._rejected = 0
        self._timeouts = 0
        self._ignored_logged = False
        # The link as last reported; a new link starts CONNECTING, which lets ROS drive.
        self._link_state = LinkState.CONNECTING
        self._gate = LinkGate.OPEN
        self._link_refused = 0
        # When the last cmd_vel asking for motion arrived (obeyed or not): the recovery
        # rule measures the quiet time from it.
        self._last_motion_at: float | None = None
        # The arm in Cartesian space (None: no [arm] in the profile, or no URDF for it).
        self.arm_kinematics: ArmKinematics | None = arm
        self.arm_error = ""
        if arm is None and profile.arm is not None:
            try:
                self.arm_kinematics = ArmKinematics(
                    load_urdf(profile_urdf_path(profile), meshes=False), profile.arm
                )
            except (ArmError, UrdfError) as err:
                self.arm_error = f"arm topics off: {err}"
                log.warning("%s", self.arm_error)
        self.poses: PoseStore | None = None
        if self.arm_kinematics is not None:
            kin = self.arm_kinematics
            limits = {
                joint: (float(kin.chain.lower[i]), float(kin.chain.upper[i]))
                for i, joint in enumerate(kin.joints)
            }
            builtin = profile.arm.poses if profile.arm is not None else {}
            self.poses = PoseStore(builtin, kin.joints, limits, arm_poses_path)
            if self.poses.error:
                log.warning("stored arm poses: %s", self.poses.error)
        self._arm: ArmController | None = None
        self._arm_owned = False
        self._throttle = Throttle()

    # ---- life --------------------------------------------------------------------------

    def attach(
        self,
        sink: VelocitySink,
        limits: VelocityLimits | None = None,
        *,
        link_state: Callable[[], LinkState] | None = None,
    ) -> None:
        """Start commanding `sink`, bounded by `limits` (the link's; the profile's defaults
        if None); `link_state` reads the link's state now (else the last one reported)."""
        with self._lock:
            self._sink = sink
            self._limits = limits if limits is not None else VelocityLimits(self.profile)
            self._controller = PositionController(self.profile, self._limits)
            if self.arm_kinematics is not None:
                self._arm = ArmController(
                    self.profile, self._limits, self.arm_kinematics, self._controller
                )
                # A sink over timed-move hardware: moves as one command (ocu.control.arm_timed).
                self._arm.timed_moves = bool(getattr(sink, "timed_moves", False))
            self._goal_channels = set()
            self._drive = self.settings.drive_zero
            self._timeout = CmdVelTimeout(self.settings.cmd_vel_timeout_s)
            # Read under the bridge's lock: a change the link makes meanwhile is reported
            # to on_link_state afterwards, which waits for this lock, so none is missed.
            if link_state is not None:
                self._link_state = link_state()
            if _is_lost(self._link_state):
                self._gate = LinkGate.LOST
            elif self._gate is not LinkGate.OPEN:
                # Off and on again while the link recovers: the recovery rule still holds.
                self._gate = LinkGate.RECOVERING
                self._open_if_quiet(self.clock())
            self._set_state(BridgeState.LISTENING)

    def detach(self, *, stop: bool = True) -> None:
        """Stop commanding; with `stop`, zero first the channels the bridge was moving."""
        with self._lock:
            if self._sink is not None and stop:
                zeros = self._owned_channels()
                if zeros:
                    self._sink.set_velocities(**dict.fromkeys(zeros, 0.0))
            self._release()
            self._sink = None
            self._set_state(BridgeState.OFF)

    def override(self, reason: str = "operator") -> bool:
        """The operator takes over: ROS is ignored until `enable()`; sends nothing itself.

        Returns True if ROS was in control (listening or commanding). The host then sends its
        own command, which replaces every channel the bridge was driving.
        """
        with self._lock:
            if self._state not in (BridgeState.LISTENING, BridgeState.COMMANDING):
                return False
            was_commanding = self._state is BridgeState.COMMANDING
            self._release()
            self._set_state(BridgeState.OVERRIDDEN)
        if was_commanding:
            log.info("ROS control overridden (%s)", reason)
        return True

    def enable(self) -> None:
        """ROS may command again after an override (the link gate still applies)."""
        with self._lock:
            if self._state is BridgeState.OVERRIDDEN and self._sink is not None:
                self._timeout = CmdVelTimeout(self.settings.cmd_vel_timeout_s)
                self._set_state(BridgeState.LISTENING)

    def _release(self) -> None:
        self._controller.cancel()
        self._goal_channels = set()
        self._drive = self.settings.drive_zero
        if self._arm is not None:
            self._arm.stop(f"{self.source} released the arm")
            self._arm.pop_messages()
        self._arm_owned = False

    def _owned_channels(self) -> list[str]:
        owned = [name for name, value in self._drive.items() if value != 0.0]
        arm = list(self._arm.channels) if self._arm is not None and self._arm_owned else []
        return owned + sorted(self._goal_channels | set(arm))

    @property
    def _in_control(self) -> bool:
        return self._sink is not None and self._state in (
            BridgeState.LISTENING,
            BridgeState.COMMANDING,
        )

    # ---- the link (link thread) --------------------------------------------------------

    def on_link_state(self, state: LinkState, reason: str = "") -> None:
        """The link changed state: LOST or CLOSED stops what ROS moves and closes the gate."""
        with self._lock:
            self._link_state = state
            if _is_lost(state):
                if self._gate is LinkGate.LOST:
                    return
                self._gate = LinkGate.LOST
                stopped = self._owned_channels() if self._in_control else []
                if stopped:
                    assert self._sink is not None
                    self._sink.set_velocities(**dict.fromkeys(stopped, 0.0))
                    # The prediction integrates what is sent: the zeros too.
                    self._controller.note_sent(self.clock(), {})
                if self._in_control:
                    self._release()
                    self._update_state()
                # A closed link is the normal end of a run: worth a line, not a warning.
                log.log(
                    logging.WARNING if state is LinkState.LOST else logging.INFO,
                    "%s%s: %s commands refused, zeros sent%s",
                    "LINK LOST" if state is LinkState.LOST else "link closed",
                    f" ({reason})" if reason else "",
                    self.source,
                    f" (stopped {', '.join(stopped)})" if stopped else "",
                )
            elif state is LinkState.CONNECTED and self._gate is LinkGate.LOST:
                self._gate = LinkGate.RECOVERING
                log.warning("%s", gate_text(LinkGate.RECOVERING, self.settings.cmd_vel_timeout_s))
                self._open_if_quiet(self.clock())

    def _open_if_quiet(self, now: float) -> None:
        """RECOVERING -> OPEN once cmd_vel has been zero or silent for the timeout."""
        if self._gate is not LinkGate.RECOVERING or self._link_state is not LinkState.CONNECTED:
            return
        quiet_s = None if self._last_motion_at is None else now - self._last_motion_at
        if quiet_s is not None and quiet_s < self.settings.cmd_vel_timeout_s:
            return
        self._gate = LinkGate.OPEN
        log.info(
            "cmd_vel zero or silent for %.2f s since the link came back: ROS may drive again",
            self.settings.cmd_vel_timeout_s,
        )

    # ---- inputs (any thread) -----------------------------------------------------------

    def on_cmd_vel(
        self, linear_x: float, angular_z: float, ignored: Sequence[float] = ()
    ) -> dict[str, float] | None:
        """A Twist arrived: returns the drive velocities sent, or None if not obeyed.

        Not obeyed: ROS is not in control (see `refusal()`), or the link gate is closed and
        the Twist asks for motion (zeros are sent instead). `ignored` are the other four
        Twist components, only to warn once that they do nothing. A non-finite component
        stops the tracks and raises BridgeError; so does any Twist for a robot without a
        chassis (a UR arm), which moves nothing.
        """
        with self._lock:
            if not self._in_control:
                self._rejected += 1
                return None
            assert self._sink is not None
            now = self.clock()
            self._cmd_vel_count += 1
            if self.settings.drive is None:
                self._rejected += 1
                raise BridgeError(NO_DRIVE)
            self._timeout.feed(now)
            if any(v != 0.0 for v in ignored) and not self._ignored_logged:
                self._ignored_logged = True
                log.warning(
                    "cmd_vel: only linear.x and angular.z move a crawler; "
                    "linear.y/z and angular.x/y are ignored"
                )
            try:
                drive = twist_to_drive(linear_x, angular_z, self.settings, self._limits)
                bounds = drive_bounds(self.settings, self._limits)
                if bound_drive(linear_x, angular_z, bounds)[2] and self._throttle.allow("cmd_vel"):
                    linear, turn = self.settings.drive_channels()
                    log.warning(
                        "cmd_vel linear.x %.4g m/s, angular.z %.4g rad/s above the maxima "
                        "(%.2f m/s, %.2f rad/s): scaled to %.3f m/s, %.3f rad/s",
                        linear_x,
                        angular_z,
                        bounds.max_linear_m_s,
                        bounds.max_angular_rad_s,
                        drive[linear],
                        drive[turn],
                    )
            except BridgeError:
                # A broken publisher is no quiet one: it does not open the gate.
                self._last_motion_at = now
                self._rejected += 1
                self._send_drive(self.settings.drive_zero)
                self._update_state()
                raise
            motion = any(v != 0.0 for v in drive.values())
            if motion:
                # Checked before this Twist counts: it may be the first after a quiet spell.
                self._open_if_quiet(now)
                self._last_motion_at = now
            if motion and self._gate is not LinkGate.OPEN:
                self._link_refused += 1
                self._send_drive(self.settings.drive_zero)
                self._update_state()
                return None
            self._send_drive(drive)
            self._update_state()
            return drive

    def refusal(self) -> str:
        """Why cmd_vel is not obeyed now ('' when it is)."""
        with self._lock:
            if not self._in_control:
                return f"{self.source} control {self._state.value}"
            if self._gate is not LinkGate.OPEN:
                return gate_text(self._gate, self.settings.cmd_vel_timeout_s)
            return ""

    def set_goals(self, names: Sequence[str], positions: Sequence[float]) -> dict[str, float]:
        """Joint position goals (rad); all or none apply. PositionError if one is bad.

        An empty goal cancels every joint goal (their joints stop). While the link is lost,
        goals are refused: no telemetry, and recovery must not start motion by itself.
        """
        with self._lock:
            if not self._in_control:
                self._rejected += 1
                raise PositionError("joint goal ignored: ROS is not in control")
            if not names and not positions:
                self._stop_goals()
                self._update_state()
                return {}
            if self._gate is LinkGate.LOST:
                self._rejected += 1
                raise PositionError(f"joint goal ignored: {self._link_state.label}")
            try:
                goals = parse_joint_goal(self.profile, self._limits, names, positions)
            except PositionError:
                self._rejected += 1
                raise
            for joint, angle_rad in goals.items():
                self._controller.set_target(joint, angle_rad)
                self._goal_channels.add(self._controller.channel_of(joint))
            self._update_state()
            return goals

    def _stop_goals(self) -> None:
        channels = sorted(self._goal_channels)
        self._controller.cancel()
        self._goal_channels = set()
        if channels and self._sink is not None:
            self._sink.set_velocities(**dict.fromkeys(channels, 0.0))
            self._controller.note_sent(self.clock(), self._drive)

    def on_telemetry(
        self,
        readings: Mapping[str, JointReading],
        received_at: float,
        delay_s: float | None = None,
    ) -> None:
        """Measured joint angles (and the round trip they took) for the position controller."""
        with self._lock:
            self._controller.on_telemetry(readings, received_at, delay_s)
            if self._arm is not None:
                self._arm.observe(readings)

    # ---- the arm (any thread) ----------------------------------------------------------

    @property
    def arm_available(self) -> bool:
        """Whether the arm topics work (the profile's [arm] and its URDF)."""
        return self.arm_kinematics is not None

    def _arm_ready(self, what: str) -> ArmController:
        """The arm controller when ROS may move it; ArmError (counted) otherwise."""
        if self._arm is None or not self._in_control:
            self._rejected += 1
            reason = self.arm_error or f"{self.source} control {self._state.value}"
            raise ArmError(f"{what} ignored: {reason}")
        if self._gate is LinkGate.LOST:
            self._rejected += 1
            raise ArmError(f"{what} ignored: {self._link_state.label}")
        return self._arm

    def _arm_takes_over(self) -> None:
        """Joint goals on the arm's joints end: the arm commands them now."""
        assert self._arm is not None
        for joint in self._arm.joints:
            self._controller.cancel(joint)
        self._goal_channels -= set(self._arm.channels)
        self._arm_owned = True

    def on_pose_goal(self, target: ToolPose | Matrix) -> dict[str, float]:
        """Move tool0 to a position and pitch, or (an arm of six joints or more) to a whole 4x4
        pose, in the base frame: IK, path check, one synchronized move. Returns the joint
        goal; ArmError with the reason when refused."""
        with self._lock:
            arm = self._arm_ready("pose goal")
            now = self.clock()
            try:
                _, start = arm.estimate(now)
                kin = arm.kinematics
                if isinstance(target, ToolPose):
                    q, label = kin.solve(target, current=start), target.describe()
                else:
                    q = kin.solve_matrix(target, current=start)
                    label = f"{kin.tool_pose(q).describe()} and the goal's orientation"
                move = arm.plan_move(q, now)
            except ArmError:
                self._rejected += 1
                raise
            self._arm_takes_over()
            arm.start(move, now, label)
            self._update_state()
            return kin.mapping(q)

    def on_named_pose(self, name: str) -> dict[str, float]:
        """Move to a stored pose (the profile's or the operator's file) by name."""
        with self._lock:
            arm = self._arm_ready("named pose")
            assert self.poses is not None
            now = self.clock()
            try:
                if len(name) > MAX_NAME_LENGTH:
                    # Not looked up (nor echoed whole by the store's message): no name is longer.
                    raise PoseError(
                        f"no stored pose is named {quoted(name)}: names are at most "
                        f"{MAX_NAME_LENGTH} characters"
                    )
                goal = self.poses.get(name)
                move = arm.plan_move(goal, now)
            except (ArmError, PoseError) as err:
                self._rejected += 1
                raise ArmError(str(err)) from err
            self._arm_takes_over()
            arm.start(move, now, name)
            self._update_state()
            return goal

    def on_arm_twist(self, linear: Sequence[float], angular: Sequence[float]) -> bool:
        """A twist of tool0 in the base frame: its linear velocity, and the angular velocity's
        part about the tool's pitch axis. Motion stops `twist_timeout_s` after the last one.
        Returns whether it was obeyed; a non-finite value stops the arm and raises ArmError."""
        with self._lock:
            arm = self._arm_ready("twist")
            now = self.clock()
            values = [float(v) for v in (*linear, *angular)]
            if len(values) != 6 or not all(math.isfinite(v) for v in values):
                arm.stop("a bad twist")
                self._rejected += 1
                raise ArmError("a twist needs six finite numbers")
            moving = any(values)
            if moving and self._gate is not LinkGate.OPEN:
                self._link_refused += 1
                return False
            try:
                current, _ = arm.estimate(now)
            except ArmError:
                self._rejected += 1
                raise
            tool = arm.kinematics.tool_matrix(current)
            settings = arm.settings
            # Bounded here, before the kinematics: a finite 1e308 overflows the Jacobian's
            # products into nan, and the chain refuses it in the control step.
            jog, clamped = bound_arm_twist(
                values[:3],
                values[3:],
                pitch_axis(tool, arm.kinematics.axis_xy, arm.kinematics.pointing),
                settings.max_linear_speed_m_s,
                settings.max_pitch_speed_rad_s,
            )
            if clamped and self._throttle.allow("arm twist"):
                log.warning(
                    "arm twist above the maxima (%.3f m/s, %.1f°/s): bounded to "
                    "(%.3f, %.3f, %.3f) m/s, %.1f°/s",
                    settings.max_linear_speed_m_s,
                    math.degrees(settings.max_pitch_speed_rad_s),
                    *jog[:3],
                    math.degrees(jog[3]),
                )
            if moving:
                self._arm_takes_over()
            arm.jog(jog, "base", now, expires_after_s=settings.twist_timeout_s)
            self._update_state()
            return True

    def goal_from_pose(
        self, position: Sequence[float], orientation_xyzw: Sequence[float]
    ) -> ToolPose | Matrix:
        """A PoseStamped's content as the arm's goal: for an arm of six joints or more (a UR)
        the whole pose (4x4); else the position and the pitch of the orientation's pointing
        axis (arm.tool_axis; its yaw and roll are the arm's to choose)."""
        if self.arm_kinematics is None:
            raise ArmError(self.arm_error or "this robot has no arm profile")
        values = [float(v) for v in position]
        if len(values) != 3 or not all(math.isfinite(v) for v in values):
            raise ArmError("the goal's position must be three finite numbers")
        try:
            rotation = rotation_of(*(float(v) for v in orientation_xyzw))
        except (BridgeError, TypeError) as err:
            raise ArmError(str(err)) from err
        pose = np.eye(4)
        pose[:3, :3] = rotation
        pose[:3, 3] = values
        if self.arm_kinematics.chain.dof >= 6:
            return pose
        return ToolPose(values[0], values[1], values[2], self.arm_kinematics.pitch(pose))

    def arm_tool_matrix(self, readings: Mapping[str, JointReading]) -> Matrix | None:
        """tool0's pose in the base frame from readings (None: an arm joint not read)."""
        kin = self.arm_kinematics
        if kin is None:
            return None
        angles = {
            name: r.angle_rad
            for name, r in readings.items()
            if r.angle_rad is not None and r.fault is None
        }
        if not all(joint in angles for joint in kin.joints):
            return None
        with self._lock:
            kin.hold(angles)
            return kin.tool_matrix(kin.vector(angles))

    # ---- periodic work -----------------------------------------------------------------

    def step(self, now: float | None = None) -> list[str]:
        """cmd_vel timeout and one position-control step; returns the controller's messages."""
        with self._lock:
            now = self.clock() if now is None else now
            self._open_if_quiet(now)
            if not self._in_control:
                return []
            assert self._sink is not None
            if self._timeout.expired(now):
                moving = any(v != 0.0 for v in self._drive.values())
                self._timeouts += 1
                if moving:
                    log.warning(
                        "no cmd_vel for %.2f s: tracks stopped", self.settings.cmd_vel_timeout_s
                    )
                    self._send_drive(self.settings.drive_zero)
            messages: list[str] = []
            velocities: dict[str, float] = {}
            # A controller that raises halts its own motion with the reason; the loop, the
            # other controllers and the node go on (MoveIt Servo halts, it does not exit).
            if self._goal_channels:
                try:
                    velocities = self._controller.update(now)
                except Exception as err:
                    velocities = {}
                    self._controller.cancel()
                    self._controller_failed("joint goals", err)
                for channel in self._goal_channels:
                    velocities.setdefault(channel, 0.0)
                self._goal_channels = {
                    self._controller.channel_of(j) for j in self._controller.targets
                }
                messages += self._controller.pop_messages()
            if self._arm is not None and (self._arm_owned or self._arm.active):
                try:
                    arm_velocities = self._arm.update(now)
                except Exception as err:
                    arm_velocities = {}
                    self._arm.stop(self._controller_failed("arm", err))
                for channel in self._arm.channels:
                    velocities[channel] = arm_velocities.get(channel, 0.0)
                self._arm_owned = self._arm.active
                messages += self._arm.pop_messages()
            ends = self._arm.until if self._arm is not None and self._arm_owned else {}
            if velocities:
                if self._arm is not None and self._arm.timed_moves:
                    self._sink.set_ends(ends, self._arm.goals)  # type: ignore[attr-defined]
                self._sink.set_velocities(**velocities)
                # The controller's prediction integrates what the bridge sent (delay-aware).
                self._controller.note_sent(now, {**self._drive, **velocities}, ends)
            self._update_state()
            return messages

    def _controller_failed(self, what: str, err: Exception) -> str:
        """Log (throttled) that a controller raised and was stopped; returns the reason."""
        reason = f"the {what} controller failed ({type(err).__name__}: {err})"
        if self._throttle.allow(f"failed {what}"):
            log.error("%s: %s stopped, %s control goes on", reason, what, self.source, exc_info=err)
        return reason

    def halt(self, reason: str) -> list[str]:
        """Zero everything ROS moves and drop its goals, keeping control (the next command is
        obeyed); returns the channels zeroed. For a failure in the host's loop."""
        with self._lock:
            stopped = self._owned_channels() if self._in_control else []
            if stopped:
                assert self._sink is not None
                self._sink.set_velocities(**dict.fromkeys(stopped, 0.0))
                self._controller.note_sent(self.clock(), {})
            if self._in_control:
                self._release()
                self._update_state()
        if stopped:
            log.error("%s motion halted (%s): %s zeroed", self.source, reason, ", ".join(stopped))
        return stopped

    def _send_drive(self, drive: dict[str, float]) -> None:
        assert self._sink is not None
        self._drive = dict(drive)
        self._sink.set_velocities(**drive)

    # ---- state -------------------------------------------------------------------------

    @property
    def state(self) -> BridgeState:
        """Who may move the robot through the bridge now."""
        with self._lock:
            return self._state

    @property
    def link_gate(self) -> LinkGate:
        """Whether the link lets ROS drive now."""
        with self._lock:
            return self._gate

    @property
    def commanding(self) -> bool:
        """Whether ROS moves something now (tracks or a joint goal)."""
        return self.state is BridgeState.COMMANDING

    def status(self) -> BridgeStatus:
        """A snapshot for diagnostics."""
        with self._lock:
            return BridgeStatus(
                state=self._state,
                drive=dict(self._drive),
                goals_rad=self._controller.targets,
                cmd_vel_age_s=self._timeout.age(self.clock()),
                cmd_vel_count=self._cmd_vel_count,
                rejected_count=self._rejected,
                timeouts=self._timeouts,
                link_gate=self._gate,
                link_refused_count=self._link_refused,
                cmd_vel_timeout_s=self.settings.cmd_vel_timeout_s,
            )

    def _update_state(self) -> None:
        if self._state not in (BridgeState.LISTENING, BridgeState.COMMANDING):
            return
        arm = self._arm is not None and self._arm.active
        moving = any(v != 0.0 for v in self._drive.values()) or bool(self._goal_channels) or arm
        self._set_state(BridgeState.COMMANDING if moving else BridgeState.LISTENING)

    def _set_state(self, state: BridgeState) -> None:
        if state is self._state:
            return
        self._state = state
        if self.on_state_changed is not None:
            try:
                self.on_state_changed(state, STATE_TEXT[state])
            except Exception:
                log.exception("bridge state callback failed")


def _is_lost(state: LinkState) -> bool:
    return state in (LinkState.LOST, LinkState.CLOSED)

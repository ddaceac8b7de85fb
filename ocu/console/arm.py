"""The arm in the console (no Qt): Cartesian mode, jog keys, pose goals, stored poses.

The console model owns one `ArmConsole`; views subscribe to its `events` and call its methods
(the dock, the 3D view, the key map). Motion goes through `ocu.control.arm.ArmController`,
whose velocities the console model merges into the arm's channels as the `ARM` source: an
automatic source that yields at once to Space, a lost link and any operator input on an arm
channel; a move (a pose goal, a stored pose) also stops for any other operator motion input.

In Cartesian mode the driving keys jog tool0 (the key map's [cartesian] table): forward/back,
left/right, up/down and pitch, in the base, tool or camera frame, at the jog speeds (Shift:
the fine fraction of them). Release = stop. A pose goal (x, y, z, pitch, typed or picked in
the 3D view; an arm of six joints or more takes the whole orientation: roll, pitch, yaw) is
solved and its path checked first: the ghost shows it, Accept moves there.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

import numpy as np

from ocu.console.events import Event
from ocu.console.poses import PoseError, PoseStore
from ocu.control.arm import ArmController, ArmStatus
from ocu.kinematics.analytic import BRANCHES
from ocu.kinematics.arm import FRAMES, ArmError, ToolPose
from ocu.kinematics.chain import Vector
from ocu.kinematics.rpy import describe_pose
from ocu.model.tree import Matrix

JOG_AXES = ("x", "y", "z", "pitch")
# An arm of six joints or more: the whole pose, turned about the jog frame's x, y and z.
WHOLE_JOG_AXES = ("x", "y", "z", "roll", "pitch", "yaw")
SPEED_STEP = 1.5  # faster / slower keys multiply or divide the jog speeds by this


@dataclass(frozen=True)
class ArmGoal:
    """Where the arm is asked to go: shown as a ghost before Accept and while moving."""

    label: str
    joints: dict[str, float]
    pose: ToolPose
    duration_s: float
    accepted: bool = False


class ArmEvents:
    """What a view may subscribe to."""

    def __init__(self) -> None:
        self.mode_changed: Event[[bool]] = Event()
        self.frame_changed: Event[[str]] = Event()
        self.speed_changed: Event[[float, float]] = Event()
        self.status_changed: Event[[ArmStatus]] = Event()
        self.goal_changed: Event[[ArmGoal | None]] = Event()
        self.poses_changed: Event[[tuple[str, ...]]] = Event()
        # The jog's direction in the base frame (None: no jog), for the 3D view.
        self.jog_changed: Event[[Vector | None]] = Event()
        self.workspace_changed: Event[[bool]] = Event()
        self.message: Event[[str]] = Event()


class ArmHost(Protocol):
    """What the arm needs of the console model (it owns the channels)."""

    clock: Callable[[], float]
    fine_factor: float

    def arm_starting(self, *, move: bool) -> None:
        """The arm is about to command its channels."""

    def arm_output(self, velocities: Mapping[str, float]) -> None:
        """The arm's velocities now (empty: the arm commands nothing)."""

    @property
    def fine(self) -> bool:
        """Whether Shift is held."""


class ArmConsole:
    """The console's arm; see the module docstring."""

    # A part of the console model: the GUI reaches it under the model's lock (ocu.core.guard).
    guarded = True

    def __init__(
        self, controller: ArmController, host: ArmHost, poses_path: Path | None = None
    ) -> None:
        self.controller = controller
        self.kinematics = controller.kinematics
        self.settings = controller.settings
        self.host = host
        self.events = ArmEvents()
        limits = {
            joint: (float(self.kinematics.chain.lower[i]), float(self.kinematics.chain.upper[i]))
            for i, joint in enumerate(self.kinematics.joints)
        }
        self.poses = PoseStore(self.settings.poses, self.kinematics.joints, limits, poses_path)
        self._cartesian = False
        self._frame = FRAMES[0]
        self._linear = self.settings.linear_speed_m_s
        self._pitch = self.settings.pitch_speed_rad_s
        self._held: dict[str, tuple[str, int]] = {}
        self._goal: ArmGoal | None = None
        self._status = controller.status
        self._workspace = False
        self.elbow: str | None = None  # the branch pose goals ask for (None: nearest)

    # ---- state -------------------------------------------------------------------------

    @property
    def channels(self) -> tuple[str, ...]:
        """The arm's velocity channels."""
        return self.controller.channels

    @property
    def cartesian(self) -> bool:
        """Whether the driving keys jog tool0 (Cartesian mode)."""
        return self._cartesian

    @property
    def frame(self) -> str:
        """The jog frame: base, tool or camera."""
        return self._frame

    @property
    def frames(self) -> tuple[str, ...]:
        """The frames this robot can jog in."""
        return FRAMES if self.kinematics.camera_chain is not None else FRAMES[:2]

    @property
    def linear_speed_m_s(self) -> float:
        """Jog speed of tool0 (before Shift)."""
        return self._linear

    @property
    def pitch_speed_rad_s(self) -> float:
        """Jog pitch rate (before Shift)."""
        return self._pitch

    @property
    def held_keys(self) -> frozenset[str]:
        """Jog keys held now."""
        return frozenset(self._held)

    @property
    def goal(self) -> ArmGoal | None:
        """The goal shown: a preview, or the move under way."""
        return self._goal

    @property
    def status(self) -> ArmStatus:
        """What the arm does now and why it is slowed or stopped."""
        return self._status

    @property
    def show_workspace(self) -> bool:
        """Whether the 3D view draws the reachable workspace."""
        return self._workspace

    def tool_pose(self, now: float | None = None) -> ToolPose | None:
        """tool0 by the prediction (None before every arm joint has a reading)."""
        return self.controller.tool_pose(self.host.clock() if now is None else now)

    @property
    def whole_pose(self) -> bool:
        """Whether a pose goal may give the whole orientation (an arm of six joints or more)."""
        return self.kinematics.chain.dof >= 6

    def tool_matrix(self, now: float | None = None) -> Matrix | None:
        """tool0's whole pose (4x4 in the base frame) by the prediction (None: not known)."""
        try:
            current, _ = self.controller.estimate(self.host.clock() if now is None else now)
        except ArmError:
            return None
        return self.kinematics.tool_matrix(current)

    # ---- settings ----------------------------------------------------------------------

    def set_cartesian(self, on: bool) -> None:
        """Cartesian mode on or off; held keys of either kind are released."""
        if on == self._cartesian:
            return
        self._cartesian = on
        self.release_keys()
        self.events.mode_changed.emit(on)
        self.events.message.emit("Cartesian mode: the driving keys move the gripper" if on
                                  else "joint mode: keys move the joints")  # fmt: skip

    def toggle_cartesian(self) -> None:
        """Switch between joint and Cartesian mode."""
        self.set_cartesian(not self._cartesian)

    def set_frame(self, frame: str) -> None:
        """The jog frame."""
        if frame not in self.frames:
            raise ArmError(f"unknown jog frame {frame!r}; one of {', '.join(self.frames)}")
        if frame == self._frame:
            return
        self._frame = frame
        self.events.frame_changed.emit(frame)
        self._apply_jog()

    def cycle_frame(self) -> None:
        """The next jog frame."""
        frames = self.frames
        self.set_frame(frames[(frames.index(self._frame) + 1) % len(frames)])

    def set_speeds(self, linear_m_s: float | None = None, pitch_rad_s: float | None = None) -> None:
        """Jog speeds, bounded by the profile's maxima."""
        if linear_m_s is not None:
            if not math.isfinite(linear_m_s):
                raise ArmError("the jog speed must be a finite number")
            self._linear = min(max(linear_m_s, 0.0), self.settings.max_linear_speed_m_s)
        if pitch_rad_s is not None:
            if not math.isfinite(pitch_rad_s):
                raise ArmError("the pitch speed must be a finite number")
            self._pitch = min(max(pitch_rad_s, 0.0), self.settings.max_pitch_speed_rad_s)
        self.events.speed_changed.emit(self._linear, self._pitch)
        self._apply_jog()

    def faster(self) -> None:
        """Both jog speeds times 1.5 (up to the maxima)."""
        self.set_speeds(self._linear * SPEED_STEP, self._pitch * SPEED_STEP)

    def slower(self) -> None:
        """Both jog speeds divided by 1.5."""
        self.set_speeds(self._linear / SPEED_STEP, self._pitch / SPEED_STEP)

    def set_show_workspace(self, show: bool) -> None:
        """Draw the reachable workspace in the 3D view or not."""
        if show != self._workspace:
            self._workspace = show
            self.events.workspace_changed.emit(show)

    # ---- jog ---------------------------------------------------------------------------

    def jog_key_down(self, key: str, axis: str, direction: int) -> bool:
        """A jog key went down; False if it was held already (or moves what this arm cannot)."""
        if axis not in WHOLE_JOG_AXES or direction not in (-1, 1):
            raise ValueError(f"a jog key moves one of {WHOLE_JOG_AXES} by +1 or -1")
        if key in self._held:
            return False
        if axis not in self._axes:
            self.events.message.emit(
                f"{key}: {axis} needs an arm of six joints; this one jogs x, y, z and pitch"
            )
            return False
        self._held[key] = (axis, direction)
        self._apply_jog()
        return True

    def jog_key_up(self, key: str) -> bool:
        """A jog key went up: the jog follows the keys still held, or stops."""
        if self._held.pop(key, None) is None:
            return False
        self._apply_jog()
        return True

    def release_keys(self) -> bool:
        """Every jog key up (focus lost, mode changed); True if any was held."""
        if not self._held:
            return False
        self._held.clear()
        self._apply_jog()
        return True

    def refresh(self) -> None:
        """Shift went down or up: the jog follows at the new speed."""
        self._apply_jog()

    def twist(self) -> Vector:
        """The twist the held keys ask for, in the jog frame (m/s, rad/s)."""
        axes = self._axes
        twist = np.zeros(len(axes))
        for axis, direction in self._held.values():
            if axis in axes:
                twist[axes.index(axis)] += direction
        twist = np.clip(twist, -1.0, 1.0)
        for part in (slice(0, 3), slice(3, None)):
            norm = float(np.linalg.norm(twist[part]))
            if norm > 0.0:
                twist[part] /= norm  # diagonal keys move at the same speed, not √2 faster
        factor = self.host.fine_factor if self.host.fine else 1.0
        twist[:3] *= self._linear * factor
        twist[3:] *= self._pitch * factor  # the turning speed (the dock's "pitch" °/s)
        return twist

    @property
    def _axes(self) -> tuple[str, ...]:
        return WHOLE_JOG_AXES if self.whole_pose else JOG_AXES

    def _apply_jog(self) -> None:
        now = self.host.clock()
        twist = self.twist()
        if not np.any(twist):
            if self.controller.jogging:
                self.controller.jog(twist, self._frame, now)
                self.host.arm_output({})
                self._publish_status()
                self.events.jog_changed.emit(None)
            return
        if not self.controller.jogging:
            self.host.arm_starting(move=False)
            self._set_goal(None)
        self.controller.jog(twist, self._frame, now)
        self.events.jog_changed.emit(self._jog_direction(twist, now))
        self.step(now)

    def _jog_direction(self, twist: Vector, now: float) -> Vector:
        try:
            current, _ = self.controller.estimate(now)
        except ArmError:
            current = np.zeros(len(self.kinematics.joints))
        rotation = self.kinematics.frame_rotation(self._frame, current, self.controller.others(now))
        result: Vector = np.concatenate([rotation @ twist[:3], twist[3:]])
        return result

    # ---- goals -------------------------------------------------------------------------

    def preview_pose(self, target: ToolPose | Matrix, elbow: str | None = None) -> ArmGoal:
        """Solve a pose goal and check its path; the ghost shows it until Accept or Cancel.

        `target`: x, y, z and pitch (`ToolPose`), or for an arm of six joints or more the whole
        pose of tool0 (4x4 in the base frame: position and orientation).
        """
        if elbow is not None and elbow not in BRANCHES:
            raise ArmError(f"elbow must be one of {', '.join(BRANCHES)}")
        now = self.host.clock()
        try:
            _, start = self.controller.estimate(now)
        except ArmError:
            start = None
        if isinstance(target, ToolPose):
            q = self.kinematics.solve(target, elbow=elbow or self.elbow, current=start)
            label = target.describe()
        else:
            q = self.kinematics.solve_matrix(target, current=start)
            label = describe_pose(target)
        move = self.controller.plan_move(q, now)
        goal = ArmGoal(label, self.kinematics.mapping(q), self.kinematics.tool_pose(q),
                       move.duration_s)  # fmt: skip
        self._set_goal(goal)
        return goal

    def preview_named(self, name: str) -> ArmGoal:
        """Show a stored pose as the goal (its path checked)."""
        try:
            angles = self.poses.get(name)
        except PoseError as err:
            raise ArmError(str(err)) from err
        move = self.controller.plan_move(angles, self.host.clock())
        q = self.kinematics.vector(angles)
        goal = ArmGoal(name, angles, self.kinematics.tool_pose(q), move.duration_s)
        self._set_goal(goal)
        return goal

    def accept(self) -> ArmGoal:
        """Move to the goal shown (planned again from where the arm is now)."""
        goal = self._goal
        if goal is None:
            raise ArmError("no goal to accept: type one, pick one in the 3D view or choose a pose")
        if goal.accepted and self.controller.moving_to == goal.label:
            return goal
        return self._start(goal)

    def _start(self, goal: ArmGoal) -> ArmGoal:
        now = self.host.clock()
        # Planned again from where the arm is now: ArmError before anything changes.
        move = self.controller.plan_move(goal.joints, now)
        self.host.arm_starting(move=True)
        self.controller.start(move, now, goal.label)
        accepted = ArmGoal(goal.label, goal.joints, goal.pose, move.duration_s, accepted=True)
        self._set_goal(accepted)
        self.events.message.emit(f"arm: moving to {goal.label} ({move.duration_s:.1f} s)")
        self.step(now)
        return accepted

    def move_to_joints(self, label: str, joints: Mapping[str, float]) -> ArmGoal:
        """Move to a joint goal (every arm joint, rad) by the same synchronized move."""
        missing = [j for j in self.kinematics.joints if j not in joints]
        if missing:
            raise ArmError(f"the goal gives no angle for {', '.join(missing)}")
        angles = {j: float(joints[j]) for j in self.kinematics.joints}
        q = self.kinematics.vector(angles)
        return self._start(ArmGoal(label, angles, self.kinematics.tool_pose(q), 0.0))

    def go_to(self, name: str) -> ArmGoal:
        """Move to a stored pose at once (a key or a button)."""
        try:
            angles = self.poses.get(name)
        except PoseError as err:
            raise ArmError(str(err)) from err
        q = self.kinematics.vector(angles)
        return self._start(ArmGoal(name, angles, self.kinematics.tool_pose(q), 0.0))

    def cancel_goal(self) -> None:
        """Drop the goal shown; a move to it stops."""
        if self._goal is not None and self._goal.accepted and self.controller.moving_to:
            self.stop("cancelled")
        self._set_goal(None)

    def _set_goal(self, goal: ArmGoal | None) -> None:
        if goal != self._goal:
            self._goal = goal
            self.events.goal_changed.emit(goal)

    # ---- stored poses ------------------------------------------------------------------

    def save_pose(self, name: str) -> str:
        """Store where the arm is now under a name (the operator's file)."""
        try:
            _, eventual = self.controller.estimate(self.host.clock())
        except ArmError as err:
            raise PoseError(str(err)) from err
        kept = self.poses.save(name, self.kinematics.mapping(eventual))
        self.events.poses_changed.emit(self.poses.names)
        self.events.message.emit(f"arm: pose {kept!r} saved to {self.poses.path}")
        return kept

    def delete_pose(self, name: str) -> None:
        """Forget one of the operator's poses."""
        self.poses.delete(name)
        self.events.poses_changed.emit(self.poses.names)
        self.events.message.emit(f"arm: pose {name!r} deleted")

    # ---- stopping and stepping ---------------------------------------------------------

    def stop(self, reason: str) -> bool:
        """Every arm motion stops at once (the console zeroes the channels); jog keys stay
        held but do nothing until pressed again."""
        was = self.controller.stop(reason)
        self._held.clear()
        if self._goal is not None and self._goal.accepted:
            self._set_goal(None)
        self.events.jog_changed.emit(None)
        self._publish_status()
        self._drain()
        return was

    def step(self, now: float) -> None:
        """One control tick: the arm's velocities to the console."""
        active = self.controller.active
        output = self.controller.update(now)
        self.host.arm_output(output)
        if active and not self.controller.active:
            if self._goal is not None and self._goal.accepted:
                self._set_goal(None)
            if self._held and not self.controller.jogging:
                self._held.clear()
            self.events.jog_changed.emit(None)
        self._publish_status()
        self._drain()

    def _publish_status(self) -> None:
        status = self.controller.status
        if status != self._status:
            self._status = status
            self.events.status_changed.emit(status)

    def _drain(self) -> None:
        for message in self.controller.pop_messages():
            self.events.message.emit(message)

"""The arm in Cartesian space, streamed as joint velocities with feedback (no Qt).

Two kinds of motion, one at a time:

- **Jog**: a twist of tool0 (x, y, z velocity and pitch rate) in the base, tool or camera
  frame, from held keys or a planner (`/arm/twist_cmd`, which stops `twist_timeout_s` after
  its last message, as MoveIt Servo's incoming-command timeout). A reference pose moves along
  the commanded line; each tick the joint velocities are J⁺ (v + K (reference - estimate)),
  with the Jacobian and the estimate taken from the delay-aware prediction (the Smith
  predictor's eventual angles: what the joints will be once every command sent has landed), so
  the tool follows the line however late the readings are.
- **Move**: to a joint pose (a pose goal solved by IK, or a stored pose), all joints starting
  and arriving together on a synchronized trapezoidal profile (ocu.kinematics.trajectory),
  streamed as the profile's mean velocity over the tick horizon (the longest recent tick
  interval, with a margin: see ocu.control.position) plus K times the error to the profile's
  position, K at most one over the horizon, so a late tick carries no joint past the profile
  or the goal; a joint is never driven back against its move on the prediction alone (it
  stops until a reading taken after the stop shows it past); done when a reading taken after
  the last command confirms every joint within the tolerance. On hardware that takes a
  position command with a duration ("timed_moves") the move is ONE such command instead,
  nothing streamed on top (ocu.control.arm_timed).

Safety, after MoveIt Servo: a jog slows down when the Jacobian's condition number passes
`singularity_slow` and stops at `singularity_stop` — only while moving toward the singularity
(moving away is always allowed); it keeps `joint_limit_margin` from every limit (slowing over
the margin before it); and it slows down from `slow_distance_m` and stops at `clearance_m`
from the chassis, the ground and the arm itself, judged where the arm will be a delay ahead.
The reason shows in `status`. A move's whole path is checked before it starts and refused if it
comes closer than the clearance. Clearances are judged pair by pair: a pair already too close
(an arm left there by a stall) may only move apart, so the arm can always be moved out.

While the command sent drives the chassis the robot does not turn its `locked_while_driving`
joints (the waist; `PositionController.driving`): a move that needs them is refused, or
stopped if it is under way, and a jog does without them (its reference follows what the
other joints can do, so nothing swings once the chassis stops). `check_targets` gives the
position controller's typed targets the same checks.

Below a channel's starting speed a servo does not move: the controller then pulses at that
speed when the error asks for it, and the predictor (which models the deadband) keeps count.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from ocu.control.arm_task import Reference, TaskSpace, singularity_cause, task_for, task_rows
from ocu.control.arm_timed import arrival_tolerances, timed_command
from ocu.control.commands import VelocityLimits
from ocu.control.position import PositionController
from ocu.kinematics.arm import ArmError, ArmKinematics, ToolPose
from ocu.kinematics.chain import Vector
from ocu.kinematics.collision import Contact
from ocu.kinematics.numeric import damped_pseudo_inverse
from ocu.kinematics.trajectory import SyncMove, plan
from ocu.profile import RobotProfile
from ocu.records import JointReading

# Joint tolerance of a move's arrival: 0.1° on each of four joints keeps tool0 within a few
# millimetres at the Engineer's reach (the position controller's 0.3° would allow 7 mm).
MOVE_TOLERANCE_RAD = math.radians(0.1)
# Share of each channel's maximum a move plans with: the rest is room for the feedback.
MOVE_SPEED_SHARE = 0.95
# Damping of the Jacobian's pseudo-inverse (lengths in units of the arm's longest link).
JOG_DAMPING = 0.02
# A step along the motion this long (s) tells whether it approaches a singularity.
LOOKAHEAD_MIN_S = 0.15
# Path checks sample the move at least this finely (rad of the joint that moves most).
PATH_STEP_RAD = math.radians(1.0)
# A move from a pose where two parts already overlap stops if they overlap this much more than
# at its start (the estimate wanders a little about the checked path); others stop at contact.
OVERLAP_GROWTH_M = 0.001
# A jog without the locked joints (the chassis drives) that keeps less than this share of the
# twist shows why (slowed); below the second share it counts as stopped.
LOCKED_SHARE_SHOWN = 0.95
LOCKED_SHARE_STOP = 0.05
MAX_TICK_S = 0.2
OK, SLOW, STOP = "ok", "slow", "stop"


@dataclass(frozen=True)
class ArmStatus:
    """What the arm does now, and why it is slowed or stopped."""

    state: str = "idle"  # idle, jogging, moving, holding
    level: str = OK  # ok, slow, stop
    reason: str = ""
    scale: float = 1.0
    condition: float | None = None
    clearance_m: float | None = None
    goal: str = ""

    def describe(self) -> str:
        """One line for the status display."""
        if self.state == "idle":
            return "arm idle" + (f" — {self.reason}" if self.reason else "")
        head = {"jogging": "jogging", "moving": f"moving to {self.goal}", "holding": "arriving"}
        text = head.get(self.state, self.state)
        if self.level == SLOW:
            return f"{text}: slowed to {self.scale:.0%} — {self.reason}"
        if self.level == STOP:
            return f"{text}: STOPPED — {self.reason}"
        return text


@dataclass
class _Jog:
    # vx, vy, vz (m/s), then the pitch rate, or wx, wy, wz (rad/s), in `frame`
    twist: Vector
    frame: str
    expires_at: float | None
    task: TaskSpace
    reference: Reference | None = None  # where the tool should be, in the task space


@dataclass
class _Move:
    path: SyncMove
    started_at: float
    label: str
    goal_pose: ToolPose
    start_gaps: Vector  # every checked pair's gap where the move started


class ArmController:
    """Jogs and moves the arm through its joints' velocity channels; see the module docstring."""

    def __init__(
        self,
        profile: RobotProfile,
        limits: VelocityLimits,
        kinematics: ArmKinematics,
        position: PositionController,
        *,
        tolerance_rad: float = MOVE_TOLERANCE_RAD,
    ) -> None:
        self.profile = profile
        self.limits = limits
        self.kinematics = kinematics
        self.position = position
        self.settings = kinematics.settings
        self.tolerance_rad = tolerance_rad
        self.joints = kinematics.joints
        self.tolerances = arrival_tolerances(profile, self.joints, tolerance_rad)
        # Hardware that takes a position command with a duration ("timed_moves"): a move is
        # sent as one, its goals and end here while it runs (ocu.control.arm_timed).
        self.timed_moves = False
        self.goals: dict[str, float] = {}
        self.until: dict[str, float] = {}
        channels = []
        for joint in self.joints:
            channel = profile.motors[joint].channel
            if channel is None:
                raise ArmError(f"arm joint {joint!r} has no velocity channel")
            channels.append(channel)
        self.channels: tuple[str, ...] = tuple(channels)
        # Joints the robot does not turn while the chassis moves (the waist).
        self.locked_while_driving = np.array(
            [profile.channels[c].locked_while_driving for c in channels], dtype=bool
        )
        self._others: dict[str, float] = {}
        self._jog: _Jog | None = None
        self._move: _Move | None = None
        self._last_tick: float | None = None
        self._messages: list[str] = []
        self.status = ArmStatus()
        self._told = (OK, "")

    # ---- state -------------------------------------------------------------------------

    @property
    def active(self) -> bool:
        """Whether a jog or a move commands the arm."""
        return self._jog is not None or self._move is not None

    @property
    def moving_to(self) -> str | None:
        """The label of the move under way (None: no move)."""
        return self._move.label if self._move is not None else None

    @property
    def move_goal(self) -> dict[str, float] | None:
        """The joint goal of the move under way."""
        if self._move is None:
            return None
        return self.kinematics.mapping(self._move.path.goal)

    @property
    def move_plan(self) -> SyncMove | None:
        """The synchronized profile of the move under way (None: no move)."""
        return self._move.path if self._move is not None else None

    @property
    def jogging(self) -> bool:
        """Whether a jog commands the arm."""
        return self._jog is not None

    def observe(self, readings: Mapping[str, JointReading]) -> None:
        """Readings of the joints the arm does not command (flippers, gripper roll, head)."""
        for name, reading in readings.items():
            if name not in self.joints and reading.angle_rad is not None and reading.fault is None:
                self._others[name] = reading.angle_rad
        self.kinematics.hold(self._others)

    def others(self, now: float) -> dict[str, float]:
        """The other joints now: predicted where they are commanded, else the last reading."""
        values = dict(self._others)
        for name, angle in self.position.predicted_angles(now).items():
            if name not in self.joints:
                values[name] = angle
        return values

    def estimate(self, now: float) -> tuple[Vector, Vector]:
        """The arm's joints now and once every command sent has landed (the prediction).

        ArmError when a joint has no believable reading.
        """
        delay = self.position.delay_s or 0.0
        current, eventual = [], []
        for joint in self.joints:
            predictor = self.position.predictors[joint]
            fault = self.position.faults.get(joint)
            if fault is not None:
                raise ArmError(f"{joint}: its reading is implausible ({fault})")
            if not predictor.known:
                raise ArmError(f"no reading of the {joint} yet")
            current.append(predictor.current(now, delay))
            eventual.append(predictor.eventual(now))
        return np.array(current), np.array(eventual)

    def tool_pose(self, now: float) -> ToolPose | None:
        """Where tool0 is now by the prediction (None before every arm joint has a reading)."""
        try:
            current, _ = self.estimate(now)
        except ArmError:
            return None
        return self.kinematics.tool_pose(current)

    def pop_messages(self) -> list[str]:
        """What happened since the last call (arrived, stopped and why)."""
        messages, self._messages = self._messages, []
        return messages

    # ---- commands ----------------------------------------------------------------------

    def jog(
        self,
        twist: Sequence[float] | Vector,
        frame: str,
        now: float,
        *,
        expires_after_s: float | None = None,
    ) -> None:
        """Move tool0 at a twist in a frame; zero stops the jog. Four values: vx, vy, vz (m/s)
        and the pitch rate (rad/s); six, for an arm of six joints or more: vx, vy, vz and wx,
        wy, wz (rad/s about the frame's axes), the whole pose held (ocu.control.arm_task).

        With `expires_after_s` the jog stops by itself that long after the last call (a
        streamed command); without, it lasts until the next call (a held key).
        """
        values = np.asarray(twist, dtype=float)
        sizes = (4, 6) if self.kinematics.chain.dof >= 6 else (4,)
        if values.ndim != 1 or values.size not in sizes or not np.all(np.isfinite(values)):
            raise ArmError(
                "a twist is four finite numbers: vx, vy, vz (m/s), pitch rate (rad/s)"
                + ("; or six: vx, vy, vz, wx, wy, wz (rad/s)" if len(sizes) > 1 else "")
            )
        self.kinematics.frame_rotation(frame, np.zeros(len(self.joints)), self._others)
        if not np.any(values):
            if self._jog is not None:
                self._jog = None
                self._set_status(ArmStatus())
            return
        if self._move is not None:
            self._finish_move(f"arm: move to {self._move.label} cancelled by a jog")
        expires = None if expires_after_s is None else now + expires_after_s
        jog = self._jog
        if jog is not None and jog.frame == frame and jog.task.rows == task_rows(values.size):
            # Same frame and task: the reference pose carries on from where it is.
            jog.twist = values
            jog.expires_at = expires
        else:
            self._jog = _Jog(values, frame, expires, task_for(self.kinematics, values.size))

    def stop(self, reason: str = "") -> bool:
        """Stop every arm motion at once; True if something was moving."""
        was = self.active
        if self._move is not None:
            label = self._move.label
            self._move = None
            if reason:
                self._messages.append(f"arm: move to {label} stopped: {reason}")
        self._jog = None
        if was:
            self._set_status(ArmStatus(reason=reason))
        return was

    def plan_move(self, goal: Mapping[str, float] | Vector, now: float) -> SyncMove:
        """The synchronized move from where the arm is headed to a joint goal, its path checked.

        ArmError when a joint has no reading, the goal is off limits, or the path comes closer
        to the chassis (or the ground, or the arm itself) than the clearance.
        """
        if isinstance(goal, Mapping):
            missing = [j for j in self.joints if j not in goal]
            if missing:
                raise ArmError(f"the goal gives no angle for {', '.join(missing)}")
            target = self.kinematics.vector(goal)
        else:
            target = np.asarray(goal, dtype=float)
        if not np.all(np.isfinite(target)):
            raise ArmError("the goal must be finite")
        for i, joint in enumerate(self.joints):
            low, high = self.kinematics.chain.lower[i], self.kinematics.chain.upper[i]
            if not low - 1e-9 <= target[i] <= high + 1e-9:
                raise ArmError(
                    f"{joint}: {math.degrees(target[i]):.1f}° is outside its limits "
                    f"[{math.degrees(low):.1f}°, {math.degrees(high):.1f}°]"
                )
        _, start = self.estimate(now)
        speeds = np.array([self.limits.get(c) * MOVE_SPEED_SHARE for c in self.channels])
        if np.any(speeds <= 0.0):
            stopped = [j for j, s in zip(self.joints, speeds, strict=True) if s <= 0.0]
            raise ArmError(f"the maximum speed of {', '.join(stopped)} is zero")
        accel = np.full(len(self.joints), self.settings.acceleration_rad_s2)
        move = plan(start, target, speeds, accel)
        held = self._held_by_driving(move.delta)
        if held:
            raise ArmError(f"the chassis is driving: {held}; stop it first")
        travel = float(np.max(np.abs(move.delta))) if move.delta.size else 0.0
        count = max(2, math.ceil(travel / PATH_STEP_RAD) + 1)
        hit = self.kinematics.check_path(move.points(count), self.others(now))
        if hit is not None:
            raise ArmError(hit.describe(count))
        return move

    def check_targets(self, targets: Mapping[str, float], now: float) -> None:
        """Joint targets for the position controller (typed ones), checked as a move is.

        The position controller runs each joint on its own at its channel's maximum speed
        from where it is headed, so that is the path checked: ArmError when it breaks the
        clearance rule (the ground, the chassis, the arm itself), or turns a joint the robot
        locks while the chassis drives. Not checked before every arm joint has a reading (the
        model of the arm has no pose to start from; the position controller moves no joint
        without its own reading).
        """
        try:
            _, eventual = self.estimate(now)
        except ArmError:
            return
        start = {**self.others(now), **self.kinematics.mapping(eventual)}
        goal: dict[str, float] = {}
        speeds: dict[str, float] = {}
        channels = self.profile.channels
        for joint, angle in targets.items():
            motor = self.profile.motors.get(joint)
            if joint not in start or motor is None or motor.channel is None:
                continue
            travel = float(angle) - start[joint]
            if abs(travel) <= self.tolerance_rad:
                continue
            if self.position.driving and channels[motor.channel].locked_while_driving:
                raise ArmError(
                    f"the chassis is driving: the robot does not turn the {joint} while it "
                    "drives; stop it first"
                )
            speed = self.limits.get(motor.channel)
            if speed > 0.0:
                goal[joint], speeds[joint] = float(angle), speed
        if not goal:
            return
        duration = max(abs(goal[j] - start[j]) / speeds[j] for j in goal)
        count = max(2, math.ceil(duration * max(speeds.values()) / PATH_STEP_RAD) + 1)
        poses: list[Mapping[str, float]] = []
        for t in np.linspace(0.0, duration, count):
            pose = dict(start)
            for joint, angle in goal.items():
                travel = angle - start[joint]
                pose[joint] = start[joint] + math.copysign(
                    min(speeds[joint] * t, abs(travel)), travel
                )
            poses.append(pose)
        hit = self.kinematics.check_poses(poses)
        if hit is not None:
            raise ArmError(hit.describe(count))

    def _locked_now(self) -> npt.NDArray[np.bool_]:
        """The arm joints the robot refuses to turn now (the chassis drives)."""
        if self.position.driving:
            return self.locked_while_driving
        return np.zeros(len(self.joints), dtype=bool)

    def _held_by_driving(self, travel: Vector) -> str:
        """Why a travel cannot be made while the chassis drives ('' when it can)."""
        turning = [
            joint
            for joint, locked, delta in zip(self.joints, self._locked_now(), travel, strict=True)
            if locked and abs(delta) > self.tolerance_rad
        ]
        if not turning:
            return ""
        return f"the robot does not turn the {', '.join(turning)} while it drives"

    def move_to(self, goal: Mapping[str, float] | Vector, now: float, label: str) -> SyncMove:
        """Plan a synchronized move (see plan_move) and start it; stops any jog."""
        move = self.plan_move(goal, now)
        self.start(move, now, label)
        return move

    def start(self, move: SyncMove, now: float, label: str) -> None:
        """Start a move planned by plan_move just now; stops any jog."""
        self._jog = None
        gaps = self.kinematics.gaps(move.start, self.others(now))
        self._move = _Move(move, now, label, self.kinematics.tool_pose(move.goal), gaps)
        self._set_status(ArmStatus(state="moving", goal=label))

    # ---- the control step --------------------------------------------------------------

    def update(self, now: float) -> dict[str, float]:
        """Velocity per arm channel for this tick; empty when the arm is not commanded.

        A motion that ends in this step returns nothing: its channels must be zeroed.
        """
        last, self._last_tick = self._last_tick, now
        self.position.note_tick(now)
        self.goals, self.until = {}, {}
        dt = 0.0 if last is None else min(max(now - last, 0.0), MAX_TICK_S)
        jog = self._jog
        if jog is not None and jog.expires_at is not None and now > jog.expires_at:
            self._jog = None
            self._messages.append(
                f"arm: no twist for {self.settings.twist_timeout_s:g} s, jog stopped"
            )
            self._set_status(ArmStatus(reason="twist timed out"))
            return {}
        if not self.active:
            return {}
        stale = self._stale(now)
        if stale:
            self.stop(stale)
            return {}
        try:
            current, eventual = self.estimate(now)
        except ArmError as err:
            self.stop(str(err))
            return {}
        velocities: Vector | None
        if self._jog is not None:
            velocities = self._jog_step(self._jog, current, eventual, now, dt)
        else:
            assert self._move is not None
            velocities = self._move_step(self._move, eventual, now)
        if velocities is None:
            return {}
        return {c: self._servo(c, v) for c, v in zip(self.channels, velocities, strict=True)}

    def _stale(self, now: float) -> str:
        limit = self.position.stale_after_s
        for joint in self.joints:
            received = self.position.predictors[joint].last_received_at
            if received is not None and now - received > limit:
                return f"telemetry of the {joint} is {now - received:.1f} s old"
        return ""

    def _servo(self, channel: str, velocity: float) -> float:
        """Bounded by the channel's maximum; below its starting speed, a pulse or nothing."""
        velocity = self.limits.clamp(channel, velocity)
        floor = self.profile.channels[channel].min_speed
        if 0.0 < abs(velocity) < floor:
            return math.copysign(floor, velocity) if abs(velocity) >= floor / 2.0 else 0.0
        return velocity

    def _jog_step(
        self, jog: _Jog, current: Vector, eventual: Vector, now: float, dt: float
    ) -> Vector:
        kin, task = self.kinematics, jog.task
        actual = task.actual(eventual)
        if jog.reference is None:
            jog.reference = actual.copy()
        rotation = kin.frame_rotation(jog.frame, current, self.others(now))
        wanted = task.wanted(rotation, jog.twist)
        jac = task.jacobian(eventual)
        # While the chassis drives the robot does not turn the waist: the jog does without it
        # (its sideways part is left out), and the reference follows what the arm can do.
        locked = self._locked_now()
        jac[:, locked] = 0.0
        weights = task.weights()
        inverse = damped_pseudo_inverse(jac * weights[:, None], JOG_DAMPING) * weights[None, :]
        direction = inverse @ wanted
        scale, level, reason, condition, clearance = self._safety(eventual, direction, now)
        share = 1.0  # of the twist the arm can make without the locked joints
        if locked.any():
            possible = jac @ direction
            asked = float(np.linalg.norm(wanted * weights))
            if asked > 1e-12:
                share = float(np.linalg.norm(possible * weights)) / asked
            wanted = possible
        # Within each joint's maximum speed, keeping the direction.
        peak = 1.0
        for i, channel in enumerate(self.channels):
            need = abs(direction[i]) * scale
            if need > 1e-12:
                peak = min(peak, self.limits.get(channel) / need)
        if peak < 1.0 and level == OK:
            level, reason = SLOW, "a joint at its maximum speed"
        scale *= peak
        shown = scale
        if share < LOCKED_SHARE_SHOWN and level == OK:
            names = ", ".join(j for j, lock in zip(self.joints, locked, strict=True) if lock)
            level = STOP if share < LOCKED_SHARE_STOP else SLOW
            reason = f"the robot does not turn the {names} while the chassis drives"
            shown = share
        self._set_status(
            ArmStatus("jogging", level, reason, shown, condition, clearance), message=level == STOP
        )
        if scale <= 0.0:
            jog.reference = actual.copy()
            return np.zeros(len(self.joints))
        moving = wanted * scale
        jog.reference = task.advance(jog.reference, moving, dt)
        error = task.error(jog.reference, actual)
        gain = self.position.gain_per_s
        velocities: Vector = inverse @ (moving + gain * error)
        return velocities

    def _safety(
        self, q: Vector, direction: Vector, now: float
    ) -> tuple[float, str, str, float | None, float | None]:
        """The jog's speed factor (1 free, 0 stopped), its level and reason, the condition
        number and the clearance."""
        settings = self.settings
        kin = self.kinematics
        results: list[tuple[float, str]] = []
        norm = float(np.linalg.norm(direction))
        unit = direction / norm if norm > 1e-12 else direction
        # Singularity: judged along the motion, MoveIt Servo's way.
        condition = kin.condition(q)
        ahead = kin.condition(q + unit * 0.01)
        if ahead > condition:
            low, high = settings.singularity_slow, settings.singularity_stop
            cause = singularity_cause(self.kinematics, q)
            if condition >= high:
                results.append((0.0, f"{cause} (condition {condition:.0f} ≥ {high:g})"))
            elif condition > low:
                results.append(
                    ((high - condition) / (high - low), f"{cause} (condition {condition:.0f})")
                )
        # Joint limits: a margin kept, slowing over the margin before it.
        margin = settings.joint_limit_margin_rad
        for i, joint in enumerate(self.joints):
            if abs(direction[i]) < 1e-9:
                continue
            low, high = kin.chain.lower[i], kin.chain.upper[i]
            room = high - q[i] if direction[i] > 0 else q[i] - low
            limit = high if direction[i] > 0 else low
            text = f"{joint} near its limit of {math.degrees(limit):.0f}°"
            if room <= margin:
                results.append((0.0, text))
            elif room < 2.0 * margin and margin > 0.0:
                results.append(((room - margin) / margin, text))
        # Collisions, where the arm will be one delay (and a bit) ahead.
        # Each pair on its own: one already too close may move apart (the jog leaves it) while
        # every pair that comes closer slows and stops the jog.
        clearance: float | None = None
        others = self.others(now)
        gaps = kin.gaps(q, others)
        if gaps.size:
            clearance = float(np.min(gaps))
            lookahead = max(LOOKAHEAD_MIN_S, 2.0 * (self.position.delay_s or 0.0))
            peak = max(
                (abs(direction[i]) / max(self.limits.get(c), 1e-9)
                 for i, c in enumerate(self.channels)),
                default=1.0,
            )  # fmt: skip
            step = direction / max(peak, 1.0) * lookahead
            future = kin.gaps(q + step, others)
            closing = np.flatnonzero((future < gaps - 1e-5) & (future < settings.slow_distance_m))
            if closing.size:
                column = int(closing[np.argmin(future[closing])])
                results.append(
                    self._clearance_scale(kin.collision.pair_contact(column, float(future[column])))
                )
        if not results:
            return 1.0, OK, "", condition, clearance
        scale, reason = min(results, key=lambda item: item[0])
        scale = min(max(scale, 0.0), 1.0)
        return scale, (STOP if scale <= 0.0 else SLOW), reason, condition, clearance

    def _clearance_scale(self, contact: Contact) -> tuple[float, str]:
        settings = self.settings
        text = contact.describe()
        if contact.distance_m <= settings.clearance_m:
            return 0.0, f"would come too close: {text}"
        band = settings.slow_distance_m - settings.clearance_m
        if contact.distance_m < settings.slow_distance_m and band > 0.0:
            return (contact.distance_m - settings.clearance_m) / band, f"close: {text}"
        return 1.0, ""

    def _move_step(self, move: _Move, eventual: Vector, now: float) -> Vector | None:
        elapsed = now - move.started_at
        reference, _ = move.path.sample(elapsed)
        error = reference - eventual
        gain = self.position.gain_per_s
        held = self._held_by_driving(move.path.goal - eventual)
        if held:
            self._finish_move(f"arm: move to {move.label} stopped: the chassis drives, and {held}")
            return None
        # A pair that started clear stops the move at contact; one that started overlapping
        # (the move takes it apart) only if it overlaps more.
        gaps = self.kinematics.gaps(eventual, self.others(now))
        if gaps.size:
            floor = np.minimum(move.start_gaps, 0.0)
            floor[move.start_gaps < 0.0] -= OVERLAP_GROWTH_M
            deeper = np.flatnonzero(gaps < floor)
            if deeper.size:
                column = int(deeper[np.argmin(gaps[deeper])])
                contact = self.kinematics.collision.pair_contact(column, float(gaps[column]))
                self._finish_move(f"arm: move to {move.label} stopped: {contact.describe()}")
                return None
        # The command chosen now stays on the wire until the next tick, which may come late
        # (a busy caller): the feed-forward is the profile's mean speed over the tick horizon
        # and the feedback gain at most one over it, so the joints reach the profile's point
        # at the horizon's end and not past it, and not past the goal at the end of the move.
        horizon = self.position.tick_horizon_s
        ahead, _ = move.path.sample(elapsed + horizon)
        gain = min(gain, 1.0 / horizon)
        if elapsed < move.path.duration_s:
            if self.timed_moves:
                velocities, self.goals, self.until = timed_command(
                    move.path, move.started_at, self.channels
                )
                return velocities
            return self._no_reversal(move, (ahead - reference) / horizon + gain * error)
        # The profile has ended: hold the goal until a reading confirms it (a timed move's
        # goal is the robot's own: nothing is fed back on top).
        velocities = np.zeros(len(self.joints)) if self.timed_moves else gain * error
        velocities[np.abs(error) <= self.tolerances / 2.0] = 0.0
        velocities = self._no_reversal(move, velocities)
        self._set_status(ArmStatus("holding", goal=move.label))
        if np.all(np.abs(error) <= self.tolerances) and self._confirmed(now):
            pose = self.kinematics.tool_pose(eventual)
            off = float(np.linalg.norm(pose.position - move.goal_pose.position))
            self._finish_move(
                f"arm: reached {move.label} ({off * 1000:.1f} mm from the goal by the estimate)"
            )
            return None
        if elapsed > move.path.duration_s + self.position.settle_timeout_s:
            worst = int(np.argmax(np.abs(error)))
            self._finish_move(
                f"arm: stopped near {move.label} without a confirming reading "
                f"({self.joints[worst]} {math.degrees(error[worst]):+.2f}° by the estimate)"
            )
            return None
        return velocities

    def _no_reversal(self, move: _Move, velocities: Vector) -> Vector:
        """A joint is never driven back against its move on the prediction alone: it stops,
        and goes back only once a reading taken after its last change shows it past."""
        out = velocities.copy()
        for i, joint in enumerate(self.joints):
            if out[i] * move.path.delta[i] < 0.0 and not self.position.may_reverse(joint):
                out[i] = 0.0
        return out

    def _confirmed(self, now: float) -> bool:
        """Every joint's channel sends zero and has a reading taken after its last change."""
        for joint in self.joints:
            predictor = self.position.predictors[joint]
            if predictor.velocity(now) != 0.0 or predictor.last_taken_at is None:
                return False
            changed = predictor.last_change_at
            if changed is not None and predictor.last_taken_at < changed:
                return False
        return True

    def _finish_move(self, message: str) -> None:
        self._move = None
        self._messages.append(message)
        self._set_status(ArmStatus(reason=message.removeprefix("arm: ")))

    def _set_status(self, status: ArmStatus, *, message: bool = False) -> None:
        self.status = status
        # Told once per stop; a stop whose reason read the same while it only slowed (a
        # joint limit's) is told too.
        told = (status.level, status.reason)
        if message and status.reason and told != self._told:
            self._messages.append(f"arm: {status.describe()}")
        self._told = told if status.level != OK else (OK, "")

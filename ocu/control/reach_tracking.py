"""Seed 003's tracking (§2.2) with a camera on an arm's tool: base, height and reach, no Qt.

The seed's arm (the xArm 1S) carries the camera at its gripper, looking along the tool. Three
controllers keep a coloured object centred and at a constant distance: the horizontal image
error turns the base (the yaw joint), the vertical one moves the tool up or down (z, through
the pitch joints' inverse kinematics at a constant tool pitch), and the object's size in the
picture (the seed's area, a proxy for its distance) moves the tool in or out (the reach).

What the Engineer's tracking does against the delay (ocu.control.tracking) is done here too:

- Each frame becomes an absolute target: the object's position in the base frame, from the
  tool's pose when the frame was taken (the shafts then: below), the pixel offset and
  the distance the object's size gives (an assumed diameter: only the ratio matters for the
  base; z and the reach scale with it). The target tool pose is the one that sees the object
  centred at the distance it had when clicked: base yaw = the object's azimuth, reach and
  height = the object's, less that distance along the tool's pitch.
- The error is that target minus where the tool ends once every command sent has landed (a
  Smith predictor), so motion on its way is not asked for twice; the target's rate (a
  least-squares slope over RATE_WINDOW_S of frames) is fed forward and the target carried
  forward to when a command lands and the shaft has followed.
- The seed's servos are lightly damped second-order systems (ξ = 0.18, ωn = 5.83 rad/s): a
  target made from the predictor's angles (readings of ringing shafts) rings with them, and
  the loop feeds the ringing back. The angles a frame is placed with are therefore the
  shafts' when it was taken, modelled: the setpoints (integrated from the velocities sent)
  through the servo's model (`ShaftModel`); the error is the target minus those setpoints.
- The gains keep stable the loop their error goes through, behind the loop's dead time (the
  link's round trip if it reports one, a frame interval, half the link's move period): with
  the prediction, the setpoints' model (an integrator: the Engineer's rule, a 60° margin,
  Kp·T = 30°, at most KP_MAX); without it, the servo too: Kp·e^(-sT)·G(s)/s, where
  `loop_gain` takes the largest Kp with a 60° phase margin and a 2x gain margin at the
  resonance (about 1 /s for this servo whatever the delay up to 0.2 s).
- The pitch joints' velocities change at most ACCELERATION_RAD_S2 (a step rings the servos),
  scaled together (the direction of the motion kept); a step that would take the arm through
  the table or itself (the Arm dock's clearance) stops them, the base going on.

The baseline (`ReachOptions.baseline()`: the seed's plain PID) acts on the last frame's errors
with fixed gains: those that give the seed's 29.5° phase margin without delay (the margin its
§4.1 shows for its loop; it states no gains), no prediction and no feed-forward.
"""

from __future__ import annotations

import functools
import math
from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from ocu.control.tracking import (
    DERIVATIVE_S,
    INTEGRAL_TIME_CONSTANTS,
    AxisPid,
    Gains,
)
from ocu.kinematics.arm import ArmError, ArmKinematics, ToolPose

Vector = npt.NDArray[np.float64]
AXES = ("yaw", "height", "reach")
# Margins the adapted gains keep (module docstring) and the seed's own (§4.1).
PHASE_MARGIN_DEG = 60.0
GAIN_MARGIN = 2.0
SEED_PHASE_MARGIN_DEG = 29.5
KP_MAX = 4.0
KP_MIN = 0.05
# The frequencies the margins are checked at (rad/s).
_OMEGA = np.logspace(-2, 3, 1000)
DELAY_STEP_MS = 5
DELAY_STEP_S = DELAY_STEP_MS / 1000.0
# Dead time assumed while nothing is known of it (s).
UNKNOWN_DELAY_S = 0.5
# Finite-difference step of the Cartesian rates into joint velocities (s of motion).
STEP_S = 0.05
# The shaft model: its integration step, how far back it remembers, and the gap after which
# it starts again from the commanded positions.
SHAFT_STEP_S = 0.002
HISTORY_S = 2.0
MAX_GAP_S = 0.5
# How fast a joint's velocity may change (rad/s²), and the least control step assumed.
ACCELERATION_RAD_S2 = 3.0
MIN_STEP_S = 0.01
# The targets' rates: fitted over this long, once the frames span at least this.
RATE_WINDOW_S = 0.5
MIN_RATE_SPAN_S = 0.15


@dataclass(frozen=True)
class ServoModel:
    """A position servo's second-order response (None for an ideal one)."""

    damping_ratio: float
    natural_frequency_rad_s: float


def _loop(kp: float, dead_time_s: float, servo: ServoModel | None) -> npt.NDArray[np.complex128]:
    s = 1j * _OMEGA
    loop: npt.NDArray[np.complex128] = kp * np.exp(-s * dead_time_s) / s
    if servo is not None:
        wn, zeta = servo.natural_frequency_rad_s, servo.damping_ratio
        loop = loop * (wn * wn / (s * s + 2.0 * zeta * wn * s + wn * wn))
    return loop


def margins(kp: float, dead_time_s: float, servo: ServoModel | None) -> tuple[float, float]:
    """Phase margin (degrees) and gain margin (x) of Kp·e^(-sT)·G(s)/s."""
    loop = _loop(kp, dead_time_s, servo)
    magnitude = np.abs(loop)
    phase = np.unwrap(np.angle(loop))
    above = np.nonzero(magnitude >= 1.0)[0]
    phase_margin = math.inf if above.size == 0 else 180.0 + math.degrees(phase[above[-1]])
    under = np.nonzero(phase <= -math.pi)[0]
    gain_margin = math.inf if under.size == 0 else 1.0 / float(np.max(magnitude[under]))
    return phase_margin, gain_margin


@functools.lru_cache(maxsize=256)
def _loop_gain(
    dead_time_ms: int, servo: ServoModel | None, phase_margin_deg: float, gain_margin: float
) -> float:
    dead_time = dead_time_ms / 1000.0
    low, high = KP_MIN, KP_MAX
    for _ in range(24):  # to 0.1 %
        kp = math.sqrt(low * high)
        phase, gain = margins(kp, dead_time, servo)
        if phase >= phase_margin_deg and gain >= gain_margin:
            low = kp
        else:
            high = kp
    return low


def loop_gain(
    dead_time_s: float | None,
    servo: ServoModel | None,
    *,
    phase_margin_deg: float = PHASE_MARGIN_DEG,
    gain_margin: float = GAIN_MARGIN,
) -> float:
    """The largest Kp (1/s) keeping both margins behind this dead time (module docstring)."""
    delay = (
        UNKNOWN_DELAY_S if dead_time_s is None or not math.isfinite(dead_time_s) else dead_time_s
    )
    # In whole steps of DELAY_STEP_S (rounded up: the cautious side), so that a dead time
    # that wanders costs one computation per step, not one per control cycle.
    steps = math.ceil(max(delay, 0.0) / DELAY_STEP_S - 1e-9)
    return _loop_gain(steps * DELAY_STEP_MS, servo, phase_margin_deg, gain_margin)


def pid_gains(kp: float) -> Gains:
    """The Engineer's tracking's integral and derivative for a Kp (ocu.control.tracking)."""
    return Gains(kp, kp / (INTEGRAL_TIME_CONSTANTS / kp), kp * DERIVATIVE_S)


def seed_gains(servo: ServoModel | None) -> Gains:
    """The baseline's fixed gains: the seed's 29.5° phase margin at no delay (no gain margin
    asked: the seed states none)."""
    return pid_gains(loop_gain(0.0, servo, phase_margin_deg=SEED_PHASE_MARGIN_DEG, gain_margin=1.0))


class ShaftModel:
    """Where the servos' shafts are, from what they were told: each joint's commanded
    position (the Smith predictor's eventual angle) through the servo's second-order model,
    kept for the last HISTORY_S. A picture shows the shafts, not the setpoints: a lightly
    damped servo rings behind its setpoint by more than the object moves, and a target made
    from the setpoint would carry that ringing into the commands (and ring the arm more)."""

    def __init__(self, servo: ServoModel | None) -> None:
        self.servo = servo
        self._state: dict[str, tuple[float, float]] = {}
        self._at: float | None = None
        self._history: deque[tuple[float, dict[str, float]]] = deque()

    def advance(self, now: float, reference: Mapping[str, float]) -> None:
        """The shafts at `now`, the reference held since the last call."""
        at = self._at
        restart = at is None or now - at > MAX_GAP_S or set(reference) != set(self._state)
        if restart or self.servo is None:
            self._state = {joint: (angle, 0.0) for joint, angle in reference.items()}
        elif at is not None and now > at:
            wn, zeta = self.servo.natural_frequency_rad_s, self.servo.damping_ratio
            steps = max(1, math.ceil((now - at) / SHAFT_STEP_S))
            dt = (now - at) / steps
            state = {}
            for joint, (start, speed) in self._state.items():
                goal, position, velocity = reference[joint], start, speed
                for _ in range(steps):  # semi-implicit Euler, as the simulator integrates
                    velocity += (wn * wn * (goal - position) - 2.0 * zeta * wn * velocity) * dt
                    position += velocity * dt
                state[joint] = (position, velocity)
            self._state = state
        self._at = now
        self._history.append((now, {joint: p for joint, (p, _) in self._state.items()}))
        while self._history and self._history[0][0] < now - HISTORY_S:
            self._history.popleft()

    def angles_at(self, when: float) -> dict[str, float] | None:
        """The shafts at a past moment (interpolated); None outside the history."""
        history = self._history
        if not history or when < history[0][0] - SHAFT_STEP_S:
            return None
        for (t0, a0), (t1, a1) in zip(history, list(history)[1:], strict=False):
            if t0 <= when <= t1:
                w = 0.0 if t1 <= t0 else (when - t0) / (t1 - t0)
                return {joint: a0[joint] + w * (a1[joint] - a0[joint]) for joint in a0}
        return dict(history[-1][1]) if when >= history[-1][0] else dict(history[0][1])

    def reset(self) -> None:
        """Forget the shafts (tracking ends)."""
        self._state = {}
        self._at = None
        self._history.clear()


@dataclass(frozen=True)
class ReachOptions:
    """What acts (all; the baseline: the seed's plain PID on the last frame's errors)."""

    adapt_gains: bool = True
    feed_forward: bool = True
    predict: bool = True

    @classmethod
    def baseline(cls) -> ReachOptions:
        """Seed 003's plain PID: fixed gains, the last frame's errors."""
        return cls(adapt_gains=False, feed_forward=False, predict=False)


@dataclass(frozen=True)
class CameraModel:
    """The camera on the tool: its picture's size and focal lengths (pixels), and the
    object's assumed diameter (m)."""

    size_px: tuple[int, int]
    focal_px: tuple[float, float]
    object_diameter_m: float = 0.04


@dataclass(frozen=True)
class Cylinder:
    """The tool in the seed's coordinates: base yaw (rad), height and reach (m), pitch."""

    yaw: float
    height: float
    reach: float
    pitch: float

    @classmethod
    def of(cls, pose: ToolPose) -> Cylinder:
        """From a tool pose in the base frame (the yaw axis through the origin)."""
        return cls(math.atan2(pose.y, pose.x), pose.z, math.hypot(pose.x, pose.y), pose.pitch)

    def pose(self) -> ToolPose:
        """Back to a tool pose."""
        return ToolPose(
            self.reach * math.cos(self.yaw), self.reach * math.sin(self.yaw), self.height,
            self.pitch,
        )  # fmt: skip

    def value(self, axis: str) -> float:
        """One of AXES."""
        return float(getattr(self, axis))


class ReachController:
    """Targets from the object seen; joint velocities of the arm's joints that reach them."""

    def __init__(
        self,
        kinematics: ArmKinematics,
        camera: CameraModel,
        limits_rad_s: Mapping[str, float],
        *,
        servo: ServoModel | None = None,
        options: ReachOptions | None = None,
    ) -> None:
        self.kinematics = kinematics
        self.camera = camera
        self.limits = dict(limits_rad_s)
        self.servo = servo
        self.options = options or ReachOptions()
        # The PIDs act on image angles (yaw: rad; height and reach: m over the distance).
        self.pids = {axis: AxisPid(math.inf) for axis in AXES}
        self.distance_m: float | None = None  # held: the distance when clicked
        self.pitch: float | None = None  # held: the tool's pitch when clicked
        self.targets: dict[str, float] = {}
        self.offsets: dict[str, float] = {}
        self.rates: dict[str, float] = {}
        self.targets_at: float | None = None
        self.reason = ""  # why the arm cannot follow (out of reach), '' while it can
        self.gains = pid_gains(KP_MIN)
        self.shaft = ShaftModel(servo)
        self._servo_lag_s = (
            0.0 if servo is None else 2.0 * servo.damping_ratio / servo.natural_frequency_rad_s
        )
        self._seen: deque[tuple[float, dict[str, float]]] = deque()
        self._sent: dict[str, float] = {}
        self._setpoints: dict[str, float] = {}
        self._others: dict[str, float] = {}  # the joints not steered (the wrist roll, ...)
        self._dt = 0.0
        self._last_update: float | None = None

    def _cylinder(self, angles: Mapping[str, float]) -> tuple[Vector, Cylinder]:
        q = self.kinematics.vector(angles)
        return q, Cylinder.of(self.kinematics.tool_pose(q))

    def on_measurement(
        self,
        centre: tuple[float, float],
        size: float,
        taken_at: float,
        angles: Mapping[str, float],
    ) -> bool:
        """The object seen at `centre` (normalised), `size` wide (a fraction of the picture's
        width), in a frame taken when the joints stood at `angles`; False without them."""
        if self.options.predict:
            # The shafts when the picture was taken, from the commands through the servo.
            angles = self.shaft.angles_at(taken_at) or angles
        if any(joint not in angles for joint in self.kinematics.joints) or size <= 0.0:
            return False
        q = self.kinematics.vector(angles)
        pose = self.kinematics.tool_matrix(q)
        width, height = self.camera.size_px
        fx, fy = self.camera.focal_px
        distance = fx * self.camera.object_diameter_m / (size * width)
        if self.distance_m is None:
            self.distance_m = distance
            self.pitch = self.kinematics.pitch(pose)
        # The tool looks along its x axis; y is its left, z its up (ocu.profile.xarm_urdf).
        right = distance * (centre[0] - 0.5) * width / fx
        up = -distance * (centre[1] - 0.5) * height / fy
        rotation = pose[:3, :3]
        seen = pose[:3, 3] + rotation @ np.array([distance, -right, up])
        assert self.pitch is not None
        held = self.distance_m
        azimuth = math.atan2(float(seen[1]), float(seen[0]))
        targets = {
            "yaw": azimuth,
            "height": float(seen[2]) - held * math.sin(self.pitch),
            "reach": math.hypot(float(seen[0]), float(seen[1])) - held * math.cos(self.pitch),
        }
        now_cylinder = Cylinder.of(self.kinematics.tool_pose(q))
        self.offsets = {axis: targets[axis] - now_cylinder.value(axis) for axis in AXES}
        self.offsets["yaw"] = math.remainder(self.offsets["yaw"], math.tau)
        self._seen.append((taken_at, targets))
        while self._seen and self._seen[0][0] < taken_at - RATE_WINDOW_S:
            self._seen.popleft()
        self.rates = self._slopes()
        self.targets, self.targets_at = targets, taken_at
        return True

    def _slopes(self) -> dict[str, float]:
        """Each target's rate: the least-squares slope over the last RATE_WINDOW_S (a frame's
        target carries the picture's noise; differences of two would feed it forward)."""
        seen = self._seen
        if len(seen) < 3 or seen[-1][0] - seen[0][0] < MIN_RATE_SPAN_S:
            return {}
        times = np.array([t for t, _ in seen]) - seen[-1][0]
        times = times - times.mean()
        spread = float(times @ times)
        rates = {}
        for axis in AXES:
            values = np.array([targets[axis] for _, targets in seen])
            if axis == "yaw":
                values = seen[-1][1][axis] + np.remainder(
                    values - seen[-1][1][axis] + math.pi, math.tau
                ) - math.pi  # fmt: skip
            rates[axis] = float(times @ (values - values.mean())) / spread
        return rates

    def update(
        self, now: float, eventual: Mapping[str, float], dead_time_s: float | None
    ) -> dict[str, float]:
        """The arm joints' velocities now (rad/s); empty without a target."""
        dt = 0.0 if self._last_update is None else max(0.0, now - self._last_update)
        self._last_update = now
        self._dt = dt
        if not self.targets or self.distance_m is None or self.pitch is None:
            return {}
        if any(joint not in eventual for joint in self.kinematics.joints):
            return {}
        self._others = {j: a for j, a in eventual.items() if j not in self.kinematics.joints}
        options = self.options
        if options.predict:
            # The board's setpoints: where tracking started, plus every velocity it sent
            # (what the link makes of them: ramps at those velocities). The readings are the
            # shafts, ringing about the setpoints: they are left to the pictures.
            if not self._setpoints:
                self._setpoints = {joint: eventual[joint] for joint in self.kinematics.joints}
            else:
                for joint, velocity in self._sent.items():
                    self._setpoints[joint] += velocity * dt
            eventual = self._setpoints
            self.shaft.advance(now, self._setpoints)
        # The gains keep stable the loop their error goes through: with the prediction, the
        # setpoints' model (an integrator) behind the dead time, the servo's dynamics being in
        # the shaft model (the Engineer's rule); without it, the servo too (`loop_gain`).
        if not options.adapt_gains:
            kp = seed_gains(self.servo).kp
        elif options.predict:
            kp = loop_gain(dead_time_s, None)
        else:
            kp = loop_gain(dead_time_s, self.servo)
        self.gains = pid_gains(kp)
        q, current = self._cylinder(eventual)
        age = 0.0 if self.targets_at is None else max(0.0, now - self.targets_at)
        # A command lands half a dead time from now, and a servo's shaft follows a ramp of its
        # setpoint 2ξ/ωn behind: aim the setpoints where the target will be by then.
        lead = age + (dead_time_s or 0.0) / 2.0 + self._servo_lag_s
        scale = {"yaw": 1.0, "height": self.distance_m, "reach": self.distance_m}
        rates: dict[str, float] = {}
        for axis in AXES:
            rate = self.rates.get(axis, 0.0) if options.feed_forward else 0.0
            if options.predict:
                error = self.targets[axis] + rate * lead - current.value(axis)
                if axis == "yaw":
                    error = math.remainder(error, math.tau)
            else:
                error = self.offsets.get(axis, 0.0)
            output = self.pids[axis].update(
                error / scale[axis], dt, self.gains, feed_forward=rate / scale[axis]
            )
            rates[axis] = output * scale[axis]
        return self._joint_velocities(q, current, rates)

    def _joint_velocities(
        self, q: Vector, current: Cylinder, rates: Mapping[str, float]
    ) -> dict[str, float]:
        """The Cartesian rates (and the held pitch) through the seed's IK, one step ahead."""
        assert self.pitch is not None
        # The pitch the tool had when clicked is kept: a drift is brought back over 0.2 s.
        pitch_rate = (self.pitch - current.pitch) / (4 * STEP_S)
        ahead = Cylinder(
            current.yaw + rates["yaw"] * STEP_S,
            current.height + rates["height"] * STEP_S,
            current.reach + rates["reach"] * STEP_S,
            current.pitch + pitch_rate * STEP_S,
        )
        joints = self.kinematics.joints
        try:
            solved = self.kinematics.solve(ahead.pose(), current=q)
            # The arm's own clearance from itself and the table (the Arm dock's checks).
            hit = self.kinematics.check_path([q, solved], self._others)
            if hit is not None:
                raise ArmError(hit.describe(2))
        except ArmError as err:
            # Out of reach or too close: the pitch joints stop at once; the base alone still
            # follows the object around.
            self.reason = str(err)
            stopped = dict.fromkeys(joints[1:], 0.0)
            base = self._bounded({joints[0]: rates["yaw"]} | stopped)[joints[0]]
            return {joints[0]: base} | stopped
        self.reason = ""
        velocities = {joint: float(solved[i] - q[i]) / STEP_S for i, joint in enumerate(joints)}
        return self._bounded(velocities)

    def _bounded(self, velocities: Mapping[str, float]) -> dict[str, float]:
        """Each joint within its limit, and its change within ACCELERATION_RAD_S2 (a step of
        velocity rings the lightly damped servos); the pitch joints together (the direction
        of the height, reach and pitch motion is kept), the base on its own."""
        base = self.kinematics.joints[0]
        step = ACCELERATION_RAD_S2 * max(self._dt, MIN_STEP_S)
        bounded: dict[str, float] = {}
        for group in ([base], [j for j in velocities if j != base]):
            factor = 1.0
            for joint in group:
                velocity, limit = velocities[joint], self.limits.get(joint, math.inf)
                if abs(velocity) > limit > 0.0:
                    factor = min(factor, limit / abs(velocity))
            last = {joint: self._sent.get(joint, 0.0) for joint in group}
            change = {joint: velocities[joint] * factor - last[joint] for joint in group}
            largest = max((abs(value) for value in change.values()), default=0.0)
            share = 1.0 if largest <= step else step / largest
            bounded.update({joint: last[joint] + share * change[joint] for joint in group})
        self._sent = dict(bounded)
        return bounded

    def stop(self) -> None:
        """No target any more (the object lost, the operator took over); the click's
        distance and pitch are kept for the same object."""
        self.targets = {}
        self.targets_at = None
        self.rates = {}
        self.offsets = {}
        for pid in self.pids.values():
            pid.reset()
        self.shaft.reset()
        self._seen.clear()
        self._sent = {}
        self._setpoints = {}
        self._last_update = None

"""Keep a tracked object centred in a camera by turning two joints (seed 003 §2.2), no Qt.

One PID per axis, like the paper's x and z controllers: the horizontal image error drives the
pan joint (the waist), the vertical one the tilt joint (the neck). What is new here is the
delay, which the paper could only answer by lowering the proportional gain (§4):

- The error is an angle: the object's offset from the image centre through the camera's focal
  length (atan(dx / fx)), so the gains mean the same at any resolution.
- The image is old when it arrives (capture, encoding, the link). The error it shows is turned
  into an absolute target — the joint's angle when the frame was taken plus the offset — and
  the controller acts on that target minus where the joint will end once every command sent
  so far has landed (the Smith predictor of ocu.control.position). So motion already on its
  way is not commanded twice, and between frames the error shrinks as commands are sent.
- A moving object (or the chassis turning under the camera) moves the target: its rate is
  estimated from successive frames and fed forward, and the target is carried forward from
  the frame's moment to now (the paper's future work: feed-forward with the feedback).
- What the prediction cannot know is left to the gains, adapted to the measured delay: the
  loop is an integrator (velocity in, angle out) behind a dead time T, whose phase margin is
  90° - Kp·T; Kp = min(KP_MAX, PHASE_BUDGET_RAD / T) keeps it at 60° or more whatever T is.
  60°, not the textbook 45°: the camera sits on the head, about a metre ahead of the waist, so
  turning the waist by δ moves a near object by (1 + lever/distance)·δ in the image (parallax);
  the loop's gain is that much higher than the controller believes (1.6x for an object 1.6 m
  from the head), which eats 45° but leaves 60° stable (bench/bench_tracking.py).
  The integral gain follows Kp and integrates only near the target (no windup on the way);
  the derivative acts on the error, filtered.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

KP_MAX = 4.0  # 1/s: a 0.1 rad error asks for 0.4 rad/s
# Phase the dead time may take at the crossover: pi/6 leaves a 60° margin (parallax: above).
PHASE_BUDGET_RAD = math.pi / 6
# Integral time in units of the closed loop's time constant (1/Kp).
INTEGRAL_TIME_CONSTANTS = 8.0
DERIVATIVE_S = 0.02
DERIVATIVE_FILTER = 0.3  # weight of the newest derivative sample
MIN_DELAY_S = 0.02
# Errors smaller than this are left alone (pixels jitter; the servo has a deadband).
DEADBAND_RAD = math.radians(0.3)
# The integral only acts within this error (it removes what is left, not the approach).
INTEGRAL_ZONE_RAD = math.radians(3.0)
# Weight of the newest frame in the target's rate; frames closer than this give no rate.
RATE_FILTER = 0.3
MIN_RATE_INTERVAL_S = 0.02


@dataclass(frozen=True)
class Gains:
    """PID gains of one axis: velocity (rad/s) per radian of error."""

    kp: float
    ki: float
    kd: float


def gains_for_delay(delay_s: float | None) -> Gains:
    """Gains that keep a 60° phase margin behind a dead time of `delay_s` (round trip plus
    the video's own age); the most cautious gains when it is unknown."""
    delay = max(delay_s if delay_s is not None and math.isfinite(delay_s) else 0.5, MIN_DELAY_S)
    kp = min(KP_MAX, PHASE_BUDGET_RAD / delay)
    ki = kp / (INTEGRAL_TIME_CONSTANTS / kp)
    return Gains(kp, ki, kp * DERIVATIVE_S)


class AxisPid:
    """One axis: PID on an angle error with anti-windup (the integral stops at the limit)."""

    def __init__(self, limit_rad_s: float) -> None:
        self.limit_rad_s = limit_rad_s
        self._integral = 0.0
        self._last_error: float | None = None
        self._derivative = 0.0

    def reset(self) -> None:
        """Forget the integral and the last error (a new target, or control given back)."""
        self._integral = 0.0
        self._last_error = None
        self._derivative = 0.0

    def update(
        self, error_rad: float, dt_s: float, gains: Gains, feed_forward: float = 0.0
    ) -> float:
        """The velocity (rad/s) for this error, on top of a feed-forward velocity."""
        if abs(error_rad) < DEADBAND_RAD:
            error_rad = 0.0
        if self._last_error is not None and dt_s > 0:
            sample = (error_rad - self._last_error) / dt_s
            self._derivative += DERIVATIVE_FILTER * (sample - self._derivative)
        self._last_error = error_rad
        if abs(error_rad) > INTEGRAL_ZONE_RAD:
            self._integral = 0.0
        candidate = self._integral + error_rad * dt_s
        output = (
            feed_forward + gains.kp * error_rad + gains.ki * candidate + gains.kd * self._derivative
        )
        if abs(output) <= self.limit_rad_s:
            self._integral = candidate  # no windup while saturated
        else:
            output = math.copysign(self.limit_rad_s, output)
        return output


@dataclass(frozen=True)
class CameraAxes:
    """How a camera sees: which joints pan and tilt it, its focal lengths, and the signs.

    `pan_sign` is the direction (+1 or -1) of the pan joint that turns the camera towards an
    object right of the image centre; `tilt_sign` the tilt joint's towards one below it.
    """

    pan_joint: str
    tilt_joint: str
    focal_px: tuple[float, float]
    size_px: tuple[int, int]
    pan_sign: float = -1.0  # + waist is to the left: an object on the right wants -
    tilt_sign: float = -1.0  # + neck is up: an object below the centre wants -


@dataclass(frozen=True)
class TrackingOptions:
    """Which parts of the controller act (all of them; the baseline of the benchmark is the
    paper's PID: fixed gains tuned for no delay, acting on the last frame's image error).

    `adapt_gains`: the gains follow the delay (off: the no-delay gains); `feed_forward`: the
    target's rate is fed forward and the target carried to when the command lands;
    `predict`: the error is the target minus where the joint will end (Smith predictor; off:
    the offset the last frame showed).
    """

    adapt_gains: bool = True
    feed_forward: bool = True
    predict: bool = True

    @classmethod
    def baseline(cls) -> TrackingOptions:
        """The paper's PID on the image error, gains for no delay."""
        return cls(adapt_gains=False, feed_forward=False, predict=False)


class TrackingController:
    """Angle targets from tracked image positions; joint velocities that reach them."""

    def __init__(
        self,
        axes: CameraAxes,
        limits_rad_s: tuple[float, float],
        options: TrackingOptions | None = None,
    ) -> None:
        self.axes = axes
        self.options = options or TrackingOptions()
        # The offset (rad) of the object from the image centre in the last frame, per joint.
        self.offsets: dict[str, float] = {}
        self.pan = AxisPid(limits_rad_s[0])
        self.tilt = AxisPid(limits_rad_s[1])
        self.targets: dict[str, float] = {}
        # When the targets were seen, and how fast they move (rad/s).
        self.targets_at: float | None = None
        self.rates: dict[str, float] = {}
        self._last_update: float | None = None

    def image_error_rad(self, centre: tuple[float, float]) -> tuple[float, float]:
        """Pan and tilt angles (rad) from the image centre to a normalised point."""
        width, height = self.axes.size_px
        fx, fy = self.axes.focal_px
        dx = (centre[0] - 0.5) * width
        dy = (centre[1] - 0.5) * height
        return math.atan2(dx, fx), math.atan2(dy, fy)

    def on_measurement(
        self, centre: tuple[float, float], taken_at: float, angles: Mapping[str, float]
    ) -> bool:
        """The object seen at `centre` (normalised) in a frame taken at `taken_at`, when the
        joints stood at `angles` (the prediction's angle at that moment); False when the
        two joints' angles are not known."""
        pan_joint, tilt_joint = self.axes.pan_joint, self.axes.tilt_joint
        if pan_joint not in angles or tilt_joint not in angles:
            return False
        pan_off, tilt_off = self.image_error_rad(centre)
        self.offsets = {
            pan_joint: self.axes.pan_sign * pan_off,
            tilt_joint: self.axes.tilt_sign * tilt_off,
        }
        targets = {joint: angles[joint] + offset for joint, offset in self.offsets.items()}
        previous, previous_at = self.targets, self.targets_at
        if previous and previous_at is not None and taken_at - previous_at >= MIN_RATE_INTERVAL_S:
            for joint, target in targets.items():
                sample = (target - previous[joint]) / (taken_at - previous_at)
                old = self.rates.get(joint, sample)
                self.rates[joint] = old + RATE_FILTER * (sample - old)
        self.targets, self.targets_at = targets, taken_at
        return True

    def update(
        self, now: float, eventual: Mapping[str, float], delay_s: float | None
    ) -> dict[str, float]:
        """Velocities of the two joints now; empty without a target.

        `eventual` is where each joint ends once every command sent so far has landed (the
        Smith predictor's b + I(now)): commands in flight are not sent twice.
        """
        dt = 0.0 if self._last_update is None else max(0.0, now - self._last_update)
        self._last_update = now
        if not self.targets:
            return {}
        options = self.options
        gains = gains_for_delay(delay_s if options.adapt_gains else 0.0)
        age = 0.0 if self.targets_at is None else max(0.0, now - self.targets_at)
        # A command lands half a round trip from now: aim where the target will be then.
        lead = age + (delay_s or 0.0) / 2.0
        velocities = {}
        for joint, pid in ((self.axes.pan_joint, self.pan), (self.axes.tilt_joint, self.tilt)):
            current = eventual.get(joint)
            target = self.targets.get(joint)
            if current is None or target is None:
                continue
            rate = max(-pid.limit_rad_s, min(pid.limit_rad_s, self.rates.get(joint, 0.0)))
            if not options.feed_forward:
                rate = 0.0
            if options.predict:
                # The target where it will be when this command lands, not where the frame
                # saw it, minus where the joint will be by then.
                error = target + rate * lead - current
            else:
                error = self.offsets.get(joint, 0.0)
            velocities[joint] = pid.update(error, dt, gains, feed_forward=rate)
        return velocities

    def stop(self) -> None:
        """No target any more (the object was lost, or the operator took over)."""
        self.targets = {}
        self.targets_at = None
        self.rates = {}
        self.offsets = {}
        self.pan.reset()
        self.tilt.reset()
        self._last_update = None

"""Today's controller before the field-control issue, kept verbatim as a benchmark baseline.

It predicts between telemetry packets by integrating what it commanded, and resets the
prediction to each reading as it arrives: a reading that is already one delay old, with the
commands still in flight forgotten (issue 15). Only bench/bench_position.py uses it, with
the paper's constant-speed controller (`ConstantSpeedController`, the other baseline).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

from ocu.control.commands import VelocityLimits
from ocu.control.position import JointPredictor, PositionController, PositionError
from ocu.control.position import _Track as _PositionTrack
from ocu.profile import Motor, RobotProfile
from ocu.records import JointReading

DEFAULT_GAIN_PER_S = 10.0
DEFAULT_TOLERANCE_RAD = math.radians(0.3)
STALE_PERIODS = 2.5
STALL_MIN_COMMANDED_RAD = math.radians(2.0)
STALL_FRACTION = 0.25
STALL_PACKETS = 2
LIMIT_MARGIN_RAD = math.radians(0.5)
DEFAULT_PERIOD_S = 0.05


@dataclass
class _Track:
    """What the controller knows about one joint under control."""

    motor: Motor
    target_rad: float
    estimate_rad: float | None = None
    estimate_at: float | None = None
    last_measured_rad: float | None = None
    last_measured_at: float | None = None
    commanded_since_packet_rad: float = 0.0
    velocity_rad_s: float = 0.0
    stall_packets: int = 0
    started_at: float | None = None


class ResetPredictionController:
    """Drives several joints to target angles at once with proportional, predicted control."""

    def __init__(
        self,
        profile: RobotProfile,
        limits: VelocityLimits,
        *,
        gain_per_s: float = DEFAULT_GAIN_PER_S,
        tolerance_rad: float = DEFAULT_TOLERANCE_RAD,
        stale_after_s: float | None = None,
    ) -> None:
        self.profile = profile
        self.limits = limits
        self.gain_per_s = gain_per_s
        self.tolerance_rad = tolerance_rad
        self.stale_after_s = (
            STALE_PERIODS / profile.link.telemetry_rate_hz
            if stale_after_s is None
            else stale_after_s
        )
        self._tracks: dict[str, _Track] = {}
        self._latest: dict[str, tuple[float, float]] = {}
        self._messages: list[str] = []
        self._last_update_at: float | None = None
        self._period_s = DEFAULT_PERIOD_S

    # ---- targets ---------------------------------------------------------------------------

    def set_target(self, joint: str, angle_rad: float) -> None:
        """Start moving a joint to an angle; PositionError if it cannot be controlled."""
        motor = self.profile.motors.get(joint)
        if motor is None or motor.channel is None:
            raise PositionError(f"{joint}: not a joint driven by a velocity channel")
        if motor.limits_rad is None:
            raise PositionError(f"{joint}: has no position feedback")
        if not math.isfinite(angle_rad):
            raise PositionError(f"{joint}: target must be a finite number")
        low, high = motor.limits_rad
        if not low <= angle_rad <= high:
            raise PositionError(
                f"{joint}: target {math.degrees(angle_rad):.1f}° outside the limits "
                f"[{math.degrees(low):.1f}°, {math.degrees(high):.1f}°]"
            )
        track = _Track(motor=motor, target_rad=angle_rad)
        latest = self._latest.get(joint)
        if latest is not None:
            track.estimate_rad, track.estimate_at = latest
            track.last_measured_rad, track.last_measured_at = latest
        self._tracks[joint] = track

    def cancel(self, joint: str | None = None) -> None:
        """Drop one target (a manual command took the joint back) or all of them."""
        if joint is None:
            self._tracks.clear()
        else:
            self._tracks.pop(joint, None)

    @property
    def targets(self) -> dict[str, float]:
        """Joint name to target angle for every joint under control."""
        return {name: track.target_rad for name, track in self._tracks.items()}

    def channel_of(self, joint: str) -> str:
        """The velocity channel that drives a joint."""
        channel = self.profile.motors[joint].channel
        assert channel is not None
        return channel

    def predicted_angle(self, joint: str) -> float | None:
        """The controller's current estimate of a joint's angle (None before telemetry)."""
        track = self._tracks.get(joint)
        return None if track is None else track.estimate_rad

    def pop_messages(self) -> list[str]:
        """Why joints stopped since the last call (reached, stale, stalled, at limit)."""
        messages, self._messages = self._messages, []
        return messages

    # ---- inputs ----------------------------------------------------------------------------

    def note_sent(self, now: float, velocities: Mapping[str, float]) -> None:
        """Not used: this controller integrates only its own outputs."""

    def on_telemetry(
        self,
        readings: Mapping[str, JointReading],
        received_at: float,
        delay_s: float | None = None,
    ) -> None:
        """Correct the prediction of every joint from a telemetry packet."""
        for name, reading in readings.items():
            if reading.angle_rad is None:
                continue
            self._latest[name] = (reading.angle_rad, received_at)
            track = self._tracks.get(name)
            if track is None:
                continue
            self._check_motion(name, track, reading.angle_rad)
            track.last_measured_rad = reading.angle_rad
            track.last_measured_at = received_at
            track.commanded_since_packet_rad = 0.0
            # The measurement replaces the prediction; the velocity commanded since it was
            # taken is integrated again by the next update().
            track.estimate_rad = reading.angle_rad
            track.estimate_at = received_at
            # Only a measurement ends control: a prediction that says "there" keeps the
            # joint still until the next packet confirms it or asks for a correction.
            if abs(track.target_rad - reading.angle_rad) <= self.tolerance_rad:
                self._finish(name, f"{name}: reached {math.degrees(track.target_rad):.1f}°")

    def _check_motion(self, name: str, track: _Track, measured_rad: float) -> None:
        if track.last_measured_rad is None:
            return
        commanded = track.commanded_since_packet_rad
        moved = measured_rad - track.last_measured_rad
        if abs(commanded) >= STALL_MIN_COMMANDED_RAD and (
            moved * commanded <= 0 or abs(moved) < STALL_FRACTION * abs(commanded)
        ):
            track.stall_packets += 1
            if track.stall_packets >= STALL_PACKETS:
                self._finish(
                    name,
                    f"{name}: stopped, does not move as commanded "
                    f"({math.degrees(moved):+.1f}° for {math.degrees(commanded):+.1f}°)",
                )
        else:
            track.stall_packets = 0

    # ---- output ----------------------------------------------------------------------------

    def update(self, now: float) -> dict[str, float]:
        """Velocity per channel (rad/s) for every joint under control, at time now."""
        if self._last_update_at is not None and now > self._last_update_at:
            self._period_s = now - self._last_update_at
        self._last_update_at = now
        output: dict[str, float] = {}
        for name, track in list(self._tracks.items()):
            channel = self.channel_of(name)
            if track.estimate_rad is None or track.estimate_at is None:
                if track.started_at is None:
                    track.started_at = now
                if now - track.started_at > self.stale_after_s:
                    self._finish(name, f"{name}: stopped, no telemetry for this joint")
                    continue
                output[channel] = 0.0
                continue
            if (
                track.last_measured_at is not None
                and now - track.last_measured_at > self.stale_after_s
            ):
                self._finish(
                    name,
                    f"{name}: stopped, telemetry stale ({now - track.last_measured_at:.1f} s old)",
                )
                output[channel] = 0.0
                continue
            dt = max(now - track.estimate_at, 0.0)
            step = track.velocity_rad_s * dt
            track.estimate_rad += step
            track.commanded_since_packet_rad += step
            track.estimate_at = now
            velocity = self._velocity(name, track)
            if name not in self._tracks:  # _velocity may finish the joint (limit)
                output[channel] = 0.0
                continue
            track.velocity_rad_s = velocity
            output[channel] = velocity
        return output

    def _velocity(self, name: str, track: _Track) -> float:
        assert track.estimate_rad is not None
        error = track.target_rad - track.estimate_rad
        if abs(error) <= self.tolerance_rad:
            return 0.0
        channel = self.profile.channels[self.channel_of(name)]
        v_max = self.limits.get(channel.name)
        if v_max <= 0.0:
            return 0.0
        # Lifted to the servo's smallest moving speed, but never so fast that one control
        # period would carry the joint past the target.
        speed = min(max(self.gain_per_s * abs(error), channel.min_speed), v_max)
        speed = min(speed, abs(error) / self._period_s)
        limits = track.motor.limits_rad
        if limits is not None and track.last_measured_rad is not None:
            low, high = limits
            at_low = error < 0 and track.last_measured_rad <= low + LIMIT_MARGIN_RAD
            at_high = error > 0 and track.last_measured_rad >= high - LIMIT_MARGIN_RAD
            if at_low or at_high:
                self._finish(name, f"{name}: stopped at its limit")
                return 0.0
        return math.copysign(speed, error)

    def _finish(self, name: str, message: str) -> None:
        self._tracks.pop(name, None)
        self._messages.append(message)


class ConstantSpeedController(PositionController):
    """The paper's controller, kept as the benchmark baseline.

    It moves at one constant speed toward the target and decides only from telemetry: no
    prediction, no slowing down, so with slow telemetry it overshoots and hunts.
    """

    def __init__(self, profile: RobotProfile, limits: VelocityLimits, speed_rad_s: float) -> None:
        super().__init__(profile, limits, stale_after_s=math.inf, settle_timeout_s=math.inf)
        self.speed_rad_s = speed_rad_s

    def update(self, now: float) -> dict[str, float]:
        """Constant speed toward the target from the last measured angle."""
        output: dict[str, float] = {}
        for name, track in list(self._tracks.items()):
            channel = self.channel_of(name)
            measured = self.predictors[name].last_angle_rad
            if measured is None:
                output[channel] = 0.0
                continue
            error = track.target_rad - measured
            output[channel] = (
                0.0 if abs(error) <= self.tolerance_rad else math.copysign(self.speed_rad_s, error)
            )
        return output

    def _check_motion(
        self,
        name: str,
        track: _PositionTrack,
        predictor: JointPredictor,
        previous_angle: float,
        previous_taken: float,
    ) -> None:
        """The paper's controller has no stall check."""

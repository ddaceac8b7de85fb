"""Plausible telemetry: a joint reading the OCU must not believe, and why (no Qt).

A wrong zero offset or ticks-per-radian in the profile, a disconnected encoder or a corrupted
record turns a joint reading into nonsense: raw 0 reads as -11796480°, and a controller that
believes it drives the joint the wrong way. Per joint, a reading is implausible when

- it lies outside the joint's limits by more than `margin_deg` (the servo cannot be there), or
- it moved since the last plausible reading faster than the joint can: more than
  `speed_factor` times the channel's hard maximum speed over the robot's tick interval, plus
  `jump_allowance_deg` for reading noise.

An implausible reading does not replace the last plausible one, so a single glitch is judged
against a good reading; the allowance grows with time, so a joint that really moved while
its readings were bad becomes plausible again. The message names the profile keys that most
likely hold the error.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

from ocu.profile import Motor, RobotProfile
from ocu.records import JointReading, RawTelemetry

DEFAULT_MARGIN_DEG = 5.0
DEFAULT_SPEED_FACTOR = 2.0
DEFAULT_JUMP_ALLOWANCE_DEG = 10.0
# Raw positions an encoder reports when it reports nothing.
EMPTY_RAW = (0, 0xFFFFFFFF)


@dataclass(frozen=True)
class _Baseline:
    angle_rad: float
    tick: int


class PlausibilityChecker:
    """Judges each joint reading of a telemetry stream (one checker per link)."""

    def __init__(
        self,
        profile: RobotProfile,
        *,
        margin_deg: float = DEFAULT_MARGIN_DEG,
        speed_factor: float = DEFAULT_SPEED_FACTOR,
        jump_allowance_deg: float = DEFAULT_JUMP_ALLOWANCE_DEG,
    ) -> None:
        self.profile = profile
        self.margin_rad = math.radians(margin_deg)
        self.speed_factor = speed_factor
        self.jump_allowance_rad = math.radians(jump_allowance_deg)
        self._baseline: dict[str, _Baseline] = {}

    def reset(self) -> None:
        """Forget the last plausible readings (the robot restarted, the link was lost)."""
        self._baseline.clear()

    def check(self, packet: RawTelemetry, readings: Mapping[str, JointReading]) -> dict[str, str]:
        """Joint name to the reason it is implausible, for the implausible joints only."""
        raw_by_device = {record.device_id: record.position for record in packet.motors}
        faults: dict[str, str] = {}
        for name, reading in readings.items():
            motor = self.profile.motors.get(name)
            if motor is None or reading.angle_rad is None or motor.limits_rad is None:
                continue
            raw = raw_by_device.get(reading.device_id, 0)
            fault = self._judge(motor, reading.angle_rad, raw, packet.tick)
            if fault is None:
                self._baseline[name] = _Baseline(reading.angle_rad, packet.tick)
            else:
                faults[name] = fault
        return faults

    def _judge(self, motor: Motor, angle_rad: float, raw: int, tick: int) -> str | None:
        assert motor.limits_rad is not None
        low, high = motor.limits_rad
        key = f"motors.{motor.name}"
        if not math.isfinite(angle_rad) or not (
            low - self.margin_rad <= angle_rad <= high + self.margin_rad
        ):
            where = (
                f"{math.degrees(angle_rad):.1f}° is outside the limits "
                f"[{math.degrees(low):g}°, {math.degrees(high):g}°]"
            )
            if raw in EMPTY_RAW:
                return (
                    f"{where}: raw position 0x{raw:08x} means the encoder reports nothing "
                    f"(a sensor fault), or {key}.zero_offset_ticks is wrong"
                )
            return (
                f"{where}: check {key}.zero_offset_ticks ({motor.zero_offset_ticks}, "
                f"raw reading {raw}) and {key}.ticks_per_rad"
            )
        baseline = self._baseline.get(motor.name)
        if baseline is None or tick <= baseline.tick or motor.channel is None:
            return None
        dt_s = (tick - baseline.tick) / self.profile.link.telemetry_tick_hz
        max_speed = self.profile.channels[motor.channel].hard_max
        allowed = self.speed_factor * max_speed * dt_s + self.jump_allowance_rad
        moved = abs(angle_rad - baseline.angle_rad)
        if moved > allowed:
            return (
                f"moved {math.degrees(moved):.1f}° in {dt_s:.2f} s, faster than the joint can "
                f"({math.degrees(max_speed):.0f}°/s): check {key}.ticks_per_rad "
                f"({motor.ticks_per_rad:g}) and the encoder"
            )
        return None

"""Step 5, guided only: a known angle, the hard stops, the drive runs."""

from __future__ import annotations

import math

from ocu.calibrate.core import NEGATIVE, POSITIVE, CalibratorCore, Measured, _Joint
from ocu.calibrate.fit import fit_through_origin
from ocu.calibrate.guard import (
    CalibrationAbortedError,
    DeadmanReleasedError,
)
from ocu.calibrate.operator import LINEAR, ROTATION, DrivePlan
from ocu.calibrate.probe import MISMATCH, NOTE
from ocu.calibrate.raw import tick_delta


class GuidedSteps(CalibratorCore):
    """Step 5, guided only: a known angle, the hard stops, the drive runs."""

    # ---- guided steps --------------------------------------------------------------------

    def _known_angles(self) -> None:
        """Move each calibrated joint by a known angle; the operator's measurement corrects
        ticks per radian (and the joint scale with it)."""
        for joint in self._joints.values():
            if joint.ticks_per_rad is None or joint.axis is None or joint.channel is None:
                continue
            if self.operator.checks_angle(joint.motor.name):
                self._known_angle(joint)

    def _known_angle(self, joint: _Joint) -> None:
        assert joint.axis is not None
        assert joint.ticks_per_rad is not None
        name = joint.motor.name
        angle_rad = math.radians(
            min(self.config.known_angle_deg, self.config.planned_excursion_deg + 2)
        )
        way = POSITIVE if len(joint.free) != 1 else next(iter(joint.free))
        speed_key = f"channels.{joint.channel}.axis_per_unit"
        scale = self.result.measured[speed_key].value
        value = max(1, round(self.config.joint_speed_rad_s * scale))
        self._allowed = {joint.device_id}
        try:
            before = self._settle()
            self._legs(
                joint.axis, [(way * joint.sign * value, angle_rad / self.config.joint_speed_rad_s)]
            )
            after = self._settle()
            ticks = tick_delta(
                before.motors[joint.device_id].position, after.motors[joint.device_id].position
            )
            reckoned_deg = math.degrees(abs(ticks) / joint.ticks_per_rad)
            measured_deg = self.operator.measured_angle(name, reckoned_deg)
            if measured_deg is not None:
                corrected = abs(ticks) / math.radians(abs(measured_deg))
                ratio = corrected / joint.ticks_per_rad
                self._finding(
                    NOTE if abs(ratio - 1) < 0.03 else MISMATCH,
                    f"{name}: the operator measured {abs(measured_deg):.2f}° where the speed "
                    f"reports say {reckoned_deg:.2f}° ({(ratio - 1) * 100:+.1f} %)"
                    + (
                        ""
                        if abs(ratio - 1) < 0.03
                        else ": si.telemetry_speed_per_rad_s may be wrong"
                    ),
                    "si.telemetry_speed_per_rad_s",
                )
                joint.ticks_per_rad = corrected
                old = self.result.measured[speed_key]
                self._measure(
                    Measured(
                        f"motors.{name}.ticks_per_rad",
                        round(corrected, 3),
                        f"guided: a move of {abs(ticks)} ticks the operator measured as "
                        f"{abs(measured_deg):g}°",
                        samples=1,
                    )
                )
                self._measure(
                    Measured(
                        speed_key,
                        round(old.value * ratio, 3),
                        f"{old.how}, rescaled by the operator's measured angle",
                        residual=old.residual,
                        residual_unit=old.residual_unit,
                        samples=old.samples,
                    )
                )
            self._legs(
                joint.axis, [(-way * joint.sign * value, angle_rad / self.config.joint_speed_rad_s)]
            )
            self._settle()
        finally:
            self._allowed = None

    def _limits(self) -> None:
        """Slow moves to each chosen joint's hard stops; the stop positions become limits."""
        for joint in self._joints.values():
            if joint.ticks_per_rad is None or joint.axis is None:
                continue
            if self.operator.wants_limits(joint.motor.name):
                self._limit(joint)

    def _limit(self, joint: _Joint) -> None:
        assert joint.axis is not None
        assert joint.ticks_per_rad is not None
        assert joint.channel
        name = joint.motor.name
        scale = self.result.measured[f"channels.{joint.channel}.axis_per_unit"].value
        speed = self.config.limit_speed_rad_s
        value = max(1, round(speed * scale))
        stops: dict[int, float] = {}
        self._allowed = {joint.device_id}
        self._expected_rad_s = speed
        self._limit_search = True
        try:
            start = self._settle()
            for way in (NEGATIVE, POSITIVE):
                stops[way] = self._seek_stop(joint, way * joint.sign * value, speed)
            low, high = sorted(stops.values())
            margin = self.config.limit_margin_deg
            limits = [round(low + margin, 2), round(high - margin, 2)]
            self._measure(
                Measured(
                    f"motors.{name}.limits_deg",
                    limits,
                    f"guided: slow moves at {math.degrees(speed):.1f}°/s until the joint "
                    f"stopped at its hard stops ({low:.2f}°, {high:.2f}°), {margin:g}° inside",
                )
            )
            target = start.motors[joint.device_id].position
            latest = self.log.latest()
            assert latest is not None
            away = tick_delta(target, latest.motors[joint.device_id].position) / joint.ticks_per_rad
            direction = NEGATIVE if away > 0 else POSITIVE
            self._legs(joint.axis, [(direction * joint.sign * value, abs(away) / speed)])
            self._settle()
        finally:
            self._limit_search = False
            self._allowed = None
            self._expected_rad_s = self.config.joint_speed_rad_s

    def _seek_stop(self, joint: _Joint, value: int, speed: float) -> float:
        """Move until the joint stops moving (a hard stop); its angle there, in degrees."""
        assert joint.axis is not None
        assert joint.ticks_per_rad is not None
        zero = self.result.measured.get(f"motors.{joint.motor.name}.zero_offset_ticks")
        offset = zero.value if zero is not None else joint.start_ticks
        start = self.clock()
        travel_s = math.radians(self.config.limit_travel_deg) / speed
        try:
            self._command({joint.axis: value})
            while True:
                self._poll()
                samples = self.log.samples(start + self._margin_s)
                still = [
                    s
                    for s in samples[-2:]
                    if abs(s.motors[joint.device_id].speed) <= self.config.speed_noise_raw
                ]
                if len(samples) >= 3 and len(still) == 2:
                    break
                if self.clock() - start > travel_s:
                    raise CalibrationAbortedError(
                        f"the {joint.motor.name} found no hard stop within "
                        f"{self.config.limit_travel_deg:g}°"
                    )
                self.stop.wait(self.config.control_period_s)
        finally:
            self._zero()
        after = self._settle()
        ticks = tick_delta(offset, after.motors[joint.device_id].position)
        return math.degrees(ticks / joint.ticks_per_rad)

    def _drive_constants(self) -> None:
        for kind in (LINEAR, ROTATION):
            plan = self.operator.drive_plan(kind)
            if plan is not None:
                self._drive_runs(plan)

    def _drive_runs(self, plan: DrivePlan) -> None:
        """Seed 000 §3.1: constant axis values, distance over time, least squares."""
        drive = self.profile.drive_channels
        if drive is None:
            return
        channel = drive[0] if plan.kind == LINEAR else drive[1]
        if channel not in self._axis_map:
            self._finding(MISMATCH, f"{plan.kind} drive constant: {channel} has no axis")
            return
        axis, sign = self._axis_map[channel]
        assumed = self.profile.channels[channel].axis_per_unit
        values: list[float] = []
        speeds: list[float] = []
        durations: list[float] = []
        tracks = {m.device_id for m in self.profile.motors.values() if m.track is not None}
        self._allowed = tracks
        self._expected_rad_s = max(plan.speeds) * 2
        try:
            for index, speed in enumerate(plan.speeds):
                value = round(speed * assumed)
                self._settle()
                commanded = self._drive_run(axis, sign * value, plan, index)
                durations.append(commanded)
                typed = self.operator.drive_time(plan.kind, index, commanded)
                if typed is None or typed <= 0:
                    continue
                values.append(float(value))
                speeds.append(plan.distance / typed)
        finally:
            self._allowed = None
            self._expected_rad_s = self.config.joint_speed_rad_s
        if not speeds:
            return
        fit = fit_through_origin(speeds, values, "axis")
        key = "si.linear_axis_per_m_s" if plan.kind == LINEAR else "si.rotation_axis_per_rad_s"
        unit = "m" if plan.kind == LINEAR else "rad"
        self._measure(
            Measured(
                key,
                round(fit.value, 3),
                f"guided, seed 000 §3.1: {len(speeds)} run(s) of {plan.distance:g} {unit} at "
                f"axis values {[int(v) for v in values]}, timed by the operator; least squares",
                residual=round(fit.residual, 3),
                residual_unit="axis",
                samples=len(speeds),
            )
        )

    def _drive_run(self, axis: int, value: int, plan: DrivePlan, index: int) -> float:
        """One run: until the given time, or until the operator lets go of the deadman."""
        start = self.clock()
        stop_after = plan.stop_after_s[index] if plan.stop_after_s is not None else None
        try:
            self._command({axis: value})
            while stop_after is None or self.clock() - start < stop_after:
                try:
                    self._poll()
                except DeadmanReleasedError:
                    break
                self.stop.wait(self.config.control_period_s)
        finally:
            self._zero()
        return self.clock() - start

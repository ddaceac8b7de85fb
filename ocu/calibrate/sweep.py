"""Step 4, joint scale and ticks per radian: each joint swept about where it stands."""

from __future__ import annotations

import math
import statistics
from collections.abc import Sequence

from ocu.calibrate.core import (
    DEFAULT_TICKS_PER_RAD,
    NEGATIVE,
    POSITIVE,
    ROUGH_FIT_ERROR,
    CalibratorCore,
    Measured,
    _Joint,
    _stated,
    log,
)
from ocu.calibrate.fit import Fit, FitError, Run, fit_through_origin, fit_ticks_per_rad
from ocu.calibrate.observer import Sample
from ocu.calibrate.probe import MISMATCH, NOTE
from ocu.calibrate.raw import tick_delta
from ocu.profile import AXIS_MAX


class JointSweeps(CalibratorCore):
    """Step 4, joint scale and ticks per radian: each joint swept about where it stands."""

    # ---- joint scale and ticks per radian ------------------------------------------------

    def _sweeps(self) -> None:
        for joint in self._joints.values():
            if joint.axis is not None and joint.channel is not None:
                self._sweep(joint)

    def _sweep_plan(self, joint: _Joint) -> tuple[int, list[tuple[int, float]], float]:
        """Axis value, legs of one cycle, and the speed aimed at (rad/s)."""
        config = self.config
        assert joint.axis is not None
        margin = self._margin_s
        symmetric = len(joint.free) != 1
        # A leg long enough for two readings at a constant speed (the middle leg of a
        # symmetric cycle is twice as long as the outer ones).
        need_s = 1.1 * self._period_s * (1 if symmetric else 2) + margin / 2
        budget_rad = math.radians(config.planned_excursion_deg)
        noise_rad = self._noise_rad(joint)
        # Noisy readings need longer runs: the slope of a run of n readings spread over a
        # travel of d is known to about noise·sqrt(12/n)/d; aim at `noisy_run_error` per run,
        # but never slower than `min_sweep_speed_rad_s` (the speed report's resolution).
        # A one-sided cycle runs each way for two legs: it travels twice as far from the start.
        reach = 1.0 if symmetric else 2.0
        noisy_s = 0.0
        if noise_rad > 0.0:
            ratio = noise_rad * math.sqrt(12.0) / (budget_rad * config.noisy_run_error)
            # The noise is reckoned with a rough ticks per radian (the profile's may be 50 %
            # off): whatever it says, noisy runs use the whole budget, the travel that divides
            # the noise; at full speed that costs no more time than shorter cycles repeated.
            full_s = budget_rad / (reach * config.joint_speed_rad_s)
            noisy_s = max(ratio**2 * self._period_s, full_s)
        slowest_s = budget_rad / (reach * config.min_sweep_speed_rad_s)
        leg_s = max(config.min_leg_s, need_s, min(noisy_s, slowest_s))
        speed = min(config.joint_speed_rad_s, budget_rad / (reach * leg_s))
        scan = joint.scan_speed_rad_s or (config.scan_axis_value / self._assumed_scale(joint))
        scale = config.scan_axis_value / scan
        value = max(1, min(AXIS_MAX, round(speed * scale)))
        out = joint.sign * value
        log.info(
            "%s: plan leg %.2f s, speed %.3f rad/s, scan speed %s, free %s, noise %.2f°",
            joint.motor.name,
            leg_s,
            speed,
            joint.scan_speed_rad_s,
            joint.free,
            math.degrees(noise_rad),
        )
        if symmetric:
            legs = [(out, leg_s), (-out, 2 * leg_s), (out, leg_s)]
        else:
            way = next(iter(joint.free))
            legs = [(way * out, 2 * leg_s), (-way * out, 2 * leg_s)]
        return value, legs, value / scale

    def _noise_rad(self, joint: _Joint) -> float:
        """The standard deviation of a resting reading, in radians (rough until measured)."""
        ticks_per_rad = self._rough_ticks(joint)
        if joint.noise_ticks <= 2:
            return 0.0
        # The spread of n uniform readings is about 0.8 of their full range: sigma ~ range/3.5.
        return joint.noise_ticks / 3.0 / abs(ticks_per_rad)

    def _assumed_scale(self, joint: _Joint) -> float:
        assert joint.channel is not None
        return self.profile.channels[joint.channel].axis_per_unit

    def _sweep(self, joint: _Joint) -> None:
        assert joint.axis is not None
        assert joint.channel is not None
        name = joint.motor.name
        value, legs, speed = self._sweep_plan(joint)
        self.operator.say(
            f"{name}: sweeps of ±{value} on axis {joint.axis} (about {math.degrees(speed):.1f}°/s)"
        )
        self._expected_rad_s = speed
        self._allowed = {joint.device_id}
        start_sample = self._settle()
        begin = self.clock()
        k_fit: Fit | None = None
        runs: list[tuple[Run, int]] = []
        try:
            for _ in range(self.config.max_sweep_cycles):
                self._legs(joint.axis, legs)
                self._settle()
                runs = self._runs(joint, self.log.samples(begin))
                try:
                    k_fit = fit_ticks_per_rad([run for run, _ in runs], self.speed_step_rad_s)
                except FitError:
                    k_fit = None
                # Back to the start after every cycle: a lost or late command stretches a
                # leg, and cycles must not add up.
                if k_fit is not None and (k_fit.relative_error or 1.0) <= ROUGH_FIT_ERROR:
                    joint.rough_ticks_per_rad = abs(k_fit.value)
                estimate = self._rough_ticks(joint)
                self._return_to(joint, start_sample, speed, value, estimate)
                good = sum(1 for run, _ in runs if len(run.times_s) >= 2)
                # Only the statistical part: more cycles do not lower the speed's rounding.
                error = k_fit.relative_error if k_fit is not None else None
                if good >= 2 and error is not None and error <= self.config.target_relative_error:
                    break
            if k_fit is None:
                self._finding(
                    MISMATCH,
                    f"{name}: no two readings at a constant speed; ticks per radian not measured",
                    f"motors.{name}.ticks_per_rad",
                )
                return
            ticks_per_rad = k_fit.value
            if ticks_per_rad < 0:
                self._finding(
                    NOTE,
                    f"{name}: the reported speed has the opposite sign of the position's change",
                )
                ticks_per_rad = -ticks_per_rad
            joint.ticks_per_rad = ticks_per_rad
            self._record_sweep(joint, k_fit, ticks_per_rad, runs, value)
        finally:
            self._allowed = None
            self._expected_rad_s = self.config.joint_speed_rad_s

    def _rough_ticks(self, joint: _Joint) -> float:
        """The best ticks per radian known so far: measured, from the scan, or assumed."""
        if joint.ticks_per_rad is not None:
            return joint.ticks_per_rad
        if joint.rough_ticks_per_rad is not None:
            return joint.rough_ticks_per_rad
        return joint.motor.ticks_per_rad or DEFAULT_TICKS_PER_RAD

    def _record_sweep(
        self,
        joint: _Joint,
        k_fit: Fit,
        ticks_per_rad: float,
        runs: Sequence[tuple[Run, int]],
        value: int,
    ) -> None:
        assert joint.channel is not None
        name = joint.motor.name
        speeds = [abs(speed_raw) / self.speed_scale for _, speed_raw in runs]
        scale_fit = fit_through_origin(
            speeds, [float(value)] * len(speeds), "axis", x_step=self.speed_step_rad_s
        )
        self._measure(
            Measured(
                f"motors.{name}.ticks_per_rad",
                round(ticks_per_rad, 3),
                f"sweeps about the start pose: positions against the robot's clock in "
                f"{len(runs)} runs at constant reported speed (speed unit "
                f"si.telemetry_speed_per_rad_s = {self.speed_scale:g})",
                residual=round(k_fit.residual, 3),
                residual_unit="ticks",
                samples=k_fit.samples,
            )
        )
        self._measure(
            Measured(
                f"channels.{joint.channel}.axis_per_unit",
                round(scale_fit.value, 3),
                f"axis value {value} against the speed the robot reported in {len(runs)} runs",
                residual=round(scale_fit.residual, 3),
                residual_unit="axis",
                samples=len(runs),
            )
        )
        slowest = min(abs(speed_raw) for _, speed_raw in runs)
        self.operator.say(
            f"{name}: {ticks_per_rad:.1f} ticks/rad {_stated(k_fit)}, "
            f"{scale_fit.value:.0f} axis per rad/s {_stated(scale_fit)} (about 95 %; the "
            f"speed it rests on is reported to 1 part in {slowest})"
        )

    def _return_to(
        self, joint: _Joint, target: Sample, speed_rad_s: float, value: int, ticks_per_rad: float
    ) -> None:
        """Move the joint back to where a sample saw it (sweeps drift with the link's jitter)."""
        assert joint.axis is not None
        away = round(
            statistics.median(
                tick_delta(target.motors[joint.device_id].position, p)
                for p in self._rest_positions(joint)
            )
        )
        away_rad = away / ticks_per_rad
        if abs(away_rad) < math.radians(0.3) + joint.noise_ticks / 3 / ticks_per_rad:
            return
        direction = NEGATIVE if away_rad > 0 else POSITIVE
        self._legs(joint.axis, [(direction * joint.sign * value, abs(away_rad) / speed_rad_s)])
        self._settle()

    def _rest_positions(self, joint: _Joint) -> list[int]:
        """Positions of a settled joint: several readings when they are noisy."""
        wanted = 1 if joint.noise_ticks <= 2 else 5
        since = self.clock()
        samples = self._wait_samples(since, wanted, (wanted + 2) * self._period_s + 1)
        latest = self.log.latest()
        if not samples and latest is not None:
            samples = [latest]
        return [s.motors[joint.device_id].position for s in samples[-wanted:]]

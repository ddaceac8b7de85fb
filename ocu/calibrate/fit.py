"""The calibration's least-squares fits, pure: numbers in, estimate and residual out.

- `fit_ticks_per_rad`: positions against time within runs of constant reported speed; one
  slope per run, all tied by one factor (ticks per radian) to the speed each run reports.
- `fit_through_origin`: y = k·x by least squares (axis value against speed: an axis scale;
  seed 000 §3.1's linear and rotation constants).

Each fit states two standard uncertainties (1 σ, relative): the statistical one the residuals
show (`relative_error`), and the one they cannot show (`systematic`): the resolution of the
speed the robot reports. Every run at one reported speed shares one rounding error, so no
number of samples averages it out: a speed reported as 100 (of 1000 per rad/s) is anywhere
in 99.5 … 100.5, ±0.5 %, however long the joint sweeps. `uncertainty` combines the two.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np


class FitError(ValueError):
    """Too little or degenerate data for a fit."""


# The standard deviation of a rounding error, in steps (uniform over ±0.5 step).
ROUNDING_SIGMA_STEPS = 1.0 / math.sqrt(12.0)
# The coverage factor of a stated uncertainty: about 95 % (GUM's k = 2).
COVERAGE_FACTOR = 2.0


@dataclass(frozen=True)
class Run:
    """Samples of one joint while its reported speed stayed constant.

    `times_s` on the robot's clock, `positions` in ticks (unwrapped, from any origin),
    `speed_rad_s` the speed the robot reported throughout.
    """

    times_s: tuple[float, ...]
    positions: tuple[float, ...]
    speed_rad_s: float


@dataclass(frozen=True)
class Fit:
    """An estimate with its residual (root mean square, in `residual_unit`), sample count,
    statistical standard error (None when the data cannot tell one) and the relative
    standard uncertainty of the reference it is scaled by (`systematic`)."""

    value: float
    residual: float
    residual_unit: str
    samples: int
    std_error: float | None
    systematic: float = 0.0

    @property
    def relative_error(self) -> float | None:
        """The statistical standard error as a fraction of the value (more data lowers it)."""
        if self.std_error is None or self.value == 0.0:
            return None
        return abs(self.std_error / self.value)

    @property
    def uncertainty(self) -> float | None:
        """The relative standard uncertainty (1 σ): statistical and systematic combined."""
        statistical = self.relative_error
        if statistical is None:
            return None
        return math.hypot(statistical, self.systematic)

    @property
    def expanded_uncertainty(self) -> float | None:
        """The relative uncertainty stated to the operator: about 95 % coverage."""
        combined = self.uncertainty
        return None if combined is None else COVERAGE_FACTOR * combined


def rounding_uncertainty(speeds: Sequence[float], weights: Sequence[float], step: float) -> float:
    """Relative 1 σ uncertainty of a scale measured against speeds reported in steps of `step`.

    Runs at one reported magnitude share one rounding error; magnitudes differ in theirs. The
    estimate is a weighted mean over the runs (`weights`: each run's share of the fit's
    information), so each magnitude's relative rounding error enters with its runs' weight.
    """
    if step <= 0.0:
        return 0.0
    total = float(sum(weights))
    if total <= 0.0:
        return 0.0
    shares: dict[int, float] = {}
    for speed, weight in zip(speeds, weights, strict=True):
        level = round(abs(speed) / step)
        shares[level] = shares.get(level, 0.0) + weight / total
    return math.sqrt(
        sum((share * ROUNDING_SIGMA_STEPS / max(level, 1)) ** 2 for level, share in shares.items())
    )


def fit_ticks_per_rad(runs: Sequence[Run], speed_step_rad_s: float = 0.0) -> Fit:
    """Ticks per radian from runs of constant speed: position_i = c_run + K·speed_run·t_i.

    Needs at least two samples in some run. The residual is in ticks. A negative K means the
    position counts against the sign of the reported speed. `speed_step_rad_s` is the
    resolution of the reported speed (its systematic share of the uncertainty).
    """
    usable = [run for run in runs if len(run.times_s) >= 2 and run.speed_rad_s != 0.0]
    if not usable:
        raise FitError("no run with two samples at a constant, non-zero speed")
    rows = sum(len(run.times_s) for run in usable)
    design = np.zeros((rows, len(usable) + 1))
    target = np.zeros(rows)
    row = 0
    for index, run in enumerate(usable):
        # Times from each run's own start keep the intercepts well conditioned.
        t0 = run.times_s[0]
        for t, p in zip(run.times_s, run.positions, strict=True):
            design[row, index] = 1.0
            design[row, -1] = run.speed_rad_s * (t - t0)
            target[row] = p
            row += 1
    solution, *_ = np.linalg.lstsq(design, target, rcond=None)
    residuals = target - design @ solution
    dof = rows - (len(usable) + 1)
    rms = float(math.sqrt(float(np.mean(residuals**2))))
    std_error: float | None = None
    if dof > 0:
        sigma2 = float(residuals @ residuals) / dof
        covariance = sigma2 * np.linalg.pinv(design.T @ design)
        std_error = float(math.sqrt(max(float(covariance[-1, -1]), 0.0)))
    # A run's information about K: speed² times the spread of its times about their mean.
    weights = [run.speed_rad_s**2 * float(np.var(run.times_s)) * len(run.times_s) for run in usable]
    systematic = rounding_uncertainty(
        [run.speed_rad_s for run in usable], weights, speed_step_rad_s
    )
    return Fit(float(solution[-1]), rms, "ticks", rows, std_error, systematic)


def fit_through_origin(
    xs: Sequence[float], ys: Sequence[float], unit: str, x_step: float = 0.0
) -> Fit:
    """k of y = k·x by least squares; the residual is the RMS of y - k·x, in `unit`.

    `x_step` is the resolution the xs were reported in (a reported speed), 0 if they were not
    rounded (the share of the uncertainty the residuals cannot show).
    """
    if len(xs) != len(ys) or not xs:
        raise FitError("no data")
    x = np.asarray(xs, dtype=float)
    y = np.asarray(ys, dtype=float)
    denominator = float(x @ x)
    if denominator == 0.0:
        raise FitError("every x is zero")
    k = float(x @ y) / denominator
    residuals = y - k * x
    rms = float(math.sqrt(float(np.mean(residuals**2))))
    std_error: float | None = None
    if len(xs) > 1:
        sigma2 = float(residuals @ residuals) / (len(xs) - 1)
        std_error = math.sqrt(sigma2 / denominator)
    systematic = rounding_uncertainty(list(x), list(x**2), x_step)
    return Fit(k, rms, unit, len(xs), std_error, systematic)

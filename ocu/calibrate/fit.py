"""The calibration's least-squares fits, pure: numbers in, estimate and residual out.

- `fit_ticks_per_rad`: positions against time within runs of constant reported speed; one
  slope per run, all tied by one factor (ticks per radian) to the speed each run reports.
- `fit_through_origin`: y = k·x by least squares (axis value against speed: an axis scale;
  seed 000 §3.1's linear and rotation constants).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np


class FitError(ValueError):
    """Too little or degenerate data for a fit."""


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
    """An estimate with its residual (root mean square, in `residual_unit`), sample count and
    standard error (None when the data cannot tell one)."""

    value: float
    residual: float
    residual_unit: str
    samples: int
    std_error: float | None

    @property
    def relative_error(self) -> float | None:
        """The standard error as a fraction of the value."""
        if self.std_error is None or self.value == 0.0:
            return None
        return abs(self.std_error / self.value)


def fit_ticks_per_rad(runs: Sequence[Run]) -> Fit:
    """Ticks per radian from runs of constant speed: position_i = c_run + K·speed_run·t_i.

    Needs at least two samples in some run. The residual is in ticks. A negative K means the
    position counts against the sign of the reported speed.
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
    return Fit(float(solution[-1]), rms, "ticks", rows, std_error)


def fit_through_origin(xs: Sequence[float], ys: Sequence[float], unit: str) -> Fit:
    """k of y = k·x by least squares; the residual is the RMS of y - k·x, in `unit`."""
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
    return Fit(k, rms, unit, len(xs), std_error)

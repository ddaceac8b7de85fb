"""The chassis' two speeds as one command: the turn radius is kept (seed 002, eq. 5.1-5.4).

A crawler drives with a linear speed v (m/s) and a turn rate ω (rad/s); their ratio is the
turn radius r = v / ω. Bounding or lifting each one on its own changes that ratio: the paper's
"0.2 rule" turns (0.1 m/s, 0.05 rad/s), a 2 m arc, into (0.2, 0.2), a 1 m arc.
Seed 002 scales both by one factor instead:

- eq. 5.1-5.2 (maxima): the ratios v/v_max and ω/ω_max; if the larger one exceeds 1, both
  speeds are divided by it, so the dominant one sits at its maximum;
- eq. 5.3-5.4 (minima): the ratios v/v_min and ω/ω_min; if the larger one is below 1 (both
  speeds under the servos' starting speed), both are divided by it, so the dominant one
  starts the servos.

The maxima win over the minima: a lift that would exceed a maximum is bounded again.
Speeds closer to zero than `ZERO_EPSILON` are zero first, so a 1e-300 m/s request stops.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

# Below this (m/s or rad/s) a requested speed is noise, not a wish to move.
ZERO_EPSILON = 1e-3


class DriveError(ValueError):
    """A drive speed or bound that is not a finite number (or a negative bound)."""


@dataclass(frozen=True)
class DriveBounds:
    """Per-speed bounds of the chassis: maxima (eq. 5.2) and starting minima (eq. 5.4)."""

    max_linear_m_s: float
    max_angular_rad_s: float
    min_linear_m_s: float = 0.0
    min_angular_rad_s: float = 0.0

    def __post_init__(self) -> None:
        for name in ("max_linear_m_s", "max_angular_rad_s", "min_linear_m_s", "min_angular_rad_s"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0.0):
                raise DriveError(f"{name} must be finite and >= 0, got {value!r}")


def _finite(name: str, value: float) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise DriveError(f"{name} must be a finite number, got {value!r}")
    return float(value)


def _ratio(value: float, bound: float) -> float:
    """|value| / bound; a zero bound with a non-zero value is an infinite ratio."""
    if value == 0.0:
        return 0.0
    return abs(value) / bound if bound > 0.0 else math.inf


def scale_drive(
    linear_m_s: float, angular_rad_s: float, bounds: DriveBounds
) -> tuple[float, float]:
    """(v, ω) bounded by the maxima and lifted to the minima with one common factor."""
    v = _finite("linear speed", linear_m_s)
    w = _finite("angular speed", angular_rad_s)
    if abs(v) < ZERO_EPSILON:
        v = 0.0
    if abs(w) < ZERO_EPSILON:
        w = 0.0
    if v == 0.0 and w == 0.0:
        return 0.0, 0.0
    # eq. 5.3-5.4: both below their minimum -> the dominant one is lifted to its minimum.
    lift = max(_ratio(v, bounds.min_linear_m_s), _ratio(w, bounds.min_angular_rad_s))
    if 0.0 < lift < 1.0:
        v, w = v / lift, w / lift
    # eq. 5.1-5.2: one above its maximum -> the dominant one is brought down to it.
    over = max(_ratio(v, bounds.max_linear_m_s), _ratio(w, bounds.max_angular_rad_s))
    if over > 1.0:
        if math.isinf(over):
            return 0.0, 0.0  # a speed whose maximum is zero: nothing may move
        v, w = v / over, w / over
    return v, w

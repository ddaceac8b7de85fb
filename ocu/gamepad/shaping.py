"""A calibrated axis value into a command: deadzone, then expo (pure functions).

The deadzone is the joy node's (0.05 by default): readings within it are 0, and the rest of
the travel is stretched so the command grows from 0 at the deadzone's edge. Expo is an RC
transmitter's (and QGroundControl's): (1 - e)·x + e·x³, finer near the centre, the same at
the ends.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

# A held stick's noise must not flood the link: a new command is kept only when it differs
# from the last by this much, or is 0 or a full deflection.
RESOLUTION = 0.01


@dataclass(frozen=True)
class AxisShape:
    """One axis's deadzone (share of the travel) and expo (0: linear, 1: cubic)."""

    deadzone: float = 0.05
    expo: float = 0.0

    def __post_init__(self) -> None:
        if not (math.isfinite(self.deadzone) and 0.0 <= self.deadzone < 0.5):
            raise ValueError(f"deadzone must be in [0, 0.5), got {self.deadzone!r}")
        if not (math.isfinite(self.expo) and 0.0 <= self.expo <= 1.0):
            raise ValueError(f"expo must be in [0, 1], got {self.expo!r}")

    def apply(self, value: float) -> float:
        """A calibrated value in [-1, 1] shaped: 0 within the deadzone, ±1 at the ends."""
        magnitude = abs(value)
        if magnitude <= self.deadzone:
            return 0.0
        x = min((magnitude - self.deadzone) / (1.0 - self.deadzone), 1.0)
        return math.copysign((1.0 - self.expo) * x + self.expo * x**3, value)


def settle(previous: float, value: float, resolution: float = RESOLUTION) -> float:
    """Keep `previous` unless `value` moved by `resolution`, reached 0 or an end, or
    changed sign: the stops and the full deflections always pass."""
    if value == 0.0 or abs(value) >= 1.0 or previous * value <= 0.0:
        return value
    return value if abs(value - previous) >= resolution else previous

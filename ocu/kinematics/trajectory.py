"""Synchronized joint moves: every joint starts and arrives together on one smooth profile.

A move from q0 to q1 is q(t) = q0 + (q1 - q0) s(t) with one scalar profile s from 0 to 1, so
the joints move in proportion and stay on the straight line of joint space between the two
poses (which is what a path check samples). The profile is the fastest that keeps every joint
within its speed and acceleration: a trapezoid (accelerate, cruise, brake; a triangle when
the move is short) or, after seed 004's `interp_cubic`, a cubic with zero speed at both ends.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

Vector = npt.NDArray[np.float64]
PROFILES = ("trapezoid", "cubic")


class TrajectoryError(ValueError):
    """A move that cannot be planned (a speed or acceleration that is not positive)."""


@dataclass(frozen=True)
class SyncMove:
    """A planned move: q(t), q'(t) for t in [0, duration_s]."""

    start: Vector
    goal: Vector
    duration_s: float
    profile: str
    # Trapezoid: peak of s' (1/s) and the time spent accelerating (and braking).
    peak_rate: float = 0.0
    ramp_s: float = 0.0

    @property
    def delta(self) -> Vector:
        """goal - start."""
        result: Vector = self.goal - self.start
        return result

    def scalar(self, t: float) -> tuple[float, float]:
        """s(t) and s'(t)."""
        if self.duration_s <= 0.0 or t >= self.duration_s:
            return 1.0, 0.0
        if t <= 0.0:
            return 0.0, 0.0
        if self.profile == "cubic":
            tau = t / self.duration_s
            return 3.0 * tau**2 - 2.0 * tau**3, 6.0 * tau * (1.0 - tau) / self.duration_s
        accel = self.peak_rate / self.ramp_s if self.ramp_s > 0.0 else 0.0
        if t < self.ramp_s:
            return 0.5 * accel * t * t, accel * t
        braking_from = self.duration_s - self.ramp_s
        if t <= braking_from:
            return 0.5 * accel * self.ramp_s**2 + self.peak_rate * (t - self.ramp_s), self.peak_rate
        left = self.duration_s - t
        return 1.0 - 0.5 * accel * left * left, accel * left

    def sample(self, t: float) -> tuple[Vector, Vector]:
        """Joint values and speeds at time t."""
        s, rate = self.scalar(t)
        delta = self.delta
        return self.start + delta * s, delta * rate

    def points(self, count: int) -> list[Vector]:
        """`count` poses evenly along the path (the start and the goal included)."""
        return [self.start + self.delta * s for s in np.linspace(0.0, 1.0, max(count, 2))]


def plan(
    start: Sequence[float] | Vector,
    goal: Sequence[float] | Vector,
    max_speed: Sequence[float] | Vector,
    max_accel: Sequence[float] | Vector,
    profile: str = "trapezoid",
) -> SyncMove:
    """The fastest synchronized move within every joint's speed and acceleration."""
    if profile not in PROFILES:
        raise TrajectoryError(f"profile must be one of {PROFILES}, got {profile!r}")
    q0 = np.asarray(start, dtype=float)
    q1 = np.asarray(goal, dtype=float)
    speed = np.asarray(max_speed, dtype=float)
    accel = np.asarray(max_accel, dtype=float)
    if not (np.all(np.isfinite(q0)) and np.all(np.isfinite(q1))):
        raise TrajectoryError("start and goal must be finite")
    distance = np.abs(q1 - q0)
    moving = distance > 1e-12
    if not moving.any():
        return SyncMove(q0, q1, 0.0, profile)
    if np.any(speed[moving] <= 0.0) or np.any(accel[moving] <= 0.0):
        raise TrajectoryError("every moving joint needs a speed and an acceleration above zero")
    # The scalar profile's limits: the tightest joint decides.
    rate = float(np.min(speed[moving] / distance[moving]))
    rate_accel = float(np.min(accel[moving] / distance[moving]))
    if profile == "cubic":
        # s' peaks at 1.5 / T, s'' at 6 / T².
        duration = max(1.5 / rate, math.sqrt(6.0 / rate_accel))
        return SyncMove(q0, q1, duration, profile)
    if rate * rate / rate_accel >= 1.0:
        # No time to cruise: a triangle.
        ramp = math.sqrt(1.0 / rate_accel)
        return SyncMove(q0, q1, 2.0 * ramp, profile, peak_rate=rate_accel * ramp, ramp_s=ramp)
    ramp = rate / rate_accel
    duration = 1.0 / rate + ramp
    return SyncMove(q0, q1, duration, profile, peak_rate=rate, ramp_s=ramp)

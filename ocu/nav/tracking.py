"""Trajectory tracking after seed 002 chapter 3: reference trajectories and Samson's controller.

A reference is a timed sequence of states (x_r, y_r, θ_r, v_r, ω_r) (eq. 3.3-3.5): the
ellipse of the thesis' experiment (eq. 6.1: semi-axes 1.8 m and 1 m, 40 s ideal), or a
smoothed path through waypoints driven at a cruise speed.

The controller (eq. 3.17) with the gains of eq. 3.18:

    v = v_r cos θ_e + k1 x_e
    ω = ω_r + k2 sign(v_r) (sin θ_e / θ_e) y_e + k3 θ_e
    k1 = k3 = 2ξ sqrt(ω_r² + b v_r²),  k2 = b |v_r|

The errors are the reference seen from the robot (Klancar et al.'s convention, which eq. 3.2
writes with the other sign; this one makes eq. 3.17 converge): x_e along the robot's heading,
y_e to its left, θ_e = θ_r − θ wrapped to [−π, π] (the thesis lost ~2 s on its ellipse to a
360°/0° jump). The y_e term is eq. 3.11's k2·sign(v_r)·y_e, the dimensionally consistent
reading of eq. 3.17's k2·v_r with k2 = b|v_r|. Pure numpy.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from ocu.nav.geometry import Pose, relative, wrap

Array = npt.NDArray[np.float64]

ELLIPSE_MAJOR_M = 1.8
ELLIPSE_MINOR_M = 1.0
ELLIPSE_PERIOD_S = 40.0
# Chaikin corner cutting rounds a polyline's corners this many times.
SMOOTHING_PASSES = 4
# Sampling of paths (m) before they get times.
PATH_STEP_M = 0.02


@dataclass(frozen=True)
class Reference:
    """One reference state: position, heading and the speeds along it (eq. 3.3-3.5)."""

    x_m: float
    y_m: float
    heading_rad: float
    linear_m_s: float
    angular_rad_s: float

    @property
    def pose(self) -> Pose:
        """The reference as a pose."""
        return Pose(self.x_m, self.y_m, self.heading_rad)


@dataclass(frozen=True)
class Trajectory:
    """A timed reference, sampled: arrays of equal length over times 0 ... duration."""

    times_s: Array
    x_m: Array
    y_m: Array
    heading_rad: Array  # unwrapped, so interpolation never jumps
    linear_m_s: Array
    angular_rad_s: Array

    @property
    def duration_s(self) -> float:
        """When the reference ends."""
        return float(self.times_s[-1])

    @property
    def end(self) -> Reference:
        """The last state, at rest."""
        return Reference(
            float(self.x_m[-1]), float(self.y_m[-1]), wrap(float(self.heading_rad[-1])), 0.0, 0.0
        )

    def at(self, t_s: float) -> Reference:
        """The reference at time t_s (clamped to the ends; at rest after the end)."""
        if t_s >= self.duration_s:
            return self.end
        t = max(t_s, 0.0)
        return Reference(
            float(np.interp(t, self.times_s, self.x_m)),
            float(np.interp(t, self.times_s, self.y_m)),
            wrap(float(np.interp(t, self.times_s, self.heading_rad))),
            float(np.interp(t, self.times_s, self.linear_m_s)),
            float(np.interp(t, self.times_s, self.angular_rad_s)),
        )

    def points(self) -> Array:
        """(N, 2) positions, for drawing the planned path."""
        return np.stack([self.x_m, self.y_m], axis=-1)

    def length_m(self) -> float:
        """Length of the path."""
        return float(np.hypot(np.diff(self.x_m), np.diff(self.y_m)).sum())


def from_samples(
    times_s: Array,
    x_m: Array,
    y_m: Array,
    derivatives: tuple[Array, Array, Array, Array] | None = None,
) -> Trajectory:
    """A trajectory through timed points: heading, v and ω by eq. 3.3-3.5, from the given
    first and second derivatives (dx, dy, ddx, ddy) or by finite differences."""
    if derivatives is not None:
        dx, dy, ddx, ddy = derivatives
    else:
        dx, dy = np.gradient(x_m, times_s), np.gradient(y_m, times_s)
        ddx, ddy = np.gradient(dx, times_s), np.gradient(dy, times_s)
    speed2 = dx * dx + dy * dy
    heading = np.unwrap(np.arctan2(dy, dx))
    with np.errstate(divide="ignore", invalid="ignore"):
        angular = np.where(speed2 > 1e-12, (dx * ddy - dy * ddx) / speed2, 0.0)
    return Trajectory(
        times_s=np.asarray(times_s, dtype=np.float64),
        x_m=np.asarray(x_m, dtype=np.float64),
        y_m=np.asarray(y_m, dtype=np.float64),
        heading_rad=np.asarray(heading, dtype=np.float64),
        linear_m_s=np.asarray(np.sqrt(speed2), dtype=np.float64),
        angular_rad_s=np.asarray(angular, dtype=np.float64),
    )


def ellipse(
    start: Pose,
    *,
    major_m: float = ELLIPSE_MAJOR_M,
    minor_m: float = ELLIPSE_MINOR_M,
    period_s: float = ELLIPSE_PERIOD_S,
    samples: int = 401,
) -> Trajectory:
    """Seed 002's test path (eq. 6.1), once round, placed so the robot at `start` is on it.

    x_r = 1.8 cos(2π t / T), y_r = sin(2π t / T) begins at (1.8, 0) heading +y; the whole
    ellipse is moved and turned so that point and heading are the robot's.
    """
    t = np.linspace(0.0, period_s, samples)
    rate = 2.0 * math.pi / period_s
    phase = rate * t
    local_x = major_m * np.cos(phase) - major_m
    local_y = minor_m * np.sin(phase)
    # Eq. 6.1's derivatives, exact.
    dlx, dly = -major_m * rate * np.sin(phase), minor_m * rate * np.cos(phase)
    ddlx, ddly = -major_m * rate**2 * np.cos(phase), -minor_m * rate**2 * np.sin(phase)
    # In the local frame the start heads along +y; the robot's heading is that direction.
    turn = start.heading_rad - math.pi / 2.0
    c, s = math.cos(turn), math.sin(turn)

    def rotate(ax: Array, ay: Array) -> tuple[Array, Array]:
        return c * ax - s * ay, s * ax + c * ay

    x, y = rotate(local_x, local_y)
    dx, dy = rotate(dlx, dly)
    ddx, ddy = rotate(ddlx, ddly)
    return from_samples(t, start.x_m + x, start.y_m + y, (dx, dy, ddx, ddy))


def chaikin(points: Array, passes: int = SMOOTHING_PASSES) -> Array:
    """Corner cutting: a smooth curve inside the polyline, ends kept."""
    curve = np.asarray(points, dtype=np.float64)
    for _ in range(passes):
        if len(curve) < 3:
            break
        q = 0.75 * curve[:-1] + 0.25 * curve[1:]
        r = 0.25 * curve[:-1] + 0.75 * curve[1:]
        middle = np.empty((2 * (len(curve) - 1), 2))
        middle[0::2], middle[1::2] = q, r
        curve = np.vstack([curve[:1], middle[1:-1], curve[-1:]])
    return curve


def along_path(points: Array, speed_m_s: float) -> Trajectory:
    """A reference through waypoints (the first one is where the robot is), corners rounded,
    driven at `speed_m_s` with gentle starts and stops."""
    waypoints = np.asarray(points, dtype=np.float64)
    if len(waypoints) < 2 or speed_m_s <= 0.0:
        raise ValueError("a path needs two points and a positive speed")
    keep = np.concatenate([[True], np.hypot(*np.diff(waypoints, axis=0).T) > 1e-6])
    waypoints = waypoints[keep]
    if len(waypoints) < 2:
        raise ValueError("a path needs two distinct points")
    curve = chaikin(waypoints)
    # Resample at even spacing along the curve.
    segment = np.hypot(*np.diff(curve, axis=0).T)
    along = np.concatenate([[0.0], np.cumsum(segment)])
    length = float(along[-1])
    count = max(int(length / PATH_STEP_M), 2) + 1
    s = np.linspace(0.0, length, count)
    x, y = np.interp(s, along, curve[:, 0]), np.interp(s, along, curve[:, 1])
    # Time along it: cruise speed with a ramp of at most a second at each end.
    ramp_m = min(speed_m_s * 0.5, length / 3.0)
    speed = np.full(count, speed_m_s)
    speed = np.minimum(speed, speed_m_s * np.sqrt(np.clip((s + 0.02) / ramp_m, 0.0, 1.0)))
    speed = np.minimum(speed, speed_m_s * np.sqrt(np.clip((length - s + 0.02) / ramp_m, 0.0, 1.0)))
    dt = np.diff(s) / np.maximum((speed[:-1] + speed[1:]) / 2.0, 1e-3)
    times = np.concatenate([[0.0], np.cumsum(dt)])
    return from_samples(times, x, y)


@dataclass(frozen=True)
class TrackingError:
    """The reference seen from the robot: along its heading, to its left, heading error."""

    x_m: float
    y_m: float
    heading_rad: float


def tracking_error(pose: Pose, reference: Reference) -> TrackingError:
    """Eq. 3.2 (reference minus robot, in the robot's frame)."""
    local = relative(pose, reference.pose)
    return TrackingError(local.x_m, local.y_m, wrap(reference.heading_rad - pose.heading_rad))


def samson_gains(
    linear_m_s: float, angular_rad_s: float, b: float, xi: float
) -> tuple[float, float, float]:
    """k1, k2, k3 of eq. 3.18."""
    natural = math.sqrt(angular_rad_s**2 + b * linear_m_s**2)
    return 2.0 * xi * natural, b * abs(linear_m_s), 2.0 * xi * natural


def samson(pose: Pose, reference: Reference, b: float, xi: float) -> tuple[float, float]:
    """(v, ω) of eq. 3.17 for a robot at `pose` tracking `reference`."""
    error = tracking_error(pose, reference)
    k1, k2, k3 = samson_gains(reference.linear_m_s, reference.angular_rad_s, b, xi)
    theta = error.heading_rad
    sinc = math.sin(theta) / theta if abs(theta) > 1e-9 else 1.0
    sign = math.copysign(1.0, reference.linear_m_s) if reference.linear_m_s else 0.0
    linear = reference.linear_m_s * math.cos(theta) + k1 * error.x_m
    angular = reference.angular_rad_s + k2 * sign * sinc * error.y_m + k3 * theta
    return linear, angular

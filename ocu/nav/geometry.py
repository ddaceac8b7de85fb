"""Planar poses and frames: x forward, y left, heading counter-clockwise (REP 103)."""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
import numpy.typing as npt

Points = npt.NDArray[np.float64]


class Pose(NamedTuple):
    """A planar pose: position in metres and heading in radians."""

    x_m: float
    y_m: float
    heading_rad: float


ORIGIN = Pose(0.0, 0.0, 0.0)


def wrap(angle_rad: float) -> float:
    """An angle in [-pi, pi]."""
    return math.remainder(angle_rad, math.tau)


def advance(pose: Pose, linear_m: float, turn_rad: float) -> Pose:
    """The pose after travelling `linear_m` along an arc that turns by `turn_rad` (exact)."""
    x, y, heading = pose
    if abs(turn_rad) < 1e-9:
        # Straight (to second order: the chord of a tiny arc leaves at the mid heading).
        mid = heading + turn_rad / 2.0
        return Pose(x + linear_m * math.cos(mid), y + linear_m * math.sin(mid), wrap(heading))
    radius = linear_m / turn_rad
    end = heading + turn_rad
    return Pose(
        x + radius * (math.sin(end) - math.sin(heading)),
        y - radius * (math.cos(end) - math.cos(heading)),
        wrap(end),
    )


def relative(origin: Pose, pose: Pose) -> Pose:
    """`pose` seen from `origin` (its frame)."""
    dx, dy = pose.x_m - origin.x_m, pose.y_m - origin.y_m
    c, s = math.cos(origin.heading_rad), math.sin(origin.heading_rad)
    return Pose(c * dx + s * dy, -s * dx + c * dy, wrap(pose.heading_rad - origin.heading_rad))


def compose(origin: Pose, local: Pose) -> Pose:
    """A pose given in `origin`'s frame, in the frame `origin` is given in."""
    c, s = math.cos(origin.heading_rad), math.sin(origin.heading_rad)
    return Pose(
        origin.x_m + c * local.x_m - s * local.y_m,
        origin.y_m + s * local.x_m + c * local.y_m,
        wrap(origin.heading_rad + local.heading_rad),
    )


def to_world(points: Points, pose: Pose) -> Points:
    """(N, 2) points from the pose's frame to the frame the pose is given in."""
    c, s = math.cos(pose.heading_rad), math.sin(pose.heading_rad)
    rotation = np.array([[c, -s], [s, c]])
    moved = np.asarray(points, dtype=np.float64) @ rotation.T + np.array([pose.x_m, pose.y_m])
    return np.asarray(moved, dtype=np.float64)


def to_local(points: Points, pose: Pose) -> Points:
    """(N, 2) points into the pose's frame."""
    c, s = math.cos(pose.heading_rad), math.sin(pose.heading_rad)
    rotation = np.array([[c, s], [-s, c]])
    shifted = np.asarray(points, dtype=np.float64) - np.array([pose.x_m, pose.y_m])
    return np.asarray(shifted @ rotation.T, dtype=np.float64)

"""Safety zones: seed 002's Algorithm 5.1, fitted to the Engineer's footprint.

The thesis caps the speeds by how close the nearest obstacle is to a round robot: zones at
600 / 900 / 1200 mm from its centre (333 / 633 / 933 mm of clearance for a radius of
267 mm), each with a maximum linear and rotational speed, both speeds scaled by one factor
so the turn radius is kept (eq. 5.1-5.2). The Engineer is a long rectangle with flippers,
not a disc, and a wall beside it does not matter while it drives straight on. So the
distance that counts here is the **travel to contact**: how far the footprint can move along
the commanded motion (the arc of v and ω) before it would touch a scan point, measured as
the travel of its fastest point (a corner in a turn). That distance, less what the robot
covers while the scan and the command are on their way (`margin_m`), picks the zone:

- below `stop_m`: nothing moves toward the obstacle (both speeds zero, the ratio kept);
- below `within_m[k]`: the speeds are capped at zone k's maxima, scaled together;
- beyond the last zone, or moving away from everything: unchanged.

Points already inside the footprint (the robot's own arm seen by its sensor, a box being
pushed) never stop it; they do not enter the footprint, they are in it. Pure numpy.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ocu.nav.geometry import Points
from ocu.profile import Footprint, ZoneSettings

# Resolution of the travel-to-contact search along the arc.
STEP_M = 0.01
# How far past the last zone the search looks.
HORIZON_MARGIN_M = 0.3
AHEAD = "ahead"
BEHIND = "behind"
IN_THE_TURN = "in the turn"


@dataclass(frozen=True)
class ZoneDecision:
    """What the zones let through, and why."""

    linear_m_s: float
    angular_rad_s: float
    # The travel to contact along the motion asked for (None: nothing within the horizon).
    distance_m: float | None = None
    direction: str = AHEAD
    # The zone that capped the command: -1 the stop zone, k zone k, None none.
    zone: int | None = None
    limited: bool = False

    @property
    def stopped(self) -> bool:
        """Whether the zones stopped a motion toward an obstacle."""
        return self.zone == -1 and self.limited

    def message(self) -> str:
        """The status bar's words: 'slowed: obstacle 0.74 m ahead' ('' when not limited)."""
        if not self.limited or self.distance_m is None:
            return ""
        verb = "stopped" if self.stopped else "slowed"
        return f"{verb}: obstacle {self.distance_m:.2f} m {self.direction}"


def direction_of(linear_m_s: float) -> str:
    """The words for where an obstacle in the motion's way is."""
    if linear_m_s > 0.0:
        return AHEAD
    if linear_m_s < 0.0:
        return BEHIND
    return IN_THE_TURN


def fastest_point_speed(footprint: Footprint, linear_m_s: float, angular_rad_s: float) -> float:
    """Speed of the footprint's fastest point (a corner, in a turn) for a twist."""
    return max(
        math.hypot(linear_m_s - angular_rad_s * y, angular_rad_s * x)
        for x, y in footprint.corners_m
    )


def travel_to_contact(
    points: Points,
    footprint: Footprint,
    linear_m_s: float,
    angular_rad_s: float,
    horizon_m: float,
) -> float | None:
    """How far the fastest footprint point travels along the twist's arc before a scan
    point (robot frame, (N, 2)) enters the footprint; None: none within `horizon_m`."""
    speed = fastest_point_speed(footprint, linear_m_s, angular_rad_s)
    if speed <= 0.0 or len(points) == 0:
        return None
    xy = np.asarray(points, dtype=np.float64)
    # Nothing farther than the horizon plus the footprint's reach can be touched.
    reach = horizon_m + math.hypot(max(footprint.front_m, footprint.rear_m), footprint.half_width_m)
    xy = xy[np.hypot(xy[:, 0], xy[:, 1]) <= reach]
    inside_now = _inside(xy[:, 0], xy[:, 1], footprint)
    xy = xy[~inside_now]
    if len(xy) == 0:
        return None
    # Per metre of the fastest point's travel: this much forward, this much turn.
    v, w = linear_m_s / speed, angular_rad_s / speed
    travel = np.arange(STEP_M, horizon_m + STEP_M / 2, STEP_M)
    theta = w * travel
    if abs(w) > 1e-12:
        px, py = v * np.sin(theta) / w, v * (1.0 - np.cos(theta)) / w
    else:
        px, py = v * travel, np.zeros_like(travel)
    # Every point in the robot's frame after each step (K, N).
    c, s = np.cos(theta)[:, None], np.sin(theta)[:, None]
    dx, dy = xy[None, :, 0] - px[:, None], xy[None, :, 1] - py[:, None]
    local_x, local_y = c * dx + s * dy, -s * dx + c * dy
    hit = _inside(local_x, local_y, footprint).any(axis=1)
    if not hit.any():
        return None
    first = int(np.argmax(hit))
    # The footprint touches between the last free step and this one: the free one counts.
    return float(travel[first] - STEP_M)


def _inside(x: Points, y: Points, footprint: Footprint) -> np.ndarray:
    return np.asarray(
        (x <= footprint.front_m) & (x >= -footprint.rear_m) & (np.abs(y) <= footprint.half_width_m)
    )


def cap_ratio(
    linear_m_s: float, angular_rad_s: float, max_linear_m_s: float, max_angular_rad_s: float
) -> tuple[float, float]:
    """Both speeds divided by the larger of v/v_max and ω/ω_max when it exceeds 1 (eq. 5.2)."""
    over = max(abs(linear_m_s) / max_linear_m_s, abs(angular_rad_s) / max_angular_rad_s)
    if over <= 1.0:
        return linear_m_s, angular_rad_s
    return linear_m_s / over, angular_rad_s / over


def apply_zones(
    linear_m_s: float,
    angular_rad_s: float,
    points: Points,
    footprint: Footprint,
    settings: ZoneSettings,
    *,
    margin_m: float = 0.0,
) -> ZoneDecision:
    """The command the zones let through for scan points in the robot's frame."""
    if linear_m_s == 0.0 and angular_rad_s == 0.0:
        return ZoneDecision(0.0, 0.0)
    horizon = settings.within_m[-1] + max(margin_m, 0.0) + HORIZON_MARGIN_M
    distance = travel_to_contact(points, footprint, linear_m_s, angular_rad_s, horizon)
    direction = direction_of(linear_m_s)
    if distance is None:
        return ZoneDecision(linear_m_s, angular_rad_s, None, direction)
    effective = distance - max(margin_m, 0.0)
    if effective < settings.stop_m:
        return ZoneDecision(0.0, 0.0, distance, direction, zone=-1, limited=True)
    for index, within in enumerate(settings.within_m):
        if effective < within:
            v, w = cap_ratio(
                linear_m_s,
                angular_rad_s,
                settings.max_linear_m_s[index],
                settings.max_angular_rad_s[index],
            )
            limited = (v, w) != (linear_m_s, angular_rad_s)
            return ZoneDecision(v, w, distance, direction, zone=index, limited=limited)
    return ZoneDecision(linear_m_s, angular_rad_s, distance, direction)

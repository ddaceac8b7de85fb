"""Safety zones (seed 002, Algorithm 5.1) as travel to contact along the commanded motion."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ocu.nav.zones import apply_zones, cap_ratio, fastest_point_speed, travel_to_contact
from ocu.profile import Footprint, ZoneSettings

FOOTPRINT = Footprint(front_m=0.62, rear_m=0.36, half_width_m=0.39)
ZONES = ZoneSettings(
    stop_m=0.10,
    within_m=(0.333, 0.633, 0.933),
    max_linear_m_s=(0.2, 0.25, 0.35),
    max_angular_rad_s=(0.3, 0.5, 0.8),
)


def wall_x(x_m: float) -> np.ndarray:
    """Scan points of a wall across the robot's path at x."""
    y = np.linspace(-3.0, 3.0, 301)
    return np.stack([np.full_like(y, x_m), y], axis=-1)


def wall_y(y_m: float) -> np.ndarray:
    x = np.linspace(-3.0, 3.0, 301)
    return np.stack([x, np.full_like(x, y_m)], axis=-1)


def test_travel_to_contact_straight_ahead_and_behind() -> None:
    points = wall_x(1.5)
    assert travel_to_contact(points, FOOTPRINT, 0.3, 0.0, 2.0) == pytest.approx(0.88, abs=0.011)
    assert travel_to_contact(points, FOOTPRINT, -0.3, 0.0, 2.0) is None
    assert travel_to_contact(wall_x(-1.0), FOOTPRINT, -0.3, 0.0, 2.0) == pytest.approx(
        0.64, abs=0.011
    )


def test_a_wall_beside_the_robot_matters_to_a_turn_not_to_driving_straight() -> None:
    side = wall_y(0.55)
    assert travel_to_contact(side, FOOTPRINT, 0.45, 0.0, 2.0) is None
    turn = travel_to_contact(side, FOOTPRINT, 0.0, 0.8, 2.0)
    assert turn is not None
    assert turn < 0.3


def test_points_inside_the_footprint_never_stop_it() -> None:
    own_arm = np.array([[0.3, 0.0], [0.5, 0.1]])
    assert travel_to_contact(own_arm, FOOTPRINT, 0.45, 0.3, 2.0) is None


@pytest.mark.parametrize(
    ("wall_m", "zone", "expected"),
    [
        (0.62 + 1.5, None, (0.45, 0.0)),  # beyond every zone: untouched
        (0.62 + 0.8, 2, (0.35, 0.0)),
        (0.62 + 0.5, 1, (0.25, 0.0)),
        (0.62 + 0.2, 0, (0.2, 0.0)),
        (0.62 + 0.05, -1, (0.0, 0.0)),  # the stop zone
    ],
)
def test_each_zone_caps_the_speed_toward_the_obstacle(
    wall_m: float, zone: int | None, expected: tuple[float, float]
) -> None:
    decision = apply_zones(0.45, 0.0, wall_x(wall_m), FOOTPRINT, ZONES)
    assert decision.zone == zone
    assert (decision.linear_m_s, decision.angular_rad_s) == pytest.approx(expected)


def test_capping_keeps_the_turn_radius() -> None:
    # An arc toward the wall: both speeds scaled by one factor (eq. 5.1-5.2).
    decision = apply_zones(0.45, 0.3, wall_x(0.62 + 0.45), FOOTPRINT, ZONES)
    assert decision.limited
    assert decision.linear_m_s / decision.angular_rad_s == pytest.approx(0.45 / 0.3)
    assert decision.linear_m_s <= 0.25 + 1e-12
    assert cap_ratio(0.4, 0.8, 0.2, 0.5) == pytest.approx((0.2, 0.4))
    assert cap_ratio(0.1, 0.1, 0.2, 0.5) == (0.1, 0.1)


def test_the_margin_for_delay_moves_the_zones_outward() -> None:
    points = wall_x(0.62 + 0.7)
    assert apply_zones(0.45, 0.0, points, FOOTPRINT, ZONES).zone == 2
    assert apply_zones(0.45, 0.0, points, FOOTPRINT, ZONES, margin_m=0.2).zone == 1


def test_the_status_words() -> None:
    decision = apply_zones(0.45, 0.0, wall_x(0.62 + 0.74), FOOTPRINT, ZONES)
    assert decision.message() == "slowed: obstacle 0.73 m ahead"
    stop = apply_zones(-0.3, 0.0, wall_x(-0.36 - 0.05), FOOTPRINT, ZONES)
    assert stop.stopped
    assert stop.message() == "stopped: obstacle 0.04 m behind"
    free = apply_zones(0.1, 0.0, wall_x(5.0), FOOTPRINT, ZONES)
    assert not free.limited
    assert free.message() == ""


def test_the_fastest_point_of_a_turn_is_a_corner() -> None:
    assert fastest_point_speed(FOOTPRINT, 0.0, 1.0) == pytest.approx(math.hypot(0.62, 0.39))
    assert fastest_point_speed(FOOTPRINT, 0.3, 0.0) == pytest.approx(0.3)

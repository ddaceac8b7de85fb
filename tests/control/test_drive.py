"""Drive scaling keeps the turn radius (seed 002, eq. 5.1-5.4)."""

from __future__ import annotations

import math

import pytest

from ocu.control.drive import DriveBounds, DriveError, scale_drive

BOUNDS = DriveBounds(max_linear_m_s=0.3, max_angular_rad_s=0.8, min_linear_m_s=0.2,
                     min_angular_rad_s=0.2)  # fmt: skip


@pytest.mark.parametrize(
    ("request_", "expected"),
    [
        ((0.1, 0.05), (0.2, 0.1)),  # both lifted by 2: the 2 m arc stays a 2 m arc
        ((0.1, 0.0), (0.2, 0.0)),  # the paper's rule for a straight line
        ((0.0, -0.1), (0.0, -0.2)),
        ((0.6, 0.4), (0.3, 0.2)),  # both halved: linear at its maximum
        ((0.25, 0.1), (0.25, 0.1)),  # within bounds: unchanged
        ((-0.05, 0.5), (-0.05, 0.5)),  # turn above its minimum: nothing lifted
        ((0.0, 0.0), (0.0, 0.0)),
    ],
)
def test_one_factor_for_both(request_: tuple[float, float], expected: tuple[float, float]) -> None:
    v, w = scale_drive(*request_, BOUNDS)
    assert (v, w) == pytest.approx(expected)
    if request_[0] and request_[1]:
        assert v / w == pytest.approx(request_[0] / request_[1])


def test_tiny_speeds_are_zero_before_the_minimum_rule() -> None:
    assert scale_drive(1e-300, 0.0, BOUNDS) == (0.0, 0.0)
    assert scale_drive(1e-300, 0.1, BOUNDS) == pytest.approx((0.0, 0.2))


def test_maxima_win_over_the_minima() -> None:
    # The operator set the linear maximum below the servos' starting speed.
    low_max = DriveBounds(
        max_linear_m_s=0.1, max_angular_rad_s=0.8, min_linear_m_s=0.2, min_angular_rad_s=0.2
    )
    assert scale_drive(0.05, 0.0, low_max) == pytest.approx((0.1, 0.0))
    v, w = scale_drive(0.05, 0.02, low_max)
    assert v == pytest.approx(0.1)
    assert v / w == pytest.approx(0.05 / 0.02)


def test_zero_maximum_stops_everything() -> None:
    stopped = DriveBounds(max_linear_m_s=0.0, max_angular_rad_s=0.8)
    assert scale_drive(0.1, 0.3, stopped) == (0.0, 0.0)
    assert scale_drive(0.0, 0.3, stopped) == pytest.approx((0.0, 0.3))


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_non_finite_is_refused(bad: float) -> None:
    with pytest.raises(DriveError, match="finite"):
        scale_drive(bad, 0.0, BOUNDS)
    with pytest.raises(DriveError, match="finite"):
        DriveBounds(max_linear_m_s=bad, max_angular_rad_s=1.0)

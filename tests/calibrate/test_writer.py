"""The calibrated profile's document: measured keys and the maxima they bound."""

from __future__ import annotations

from ocu.calibrate.session import CalibrationResult, Measured
from ocu.calibrate.writer import calibrated_data
from ocu.profile import AXIS_MAX, load_profile_data, parse_profile


def result_with(*items: Measured) -> CalibrationResult:
    return CalibrationResult(measured={item.key: item for item in items})


def test_a_measured_si_scale_lowers_the_maxima_it_cannot_carry() -> None:
    base = load_profile_data()
    scale = AXIS_MAX / 0.3  # the axis reaches only 0.3 m/s at this scale
    data = calibrated_data(
        base, result_with(Measured("si.linear_axis_per_m_s", scale, "drive past a wall"))
    )
    channel = data["channels"]["drive_linear"]
    assert channel["hard_max"] == 0.3
    assert channel["default_max"] <= 0.3
    assert "lowered" in data["measured"]["channels.drive_linear.hard_max"]["how"]
    assert data["channels"]["drive_turn"] == base["channels"]["drive_turn"]
    parse_profile(data)  # loads: every maximum fits the axis


def test_a_measured_channel_scale_lowers_only_that_channel() -> None:
    base = load_profile_data()
    data = calibrated_data(
        base, result_with(Measured("channels.shoulder.axis_per_unit", AXIS_MAX / 0.2, "sweep"))
    )
    assert data["channels"]["shoulder"]["hard_max"] == 0.2
    assert data["channels"]["elbow"]["hard_max"] == base["channels"]["elbow"]["hard_max"]
    parse_profile(data)


def test_a_scale_that_fits_changes_no_maximum() -> None:
    base = load_profile_data()
    scale = float(base["si"]["linear_axis_per_m_s"])
    data = calibrated_data(
        base, result_with(Measured("si.linear_axis_per_m_s", scale, "drive past a wall"))
    )
    assert data["channels"] == base["channels"]
    assert "channels.drive_linear.hard_max" not in data["measured"]

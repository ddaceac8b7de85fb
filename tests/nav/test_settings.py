"""The profile's [navigation] table: the Engineer's values and every refusal by key."""

from __future__ import annotations

import copy
import tomllib
from typing import Any

import pytest

from ocu.profile import ProfileError, RobotProfile, default_profile_path, parse_profile

SHIPPED: dict[str, Any] = tomllib.loads(default_profile_path().read_text(encoding="utf-8"))


def edited(table: str | None, key: str, value: object) -> dict[str, Any]:
    data = copy.deepcopy(SHIPPED)
    target = data["navigation"] if table is None else data["navigation"][table]
    target[key] = value
    return data


def test_the_engineers_navigation_facts(profile: RobotProfile) -> None:
    navigation = profile.navigation
    assert navigation.footprint is not None
    assert navigation.footprint.front_m == 0.62
    assert navigation.footprint.swing_radius_m == pytest.approx(0.7325, abs=1e-4)
    assert navigation.zones.within_m == (0.333, 0.633, 0.933)
    assert navigation.assist.samson_b == 40.0
    assert navigation.assist.samson_xi == 0.8
    assert profile.extension is not None
    assert profile.extension.frame_types.scan == 0x13
    assert profile.cameras[3].mount is not None
    assert profile.cameras[3].mount.yaw_rad == pytest.approx(3.14159, abs=1e-4)


def test_a_profile_without_the_table_has_no_footprint() -> None:
    data = copy.deepcopy(SHIPPED)
    del data["navigation"]
    assert parse_profile(data).navigation.footprint is None


@pytest.mark.parametrize(
    ("table", "key", "value", "message"),
    [
        (None, "footprint_front_m", 0.0, r"navigation\.footprint_front_m: must be >= 0\.01"),
        (None, "footprint_length_m", 1.0, r"footprint_length_m: unknown key; did you mean"),
        ("zones", "within_m", [0.6, 0.3, 0.9], r"within_m: must grow from zone to zone"),
        ("zones", "within_m", [0.05, 0.3, 0.9], r"the first zone must lie beyond stop_m"),
        ("zones", "max_linear_m_s", [0.2, 0.3], r"max_linear_m_s: must be a list of 3"),
        ("assist", "samson_xi", 1.5, r"assist\.samson_xi: must be <= 1\.0"),
        ("odometry", "stale_after_s", 0.0, r"odometry\.stale_after_s: must be >= 0\.05"),
    ],
)
def test_bad_navigation_values_are_refused_by_key(
    table: str | None, key: str, value: object, message: str
) -> None:
    with pytest.raises(ProfileError, match=message):
        parse_profile(edited(table, key, value))


def test_the_scan_id_must_differ_from_the_others() -> None:
    data = copy.deepcopy(SHIPPED)
    data["extension"]["frame_types"]["scan"] = data["extension"]["frame_types"]["status"]
    with pytest.raises(ProfileError, match="the IDs must differ"):
        parse_profile(data)

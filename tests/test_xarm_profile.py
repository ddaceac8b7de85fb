"""The xArm profile: the shipped xarm1s (seed 003's defaults), the angle mapping, and every
malformed value refused by name."""

from __future__ import annotations

import math
import tomllib
from importlib import resources
from typing import Any

import pytest

from ocu.profile.keys import ProfileError
from ocu.profile.xarm import load_xarm_profile, parse_xarm_profile


def _data() -> dict[str, Any]:
    path = resources.files("ocu") / "profiles" / "xarm" / "xarm1s.toml"
    return tomllib.loads(path.read_text(encoding="utf-8"))


def test_shipped_xarm1s_has_seed_003_defaults() -> None:
    profile = load_xarm_profile("xarm1s")
    assert profile.baud == 115200
    assert profile.range_deg == 240.0
    assert [(j.name, j.servo) for j in profile.joints] == [
        ("base", 6),
        ("shoulder", 5),
        ("elbow", 4),
        ("wrist_pitch", 3),
        ("wrist_roll", 2),
        ("gripper", 1),
    ]
    assert profile.servo.damping_ratio == 0.18
    assert profile.servo.natural_frequency_rad_s == 5.83
    assert profile.link_lengths_m == (0.061, 0.102, 0.096, 0.166)


def test_angle_mapping_round_trips_with_sign_and_offset() -> None:
    data = _data()
    data["joints"][1].update(sign=-1, offset=20)
    profile = parse_xarm_profile(data)
    shoulder = profile.joint("shoulder")
    assert profile.angle_rad(shoulder, 520) == 0.0
    # 240° over 1000 units: 1000 / 240 units a degree; sign -1 turns the other way.
    assert profile.angle_rad(shoulder, 520 - 1000 / 240 * 30) == pytest.approx(math.radians(30))
    assert profile.raw_units(shoulder, math.radians(30)) == pytest.approx(520 - 125)


@pytest.mark.parametrize(
    ("change", "match"),
    [
        (lambda d: d.update(baud=12345), "baud must be one of"),
        (lambda d: d.update(range_deg=0), "range_deg must be > 0"),
        (lambda d: d.update(colour="red"), r"unknown keys \['colour'\]"),
        (lambda d: d["servo"].update(damping_ratio="x"), "damping_ratio must be a number"),
        (lambda d: d["timing"].update(jog_move_s=0.01), "jog_move_s must be longer"),
        (lambda d: d["joints"][0].update(sign=2), "sign must be 1 or -1"),
        (lambda d: d["joints"][0].update(servo=5), "servo is given twice"),
        (lambda d: d["joints"][0].update(min=900, max=100), "min must be below max"),
        (lambda d: d["joints"][0].update(max=1001), "max must be an integer 0-1000"),
        (lambda d: d.update(link_lengths_m=[0.1]), "link_lengths_m must list 4"),
    ],
)
def test_bad_values_are_refused_by_name(change: Any, match: str) -> None:
    data = _data()
    change(data)
    with pytest.raises(ProfileError, match=match):
        parse_xarm_profile(data)


def test_unknown_name_says_what_is_shipped() -> None:
    with pytest.raises(ProfileError, match="not a shipped name"):
        load_xarm_profile("xarm9")

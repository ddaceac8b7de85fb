"""The profile's video facts: extension IDs, video settings, per-camera calibration."""

from __future__ import annotations

import copy
import tomllib
from typing import Any

import pytest

from ocu.profile import ProfileError, RobotProfile, default_profile_path, parse_profile

SHIPPED: dict[str, Any] = tomllib.loads(default_profile_path().read_text(encoding="utf-8"))


def edited(path: tuple[str, ...], value: object) -> dict[str, Any]:
    data = copy.deepcopy(SHIPPED)
    table = data
    for key in path[:-1]:
        table = table[key]
    if value is None:
        del table[path[-1]]
    else:
        table[path[-1]] = value
    return data


def test_shipped_video_facts(profile: RobotProfile) -> None:
    assert profile.extension is not None
    types = profile.extension.frame_types
    assert (types.hello, types.video_fragment, types.status) == (0x10, 0x11, 0x12)
    assert profile.video.battery_warning_percent == 20.0
    assert [c.name for c in profile.cameras] == list(profile.link.camera_names)
    assert all(c.calibration is not None for c in profile.cameras)
    assert "extension.frame_types" in profile.assumptions


def test_profile_without_extension_or_cameras_is_vendor_only() -> None:
    data = copy.deepcopy(SHIPPED)
    for key in ("extension", "video", "cameras"):
        del data[key]
    profile = parse_profile(data)
    assert profile.extension is None
    assert all(c.calibration is None and c.colour == "off" for c in profile.cameras)


@pytest.mark.parametrize(
    ("path", "value", "message"),
    [
        (("extension", "frame_types", "status"), 0x02, r"must differ from each other and from"),
        (
            ("extension", "frame_types", "hello"),
            None,
            r"^profile\.extension\.frame_types\.hello: missing$",
        ),
        (
            ("extension", "max_datagram_bytes"),
            70000,
            r"max_datagram_bytes: must be in \[64, 65507\]",
        ),
        (("extension", "probe"), 1, r"^profile\.extension\.probe: must be true or false, got 1$"),
        (("video", "battery_warning_percent"), 120, r"battery_warning_percent: must be <= 100"),
        (("video", "reassembly_max_frames"), 0, r"reassembly_max_frames: must be in \[1, 1024\]"),
        (
            ("cameras", "front", "model"),
            "kannala",
            r"^profile\.cameras\.front\.model: must be one of",
        ),
        (
            ("cameras", "front", "distortion"),
            [0.1],
            r"front\.distortion: must be a list of 4 finite",
        ),
        (
            ("cameras", "zoom", "distortion"),
            [0.1] * 6,
            r"zoom\.distortion: must be a list of 4 or 5",
        ),
        (
            ("cameras", "rear", "focal_px"),
            [0.0, 1.0],
            r"rear\.focal_px: every value must be >= 1e-06",
        ),
        (("cameras", "rear", "centre_px"), [900.0, 240.0], r"centre_px: must lie inside"),
        (("cameras", "rear", "calibration_size_px"), [640.5, 480], r"must be whole pixels"),
        (("cameras", "stereo", "colour"), "auto", r"stereo\.colour: must be one of"),
        (("cameras", "stereo", "balance"), 2.0, r"stereo\.balance: must be <= 1\.0"),
        (("cameras", "stereo", "fixed_gains_rgb"), [1.0, -1.0, 1.0], r"every value must be >= 0"),
        (
            ("cameras", "nose"),
            {},
            r"^profile\.cameras\.nose: not in link\.camera_names; known: front, zoom",
        ),
        (("link", "camera_names"), ["a", "a"], r"names must be distinct"),
    ],
)
def test_video_keys_are_validated(path: tuple[str, ...], value: object, message: str) -> None:
    # Without a file, the profile's source comes first: "<profile>: profile.cameras...".
    with pytest.raises(ProfileError, match=message.replace("^", "^<profile>: ", 1)):
        parse_profile(edited(path, value))

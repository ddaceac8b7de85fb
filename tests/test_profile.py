"""The robot profile: the shipped Engineer profile, and every validation error by key."""

from __future__ import annotations

import copy
import dataclasses
import datetime as dt
import math
import re
import tomllib
from pathlib import Path
from typing import Any

import pytest

from ocu.nav.world import parse_world
from ocu.profile import (
    AXIS_MAX,
    ProfileError,
    RobotProfile,
    assumption_covers,
    default_profile_path,
    load_profile,
    load_profile_data,
    parse_profile,
    profile_to_toml,
    write_profile_data,
)
from ocu.sim.simulator import RobotSimulator

SHIPPED_TEXT = default_profile_path().read_text(encoding="utf-8")
SHIPPED_DATA: dict[str, Any] = tomllib.loads(SHIPPED_TEXT)

# Paper constants (seed 000, section 3.1): axis value per m/s and per rad/s of the chassis.
LINEAR_AXIS_PER_M_S = 71553.837
ROTATION_AXIS_PER_RAD_S = 25171.216

DELETE = object()

# The Engineer's channels, in the order the shipped profile lists them.
ENGINEER_CHANNELS = (
    "drive_linear",
    "drive_turn",
    "flippers",
    "waist",
    "shoulder",
    "elbow",
    "neck",
    "gripper",
)


def _edited(path: tuple[str, ...], value: object) -> dict[str, Any]:
    """A deep copy of the shipped profile with one key set or deleted."""
    data = copy.deepcopy(SHIPPED_DATA)
    table = data
    for key in path[:-1]:
        table = table[key]
    if value is DELETE:
        del table[path[-1]]
    else:
        table[path[-1]] = value
    return data


def _in_memory(message: str) -> str:
    """The pattern of an error of parse_profile(data) without a file: its source comes first."""
    return message.replace("^", "^<profile>: ", 1)


def _write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "robot.toml"
    path.write_text(text, encoding="utf-8")
    return path


def _replace_once(text: str, old: str, new: str) -> str:
    assert text.count(old) == 1, f"{old!r} is not unique in the shipped profile"
    return text.replace(old, new)


@pytest.fixture(scope="module")
def profile() -> RobotProfile:
    return load_profile()


# --- the shipped profile ------------------------------------------------------------------


def test_shipped_profile_loads(profile: RobotProfile) -> None:
    assert profile.name == "Servosila Engineer"
    assert profile.source == str(default_profile_path())
    assert Path(profile.source).name == "engineer.toml"


def test_paper_si_constants(profile: RobotProfile) -> None:
    assert profile.linear_axis_per_m_s == LINEAR_AXIS_PER_M_S
    assert profile.rotation_axis_per_rad_s == ROTATION_AXIS_PER_RAD_S
    assert profile.channels["drive_linear"].axis_per_unit == LINEAR_AXIS_PER_M_S
    assert profile.channels["drive_turn"].axis_per_unit == ROTATION_AXIS_PER_RAD_S


def test_documented_link_facts(profile: RobotProfile) -> None:
    assert profile.link.send_rate_hz == 5.0
    assert profile.link.robot_watchdog_s == 1.0
    assert profile.link.telemetry_rate_hz == 1.0
    assert profile.link.send_rate_min_hz <= profile.link.send_rate_hz
    assert profile.link.send_rate_hz <= profile.link.send_rate_max_hz
    assert len(profile.link.camera_names) == 4
    types = profile.link.frame_types
    assert (types.rcp, types.telemetry, types.video) == (0x01, 0x02, 0x03)
    assert profile.link.port == 10000


def test_drive_minimum_speed_from_the_paper(profile: RobotProfile) -> None:
    assert profile.channels["drive_linear"].min_speed == 0.2
    assert profile.channels["drive_turn"].min_speed == 0.2


def test_every_channel_fits_the_int16_axis(profile: RobotProfile) -> None:
    assert tuple(profile.channels) == ENGINEER_CHANNELS
    assert profile.drive_channels == ("drive_linear", "drive_turn")
    assert profile.switch_channels == ["flippers", "gripper"]
    assert [c.name for c in profile.channels.values() if c.locked_while_driving] == ["waist"]
    assert profile.channels["gripper"].directions == ("open", "close")
    for channel in profile.channels.values():
        assert 0 <= channel.axis <= 15
        assert 0.0 <= channel.min_speed <= channel.default_max <= channel.hard_max
        assert channel.hard_max * channel.axis_per_unit <= AXIS_MAX
        assert round(channel.hard_max * channel.axis_per_unit) <= 32767


def test_axes_and_device_ids_are_distinct(profile: RobotProfile) -> None:
    axes = [c.axis for c in profile.channels.values()]
    assert len(set(axes)) == len(axes)
    ids = [m.device_id for m in profile.motors.values()]
    assert len(set(ids)) == len(ids)
    assert len(profile.motors) <= 10
    assert profile.torch_button != profile.camera_button


def test_motors(profile: RobotProfile) -> None:
    for name in ("left_track", "right_track"):
        track = profile.motors[name]
        assert not track.has_position
        assert track.limits_rad is None
    assert {m.track for m in profile.motors.values()} == {"left", "right", None}
    waist = profile.motors["waist"]
    assert waist.has_position
    assert waist.limits_rad == (math.radians(-170.0), math.radians(170.0))
    assert profile.motor_by_device(waist.device_id) is waist
    assert profile.motor_by_device(255) is None
    assert profile.motor_for_channel("waist") is waist
    assert profile.motor_for_channel("drive_linear") is None
    for motor in profile.positioned_motors:
        assert motor.channel in profile.channels
        assert motor.limits_rad is not None


def test_parse_matches_load(profile: RobotProfile) -> None:
    parsed = parse_profile(copy.deepcopy(SHIPPED_DATA))
    assert parsed.source == "<profile>"
    assert dataclasses.replace(parsed, source=profile.source) == profile


def test_load_from_a_path(tmp_path: Path, profile: RobotProfile) -> None:
    path = _write(tmp_path, SHIPPED_TEXT)
    loaded = load_profile(path)
    assert loaded.source == str(path)
    assert dataclasses.replace(loaded, source=profile.source) == profile
    assert load_profile(str(path)) == loaded


def _matches(data: Any, parts: list[str]) -> int:
    """How many keys a dotted pattern names; `*` stands for every table at its level."""
    if not parts:
        return 1
    if not isinstance(data, dict):
        return 0
    head, rest = parts[0], parts[1:]
    if head == "*":
        return sum(_matches(value, rest) for value in data.values() if isinstance(value, dict))
    return _matches(data[head], rest) if head in data else 0


def test_assumptions_name_existing_keys(profile: RobotProfile) -> None:
    assert profile.assumptions == tuple(SHIPPED_DATA["assumptions"])
    assert profile.assumptions
    for key in profile.assumptions:
        assert _matches(SHIPPED_DATA, key.split(".")) > 0, key


def test_assumption_patterns_are_checked() -> None:
    assert _matches(SHIPPED_DATA, ["channels", "*", "axis"]) == len(ENGINEER_CHANNELS)
    assert _matches(SHIPPED_DATA, ["motors", "*", "ticks_per_rad"]) == 8
    assert _matches(SHIPPED_DATA, ["link", "no_such_key"]) == 0
    assert _matches(SHIPPED_DATA, ["channels", "*", "no_such_key"]) == 0


# --- validation errors, one per key -------------------------------------------------------

_LIMITS = r"must be \[low, high\] with low < high$"


@pytest.mark.parametrize(
    ("path", "value", "message"),
    [
        # missing keys
        (("name",), DELETE, r"^profile\.name: missing$"),
        (("link",), DELETE, r"^profile\.link: missing$"),
        (("link", "port"), DELETE, r"^profile\.link\.port: missing$"),
        (
            ("link", "frame_types", "video"),
            DELETE,
            r"^profile\.link\.frame_types\.video: missing$",
        ),
        (
            ("si", "linear_axis_per_m_s"),
            DELETE,
            r"^profile\.si\.linear_axis_per_m_s: missing$",
        ),
        (("chassis",), DELETE, r"^profile\.chassis: missing$"),
        # Channels are the profile's own: without one, the motor that names it is wrong.
        (
            ("channels", "neck"),
            DELETE,
            r"^profile\.motors\.neck\.channel: unknown channel 'neck'; known: ",
        ),
        (("channels", "waist", "role"), "drive_linear", r"all have role 'drive_linear'"),
        (("channels", "drive_turn", "role"), DELETE, r"needs both roles"),
        (("channels", "flippers", "directions"), ["up"], r"flippers\.directions: two words"),
        (
            ("channels", "waist", "axis"),
            DELETE,
            r"^profile\.channels\.waist\.axis: missing$",
        ),
        (
            ("motors", "waist", "zero_offset_ticks"),
            DELETE,
            r"^profile\.motors\.waist\.zero_offset_ticks: missing$",
        ),
        (("buttons", "torch"), DELETE, r"^profile\.buttons\.torch: missing$"),
        (("motors",), DELETE, r"^profile\.motors: missing$"),
        # wrong types
        (("link",), 5, r"^profile\.link: must be a table$"),
        (
            ("link", "port"),
            "10000",
            r"^profile\.link\.port: must be an integer, got '10000'$",
        ),
        (
            ("link", "port"),
            10000.0,
            r"^profile\.link\.port: must be an integer, got 10000\.0$",
        ),
        (
            ("link", "send_rate_hz"),
            "fast",
            r"^profile\.link\.send_rate_hz: must be a number, got 'fast'$",
        ),
        (
            ("link", "send_rate_hz"),
            True,
            r"^profile\.link\.send_rate_hz: must be a number, got True$",
        ),
        (
            ("channels", "drive_linear", "axis"),
            True,
            r"^profile\.channels\.drive_linear\.axis: must be an integer, got True$",
        ),
        (
            ("link", "address"),
            192,
            r"^profile\.link\.address: must be a non-empty string$",
        ),
        (
            ("channels", "waist", "unit"),
            "",
            r"^profile\.channels\.waist\.unit: must be a non-empty",
        ),
        (
            ("link", "camera_names"),
            [],
            r"^profile\.link\.camera_names: must be a non-empty list",
        ),
        (
            ("link", "camera_names"),
            ["a", 2],
            r"^profile\.link\.camera_names: must be a non-empty",
        ),
        (
            ("assumptions",),
            "link.port",
            r"^profile\.assumptions: must be a list of key names$",
        ),
        # non-finite numbers
        (
            ("channels", "drive_linear", "hard_max"),
            math.inf,
            r"^profile\.channels\.drive_linear\.hard_max: must be finite, got inf$",
        ),
        (
            ("si", "joint_axis_per_rad_s"),
            math.nan,
            r"^profile\.si\.joint_axis_per_rad_s: must be finite, got nan$",
        ),
        (
            ("motors", "waist", "ticks_per_rad"),
            math.inf,
            r"^profile\.motors\.waist\.ticks_per_rad: must be finite, got inf$",
        ),
        (
            ("link", "robot_watchdog_s"),
            -math.inf,
            r"^profile\.link\.robot_watchdog_s: must be finite, got -inf$",
        ),
        # values out of range
        (
            ("channels", "drive_linear", "default_max"),
            0.5,
            r"^profile\.channels\.drive_linear\.default_max: must be <= 0\.45, got 0\.5$",
        ),
        (
            ("channels", "drive_linear", "hard_max"),
            0.5,
            r"^profile\.channels\.drive_linear\.hard_max: 0\.5 needs axis value 35777, "
            r"over the int16 range; at most 0\.4579$",
        ),
        (
            ("channels", "drive_turn", "hard_max"),
            1.31,
            r"^profile\.channels\.drive_turn\.hard_max: 1\.31 needs axis value 32974, "
            r"over the int16 range; at most 1\.3018$",
        ),
        (
            ("si", "joint_axis_per_rad_s"),
            40000.0,
            r"^profile\.channels\.flippers\.hard_max: 1\.0 needs axis value 40000, over the int16",
        ),
        (
            ("channels", "flippers", "min_speed"),
            0.6,
            r"^profile\.channels\.flippers\.min_speed: above default_max \(0\.5\)$",
        ),
        (
            ("channels", "flippers", "min_speed"),
            -0.1,
            r"^profile\.channels\.flippers\.min_speed: must be >= 0\.0, got -0\.1$",
        ),
        (
            ("channels", "waist", "axis"),
            16,
            r"^profile\.channels\.waist\.axis: must be in \[0, 15\], got 16$",
        ),
        (
            ("channels", "waist", "scale"),
            "angular",
            r"^profile\.channels\.waist\.scale: must be one of "
            r"\('linear', 'rotation', 'joint'\), got 'angular'$",
        ),
        (("link", "port"), 0, r"^profile\.link\.port: must be in \[1, 65535\], got 0$"),
        (
            ("link", "port"),
            65536,
            r"^profile\.link\.port: must be in \[1, 65535\], got 65536$",
        ),
        (
            ("link", "send_rate_hz"),
            100.0,
            r"^profile\.link\.send_rate_hz: must be <= 50\.0, got 100\.0$",
        ),
        (
            ("motors", "waist", "device_id"),
            256,
            r"^profile\.motors\.waist\.device_id: must be in \[0, 255\], got 256$",
        ),
        (
            ("motors", "waist", "zero_offset_ticks"),
            2**32,
            r"^profile\.motors\.waist\.zero_offset_ticks: must be in \[0, 4294967295\]",
        ),
        (
            ("motors", "left_track", "track"),
            "middle",
            r"^profile\.motors\.left_track\.track: must be 'left' or 'right'$",
        ),
        # duplicates and references
        (
            ("channels", "waist", "axis"),
            3,
            r"^profile\.channels: two channels share one axis$",
        ),
        (
            ("motors", "waist", "device_id"),
            5,
            r"^profile\.motors: two motors share one device_id$",
        ),
        (
            ("motors", "waist", "channel"),
            "tail",
            r"^profile\.motors\.waist\.channel: unknown channel 'tail'; ",
        ),
        # A robot may have a channel more (the profile names them), on an axis of its own.
        (
            ("channels", "tail"),
            {"axis": 2, "scale": "joint", "unit": "rad/s", "min_speed": 0.0}
            | {"default_max": 0.1, "hard_max": 0.2},
            r"^profile\.channels: two channels share one axis$",
        ),
        # motor limits
        (
            ("motors", "waist", "limits_deg"),
            [10.0, -10.0],
            r"^profile\.motors\.waist\.limits_deg: ",
        ),
        (("motors", "waist", "limits_deg"), [5.0, 5.0], _LIMITS),
        (("motors", "waist", "limits_deg"), [-10.0], _LIMITS),
        (("motors", "waist", "limits_deg"), [-10.0, 0.0, 10.0], _LIMITS),
        (("motors", "waist", "limits_deg"), "wide", _LIMITS),
        (("motors", "waist", "limits_deg"), [0.0, "90"], _LIMITS),
        (("motors", "waist", "limits_deg"), [math.nan, 10.0], _LIMITS),
        (("motors", "waist", "limits_deg"), DELETE, _LIMITS),
        # buttons and frame types
        (
            ("buttons", "torch"),
            1,
            r"^profile\.buttons: torch and camera_select must differ$",
        ),
        (
            ("buttons", "camera_select"),
            16,
            r"^profile\.buttons\.camera_select: must be in \[0, 15\], got 16$",
        ),
        (
            ("link", "frame_types", "video"),
            0x01,
            r"^profile\.link\.frame_types: the three IDs must differ$",
        ),
        (
            ("link", "frame_types", "telemetry"),
            0x03,
            r"^profile\.link\.frame_types: the three IDs must differ$",
        ),
        (
            ("link", "frame_types", "rcp"),
            256,
            r"^profile\.link\.frame_types\.rcp: must be in \[0, 255\], got 256$",
        ),
    ],
)
def test_validation_error_names_the_key(path: tuple[str, ...], value: object, message: str) -> None:
    with pytest.raises(ProfileError, match=_in_memory(message)):
        parse_profile(_edited(path, value))


def _renamed(path: tuple[str, ...], new_name: str) -> dict[str, Any]:
    """A deep copy of the shipped profile with one key renamed (a misspelling)."""
    data = copy.deepcopy(SHIPPED_DATA)
    table = data
    for key in path[:-1]:
        table = table[key]
    table[new_name] = table.pop(path[-1])
    return data


@pytest.mark.parametrize(
    ("path", "misspelt", "message"),
    [
        (
            ("chassis",),
            "chasis",
            r"^profile\.chasis: unknown key; did you mean 'chassis'\?$",
        ),
        (("name",), "Name", r"^profile\.Name: unknown key; did you mean 'name'\?$"),
        (
            ("assumptions",),
            "assumption",
            r"^profile\.assumption: unknown key; did you mean 'assumptions'\?$",
        ),
        (
            ("link", "send_rate_hz"),
            "sned_rate_hz",
            r"^profile\.link\.sned_rate_hz: unknown key; did you mean 'send_rate_hz'\?$",
        ),
        (
            ("link", "frame_types", "telemetry"),
            "telemetery",
            r"^profile\.link\.frame_types\.telemetery: unknown key; did you mean 'telemetry'\?$",
        ),
        (
            ("extension", "probe"),
            "prob",
            r"^profile\.extension\.prob: .*did you mean 'probe'\?$",
        ),
        (
            ("extension", "frame_types", "video_fragment"),
            "video_fragments",
            r"^profile\.extension\.frame_types\.video_fragments: .* 'video_fragment'\?$",
        ),
        (
            ("video", "no_signal_after_s"),
            "no_signal_after",
            r"^profile\.video\.no_signal_after: unknown key; did you mean 'no_signal_after_s'\?$",
        ),
        (
            ("cameras", "front"),
            "frnt",
            r"^profile\.cameras\.frnt: not in link\.camera_names; did you mean 'front'\?$",
        ),
        (
            ("cameras", "front", "undistort"),
            "undistrot",
            r"^profile\.cameras\.front\.undistrot: unknown key; did you mean 'undistort'\?$",
        ),
        (
            ("si", "joint_axis_per_rad_s"),
            "joint_axis_per_rad",
            r"^profile\.si\.joint_axis_per_rad: .*did you mean 'joint_axis_per_rad_s'\?$",
        ),
        (
            ("chassis", "track_width_m"),
            "track_width",
            r"^profile\.chassis\.track_width: unknown key; did you mean 'track_width_m'\?$",
        ),
        (
            ("buttons", "camera_select"),
            "camera",
            r"^profile\.buttons\.camera: unknown key; did you mean 'camera_select'\?$",
        ),
        (
            ("channels", "waist"),
            "wasit",
            r"^profile\.motors\.waist\.channel: unknown channel 'waist'; did you mean 'wasit'\?$",
        ),
        (
            ("channels", "waist", "min_speed"),
            "minspeed",
            r"^profile\.channels\.waist\.minspeed: unknown key; did you mean 'min_speed'\?$",
        ),
        (
            ("motors", "waist", "limits_deg"),
            "limit_deg",
            r"^profile\.motors\.waist\.limit_deg: unknown key; did you mean 'limits_deg'\?$",
        ),
        # Not "zero_offset_ticks: needs ticks_per_rad": the misspelling is what is wrong.
        (
            ("motors", "waist", "ticks_per_rad"),
            "ticks_per_rads",
            r"^profile\.motors\.waist\.ticks_per_rads: .*did you mean 'ticks_per_rad'\?$",
        ),
        (
            ("link", "address"),
            "host",
            r"^profile\.link\.host: unknown key; known: address, port, send_rate_hz, ",
        ),
    ],
)
def test_unknown_key_is_named_with_a_suggestion(
    path: tuple[str, ...], misspelt: str, message: str
) -> None:
    with pytest.raises(ProfileError, match=_in_memory(message)):
        parse_profile(_renamed(path, misspelt))


def test_every_unknown_key_of_a_table_is_named() -> None:
    data = _edited(("buttons", "torhc"), 0)
    data["buttons"]["camera_selcet"] = 1
    with pytest.raises(ProfileError) as error:
        parse_profile(data)
    assert str(error.value) == (
        "<profile>: profile.buttons.torhc: unknown key; did you mean 'torch'?; "
        "profile.buttons.camera_selcet: unknown key; did you mean 'camera_select'?"
    )


def test_optional_keys_stay_optional() -> None:
    data = copy.deepcopy(SHIPPED_DATA)
    for key in ("assumptions", "extension", "video", "cameras", "arm"):
        del data[key]
    del data["motors"]["waist"]["channel"]
    profile = parse_profile(data)
    assert profile.assumptions == ()
    assert profile.motors["waist"].channel is None
    assert not profile.motors["left_track"].has_position  # a motor without ticks_per_rad
    assert profile.arm is None


def test_arm_table_is_checked(profile: RobotProfile) -> None:
    assert profile.arm is not None
    assert profile.arm.joints == ("waist", "shoulder", "elbow", "neck")
    assert set(profile.arm.poses) == {"stow", "ready", "look_forward", "look_back"}
    assert profile.arm.joint_limit_margin_rad == pytest.approx(0.1, abs=1e-3)
    cases = {
        ("arm", "joints"): (["waist", "knee"], r"arm\.joints: unknown motor 'knee'"),
        ("arm", "singularity_stop"): (5.0, r"arm\.singularity_stop: must be >= 17"),
        ("arm", "poses", "ready", "elbow"): (170.0, r"poses\.ready\.elbow: 170\.0° outside"),
        ("arm", "poses", "ready", "tail"): (1.0, r"poses\.ready\.tail: not one of arm\.joints"),
        ("arm", "speed"): (1.0, r"arm\.speed: unknown key"),
    }
    for path, (value, message) in cases.items():
        with pytest.raises(ProfileError, match=message):
            parse_profile(_edited(path, value))
    data = copy.deepcopy(SHIPPED_DATA)
    del data["arm"]["poses"]["stow"]["neck"]
    with pytest.raises(ProfileError, match=r"poses\.stow: every arm joint needs an angle \(neck\)"):
        parse_profile(data)
    data["motors"]["waist"].pop("channel")
    with pytest.raises(ProfileError, match="'waist' must report a position and have a channel"):
        parse_profile(data)


@pytest.mark.parametrize("key", ["zero_offset_ticks", "limits_deg"])
def test_position_keys_need_ticks_per_rad(key: str) -> None:
    data = _edited(("motors", "left_track", key), SHIPPED_DATA["motors"]["waist"][key])
    with pytest.raises(
        ProfileError, match=rf"^<profile>: profile\.motors\.left_track\.{key}: needs ticks_per_rad "
    ):
        parse_profile(data)


def test_profile_error_is_a_value_error() -> None:
    assert issubclass(ProfileError, ValueError)


def test_more_than_ten_motors() -> None:
    data = copy.deepcopy(SHIPPED_DATA)
    data["motors"]["extra"] = {"device_id": 11}
    with pytest.raises(ProfileError, match=r"^<profile>: profile\.motors: .* at most 10 motors$"):
        parse_profile(data)


@pytest.mark.parametrize("limits", [[-math.inf, 180.0], [0.0, math.inf]])
def test_infinite_limits_are_refused(limits: list[float]) -> None:
    with pytest.raises(ProfileError, match=r"^<profile>: profile\.motors\.waist\.limits_deg: "):
        parse_profile(_edited(("motors", "waist", "limits_deg"), limits))


# --- files --------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("old", "new", "message"),
    [
        (
            "hard_max = 0.45",
            "hard_max = inf",
            r"profile\.channels\.drive_linear\.hard_max: must be finite, got inf$",
        ),
        (
            "hard_max = 0.45",
            "hard_max = nan",
            r"profile\.channels\.drive_linear\.hard_max: must be finite, got nan$",
        ),
        ("port = 10000", 'port = "10000"', r"profile\.link\.port: must be an integer"),
        ("torch = 0 ", "torch = 1 ", r"profile\.buttons: torch and camera_select must differ$"),
        ("video = 0x03", "video = 0x02", r"profile\.link\.frame_types: the three IDs must differ"),
        ("device_id = 8\n", "device_id = 7\n", r"profile\.motors: two motors share one device_id"),
        (
            "send_rate_hz = 5.0",
            "sned_rate_hz = 5.0",
            r"profile\.link\.sned_rate_hz: unknown key; did you mean 'send_rate_hz'\?$",
        ),
    ],
    ids=["inf", "nan", "port-string", "torch-camera", "frame-types", "device-id", "misspelt"],
)
def test_edited_file(tmp_path: Path, old: str, new: str, message: str) -> None:
    path = _write(tmp_path, _replace_once(SHIPPED_TEXT, old, new))
    # Every error names the file, then the key.
    with pytest.raises(ProfileError, match=rf"^{re.escape(str(path))}: {message}"):
        load_profile(path)


@pytest.mark.parametrize(
    "text",
    [
        SHIPPED_TEXT + "\n[link\n",
        SHIPPED_TEXT.replace("port = 10000", "port = = 10000"),
        "name = 'twice'\n" + SHIPPED_TEXT,
        "\x00",
    ],
    ids=["open-table", "double-equals", "duplicate-key", "nul"],
)
def test_invalid_toml(tmp_path: Path, text: str) -> None:
    path = _write(tmp_path, text)
    with pytest.raises(
        ProfileError, match=rf"^{re.escape(str(tmp_path))}/robot\.toml: not valid TOML: "
    ):
        load_profile(path)


@pytest.mark.parametrize(
    ("value", "message"),
    [
        ("1e9", r"must be <= 30 s, got 1e\+09: the operator must learn within seconds"),
        ("0.5", r"must be longer than one telemetry period \(1 s at telemetry_rate_hz\)"),
    ],
    ids=["never", "between-packets"],
)
def test_link_lost_after_s_is_bounded(tmp_path: Path, value: str, message: str) -> None:
    old = "link_lost_after_s = 3.0"
    path = _write(tmp_path, _replace_once(SHIPPED_TEXT, old, f"link_lost_after_s = {value}"))
    with pytest.raises(
        ProfileError, match=rf"^{re.escape(str(path))}: profile\.link\.link_lost_after_s: {message}"
    ):
        load_profile(path)
    # The bound's ends are accepted.
    ok = _replace_once(SHIPPED_TEXT, old, "link_lost_after_s = 30.0")
    assert load_profile(_write(tmp_path, ok)).link.link_lost_after_s == 30.0


def test_missing_file(tmp_path: Path) -> None:
    with pytest.raises(ProfileError, match=r"^cannot read profile .*absent\.toml: No such file"):
        load_profile(tmp_path / "absent.toml")


def test_directory_instead_of_file(tmp_path: Path) -> None:
    with pytest.raises(ProfileError, match=rf"^cannot read profile {re.escape(str(tmp_path))}: "):
        load_profile(tmp_path)


def test_not_utf8(tmp_path: Path) -> None:
    path = tmp_path / "robot.toml"
    path.write_bytes(b"name = '\xff'\n")
    with pytest.raises(ProfileError, match=r"robot\.toml: not UTF-8 text: .*byte 0xff"):
        load_profile(path)


# --- direction, per-channel scale, measured keys, writing ---------------------------------

MEASURED = {
    "channels.shoulder.axis": {
        "how": "a pulse on axis 3 moved the shoulder",
        "when": dt.datetime(2025, 6, 1, 12, 0, tzinfo=dt.UTC),
    },
    "motors.shoulder.ticks_per_rad": {
        "how": "sweeps",
        "when": dt.datetime(2025, 6, 1, 12, 0, tzinfo=dt.UTC),
        "residual": 0.4,
        "residual_unit": "ticks",
        "samples": 24,
    },
}


def _measured(entries: dict[str, Any]) -> dict[str, Any]:
    data = copy.deepcopy(SHIPPED_DATA)
    data["measured"] = copy.deepcopy(entries)
    return data


def test_axis_sign_and_own_scale(profile: RobotProfile) -> None:
    assert all(c.axis_sign == 1 for c in profile.channels.values())
    data = _edited(("channels", "shoulder", "axis_sign"), -1)
    data["channels"]["shoulder"]["axis_per_unit"] = 25_000.0
    shoulder = parse_profile(data).channels["shoulder"]
    assert (shoulder.axis_sign, shoulder.axis_per_unit) == (-1, 25_000.0)
    del data["channels"]["elbow"]["axis_sign"]  # optional: +1 when absent
    assert parse_profile(data).channels["elbow"].axis_sign == 1


@pytest.mark.parametrize(
    ("key", "value", "message"),
    [
        ("axis_sign", 0, r"axis_sign: must be 1 or -1, got 0$"),
        ("axis_sign", 2, r"axis_sign: must be in \[-1, 1\], got 2$"),
        ("axis_sign", 1.0, r"axis_sign: must be an integer"),
        ("axis_per_unit", 0.0, r"axis_per_unit: must be >= 1e-09"),
        ("axis_per_unit", 40_000.0, r"shoulder\.hard_max: 1.0 needs axis value 40000"),
    ],
)
def test_bad_direction_or_scale(key: str, value: object, message: str) -> None:
    with pytest.raises(ProfileError, match=message):
        parse_profile(_edited(("channels", "shoulder", key), value))


def test_measured_keys_and_provenance(profile: RobotProfile) -> None:
    measured = parse_profile(_measured(MEASURED))
    entry = measured.measured["motors.shoulder.ticks_per_rad"]
    assert (entry.how, entry.residual, entry.residual_unit, entry.samples) == (
        "sweeps",
        0.4,
        "ticks",
        24,
    )
    # A measured key is no assumption, though a wildcard still covers it.
    assert measured.provenance("channels.shoulder.axis") == "measured"
    assert measured.provenance("channels.elbow.axis") == "assumption"
    assert profile.provenance("channels.shoulder.axis") == "assumption"
    assert profile.provenance("buttons.torch") == "assumption"
    assert profile.provenance("si.linear_axis_per_m_s") == "documents"
    assert assumption_covers("channels.*.axis", "channels.elbow.axis")
    assert not assumption_covers("channels.*.axis", "channels.elbow.axis_sign")
    assert not assumption_covers("link.port.x", "link.port")


@pytest.mark.parametrize(
    ("entries", "message"),
    [
        ({"link.nope": MEASURED["channels.shoulder.axis"]}, r'"link\.nope": names no key'),
        ({"link.port": MEASURED["channels.shoulder.axis"]}, r'"link\.port": also listed in'),
        (
            {"link.send_rate_hz": {"how": "x", "when": dt.datetime(2025, 6, 1, 12, 0)}},
            r'"link\.send_rate_hz"\.when: must be a date and time with its offset',
        ),
        (
            {"link.send_rate_hz": {"when": dt.datetime(2025, 6, 1, tzinfo=dt.UTC)}},
            r'"link\.send_rate_hz"\.how: missing$',
        ),
        (
            {"link.send_rate_hz": {**MEASURED["channels.shoulder.axis"], "resid": 1.0}},
            r"resid: unknown key; did you mean 'residual'\?",
        ),
        (
            {"link.send_rate_hz": {**MEASURED["channels.shoulder.axis"], "residual": -1.0}},
            r"residual: must be >= 0.0",
        ),
    ],
)
def test_bad_measured_entries(entries: dict[str, Any], message: str) -> None:
    with pytest.raises(ProfileError, match=message):
        parse_profile(_measured(entries))


def test_toml_writer_round_trips_the_shipped_profile_and_measurements() -> None:
    data = _measured(MEASURED)
    data["name"] = 'A "quoted" name\twith a tab, é and \x7f'
    text = profile_to_toml(data, header="first line\nsecond line")
    assert text.startswith("# first line\n# second line\n")
    assert tomllib.loads(text) == data
    assert load_profile_data() == SHIPPED_DATA


def test_written_profiles_are_validated_and_replace_the_old_file_whole(tmp_path: Path) -> None:
    target = tmp_path / "robot.toml"
    write_profile_data(target, _measured(MEASURED), header="ocu test")
    assert load_profile(target).measured.keys() == MEASURED.keys()
    before = target.read_bytes()
    bad = _edited(("channels", "shoulder", "axis_sign"), 0)
    with pytest.raises(ProfileError, match="axis_sign"):
        write_profile_data(target, bad)
    assert target.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == ["robot.toml"]  # no temp file left


def test_a_camera_on_a_link_needs_its_offset_and_the_simulator_checks_the_link(
    profile: RobotProfile,
) -> None:
    head = next(c for c in profile.cameras if c.mount is not None and c.mount.link is not None)
    assert head.mount is not None
    assert head.mount.link == "head_cameras"
    assert profile.arm is not None
    assert head.mount.link == profile.arm.camera_link
    data = _edited(("cameras", head.name, "mount_xyz_m"), DELETE)
    del data["cameras"][head.name]["mount_yaw_deg"]
    del data["cameras"][head.name]["mount_pitch_deg"]
    with pytest.raises(ProfileError, match=rf"cameras\.{head.name}\.mount_link: needs mount_xyz_m"):
        parse_profile(data)
    wrong = parse_profile(_edited(("cameras", head.name, "mount_link"), "no_such_link"))
    with pytest.raises(ValueError, match="the robot model has no link no_such_link"):
        RobotSimulator(
            wrong, world=parse_world({"box": [{"centre_m": [2.0, 0.0], "size_m": [0.3, 0.3]}]})
        )


def test_a_profile_names_its_robot_description_and_the_writer_keeps_it(tmp_path: Path) -> None:
    """`urdf`: a file, relative to the profile's folder; the console and the 3D view load it."""
    description = tmp_path / "models" / "robot.urdf"
    description.parent.mkdir()
    description.write_text('<robot name="r"><link name="base_link"/></robot>', encoding="utf-8")
    data = copy.deepcopy(SHIPPED_DATA)
    data["urdf"] = "models/robot.urdf"
    data["arm"]["tool_axis"] = "z"
    target = tmp_path / "robot.toml"
    write_profile_data(target, data, header="ocu test")
    assert tomllib.loads(target.read_text(encoding="utf-8")) == data
    written = load_profile(target)
    assert written.urdf == description
    assert written.arm is not None
    assert written.arm.tool_axis == "z"
    # Absolute paths are taken as they are; without the key the Engineer's model is meant.
    data["urdf"] = str(description)
    assert parse_profile(data).urdf == description
    engineer = load_profile()
    assert engineer.urdf is None
    assert engineer.arm is not None
    assert engineer.arm.tool_axis == "x"


@pytest.mark.parametrize(
    ("key", "value", "message"),
    [
        (("urdf",), 3, r"profile\.urdf: must be a non-empty string"),
        (("urdf",), "", r"profile\.urdf: must be a non-empty string"),
        (("urdf",), "no_such.urdf", r"robot\.toml: profile\.urdf: no file .*no_such\.urdf"),
        (("arm", "tool_axis"), "y", r"robot\.toml: profile\.arm\.tool_axis: must be one of"),
    ],
)
def test_a_bad_robot_description_is_refused_by_file_and_key(
    tmp_path: Path, key: tuple[str, ...], value: object, message: str
) -> None:
    target = tmp_path / "robot.toml"
    with pytest.raises(ProfileError, match=message):
        parse_profile(_edited(key, value), source=str(target))
    with pytest.raises(ProfileError, match=message):
        write_profile_data(target, _edited(key, value))
    assert list(tmp_path.iterdir()) == []  # nothing written

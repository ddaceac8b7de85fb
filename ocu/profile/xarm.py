"""The xArm 1S's profile: its board's serial settings, its servos as joints, the servo model.

The shipped one is ocu/profiles/xarm/xarm1s.toml; a path to another file works the same.
Sources and assumptions: docs/xarm.md. A joint's angle is `sign * (raw - 500 - offset)` servo
units, at `units_per_rad` units a radian (1000 units span `range_deg`).
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any

from ocu.profile.keys import ProfileError

#: The servo unit that is 0 rad (the middle of 0-1000), before a joint's offset.
CENTRE_UNITS = 500
RANGE_UNITS = 1000
BAUD_RATES = (9600, 19200, 38400, 57600, 115200)

_TOP_KEYS = {"name", "baud", "range_deg", "link_lengths_m", "servo", "timing", "joints"}
_SERVO_KEYS = {"damping_ratio", "natural_frequency_rad_s", "max_speed_deg_s"}
_TIMING_KEYS = {
    "jog_period_s",
    "jog_move_s",
    "read_period_s",
    "read_period_moving_s",
    "battery_period_s",
    "link_lost_after_s",
}
_JOINT_KEYS = {"name", "servo", "sign", "offset", "min", "max", "max_speed_deg_s"}


@dataclass(frozen=True)
class XarmJoint:
    """One joint: its servo on the board, the mapping to radians, its limits (servo units)."""

    name: str
    servo: int
    sign: int
    offset_units: int
    min_units: int
    max_units: int
    max_speed_rad_s: float


@dataclass(frozen=True)
class ServoModel:
    """A servo's response to its setpoint: second order (seed 003), and a top speed."""

    damping_ratio: float
    natural_frequency_rad_s: float
    max_speed_rad_s: float


@dataclass(frozen=True)
class XarmTiming:
    """The link's timing (docs/xarm.md): jog moves, reads, LINK LOST."""

    jog_period_s: float
    jog_move_s: float
    read_period_s: float
    read_period_moving_s: float
    battery_period_s: float
    link_lost_after_s: float


@dataclass(frozen=True)
class XarmProfile:
    """An xArm as the simulator and the xArm link need it."""

    name: str
    baud: int
    range_deg: float
    link_lengths_m: tuple[float, ...]
    servo: ServoModel
    timing: XarmTiming
    joints: tuple[XarmJoint, ...]
    source: str = ""

    @property
    def joint_names(self) -> tuple[str, ...]:
        """The joint names, base to tool."""
        return tuple(joint.name for joint in self.joints)

    @property
    def units_per_rad(self) -> float:
        """Servo units a radian."""
        return RANGE_UNITS / math.radians(self.range_deg)

    def joint(self, name: str) -> XarmJoint:
        """The joint named `name`; KeyError if none."""
        for joint in self.joints:
            if joint.name == name:
                return joint
        raise KeyError(name)

    def angle_rad(self, joint: XarmJoint, raw: float) -> float:
        """A servo reading (units) as the joint's angle."""
        return joint.sign * (raw - CENTRE_UNITS - joint.offset_units) / self.units_per_rad

    def raw_units(self, joint: XarmJoint, angle_rad: float) -> float:
        """A joint angle as the servo's position (units, not rounded nor limited)."""
        return CENTRE_UNITS + joint.offset_units + joint.sign * angle_rad * self.units_per_rad


# Files beside the xArm profiles that are not profiles (ocu.profile.companion_file).
_COMPANIONS = ("hotkeys.toml", "gamepad.toml")


def shipped_xarm_profiles() -> tuple[str, ...]:
    """The names of the shipped xArm profiles."""
    folder = resources.files("ocu") / "profiles" / "xarm"
    return tuple(
        sorted(
            p.name[:-5]
            for p in folder.iterdir()
            if p.name.endswith(".toml") and p.name not in _COMPANIONS
        )
    )


def is_xarm_file(path: str | Path) -> bool:
    """Whether `path` is a TOML file in the xArm format (it has `baud` and `range_deg`, as
    one `ocu calibrate` wrote does); False for anything else, readable or not."""
    path = Path(path)
    if path.suffix != ".toml" or not path.is_file():
        return False
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError):
        return False  # the Engineer's loader says what is wrong with it
    return "baud" in data and "range_deg" in data


def load_xarm_arm(name: str | None) -> XarmProfile | None:
    """The xArm `--profile` names (a shipped name, or a file in the xArm format), else None;
    ProfileError for a bad one."""
    if name is None:
        return None
    if name in shipped_xarm_profiles() or is_xarm_file(name):
        return load_xarm_profile(name)
    return None


def load_xarm_profile(name_or_path: str | Path) -> XarmProfile:
    """A shipped profile by name ("xarm1s") or a TOML file by path; ProfileError if wrong."""
    text_name = str(name_or_path)
    if text_name in shipped_xarm_profiles():
        path = Path(str(resources.files("ocu") / "profiles" / "xarm" / f"{text_name}.toml"))
    else:
        path = Path(name_or_path)
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError as err:
        raise ProfileError(
            f"no xArm profile {text_name!r}: not a shipped name "
            f"({', '.join(shipped_xarm_profiles())}) nor a file"
        ) from err
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as err:
        raise ProfileError(f"{path}: cannot read the xArm profile: {err}") from err
    return parse_xarm_profile(data, source=str(path))


def _number(table: dict[str, Any], key: str, where: str, *, positive: bool = False) -> float:
    value = table.get(key)
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise ProfileError(f"{where}: {key} must be a number, got {value!r}")
    if positive and value <= 0:
        raise ProfileError(f"{where}: {key} must be > 0, got {value!r}")
    return float(value)


def _integer(table: dict[str, Any], key: str, where: str, low: int, high: int) -> int:
    value = table.get(key)
    if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
        raise ProfileError(f"{where}: {key} must be an integer {low}-{high}, got {value!r}")
    return value


def _table(data: dict[str, Any], key: str, keys: set[str], where: str) -> dict[str, Any]:
    table = data.get(key)
    if not isinstance(table, dict):
        raise ProfileError(f"{where}: [{key}] must be a table")
    unknown = sorted(table.keys() - keys)
    if unknown:
        raise ProfileError(f"{where}: [{key}] unknown keys {unknown}")
    return table


def parse_xarm_profile(data: dict[str, Any], *, source: str = "<data>") -> XarmProfile:
    """An XarmProfile from a TOML document; ProfileError naming the key for anything wrong."""
    unknown = sorted(data.keys() - _TOP_KEYS)
    if unknown:
        raise ProfileError(f"{source}: unknown keys {unknown}")
    name = data.get("name")
    if not isinstance(name, str) or not name:
        raise ProfileError(f"{source}: name must be a non-empty string")
    baud = data.get("baud")
    if baud not in BAUD_RATES:
        raise ProfileError(f"{source}: baud must be one of {BAUD_RATES}, got {baud!r}")
    lengths = data.get("link_lengths_m")
    if (
        not isinstance(lengths, list)
        or len(lengths) != 4
        or not all(isinstance(v, int | float) and not isinstance(v, bool) for v in lengths)
        or not all(v > 0 for v in lengths)
    ):
        raise ProfileError(f"{source}: link_lengths_m must list 4 lengths > 0")
    servo = _table(data, "servo", _SERVO_KEYS, source)
    timing = _table(data, "timing", _TIMING_KEYS, source)
    model = ServoModel(
        damping_ratio=_number(servo, "damping_ratio", source, positive=True),
        natural_frequency_rad_s=_number(servo, "natural_frequency_rad_s", source, positive=True),
        max_speed_rad_s=math.radians(_number(servo, "max_speed_deg_s", source, positive=True)),
    )
    times = XarmTiming(**{key: _number(timing, key, source, positive=True) for key in _TIMING_KEYS})
    if times.jog_move_s <= times.jog_period_s:
        raise ProfileError(f"{source}: jog_move_s must be longer than jog_period_s")
    joints_data = data.get("joints")
    if not isinstance(joints_data, list) or not joints_data:
        raise ProfileError(f"{source}: [[joints]] must list the joints")
    joints: list[XarmJoint] = []
    for index, table in enumerate(joints_data):
        where = f"{source}: joints[{index}]"
        if not isinstance(table, dict):
            raise ProfileError(f"{where} must be a table")
        unknown = sorted(table.keys() - _JOINT_KEYS)
        if unknown:
            raise ProfileError(f"{where}: unknown keys {unknown}")
        joint_name = table.get("name")
        if not isinstance(joint_name, str) or not joint_name:
            raise ProfileError(f"{where}: name must be a non-empty string")
        sign = table.get("sign")
        if sign not in (1, -1):
            raise ProfileError(f"{where}: sign must be 1 or -1, got {sign!r}")
        low = _integer(table, "min", where, 0, RANGE_UNITS)
        high = _integer(table, "max", where, 0, RANGE_UNITS)
        if low >= high:
            raise ProfileError(f"{where}: min must be below max")
        joints.append(
            XarmJoint(
                name=joint_name,
                servo=_integer(table, "servo", where, 1, 254),
                sign=int(sign),
                offset_units=_integer(table, "offset", where, -RANGE_UNITS, RANGE_UNITS),
                min_units=low,
                max_units=high,
                max_speed_rad_s=math.radians(
                    _number(table, "max_speed_deg_s", where, positive=True)
                ),
            )
        )
    for what, values in (("name", [j.name for j in joints]), ("servo", [j.servo for j in joints])):
        if len(set(values)) != len(values):
            raise ProfileError(f"{source}: a joint {what} is given twice in {values}")
    return XarmProfile(
        name=name,
        baud=int(baud),
        range_deg=_number(data, "range_deg", source, positive=True),
        link_lengths_m=tuple(float(v) for v in lengths),
        servo=model,
        timing=times,
        joints=tuple(joints),
        source=source,
    )

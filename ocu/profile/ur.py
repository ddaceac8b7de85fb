"""Universal Robots arm profiles: joint limits, speeds and DH parameters, one TOML per model.

The shipped ones are ocu/profiles/ur/<name>.toml (ur3e, ur5e, ur10e and the CB3 ur5); a path
to another file works the same. Sources and assumptions: docs/ur.md.
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any

from ocu.profile.keys import ProfileError

SERIES = ("cb3", "e-series")
_TOP_KEYS = {
    "name",
    "series",
    "controller_version",
    "realtime_hz",
    "secondary_hz",
    "max_acceleration_rad_s2",
    "joints",
}
_JOINT_KEYS = {"name", "min_deg", "max_deg", "max_speed_deg_s", "dh_d_m", "dh_a_m", "dh_alpha_deg"}


@dataclass(frozen=True)
class UrJoint:
    """One joint: its limits (rad; None: continuous), top speed (rad/s) and DH row."""

    name: str
    min_rad: float | None
    max_rad: float | None
    max_speed_rad_s: float
    dh_d_m: float
    dh_a_m: float
    dh_alpha_rad: float


@dataclass(frozen=True)
class UrArmProfile:
    """A UR arm as the simulator and the UR link need it."""

    name: str
    series: str
    controller_version: tuple[int, int, int]
    realtime_hz: float
    secondary_hz: float
    max_acceleration_rad_s2: float
    joints: tuple[UrJoint, ...]
    source: str = ""

    @property
    def joint_names(self) -> tuple[str, ...]:
        """The six joint names, base to tool."""
        return tuple(joint.name for joint in self.joints)


# Files beside the UR profiles that are not profiles (ocu.profile.companion_file).
_COMPANIONS = ("hotkeys.toml", "gamepad.toml")


def shipped_ur_profiles() -> tuple[str, ...]:
    """The names of the shipped UR profiles."""
    folder = resources.files("ocu") / "profiles" / "ur"
    return tuple(
        sorted(
            p.name[:-5]
            for p in folder.iterdir()
            if p.name.endswith(".toml") and p.name not in _COMPANIONS
        )
    )


def load_ur_profile(name_or_path: str | Path) -> UrArmProfile:
    """A shipped profile by name ("ur5e") or a TOML file by path; ProfileError if wrong."""
    text_name = str(name_or_path)
    if text_name in shipped_ur_profiles():
        path = Path(str(resources.files("ocu") / "profiles" / "ur" / f"{text_name}.toml"))
    else:
        path = Path(name_or_path)
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError as err:
        raise ProfileError(
            f"no UR profile {text_name!r}: not a shipped name "
            f"({', '.join(shipped_ur_profiles())}) nor a file"
        ) from err
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as err:
        raise ProfileError(f"{path}: cannot read the UR profile: {err}") from err
    return parse_ur_profile(data, source=str(path))


def _number(table: dict[str, Any], key: str, where: str, *, positive: bool = False) -> float:
    value = table.get(key)
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise ProfileError(f"{where}: {key} must be a number, got {value!r}")
    if positive and value <= 0:
        raise ProfileError(f"{where}: {key} must be > 0, got {value!r}")
    return float(value)


def parse_ur_profile(data: dict[str, Any], *, source: str = "<data>") -> UrArmProfile:
    """A UrArmProfile from a TOML document; ProfileError naming the key for anything wrong."""
    unknown = sorted(data.keys() - _TOP_KEYS)
    if unknown:
        raise ProfileError(f"{source}: unknown keys {unknown}")
    name = data.get("name")
    if not isinstance(name, str) or not name:
        raise ProfileError(f"{source}: name must be a non-empty string")
    series = data.get("series")
    if series not in SERIES:
        raise ProfileError(f"{source}: series must be one of {SERIES}, got {series!r}")
    version_text = data.get("controller_version")
    try:
        parts = tuple(int(p) for p in str(version_text).split("."))
    except ValueError:
        parts = ()
    if len(parts) != 3:
        raise ProfileError(f"{source}: controller_version must be MAJOR.MINOR.BUGFIX")
    joints_data = data.get("joints")
    if not isinstance(joints_data, list) or len(joints_data) != 6:
        raise ProfileError(f"{source}: [[joints]] must list 6 joints")
    joints: list[UrJoint] = []
    for index, table in enumerate(joints_data):
        where = f"{source}: joints[{index}]"
        if not isinstance(table, dict):
            raise ProfileError(f"{where} must be a table")
        unknown = sorted(table.keys() - _JOINT_KEYS)
        if unknown:
            raise ProfileError(f"{where}: unknown keys {unknown}")
        has_limits = "min_deg" in table or "max_deg" in table
        low = math.radians(_number(table, "min_deg", where)) if has_limits else None
        high = math.radians(_number(table, "max_deg", where)) if has_limits else None
        if low is not None and high is not None and low >= high:
            raise ProfileError(f"{where}: min_deg must be below max_deg")
        joints.append(
            UrJoint(
                name=str(table.get("name", "")),
                min_rad=low,
                max_rad=high,
                max_speed_rad_s=math.radians(
                    _number(table, "max_speed_deg_s", where, positive=True)
                ),
                dh_d_m=_number(table, "dh_d_m", where),
                dh_a_m=_number(table, "dh_a_m", where),
                dh_alpha_rad=math.radians(_number(table, "dh_alpha_deg", where)),
            )
        )
    return UrArmProfile(
        name=name,
        series=str(series),
        controller_version=(parts[0], parts[1], parts[2]),
        realtime_hz=_number(data, "realtime_hz", source, positive=True),
        secondary_hz=_number(data, "secondary_hz", source, positive=True),
        max_acceleration_rad_s2=_number(data, "max_acceleration_rad_s2", source, positive=True),
        joints=tuple(joints),
        source=source,
    )

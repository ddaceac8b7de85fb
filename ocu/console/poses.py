"""Stored arm poses: the profile's (stow, ready, ...) and the operator's own, kept in a TOML file.

The operator's poses live beside the hotkey file (`arm_poses.toml` in the console's config
directory), one table per pose with the arm's joint angles in degrees:

    [poses."over the box"]
    waist = 12.5
    shoulder = 40.0
    elbow = 95.0
    neck = -30.0

The file is written to a temporary file in the same folder and renamed over the old one, so it
is whole whatever moment the program is killed at. A bad file is refused with the reason and
the profile's poses stay usable; a name, a joint or an angle that is wrong is named.
"""

from __future__ import annotations

import json
import math
import os
import re
import tomllib
from collections.abc import Mapping, Sequence
from pathlib import Path

from ocu.files import write_text_atomically

ARM_POSES_NAME = "arm_poses.toml"
CONFIG_DIR_ENV = "OCU_CONFIG_DIR"
MAX_NAME_LENGTH = 40
_NAME = re.compile(r"^[\w][\w .\-]*$")
HEADER = (
    "# Arm poses saved from the ocu console (docs/arm.md): joint angles in degrees.\n"
    "# Written by the program; edits by hand are read at the next start.\n"
)


def default_config_dir() -> Path:
    """The console's config directory: $OCU_CONFIG_DIR, else $XDG_CONFIG_HOME/ocu, else
    ~/.config/ocu (the hotkey file, the layout and the stored poses live there)."""
    if os.environ.get(CONFIG_DIR_ENV):
        return Path(os.environ[CONFIG_DIR_ENV])
    base = os.environ.get("XDG_CONFIG_HOME") or str(Path.home() / ".config")
    return Path(base) / "ocu"


class PoseError(ValueError):
    """A pose name, file or angle that cannot be used."""


def check_name(name: str) -> str:
    """A usable pose name, stripped; PoseError with the reason otherwise."""
    text = name.strip()
    if not text:
        raise PoseError("a pose needs a name")
    if len(text) > MAX_NAME_LENGTH:
        raise PoseError(f"pose names are at most {MAX_NAME_LENGTH} characters")
    if not _NAME.match(text):
        raise PoseError(
            f"{text!r}: use letters, digits, spaces, '.', '_' and '-' (starting with a letter "
            "or digit)"
        )
    return text


class PoseStore:
    """The profile's poses (read-only) and the operator's (read from and saved to a file)."""

    def __init__(
        self,
        builtin: Mapping[str, Mapping[str, float]],
        joints: Sequence[str],
        limits_rad: Mapping[str, tuple[float, float]],
        path: Path | None,
    ) -> None:
        self.builtin = {name: dict(angles) for name, angles in builtin.items()}
        self.joints = tuple(joints)
        self.limits_rad = dict(limits_rad)
        self.path = path
        self.saved: dict[str, dict[str, float]] = {}
        self.error = ""
        if path is not None and path.exists():
            try:
                self.saved = self._read(path)
            except PoseError as err:
                self.error = str(err)

    @property
    def names(self) -> tuple[str, ...]:
        """Every pose: the profile's first, then the operator's in the order saved."""
        return (*self.builtin, *self.saved)

    def get(self, name: str) -> dict[str, float]:
        """A pose's joint angles (rad); PoseError if there is none by that name."""
        if name in self.builtin:
            return dict(self.builtin[name])
        if name in self.saved:
            return dict(self.saved[name])
        raise PoseError(f"no stored pose {name!r}; known: {', '.join(self.names) or 'none'}")

    def save(self, name: str, angles_rad: Mapping[str, float]) -> str:
        """Store a pose under a name (replacing one of the operator's); returns the name kept."""
        text = check_name(name)
        if text in self.builtin:
            raise PoseError(f"{text!r} is one of the robot's poses; choose another name")
        if self.path is None:
            raise PoseError("there is no file to keep poses in (no config directory)")
        angles = {joint: float(angles_rad[joint]) for joint in self.joints if joint in angles_rad}
        if set(angles) != set(self.joints):
            raise PoseError("the arm's joints are not all known yet")
        self._check(text, angles, "")
        updated = {**self.saved, text: angles}
        self._write(updated)
        self.saved = updated
        return text

    def delete(self, name: str) -> None:
        """Remove one of the operator's poses."""
        if name in self.builtin:
            raise PoseError(f"{name!r} is one of the robot's poses and cannot be deleted")
        if name not in self.saved:
            raise PoseError(f"no saved pose {name!r}")
        updated = {k: v for k, v in self.saved.items() if k != name}
        self._write(updated)
        self.saved = updated

    def _check(self, name: str, angles: Mapping[str, float], where: str) -> None:
        for joint, value in angles.items():
            low, high = self.limits_rad.get(joint, (-math.inf, math.inf))
            if not (math.isfinite(value) and low - 1e-9 <= value <= high + 1e-9):
                raise PoseError(
                    f"{where}{name!r}: {joint} {math.degrees(value):.1f}° is outside its limits "
                    f"[{math.degrees(low):.1f}°, {math.degrees(high):.1f}°]"
                )

    def _read(self, path: Path) -> dict[str, dict[str, float]]:
        where = f"{path}: "
        try:
            data = tomllib.loads(path.read_text(encoding="utf-8"))
        except OSError as err:
            raise PoseError(f"{where}cannot read: {err.strerror}") from err
        except (tomllib.TOMLDecodeError, UnicodeDecodeError) as err:
            raise PoseError(f"{where}not valid TOML: {err}") from err
        unknown = [key for key in data if key != "poses"]
        if unknown:
            raise PoseError(f"{where}unknown table {unknown[0]!r} (only [poses.NAME] tables)")
        tables = data.get("poses", {})
        if not isinstance(tables, dict):
            raise PoseError(f"{where}poses must be tables of joint angles")
        poses: dict[str, dict[str, float]] = {}
        for name, table in tables.items():
            try:
                check_name(name)
            except PoseError as err:
                raise PoseError(f"{where}{err}") from None
            if name in self.builtin:
                raise PoseError(f"{where}{name!r} is one of the robot's poses; rename it")
            if not isinstance(table, dict):
                raise PoseError(f"{where}poses.{name!r} must be a table of joint angles")
            angles: dict[str, float] = {}
            for joint, value in table.items():
                if joint not in self.joints:
                    raise PoseError(
                        f"{where}poses.{name!r}: unknown joint {joint!r}; the arm's joints are "
                        f"{', '.join(self.joints)}"
                    )
                if isinstance(value, bool) or not isinstance(value, (int, float)):
                    raise PoseError(f"{where}poses.{name!r}.{joint} must be a number (degrees)")
                angles[joint] = math.radians(float(value))
            missing = [j for j in self.joints if j not in angles]
            if missing:
                raise PoseError(f"{where}poses.{name!r}: no angle for {', '.join(missing)}")
            self._check(name, angles, where)
            poses[name] = angles
        return poses

    def _write(self, poses: Mapping[str, Mapping[str, float]]) -> None:
        assert self.path is not None
        lines = [HEADER]
        for name, angles in poses.items():
            lines.append(f"\n[poses.{json.dumps(name)}]\n")
            lines.extend(f"{joint} = {math.degrees(angles[joint]):.4f}\n" for joint in self.joints)
        text = "".join(lines)
        try:
            write_text_atomically(self.path, text)
        except OSError as err:
            raise PoseError(f"cannot write {self.path}: {err.strerror or err}") from err

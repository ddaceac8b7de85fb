"""Stored arm poses: the profile's (stow, ready, ...) and the operator's own, kept in a TOML file.

The operator's poses live beside the hotkey file (`arm_poses.toml` in the console's config
directory), one table per pose with the arm's joint angles in degrees:

    [poses.over_the_box]
    waist = 12.5
    shoulder = 40.0
    elbow = 95.0
    neck = -30.0

The file is written to a temporary file in the same folder and renamed over the old one, so it
is whole whatever moment the program is killed at. Every pose that can be used is offered; one
that cannot (a wrong name, joint or angle, an angle outside its limit) is named in `problems`
and written back as it was when the file is saved again. A file that cannot be read at all is
never written over: saving is refused, with the reason, until it is fixed or moved away.
"""

from __future__ import annotations

import datetime
import json
import math
import os
import re
import tomllib
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

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

    # A part of the console model: the GUI reaches it under the model's lock (ocu.core.guard).
    guarded = True

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
        # What in the file could not be used, one line each (the file named in every line).
        self.problems: tuple[str, ...] = ()
        # The file could not be read as a whole: it is never written over.
        self.unreadable = ""
        # Poses in the file that could not be used, as read (written back unchanged), and why.
        self._kept: dict[str, Any] = {}
        self._why: dict[str, str] = {}
        self._load()

    @property
    def error(self) -> str:
        """Every problem with the file, in one line ("" if none)."""
        return "; ".join(self.problems)

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
        if name in self._kept:
            raise PoseError(f"stored pose {name!r} cannot be used: {self._why[name]}")
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
        self._refuse_unreadable()
        if text in self._kept:
            raise PoseError(
                f"{self.path} holds a pose {text!r} that cannot be used ({self._why[text]}): "
                "fix it there or choose another name"
            )
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
        self._refuse_unreadable()
        updated = {k: v for k, v in self.saved.items() if k != name}
        self._write(updated)
        self.saved = updated

    def _load(self) -> None:
        self.saved, self._kept, self._why, self.problems, self.unreadable = {}, {}, {}, (), ""
        if self.path is None or not self.path.exists():
            return
        try:
            self._read(self.path)
        except PoseError as err:
            self.saved, self._kept, self._why = {}, {}, {}
            self.unreadable = str(err)
            self.problems = (
                f"{err}; the file is left as it is (nothing is saved to it until it is fixed)",
            )

    def _refuse_unreadable(self) -> None:
        """PoseError if the file could not be read (read again first: it may be fixed now)."""
        if not self.unreadable:
            return
        self._load()
        if self.unreadable:
            raise PoseError(
                f"not saved: {self.unreadable}; fix or move the file away, it is not written over"
            )

    def _check(self, name: str, angles: Mapping[str, float], where: str) -> None:
        for joint, value in angles.items():
            low, high = self.limits_rad.get(joint, (-math.inf, math.inf))
            if not (math.isfinite(value) and low - 1e-9 <= value <= high + 1e-9):
                raise PoseError(
                    f"{where}{name!r}: {joint} {math.degrees(value):.1f}° is outside its limits "
                    f"[{math.degrees(low):.1f}°, {math.degrees(high):.1f}°]"
                )

    def _read(self, path: Path) -> None:
        """Read the file: usable poses to `saved`, the others to `_kept` and `problems`.

        PoseError if the file cannot be read as a whole."""
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
        problems = []
        for name, table in tables.items():
            try:
                self.saved[name] = self._pose(name, table)
            except PoseError as err:
                self._kept[name] = table
                self._why[name] = str(err)
                problems.append(f"{where}{err}; not offered")
        self.problems = tuple(problems)

    def _pose(self, name: str, table: Any) -> dict[str, float]:
        """One pose of the file; PoseError naming it if it cannot be used."""
        try:
            check_name(name)
        except PoseError as err:
            raise PoseError(f"{name!r}: {err}") from None
        if name in self.builtin:
            raise PoseError(f"{name!r}: one of the robot's poses has this name; rename it")
        if not isinstance(table, dict):
            raise PoseError(f"{name!r}: must be a table of joint angles")
        angles: dict[str, float] = {}
        for joint, value in table.items():
            if joint not in self.joints:
                raise PoseError(
                    f"{name!r}: unknown joint {joint!r}; the arm's joints are "
                    f"{', '.join(self.joints)}"
                )
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise PoseError(f"{name!r}: {joint} must be a number (degrees)")
            angles[joint] = math.radians(float(value))
        missing = [j for j in self.joints if j not in angles]
        if missing:
            raise PoseError(f"{name!r}: no angle for {', '.join(missing)}")
        self._check(name, angles, "")
        return angles

    def _write(self, poses: Mapping[str, Mapping[str, float]]) -> None:
        assert self.path is not None
        lines = [HEADER]
        loose = {name: value for name, value in self._kept.items() if not isinstance(value, dict)}
        if loose:
            lines.append("\n# Not poses (kept as they were):\n[poses]\n")
            lines.extend(f"{_toml_key(n)} = {_toml_value(v)}\n" for n, v in loose.items())
        for name, angles in poses.items():
            lines.append(f"\n[poses.{json.dumps(name)}]\n")
            lines.extend(f"{joint} = {math.degrees(angles[joint]):.4f}\n" for joint in self.joints)
        for name, table in self._kept.items():
            if isinstance(table, dict):
                lines.append(f"\n# Cannot be used (kept as it was): {self._why[name]}\n")
                lines.append(f"[poses.{_toml_key(name)}]\n")
                lines.extend(f"{_toml_key(k)} = {_toml_value(v)}\n" for k, v in table.items())
        text = "".join(lines)
        try:
            write_text_atomically(self.path, text)
        except OSError as err:
            raise PoseError(f"cannot write {self.path}: {err.strerror or err}") from err


def _toml_key(key: str) -> str:
    """A TOML key: quoted (always valid)."""
    return _toml_string(key)


def _toml_string(text: str) -> str:
    # JSON's escapes are TOML's, but for DEL (U+007F), which TOML wants escaped too.
    return json.dumps(text, ensure_ascii=False).replace("\x7f", "\\u007f")


def _toml_value(value: Any) -> str:
    """A value as tomllib read it, written back as TOML."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if math.isnan(value):
            return "nan"
        if math.isinf(value):
            return "inf" if value > 0 else "-inf"
        return repr(value)
    if isinstance(value, str):
        return _toml_string(value)
    if isinstance(value, (datetime.datetime, datetime.date, datetime.time)):
        return value.isoformat()
    if isinstance(value, list):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    if isinstance(value, dict):
        items = ", ".join(f"{_toml_key(k)} = {_toml_value(v)}" for k, v in value.items())
        return "{ " + items + " }" if items else "{}"
    raise TypeError(f"not a TOML value: {value!r}")

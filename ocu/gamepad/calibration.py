"""Each pad's axis ranges and centres: the values, the procedure that learns them, the file.

QGroundControl's joystick calibration is the model: move every stick and trigger to its ends,
let go, and the console learns each axis's range and rest position. A worn stick that rests
at +900 or reaches only 28000 then still gives 0 at rest and 1 at full deflection.

The file (`gamepad-calibration.toml` in the config directory) holds one table per pad, keyed
by SDL's GUID; the program writes it whole to a temporary file and renames it over the old
one, so a killed console leaves either the old file or the new one.
"""

from __future__ import annotations

import json
import logging
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ocu.files import write_text_atomically
from ocu.gamepad.pad import AXES, RAW_MAX, RAW_MIN, TRIGGERS, PadInfo

CALIBRATION_FILE_NAME = "gamepad-calibration.toml"
# A calibrated axis must have travelled at least this share of SDL's half range (a stick) or
# of its whole range (a trigger) on each side of its centre: less is a stick not moved.
MIN_TRAVEL = 0.5
# A stick rests within this share of SDL's half range of 0, a trigger as near its minimum:
# farther, it is still held.
CENTRE_LIMIT = 0.25
FIELDS = ("min", "centre", "max")


class CalibrationError(ValueError):
    """A calibration that cannot be used, or a calibration file that cannot be read."""


@dataclass(frozen=True)
class AxisCalibration:
    """One axis: raw minimum, rest position and maximum."""

    minimum: int
    centre: int
    maximum: int

    def __post_init__(self) -> None:
        if not RAW_MIN <= self.minimum <= self.centre <= self.maximum <= RAW_MAX:
            raise CalibrationError(
                f"need {RAW_MIN} <= min <= centre <= max <= {RAW_MAX}, got "
                f"{self.minimum}, {self.centre}, {self.maximum}"
            )
        if self.minimum == self.maximum:
            raise CalibrationError(f"an empty range ({self.minimum})")

    def normalise(self, raw: int) -> float:
        """Raw value to [-1, 1] (a trigger: [0, 1]), 0 at the centre, ±1 at the ends."""
        if raw >= self.centre:
            span = self.maximum - self.centre
            value = (raw - self.centre) / span if span else 0.0
        else:
            span = self.centre - self.minimum
            value = (raw - self.centre) / span if span else 0.0
        return min(max(value, -1.0), 1.0)


def default_axis(axis: str) -> AxisCalibration:
    """SDL's own range: sticks centred on 0, triggers resting at 0."""
    if axis in TRIGGERS:
        return AxisCalibration(0, 0, RAW_MAX)
    return AxisCalibration(RAW_MIN, 0, RAW_MAX)


@dataclass(frozen=True)
class PadCalibration:
    """Every axis of one pad (an axis left out has SDL's own range)."""

    axes: Mapping[str, AxisCalibration] = field(default_factory=dict)

    def axis(self, name: str) -> AxisCalibration:
        """One axis's calibration."""
        return self.axes.get(name) or default_axis(name)

    def normalise(self, name: str, raw: int) -> float:
        """One axis's raw value, calibrated."""
        return self.axis(name).normalise(raw)


class CalibrationSession:
    """Learn each axis's range while the operator moves every stick and trigger to its ends."""

    def __init__(self) -> None:
        self.low: dict[str, int] = {}
        self.high: dict[str, int] = {}

    def feed(self, raw_axes: Mapping[str, int]) -> None:
        """One reading of the pad."""
        for axis, raw in raw_axes.items():
            self.low[axis] = min(self.low.get(axis, raw), raw)
            self.high[axis] = max(self.high.get(axis, raw), raw)

    def finish(self, rest: Mapping[str, int]) -> PadCalibration:
        """The calibration, with the centres read at rest; CalibrationError names the axes
        that were not moved far enough or do not rest between their ends."""
        problems = []
        axes = {}
        for axis in AXES:
            if axis not in self.low or axis not in rest:
                problems.append(f"{axis}: never read")
                continue
            low, high, centre = self.low[axis], self.high[axis], rest[axis]
            low, high = min(low, centre), max(high, centre)
            if axis in TRIGGERS:
                if centre - low > CENTRE_LIMIT * RAW_MAX:
                    problems.append(f"{axis}: let go of it before saving")
                elif high - low < MIN_TRAVEL * RAW_MAX:
                    problems.append(f"{axis}: press it all the way, then let go")
                else:
                    axes[axis] = AxisCalibration(low, low, high)
                continue
            half = RAW_MAX * MIN_TRAVEL
            if abs(centre) > CENTRE_LIMIT * RAW_MAX:
                problems.append(f"{axis}: let go of it before saving")
            elif centre - low < half or high - centre < half:
                problems.append(f"{axis}: move it to both ends")
            else:
                axes[axis] = AxisCalibration(low, centre, high)
        if problems:
            raise CalibrationError("; ".join(problems))
        return PadCalibration(axes)


def _parse_axis(where: str, table: Any) -> AxisCalibration:
    if not isinstance(table, dict):
        raise CalibrationError(f"{where}: must be a table like {{ min = -32768, centre = 0 }}")
    for key in table:
        if key not in FIELDS:
            raise CalibrationError(f"{where}.{key}: unknown field (use {', '.join(FIELDS)})")
    values = []
    for key in FIELDS:
        value = table.get(key)
        if isinstance(value, bool) or not isinstance(value, int):
            raise CalibrationError(f"{where}.{key}: must be an integer")
        values.append(value)
    try:
        return AxisCalibration(*values)
    except CalibrationError as err:
        raise CalibrationError(f"{where}: {err}") from err


class CalibrationStore:
    """The calibration file: one table per pad GUID, with the pad's name for people."""

    def __init__(self, path: Path) -> None:
        self.path = path

    def load(self) -> dict[str, tuple[str, PadCalibration]]:
        """Every pad's calibration; an absent file is empty, a bad one a CalibrationError."""
        try:
            text = self.path.read_text(encoding="utf-8")
        except FileNotFoundError:
            return {}
        except (OSError, UnicodeDecodeError) as err:
            raise CalibrationError(f"cannot read {self.path}: {err}") from err
        try:
            data = tomllib.loads(text)
        except tomllib.TOMLDecodeError as err:
            raise CalibrationError(f"{self.path}: not valid TOML: {err}") from err
        pads = data.get("pads", {})
        unknown = [key for key in data if key != "pads"]
        if unknown or not isinstance(pads, dict):
            raise CalibrationError(f"{self.path}: only [pads.GUID] tables belong here")
        result = {}
        for guid, table in pads.items():
            where = f"{self.path}: pads.{guid}"
            if not isinstance(table, dict):
                raise CalibrationError(f"{where}: must be a table")
            name = table.get("name", "")
            if not isinstance(name, str):
                raise CalibrationError(f"{where}.name: must be a string")
            axes = {}
            for axis, value in table.items():
                if axis == "name":
                    continue
                if axis not in AXES:
                    raise CalibrationError(f"{where}.{axis}: unknown axis (use {', '.join(AXES)})")
                axes[axis] = _parse_axis(f"{where}.{axis}", value)
            result[guid] = (name, PadCalibration(axes))
        return result

    def get(self, guid: str) -> PadCalibration:
        """One pad's calibration (SDL's ranges if none was saved)."""
        entry = self.load().get(guid)
        return entry[1] if entry else PadCalibration()

    def save(self, guid: str, name: str, calibration: PadCalibration | None) -> None:
        """Store (None: forget) one pad's calibration; the others are kept. Atomic."""
        pads = self.load()
        if calibration is None:
            pads.pop(guid, None)
        else:
            pads[guid] = (name, calibration)
        lines = [
            "# Game controller calibration, written by ocu (the Gamepad dock's Calibrate).",
            "# Raw SDL values: min, centre (at rest) and max per axis; one table per pad GUID.",
        ]
        for pad_guid, (pad_name, pad) in sorted(pads.items()):
            lines += ["", f"[pads.{json.dumps(pad_guid)}]", f"name = {json.dumps(pad_name)}"]
            for axis in AXES:
                if axis in pad.axes:
                    a = pad.axes[axis]
                    lines.append(
                        f"{axis} = {{ min = {a.minimum}, centre = {a.centre}, max = {a.maximum} }}"
                    )
        write_text_atomically(self.path, "\n".join(lines) + "\n")


def saved_or_default(store: CalibrationStore | None, info: PadInfo) -> PadCalibration:
    """A pad's saved calibration; SDL's ranges if none (or the file is unreadable)."""
    if store is None:
        return PadCalibration()
    try:
        return store.get(info.guid)
    except CalibrationError as err:
        logging.getLogger("ocu.console").warning("%s; using SDL's ranges", err)
        return PadCalibration()

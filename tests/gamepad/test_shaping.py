"""Deadzone, expo, noise settling and calibration of one axis; the calibration file (pure)."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from ocu.gamepad.calibration import (
    AxisCalibration,
    CalibrationError,
    CalibrationSession,
    CalibrationStore,
    PadCalibration,
)
from ocu.gamepad.pad import AXES, RAW_MAX, RAW_MIN
from ocu.gamepad.shaping import AxisShape, settle


def test_deadzone_is_zero_inside_and_continuous_at_its_edge() -> None:
    shape = AxisShape(deadzone=0.05, expo=0.0)
    assert shape.apply(0.0) == 0.0
    assert shape.apply(0.05) == 0.0
    assert shape.apply(-0.049) == 0.0
    assert shape.apply(0.06) == pytest.approx(0.01 / 0.95)
    assert shape.apply(1.0) == 1.0
    assert shape.apply(-1.0) == -1.0
    assert shape.apply(0.525) == pytest.approx(0.5)


def test_expo_is_finer_near_the_centre_and_the_same_at_the_ends() -> None:
    linear, expo = AxisShape(deadzone=0.0), AxisShape(deadzone=0.0, expo=0.5)
    assert expo.apply(0.5) == pytest.approx(0.5 * 0.5 + 0.5 * 0.125)
    assert expo.apply(0.2) < linear.apply(0.2)
    assert expo.apply(-1.0) == -1.0
    with pytest.raises(ValueError, match="expo"):
        AxisShape(expo=1.5)


def test_settle_ignores_noise_but_never_a_stop_or_a_full_deflection() -> None:
    assert settle(0.50, 0.505) == 0.50
    assert settle(0.50, 0.52) == 0.52
    assert settle(0.004, 0.0) == 0.0
    assert settle(0.995, 1.0) == 1.0
    assert settle(0.003, -0.003) == -0.003  # a change of sign passes


def test_calibration_maps_a_worn_stick_to_the_full_range() -> None:
    worn = AxisCalibration(minimum=-29000, centre=900, maximum=28000)
    assert worn.normalise(900) == 0.0
    assert worn.normalise(28000) == 1.0
    assert worn.normalise(32767) == 1.0
    assert worn.normalise(-29000) == -1.0
    assert worn.normalise(900 + 13550) == pytest.approx(0.5)
    with pytest.raises(CalibrationError):
        AxisCalibration(minimum=10, centre=0, maximum=20)


def sweep(session: CalibrationSession, low: int, high: int) -> None:
    """Every stick from `low` to `high`, every trigger from 0 to `high`."""
    triggers = {"lefttrigger": 0, "righttrigger": 0}
    session.feed({**dict.fromkeys(AXES, low), **triggers})
    session.feed(dict.fromkeys(AXES, high))


def test_session_learns_ranges_and_centres() -> None:
    session = CalibrationSession()
    sweep(session, -30000, 31000)
    rest = {**dict.fromkeys(AXES, 400), "lefttrigger": 0, "righttrigger": 0}
    calibration = session.finish(rest)
    assert calibration.axis("leftx") == AxisCalibration(-30000, 400, 31000)
    assert calibration.axis("lefttrigger") == AxisCalibration(0, 0, 31000)


def test_session_refuses_an_axis_not_moved_or_not_released() -> None:
    session = CalibrationSession()
    sweep(session, -30000, 31000)
    session.low["lefty"] = -2000  # lefty was never pushed up
    rest = {**dict.fromkeys(AXES, 0), "righty": 25000}  # righty still held
    with pytest.raises(CalibrationError) as raised:
        session.finish(rest)
    message = str(raised.value)
    assert "lefty: move it to both ends" in message
    assert "righty: let go of it before saving" in message
    assert "leftx" not in message


def test_store_round_trip_keeps_other_pads(tmp_path: Path) -> None:
    store = CalibrationStore(tmp_path / "cfg" / "gamepad-calibration.toml")
    assert store.get("abc") == PadCalibration()
    first = PadCalibration({"leftx": AxisCalibration(-30000, 100, 30000)})
    second = PadCalibration({"righty": AxisCalibration(RAW_MIN, -50, RAW_MAX)})
    store.save("abc", 'Pad "one"', first)
    store.save("def", "Pad two", second)
    assert store.get("abc") == first
    assert store.load()["def"] == ("Pad two", second)
    store.save("abc", "Pad one", None)
    assert set(store.load()) == {"def"}
    assert [p.name for p in store.path.parent.iterdir()] == [store.path.name]  # no temp left


def test_store_keeps_the_old_file_when_a_write_fails(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    store = CalibrationStore(tmp_path / "gamepad-calibration.toml")
    old = PadCalibration({"leftx": AxisCalibration(-30000, 100, 30000)})
    store.save("abc", "Pad", old)
    before = store.path.read_bytes()

    def fail(_src: object, _dst: object) -> None:
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(os, "replace", fail)
    with pytest.raises(OSError, match="No space"):
        store.save("abc", "Pad", PadCalibration())
    assert store.path.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == [store.path.name]


@pytest.mark.parametrize(
    ("text", "error"),
    [
        ("[pads.x]\nleftz = { min = 0, centre = 0, max = 1 }\n", r"pads.x.leftz: unknown axis"),
        ("[pads.x]\nleftx = { min = 0, centre = 0, mx = 1 }\n", r"pads.x.leftx.mx: unknown field"),
        ("[pads.x]\nleftx = { min = 5, centre = 0, max = 9 }\n", r"pads.x.leftx: need"),
        ("[pad]\n", r"only \[pads.GUID\] tables"),
        ("[pads\n", r"not valid TOML"),
    ],
)
def test_bad_calibration_file_is_named(tmp_path: Path, text: str, error: str) -> None:
    store = CalibrationStore(tmp_path / "gamepad-calibration.toml")
    store.path.write_text(text, encoding="utf-8")
    with pytest.raises(CalibrationError, match=error):
        store.load()

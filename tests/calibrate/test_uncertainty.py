"""The uncertainties `ocu calibrate` states cover its errors against the simulator's truth.

It used to print ticks per radian "±0.00-0.11 %" (the least-squares standard error alone)
for errors of 0.3-0.8 %: the robot reports speeds as integers (1000 per rad/s), and every run
of a sweep rests on the same rounded speed, an error no number of samples shows.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from ocu.calibrate.operator import AutoOperator
from tests.calibrate.scrambled import calibrate_scrambled

pytestmark = pytest.mark.slow

STATED = re.compile(
    r"^(?P<joint>\w+): (?P<ticks>[\d.]+) ticks/rad ±(?P<ticks_u>[\d.]+) %, "
    r"(?P<axis>\d+) axis per rad/s ±(?P<axis_u>[\d.]+) % \(about 95 %"
)


def test_the_stated_uncertainties_cover_the_true_errors(tmp_path: Path) -> None:
    said: list[str] = []
    outcome = calibrate_scrambled(
        7, tmp_path, operator=lambda _sim: AutoOperator(said.append), noise_deg=0.0
    )
    assert outcome.result.complete, outcome.result.findings
    truth, found = outcome.truth, outcome.profile
    stated = {m["joint"]: m for m in map(STATED.match, said) if m is not None}
    joints = {name for name, motor in truth.motors.items() if motor.channel is not None}
    assert set(stated) == joints, said
    for name in sorted(joints):
        motor, line = truth.motors[name], stated[name]
        measured = found.motors[name].ticks_per_rad
        assert motor.ticks_per_rad is not None
        assert measured is not None
        assert motor.channel is not None
        ticks_error = abs(measured / motor.ticks_per_rad - 1) * 100
        true_axis = truth.channels[motor.channel].axis_per_unit
        axis_error = abs(found.channels[motor.channel].axis_per_unit / true_axis - 1) * 100
        assert ticks_error <= float(line["ticks_u"]), (name, ticks_error, line[0])
        assert axis_error <= float(line["axis_u"]), (name, axis_error, line[0])
        # Honest, and still worth reading: the rounding of a speed of about 100 steps.
        assert float(line["ticks_u"]) < 1.5, line[0]

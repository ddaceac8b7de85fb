"""The simulator as an unknown robot: `--scramble SEED` redraws what a calibration must find."""

from __future__ import annotations

import copy
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from ocu.profile import AXIS_MAX, load_profile, load_profile_data, parse_profile
from ocu.sim.cli import main
from ocu.sim.scramble import scramble_profile_data

BASE = load_profile_data()


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_every_fact_a_calibration_finds_is_redrawn_within_its_bounds(seed: int) -> None:
    data = scramble_profile_data(BASE, seed)
    truth, base = parse_profile(data), load_profile()
    assert scramble_profile_data(BASE, seed) == data  # a seed is one robot
    assert load_profile_data() == BASE  # the input is left alone
    axes = [c.axis for c in truth.channels.values()]
    assert len(set(axes)) == len(axes)
    assert axes != [c.axis for c in base.channels.values()]
    for name, channel in truth.channels.items():
        assert channel.hard_max * channel.axis_per_unit <= AXIS_MAX
        ratio = channel.axis_per_unit / base.channels[name].axis_per_unit
        spread = 0.5 if base.channels[name].axis_per_unit == 20000.0 else 0.2
        assert 1 - spread <= ratio <= 1 + spread, name
    for name, motor in truth.motors.items():
        assert motor.device_id == base.motors[name].device_id
        if motor.ticks_per_rad is None:
            continue
        base_ticks = base.motors[name].ticks_per_rad
        assert base_ticks is not None
        assert 0.5 <= motor.ticks_per_rad / base_ticks <= 1.5
        # The whole range of the joint stays inside the u32 counter.
        assert motor.limits_rad is not None
        low = motor.zero_offset_ticks + motor.limits_rad[0] * motor.ticks_per_rad
        high = motor.zero_offset_ticks + motor.limits_rad[1] * motor.ticks_per_rad
        assert 0 <= low < high <= 2**32 - 1


def test_directions_are_flipped_across_seeds() -> None:
    signs = {
        c.axis_sign
        for seed in range(4)
        for c in parse_profile(scramble_profile_data(BASE, seed)).channels.values()
    }
    assert signs == {1, -1}


def test_ids_shuffle_only_the_motors_with_a_position() -> None:
    data = scramble_profile_data(BASE, 4, ids=True)
    plain = scramble_profile_data(BASE, 4)
    truth = parse_profile(data)
    moved = [n for n, m in truth.motors.items() if m.device_id != BASE["motors"][n]["device_id"]]
    assert moved
    assert all(truth.motors[n].has_position for n in moved)
    assert {truth.motors[n].device_id for n in truth.motors} == {
        m["device_id"] for m in BASE["motors"].values()
    }
    # The other facts are the same draws with or without the IDs.
    without_ids = copy.deepcopy(data)
    for name in without_ids["motors"]:
        without_ids["motors"][name]["device_id"] = plain["motors"][name]["device_id"]
    assert without_ids == plain


def test_scramble_out_writes_the_hidden_truth(tmp_path: Path) -> None:
    out = tmp_path / "truth.toml"
    command = [sys.executable, "-m", "ocu.sim", "--port", "0", "--video-fps", "0"]
    command += ["--scramble", "9", "--scramble-ids", "--scramble-out", str(out)]
    with subprocess.Popen(command, stdout=subprocess.PIPE, text=True) as sim:
        assert sim.stdout is not None
        assert "listening" in sim.stdout.readline()
        sim.send_signal(signal.SIGTERM)
        assert sim.wait(10) == 0
    truth = load_profile(out)
    assert truth == parse_profile(scramble_profile_data(BASE, 9, ids=True), source=str(out))
    assert "hidden truth of `ocu-sim --scramble 9 --scramble-ids`" in out.read_text()


def test_scramble_options_need_a_seed(tmp_path: Path) -> None:
    with pytest.raises(SystemExit):
        main(["--scramble-out", str(tmp_path / "truth.toml")])
    with pytest.raises(SystemExit):
        main(["--scramble-ids"])
    assert not (tmp_path / "truth.toml").exists()

"""The gamepad mapping file: the shipped default, overrides, and clear errors (no Qt, no SDL)."""

from __future__ import annotations

from pathlib import Path

import pytest

from ocu.gamepad.mapping import (
    AxisBinding,
    ButtonAction,
    PadMappingError,
    load_pad_mapping,
    parse_pad_mapping,
)
from ocu.gamepad.pad import AXES, BUTTONS
from ocu.gamepad.shaping import AxisShape
from ocu.profile import RobotProfile


def test_default_mapping_drives_with_the_left_stick_behind_a_deadman(
    profile: RobotProfile,
) -> None:
    mapping = load_pad_mapping(profile)
    assert mapping.deadman == "leftshoulder"
    assert mapping.axes["lefty"] == AxisBinding("drive_linear", -1)  # stick up: forward
    assert mapping.axes["leftx"] == AxisBinding("drive_turn", -1)  # stick right: turn right
    assert {mapping.axes[a].channel for a in ("rightx", "righty")} == {"shoulder", "elbow"}
    assert {mapping.alt_axes[a].channel for a in ("rightx", "righty")} == {"waist", "neck"}
    assert mapping.binding("rightx", alt=True) == mapping.alt_axes["rightx"]
    assert mapping.binding("leftx", alt=True) == mapping.axes["leftx"]
    assert mapping.axes["lefttrigger"].channel == mapping.axes["righttrigger"].channel == "gripper"
    assert mapping.buttons["dpup"] == ButtonAction(channel="flippers", direction=1)
    assert mapping.buttons_for("emergency_stop") == ["b"]
    assert {mapping.buttons[b].command for b in ("x", "y", "start")} == {
        "camera_next",
        "torch",
        "help",
    }
    assert mapping.shape("leftx") == AxisShape(deadzone=0.05, expo=0.3)
    assert mapping.shape("lefttrigger").expo == 0.0
    assert mapping.background
    assert mapping.stall_timeout_s == pytest.approx(0.1)
    # Every row of the panel names a real control.
    for control, _does in mapping.describe():
        for part in control.split(" + "):
            assert part in AXES or part in BUTTONS


def test_user_file_is_merged_over_the_default(profile: RobotProfile, tmp_path: Path) -> None:
    override = tmp_path / "gamepad.toml"
    override.write_text(
        '[options]\ndeadman = "rightshoulder"\nalt_button = "leftshoulder"\nexpo = 0.0\n'
        'background = false\n[axes]\nrightx = ""\n[buttons]\nb = ""\nback = "emergency_stop"\n'
        'a = "pose stow"\n[shape]\nlefty = { deadzone = 0.1 }\n',
        encoding="utf-8",
    )
    mapping = load_pad_mapping(profile, override)
    assert mapping.deadman == "rightshoulder"
    assert "rightx" not in mapping.axes
    assert mapping.buttons_for("emergency_stop") == ["back"]
    assert mapping.buttons["a"] == ButtonAction(command="pose", argument="stow")
    assert mapping.shape("lefty") == AxisShape(deadzone=0.1, expo=0.0)
    assert mapping.shape("leftx") == AxisShape(deadzone=0.05, expo=0.0)
    assert not mapping.background
    assert mapping.axes["lefty"] == AxisBinding("drive_linear", -1)  # the rest is kept
    assert mapping.sources[-1] == str(override)


@pytest.mark.parametrize(
    ("text", "error"),
    [
        ("[axis]\n", r"axis: unknown table; did you mean 'axes'\?"),
        ("[options]\ndeadmen = 'a'\n", r"options.deadmen: unknown option 'deadmen'; did you mean"),
        ("[options]\ndeadman = 'LB'\n", r"options.deadman: unknown button 'LB'"),
        ("[axes]\nleft_x = 'waist +'\n", r"axes.left_x: unknown axis 'left_x'; did you"),
        ("[axes]\nleftx = 'wiast +'\n", r"unknown channel 'wiast'; did you mean 'waist'"),
        ("[axes]\nleftx = 'waist'\n", r'must be "CHANNEL \+" or "CHANNEL -"'),
        ("[buttons]\nstrat = 'help'\n", r"buttons.strat: unknown button 'strat'; did you mean"),
        ("[buttons]\na = 'tourch'\n", r"unknown command or channel 'tourch'; did you mean 'torch'"),
        ("[buttons]\na = 'pose'\n", r'must be "pose NAME"'),
        ("[buttons]\nleftshoulder = 'torch'\n", r"leftshoulder is the deadman and also buttons"),
        ("[options]\nturbo_button = 'leftshoulder'\n", r"must differ"),
        ("[options]\nscale = 2\n", r"options.scale must be in \(0, 1\]"),
        ("[options]\npoll_hz = 5\n", r"options.poll_hz must be in \[10, 1000\]"),
        ("[options]\nstall_timeout_ms = 5\n", r"stall_timeout_ms must be between 15"),
        ("[options]\nbackground = 'yes'\n", r"options.background must be true or false"),
        ("[shape]\nleftx = { deadzone = 0.7 }\n", r"shape.leftx: deadzone must be in \[0, 0.5\)"),
        ("[shape]\nleftx = { expo_ = 0.2 }\n", r"shape.leftx.expo_: unknown field; did you mean"),
        ("[options]\nalt_button = ''\n", r"\[alt_axes\] need options.alt_button"),
        ("[axes\n", r"not valid TOML"),
    ],
)
def test_bad_mapping_is_refused_with_the_reason(
    profile: RobotProfile, tmp_path: Path, text: str, error: str
) -> None:
    override = tmp_path / "gamepad.toml"
    override.write_text(text, encoding="utf-8")
    with pytest.raises(PadMappingError, match=error) as raised:
        load_pad_mapping(profile, override)
    assert str(override) in str(raised.value)


def test_no_deadman_is_allowed_but_explicit(profile: RobotProfile) -> None:
    mapping = parse_pad_mapping(
        {"options": {"deadman": ""}}, profile, load_pad_mapping(profile), source="test"
    )
    assert mapping.deadman is None
    assert mapping.describe()[0][0] != "leftshoulder"

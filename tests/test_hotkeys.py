"""The key map file and the key bindings as plain functions over the model (no Qt)."""

from __future__ import annotations

from pathlib import Path

import pytest

from ocu import hotkeys
from ocu.console.model import ConsoleModel
from ocu.hotkeys import HoldBinding, KeyMap, KeyMapError, load_key_map
from ocu.profile import RobotProfile

# Table 4 of the paper: key, channel, direction (+ forward / left / up / open).
TABLE_4 = {
    "W": ("drive_linear", 1),
    "S": ("drive_linear", -1),
    "A": ("drive_turn", 1),
    "D": ("drive_turn", -1),
    "Q": ("waist", 1),
    "E": ("waist", -1),
    "Y": ("shoulder", 1),
    "H": ("shoulder", -1),
    "U": ("elbow", 1),
    "J": ("elbow", -1),
    "F": ("flippers", 1),
    "R": ("flippers", -1),
    "T": ("gripper", 1),
    "G": ("gripper", -1),
}


@pytest.fixture
def key_map(profile: RobotProfile) -> KeyMap:
    return load_key_map(profile)


@pytest.fixture
def model(profile: RobotProfile) -> ConsoleModel:
    return ConsoleModel(profile)


def test_default_map_is_table_4(key_map: KeyMap) -> None:
    assert {k: (b.channel, b.direction) for k, b in key_map.hold.items()} == TABLE_4
    paper = {"Space": "emergency_stop", "F1": "help", "Slash": "help"}
    assert {k: key_map.commands[k] for k in paper} == paper
    map_keys = {
        "O": "odometry_reset",
        "Z": "zones_override",
        "L": "assist_linear",
        "P": "assist_path",
        "X": "path_clear",
    }
    assert {k: key_map.commands[k] for k in map_keys} == map_keys
    assert key_map.fine_factor == 0.25


def test_arm_keys_use_only_their_own_keys(key_map: KeyMap) -> None:
    """The arm's commands sit on C V B N M I and F2-F8; Cartesian mode re-reads hold keys."""
    map_commands = (
        "odometry_reset",
        "zones_override",
        "assist_linear",
        "assist_path",
        "path_clear",
    )
    others = ("emergency_stop", "help", *map_commands)
    arm = {k: v for k, v in key_map.commands.items() if v not in others}
    assert set(arm) <= {"C", "V", "B", "N", "M", "I", *(f"F{n}" for n in range(2, 9))}
    assert arm["C"] == "cartesian_mode"
    assert arm["F2"] == "pose_stow"
    jog = {k: b.describe() for k, b in key_map.cartesian.items()}
    assert jog == {
        "W": "x +", "S": "x -", "A": "y +", "D": "y -",
        "R": "z +", "F": "z -", "Y": "pitch +", "H": "pitch -",
    }  # fmt: skip
    assert set(jog) <= set(key_map.hold)  # only keys that already move something
    rows = dict(key_map.help_rows())
    assert rows["W / S (Cartesian)"] == "gripper forward / back"
    assert rows["Y / H (Cartesian)"] == "gripper pitch up / pitch down"
    assert rows["C"].startswith("arm: joint / Cartesian mode")


def test_cartesian_table_errors(profile: RobotProfile) -> None:
    with pytest.raises(KeyMapError, match=r'cartesian\.W: \'spin \+\' must be "AXIS \+"'):
        hotkeys.parse_key_map({"cartesian": {"W": "spin +"}}, profile)
    with pytest.raises(KeyMapError, match="Space is the emergency stop"):
        hotkeys.parse_key_map({"cartesian": {"Space": "x +"}}, profile)
    with pytest.raises(KeyMapError, match="bound to the command 'cartesian_mode' and to a"):
        hotkeys.parse_key_map({"commands": {"C": "cartesian_mode"}, "cartesian": {"C": "z +"}},
                              profile)  # fmt: skip


def test_key_positions_are_the_us_scan_codes() -> None:
    # evdev codes (= PC set-1 scan codes) of a few keys, from linux/input-event-codes.h.
    assert hotkeys.KEY_POSITIONS["Q"] == 16
    assert hotkeys.KEY_POSITIONS["W"] == 17
    assert hotkeys.KEY_POSITIONS["A"] == 30
    assert hotkeys.KEY_POSITIONS["Z"] == 44
    assert hotkeys.KEY_POSITIONS["Space"] == 57
    assert hotkeys.KEY_POSITIONS["Slash"] == 53
    assert hotkeys.KEY_POSITIONS["1"] == 2
    assert hotkeys.KEY_POSITIONS["0"] == 11
    assert hotkeys.KEY_POSITIONS["F12"] == 88
    assert hotkeys.key_for_position(17) == "W"
    assert hotkeys.key_for_position(250) is None
    assert len(set(hotkeys.KEY_POSITIONS.values())) == len(hotkeys.KEY_POSITIONS)


def test_user_file_changes_the_map_without_code(profile: RobotProfile, tmp_path: Path) -> None:
    override = tmp_path / "hotkeys.toml"
    override.write_text(
        '[options]\nfine_factor = 0.5\n[hold]\nI = "drive_linear +"\nW = ""\nF1 = "neck +"\n'
        '[commands]\nP = "emergency_stop"\n',
        encoding="utf-8",
    )
    key_map = load_key_map(profile, override)
    assert key_map.hold["I"] == HoldBinding("drive_linear", 1)
    assert "W" not in key_map.hold
    assert key_map.hold["F1"] == HoldBinding("neck", 1)
    assert "F1" not in key_map.commands
    assert key_map.commands["P"] == "emergency_stop"
    assert key_map.fine_factor == 0.5
    assert key_map.sources[-1] == str(override)
    assert key_map.hold["S"] == HoldBinding("drive_linear", -1)  # the rest is kept


def test_missing_user_file_means_the_default(profile: RobotProfile, tmp_path: Path) -> None:
    assert load_key_map(profile, tmp_path / "none.toml") == load_key_map(profile)


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ('[hold]\n"Ä" = "waist +"\n', "unknown key 'Ä'; known: Escape, 1, 2, "),
        ('[hold]\nw = "waist +"\n', r"hold\.w: unknown key 'w'; did you mean 'W'\?$"),
        (
            '[commands]\nSpcae = "help"\n',
            r"commands\.Spcae: unknown key 'Spcae'; did you mean 'Space'\?$",
        ),
        ('[hold]\nK = "tail +"\n', "unknown channel 'tail'; known: drive_linear, drive_turn, "),
        ('[hold]\nK = "wasit +"\n', r"hold\.K: unknown channel 'wasit'; did you mean 'waist'\?$"),
        ('[hold]\nK = "waist up"\n', "must be"),
        ("[hold]\nK = 3\n", "must be a string"),
        ('[hold]\nSpace = "waist +"\n', "emergency stop"),
        (
            '[commands]\nSpace = "help"\n',
            r"toml: commands\.Space: Space is always the emergency stop; it cannot be bound to "
            r"'help'$",
        ),
        ('[commands]\nSpace = ""\n', r"commands\.Space: .* emergency stop; it cannot be freed$"),
        (
            '[hold]\nK = "waist +"\n[commands]\nK = "help"\n',
            r"toml: K is bound twice, in \[hold\] \('waist \+'\) and in \[commands\] \('help'\); "
            "keep one$",
        ),
        ('[commands]\nK = "dance"\n', "unknown command 'dance'; known: emergency_stop, help, "),
        (
            '[commands]\nK = "halp"\n',
            r"commands\.K: unknown command 'halp'; did you mean 'help'\?$",
        ),
        (
            "[options]\nfine_factr = 0.5\n",
            r"options\.fine_factr: unknown option; .* 'fine_factor'\?$",
        ),
        ("[options]\nspeed = 0.5\n", r"options\.speed: unknown option; known: fine_factor$"),
        ("[options]\nfine_factor = 0\n", r"\(0, 1\]"),
        ('[options]\nfine_factor = "x"\n', "must be a number"),
        ("[keys]\n", r"toml: keys: unknown table; known: options, hold, commands, cartesian$"),
        ('[holds]\nK = "waist +"\n', r"toml: holds: unknown table; did you mean 'hold'\?$"),
        ("hold = 3\n", "must be a table"),
        ("[hold\n", "not valid TOML"),
    ],
)
def test_bad_user_files_are_refused_with_the_reason(
    profile: RobotProfile, tmp_path: Path, text: str, message: str
) -> None:
    override = tmp_path / "hotkeys.toml"
    override.write_text(text, encoding="utf-8")
    with pytest.raises(KeyMapError, match=message) as raised:
        load_key_map(profile, override)
    assert str(raised.value).startswith(f"{override}: ")  # the file is named


def test_non_utf8_file_is_refused_with_the_reason(profile: RobotProfile, tmp_path: Path) -> None:
    override = tmp_path / "hotkeys.toml"
    override.write_bytes(b'[hold]\nK = "waist \xff"\n')
    with pytest.raises(KeyMapError, match=r"hotkeys\.toml: not UTF-8 text: .*byte 0xff"):
        load_key_map(profile, override)


def test_every_table_4_key_moves_its_channel_while_held(
    model: ConsoleModel, key_map: KeyMap
) -> None:
    for key, (channel, direction) in TABLE_4.items():
        assert hotkeys.press(model, key_map, key)
        assert model.velocities() == {channel: direction * model.hotkey_speed(channel)}
        assert hotkeys.release(model, key_map, key)
        assert model.velocities() == {}


def test_space_stops_everything(model: ConsoleModel, key_map: KeyMap) -> None:
    stops: list[str] = []
    model.events.estop_requested.connect(stops.append)
    hotkeys.press(model, key_map, "W")
    hotkeys.press(model, key_map, "Q")
    assert hotkeys.press(model, key_map, "Space")
    assert stops == ["Space"]
    assert model.velocities() == {}
    assert model.estopped
    assert not hotkeys.release(model, key_map, "W")  # nothing held any more


def test_help_keys_toggle_and_escape_closes(model: ConsoleModel, key_map: KeyMap) -> None:
    assert hotkeys.press(model, key_map, "F1")
    assert model.help_visible
    assert hotkeys.press(model, key_map, "Slash")
    assert not model.help_visible
    assert not hotkeys.press(model, key_map, "Escape")  # nothing to close: not consumed
    hotkeys.toggle_help(model)
    assert hotkeys.press(model, key_map, "Escape")
    assert not model.help_visible


def test_unbound_keys_are_not_consumed(model: ConsoleModel, key_map: KeyMap) -> None:
    assert not hotkeys.press(model, key_map, "K")
    assert not hotkeys.release(model, key_map, "K")


def test_release_all_and_shift(model: ConsoleModel, key_map: KeyMap) -> None:
    hotkeys.press(model, key_map, "Q")
    hotkeys.set_fine(model, True)
    assert model.velocities() == {"waist": model.fine_speed("waist")}
    assert hotkeys.release_all(model, "focus lost")
    assert model.velocities() == {}
    assert not hotkeys.release_all(model, "focus lost")


def test_help_rows_list_every_binding(key_map: KeyMap) -> None:
    rows = dict(key_map.help_rows())
    assert rows["W / S"] == "drive linear: forward / reverse"
    assert rows["T / G"] == "gripper: open / close"
    assert rows["Space"].startswith("EMERGENCY STOP")
    assert rows["F1 or ?"] == "show / hide this help"
    assert "Shift + key" in rows
    arm = [k for k, v in rows.items() if v.startswith(("arm:", "gripper ")) or "Cartesian" in k]
    assert rows["O"] == "map: reset odometry to (0, 0, 0°)"
    assert rows["Z"] == "map: override the safety zones for the next motion"
    # 7 channels, Shift, Space, help and the five map commands (and the arm's rows).
    assert len(rows) - len(arm) == 15

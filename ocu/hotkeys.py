"""Hotkeys: the key map file and the key bindings, plain functions over a ConsoleModel (no Qt).

A key is named by its position on a US keyboard ("W"), whatever the layout prints on it; the
Qt side turns a key event into that name (from the scan code when the platform gives one)
and calls `press` / `release` here.
"""

from __future__ import annotations

import math
import tomllib
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

from ocu.console.arm import ArmConsole
from ocu.console.model import DEFAULT_FINE_FACTOR, ConsoleModel
from ocu.console.poses import PoseError
from ocu.kinematics.arm import ArmError
from ocu.profile import RobotProfile, companion_file, did_you_mean
from ocu.records import CommandError

USER_KEY_MAP_NAME = "hotkeys.toml"
ESTOP_KEY = "Space"
CLOSE_HELP_KEY = "Escape"
TABLES = ("options", "hold", "commands", "cartesian")
# What a [cartesian] key moves: tool0 along an axis of the jog frame, or its pitch; an arm of
# six joints or more also turns it about the frame's x (roll) and z (yaw), pitch being y.
CARTESIAN_AXES = ("x", "y", "z", "pitch", "roll", "yaw")
CARTESIAN_WORDS = {
    "x": ("forward", "back"),
    "y": ("left", "right"),
    "z": ("up", "down"),
    "pitch": ("pitch up", "pitch down"),
    "roll": ("roll +", "roll -"),
    "yaw": ("turn left", "turn right"),
}
OPTIONS = ("fine_factor",)

# Linux evdev key codes (the PC set-1 scan codes of the main block) of the US positions.
# X11 and Wayland report evdev + 8 as the native scan code; Windows reports the set-1 code.
KEY_POSITIONS: dict[str, int] = {
    "Escape": 1,
    **{str((n + 1) % 10): 2 + n for n in range(10)},
    "Minus": 12,
    "Equal": 13,
    **{letter: 16 + n for n, letter in enumerate("QWERTYUIOP")},
    "BracketLeft": 26,
    "BracketRight": 27,
    **{letter: 30 + n for n, letter in enumerate("ASDFGHJKL")},
    "Semicolon": 39,
    "Apostrophe": 40,
    "Grave": 41,
    "Backslash": 43,
    **{letter: 44 + n for n, letter in enumerate("ZXCVBNM")},
    "Comma": 51,
    "Period": 52,
    "Slash": 53,
    "Space": 57,
    **{f"F{n + 1}": 59 + n for n in range(10)},
    "F11": 87,
    "F12": 88,
}
_NAME_BY_POSITION = {code: name for name, code in KEY_POSITIONS.items()}
# How the help names a key, where its name is not what is printed on it.
KEY_LABELS = {"Slash": "?", "Minus": "-", "Equal": "=", "Comma": ",", "Period": "."}


class KeyMapError(ValueError):
    """The key map file is missing, not TOML, or binds something unknown."""


@dataclass(frozen=True)
class HoldBinding:
    """Hold a key to move one channel in one direction."""

    channel: str
    direction: int

    def describe(self) -> str:
        """'drive_linear +' as written in the key map file."""
        return f"{self.channel} {'+' if self.direction > 0 else '-'}"


@dataclass(frozen=True)
class JogBinding:
    """In Cartesian mode, hold a key to move tool0 along an axis (or pitch it) one way."""

    axis: str
    direction: int

    def describe(self) -> str:
        """'x +' as written in the key map file."""
        return f"{self.axis} {'+' if self.direction > 0 else '-'}"


@dataclass(frozen=True)
class KeyMap:
    """Key name to hold binding or command name, and the Shift fine factor."""

    hold: Mapping[str, HoldBinding]
    commands: Mapping[str, str]
    fine_factor: float = DEFAULT_FINE_FACTOR
    sources: tuple[str, ...] = ()
    # Words for each channel's + and - (the profile's `directions`), for the help.
    directions: Mapping[str, tuple[str, str]] = field(default_factory=dict)
    # Cartesian mode: these keys jog tool0 instead of what [hold] says.
    cartesian: Mapping[str, JogBinding] = field(default_factory=dict)

    def is_bound(self, key: str) -> bool:
        """Whether pressing this key does something."""
        return key in self.hold or key in self.commands or key in self.cartesian or key == ESTOP_KEY

    def keys_for(self, command: str) -> list[str]:
        """Keys bound to a command, Space first for the emergency stop."""
        keys = [key for key, name in self.commands.items() if name == command]
        if command == "emergency_stop" and ESTOP_KEY not in keys:
            keys.insert(0, ESTOP_KEY)
        return keys

    def help_rows(self) -> list[tuple[str, str]]:
        """(keys, what they do) for the help overlay, one row per channel."""
        by_channel: dict[str, dict[int, list[str]]] = {}
        for key, binding in self.hold.items():
            directions = by_channel.setdefault(binding.channel, {1: [], -1: []})
            directions[binding.direction].append(key_label(key))
        lines = []
        for channel, directions in by_channel.items():
            words = self.directions.get(channel, ("+", "-"))
            keys = " / ".join(" ".join(directions[d]) for d in (1, -1) if directions[d])
            what = " / ".join(words[i] for i, d in enumerate((1, -1)) if directions[d])
            lines.append((keys, f"{channel.replace('_', ' ')}: {what}"))
        lines.append(("Shift + key", f"fine: {self.fine_factor:g} of the hotkey speed"))
        if self.cartesian:
            by_axis: dict[str, dict[int, list[str]]] = {}
            for key, jog in self.cartesian.items():
                by_axis.setdefault(jog.axis, {1: [], -1: []})[jog.direction].append(key_label(key))
            for axis in CARTESIAN_AXES:
                if axis not in by_axis:
                    continue
                keys = " / ".join(" ".join(by_axis[axis][d]) for d in (1, -1) if by_axis[axis][d])
                what = " / ".join(
                    CARTESIAN_WORDS[axis][i] for i, d in enumerate((1, -1)) if by_axis[axis][d]
                )
                lines.append((f"{keys} (Cartesian)", f"gripper {what}"))
        for command in dict.fromkeys(self.commands.values()):
            keys = " or ".join(key_label(k) for k in self.keys_for(command))
            lines.append((keys, COMMAND_TITLES[command]))
        if "emergency_stop" not in self.commands.values():
            lines.append((ESTOP_KEY, COMMAND_TITLES["emergency_stop"]))
        return lines


def key_label(key: str) -> str:
    """What the help shows for a key name ('Slash' -> '?')."""
    return KEY_LABELS.get(key, key)


def key_for_position(code: int) -> str | None:
    """The key name at an evdev position, or None."""
    return _NAME_BY_POSITION.get(code)


def default_key_map_path(profile: RobotProfile | None = None) -> Path:
    """The robot's shipped key map: `hotkeys.toml` beside its profile (a UR's in
    ocu/profiles/ur/), else the package's (the Engineer's: the paper's table 4)."""
    beside = companion_file(profile, "hotkeys.toml") if profile is not None else None
    if beside is not None:
        return beside
    return Path(str(resources.files("ocu") / "profiles" / "hotkeys.toml"))


def _read_toml(path: Path) -> dict[str, Any]:
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as err:
        raise KeyMapError(f"cannot read key map {path}: {err.strerror}") from err
    except UnicodeDecodeError as err:
        raise KeyMapError(f"{path}: not UTF-8 text: {err}") from err
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        raise KeyMapError(f"{path}: not valid TOML: {err}") from err


def _check_key(key: str, where: str) -> None:
    if key not in KEY_POSITIONS:
        raise KeyMapError(f"{where}: unknown key {key!r}; {did_you_mean(key, KEY_POSITIONS)}")


def _table(data: dict[str, Any], name: str, source: str) -> dict[str, Any]:
    table = data.get(name, {})
    if not isinstance(table, dict):
        raise KeyMapError(f"{source}: [{name}] must be a table")
    return table


def parse_key_map(
    data: dict[str, Any], profile: RobotProfile, base: KeyMap | None = None, source: str = "?"
) -> KeyMap:
    """Validate a decoded key map and merge it over `base`."""
    for name in data:
        if name not in TABLES:
            raise KeyMapError(f"{source}: {name}: unknown table; {did_you_mean(name, TABLES)}")
    hold = dict(base.hold) if base else {}
    commands = dict(base.commands) if base else {}
    cartesian = dict(base.cartesian) if base else {}
    fine_factor = base.fine_factor if base else DEFAULT_FINE_FACTOR

    options = _table(data, "options", source)
    for name in options:
        if name not in OPTIONS:
            raise KeyMapError(
                f"{source}: options.{name}: unknown option; {did_you_mean(name, OPTIONS)}"
            )
    if "fine_factor" in options:
        value = options["fine_factor"]
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise KeyMapError(f"{source}: options.fine_factor must be a number")
        if not (math.isfinite(value) and 0.0 < value <= 1.0):
            raise KeyMapError(f"{source}: options.fine_factor must be in (0, 1], got {value}")
        fine_factor = float(value)

    hold_table = _table(data, "hold", source)
    commands_table = _table(data, "commands", source)
    for key, text in hold_table.items():
        other = commands_table.get(key)
        if text and other:
            # Which one would win is an accident of the order the tables are read in.
            raise KeyMapError(
                f"{source}: {key} is bound twice, in [hold] ({text!r}) and in [commands] "
                f"({other!r}); keep one"
            )
    for key, text in hold_table.items():
        where = f"{source}: hold.{key}"
        _check_key(key, where)
        if not isinstance(text, str):
            raise KeyMapError(f'{where}: must be a string like "waist +"')
        commands.pop(key, None)
        if not text.strip():
            hold.pop(key, None)
            continue
        parts = text.split()
        if len(parts) != 2 or parts[1] not in ("+", "-"):
            raise KeyMapError(f'{where}: {text!r} must be "CHANNEL +" or "CHANNEL -"')
        if parts[0] not in profile.channels:
            raise KeyMapError(
                f"{where}: unknown channel {parts[0]!r}; {did_you_mean(parts[0], profile.channels)}"
            )
        hold[key] = HoldBinding(parts[0], 1 if parts[1] == "+" else -1)

    for key, name in commands_table.items():
        where = f"{source}: commands.{key}"
        _check_key(key, where)
        if not isinstance(name, str):
            raise KeyMapError(f"{where}: must be a command name")
        if key == ESTOP_KEY and name != "emergency_stop":
            raise KeyMapError(
                f"{where}: {ESTOP_KEY} is always the emergency stop; it cannot be "
                + (f"bound to {name!r}" if name else "freed")
            )
        hold.pop(key, None)
        if not name:
            commands.pop(key, None)
            continue
        if name not in COMMANDS:
            raise KeyMapError(f"{where}: unknown command {name!r}; {did_you_mean(name, COMMANDS)}")
        commands[key] = name
    for key, text in _table(data, "cartesian", source).items():
        where = f"{source}: cartesian.{key}"
        _check_key(key, where)
        if not isinstance(text, str):
            raise KeyMapError(f'{where}: must be a string like "x +"')
        if not text.strip():
            cartesian.pop(key, None)
            continue
        parts = text.split()
        if len(parts) != 2 or parts[1] not in ("+", "-") or parts[0] not in CARTESIAN_AXES:
            raise KeyMapError(
                f'{where}: {text!r} must be "AXIS +" or "AXIS -" with AXIS one of '
                f"{', '.join(CARTESIAN_AXES)}"
            )
        cartesian[key] = JogBinding(parts[0], 1 if parts[1] == "+" else -1)
    if ESTOP_KEY in hold or ESTOP_KEY in cartesian:
        raise KeyMapError(f"{source}: {ESTOP_KEY} is the emergency stop and cannot move a joint")
    for key in cartesian:
        if key in commands:
            raise KeyMapError(
                f"{source}: {key} is bound to the command {commands[key]!r} and to a Cartesian "
                "jog; free one of them"
            )
    sources = (*base.sources, source) if base else (source,)
    directions = {name: channel.directions for name, channel in profile.channels.items()}
    return KeyMap(
        hold=hold,
        commands=commands,
        fine_factor=fine_factor,
        sources=sources,
        directions=directions,
        cartesian=cartesian,
    )


def load_key_map(profile: RobotProfile, override: Path | None = None) -> KeyMap:
    """The robot's shipped key map, with the user's override file merged over it when it
    exists."""
    default = default_key_map_path(profile)
    key_map = parse_key_map(_read_toml(default), profile, source=str(default))
    if override is not None and override.exists():
        key_map = parse_key_map(_read_toml(override), profile, key_map, source=str(override))
    return key_map


# ---- key bindings: plain functions over the model ------------------------------------------


def emergency_stop(model: ConsoleModel, reason: str = "Space") -> None:
    """Stop everything now and latch until the operator acts again."""
    model.emergency_stop(reason)


def toggle_help(model: ConsoleModel) -> None:
    """Show or hide the hotkey help overlay."""
    model.set_help_visible(not model.help_visible)


def _with_arm(action: Callable[[ArmConsole], None]) -> Callable[[ConsoleModel], None]:
    """A command on the arm; says why when the console has no Cartesian arm control."""

    def run(model: ConsoleModel) -> None:
        if model.arm is None:
            model.events.message.emit(model.arm_error or "this robot has no arm profile")
            return
        try:
            action(model.arm)
        except (ArmError, PoseError) as err:
            model.events.message.emit(f"arm: {err}")

    run.__doc__ = action.__doc__
    return run


def _go(name: str) -> Callable[[ArmConsole], None]:
    def go(arm: ArmConsole) -> None:
        arm.go_to(name)

    go.__doc__ = f"Move the arm to its stored pose {name!r}."
    return go


def _accept(arm: ArmConsole) -> None:
    """Move the arm to the goal shown."""
    arm.accept()


def _toggle_workspace(arm: ArmConsole) -> None:
    """Show or hide the reachable workspace in the 3D view."""
    arm.set_show_workspace(not arm.show_workspace)


def _refused(model: ConsoleModel, action: Callable[[], None]) -> None:
    """Run an operator action; a refusal (no points marked, ...) becomes a message."""
    try:
        action()
    except CommandError as err:
        model.events.message.emit(str(err))


def odometry_reset(model: ConsoleModel) -> None:
    """The robot is at the map's origin again (the operator knows where it is)."""
    model.reset_odometry()


def zones_override(model: ConsoleModel) -> None:
    """Let the next motion through the safety zones (pushing an object)."""
    model.override_zones()


def assist_linear(model: ConsoleModel) -> None:
    """Start the linear shuttle between the marked points, or stop it."""
    if model.assist_mode == "linear":
        model.stop_assist("L pressed")
    else:
        _refused(model, model.start_linear)


def assist_path(model: ConsoleModel) -> None:
    """Follow the waypoints, or stop following them."""
    if model.assist_mode == "path":
        model.stop_assist("P pressed")
    else:
        _refused(model, model.start_path)


def path_clear(model: ConsoleModel) -> None:
    """Forget the waypoints and shuttle points; a running mode stops."""
    model.clear_waypoints()


COMMANDS: dict[str, Callable[[ConsoleModel], None]] = {
    "emergency_stop": emergency_stop,
    "help": toggle_help,
    "cartesian_mode": _with_arm(ArmConsole.toggle_cartesian),
    "jog_frame": _with_arm(ArmConsole.cycle_frame),
    "jog_faster": _with_arm(ArmConsole.faster),
    "jog_slower": _with_arm(ArmConsole.slower),
    "arm_accept": _with_arm(_accept),
    "arm_workspace": _with_arm(_toggle_workspace),
    "pose_stow": _with_arm(_go("stow")),
    "pose_ready": _with_arm(_go("ready")),
    "pose_look_forward": _with_arm(_go("look_forward")),
    "pose_look_back": _with_arm(_go("look_back")),
    "odometry_reset": odometry_reset,
    "zones_override": zones_override,
    "assist_linear": assist_linear,
    "assist_path": assist_path,
    "path_clear": path_clear,
}
COMMAND_TITLES = {
    "emergency_stop": "EMERGENCY STOP (also the StopAll button)",
    "help": "show / hide this help",
    "cartesian_mode": "arm: joint / Cartesian mode (the driving keys move the gripper)",
    "jog_frame": "arm: jog frame base → tool → camera",
    "jog_faster": "arm: jog faster (×1.5)",
    "jog_slower": "arm: jog slower (÷1.5)",
    "arm_accept": "arm: go to the goal shown (Accept)",
    "arm_workspace": "arm: show / hide the reachable workspace",
    "pose_stow": "arm: stored pose stow",
    "pose_ready": "arm: stored pose ready",
    "pose_look_forward": "arm: stored pose look forward",
    "pose_look_back": "arm: stored pose look back",
    "odometry_reset": "map: reset odometry to (0, 0, 0°)",
    "zones_override": "map: override the safety zones for the next motion",
    "assist_linear": "map: linear shuttle between the marked points, start / stop",
    "assist_path": "map: follow the waypoints, start / stop",
    "path_clear": "map: clear waypoints and shuttle points",
}


def press(model: ConsoleModel, key_map: KeyMap, key: str) -> bool:
    """A key went down (auto-repeat already filtered out); True if it is bound."""
    if key == ESTOP_KEY:
        emergency_stop(model, ESTOP_KEY)
        return True
    jog = key_map.cartesian.get(key)
    if jog is not None and model.arm is not None and model.arm.cartesian:
        model.arm_jog_down(key, jog.axis, jog.direction)
        return True
    binding = key_map.hold.get(key)
    if binding is not None:
        model.hotkey_down(key, binding.channel, binding.direction)
        return True
    command = key_map.commands.get(key)
    if command is not None:
        COMMANDS[command](model)
        return True
    if key == CLOSE_HELP_KEY and model.help_visible:
        model.set_help_visible(False)
        return True
    if key == CLOSE_HELP_KEY and model.tracking is not None:
        model.stop_tracking("Esc")
        return True
    return False


def release(model: ConsoleModel, key_map: KeyMap, key: str) -> bool:
    """A key went up; True if it was a held motion key."""
    return model.hotkey_up(key)


def release_all(model: ConsoleModel, reason: str) -> bool:
    """Release every held key (focus lost, window hidden); True if any was held."""
    return model.release_hotkeys(reason)


def set_fine(model: ConsoleModel, fine: bool) -> None:
    """Shift went down or up."""
    model.set_fine(fine)

"""The gamepad mapping file: which stick, trigger and button does what (TOML, validated).

Like the hotkey file: the shipped default is `ocu/profiles/gamepad.toml`; a `gamepad.toml` in
the config directory (or `--pad-map FILE`) is merged over it, entry by entry. Every name is
checked — tables, options, SDL's axis and button names, the profile's channels, commands —
and a wrong one is refused with the file, the key and what was probably meant.
"""

from __future__ import annotations

import math
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

from ocu.gamepad.pad import AXES, BUTTONS
from ocu.gamepad.shaping import AxisShape
from ocu.profile import RobotProfile, companion_file, did_you_mean

USER_PAD_MAP_NAME = "gamepad.toml"
TABLES = ("options", "axes", "alt_axes", "buttons", "shape")
OPTIONS = (
    "deadman",
    "alt_button",
    "turbo_button",
    "scale",
    "deadzone",
    "expo",
    "poll_hz",
    "stall_timeout_ms",
    "background",
)
BUTTON_OPTIONS = ("deadman", "alt_button", "turbo_button")
SHAPE_FIELDS = ("deadzone", "expo")
# One-shot commands a button can give; `pose NAME` calls the console's "pose" hook.
COMMANDS = ("emergency_stop", "torch", "camera_next", "camera_previous", "help")
HOOKS = ("pose",)
COMMAND_TITLES = {
    "emergency_stop": "EMERGENCY STOP (latched, like Space)",
    "torch": "torch on / off",
    "camera_next": "next camera",
    "camera_previous": "previous camera",
    "help": "show / hide the hotkey help",
    "pose": "stored pose",
}
POLL_HZ_RANGE = (10.0, 1000.0)
# The poll thread is declared stalled after this many periods at least.
MIN_STALL_PERIODS = 3


class PadMappingError(ValueError):
    """The mapping file is missing, not TOML, or names something unknown."""


@dataclass(frozen=True)
class AxisBinding:
    """An axis drives a channel; sign -1 when the axis's + is the channel's -."""

    channel: str
    sign: int

    def describe(self) -> str:
        """'drive_linear -' as written in the file."""
        return f"{self.channel} {'+' if self.sign > 0 else '-'}"


@dataclass(frozen=True)
class ButtonAction:
    """A button held moves a channel (channel, direction), or a press gives a command."""

    channel: str | None = None
    direction: int = 0
    command: str | None = None
    argument: str = ""

    def describe(self) -> str:
        """What the file says: 'flippers +', 'torch', 'pose stow'."""
        if self.channel is not None:
            return f"{self.channel} {'+' if self.direction > 0 else '-'}"
        return f"{self.command} {self.argument}".strip()


@dataclass(frozen=True)
class PadMapping:
    """The whole mapping: bindings, shapes and the options."""

    axes: Mapping[str, AxisBinding]
    alt_axes: Mapping[str, AxisBinding]
    buttons: Mapping[str, ButtonAction]
    shapes: Mapping[str, AxisShape]
    deadman: str | None = "leftshoulder"
    alt_button: str | None = "rightshoulder"
    turbo_button: str | None = None
    scale: float = 1.0
    poll_hz: float = 200.0
    stall_timeout_s: float = 0.1
    background: bool = True
    sources: tuple[str, ...] = ()
    # Words for each channel's + and - (the profile's `directions`), for the panel.
    directions: Mapping[str, tuple[str, str]] = field(default_factory=dict)

    def binding(self, axis: str, alt: bool) -> AxisBinding | None:
        """What an axis drives now: its alt binding while the alt button is held."""
        if alt and axis in self.alt_axes:
            return self.alt_axes[axis]
        return self.axes.get(axis)

    def channels(self) -> list[str]:
        """Every channel the pad can move, in a stable order."""
        names = [b.channel for b in (*self.axes.values(), *self.alt_axes.values())]
        names += [a.channel for a in self.buttons.values() if a.channel is not None]
        return list(dict.fromkeys(names))

    def shape(self, axis: str) -> AxisShape:
        """One axis's deadzone and expo."""
        return self.shapes[axis]

    def buttons_for(self, command: str) -> list[str]:
        """Buttons bound to a command."""
        return [name for name, action in self.buttons.items() if action.command == command]

    def describe(self) -> list[tuple[str, str]]:
        """(control, what it does) rows for the panel and the docs."""
        rows = []
        if self.deadman:
            rows.append((self.deadman, "deadman: hold to move the robot"))
        for axis in AXES:
            if axis in self.axes:
                rows.append((axis, self._describe_binding(self.axes[axis])))
        if self.alt_button and self.alt_axes:
            rows.append((self.alt_button, "hold: the right stick's other joints"))
            for axis in AXES:
                if axis in self.alt_axes:
                    held = self._describe_binding(self.alt_axes[axis])
                    rows.append((f"{self.alt_button} + {axis}", held))
        if self.turbo_button:
            rows.append((self.turbo_button, "hold: full stick = the maximum velocity"))
        for button in BUTTONS:
            action = self.buttons.get(button)
            if action is None:
                continue
            if action.channel is not None:
                words = self.directions.get(action.channel, ("+", "-"))
                word = words[0] if action.direction > 0 else words[1]
                rows.append((button, f"{action.channel.replace('_', ' ')}: {word}"))
            else:
                assert action.command is not None
                title = COMMAND_TITLES[action.command]
                rows.append((button, f"{title} {action.argument}".strip()))
        return rows

    def _describe_binding(self, binding: AxisBinding) -> str:
        words = self.directions.get(binding.channel, ("+", "-"))
        return f"{binding.channel.replace('_', ' ')} ({words[0]} / {words[1]})"


def default_pad_map_path(profile: RobotProfile | None = None) -> Path:
    """The robot's shipped mapping: `gamepad.toml` beside its profile, else the package's
    (the Engineer's)."""
    beside = companion_file(profile, "gamepad.toml") if profile is not None else None
    if beside is not None:
        return beside
    return Path(str(resources.files("ocu") / "profiles" / "gamepad.toml"))


def _read_toml(path: Path) -> dict[str, Any]:
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as err:
        raise PadMappingError(f"cannot read gamepad mapping {path}: {err.strerror}") from err
    except UnicodeDecodeError as err:
        raise PadMappingError(f"{path}: not UTF-8 text: {err}") from err
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        raise PadMappingError(f"{path}: not valid TOML: {err}") from err


def _table(data: dict[str, Any], name: str, source: str) -> dict[str, Any]:
    table = data.get(name, {})
    if not isinstance(table, dict):
        raise PadMappingError(f"{source}: [{name}] must be a table")
    return table


def _check_name(name: str, known: tuple[str, ...], what: str, where: str) -> None:
    if name not in known:
        raise PadMappingError(f"{where}: unknown {what} {name!r}; {did_you_mean(name, known)}")


def _channel_and_sign(text: Any, where: str, profile: RobotProfile) -> tuple[str, int]:
    if not isinstance(text, str):
        raise PadMappingError(f'{where}: must be a string like "waist +"')
    parts = text.split()
    if len(parts) != 2 or parts[1] not in ("+", "-"):
        raise PadMappingError(f'{where}: {text!r} must be "CHANNEL +" or "CHANNEL -"')
    if parts[0] not in profile.channels:
        raise PadMappingError(
            f"{where}: unknown channel {parts[0]!r}; {did_you_mean(parts[0], profile.channels)}"
        )
    return parts[0], 1 if parts[1] == "+" else -1


def _number(options: dict[str, Any], name: str, source: str) -> float:
    value = options[name]
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise PadMappingError(f"{source}: options.{name} must be a finite number, got {value!r}")
    return float(value)


def _shape(
    table: dict[str, Any], base: AxisShape, where: str, options: dict[str, float]
) -> AxisShape:
    values = {"deadzone": base.deadzone, "expo": base.expo, **options}
    for key, value in table.items():
        if key not in SHAPE_FIELDS:
            raise PadMappingError(
                f"{where}.{key}: unknown field; {did_you_mean(key, SHAPE_FIELDS)}"
            )
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise PadMappingError(f"{where}.{key}: must be a number")
        values[key] = float(value)
    try:
        return AxisShape(deadzone=values["deadzone"], expo=values["expo"])
    except ValueError as err:
        raise PadMappingError(f"{where}: {err}") from err


def parse_pad_mapping(
    data: dict[str, Any], profile: RobotProfile, base: PadMapping | None = None, source: str = "?"
) -> PadMapping:
    """Validate a decoded mapping and merge it over `base`."""
    for name in data:
        if name not in TABLES:
            raise PadMappingError(f"{source}: {name}: unknown table; {did_you_mean(name, TABLES)}")
    axes = dict(base.axes) if base else {}
    alt_axes = dict(base.alt_axes) if base else {}
    buttons = dict(base.buttons) if base else {}
    settings: dict[str, Any] = {}
    if base is not None:
        settings = {
            "deadman": base.deadman,
            "alt_button": base.alt_button,
            "turbo_button": base.turbo_button,
            "scale": base.scale,
            "poll_hz": base.poll_hz,
            "stall_timeout_s": base.stall_timeout_s,
            "background": base.background,
        }

    options = _table(data, "options", source)
    for name in options:
        _check_name(name, OPTIONS, "option", f"{source}: options.{name}")
    for name in BUTTON_OPTIONS:
        if name in options:
            value = options[name]
            if not isinstance(value, str):
                raise PadMappingError(f'{source}: options.{name} must be a button name or ""')
            if value:
                _check_name(value, BUTTONS, "button", f"{source}: options.{name}")
            settings[name] = value or None
    if "scale" in options:
        scale = _number(options, "scale", source)
        if not 0.0 < scale <= 1.0:
            raise PadMappingError(f"{source}: options.scale must be in (0, 1], got {scale:g}")
        settings["scale"] = scale
    if "poll_hz" in options:
        poll_hz = _number(options, "poll_hz", source)
        low, high = POLL_HZ_RANGE
        if not low <= poll_hz <= high:
            raise PadMappingError(
                f"{source}: options.poll_hz must be in [{low:g}, {high:g}], got {poll_hz:g}"
            )
        settings["poll_hz"] = poll_hz
    if "stall_timeout_ms" in options:
        settings["stall_timeout_s"] = _number(options, "stall_timeout_ms", source) / 1000.0
    if "background" in options:
        if not isinstance(options["background"], bool):
            raise PadMappingError(f"{source}: options.background must be true or false")
        settings["background"] = options["background"]
    overall = {}
    for name in SHAPE_FIELDS:
        if name in options:
            overall[name] = _number(options, name, source)

    for table_name, bindings in (("axes", axes), ("alt_axes", alt_axes)):
        for axis, text in _table(data, table_name, source).items():
            where = f"{source}: {table_name}.{axis}"
            _check_name(axis, AXES, "axis", where)
            if text == "":
                bindings.pop(axis, None)
                continue
            channel, sign = _channel_and_sign(text, where, profile)
            bindings[axis] = AxisBinding(channel, sign)

    for button, text in _table(data, "buttons", source).items():
        where = f"{source}: buttons.{button}"
        _check_name(button, BUTTONS, "button", where)
        if not isinstance(text, str):
            raise PadMappingError(f'{where}: must be a string like "torch" or "flippers +"')
        parts = text.split()
        if not parts:
            buttons.pop(button, None)
        elif parts[0] in COMMANDS:
            if len(parts) != 1:
                raise PadMappingError(f"{where}: {parts[0]} takes no argument")
            buttons[button] = ButtonAction(command=parts[0])
        elif parts[0] in HOOKS:
            if len(parts) != 2:
                raise PadMappingError(f'{where}: {text!r} must be "{parts[0]} NAME"')
            buttons[button] = ButtonAction(command=parts[0], argument=parts[1])
        elif parts[0] in profile.channels:
            channel, sign = _channel_and_sign(text, where, profile)
            buttons[button] = ButtonAction(channel=channel, direction=sign)
        else:
            known = (*COMMANDS, *HOOKS, *profile.channels)
            raise PadMappingError(
                f"{where}: unknown command or channel {parts[0]!r}; {did_you_mean(parts[0], known)}"
            )

    shapes_table = _table(data, "shape", source)
    for axis in shapes_table:
        _check_name(axis, AXES, "axis", f"{source}: shape.{axis}")
    shapes = {}
    for axis in AXES:
        inherited = base.shapes[axis] if base else AxisShape()
        table = shapes_table.get(axis, {})
        if not isinstance(table, dict):
            raise PadMappingError(f"{source}: shape.{axis} must be a table like {{ expo = 0.3 }}")
        shapes[axis] = _shape(table, inherited, f"{source}: shape.{axis}", overall)

    mapping = PadMapping(
        axes=axes,
        alt_axes=alt_axes,
        buttons=buttons,
        shapes=shapes,
        sources=(*base.sources, source) if base else (source,),
        directions={name: channel.directions for name, channel in profile.channels.items()},
        **settings,
    )
    _check_consistent(mapping, source)
    return mapping


def _check_consistent(mapping: PadMapping, source: str) -> None:
    held = {
        name: button for name in BUTTON_OPTIONS if (button := getattr(mapping, name)) is not None
    }
    for name, button in held.items():
        if button in mapping.buttons:
            raise PadMappingError(
                f"{source}: {button} is the {name} and also buttons.{button} "
                f"({mapping.buttons[button].describe()}); free one of them"
            )
    if len(set(held.values())) != len(held):
        raise PadMappingError(f"{source}: deadman, alt_button and turbo_button must differ")
    if mapping.alt_axes and mapping.alt_button is None:
        raise PadMappingError(f"{source}: [alt_axes] need options.alt_button")
    minimum_s = MIN_STALL_PERIODS / mapping.poll_hz
    if not minimum_s <= mapping.stall_timeout_s <= 5.0:
        raise PadMappingError(
            f"{source}: options.stall_timeout_ms must be between {1000 * minimum_s:.0f} "
            f"({MIN_STALL_PERIODS} poll periods) and 5000, got {1000 * mapping.stall_timeout_s:g}"
        )


def load_pad_mapping(profile: RobotProfile, override: Path | None = None) -> PadMapping:
    """The robot's shipped mapping, with the user's file merged over it when it exists."""
    default = default_pad_map_path(profile)
    mapping = parse_pad_mapping(_read_toml(default), profile, source=str(default))
    if override is not None and override.exists():
        mapping = parse_pad_mapping(_read_toml(override), profile, mapping, source=str(override))
    return mapping

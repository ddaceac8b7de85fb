"""What a game controller has and what one poll of it reads (SDL's names, no SDL here)."""

from __future__ import annotations

from dataclasses import dataclass, field

# SDL's game controller axes and buttons, in the order of SDL's enums (SDL_GameControllerAxis,
# SDL_GameControllerButton) and by SDL's own names (SDL_GameControllerGetStringForAxis):
# the same position on every pad in SDL's controller database (Xbox, PlayStation, F310...).
AXES: tuple[str, ...] = ("leftx", "lefty", "rightx", "righty", "lefttrigger", "righttrigger")
BUTTONS: tuple[str, ...] = (
    "a",
    "b",
    "x",
    "y",
    "back",
    "guide",
    "start",
    "leftstick",
    "rightstick",
    "leftshoulder",
    "rightshoulder",
    "dpup",
    "dpdown",
    "dpleft",
    "dpright",
    "misc1",
    "paddle1",
    "paddle2",
    "paddle3",
    "paddle4",
    "touchpad",
)
# Triggers rest at one end of their range; sticks rest in the middle.
TRIGGERS = frozenset({"lefttrigger", "righttrigger"})
RAW_MIN = -32768
RAW_MAX = 32767

# What the buttons are called on each family of pads (SDL names them by position).
_PLAYSTATION = {
    "a": "Cross",
    "b": "Circle",
    "x": "Square",
    "y": "Triangle",
    "back": "Share",
    "guide": "PS",
    "start": "Options",
    "leftstick": "L3",
    "rightstick": "R3",
    "leftshoulder": "L1",
    "rightshoulder": "R1",
    "lefttrigger": "L2",
    "righttrigger": "R2",
}
_XBOX = {
    "a": "A",
    "b": "B",
    "x": "X",
    "y": "Y",
    "back": "Back",
    "guide": "Guide",
    "start": "Start",
    "leftstick": "LS",
    "rightstick": "RS",
    "leftshoulder": "LB",
    "rightshoulder": "RB",
    "lefttrigger": "LT",
    "righttrigger": "RT",
}
_COMMON = {
    "dpup": "D-pad up",
    "dpdown": "D-pad down",
    "dpleft": "D-pad left",
    "dpright": "D-pad right",
    "leftx": "left stick X",
    "lefty": "left stick Y",
    "rightx": "right stick X",
    "righty": "right stick Y",
}


def control_label(family: str, name: str) -> str:
    """What the pad calls a control ('a' is 'Cross' on a PlayStation pad, 'A' on an Xbox)."""
    labels = _PLAYSTATION if family == "playstation" else _XBOX
    return labels.get(name) or _COMMON.get(name) or name


@dataclass(frozen=True)
class PadInfo:
    """One pad SDL opened: its name, GUID (what calibrations are keyed by) and family."""

    name: str
    guid: str
    family: str = "xbox"
    instance_id: int = 0


@dataclass(frozen=True)
class PadState:
    """One poll of a pad: raw axes (AXES order), buttons (BUTTONS order).

    `pressed` holds the buttons that went down since the previous state was taken, even if
    they are up again: a tap shorter than the GUI's delay still counts (the e-stop).
    """

    instance_id: int
    axes: tuple[int, ...]
    buttons: tuple[bool, ...]
    polled_at: float
    pressed: frozenset[str] = field(default_factory=frozenset)

    def axis(self, name: str) -> int:
        """The raw value of one axis."""
        return self.axes[AXES.index(name)]

    @property
    def down(self) -> frozenset[str]:
        """Names of the buttons held."""
        return frozenset(name for name, down in zip(BUTTONS, self.buttons, strict=True) if down)


@dataclass(frozen=True)
class PadConnected:
    """A pad was opened (plugged in, or found at start)."""

    info: PadInfo


@dataclass(frozen=True)
class PadDisconnected:
    """The pad in use went away."""

    info: PadInfo
    reason: str


@dataclass(frozen=True)
class PadError:
    """An SDL call failed; the pad in use (if any) was closed."""

    message: str


@dataclass(frozen=True)
class PadUnavailable:
    """SDL could not start: no pad can be read in this console."""

    message: str


@dataclass(frozen=True)
class PadUnsupported:
    """A joystick SDL has no game controller mapping for (it is not used)."""

    name: str


PadEvent = PadConnected | PadDisconnected | PadError | PadUnavailable | PadUnsupported

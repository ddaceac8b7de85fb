"""A channel's command and what set it (`Source`), and the events the console model emits.

Shared by the model (ocu.console.model) and its parts (driving.py, clicktrack.py, inputs.py);
`ocu.console.model` imports them back, so `from ocu.console.model import Source` still works.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import ClassVar

from ocu.console.events import Event
from ocu.console.tracking import TrackView
from ocu.nav.navigator import ZoneState
from ocu.records import CameraRequest, CommandError


class Source:
    """What set a channel's velocity: one per row of the input mux's table (ocu/control/mux.md).

    The built-in ones are attributes; a new source is `Source.define("name")` beside its row.
    Each name has one instance, so sources compare with `is`.
    """

    __slots__ = ("value",)
    _known: ClassVar[dict[str, Source]] = {}

    NONE: ClassVar[Source]
    SLIDER: ClassVar[Source]
    TEXT: ClassVar[Source]
    HOTKEY: ClassVar[Source]
    SWITCH: ClassVar[Source]
    POSITION: ClassVar[Source]
    # A planner through the ROS bridge: any manual input on the channel overrides it.
    ROS: ClassVar[Source]
    # The arm in Cartesian space (ocu.console.arm): jogs, pose goals, stored poses.
    ARM: ClassVar[Source]
    # The operator's game controller (ocu.gamepad): a stick or a button held, deadman held.
    GAMEPAD: ClassVar[Source]
    # An assisted mode (linear shuttle, path following): any operator input ends it.
    ASSIST: ClassVar[Source]
    # Click-to-track (ocu.console.tracking): the pan and tilt joints keep an object centred;
    # any operator input ends it.
    TRACK: ClassVar[Source]
    # A remote client of the live server (ocu.live, `--live-control`): a planner that stops
    # for every lock and any operator input.
    LIVE: ClassVar[Source]

    value: str

    def __new__(cls, value: str) -> Source:
        try:
            return cls._known[value]
        except KeyError:
            raise ValueError(f"{value!r} is not a source ({', '.join(cls._known)})") from None

    @classmethod
    def define(cls, value: str) -> Source:
        """The source of this name, made on the first call."""
        known = cls._known.get(value)
        if known is None:
            known = object.__new__(cls)
            object.__setattr__(known, "value", value)
            cls._known[value] = known
        return known

    @classmethod
    def all(cls) -> tuple[Source, ...]:
        """Every source defined so far."""
        return tuple(cls._known.values())

    def __setattr__(self, name: str, value: object) -> None:
        raise AttributeError("a Source cannot be changed")

    def __repr__(self) -> str:
        return f"Source({self.value!r})"

    def __reduce__(self) -> tuple[Callable[[str], Source], tuple[str]]:
        return (Source.define, (self.value,))


_BUILT_IN = ("none", "slider", "text", "hotkey", "switch", "position", "ros", "arm", "gamepad")
for _name in (*_BUILT_IN, "assist", "track", "live"):
    setattr(Source, _name.upper(), Source.define(_name))


MANUAL_SOURCES = (Source.SLIDER, Source.TEXT, Source.HOTKEY, Source.SWITCH, Source.GAMEPAD)
# What the pad asks of one channel: a stick's fraction of the maximum, a button's direction.
PadWish = tuple[float, int]
PAD_AT_REST: PadWish = (0.0, 0)


@dataclass(frozen=True)
class ChannelCommand:
    """One channel's commanded velocity (m/s or rad/s) and its source."""

    velocity: float = 0.0
    source: Source = Source.NONE


class ConsoleEvents:
    """Everything a view may subscribe to (the robot's own are on `model.robot.events`)."""

    def __init__(self) -> None:
        self.channel_changed: Event[[str, ChannelCommand]] = Event()
        self.command_changed: Event[[]] = Event()
        self.max_changed: Event[[str, float]] = Event()
        self.hotkey_speed_changed: Event[[str, float]] = Event()
        self.estop_requested: Event[[str]] = Event()
        self.estop_changed: Event[[bool, str]] = Event()
        self.torch_changed: Event[[bool]] = Event()
        self.fine_changed: Event[[bool]] = Event()
        self.held_changed: Event[[frozenset[str]]] = Event()
        self.targets_changed: Event[[dict[str, float]]] = Event()
        self.connection_changed: Event[[bool]] = Event()
        self.help_changed: Event[[bool]] = Event()
        self.camera_changed: Event[[int | None]] = Event()
        self.bitrate_changed: Event[[float]] = Event()
        self.stream_request_changed: Event[[tuple[CameraRequest, ...]]] = Event()
        self.message: Event[[str]] = Event()
        self.position_message: Event[[str]] = Event()
        # Before any operator input or emergency stop takes effect (a host hands control back
        # from another commander, e.g. ROS, before the operator's command is sent).
        self.operator_acted: Event[[]] = Event()
        # Driving with a map: what the safety zones say, the assisted mode running (None)
        # with a message, the operator's waypoints and shuttle points, an odometry reset.
        self.zones_changed: Event[[ZoneState]] = Event()
        self.assist_changed: Event[[str | None, str]] = Event()
        self.waypoints_changed: Event[[tuple[tuple[float, float], ...]]] = Event()
        self.shuttle_points_changed: Event[[tuple[tuple[float, float], ...]]] = Event()
        self.odometry_reset: Event[[]] = Event()
        # Click-to-track: what to draw (None: not tracking) after every frame, start and stop.
        self.tracking_changed: Event[[TrackView | None]] = Event()


def check_finite(channel: str, value: float) -> float:
    """A velocity as a float; CommandError if it is not a finite number."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise CommandError(f"{channel}: velocity must be a finite number, got {value!r}")
    return float(value)

"""The one Link interface: commands in, events out (python-can's BusABC for our robot).

Implementations: `UdpLink` and `VirtualLink` (ocu.link.live: the live link over a UDP socket
or an in-process virtual wire) and `ReplayLink` (ocu.record.replay_link: a recording played
back, read-only). Everything above — the console, the ROS bridge, the recorder, the
benchmarks — holds a `Link` and never asks which one. A backend for another robot (a UR arm
streaming speedj, a bus-servo arm on a serial line) is one more implementation.
"""

from __future__ import annotations

import logging
import threading
from abc import ABC, abstractmethod
from collections.abc import Sequence

from ocu.profile import RobotProfile
from ocu.records import (
    CameraRequest,
    Command,
    LinkEvent,
    LinkState,
    LinkStats,
    Listener,
    StreamRequest,
    VideoStats,
)

log = logging.getLogger("ocu.link")


class LinkError(OSError):
    """The link cannot be set up (unresolvable host, address in use, unreadable file)."""


class Listeners:
    """A link's subscribers: every event to each, in order; one failing spares the others."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._listeners: tuple[Listener, ...] = ()

    def subscribe(self, listener: Listener) -> None:
        """Call `listener` with every event from now on (on the link's threads)."""
        with self._lock:
            self._listeners = (*self._listeners, listener)

    def unsubscribe(self, listener: Listener) -> None:
        """Stop calling `listener`; no error if it was not subscribed."""
        with self._lock:
            self._listeners = tuple(item for item in self._listeners if item != listener)

    def emit(self, event: LinkEvent) -> None:
        """Hand one event to every subscriber."""
        for listener in self._listeners:
            # A faulty listener must not take the link (and with it the robot's safety) down.
            try:
                listener(event)
            except Exception:
                log.exception("link listener %r failed on %s", listener, type(event).__name__)


class Link(ABC):
    """Commands in, events out. Thread-safe; events arrive on the link's own threads."""

    #: A link that commands nothing (a replay): set_command and emergency_stop do nothing.
    read_only = False

    def __init__(self, profile: RobotProfile, description: str) -> None:
        self.profile = profile
        self.description = description
        self._listeners = Listeners()

    # ---- events out ------------------------------------------------------------------------

    def subscribe(self, listener: Listener) -> None:
        """Call `listener(event)` for every LinkEvent (ocu.records) from now on."""
        self._listeners.subscribe(listener)

    def unsubscribe(self, listener: Listener) -> None:
        """Stop calling `listener`."""
        self._listeners.unsubscribe(listener)

    def emit(self, event: LinkEvent) -> None:
        """Hand an event to the subscribers (the implementation's threads)."""
        self._listeners.emit(event)

    # ---- commands in -----------------------------------------------------------------------

    @property
    @abstractmethod
    def command(self) -> Command:
        """The command the link sends now."""

    @abstractmethod
    def set_command(self, command: Command) -> None:
        """Send this command from now on (at once when it changed)."""

    def set_velocities(self, **velocities: float) -> None:
        """Change some channels of the link's own command (for a single commander)."""
        self.set_command(self.command.with_velocities(velocities))

    @abstractmethod
    def emergency_stop(self, reason: str = "operator") -> None:
        """Zero all motion at once, with repeats against loss."""

    @abstractmethod
    def heartbeat(self) -> None:
        """The commanding thread proves it is alive (it becomes the command's owner)."""

    @property
    @abstractmethod
    def stream_request(self) -> StreamRequest:
        """What the OCU asks of an extended robot's cameras."""

    @abstractmethod
    def set_stream_request(self, cameras: Sequence[CameraRequest]) -> None:
        """Ask an extended robot for these per-camera streams."""

    @property
    @abstractmethod
    def rate_hz(self) -> float:
        """The periodic command rate."""

    @abstractmethod
    def set_rate_hz(self, rate_hz: float) -> None:
        """Change the periodic command rate (within the profile's bounds)."""

    # ---- state -----------------------------------------------------------------------------

    @property
    @abstractmethod
    def state(self) -> LinkState:
        """Whether valid packets are arriving."""

    @property
    @abstractmethod
    def extension_active(self) -> bool:
        """Whether the robot speaks the protocol extension."""

    @abstractmethod
    def stats(self) -> LinkStats:
        """Counters and rates now."""

    @abstractmethod
    def video_stats(self) -> VideoStats:
        """Counters of the extension's fragment reassembly."""

    # ---- life ------------------------------------------------------------------------------

    @abstractmethod
    def start(self) -> None:
        """Start the link's threads."""

    @abstractmethod
    def shutdown(self, timeout_s: float = 2.0) -> None:
        """Stop, sending zeros last where there is a robot; idempotent."""

    def __enter__(self) -> Link:
        return self

    def __exit__(self, *exc: object) -> None:
        self.shutdown()

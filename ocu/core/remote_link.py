"""The link of a control core in another process, as the GUI's views hold it.

In the core's process, `forward_link_events` sends each event of the link to the GUI
(ocu.core.remote: ("link", event)), the raw datagrams too (the recorder keeps them) except
the video's fragments; the video's compressed frames go as video (dropped first when the GUI
does not keep up). In the GUI, `RemoteLink` is a `Link` (ocu.link.base) whose events are
those forwarded, and whose questions and commands are round trips to the core's link
("@link"): QtLink, the video panel, the robot check and the link graphs take it as they take
a link of their own. `start()` asks the core to connect its hardware, `shutdown()` to shut it
down (zeros last); the core, not the GUI, heartbeats and commands it.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

from ocu.core.remote import CoreConnection, CoreGoneError
from ocu.link.base import Link
from ocu.profile import RobotProfile
from ocu.records import (
    VIDEO,
    VIDEO_FRAGMENT,
    CameraRequest,
    Command,
    DatagramReceived,
    LinkEvent,
    LinkState,
    LinkStats,
    StreamRequest,
    VideoFrame,
    VideoStats,
)

# The video's raw datagrams stay in the core: the GUI gets each frame whole (VideoFrame).
RAW_VIDEO_KINDS = frozenset({VIDEO, VIDEO_FRAGMENT})
LINK_ROOT = ("@link",)
CORE_ROOT = ("@core",)


def forward_link_events(link: Link, send: Callable[..., bool]) -> Callable[[], None]:
    """Send `link`'s events with `send(("link", event), video=...)`; the unsubscriber."""

    def forward(event: LinkEvent) -> None:
        if isinstance(event, DatagramReceived) and event.kind in RAW_VIDEO_KINDS:
            return
        send(("link", event), video=isinstance(event, VideoFrame))

    link.subscribe(forward)
    return lambda: link.unsubscribe(forward)


class RemoteLink(Link):
    """The core's link as the GUI sees it (module docstring)."""

    def __init__(self, connection: CoreConnection, profile: RobotProfile, description: str) -> None:
        super().__init__(profile, description)
        self.connection = connection
        self._started = False
        self._open = True
        self._last: dict[str, Any] = {}
        # The core builds its hardware now (not started): the window sets the link's rate
        # and subscribes its listeners before it starts, as with a link of its own.
        connection.on_link = self.emit
        connection.request("call", CORE_ROOT, "prepare", (), {})

    def _get(self, name: str) -> Any:
        return self._ask("get", name)

    def _call(self, name: str, *args: Any) -> Any:
        return self._ask("call", name, args, {})

    def _ask(self, kind: str, name: str, *rest: Any) -> Any:
        # Once the core is gone: the last answer (the views show what was last known), and
        # commands go nowhere (the robot's own watchdog has stopped it).
        try:
            value = self.connection.request(kind, LINK_ROOT, name, *rest)[1]
        except CoreGoneError:
            if name.startswith("set_") or name == "emergency_stop":
                return None
            if name in self._last:
                return self._last[name]
            if name == "video_stats":
                return VideoStats()  # never asked before the core went: nothing counted
            raise
        self._last[name] = value
        return value

    @property
    def command(self) -> Command:
        """The command the core's link sends now."""
        return self._get("command")  # type: ignore[no-any-return]

    def set_command(self, command: Command) -> None:
        """Send this command from now on (the core's model usually owns it)."""
        self._call("set_command", command)

    def emergency_stop(self, reason: str = "operator") -> None:
        """Zero all motion at once, in the core."""
        self._call("emergency_stop", reason)

    def heartbeat(self) -> None:
        """Nothing: the core's control thread is the link's commander."""

    @property
    def stream_request(self) -> StreamRequest:
        """What the core's link asks of the cameras."""
        return self._get("stream_request")  # type: ignore[no-any-return]

    def set_stream_request(self, cameras: Sequence[CameraRequest]) -> None:
        """Ask for these streams."""
        self._call("set_stream_request", tuple(cameras))

    @property
    def rate_hz(self) -> float:
        """The core's link's command rate."""
        return float(self._get("rate_hz"))

    def set_rate_hz(self, rate_hz: float) -> None:
        """Change the command rate."""
        self._call("set_rate_hz", rate_hz)

    @property
    def state(self) -> LinkState:
        """Whether valid packets are arriving (CLOSED once the core is gone)."""
        try:
            return self._get("state")  # type: ignore[no-any-return]
        except CoreGoneError:
            return LinkState.CLOSED

    @property
    def extension_active(self) -> bool:
        """Whether the robot speaks the protocol extension."""
        return bool(self._get("extension_active"))

    def stats(self) -> LinkStats:
        """The core's link's counters."""
        return self._call("stats")  # type: ignore[no-any-return]

    def video_stats(self) -> VideoStats:
        """The core's link's reassembly counters."""
        return self._call("video_stats")  # type: ignore[no-any-return]

    def start(self) -> None:
        """The core builds its hardware and starts it; its events come here from now on."""
        if self._started or not self._open:
            return
        self._started = True
        self.connection.request("call", CORE_ROOT, "connect", (), {})

    def shutdown(self, timeout_s: float = 2.0) -> None:
        """The core shuts its hardware down (zeros last); idempotent."""
        del timeout_s
        if not self._open:
            return
        self._open = self._started = False
        if not self.connection.closed.is_set():
            # What the shutdown sends (the zeros, a UR's stopj) still comes here: a recorder
            # keeps it (events a call emitted are dispatched before it returns).
            self.connection.request("call", CORE_ROOT, "disconnect", (), {})
        if self.connection.on_link == self.emit:
            self.connection.on_link = None

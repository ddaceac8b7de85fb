"""Teleop from a live client (`--live-control`): a client's `/cmd_vel` is the input mux's
`live` source (ocu/control/mux.md), under the same locks as every source (docs/live.md).

- One client commands at a time: the first that publishes; another is refused until the
  first has been silent for its timeout, unadvertised `/cmd_vel` or left.
- Its timeout follows its own rate: 1.5 of its last interval between messages, at least
  MIN_TIMEOUT_S and at most the mux table's 0.6 s (the first message gets the 0.6 s), so a
  panel publishing once a second drives 0.6 s per message, not a second and more. The
  server's loop expires it; the model's own timeout (the table's 0.6 s, the control thread)
  stops the source even if the server's thread stalls.
- A client that leaves or unadvertises stops what it drove at once.
- The model is reached under the control core's lock, never through the window's guarded
  handle (each of whose calls is the GUI's sign of life).
"""

from __future__ import annotations

import json
import math
import threading
from collections.abc import Callable
from typing import Any, Final, Protocol

from mcap_ros2._dynamic import DecoderFunction, generate_dynamic

from ocu.console.channels import Source
from ocu.console.model import ConsoleModel
from ocu.live.options import LiveError
from ocu.record import schemas as s

CMD_VEL: Final = "/cmd_vel"
# Foxglove's Teleop panel names the ROS 2 type, Lichtblick's the ROS 1 name.
TWIST_SCHEMAS: Final = ("geometry_msgs/msg/Twist", "geometry_msgs/Twist")
ENCODINGS: Final = ("json", "cdr")
MIN_TIMEOUT_S: Final = 0.15
PERIOD_FACTOR: Final = 1.5
# An interval longer than this is a new start, not the client's rate.
MAX_PERIOD_S: Final = 5.0
NOT_FREE: Final = "the drive is not free: the operator holds it, or the e-stop is latched"


REVOKED = "the operator has not allowed a remote drive"


class TwistError(ValueError):
    """A /cmd_vel message that is not a Twist of finite numbers."""


class Core(Protocol):
    """The control core's side the server needs (ocu.core.manager.ControllerManager)."""

    model: ConsoleModel
    lock: threading.RLock


_decode_cdr: DecoderFunction = generate_dynamic(s.TWIST.name, s.TWIST.definition)[s.TWIST.name]


def _finite(value: object, what: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise TwistError(f"{what} must be a finite number, not {value!r:.40}")
    return float(value)


def decode_twist(encoding: str, payload: bytes) -> tuple[float, float]:
    """(linear.x, angular.z) of a Twist in json or cdr; TwistError if it is not one."""
    if encoding == "json":
        try:
            message = json.loads(payload)
            linear, angular = message["linear"], message["angular"]
            return _finite(linear["x"], "linear.x"), _finite(angular["z"], "angular.z")
        except (ValueError, KeyError, TypeError) as err:
            raise TwistError(f"not a JSON Twist: {err}") from err
    try:
        decoded: Any = _decode_cdr(payload)
        return _finite(decoded.linear.x, "linear.x"), _finite(decoded.angular.z, "angular.z")
    except TwistError:
        raise
    except Exception as err:  # the generated decoder raises what the bytes make it raise
        raise TwistError(f"not a CDR Twist: {type(err).__name__}: {err}") from err


class LiveControl:
    """The `live` source of one model: who commands, until when (module docstring)."""

    def __init__(self, core: Core, clock: Callable[[], float]) -> None:
        drive = core.model.profile.drive_channels
        if drive is None:
            raise LiveError("--live-control: this robot has no drive channels for /cmd_vel")
        self.core = core
        self.clock = clock
        self.drive = drive
        self.timeout_max_s = dict(core.model.mux.timed())[Source.LIVE.value]
        self._lock = threading.Lock()
        # The operator's permission: the console's LIVE indicator revokes and allows again
        # (ocu.widgets.live_status); --live-control itself allows.
        self._allowed = True
        self._owner: str | None = None
        self._deadline = 0.0
        self._last: dict[str, float] = {}
        with core.lock:
            core.model.mux.register(Source.LIVE.value, self._stopped)

    @property
    def owner(self) -> str | None:
        """The client commanding now (its address), or None."""
        with self._lock:
            return self._owner

    @property
    def allowed(self) -> bool:
        """Whether the operator lets a client drive."""
        with self._lock:
            return self._allowed

    def set_allowed(self, allowed: bool) -> None:
        """The operator allows a client to drive, or revokes it: the client driving stops at
        once, and nothing a client sends moves the robot until it is allowed again."""
        with self._lock:
            if allowed == self._allowed:
                return
            self._allowed = allowed
            owner, self._owner = self._owner, None
        word = "allowed" if allowed else "revoked"
        with self.core.lock:
            if not allowed:
                self.core.model.clear_source(Source.LIVE, "the operator revoked the remote drive")
            self.core.model.events.message.emit(
                f"remote drive {word} by the operator" + (f" ({owner} stopped)" if owner else "")
            )

    def twist(self, client: str, linear_m_s: float, angular_rad_s: float) -> str | None:
        """One /cmd_vel from a client; None if taken, else why it was not."""
        now = self.clock()
        with self._lock:
            if not self._allowed:
                return REVOKED
            owner = self._owner
            if owner is not None and owner != client and now < self._deadline:
                return f"{owner} commands /cmd_vel now"
            last = self._last.get(client)
            period = None if last is None or now - last > MAX_PERIOD_S else now - last
            self._last[client] = now
            timeout = self.timeout_max_s
            if period is not None:
                timeout = min(max(PERIOD_FACTOR * period, MIN_TIMEOUT_S), self.timeout_max_s)
        linear, turn = self.drive
        model = self.core.model
        with self.core.lock:
            if model.estopped:  # latched until the operator acts: nothing moves meanwhile
                return NOT_FREE
            applied = model.set_source_velocities(
                Source.LIVE, {linear: linear_m_s, turn: angular_rad_s}
            )
            taken = bool(applied)
            if taken and owner != client:
                model.events.message.emit(f"live client {client} drives (/cmd_vel)")
        with self._lock:
            if taken:
                self._owner = client
                self._deadline = now + timeout
        return None if taken else NOT_FREE

    def expire(self) -> None:
        """Stop the commanding client's drive once its timeout has passed."""
        with self._lock:
            owner = self._owner
            late = owner is not None and self.clock() >= self._deadline
        if owner is not None and late:
            self.release(owner, "no /cmd_vel within its timeout")

    def release(self, client: str, reason: str) -> None:
        """The client stops commanding (it left, unadvertised, timed out)."""
        with self._lock:
            self._last.pop(client, None)
            if self._owner != client:
                return
            self._owner = None
        with self.core.lock:
            self.core.model.clear_source(Source.LIVE, f"{client}: {reason}")

    def _stopped(self, _reason: str) -> None:
        # A lock or the operator stopped the source (the model's lock held): it needs new
        # input, and the next client to publish may take it.
        with self._lock:
            self._owner = None
        self.core.model.clear_source(Source.LIVE)

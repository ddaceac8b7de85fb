"""Run a position controller against a Link without Qt (tests and benchmarks)."""

from __future__ import annotations

import queue
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace
from typing import Protocol

from ocu.link.base import Link
from ocu.records import JointReading, LinkEvent, TelemetryFrame

CONTROL_PERIOD_S = 0.02


class Controller(Protocol):
    """What the runner drives: PositionController, or a benchmark's baseline."""

    @property
    def targets(self) -> dict[str, float]: ...

    def channel_of(self, joint: str) -> str: ...

    def on_telemetry(
        self,
        readings: Mapping[str, JointReading],
        received_at: float,
        delay_s: float | None = None,
    ) -> None: ...

    def note_sent(self, now: float, velocities: Mapping[str, float]) -> None: ...

    def update(self, now: float) -> dict[str, float]: ...

    def pop_messages(self) -> list[str]: ...


@dataclass
class RunResult:
    """What happened during one run: messages and the measured angle trace."""

    messages: list[str] = field(default_factory=list)
    # (clock time, message) of each message, for judging it against ground truth.
    events: list[tuple[float, str]] = field(default_factory=list)
    trace: dict[str, list[tuple[float, float]]] = field(default_factory=dict)
    finished: bool = False
    elapsed_s: float = 0.0


class PositionRunner:
    """Feeds telemetry to a controller and its outputs to a link at a fixed control period.

    Telemetry arrives on the link's thread; it is queued and consumed on the runner's
    thread, so the controller itself needs no locking.
    """

    def __init__(self, controller: Controller, link: Link) -> None:
        self.controller = controller
        self.link = link
        self._telemetry: queue.Queue[tuple[Mapping[str, JointReading], float, float | None]] = (
            queue.Queue()
        )

    def on_link_event(self, event: LinkEvent) -> None:
        """A Link listener: telemetry frames go to the controller (any thread)."""
        if isinstance(event, TelemetryFrame):
            self.on_readings(event.readings, event.received_at, event.delay_s)

    def on_readings(
        self,
        readings: Mapping[str, JointReading],
        received_at: float,
        delay_s: float | None = None,
    ) -> None:
        """Thread-safe entry for telemetry (call from the link's listener)."""
        self._telemetry.put((readings, received_at, delay_s))

    def run(
        self,
        timeout_s: float,
        *,
        clock: Callable[[], float] = time.monotonic,
        settle_s: float = 0.0,
    ) -> RunResult:
        """Control until no target is left (plus settle_s of watching) or the timeout."""
        result = RunResult()
        start = clock()
        deadline = start + timeout_s
        idle_since: float | None = None
        channels = {self.controller.channel_of(j) for j in self.controller.targets}
        while clock() < deadline:
            next_step = clock() + CONTROL_PERIOD_S
            # Waiting on the queue both paces the loop and reacts to telemetry at once.
            while (remaining := next_step - clock()) > 0:
                try:
                    readings, received_at, delay_s = self._telemetry.get(timeout=remaining)
                except queue.Empty:
                    break
                self.controller.on_telemetry(readings, received_at, delay_s)
                for name, reading in readings.items():
                    if reading.angle_rad is not None:
                        result.trace.setdefault(name, []).append((received_at, reading.angle_rad))
            now = clock()
            velocities = self.controller.update(now)
            for channel in channels:
                velocities.setdefault(channel, 0.0)
            self.link.heartbeat()
            # A controller that says when its motions end (PositionController.until) has the
            # link end them then, as the console's control core does (Command.until).
            ends: dict[str, float] | None = getattr(self.controller, "until", None)
            if ends is None:
                self.link.set_velocities(**velocities)
                self.controller.note_sent(now, velocities)
            else:
                ends = {c: at for c, at in ends.items() if velocities.get(c, 0.0) != 0.0}
                command = self.link.command.with_velocities(velocities)
                self.link.set_command(replace(command, until={**command.until, **ends}))
                note_sent: Callable[..., None] = self.controller.note_sent
                note_sent(now, velocities, ends)
            for message in self.controller.pop_messages():
                result.messages.append(message)
                result.events.append((now, message))
            if not self.controller.targets:
                idle_since = now if idle_since is None else idle_since
                if now - idle_since >= settle_s:
                    result.finished = True
                    break
        result.elapsed_s = clock() - start
        self.link.set_velocities(**dict.fromkeys(channels, 0.0))
        self.controller.note_sent(clock(), {})
        return result

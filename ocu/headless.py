"""The console model bound to a link without Qt: benchmarks, tests and scripts.

`HeadlessConsole` does what the window and its ConsoleBinding do, on one thread of its own
("ocu-headless"): link events go into the model (telemetry, status, scans, statistics, the
commands the link sent, the link's state), the model's control step runs every
`control_period_s` (position control, assisted modes, the safety zones), the model's command
goes to the link whenever it changes, the e-stop reaches the link at once, LINK LOST and the
link's own safety stops halt the model. The model is touched only from that thread: operator
input goes through `call()`, which runs a function there and returns its result.
"""

from __future__ import annotations

import logging
import queue
import threading
import time
from collections.abc import Callable
from typing import TypeVar

from ocu.console.model import ConsoleModel
from ocu.link.base import Link
from ocu.records import (
    CommandSent,
    ExtensionChanged,
    LinkEvent,
    LinkState,
    LinkStateChanged,
    LinkStats,
    SafetyEvent,
    ScanFrame,
    StatusFrame,
    TelemetryFrame,
)

log = logging.getLogger("ocu.console")
T = TypeVar("T")
CONTROL_PERIOD_S = 0.05
JOIN_TIMEOUT_S = 2.0


class HeadlessConsole:
    """A ConsoleModel driving a Link from a thread of its own (see the module docstring)."""

    def __init__(
        self, model: ConsoleModel, link: Link, *, control_period_s: float = CONTROL_PERIOD_S
    ) -> None:
        self.model = model
        self.link = link
        self.control_period_s = control_period_s
        self._queue: queue.Queue[Callable[[], object]] = queue.Queue()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="ocu-headless", daemon=True)
        self._error: BaseException | None = None
        model.events.command_changed.connect(self._push, direct=True)
        model.events.estop_requested.connect(link.emergency_stop, direct=True)

    def start(self) -> None:
        """Subscribe to the link, start the thread and the link."""
        self.link.subscribe(self._on_event)
        self.link.set_command(self.model.command())
        self._thread.start()
        self.link.start()

    def stop(self) -> None:
        """Halt the model, stop the thread, shut the link down (zeros last); idempotent."""
        if self._thread.is_alive():
            self.call(lambda: self.model.halt("headless console stopped"))
            self._stop.set()
            self._thread.join(JOIN_TIMEOUT_S)
        self.link.unsubscribe(self._on_event)
        self.link.shutdown()

    def call(self, function: Callable[[], T], timeout_s: float = 5.0) -> T:
        """Run `function` on the console's thread (where the model lives); its result."""
        done = threading.Event()
        result: list[T] = []
        errors: list[BaseException] = []

        def run() -> None:
            try:
                result.append(function())
            except BaseException as err:  # handed to the caller
                errors.append(err)
            finally:
                done.set()

        self._queue.put(run)
        if not done.wait(timeout_s):
            raise TimeoutError("the headless console did not run the call in time")
        if errors:
            raise errors[0]
        return result[0]

    # ---- the link's threads ------------------------------------------------------------

    def _on_event(self, event: LinkEvent) -> None:
        model = self.model
        if isinstance(event, TelemetryFrame):
            self._queue.put(lambda: model.on_telemetry(event))
        elif isinstance(event, StatusFrame):
            self._queue.put(lambda: model.on_status(event))
        elif isinstance(event, ScanFrame):
            self._queue.put(lambda: model.on_scan(event))
        elif isinstance(event, CommandSent):
            self._queue.put(lambda: model.on_command_sent(event.command, event.sent_at))
        elif isinstance(event, LinkStats):
            self._queue.put(lambda: model.on_stats(event))
        elif isinstance(event, ExtensionChanged):
            self._queue.put(lambda: model.robot.on_extension(event.active, event.reason))
        elif isinstance(event, LinkStateChanged):
            self._queue.put(lambda: self._link_state(event.state, event.reason))
        elif isinstance(event, SafetyEvent):
            self._queue.put(lambda: model.halt(event.message))

    def _link_state(self, state: LinkState, reason: str) -> None:
        self.model.robot.on_link_state(state, reason)
        if state is LinkState.LOST:
            self.model.halt("link lost")

    # ---- the console's thread ----------------------------------------------------------

    def _push(self) -> None:
        self.link.set_command(self.model.command())

    def _run(self) -> None:
        next_tick = time.monotonic()
        while not self._stop.is_set():
            timeout = max(next_tick - time.monotonic(), 0.0)
            try:
                work = self._queue.get(timeout=timeout)
            except queue.Empty:
                work = None
            while work is not None:
                try:
                    work()
                except Exception:  # one bad event must not stop the robot's console
                    log.exception("headless console: event failed")
                try:
                    work = self._queue.get_nowait()
                except queue.Empty:
                    work = None
            now = time.monotonic()
            if now >= next_tick:
                next_tick = max(next_tick + self.control_period_s, now)
                self.link.heartbeat()
                self.model.update(now)

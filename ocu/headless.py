"""The console model bound to a link without Qt: benchmarks, tests and scripts.

`HeadlessConsole` runs the same control core as the window (ocu.core): a `ControllerManager`
("ocu-control" thread, every `control_period_s`: 50 ms unless told otherwise) feeds the
model from the link (`LinkFeed`: telemetry, status, scans, statistics, the commands the
link sent, the link's state; LINK LOST and the link's own safety stops halt the model),
runs its control step (position control, assisted modes, the safety zones) and tells the
link it is alive; the model's command goes to the link whenever it changes and the e-stop
reaches the link at once. Operator input goes through `call()`, which runs a function
under the model's lock and returns its result - the same lock the control thread holds for
each cycle.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from typing import TypeVar

from ocu.console.model import ConsoleModel
from ocu.core.feed import LinkFeed
from ocu.core.manager import ControllerManager
from ocu.link.base import Link

log = logging.getLogger("ocu.console")
T = TypeVar("T")
# 20 Hz, as before the control core (the benchmarks' figures were measured at it); the
# window's control thread runs at ocu.core.manager.DEFAULT_RATE_HZ.
CONTROL_PERIOD_S = 0.05


class HeadlessConsole:
    """A ConsoleModel driving a Link from the control core (see the module docstring)."""

    def __init__(
        self, model: ConsoleModel, link: Link, *, control_period_s: float = CONTROL_PERIOD_S
    ) -> None:
        self.model = model
        self.link = link
        self.control_period_s = control_period_s
        self.lock = threading.RLock()
        self._feed: LinkFeed | None = None
        self.manager = ControllerManager(
            model,
            self.lock,
            read=self._read,
            hardware=link,
            rate_hz=1.0 / control_period_s,
            alive_timeout_s=link.profile.link.gui_alive_timeout_s,
        )
        model.events.command_changed.connect(self._push, direct=True)
        model.events.estop_requested.connect(link.emergency_stop, direct=True)

    def start(self) -> None:
        """Subscribe to the link, start the control thread and the link."""
        self._feed = LinkFeed(self.link)
        self.link.set_command(self.model.command())
        self.manager.start()
        self.link.start()

    def stop(self) -> None:
        """Halt the model, stop the thread, shut the link down (zeros last); idempotent."""
        if self.manager.running:
            self.call(lambda: self.model.halt("headless console stopped"))
        self.manager.stop()
        feed, self._feed = self._feed, None
        if feed is not None:
            feed.close()
        self.link.shutdown()

    def call(self, function: Callable[[], T], timeout_s: float = 5.0) -> T:
        """Run `function` under the model's lock (on the calling thread); its result."""
        if not self.lock.acquire(timeout=timeout_s):
            raise TimeoutError("the headless console's model stayed locked")
        try:
            return function()
        finally:
            self.lock.release()

    def _read(self, model: ConsoleModel) -> None:
        feed = self._feed
        if feed is not None:
            feed.read(model)

    def _push(self) -> None:
        self.link.set_command(self.model.command())

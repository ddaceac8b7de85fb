"""The console model bound to a robot without Qt: benchmarks, tests and scripts.

`HeadlessConsole` runs the same control core as the window (ocu.core): a `ControllerManager`
("ocu-control" thread, every `control_period_s`: 50 ms unless told otherwise) reads the
hardware component (ocu.core.hardware: telemetry, status, scans, statistics, the commands
the link sent, the link's state; LINK LOST and the link's own safety stops halt the model),
runs its control step (position control, assisted modes, the safety zones), writes the
hardware and tells it it is alive; the model's command reaches the hardware whenever it
changes and the e-stop at once. Operator input goes through `call()`, which runs a function
under the model's lock and returns its result - the same lock the control thread holds for
each cycle.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from typing import TypeVar

from ocu.console.model import ConsoleModel
from ocu.core.hardware import HardwareComponent
from ocu.core.manager import ControllerManager
from ocu.link.base import Link

log = logging.getLogger("ocu.console")
T = TypeVar("T")
# 20 Hz, as before the control core (the benchmarks' figures were measured at it); the
# window's control thread runs at ocu.core.manager.DEFAULT_RATE_HZ.
CONTROL_PERIOD_S = 0.05


class HeadlessConsole:
    """A ConsoleModel driving a hardware component from the control core (module docstring)."""

    def __init__(
        self,
        model: ConsoleModel,
        hardware: HardwareComponent,
        *,
        control_period_s: float = CONTROL_PERIOD_S,
    ) -> None:
        self.model = model
        self.hardware = hardware
        self.control_period_s = control_period_s
        self.lock = threading.RLock()
        self.manager = ControllerManager(
            model,
            self.lock,
            rate_hz=1.0 / control_period_s,
            alive_timeout_s=hardware.profile.link.gui_alive_timeout_s,
        )

    @property
    def link(self) -> Link:
        """The hardware's link."""
        return self.hardware.link

    def start(self) -> None:
        """Attach the hardware (its events subscribed), start the control thread and it."""
        self.manager.attach(self.hardware)
        self.manager.start()
        self.hardware.start()

    def stop(self) -> None:
        """Halt the model, stop the thread, shut the link down (zeros last); idempotent."""
        if self.manager.running:
            self.call(lambda: self.model.halt("headless console stopped"))
        self.manager.stop()
        self.manager.detach()
        self.hardware.shutdown()

    def call(self, function: Callable[[], T], timeout_s: float = 5.0) -> T:
        """Run `function` under the model's lock (on the calling thread); its result."""
        if not self.lock.acquire(timeout=timeout_s):
            raise TimeoutError("the headless console's model stayed locked")
        try:
            return function()
        finally:
            self.lock.release()

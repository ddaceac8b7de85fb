"""The window's control core: the console model on the control thread, and the GUI's side of it.

`ConsoleControl` puts a `ConsoleModel` under a `ControllerManager` (ocu.core.manager: the
"ocu-control" thread at `control_hz`, 50 Hz by default) and gives the window:

- `model`: the GUI's handle on it (ocu.core.guard: each call and read under the model's lock;
  each call also a sign of life of the GUI thread);
- the model's events handed to the GUI thread (ocu.console.events.hand_over), so views are
  only ever called there;
- `attach(hardware)` / `detach()`: the current hardware component (ocu.core.hardware) read
  into the model and written by the control thread, and told by it that the controls are
  alive; a changed command, an e-stop and a stream request reach it at once;
- the GUI thread's heartbeat (a timer): silent past the link's alive timeout less one period
  while motion is commanded, and the control thread halts the model - the operator's keys
  and sliders cannot be released through a frozen GUI;
- `label`: the control thread's rate, worst period and overruns in the status bar.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import TypeVar, cast

from PySide6.QtCore import QObject, QTimer

from ocu.console.events import hand_over
from ocu.console.model import ConsoleModel
from ocu.core.guard import Guarded
from ocu.core.hardware import HardwareComponent
from ocu.core.manager import DEFAULT_RATE_HZ, TIMING_WINDOW_S, ControllerManager, ControlTiming
from ocu.profile import RobotProfile
from ocu.qt.link import HEARTBEAT_PERIOD_MS
from ocu.widgets.elided_label import ElidedLabel

T = TypeVar("T")

# The control thread's timing in the status bar, refreshed this often.
TIMING_PERIOD_MS = 1000
LATE_STYLE = "color:#b35c00;"


class ConsoleControl(QObject):
    """The control thread running `model`, and the window's side of it (module docstring)."""

    def __init__(
        self,
        model: ConsoleModel,
        profile: RobotProfile,
        *,
        control_hz: float = DEFAULT_RATE_HZ,
        parent: QObject | None = None,
    ) -> None:
        super().__init__(parent)
        groups = [model.events, model.robot.events]
        if model.arm is not None:
            groups.append(model.arm.events)
        hand_over(*groups)
        self.lock = threading.RLock()
        self.hardware: HardwareComponent | None = None
        gui_limit_s = profile.link.gui_alive_timeout_s - HEARTBEAT_PERIOD_MS / 1000.0
        self.manager = ControllerManager(
            model,
            self.lock,
            rate_hz=control_hz,
            alive_timeout_s=profile.link.gui_alive_timeout_s,
            gui_timeout_s=max(gui_limit_s, HEARTBEAT_PERIOD_MS / 1000.0),
        )
        self.model: ConsoleModel = cast(
            ConsoleModel, Guarded(model, self.lock, self.manager.gui_alive)
        )
        self._alive_timer = QTimer(self)
        self._alive_timer.setInterval(HEARTBEAT_PERIOD_MS)
        self._alive_timer.timeout.connect(self.manager.gui_alive)
        self.label = ElidedLabel(floor_text="ctl")
        self.label.setObjectName("control_timing")
        self._overruns_shown = 0
        self._timing_timer = QTimer(self)
        self._timing_timer.setInterval(TIMING_PERIOD_MS)
        self._timing_timer.timeout.connect(self.show_timing)

    def adopt(self, part: T) -> T:
        """Another part of the model (the pad's teleop): the GUI reaches it under the model's
        lock, and its events (`part.events`) call the GUI's callbacks on the GUI thread."""
        hand_over(part.events)  # type: ignore[attr-defined]
        return cast(T, Guarded(part, self.lock, self.manager.gui_alive))

    def teleop_for(self, make: Callable[[], T]) -> T:
        """The pad's teleop (made here, adopted as a part of the model)."""
        return self.adopt(make())

    def start(self) -> None:
        """Start the control thread and the GUI's heartbeat."""
        self.manager.gui_alive()
        self._alive_timer.start()
        self._timing_timer.start()
        self.manager.start()
        self.show_timing()

    def shutdown(self) -> None:
        """Stop the control thread (the model halted first by the window); idempotent."""
        self._alive_timer.stop()
        self._timing_timer.stop()
        self.manager.stop()
        self.detach()

    # ---- the hardware --------------------------------------------------------------------------

    def end(self) -> None:
        """After the link's shutdown: nothing left (the thread stopped in `shutdown`)."""

    def attach(self, hardware: HardwareComponent) -> None:
        """Read and write this hardware from now on (made before any datagram flows)."""
        self.detach()
        self.hardware = hardware
        self.manager.attach(hardware)

    def detach(self) -> None:
        """Stop reading and writing the current hardware; what it still had queued is dropped."""
        hardware, self.hardware = self.hardware, None
        self.manager.detach()
        if hardware is not None:
            hardware.feed.close()

    # ---- timing --------------------------------------------------------------------------------

    def show_timing(self) -> None:
        """The control thread's rate, worst period and overruns in the status bar."""
        self._overruns_shown = show_timing(
            self.label,
            self.manager.timing(),
            self._overruns_shown,
            "The control thread (position control, arm moves, assisted modes, tracking, the\n"
            "zones and the command to the robot)",
        )


def show_timing(
    label: ElidedLabel, timing: ControlTiming, shown: int, what: str, suffix: str = ""
) -> int:
    """A control thread's rate and worst period on `label` (then `suffix`), its timing in the
    tool tip, orange while cycles came late since the last look; the overruns seen now."""
    label.setText(f"ctl {timing.measured_hz:.0f} Hz, {1000 * timing.worst_period_s:.0f} ms{suffix}")
    label.setToolTip(f"{what}: {timing.text} in the last {TIMING_WINDOW_S:.0f} s.")
    label.setStyleSheet(LATE_STYLE if timing.overruns > shown else "")
    return timing.overruns

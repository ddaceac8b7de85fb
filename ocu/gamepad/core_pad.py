"""The game controller in the control core's process (ocu.core_process, `ocu --core-process`).

What `ocu.qt.gamepad.QtGamepad` does on the window's side, without Qt, beside the model it
acts on: the `PadPoller` ("ocu-gamepad" thread) hands the pad's events and newest state to the
`GamepadTeleop` at once, under the model's lock; a watchdog thread stops the pad's motion when
the poll thread falls silent past the mapping's `stall_timeout_ms`. The teleop is the core's
"teleop" root: the window's Gamepad dock and pad indicator reach it through the core's pipe.
The pad's "pose NAME" button moves the arm to a stored pose here too (stopped when the pad
lets go); what goes wrong is said in the Events dock (the model's `message`).
"""

from __future__ import annotations

import logging
import threading
import time
from collections import deque
from typing import Any

from ocu.console.poses import PoseError
from ocu.gamepad.calibration import CalibrationStore, saved_or_default
from ocu.gamepad.mapping import load_pad_mapping
from ocu.gamepad.pad import (
    PadConnected,
    PadDisconnected,
    PadError,
    PadEvent,
    PadUnavailable,
    PadUnsupported,
)
from ocu.gamepad.poller import PadPoller
from ocu.gamepad.teleop import GamepadTeleop, PadStatus, Stopper
from ocu.kinematics.arm import ArmError

log = logging.getLogger("ocu.gamepad")

WATCHDOG_CHECKS = 4  # looks per stall timeout, as QtGamepad's


class CorePad:
    """The poller and its watchdog feeding `teleop` under `lock` (module docstring)."""

    def __init__(self, teleop: GamepadTeleop, lock: threading.RLock) -> None:
        self.teleop = teleop
        self.lock = lock
        mapping = teleop.mapping
        self.stall_timeout_s = mapping.stall_timeout_s
        self.poller = PadPoller(mapping.poll_hz, self._take, self._on_event_thread)
        self._events: deque[PadEvent] = deque()
        self._stop = threading.Event()
        self._watchdog: threading.Thread | None = None
        self._started = False

    def start(self) -> None:
        """Start polling and watching."""
        if self._started:
            return
        self._started = True
        with self.lock:
            self.teleop.start()
        self.poller.start()
        self._watchdog = threading.Thread(target=self._watch, name="ocu-pad-watch", daemon=True)
        self._watchdog.start()

    def stop(self) -> None:
        """Stop polling; the pad's motion stops. Idempotent."""
        if not self._started:
            return
        self._started = False
        self._stop.set()
        self.poller.stop()
        if self._watchdog is not None:
            self._watchdog.join(2.0)
        with self.lock:
            if self.teleop.info is not None:
                self.teleop.on_disconnected("closed with the console")

    def _on_event_thread(self, event: PadEvent) -> None:
        self._events.append(event)
        self._take()

    def _take(self) -> None:
        # The poll thread: the pad's events in order, then its newest state.
        with self.lock:
            while self._events:
                self._on_event(self._events.popleft())
            state = self.poller.take()
            if state is not None and self._started:
                self.teleop.on_state(state)

    def _on_event(self, event: PadEvent) -> None:
        if self._started:
            deliver(self.teleop, event)

    def _watch(self) -> None:
        period = max(0.005, self.stall_timeout_s / WATCHDOG_CHECKS)
        while not self._stop.wait(period):
            with self.lock:
                self.check_stall()

    def check_stall(self) -> None:
        """A poll thread silent too long stops the pad's motion (the model's lock held)."""
        if self._started:
            watch_poller(self.teleop, self.poller, self.stall_timeout_s)


def deliver(teleop: GamepadTeleop, event: PadEvent) -> None:
    """One of the poller's events to the teleop (QtGamepad's and CorePad's)."""
    if isinstance(event, PadConnected):
        teleop.on_connected(event.info)
    elif isinstance(event, PadDisconnected):
        teleop.on_disconnected(event.reason)
    elif isinstance(event, PadError):
        teleop.on_error(event.message)
    elif isinstance(event, PadUnavailable):
        teleop.on_unavailable(event.message)
    elif isinstance(event, PadUnsupported):
        teleop.events.message.emit(
            f"joystick '{event.name}' is not a game controller SDL knows: it is not used "
            "(give SDL its mapping in SDL_GAMECONTROLLERCONFIG)"
        )


def watch_poller(teleop: GamepadTeleop, poller: PadPoller, stall_timeout_s: float) -> None:
    """The stall watchdog's look: a poll thread ended, or silent past `stall_timeout_s` while a
    pad is in use, stops the pad's motion; else it is polling (QtGamepad's and CorePad's)."""
    if not poller.running:
        if teleop.status is not PadStatus.UNAVAILABLE:
            teleop.on_stalled("the gamepad poll thread ended")
        return
    last = poller.last_poll_at
    if last is None or teleop.info is None:  # no pad in use: nothing to stop
        return
    silent_s = time.monotonic() - last
    if silent_s > stall_timeout_s:
        teleop.on_stalled(f"gamepad poll thread silent for {1000 * silent_s:.0f} ms")
    else:
        teleop.on_polling()


def pose_hook(model: Any, name: str) -> Stopper | None:
    """The pad's "pose NAME": the arm's stored pose, stopped when the pad lets go."""
    arm = model.arm
    if arm is None:
        model.events.message.emit(model.arm_error or "this robot has no arm profile")
        return None
    try:
        arm.go_to(name)
    except (ArmError, PoseError) as err:
        model.events.message.emit(f"arm: {err}")
        return None
    return lambda reason: model.stop_arm(f"stored pose {name} stopped ({reason})")


def core_pad(core: Any) -> CorePad:
    """The "pad" part of a control core (ocu.core_process.Core): the teleop on its model,
    reachable as the root "teleop", fed by a poller in this process."""
    spec = core.spec
    mapping = spec.pad_mapping or load_pad_mapping(spec.profile)
    store = CalibrationStore(spec.pad_calibrations) if spec.pad_calibrations else None
    teleop = GamepadTeleop(
        core.model, mapping, calibration_for=lambda info: saved_or_default(store, info)
    )
    teleop.register_hook("pose", lambda name: pose_hook(core.model, name))
    core.server.add_root("teleop", teleop)
    pad = CorePad(teleop, core.lock)
    pad.start()
    return pad

"""The window's control core in a process of its own (`ocu --core-process`, docs/core-process.md).

`RemoteControl` has the surface of `ConsoleControl` (ocu.windows.control) for a core that runs
in a child process (ocu.core_process): `model` is the `RemoteModel`, `link_factory()` makes
the `RemoteLink`s the window connects (the core builds and commands the hardware itself),
`attach`/`detach` have nothing to do (the core attaches its hardware when the link starts),
the GUI's heartbeat is a post to the core, and the status bar shows the core's control timing.
The X key reader runs in the core ("keys", ocu.windows.x_keys.core_keys) where the window is
on X11: `keys` is the key filter's handle on it.

The core ending on its own (killed, crashed) shows as LINK LOST, "the control core ended";
the robot stops by itself (its link's watchdog); nothing restarts it without the operator.
"""

from __future__ import annotations

import dataclasses
import logging
import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar, cast

from PySide6.QtCore import QObject, QTimer, Signal
from PySide6.QtGui import QGuiApplication

from ocu.console.events import hand_over
from ocu.console.model import ConsoleModel
from ocu.core.guard import Guarded
from ocu.core.hardware import HardwareComponent
from ocu.core.manager import DEFAULT_RATE_HZ
from ocu.core.remote import CoreGoneError, remote_root
from ocu.core.remote_link import RemoteLink
from ocu.core_process import CoreProcess, CoreSpec
from ocu.gamepad.mapping import PadMapping
from ocu.gamepad.teleop import GamepadTeleop
from ocu.hotkeys import KeyMap
from ocu.link.base import Link
from ocu.profile import RobotProfile
from ocu.qt.inbox import gui_inbox
from ocu.qt.link import HEARTBEAT_PERIOD_MS
from ocu.records import LinkState
from ocu.widgets.elided_label import ElidedLabel
from ocu.windows.control import LATE_STYLE, TIMING_PERIOD_MS, ConsoleControl, show_timing

T = TypeVar("T")

CORE_ENDED = "the control core ended"
KEYS_PART = "keys=ocu.windows.x_keys:core_keys"
PAD_PART = "pad=ocu.gamepad.core_pad:core_pad"


class RemoteControl(QObject):
    """The core process and the window's side of it (module docstring)."""

    core_ended = Signal(str)

    def __init__(self, spec: CoreSpec, parent: QObject | None = None) -> None:
        super().__init__(parent)
        inbox = gui_inbox()
        self.profile = spec.profile
        self.process = CoreProcess(
            spec,
            post=inbox.post,
            on_closed=lambda: inbox.post(self._on_core_gone),
        )
        self.connection = self.process.connection
        # What the views read and call once the core is gone: a model of this process's own,
        # connected to nothing, halted and LINK LOST.
        fallback = ConsoleModel(
            spec.profile, fine_factor=spec.fine_factor, arm_poses_path=spec.arm_poses_path
        )
        self.connection.fallbacks[""] = fallback
        if spec.pad_mapping is not None:
            self.connection.fallbacks["teleop"] = GamepadTeleop(fallback, spec.pad_mapping)
        self.model: ConsoleModel = cast(ConsoleModel, self.process.model)
        self.manager: Any = self.process.core  # timing(), as ControllerManager has
        self.keys: Any = (
            self.process.part("keys") if any(p.startswith("keys=") for p in spec.parts) else None
        )
        # The pad's teleop where the core reads the pad (its "pad" part), else None.
        self.teleop: Any = (
            remote_root(self.connection, "teleop") if PAD_PART in spec.parts else None
        )
        self.lock: threading.RLock | None = None  # the model's lock is in the core
        self.hardware: HardwareComponent | None = None  # and so is the hardware
        self._local_lock = threading.RLock()  # for the window's own parts (the pad's teleop)
        self._ended = False
        self._alive_timer = QTimer(self)
        self._alive_timer.setInterval(HEARTBEAT_PERIOD_MS)
        self._alive_timer.timeout.connect(self._beat)
        self.label = ElidedLabel(floor_text="ctl")
        self.label.setObjectName("control_timing")
        self._overruns_shown = 0
        self._timing_timer = QTimer(self)
        self._timing_timer.setInterval(TIMING_PERIOD_MS)
        self._timing_timer.timeout.connect(self.show_timing)

    def link_factory(self, description: str) -> Callable[[], Link]:
        """Links for the window to connect: the core's link, one per Connect."""
        return lambda: RemoteLink(self.connection, self.profile, description)

    @staticmethod
    def hardware_for(_link: Link) -> None:
        """Nothing in this process: the core builds the hardware when the link starts."""
        return None

    def adopt(self, part: T) -> T:
        """A part of the window's own (the pad's teleop) on the remote model: its events on
        the GUI thread, its calls under a lock of the window's."""
        hand_over(part.events)  # type: ignore[attr-defined]
        return cast(T, Guarded(part, self._local_lock))

    def teleop_for(self, make: Callable[[], T]) -> T:
        """The core's teleop where it reads the pad; else one of the window's own."""
        return cast(T, self.teleop) if self.teleop is not None else self.adopt(make())

    def start(self) -> None:
        """The heartbeat and the timing label (the core's control thread runs already)."""
        self._beat()
        self._alive_timer.start()
        self._timing_timer.start()
        self.show_timing()

    def shutdown(self) -> None:
        """The window is closing (the model halted first): no more heartbeats, and the core's
        end is no LINK LOST from now on; the core lives on until `end()`, so that the link's
        shutdown (zeros last, a UR's stopj) still reaches the window's recorder."""
        self._alive_timer.stop()
        self._timing_timer.stop()
        self._ended = True

    def end(self) -> None:
        """Close the core's pipe: it halts the model, shuts the hardware down (if the link
        did not already), ends; idempotent."""
        self._ended = True
        self.process.stop()

    def attach(self, _hardware: object) -> None:
        """Nothing: the core attached its hardware when the link started."""

    def detach(self) -> None:
        """Nothing: the core detaches its hardware when the link shuts down."""

    def _beat(self) -> None:
        if not self.connection.closed.is_set():
            self.connection.tell("post", ("@core",), "gui_alive", (), {})

    def _on_core_gone(self) -> None:
        """The core ended without being asked: LINK LOST, said once."""
        if self._ended:
            return
        self._ended = True
        self._alive_timer.stop()
        self._timing_timer.stop()
        fallback = self.connection.fallbacks[""]
        assert isinstance(fallback, ConsoleModel)
        fallback.robot.on_link_state(LinkState.LOST, CORE_ENDED)
        fallback.halt(CORE_ENDED)
        robot = ("", "robot", "events")
        self.connection.inject(robot, "link_state_changed", LinkState.LOST, CORE_ENDED)
        self.label.setText("ctl: core ended")
        self.label.setStyleSheet(LATE_STYLE)
        self.core_ended.emit(CORE_ENDED)

    def show_timing(self) -> None:
        """The core's control thread: rate, worst period and overruns in the status bar."""
        try:
            timing = self.manager.timing()
        except CoreGoneError:
            return
        if timing is None:
            return
        self._overruns_shown = show_timing(
            self.label,
            timing,
            self._overruns_shown,
            "The control core, in a process of its own (position control, arm moves, assisted\n"
            "modes, tracking, the zones, the keys and the command to the robot)",
            " (core)",
        )


def control_for(
    core: CoreSpec | None,
    profile: RobotProfile,
    key_map: KeyMap,
    arm_poses_path: Path | None,
    *,
    control_hz: float = DEFAULT_RATE_HZ,
    pad_mapping: PadMapping | None = None,
    pad_calibrations: Path | None = None,
    parent: QObject | None = None,
) -> ConsoleControl | RemoteControl:
    """The window's control: in this process (`core` None), or in a child process built from
    `core` (the X key reader in it where the window is on X11; the pad read there with
    `pad_mapping`)."""
    if core is None:
        model = ConsoleModel(
            profile, fine_factor=key_map.fine_factor, arm_poses_path=arm_poses_path
        )
        return ConsoleControl(model, profile, control_hz=control_hz, parent=parent)
    parts = list(core.parts)
    if QGuiApplication.platformName() == "xcb" and KEYS_PART not in parts:
        parts.append(KEYS_PART)
    if pad_mapping is not None and PAD_PART not in parts:
        parts.append(PAD_PART)
    gui_limit_s = profile.link.gui_alive_timeout_s - HEARTBEAT_PERIOD_MS / 1000.0
    spec = dataclasses.replace(
        core,
        profile=profile,
        fine_factor=key_map.fine_factor,
        arm_poses_path=arm_poses_path,
        control_hz=control_hz,
        gui_timeout_s=max(gui_limit_s, HEARTBEAT_PERIOD_MS / 1000.0),
        key_map=key_map,
        pad_mapping=pad_mapping,
        pad_calibrations=pad_calibrations,
        parts=tuple(parts),
        log_level=logging.getLogger().getEffectiveLevel(),
    )
    return RemoteControl(spec, parent=parent)

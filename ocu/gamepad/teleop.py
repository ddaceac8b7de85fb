"""The pad on the console model: deadman, arming, bindings, commands, hooks (no Qt, no SDL).

Everything arrives here on the GUI thread (the Qt glue forwards the poll thread's states and
events): `on_state` for each poll taken, `on_connected` / `on_disconnected` / `on_error` /
`on_unavailable` from the poller, `on_stalled` / `on_polling` from the glue's watchdog, and
`set_active` from the window's focus policy.

Rules (docs/gamepad.md):
- The pad moves the robot only while it is *engaged*: its deadman went down while the pad was
  connected, polled and allowed (the console visible, and focused unless the mapping allows
  the background), and is still held. A deadman already held when the pad appears, when
  polling resumes or when the console is allowed again does nothing until it is released
  and pressed again.
- When the pad engages, a stick, trigger or button not at rest is *disarmed*: it moves
  nothing until it has been back at rest. The same when the alt button changes what an
  axis drives. A pad plugged in mid-motion, or a stick held while the deadman goes down,
  starts nothing.
- Releasing the deadman, unplugging the pad, an SDL error, a stalled poll thread, the console
  hidden (or unfocused, if the mapping says so) and any emergency stop disengage the pad: its
  channels stop at once (`ConsoleModel.stop_gamepad`), and so does a stored pose it started.
- The emergency stop button works whatever the state: connected is enough.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from enum import Enum

from ocu.console.events import Event
from ocu.console.model import ConsoleModel
from ocu.gamepad.calibration import PadCalibration
from ocu.gamepad.mapping import AxisBinding, PadMapping
from ocu.gamepad.pad import AXES, PadInfo, PadState
from ocu.gamepad.shaping import settle

log = logging.getLogger("ocu.gamepad")

ESTOP_REASON = "gamepad"


class PadStatus(Enum):
    """What the pad can do now (shown in the status bar and the panel)."""

    OFF = "off"  # not started (a replay, or --no-gamepad)
    UNAVAILABLE = "unavailable"  # SDL could not start
    NO_PAD = "no pad"
    READY = "ready"  # connected; the deadman is not held
    ENGAGED = "engaged"  # the deadman is held: the pad drives
    INACTIVE = "inactive"  # the console is hidden (or unfocused, by the focus policy)
    STALLED = "stalled"  # the poll thread stopped reporting
    ERROR = "error"  # an SDL call failed


# A hook command's handler: called with the mapping's argument; it may return how to stop
# what it started (called when the pad lets go: deadman released, unplugged, stalled).
Stopper = Callable[[str], object]
Hook = Callable[[str], Stopper | None]


class TeleopEvents:
    """What the views subscribe to."""

    def __init__(self) -> None:
        self.status_changed: Event[[PadStatus, str]] = Event()
        self.pad_changed: Event[[PadInfo | None]] = Event()
        # Every state taken from the pad in use (the calibration learns from each).
        self.state_changed: Event[[PadState]] = Event()
        self.message: Event[[str]] = Event()


class GamepadTeleop:
    """Turns pad states into the model's gamepad input under the deadman and arming rules."""

    def __init__(
        self,
        model: ConsoleModel,
        mapping: PadMapping,
        calibration_for: Callable[[PadInfo], PadCalibration] | None = None,
    ) -> None:
        self.model = model
        self.mapping = mapping
        self.events = TeleopEvents()
        self._calibration_for = calibration_for or (lambda _info: PadCalibration())
        self.calibration = PadCalibration()
        self._info: PadInfo | None = None
        self._state: PadState | None = None
        self._status = PadStatus.OFF
        self._status_text = ""
        self._active = True
        self._stalled = False
        self._error = ""
        self._engaged = False
        # Per axis, the binding it may drive (it was at rest while bound so since engaging).
        self._armed: dict[str, AxisBinding] = {}
        # Buttons seen up since engaging: only these move a channel while held.
        self._buttons_armed: set[str] = set()
        self._settled: dict[str, float] = dict.fromkeys(AXES, 0.0)
        self._hooks: dict[str, Hook] = {}
        # How to stop what hooks started during this engagement (a stored pose's move).
        self._hook_stops: list[Stopper] = []
        # Direct: the pad lets go in the same step as the e-stop, on whatever thread it came.
        model.events.estop_changed.connect(self._on_estop, direct=True)

    # ---- what the views read ---------------------------------------------------------------

    @property
    def status(self) -> PadStatus:
        """What the pad can do now."""
        return self._status

    @property
    def status_text(self) -> str:
        """Why (the pad's name, the error, the reason it is inactive)."""
        return self._status_text

    @property
    def info(self) -> PadInfo | None:
        """The pad in use, if any."""
        return self._info

    @property
    def state(self) -> PadState | None:
        """The newest reading of the pad in use."""
        return self._state

    @property
    def engaged(self) -> bool:
        """Whether the deadman is held and the pad drives."""
        return self._engaged

    @property
    def alt(self) -> bool:
        """Whether the alt button is held (the right stick drives its other joints)."""
        button = self.mapping.alt_button
        return self._state is not None and button is not None and button in self._state.down

    def value(self, axis: str) -> float:
        """One axis now: calibrated and shaped (deadzone, expo), before arming."""
        if self._state is None:
            return 0.0
        calibrated = self.calibration.normalise(axis, self._state.axis(axis))
        return self.mapping.shape(axis).apply(calibrated)

    def armed(self, axis: str) -> bool:
        """Whether an axis may move its channel now."""
        binding = self.mapping.binding(axis, self.alt)
        return binding is not None and self._armed.get(axis) == binding

    # ---- wiring ----------------------------------------------------------------------------

    def register_hook(self, name: str, hook: Hook) -> None:
        """Give a hook command ('pose') its handler: called with the mapping's argument."""
        self._hooks[name] = hook

    def set_calibration(self, calibration: PadCalibration) -> None:
        """Use a new calibration for the pad in use (the panel saved one)."""
        self.calibration = calibration
        self._settled = dict.fromkeys(AXES, 0.0)
        if self._engaged:
            self._disengage("calibration changed")

    # ---- the poller's events ---------------------------------------------------------------

    def on_unavailable(self, message: str) -> None:
        """SDL could not start."""
        self._drop_pad(f"gamepad unavailable: {message}")
        self._set_status(PadStatus.UNAVAILABLE, message)

    def on_connected(self, info: PadInfo) -> None:
        """A pad was opened: it starts nothing until its deadman is pressed."""
        if self._info is not None:
            self._drop_pad("another pad took its place")
        self._info = info
        self._state = None
        self._error = ""
        self.calibration = self._calibration_for(info)
        self._settled = dict.fromkeys(AXES, 0.0)
        self.events.pad_changed.emit(info)
        self.events.message.emit(f"gamepad connected: {info.name}")
        self._refresh_status()
        self._engage_without_deadman()

    def on_disconnected(self, reason: str) -> None:
        """The pad went away: its motion stops now."""
        name = self._info.name if self._info else "gamepad"
        self._drop_pad(f"{name} {reason}")
        self.events.message.emit(f"gamepad {reason}: {name}")
        self._refresh_status()

    def on_error(self, message: str) -> None:
        """An SDL call failed: the pad's motion stops now; the poller tries again."""
        self._error = message
        self._drop_pad(f"SDL error: {message}")
        self._refresh_status()

    def on_stalled(self, reason: str) -> None:
        """The poll thread stopped reporting: stop the pad's motion now."""
        if self._stalled:
            return
        self._stalled = True
        if not self._disengage(reason):  # the model tells when something stopped
            self.events.message.emit(reason)
        self._refresh_status()

    def on_polling(self) -> None:
        """The poll thread reports again; the deadman must be pressed anew."""
        if not self._stalled:
            return
        self._stalled = False
        self.events.message.emit("gamepad polling again: press the deadman to drive")
        self._refresh_status()
        self._engage_without_deadman()

    def set_active(self, active: bool, reason: str = "") -> None:
        """The window's focus policy: an inactive pad moves nothing (its e-stop still works)."""
        if active == self._active:
            return
        self._active = active
        if not active:
            self._disengage(reason or "console inactive")
        self._refresh_status()
        self._engage_without_deadman()

    # ---- a poll ----------------------------------------------------------------------------

    def on_state(self, state: PadState) -> None:
        """One poll of the pad in use: e-stop, deadman, commands, then the channels."""
        if self._info is None or state.instance_id != self._info.instance_id:
            return
        previous = self._state
        self._state = state
        self.events.state_changed.emit(state)
        down = state.down
        # The poller counts only presses it saw happen: a button held when the pad appeared
        # is not among them.
        pressed = state.pressed
        if previous is not None:
            pressed = pressed | (down - previous.down)
        if any(self._command(b) == "emergency_stop" for b in pressed):
            self.model.emergency_stop(ESTOP_REASON)
            self._disengage("emergency stop")
            return
        deadman = self.mapping.deadman
        if deadman is not None:
            if deadman in pressed and self._may_engage and not self._engaged:
                self._engage()
            if deadman not in down and self._engaged:
                self._disengage("deadman released")
        for button in sorted(pressed):
            self._on_press(button)
        self._apply()

    # ---- internals -------------------------------------------------------------------------

    @property
    def _may_engage(self) -> bool:
        return self._info is not None and self._active and not self._stalled and not self._error

    def _command(self, button: str) -> str | None:
        action = self.mapping.buttons.get(button)
        return action.command if action is not None else None

    def _on_press(self, button: str) -> None:
        action = self.mapping.buttons.get(button)
        if action is None or action.command is None or not self._may_engage:
            return
        command, argument = action.command, action.argument
        if command == "torch":
            self.model.set_torch(not self.model.torch)
        elif command in ("camera_next", "camera_previous"):
            count = len(self.model.profile.link.camera_names)
            step = 1 if command == "camera_next" else -1
            current = self.model.camera
            if current is None:  # none selected yet: the first, or the last going back
                current = -1 if step > 0 else 0
            self.model.select_camera((current + step) % count)
        elif command == "help":
            self.model.set_help_visible(not self.model.help_visible)
        elif command != "emergency_stop":
            self._call_hook(command, argument)

    def _call_hook(self, name: str, argument: str) -> None:
        hook = self._hooks.get(name)
        if hook is None:
            self.events.message.emit(
                f"gamepad: '{name} {argument}' does nothing: this console has no {name} hook"
            )
            return
        if not self._engaged:
            self.events.message.emit(f"gamepad: hold the deadman for '{name} {argument}'")
            return
        stop = hook(argument)
        if stop is not None:
            self._hook_stops.append(stop)

    def _engage_without_deadman(self) -> None:
        """With no deadman configured, the pad engages as soon as it may (still armed)."""
        if self.mapping.deadman is None and self._may_engage and not self._engaged:
            self._engage()
            self._apply()

    def _engage(self) -> None:
        self._engaged = True
        self._armed.clear()
        self._buttons_armed.clear()
        state = self._state
        if state is not None:  # otherwise each arms when its first reading is at rest
            alt = self.alt
            for axis in AXES:
                binding = self.mapping.binding(axis, alt)
                if binding is not None and self.value(axis) == 0.0:
                    self._armed[axis] = binding
            self._buttons_armed = {b for b in self.mapping.buttons if b not in state.down}
        self._refresh_status()

    def _disengage(self, reason: str) -> bool:
        """The pad lets go; True if it was moving something."""
        was_engaged = self._engaged
        self._engaged = False
        self._armed.clear()
        self._buttons_armed.clear()
        stopped = self.model.stop_gamepad(reason)
        hook_stops, self._hook_stops = self._hook_stops, []
        for stop in hook_stops:
            stopped = bool(stop(reason)) or stopped
        if was_engaged:
            self._refresh_status()
        return stopped

    def _drop_pad(self, reason: str) -> None:
        self._disengage(reason)
        self._info = None
        self._state = None
        self.events.pad_changed.emit(None)

    def _on_estop(self, active: bool, _reason: str) -> None:
        if active and self._engaged:
            self._disengage("emergency stop")

    def _apply(self) -> None:
        """The channels: armed axes and held buttons while engaged, all at rest otherwise."""
        fractions: dict[str, float] = dict.fromkeys(self.mapping.channels(), 0.0)
        held: dict[str, int] = {}
        if self._engaged and self._state is not None:
            alt = self.alt
            turbo = self.mapping.turbo_button
            scale = 1.0 if turbo is not None and turbo in self._state.down else self.mapping.scale
            for axis in AXES:
                binding = self.mapping.binding(axis, alt)
                if binding is None:
                    continue
                value = self._settled[axis] = settle(self._settled[axis], self.value(axis))
                if self._armed.get(axis) != binding:
                    if value != 0.0:
                        continue
                    self._armed[axis] = binding  # back at rest: armed for its binding now
                fractions[binding.channel] += binding.sign * value * scale
            down = self._state.down
            for button, action in self.mapping.buttons.items():
                if action.channel is None:
                    continue
                if button not in down:
                    self._buttons_armed.add(button)
                elif button in self._buttons_armed:
                    held[action.channel] = held.get(action.channel, 0) + action.direction
            held = {channel: max(-1, min(1, net)) for channel, net in held.items()}
        self.model.set_gamepad(fractions, held)

    def _refresh_status(self) -> None:
        if self._status is PadStatus.UNAVAILABLE:
            return
        if self._info is None:
            status, text = (PadStatus.ERROR, self._error) if self._error else (PadStatus.NO_PAD, "")
        elif self._stalled:
            status, text = PadStatus.STALLED, self._info.name
        elif not self._active:
            status, text = PadStatus.INACTIVE, self._info.name
        elif self._engaged:
            status, text = PadStatus.ENGAGED, self._info.name
        else:
            status, text = PadStatus.READY, self._info.name
        self._set_status(status, text)

    def _set_status(self, status: PadStatus, text: str) -> None:
        if (status, text) != (self._status, self._status_text):
            self._status, self._status_text = status, text
            self.events.status_changed.emit(status, text)

    def start(self) -> None:
        """The poller is starting: no pad yet."""
        if self._status is PadStatus.OFF:
            self._set_status(PadStatus.NO_PAD, "")

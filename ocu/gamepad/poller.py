"""SDL's game controllers read on a thread of their own ("ocu-gamepad"), no Qt.

The thread opens the first game controller SDL knows (hot-plug included) and keeps the
newest `PadState`; it calls `on_state()` when the state changed and `on_event(event)` when a
pad comes, goes, or SDL fails. It sleeps inside SDL (`SDL_WaitEventTimeout`, the GIL
released) until SDL reports a change — SDL reads the device every millisecond — or the
poll period (1 / `poll_hz`) passes; so a stick moved is read within about a millisecond,
and the thread reports at least `poll_hz` times a second. With no pad open it only looks for
one, ten times a second. With `wake_on_events=False` it only polls, every period (the
benchmark's baseline). Both callbacks run
on the poll thread: the consumer takes the newest state with `take()` on its own thread
(`ocu.qt.gamepad` does so on the GUI thread). A button pressed and released between two
takes is still reported, in `PadState.pressed`. `last_poll_at` says when the thread last
finished a poll (None until the first, while SDL starts): a consumer that sees it grow old
knows the thread stalled.
"""

from __future__ import annotations

import ctypes
import logging
import threading
import time
from collections.abc import Callable
from types import ModuleType
from typing import Any

from ocu.gamepad import sdl as sdl_loader
from ocu.gamepad.pad import (
    AXES,
    BUTTONS,
    PadConnected,
    PadDisconnected,
    PadError,
    PadEvent,
    PadInfo,
    PadState,
    PadUnavailable,
    PadUnsupported,
)

log = logging.getLogger("ocu.gamepad")

THREAD_NAME = "ocu-gamepad"
# After an SDL error, or while no pad is open, look for one this often.
RESCAN_S = 1.0
JOIN_TIMEOUT_S = 2.0
# How often the thread looks for a pad while none is open.
NO_PAD_PERIOD_S = 0.1
# With a pad open and no events, read it whole with SDL's getters this often.
RESYNC_S = 0.25
# SDL's controller types, grouped by the labels printed on the buttons.
_FAMILIES = {3: "playstation", 4: "playstation", 7: "playstation", 6: "virtual"}
# Events the poller does not need; SDL stops queueing them. (The joystick events stay: SDL
# makes the game controller events from them.)
_IGNORED_EVENTS = (
    "SDL_JOYBALLMOTION",
    "SDL_CONTROLLERTOUCHPADDOWN",
    "SDL_CONTROLLERTOUCHPADMOTION",
    "SDL_CONTROLLERTOUCHPADUP",
    "SDL_CONTROLLERSENSORUPDATE",
    "SDL_SENSORUPDATE",
)


class _OpenPad:
    """An SDL game controller the poller holds."""

    def __init__(self, handle: Any, info: PadInfo, buttons: tuple[bool, ...]) -> None:
        self.handle = handle
        self.info = info
        self.buttons = buttons  # as last published
        # As SDL's events say (the getters' values when read whole, at `read_at`).
        self.axes = [0] * len(AXES)
        self.held = list(buttons)
        self.read_at = 0.0


class PadPoller:
    """Reads SDL's game controllers on the "ocu-gamepad" thread."""

    def __init__(
        self,
        poll_hz: float,
        on_state: Callable[[], None],
        on_event: Callable[[PadEvent], None],
        *,
        wake_on_events: bool = True,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        if not poll_hz > 0:
            raise ValueError(f"poll_hz must be positive, got {poll_hz!r}")
        self.period_s = 1.0 / poll_hz
        self.wake_on_events = wake_on_events
        self._on_state = on_state
        self._on_event = on_event
        self._clock = clock
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._lock = threading.Lock()
        self._latest: PadState | None = None
        self._taken = True
        self._pressed: set[str] = set()
        self._pad: _OpenPad | None = None
        self._rescan_at = 0.0
        self._unsupported: set[str] = set()
        self.last_poll_at: float | None = None
        self.polls = 0

    # ---- the consumer's side -----------------------------------------------------------------

    def start(self) -> None:
        """Start the poll thread."""
        if self._thread is not None:
            raise RuntimeError("the poller runs already")
        self.last_poll_at = None
        self._thread = threading.Thread(target=self._run, name=THREAD_NAME, daemon=True)
        self._thread.start()

    def stop(self) -> None:
        """Stop the poll thread and close the pad; idempotent."""
        self._stop.set()
        thread, self._thread = self._thread, None
        if thread is not None:
            thread.join(JOIN_TIMEOUT_S)
            if thread.is_alive():
                log.error("the gamepad poll thread did not stop within %.1f s", JOIN_TIMEOUT_S)

    @property
    def running(self) -> bool:
        """Whether the poll thread runs."""
        return self._thread is not None and self._thread.is_alive()

    def peek(self) -> PadState | None:
        """The newest state, taken or not (None while no pad is open)."""
        with self._lock:
            return self._latest

    def take(self) -> PadState | None:
        """The newest state not yet taken (None: nothing new), with every press since the last."""
        with self._lock:
            if self._taken or self._latest is None:
                return None
            self._taken = True
            state = self._latest
            if self._pressed:
                state = PadState(
                    state.instance_id,
                    state.axes,
                    state.buttons,
                    state.polled_at,
                    frozenset(self._pressed),
                )
                self._pressed.clear()
            return state

    # ---- the poll thread ---------------------------------------------------------------------

    def _run(self) -> None:
        try:
            sdl = sdl_loader.acquire()
        except sdl_loader.SdlUnavailableError as err:
            log.warning("%s", err)
            self._on_event(PadUnavailable(str(err)))
            return
        try:
            for name in _IGNORED_EVENTS:
                if hasattr(sdl, name):
                    sdl.SDL_EventState(getattr(sdl, name), sdl.SDL_IGNORE)
            event = sdl.SDL_Event()
            timeout_ms = max(1, round(1000 * self.period_s))
            next_at = self._clock()
            while not self._stop.is_set():
                waiting = self.wake_on_events and self._pad is not None
                try:
                    if waiting:
                        pending = sdl.SDL_WaitEventTimeout(ctypes.byref(event), timeout_ms)
                        if pending:
                            self._one_event(sdl, event)
                        else:
                            self._quiet(sdl)
                    else:
                        pending = sdl.SDL_PollEvent(ctypes.byref(event))
                        self._poll(sdl, event, bool(pending))
                except Exception as err:  # an SDL call failed: the pad's motion must stop
                    log.exception("gamepad poll failed")
                    self._close(sdl)
                    self._rescan_at = self._clock() + RESCAN_S
                    self._on_event(PadError(f"{type(err).__name__}: {err}"))
                    self._stop.wait(self.period_s)
                now = self._clock()
                self.last_poll_at = now
                self.polls += 1
                if not waiting:
                    # Without a pad, look for one now and then (plugging one in is seen
                    # within NO_PAD_PERIOD_S); late (a loaded machine): no catch-up burst.
                    period_s = self.period_s if self._pad is not None else NO_PAD_PERIOD_S
                    next_at = max(next_at + period_s, now)
                    self._stop.wait(next_at - now)
        finally:
            self._close(sdl)
            sdl_loader.release(sdl)

    def _one_event(self, sdl: ModuleType, event: Any) -> None:
        """A wake-up by one event: the pad's state follows it, published at once.

        The state is taken from the event itself (SDL's controller events carry the axis's
        value and the button's state), not read back with SDL's getters: every ctypes call
        lets the GIL go and waits for it again behind the GUI thread, and reading the whole
        pad is 22 calls. The events still queued wake the thread again at once.
        """
        taps: set[str] = set()
        changed = self._handle(sdl, event, taps)
        pad = self._pad
        if pad is not None and (changed or taps):
            self._publish(pad, tuple(pad.axes), tuple(pad.held), taps)

    def _quiet(self, sdl: ModuleType) -> None:
        """A poll period without events: is the pad there; now and then, read it whole."""
        pad = self._pad
        if pad is None:
            return
        if not sdl.SDL_GameControllerGetAttached(pad.handle):
            self._lost(sdl, "disconnected")
            return
        now = self._clock()
        if now >= pad.read_at + RESYNC_S:
            # What SDL says, in case an event was dropped (its queue was full).
            self._read(sdl, pad, set())

    def _handle(self, sdl: ModuleType, event: Any, taps: set[str]) -> bool:
        """One event: hot-plug, or the open pad's axis or button (its tracked state follows;
        a press goes into `taps`). Whether the pad's state may have changed."""
        kind = event.type
        pad = self._pad
        if kind == sdl.SDL_CONTROLLERDEVICEADDED:
            if pad is None:
                return self._open(sdl, event.cdevice.which)
        elif kind == sdl.SDL_CONTROLLERDEVICEREMOVED:
            if pad is not None and event.cdevice.which == pad.info.instance_id:
                self._lost(sdl, "unplugged")
        elif kind == sdl.SDL_JOYDEVICEADDED:
            self._check_supported(sdl, event.jdevice.which)
        elif kind in (sdl.SDL_CONTROLLERBUTTONDOWN, sdl.SDL_CONTROLLERBUTTONUP):
            if pad is not None and event.cbutton.which == pad.info.instance_id:
                button = event.cbutton.button
                if 0 <= button < len(BUTTONS):
                    down = kind == sdl.SDL_CONTROLLERBUTTONDOWN
                    # A press counts only for a button last read up: one held when the pad
                    # was opened is not pressed now.
                    if down and not pad.buttons[button]:
                        taps.add(BUTTONS[button])
                    pad.held[button] = down
                return True
        elif (
            kind == sdl.SDL_CONTROLLERAXISMOTION
            and pad is not None
            and event.caxis.which == pad.info.instance_id
        ):
            axis = event.caxis.axis
            if 0 <= axis < len(AXES):
                pad.axes[axis] = event.caxis.value
            return True
        return False

    def _poll(self, sdl: ModuleType, event: Any, pending: bool) -> None:
        """Handle `event` (if `pending`) and every other queued event, then read the pad
        (the polling mode: no pad open, or `wake_on_events=False`)."""
        changed = False
        taps: set[str] = set()
        while pending:
            changed |= self._handle(sdl, event, taps)
            pending = bool(sdl.SDL_PollEvent(ctypes.byref(event)))
        if self._pad is None and self._clock() >= self._rescan_at:
            self._rescan_at = self._clock() + RESCAN_S
            changed |= self._scan(sdl)
        pad = self._pad
        if pad is None:
            return
        if not sdl.SDL_GameControllerGetAttached(pad.handle):
            self._lost(sdl, "disconnected")
            return
        if changed or taps:
            self._read(sdl, pad, taps)

    def _read(self, sdl: ModuleType, pad: _OpenPad, taps: set[str], *, notify: bool = True) -> None:
        """The pad read whole with SDL's getters (the tracked state follows), published."""
        handle = pad.handle
        pad.axes = [sdl.SDL_GameControllerGetAxis(handle, i) for i in range(len(AXES))]
        pad.held = [bool(sdl.SDL_GameControllerGetButton(handle, i)) for i in range(len(BUTTONS))]
        pad.read_at = self._clock()
        self._publish(pad, tuple(pad.axes), tuple(pad.held), taps, notify=notify)

    def _publish(
        self,
        pad: _OpenPad,
        axes: tuple[int, ...],
        buttons: tuple[bool, ...],
        taps: set[str],
        *,
        notify: bool = True,
    ) -> None:
        went_down = {BUTTONS[i] for i, down in enumerate(buttons) if down and not pad.buttons[i]}
        pad.buttons = buttons
        with self._lock:
            latest = self._latest
            if (
                latest is not None
                and latest.instance_id == pad.info.instance_id
                and latest.axes == axes
                and latest.buttons == buttons
                and not taps
            ):
                return
            self._latest = PadState(pad.info.instance_id, axes, buttons, self._clock())
            self._pressed |= taps | went_down
            self._taken = False
        if notify:
            self._on_state()

    def _scan(self, sdl: ModuleType) -> bool:
        for index in range(sdl.SDL_NumJoysticks()):
            if sdl.SDL_IsGameController(index):
                return self._open(sdl, index)
            self._check_supported(sdl, index)
        return False

    def _check_supported(self, sdl: ModuleType, index: int) -> None:
        if sdl.SDL_IsGameController(index):
            return
        raw = sdl.SDL_JoystickNameForIndex(index) or b"joystick"
        name = raw.decode("utf-8", "replace")
        if name not in self._unsupported:
            self._unsupported.add(name)
            self._on_event(PadUnsupported(name))

    def _open(self, sdl: ModuleType, index: int) -> bool:
        handle = sdl.SDL_GameControllerOpen(index)
        if not handle:
            raise RuntimeError(f"cannot open game controller {index}: {sdl_loader.error_text(sdl)}")
        joystick = sdl.SDL_GameControllerGetJoystick(handle)
        guid = sdl.SDL_JoystickGetGUID(joystick)
        text = ctypes.create_string_buffer(33)
        sdl.SDL_JoystickGetGUIDString(guid, text, len(text))
        raw_name = sdl.SDL_GameControllerName(handle) or b"game controller"
        info = PadInfo(
            name=raw_name.decode("utf-8", "replace"),
            guid=text.value.decode("ascii"),
            family=_FAMILIES.get(sdl.SDL_GameControllerGetType(handle), "xbox"),
            instance_id=sdl.SDL_JoystickInstanceID(joystick),
        )
        buttons = tuple(
            bool(sdl.SDL_GameControllerGetButton(handle, i)) for i in range(len(BUTTONS))
        )
        self._pad = _OpenPad(handle, info, buttons)
        log.info("gamepad opened: %s (%s)", info.name, info.guid)
        # The first state is there before anyone hears of the pad: a consumer told it is
        # connected can take it at once.
        self._read(sdl, self._pad, set(), notify=False)
        self._on_event(PadConnected(info))
        self._on_state()
        return True

    def _lost(self, sdl: ModuleType, reason: str) -> None:
        pad = self._pad
        if pad is None:
            return
        self._close(sdl)
        self._rescan_at = self._clock()  # another pad may be plugged in already
        self._on_event(PadDisconnected(pad.info, reason))

    def _close(self, sdl: ModuleType) -> None:
        pad, self._pad = self._pad, None
        if pad is not None:
            sdl.SDL_GameControllerClose(pad.handle)
        with self._lock:
            self._latest = None
            self._taken = True
            self._pressed.clear()

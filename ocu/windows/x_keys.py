"""The motion keys off the GUI thread: XInput2 raw key events on an X connection of our own.

A key event reaches Qt's key filter only when the GUI thread gets to it: after the paint it
is in (the map, the plots, the video and the 3D view each take up to 25 ms on a loaded
machine). The X server also reports every key to any client that asks for XInput2 *raw*
events on the root window, at once and whatever window has the focus. `XKeyReader` asks for
them on a connection of its own (libX11 and libXi through ctypes, the libraries Qt's xcb
plugin and xdotool bring) and acts on them from its own thread, under the model's lock, as
the control thread and the pad's thread do:

- only while the X server's input focus is one of the console's own top-level windows (the
  main window, a floating dock; a dialog is not one), which the GUI thread publishes
  (`set_windows`), and while no text box has the keyboard focus (`set_typing`);
- Space: the emergency stop;
- the hold and Cartesian keys of the key map, pressed without Ctrl, Alt or Super: pressed
  and released; a release is acted on wherever the focus is (a release only stops);
- Shift: the fine speed.

Raw events are the device's own: a key's auto-repeat makes none, and a key held before the
console got the focus shows no press, so the reader never mistakes either for a press (what
`ocu.windows.key_filter.KeyGuard` has to work out from Qt's events).

Qt's key events still come, later. Whichever of the two sees an event first acts on it: both
ask `take(key, pressed, server_time)` (the raw event and Qt's event carry the same X server
time), and the one that loses only keeps its bookkeeping. Everything else — command keys,
the help, Escape, typing, dialogs, a platform that is not X11, an X server without XInput2 —
goes through Qt's key filter as before. `OCU_X_KEYS=0` turns the reader off (benchmarks
compare the two paths).
"""

from __future__ import annotations

import contextlib
import ctypes
import ctypes.util
import logging
import os
import select
import socket
import threading
from collections import OrderedDict
from collections.abc import Callable
from typing import Any

from ocu import hotkeys
from ocu.hotkeys import KeyMap
from ocu.windows.held_keys import X_KEYCODE_OFFSET

log = logging.getLogger("ocu.keys")

ENV_SWITCH = "OCU_X_KEYS"
GENERIC_EVENT = 35  # X11 GenericEvent
XI_RAW_KEY_PRESS = 13
XI_RAW_KEY_RELEASE = 14
XI_ALL_MASTER_DEVICES = 1
POINTER_ROOT = 1  # the input focus follows the pointer
FOCUS_IN, FOCUS_OUT = 9, 10  # X11 core events
FOCUS_CHANGE_MASK = 1 << 21
NOTIFY_INFERIOR = 2  # FocusOut's detail: the focus went to a window inside this one
NOTIFY_POINTER = 5  # this detail and those above: the focus follows the pointer (or is none)
# X key codes (evdev + 8) of the modifiers: Shift sets the fine speed; with Ctrl, Alt or
# Super down a key is a shortcut, left to Qt.
SHIFT_CODES = frozenset({50, 62})
SHORTCUT_CODES = frozenset({37, 105, 64, 108, 133, 134})
# Events both paths remember, to tell who acted first (a few seconds of typing).
TAKEN_KEPT = 256
STARTED = "X key reader running"  # log line (tests wait on it)


class _XGenericEventCookie(ctypes.Structure):
    _fields_ = [
        ("type", ctypes.c_int),
        ("serial", ctypes.c_ulong),
        ("send_event", ctypes.c_int),
        ("display", ctypes.c_void_p),
        ("extension", ctypes.c_int),
        ("evtype", ctypes.c_int),
        ("cookie", ctypes.c_uint),
        ("data", ctypes.c_void_p),
    ]


class _XFocusChangeEvent(ctypes.Structure):
    _fields_ = [
        ("type", ctypes.c_int),
        ("serial", ctypes.c_ulong),
        ("send_event", ctypes.c_int),
        ("display", ctypes.c_void_p),
        ("window", ctypes.c_ulong),
        ("mode", ctypes.c_int),
        ("detail", ctypes.c_int),
    ]


class _XEvent(ctypes.Union):
    _fields_ = [
        ("type", ctypes.c_int),
        ("cookie", _XGenericEventCookie),
        ("focus", _XFocusChangeEvent),
        ("pad", ctypes.c_long * 24),
    ]


class _XIValuatorState(ctypes.Structure):
    _fields_ = [
        ("mask_len", ctypes.c_int),
        ("mask", ctypes.c_void_p),
        ("values", ctypes.c_void_p),
    ]


class _XIRawEvent(ctypes.Structure):
    _fields_ = [
        ("type", ctypes.c_int),
        ("serial", ctypes.c_ulong),
        ("send_event", ctypes.c_int),
        ("display", ctypes.c_void_p),
        ("extension", ctypes.c_int),
        ("evtype", ctypes.c_int),
        ("time", ctypes.c_ulong),
        ("deviceid", ctypes.c_int),
        ("sourceid", ctypes.c_int),
        ("detail", ctypes.c_int),
        ("flags", ctypes.c_int),
        ("valuators", _XIValuatorState),
        ("raw_values", ctypes.c_void_p),
    ]


class _XIEventMask(ctypes.Structure):
    _fields_ = [
        ("deviceid", ctypes.c_int),
        ("mask_len", ctypes.c_int),
        ("mask", ctypes.POINTER(ctypes.c_ubyte)),
    ]


def _library(name: str, soname: str, *, holding_gil: bool = False) -> ctypes.CDLL | None:
    """The library; with `holding_gil` its functions are called holding the GIL
    (ctypes.PyDLL). The reader's local calls (taking an event already read, its data) are
    short, and a call that let go of the GIL would wait for it again afterwards, behind
    whichever thread got it meanwhile (up to Python's switch interval each time, several
    times per key). Its round trips to the server (the focus, the pointer) let go of it: a
    slow or remote X server must not hold up the control thread."""
    kind = ctypes.PyDLL if holding_gil else ctypes.CDLL
    for candidate in (ctypes.util.find_library(name), soname):
        if candidate:
            try:
                return kind(candidate)
            except OSError:
                continue
    return None


# void (*)(Display *, void *): what Xlib calls when a connection is lost (libX11 >= 1.7).
_IOErrorExitHandler = ctypes.CFUNCTYPE(None, ctypes.c_void_p, ctypes.c_void_p)


def _declare(x11: ctypes.CDLL, xi: ctypes.CDLL) -> None:
    vp, c_int = ctypes.c_void_p, ctypes.c_int
    x11.XOpenDisplay.restype = vp
    x11.XOpenDisplay.argtypes = [ctypes.c_char_p]
    x11.XCloseDisplay.argtypes = [vp]
    x11.XDefaultRootWindow.restype = ctypes.c_ulong
    x11.XDefaultRootWindow.argtypes = [vp]
    x11.XConnectionNumber.argtypes = [vp]
    x11.XQueryExtension.argtypes = [vp, ctypes.c_char_p, *([ctypes.POINTER(c_int)] * 3)]
    x11.XPending.argtypes = [vp]
    x11.XNextEvent.argtypes = [vp, ctypes.POINTER(_XEvent)]
    x11.XGetEventData.argtypes = [vp, ctypes.POINTER(_XGenericEventCookie)]
    x11.XFreeEventData.argtypes = [vp, ctypes.POINTER(_XGenericEventCookie)]
    x11.XGetInputFocus.argtypes = [vp, ctypes.POINTER(ctypes.c_ulong), ctypes.POINTER(c_int)]
    x11.XFlush.argtypes = [vp]
    x11.XSelectInput.argtypes = [vp, ctypes.c_ulong, ctypes.c_long]
    if hasattr(x11, "XSetIOErrorExitHandler"):
        x11.XSetIOErrorExitHandler.argtypes = [vp, _IOErrorExitHandler, vp]
        x11.XSetIOErrorExitHandler.restype = None
    x11.XQueryPointer.argtypes = [
        vp,
        ctypes.c_ulong,
        *([ctypes.POINTER(ctypes.c_ulong)] * 2),
        *([ctypes.POINTER(c_int)] * 4),
        ctypes.POINTER(ctypes.c_uint),
    ]
    xi.XIQueryVersion.argtypes = [vp, ctypes.POINTER(c_int), ctypes.POINTER(c_int)]
    xi.XISelectEvents.argtypes = [vp, ctypes.c_ulong, ctypes.POINTER(_XIEventMask), c_int]


class FocusTracker:
    """Whether the X input focus is in one of the console's windows, from the FocusIn and
    FocusOut events the reader asks for on each of them: no round trip to the server per key.

    Asking the server (XGetInputFocus) lets the GIL go for the round trip, and getting it back
    behind the GUI thread's paints took up to 5 ms (the interpreter's switch interval) before
    the key could act. The server sends a window's focus events before any key that follows
    the change, on the reader's own connection, so the events keep the answer exact once it is
    `known`: from a first round trip after the windows were (re)selected, or from a FocusIn or
    FocusOut on one of them. While the focus follows the pointer (PointerRoot, or none) it is
    not known, and each key asks the server as before. Any doubt leaves a key to Qt's filter.
    """

    def __init__(self) -> None:
        self.known = False
        self.window: int | None = None  # the console's window that has the focus, if any

    def forget(self) -> None:
        """Ask the server at the next key (the windows watched changed)."""
        self.known = False
        self.window = None

    def event(self, kind: int, window: int, detail: int) -> None:
        """A FocusIn or FocusOut on a console window."""
        if detail >= NOTIFY_POINTER:
            self.forget()
        elif kind == FOCUS_IN:
            self.known, self.window = True, window
        elif detail != NOTIFY_INFERIOR and self.window in (window, None):
            # Out of this window: to another console window (its FocusIn comes next) or to
            # someone else's.
            self.known, self.window = True, None

    def asked(self, focus: int, windows: frozenset[int]) -> None:
        """What XGetInputFocus said (POINTER_ROOT: still not known)."""
        if focus == POINTER_ROOT:
            self.forget()
        else:
            self.known, self.window = True, focus if focus in windows else None


class TakenEvents:
    """Which key events were acted on, by server time: the first to `take` one acts on it."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._taken: OrderedDict[tuple[str, bool, int], None] = OrderedDict()

    def take(self, key: str, pressed: bool, server_ms: int) -> bool:
        """True for the first caller with this event, False for every later one."""
        entry = (key, pressed, server_ms & 0xFFFFFFFF)
        with self._lock:
            if entry in self._taken:
                return False
            self._taken[entry] = None
            while len(self._taken) > TAKEN_KEPT:
                self._taken.popitem(last=False)
            return True


class XKeyReader:
    """The reader of the module docstring: `open()`, then `start()`; `stop()` at the end."""

    def __init__(self, x11: ctypes.CDLL, xi: ctypes.CDLL, display: int, opcode: int) -> None:
        self._x11 = x11
        self._events = x11  # open(): the same library, its calls holding the GIL
        self._broken = threading.Event()  # the connection to the server is lost
        self._on_loss: object = None
        self._xi = xi
        self._display: int | None = display
        self._opcode = opcode
        self.taken = TakenEvents()
        self.keys: RawKeys | None = None  # set by start()
        self._windows: frozenset[int] = frozenset()
        self._watched: frozenset[int] = frozenset()  # windows whose focus events come (thread)
        self.focus = FocusTracker()  # the reader thread's
        self.focus_queries = 0  # round trips to the server for the focus
        self._typing = False
        self._wake_r, self._wake_w = os.pipe()
        os.set_blocking(self._wake_r, False)
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    # ---- opening --------------------------------------------------------------------------

    @classmethod
    def open(cls, display_name: str | None = None) -> XKeyReader | None:
        """A reader on `display_name` ($DISPLAY); None where raw key events cannot be had."""
        if os.environ.get(ENV_SWITCH, "1") == "0":
            log.info("X key reader off (%s=0): keys go through Qt's events", ENV_SWITCH)
            return None
        events = _library("X11", "libX11.so.6", holding_gil=True)  # the reader's local calls
        x11 = _library("X11", "libX11.so.6")
        xi = _library("Xi", "libXi.so.6")
        if x11 is None or xi is None or events is None:
            log.info("no libX11/libXi: keys go through Qt's events only")
            return None
        try:
            _declare(x11, xi)
            _declare(events, xi)
        except AttributeError:
            return None
        if not hasattr(x11, "XSetIOErrorExitHandler"):  # libX11 < 1.7
            log.info("libX11 before 1.7: keys go through Qt's events only")
            return None
        display = x11.XOpenDisplay(display_name.encode() if display_name else None)
        if not display:
            return None
        # The server gone (it died, the session ended): Xlib's default ends the process with
        # C's exit() from whichever thread noticed - from this one, exit() ran Qt's global
        # destructors under the GUI thread's feet and the process hung (a hog run). This
        # connection's handler only marks it broken; the GUI thread's own connection then
        # ends the console as before (ocu.app hooks the zeros to the loss).
        broken = threading.Event()
        on_loss = _IOErrorExitHandler(lambda _display, _data: broken.set())
        x11.XSetIOErrorExitHandler(display, on_loss, None)
        opcode, event, error = ctypes.c_int(), ctypes.c_int(), ctypes.c_int()
        major, minor = ctypes.c_int(2), ctypes.c_int(2)
        if (
            not x11.XQueryExtension(
                display,
                b"XInputExtension",
                ctypes.byref(opcode),
                ctypes.byref(event),
                ctypes.byref(error),
            )
            or xi.XIQueryVersion(display, ctypes.byref(major), ctypes.byref(minor)) != 0
        ):
            x11.XCloseDisplay(display)
            log.info("the X server has no XInput 2.2: keys go through Qt's events only")
            return None
        mask_bytes = (ctypes.c_ubyte * 4)()
        for kind in (XI_RAW_KEY_PRESS, XI_RAW_KEY_RELEASE):
            mask_bytes[kind // 8] |= 1 << (kind % 8)
        mask = _XIEventMask(XI_ALL_MASTER_DEVICES, len(mask_bytes), mask_bytes)
        xi.XISelectEvents(display, x11.XDefaultRootWindow(display), ctypes.byref(mask), 1)
        x11.XFlush(display)
        reader = cls(x11, xi, display, opcode.value)
        reader._events = events
        reader._broken, reader._on_loss = broken, on_loss  # kept alive with the display
        return reader

    # ---- what the GUI thread tells it ---------------------------------------------------------

    def set_windows(self, windows: frozenset[int]) -> None:
        """The console's top-level X windows (any thread)."""
        if windows == self._windows:
            return
        self._windows = windows
        with contextlib.suppress(OSError):
            os.write(self._wake_w, b"w")  # the thread asks for their focus events

    def set_typing(self, typing: bool) -> None:
        """Whether a text box has the keyboard focus (any thread)."""
        self._typing = typing
        if self.keys is not None:
            self.keys.typing = typing

    # ---- the thread ---------------------------------------------------------------------------

    def start(self, model: Any, key_map: KeyMap, lock: Any) -> None:
        """Act on `model` (a handle whose calls are safe from this thread) under `lock`."""
        if self._thread is not None:
            return
        self.keys = RawKeys(model, key_map, lock)
        self.keys.taken = self.taken
        self.keys.typing = self._typing
        self._thread = threading.Thread(target=self._run, name="ocu-x-keys", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        """Stop the thread and close the connection (idempotent)."""
        self._stop.set()
        with contextlib.suppress(OSError):
            os.write(self._wake_w, b"x")
        thread, self._thread = self._thread, None
        if thread is not None and thread is not threading.current_thread():
            thread.join(2.0)
        display, self._display = self._display, None
        alive = thread is not None and thread.is_alive()
        if display is not None and not alive and not self._broken.is_set():
            self._x11.XCloseDisplay(display)
            for fd in (self._wake_r, self._wake_w):
                os.close(fd)

    def _run(self) -> None:
        display = self._display
        assert display is not None
        events = self._events
        fd = events.XConnectionNumber(display)
        # A look at the connection before Xlib reads it: a server gone is noticed here, and
        # Xlib's I/O error path (a global handler, then exit()) is never taken from this
        # thread (once it hung the process while Qt's own connection ended it).
        peek = socket.socket(fileno=os.dup(fd))
        event = _XEvent()
        log.info(STARTED)
        try:
            while not self._stop.is_set():
                self._watch(display)
                while events.XPending(display) and not self._broken.is_set():
                    events.XNextEvent(display, ctypes.byref(event))
                    self._dispatch(display, event)
                if self._stop.is_set() or self._broken.is_set():
                    break
                ready, _, _ = select.select([fd, self._wake_r], [], [])
                if self._wake_r in ready:
                    with contextlib.suppress(OSError):
                        os.read(self._wake_r, 64)
                if not _connected(peek):
                    self._broken.set()
                    break
        except Exception:
            log.exception("the X key reader failed: keys go through Qt's events only")
        finally:
            peek.close()
        if self._broken.is_set():
            log.warning("the X key reader lost the X server: keys go through Qt's events only")

    def _watch(self, display: int) -> None:
        """Ask for the focus events of the console's windows published since the last time.
        (A window gone meanwhile is an X error that Qt's Xlib error handler ignores.)"""
        windows = self._windows
        if windows == self._watched:
            return
        for window in windows - self._watched:
            self._events.XSelectInput(display, window, FOCUS_CHANGE_MASK)
        self._events.XFlush(display)
        self._watched = windows
        self.focus.forget()  # a change before the selection was not seen: ask once

    def _dispatch(self, display: int, event: _XEvent) -> None:
        if event.type in (FOCUS_IN, FOCUS_OUT):
            change = event.focus
            if change.window in self._watched:
                self.focus.event(change.type, change.window, change.detail)
            return
        cookie = event.cookie
        if event.type != GENERIC_EVENT or cookie.extension != self._opcode:
            return
        if not self._events.XGetEventData(display, ctypes.byref(cookie)):
            return
        try:
            if cookie.evtype not in (XI_RAW_KEY_PRESS, XI_RAW_KEY_RELEASE):
                return
            raw = ctypes.cast(cookie.data, ctypes.POINTER(_XIRawEvent)).contents
            pressed = cookie.evtype == XI_RAW_KEY_PRESS
            code, server_ms = raw.detail, raw.time
        finally:
            self._events.XFreeEventData(display, ctypes.byref(cookie))
        keys = self.keys
        if keys is None:
            return
        try:
            keys.key(code, pressed, server_ms, self._focused(display))
        except Exception:
            log.exception("X key reader: key %d failed", code)

    def _focused(self, display: int) -> bool:
        tracked = self.focus
        if tracked.known:
            return tracked.window is not None and tracked.window in self._windows
        self.focus_queries += 1
        log.debug("X focus asked of the server (%d)", self.focus_queries)
        focus, revert = ctypes.c_ulong(), ctypes.c_int()
        self._x11.XGetInputFocus(display, ctypes.byref(focus), ctypes.byref(revert))
        tracked.asked(focus.value, self._watched)
        if focus.value == POINTER_ROOT:
            # No window has the focus: keys go to the top-level window under the pointer.
            root, child = ctypes.c_ulong(), ctypes.c_ulong()
            xy = [ctypes.c_int() for _ in range(4)]
            mask = ctypes.c_uint()
            self._x11.XQueryPointer(
                display,
                self._x11.XDefaultRootWindow(display),
                ctypes.byref(root),
                ctypes.byref(child),
                *(ctypes.byref(v) for v in xy),
                ctypes.byref(mask),
            )
            focus = child
        if focus.value not in self._windows:
            log.debug("X focus 0x%x, not the console's %s", focus.value, sorted(self._windows))
            return False
        return True


def _connected(sock: socket.socket) -> bool:
    """Whether the X server's end of the connection is still there (EOF or a reset: gone)."""
    try:
        return sock.recv(1, socket.MSG_PEEK | socket.MSG_DONTWAIT) != b""
    except BlockingIOError:
        return True  # nothing to read: woken by the stop pipe
    except OSError:
        return False


class RawKeys:
    """What the reader does with one raw key event (Qt-free, no X: tests drive it directly).

    `model` is a handle whose calls are safe from the reader's thread; every action also
    holds `lock` (the model's), so one key is one step of the model.
    """

    def __init__(self, model: Any, key_map: KeyMap, lock: Any) -> None:
        self.model = model
        self.key_map = key_map
        self.lock = lock
        self.taken = TakenEvents()
        self.typing = False  # a text box has the keyboard focus (the GUI thread sets it)
        self._shortcut_down: set[int] = set()
        self._shift_down: set[int] = set()
        self.acted = 0  # events acted on
        self.on_action: Callable[[str, bool], None] | None = None  # benchmarks' probe

    def key(self, code: int, pressed: bool, server_ms: int, focused: bool) -> bool:
        """Act on one raw key event (X key code); True if acted on."""
        for codes, down in ((SHORTCUT_CODES, self._shortcut_down), (SHIFT_CODES, self._shift_down)):
            if code in codes:
                if pressed:
                    down.add(code)
                else:
                    down.discard(code)
        if code in SHIFT_CODES:
            if focused and not self.typing:
                with self.lock:
                    hotkeys.set_fine(self.model, bool(self._shift_down))
            return False
        name = hotkeys.key_for_position(code - X_KEYCODE_OFFSET)
        key_map = self.key_map
        if name is None:
            return False
        motion = name in key_map.hold or name in key_map.cartesian
        if name != hotkeys.ESTOP_KEY and not motion:
            return False  # a command key: Qt's key filter
        if not pressed:
            # Wherever the focus is: a release only stops, whoever acted on the press.
            if name == hotkeys.ESTOP_KEY:
                return False
            with self.lock:
                held = name in self.model.held_keys
            return held and self._act(name, pressed, server_ms)
        if not focused:
            log.debug("%s left to Qt (focus elsewhere)", name)
            return False
        if name != hotkeys.ESTOP_KEY and (self.typing or self._shortcut_down):
            # Letters typed into a text box are text; with Ctrl, Alt or Super a shortcut.
            # Space stops, as Qt's filter does, wherever the keyboard focus is.
            log.debug("%s left to Qt (%s)", name, "typing" if self.typing else "a shortcut")
            return False
        return self._act(name, pressed, server_ms)

    def _act(self, name: str, pressed: bool, server_ms: int) -> bool:
        if not self.taken.take(name, pressed, server_ms):
            log.debug("%s at %d: Qt's key filter was first", name, server_ms)
            return False
        model, key_map = self.model, self.key_map
        with self.lock:
            if pressed:
                hotkeys.press(model, key_map, name)
            else:
                hotkeys.release(model, key_map, name)
        self.acted += 1
        probe = self.on_action
        if probe is not None:
            probe(name, pressed)
        log.debug(
            "%s %s at %d (X key reader)", name, "pressed" if pressed else "released", server_ms
        )
        return True


class CoreKeys:
    """The X key reader in the control core's process (ocu.core_process), as the GUI reaches
    it: the window tells it its top-level windows and whether a text box has the keyboard
    focus; Qt's key filter asks `take` (the reader's bookkeeping of who acted first)."""

    def __init__(self, reader: XKeyReader | None) -> None:
        self.reader = reader

    def running(self) -> bool:
        """Whether raw key events are read (an X server with XInput 2.2 on $DISPLAY)."""
        return self.reader is not None

    def set_windows(self, windows: frozenset[int]) -> None:
        """The console's top-level X windows."""
        if self.reader is not None:
            self.reader.set_windows(frozenset(windows))

    def set_typing(self, typing: bool) -> None:
        """Whether a text box has the keyboard focus."""
        if self.reader is not None:
            self.reader.set_typing(typing)

    def take(self, key: str, pressed: bool, server_ms: int) -> bool:
        """True if the event is Qt's to act on (the reader did not act on it first)."""
        return self.reader is None or self.reader.taken.take(key, pressed, server_ms)

    def acted(self) -> int:
        """Events the reader acted on."""
        return 0 if self.reader is None or self.reader.keys is None else self.reader.keys.acted

    def stop(self) -> None:
        """Stop the reader (the core ends)."""
        reader, self.reader = self.reader, None
        if reader is not None:
            reader.stop()


def core_keys(core: Any) -> CoreKeys:
    """The "keys" part of a control core process: the reader on $DISPLAY, acting on the
    core's model under its lock (ocu.core_process.Core)."""
    from ocu.core.guard import Guarded

    reader = XKeyReader.open()
    if reader is not None:
        key_map = core.spec.key_map or hotkeys.load_key_map(core.spec.profile)
        reader.start(Guarded(core.model, core.lock), key_map, core.lock)
    return CoreKeys(reader)


class RemoteReader:
    """The GUI's handle on the core's `CoreKeys`, with the surface the key filter uses of an
    `XKeyReader` (`taken.take`, `set_windows`, `set_typing`, `stop`)."""

    def __init__(self, part: Any) -> None:
        self.part = part
        self.taken = self

    def take(self, key: str, pressed: bool, server_ms: int) -> bool:
        """True if Qt's filter is first (a round trip to the core; the core gone: Qt's)."""
        try:
            return bool(self.part.take(key, pressed, server_ms))
        except ConnectionError:
            return True

    def set_windows(self, windows: frozenset[int]) -> None:
        """Tell the core's reader (without waiting)."""
        self.part.set_windows.post(windows)

    def set_typing(self, typing: bool) -> None:
        """Tell the core's reader (without waiting)."""
        self.part.set_typing.post(typing)

    def stop(self) -> None:
        """Nothing: the core stops its reader when it ends."""

"""Qt's part of the hotkeys: turn key events into key names and call ocu.hotkeys.

An application-wide event filter sees every key event before the focused widget does, so
Space stops the robot even while a text box has focus. Letters typed into a text box stay
there; a key's release is always honoured, wherever the focus went meanwhile.

A motion key acts only on a press the console saw happen. Auto-repeat is told apart here,
not left to Qt: Qt flags a repeat only when it saw the key go down, and under X11 only when
the repeat's release and press reach it together (Xvfb with Qt 6.11: only when the GUI
thread was busy as they came). A key
held in another window therefore arrives as a stream of ordinary-looking presses when the
console gets the keyboard; `KeyGuard` ignores such a key until it is released and pressed
again, asking the X server which keys are down where it can (`ocu.windows.held_keys`).

Qt's flag can also be wrong the other way: its xcb backend remembers the key it last saw
repeating, and when that key's release goes to another window (the focus moved while it
was held) the key's next press in the console is flagged as a repeat. So Space stops on
every press, flagged or not, and where the X server says which keys are down the guard
does not use Qt's flag on presses at all.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from enum import Enum
from typing import cast

from PySide6.QtCore import QEvent, QObject, Qt
from PySide6.QtGui import QGuiApplication, QKeyEvent
from PySide6.QtWidgets import (
    QAbstractButton,
    QAbstractSlider,
    QAbstractSpinBox,
    QApplication,
    QComboBox,
    QDockWidget,
    QLineEdit,
    QMainWindow,
    QPlainTextEdit,
    QTextEdit,
    QWidget,
)

from ocu import hotkeys
from ocu.console.model import ConsoleModel
from ocu.core.guard import Guarded
from ocu.hotkeys import KeyMap
from ocu.windows.held_keys import XKeymapProbe
from ocu.windows.x_keys import RemoteReader, XKeyReader

log = logging.getLogger("ocu.keys")

# Native scan code minus this is the evdev position code, per Qt platform plugin.
SCAN_CODE_OFFSETS = {"xcb": 8, "wayland": 8, "windows": 0}

_PUNCTUATION = {
    "-": "Minus",
    "=": "Equal",
    "[": "BracketLeft",
    "]": "BracketRight",
    ";": "Semicolon",
    "'": "Apostrophe",
    "`": "Grave",
    "\\": "Backslash",
    ",": "Comma",
    ".": "Period",
    "/": "Slash",
}
# US shifted characters to the key that prints them unshifted (Qt reports the shifted key).
_SHIFTED = dict(zip('!@#$%^&*()_+{}:"~|<>?', "1234567890-=[];'`\\,./", strict=True))
_NAMED_KEYS: dict[int, str] = {
    Qt.Key.Key_Space.value: "Space",
    Qt.Key.Key_Escape.value: "Escape",
    **{getattr(Qt.Key, f"Key_F{n}").value: f"F{n}" for n in range(1, 13)},
}
_TEXT_INPUTS = (QLineEdit, QAbstractSpinBox, QTextEdit, QPlainTextEdit)
_SHORTCUT_MODIFIERS = (
    Qt.KeyboardModifier.ControlModifier
    | Qt.KeyboardModifier.AltModifier
    | Qt.KeyboardModifier.MetaModifier
)

# Keys a slider moves its handle with (QAbstractSlider::keyPressEvent): one Home tap on a
# focused velocity slider would command the full reverse speed. The arrows also click the
# neighbour of a checked button in an exclusive group (a switch: flippers up).
ARROW_KEYS = frozenset(
    key.value for key in (Qt.Key.Key_Left, Qt.Key.Key_Right, Qt.Key.Key_Up, Qt.Key.Key_Down)
)
SLIDER_KEYS = ARROW_KEYS | frozenset(
    key.value
    for key in (
        Qt.Key.Key_PageUp,
        Qt.Key.Key_PageDown,
        Qt.Key.Key_Home,
        Qt.Key.Key_End,
    )
)
# No keyboard auto-repeats sooner than this after the press (X11's default delay is 660 ms,
# desktop settings go down to about 200 ms). A repeat sooner than this is of a key that was
# down before the console saw it: the press it followed was itself a repeat.
REPEAT_DELAY_FLOOR_MS = 150
# Debug log lines (the X11 tests wait on them).
KEYBOARD_GAINED = "the console has the keyboard; keys down then"
KEYBOARD_LOST = "the console lost the keyboard"


class Verdict(Enum):
    """What a press of a guarded key means."""

    PRESS = "press"  # a real press: act on it
    REPEAT = "repeat"  # auto-repeat of a press acted on: nothing new
    BLOCKED = "blocked"  # held since before the console saw it go down: ignore until released
    HELD_BEFORE = "held before"  # the press acted on was a repeat after all: stop the key now
    RESUME = "resume"  # the release just acted on was an auto-repeat's: press again


@dataclass(frozen=True)
class _Release:
    timestamp_ms: int
    real: bool  # taken as the key going up
    stopped: bool  # and it stopped a key the model held
    # Taken as a repeat's only because the window system said the key was down when we
    # asked: the next press tells (the same server time: a repeat; another: it went up).
    asked: bool = False


class KeyGuard:
    """Tells real presses and releases of keys from auto-repeat and from keys held before.

    Qt-free. `pressed_now` asks the window system which keys are down (None: cannot tell);
    timestamps are the window system's milliseconds (0: unknown, `clock` is used).

    - When the console gets the keyboard, every key down at that moment is blocked: its
      presses are ignored until a real release.
    - A press is an auto-repeat if the key is already down, or if it carries the timestamp
      of the key's release just before (X11 repeats as release+press pairs with one server
      time; nobody releases and presses a key within one millisecond), or if Qt says so
      and the window system could not say which keys were down when the console got the
      keyboard (Qt's xcb flag outlives a release that went to another window: a key the
      window system said was up is pressed anew, whatever Qt says).
    - A release is an auto-repeat's if Qt says so or the window system says the key is
      still down (an X11 pair's press is generated with its release, before we ask) - unless
      the next press carries another server time: then the key went up and was pressed
      again before we asked (the GUI thread was busy), and the release counts.
    - An auto-repeat of a key not seen going down blocks it. One that comes sooner than any
      auto-repeat delay after the press acted on means that press was a repeat too: stop.
    """

    def __init__(
        self,
        pressed_now: Callable[[], frozenset[str] | None] | None = None,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.pressed_now = pressed_now
        self.clock = clock
        self._down: set[str] = set()
        self._blocked: set[str] = set()
        self._pressed_at: dict[str, float] = {}
        self._last_release: dict[str, _Release] = {}
        # Whether the window system told which keys were down when the console got the
        # keyboard (every other key was up then; Qt's repeat flag is not needed).
        self._keys_known = False

    @property
    def blocked(self) -> frozenset[str]:
        """Keys whose presses are ignored until they are released."""
        return frozenset(self._blocked)

    @property
    def down(self) -> frozenset[str]:
        """Keys seen going down and not yet up."""
        return frozenset(self._down)

    def activated(self) -> None:
        """The console got the keyboard: whatever is down now was pressed elsewhere."""
        self.deactivated()
        held = self.pressed_now() if self.pressed_now is not None else None
        self._blocked = set(held or ())
        self._keys_known = held is not None

    def deactivated(self) -> None:
        """The console lost the keyboard: releases go elsewhere, forget every key."""
        self._down.clear()
        self._blocked.clear()
        self._pressed_at.clear()
        self._last_release.clear()
        self._keys_known = False

    def press(self, key: str, timestamp_ms: int, qt_repeat: bool) -> Verdict:
        """Classify a press of `key`."""
        now_ms = float(timestamp_ms) if timestamp_ms else self.clock() * 1000.0
        last = self._last_release.pop(key, None)
        pair = bool(timestamp_ms) and last is not None and last.timestamp_ms == timestamp_ms
        if last is not None and last.asked and timestamp_ms and last.timestamp_ms and not pair:
            # That release was real: the key went up and was pressed again before we asked
            # (a busy GUI thread). It counts as up; this press is judged on its own.
            self._down.discard(key)
            self._blocked.discard(key)
        if key in self._blocked:
            return Verdict.BLOCKED
        qt_says_repeat = qt_repeat and not self._keys_known
        if not (qt_says_repeat or pair or key in self._down):
            self._down.add(key)
            self._pressed_at[key] = now_ms
            return Verdict.PRESS
        if key in self._down:
            elapsed = now_ms - self._pressed_at.get(key, -float("inf"))
            if 0.0 <= elapsed < REPEAT_DELAY_FLOOR_MS:
                self._down.discard(key)
                self._blocked.add(key)
                return Verdict.HELD_BEFORE
            return Verdict.REPEAT
        if pair and last is not None and last.real and last.stopped:
            # Neither Qt nor the window system told that release from a repeat's: the key
            # never went up, it was ours and moving; take it back as it was.
            self._down.add(key)
            return Verdict.RESUME
        self._blocked.add(key)
        return Verdict.BLOCKED

    def release(self, key: str, timestamp_ms: int, qt_repeat: bool, held: bool) -> bool:
        """Classify a release of `key` (`held`: the model holds it); True if it is real."""
        still_down = False
        if not qt_repeat and self.pressed_now is not None:
            now = self.pressed_now()
            still_down = now is not None and key in now
        if qt_repeat or still_down:
            self._last_release[key] = _Release(
                timestamp_ms, real=False, stopped=False, asked=still_down and not qt_repeat
            )
            return False
        self._down.discard(key)
        self._blocked.discard(key)
        self._last_release[key] = _Release(timestamp_ms, real=True, stopped=held)
        return True


def key_from_qt(key: int) -> str | None:
    """Key name from Qt's layout-dependent key code (used when there is no scan code)."""
    named = _NAMED_KEYS.get(key)
    if named is not None:
        return named
    if not 0x20 < key < 0x7F:
        return None
    char = _SHIFTED.get(chr(key), chr(key))
    if char.isalnum():
        return char.upper()
    return _PUNCTUATION.get(char)


def key_name(event: QKeyEvent, platform: str) -> str | None:
    """The US-position name of the key: from the scan code if there is one, else Qt's key."""
    offset = SCAN_CODE_OFFSETS.get(platform)
    scan_code = event.nativeScanCode()
    if offset is not None and scan_code > offset:
        name = hotkeys.key_for_position(scan_code - offset)
        if name is not None:
            return name
    return key_from_qt(event.key())


def is_text_input(widget: QObject | None) -> bool:
    """Whether typing in this widget means text (letters must go to it, not to the robot)."""
    if isinstance(widget, QComboBox):
        return widget.isEditable()
    return isinstance(widget, _TEXT_INPUTS)


def is_navigation(widget: QObject | None, key: int) -> bool:
    """Whether this key would move this widget's value: keys at a slider, arrows at a switch."""
    if isinstance(widget, QAbstractSlider):
        return key in SLIDER_KEYS
    if isinstance(widget, QAbstractButton) and widget.isCheckable():
        return key in ARROW_KEYS
    return False


class KeyFilter(QObject):
    """Application event filter: key events of the console's windows to ocu.hotkeys."""

    def __init__(
        self,
        model: ConsoleModel,
        key_map: KeyMap,
        owns: Callable[[QWidget], bool],
        platform: str | None = None,
        parent: QObject | None = None,
        *,
        pressed_now: Callable[[], frozenset[str] | None] | None = None,
        lock: threading.RLock | None = None,
    ) -> None:
        super().__init__(parent)
        self.model = model
        self.key_map = key_map
        self.owns = owns
        self.platform = platform if platform is not None else QGuiApplication.platformName()
        self._probe: XKeymapProbe | None = None
        if pressed_now is None and self.platform == "xcb":
            self._probe = XKeymapProbe.open()
            if self._probe is not None:
                pressed_now = self._probe.pressed
        self.guard = KeyGuard(pressed_now)
        self._active = False
        self._told: set[str] = set()  # keys the operator was told are ignored until released
        # The motion keys and Space off the GUI thread, under X11 (ocu.windows.x_keys). Its
        # handle on the model takes the lock but is no sign of the GUI thread's life.
        self.x_reader: XKeyReader | RemoteReader | None = None
        if lock is not None and self.platform == "xcb":
            self.x_reader = XKeyReader.open()
            if self.x_reader is not None:
                own = Guarded(cast(Guarded, model).unguarded, lock)
                self.x_reader.start(own, key_map, lock)
                QApplication.instance().focusChanged.connect(self._on_focus_widget)  # type: ignore[union-attr]

    def use_reader(self, reader: RemoteReader) -> None:
        """The X key reader of a control core in another process (ocu.windows.x_keys)."""
        self.x_reader = reader
        QApplication.instance().focusChanged.connect(self._on_focus_widget)  # type: ignore[union-attr]
        self._publish_windows()

    def shutdown(self) -> None:
        """No key acts from now on: the X key reader stopped, the filter removed."""
        reader, self.x_reader = self.x_reader, None
        if reader is not None:
            reader.stop()
        app = QApplication.instance()
        if app is not None:
            app.removeEventFilter(self)

    def _on_focus_widget(self, _old: QWidget | None, new: QWidget | None) -> None:
        reader = self.x_reader
        if reader is not None:
            reader.set_typing(is_text_input(new))

    def _publish_windows(self) -> None:
        """Tell the X key reader which top-level windows are the console's own."""
        reader = self.x_reader
        if reader is None:
            return
        windows = {
            int(widget.winId())
            for widget in QApplication.topLevelWidgets()
            if isinstance(widget, (QMainWindow, QDockWidget))
            and widget.isVisible()
            and self.owns(widget)
        }
        reader.set_windows(frozenset(windows))

    def eventFilter(self, watched: QObject, event: QEvent) -> bool:
        """Handle key presses and releases aimed at a widget of the console."""
        kind = event.type()
        if kind in _ACTIVATION_EVENTS:
            self._check_activation()
            return False
        if kind in _SHOW_EVENTS and isinstance(watched, QWidget) and watched.isWindow():
            self._publish_windows()  # a floating dock, the main window shown
            return False
        if kind not in (QEvent.Type.KeyPress, QEvent.Type.KeyRelease):
            return False
        if not isinstance(watched, QWidget) or not self.owns(watched):
            return False
        assert isinstance(event, QKeyEvent)
        return self.handle_key(watched, event, kind == QEvent.Type.KeyPress)

    def _check_activation(self) -> None:
        """Follow whether a console window has the keyboard (the guard's key state)."""
        self._publish_windows()
        window = QApplication.activeWindow()
        active = window is not None and self.owns(window)
        if active and not self._active:
            self.guard.activated()
            self._told.clear()
            log.debug("%s: %s", KEYBOARD_GAINED, ", ".join(sorted(self.guard.blocked)) or "none")
        elif self._active and not active:
            self.guard.deactivated()
            self._told.clear()
            log.debug(KEYBOARD_LOST)
        self._active = active

    def handle_key(self, receiver: QWidget, event: QKeyEvent, pressed: bool) -> bool:
        """Act on one key event; True when it is consumed (kept from the widget)."""
        modifiers = event.modifiers()
        hotkeys.set_fine(self.model, bool(modifiers & Qt.KeyboardModifier.ShiftModifier))
        if event.key() in (Qt.Key.Key_Shift, Qt.Key.Key_Control, Qt.Key.Key_Alt):
            return False
        if is_navigation(receiver, event.key()):
            # Belt and braces: sliders and switches take no focus, but one that has it
            # anyway must not move the robot on Home, End, PageUp/Down or an arrow.
            return True
        name = key_name(event, self.platform)
        if name is None:
            return False
        typing = is_text_input(receiver)
        if pressed and event.isAutoRepeat():
            log.debug("%s auto-repeat flagged by Qt", name)
        reader = self.x_reader
        if (
            reader is not None
            and (name == hotkeys.ESTOP_KEY or self.key_map.is_bound(name))
            and not reader.taken.take(name, pressed, int(event.timestamp()))
        ):
            return self._acted_by_reader(name, event, pressed, typing)
        if reader is not None and not event.isAutoRepeat():
            log.debug(
                "%s %s at %d (Qt)", name, "pressed" if pressed else "released", event.timestamp()
            )
        if name == hotkeys.ESTOP_KEY:
            # Space always stops, wherever it is aimed, however long it was held and whatever
            # Qt says: its repeat flag can be a leftover of a release that went elsewhere
            # (module docstring). Stopping again while stopped does no harm.
            if pressed:
                hotkeys.emergency_stop(self.model, "Space")
            return True
        guarded = self.key_map.is_bound(name)
        timestamp_ms = int(event.timestamp())
        if not pressed:
            if guarded:
                held = name in self.model.held_keys
                if not self.guard.release(name, timestamp_ms, event.isAutoRepeat(), held):
                    return not typing  # an auto-repeat's release carries no news
                self._told.discard(name)
            elif event.isAutoRepeat():
                return False
            return hotkeys.release(self.model, self.key_map, name)
        if guarded:
            verdict = self.guard.press(name, timestamp_ms, event.isAutoRepeat())
            if verdict is Verdict.HELD_BEFORE:
                hotkeys.release(self.model, self.key_map, name)
            if verdict in (Verdict.HELD_BEFORE, Verdict.BLOCKED) and name not in self._told:
                self._told.add(name)
                self.model.events.message.emit(
                    f"{name} was already down when the console got it: ignored until released"
                )
            if verdict not in (Verdict.PRESS, Verdict.RESUME):
                # Keep repeats from the widgets (a button or slider would act) but let a
                # text box repeat its characters.
                return not typing
        elif event.isAutoRepeat():
            return False
        if modifiers & _SHORTCUT_MODIFIERS:
            return False
        if typing and (event.text().isprintable() and event.text()):
            return False
        return hotkeys.press(self.model, self.key_map, name)

    def _acted_by_reader(self, name: str, event: QKeyEvent, pressed: bool, typing: bool) -> bool:
        """The X key reader acted on this event already: only the guard's bookkeeping."""
        if name == hotkeys.ESTOP_KEY:
            return True
        timestamp_ms = int(event.timestamp())
        if pressed:
            self.guard.press(name, timestamp_ms, event.isAutoRepeat())
        else:
            self.guard.release(name, timestamp_ms, event.isAutoRepeat(), held=False)
            self._told.discard(name)
        return not typing


_SHOW_EVENTS = (QEvent.Type.Show, QEvent.Type.Hide)
_ACTIVATION_EVENTS = (
    QEvent.Type.WindowActivate,
    QEvent.Type.WindowDeactivate,
    QEvent.Type.ApplicationStateChange,
)

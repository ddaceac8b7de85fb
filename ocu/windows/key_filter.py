"""Qt's part of the hotkeys: turn key events into key names and call ocu.hotkeys.

An application-wide event filter sees every key event before the focused widget does, so
Space stops the robot even while a text box has focus. Letters typed into a text box stay
there; a key's release is always honoured, wherever the focus went meanwhile.
"""

from __future__ import annotations

from collections.abc import Callable

from PySide6.QtCore import QEvent, QObject, Qt
from PySide6.QtGui import QGuiApplication, QKeyEvent
from PySide6.QtWidgets import (
    QAbstractSpinBox,
    QComboBox,
    QLineEdit,
    QPlainTextEdit,
    QTextEdit,
    QWidget,
)

from ocu import hotkeys
from ocu.control.teleop import TeleopModel
from ocu.hotkeys import KeyMap

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


class KeyFilter(QObject):
    """Application event filter: key events of the console's windows to ocu.hotkeys."""

    def __init__(
        self,
        model: TeleopModel,
        key_map: KeyMap,
        owns: Callable[[QWidget], bool],
        platform: str | None = None,
        parent: QObject | None = None,
    ) -> None:
        super().__init__(parent)
        self.model = model
        self.key_map = key_map
        self.owns = owns
        self.platform = platform if platform is not None else QGuiApplication.platformName()

    def eventFilter(self, watched: QObject, event: QEvent) -> bool:
        """Handle key presses and releases aimed at a widget of the console."""
        kind = event.type()
        if kind not in (QEvent.Type.KeyPress, QEvent.Type.KeyRelease):
            return False
        if not isinstance(watched, QWidget) or not self.owns(watched):
            return False
        assert isinstance(event, QKeyEvent)
        return self.handle_key(watched, event, kind == QEvent.Type.KeyPress)

    def handle_key(self, receiver: QWidget, event: QKeyEvent, pressed: bool) -> bool:
        """Act on one key event; True when it is consumed (kept from the widget)."""
        modifiers = event.modifiers()
        hotkeys.set_fine(self.model, bool(modifiers & Qt.KeyboardModifier.ShiftModifier))
        if event.key() in (Qt.Key.Key_Shift, Qt.Key.Key_Control, Qt.Key.Key_Alt):
            return False
        name = key_name(event, self.platform)
        if name is None:
            return False
        typing = is_text_input(receiver)
        if event.isAutoRepeat():
            # Auto-repeat press/release pairs carry no news; keep them from the widgets
            # (a slider would move) but let a text box repeat its characters.
            return name == hotkeys.ESTOP_KEY or (self.key_map.is_bound(name) and not typing)
        if not pressed:
            return hotkeys.release(self.model, self.key_map, name)
        if name == hotkeys.ESTOP_KEY:
            hotkeys.emergency_stop(self.model, "Space")
            return True
        if modifiers & _SHORTCUT_MODIFIERS:
            return False
        if typing and (event.text().isprintable() and event.text()):
            return False
        return hotkeys.press(self.model, self.key_map, name)

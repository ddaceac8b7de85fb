"""The hotkey help overlay (F1 or ?): the key map over the whole window, mouse-transparent.

With a game controller connected, its mapping stands beside the keys.
"""

from __future__ import annotations

from collections.abc import Callable
from html import escape

from PySide6.QtCore import QEvent, QObject, Qt
from PySide6.QtWidgets import QLabel, QVBoxLayout, QWidget

from ocu.console.model import ConsoleModel
from ocu.hotkeys import KeyMap

OVERLAY_STYLE = "background: rgba(20, 24, 28, 215); color: white;"


PadRows = Callable[[], list[tuple[str, str]]]


def _table(rows: list[tuple[str, str]], key_pt: int, text_pt: int) -> str:
    return (
        "<table>"
        + "".join(
            f"<tr><td align='right' style='padding:2px 12px;font-weight:bold;font-size:{key_pt}pt;"
            f"color:#ffd54f'>{escape(keys)}</td>"
            f"<td style='padding:2px 4px;font-size:{text_pt}pt'>{escape(what)}</td></tr>"
            for keys, what in rows
        )
        + "</table>"
    )


def _title(text: str) -> str:
    return (
        "<div style='font-size:14pt;font-weight:bold;color:#90caf9;margin-top:8px'>"
        f"{escape(text)}</div>"
    )


def _column(sections: list[tuple[str, list[tuple[str, str]]]], key_pt: int, text_pt: int) -> str:
    body = "".join(_title(title) + _table(rows, key_pt, text_pt) for title, rows in sections)
    return f"<td valign='top' style='padding:0px 16px'>{body}</td>"


def _groups(rows: list[tuple[str, str]]) -> list[list[tuple[str, list[tuple[str, str]]]]]:
    """The key map's rows in columns: driving and joints with the map under them, the arm
    beside (as the key map's descriptions prefix them)."""
    basic: list[tuple[str, str]] = []
    arm: list[tuple[str, str]] = []
    nav: list[tuple[str, str]] = []
    for keys, what in rows:
        if what.startswith("arm: ") or "(Cartesian)" in keys:
            arm.append((keys, what.removeprefix("arm: ")))
        elif what.startswith("map: "):
            nav.append((keys, what.removeprefix("map: ")))
        else:
            basic.append((keys, what))
    first = [("Driving and joints", basic)] + ([("Map", nav)] if nav else [])
    return [first] + ([[("Arm", arm)]] if arm else [])


def help_html(key_map: KeyMap, pad_rows: list[tuple[str, str]] | None = None) -> str:
    """The key map as HTML tables in columns (keys by US position), the pad's mapping beside."""
    columns = [_column(sections, 14, 12) for sections in _groups(key_map.help_rows())]
    if pad_rows:
        columns.append(_column([("Gamepad — hold the deadman", pad_rows)], 11, 11))
    body = "<table align='center'><tr>" + "".join(columns) + "</tr></table>"
    sources = "<br>".join(escape(s) for s in key_map.sources)
    return (
        "<div style='font-size:20pt;font-weight:bold'>Hotkeys — hold to move, release to stop"
        "</div>" + body + "<p style='font-size:11pt'>Keys work by position (a Russian layout "
        "drives the same). Letters go to a text box that has focus; Space stops from anywhere. "
        "F1, ? or Esc closes this help.<br>Key map: " + sources + "</p>"
    )


class HelpOverlay(QWidget):
    """Covers its parent while the model says help is visible."""

    def __init__(
        self,
        model: ConsoleModel,
        key_map: KeyMap,
        parent: QWidget,
        pad_rows: PadRows | None = None,
    ) -> None:
        super().__init__(parent)
        self.host = parent
        self.key_map = key_map
        self.pad_rows = pad_rows
        self.setObjectName("help_overlay")
        self.setAttribute(Qt.WidgetAttribute.WA_TransparentForMouseEvents)
        self.setAttribute(Qt.WidgetAttribute.WA_StyledBackground)
        self.setStyleSheet(OVERLAY_STYLE)
        self.label = QLabel(help_html(key_map))
        self.label.setObjectName("help_text")
        self.label.setTextFormat(Qt.TextFormat.RichText)
        self.label.setAlignment(Qt.AlignmentFlag.AlignCenter)
        self.label.setStyleSheet("background: transparent; color: white;")
        layout = QVBoxLayout(self)
        layout.addWidget(self.label)
        parent.installEventFilter(self)
        model.events.help_changed.connect(self._on_help)
        self.setVisible(model.help_visible)
        self.setGeometry(parent.rect())

    def eventFilter(self, watched: QObject, event: QEvent) -> bool:
        """Follow the parent's size."""
        if watched is self.host and event.type() == QEvent.Type.Resize:
            self.setGeometry(self.host.rect())
        return False

    def _on_help(self, visible: bool) -> None:
        if visible and self.pad_rows is not None:
            self.label.setText(help_html(self.key_map, self.pad_rows()))
        self.setGeometry(self.host.rect())
        self.setVisible(visible)
        if visible:
            self.raise_()

"""A one-line label that gives way: narrower than its text, it ends in an ellipsis."""

from __future__ import annotations

from PySide6.QtCore import QEvent, QSize, Qt
from PySide6.QtGui import QResizeEvent
from PySide6.QtWidgets import QLabel, QWidget

ELLIPSIS = "…"


class ElidedLabel(QLabel):
    """A one-line label that may get narrower than its text, down to `floor_text` (or an
    ellipsis alone): it then ends in an ellipsis and its tooltip shows the whole text.

    Its size hint is the whole text's; `text()` is the whole text too.
    """

    def __init__(self, parent: QWidget | None = None, *, floor_text: str = "") -> None:
        super().__init__(parent)
        self.floor_text = floor_text
        self._full = ""
        self._own_tip = ""

    def text(self) -> str:
        """The text set, whole (what shows may be shortened: `shown_text`)."""
        return self._full

    def shown_text(self) -> str:
        """The text as it shows now."""
        return super().text()

    def setText(self, text: str) -> None:
        """Show `text`, shortened to the width the label has."""
        self._full = text
        self._elide()
        self.updateGeometry()

    def setToolTip(self, text: str) -> None:
        """A tooltip of its own (the whole text is added to it while shortened)."""
        self._own_tip = text
        self._elide()

    def _extra_px(self) -> int:
        """Padding, margins and frame: what the label needs beside its text."""
        shown = self.fontMetrics().horizontalAdvance(super().text())
        return max(super().sizeHint().width() - shown, 0)

    def sizeHint(self) -> QSize:
        """Room for the whole text."""
        width = self._extra_px() + self.fontMetrics().horizontalAdvance(self._full)
        return QSize(width, super().sizeHint().height())

    def minimumSizeHint(self) -> QSize:
        """Room for the floor text (or the ellipsis), never more than the whole text."""
        metrics = self.fontMetrics()
        floor = metrics.horizontalAdvance(self.floor_text or ELLIPSIS)
        width = self._extra_px() + min(floor, metrics.horizontalAdvance(self._full))
        return QSize(width, super().minimumSizeHint().height())

    def resizeEvent(self, event: QResizeEvent) -> None:
        """Shorten the text to the new width."""
        super().resizeEvent(event)
        self._elide()

    def changeEvent(self, event: QEvent) -> None:
        """A new font or style sheet: shorten again, and say the size changed."""
        super().changeEvent(event)
        if event.type() in (QEvent.Type.FontChange, QEvent.Type.StyleChange):
            self._elide()
            self.updateGeometry()

    def _elide(self) -> None:
        if self.width() >= self.sizeHint().width():
            shown = self._full  # room for it all (elidedText measures a little differently)
        else:
            room = self.width() - self._extra_px()
            shown = self.fontMetrics().elidedText(self._full, Qt.TextElideMode.ElideRight, room)
        if shown != super().text():
            super().setText(shown)
        cut = shown != self._full
        tip = "\n".join(t for t in (self._full if cut else "", self._own_tip) if t)
        if tip != super().toolTip():
            super().setToolTip(tip)

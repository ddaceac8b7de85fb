"""A horizontal slider over a real range: shows model values, reports operator moves."""

from __future__ import annotations

from PySide6.QtCore import Qt, Signal
from PySide6.QtGui import QWheelEvent
from PySide6.QtWidgets import QSlider, QWidget

STEPS = 1000


class ValueSlider(QSlider):
    """[-limit, limit] (symmetric) or [0, limit] in STEPS steps per side.

    The wheel is ignored: scrolling the window over a slider must not move the robot. The
    slider takes no keyboard focus: a focused slider moves on Home, End, PageUp/Down and the
    arrows (one Home tap would command the full reverse speed until the next stop).
    """

    value_moved = Signal(float)

    def __init__(self, limit: float, symmetric: bool = True, parent: QWidget | None = None) -> None:
        super().__init__(Qt.Orientation.Horizontal, parent)
        self.symmetric = symmetric
        self.limit = limit
        self._value = 0.0
        self.setRange(-STEPS if symmetric else 0, STEPS)
        self.setPageStep(STEPS // 10)
        self.setSingleStep(STEPS // 100)
        self.setTickPosition(QSlider.TickPosition.TicksBelow)
        self.setTickInterval(STEPS // 2 if symmetric else STEPS // 4)
        self.setMinimumWidth(160)
        self.setFocusPolicy(Qt.FocusPolicy.NoFocus)
        self.valueChanged.connect(self._on_value_changed)

    def set_limit(self, limit: float) -> None:
        """Change the value at the slider's end; the shown value is kept (clipped)."""
        self.limit = limit
        self.show_value(self._value)

    def show_value(self, value: float) -> None:
        """Move the handle to a value without reporting it as an operator move."""
        self._value = value
        steps = round(value / self.limit * STEPS) if self.limit > 0 else 0
        self.blockSignals(True)
        try:
            self.setValue(steps)
        finally:
            self.blockSignals(False)

    def current(self) -> float:
        """The value the handle shows."""
        return self._value

    def wheelEvent(self, event: QWheelEvent) -> None:
        """Ignore the wheel (pass it to the parent for scrolling)."""
        event.ignore()

    def _on_value_changed(self, steps: int) -> None:
        self._value = steps / STEPS * self.limit
        self.value_moved.emit(self._value)

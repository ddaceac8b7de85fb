"""A text box for one number in SI units: locale-proof, finite, in range, says why it refused."""

from __future__ import annotations

import math
import re

from PySide6.QtCore import Qt
from PySide6.QtWidgets import QLineEdit, QWidget

# One optional sign, digits with at most one decimal mark ("." or ","), optional exponent.
_NUMBER = re.compile(r"[+-]?(\d+([.,]\d*)?|[.,]\d+)([eE][+-]?\d+)?")
_MINUS_SIGNS = str.maketrans({"\u2212": "-", "\u2013": "-"})

ERROR_STYLE = "QLineEdit { border: 2px solid #c62828; background: #ffebee; }"


class NumberError(ValueError):
    """The text is not a finite number within the allowed range."""


def format_number(value: float, decimals: int) -> str:
    """A value as shown in a box (no '-0.000')."""
    text = f"{value:.{decimals}f}"
    return text[1:] if text.startswith("-") and float(text) == 0.0 else text


def parse_number(text: str, low: float, high: float, unit: str = "") -> float:
    """'0,5' or '0.5' into 0.5; NumberError with the reason for anything else."""
    cleaned = text.strip().translate(_MINUS_SIGNS)
    unit_text = f" {unit}" if unit else ""
    if not cleaned:
        raise NumberError("empty: type a number")
    if not _NUMBER.fullmatch(cleaned):
        raise NumberError(f"{text.strip()!r} is not a number (use digits, one . or ,)")
    value = float(cleaned.replace(",", "."))
    if not math.isfinite(value):
        raise NumberError(f"{text.strip()!r} is too large")
    if not low <= value <= high:
        raise NumberError(f"{value:g} is outside [{low:g}, {high:g}]{unit_text}")
    return value


class NumberBox(QLineEdit):
    """A QLineEdit for one value; the caller reads it with `value()` only on Accept/Enter."""

    def __init__(
        self,
        low: float,
        high: float,
        unit: str = "",
        decimals: int = 3,
        parent: QWidget | None = None,
    ) -> None:
        super().__init__(parent)
        self.low = low
        self.high = high
        self.unit = unit
        self.decimals = decimals
        self.error = ""
        self.setAlignment(Qt.AlignmentFlag.AlignRight | Qt.AlignmentFlag.AlignVCenter)
        self.setMaxLength(24)
        self.textEdited.connect(self._on_edited)
        self._update_tooltip()

    def set_range(self, low: float, high: float) -> None:
        """Change the accepted range."""
        self.low, self.high = low, high
        self._update_tooltip()

    def show_value(self, value: float) -> None:
        """Show a value from the model unless the operator is typing in this box."""
        if self.isModified() and self.hasFocus():
            return
        self.reset_value(value)

    def reset_value(self, value: float) -> None:
        """Show a value and drop whatever was typed (e-stop)."""
        self.setText(format_number(value, self.decimals))
        self.setModified(False)
        self.set_error("")

    def value(self) -> float:
        """The typed value; NumberError (also shown on the box) if it is not acceptable."""
        try:
            number = parse_number(self.text(), self.low, self.high, self.unit)
        except NumberError as err:
            self.set_error(str(err))
            raise
        self.set_error("")
        return number

    def set_error(self, message: str) -> None:
        """Mark the box as refused with a reason, or clear the mark."""
        self.error = message
        self.setStyleSheet(ERROR_STYLE if message else "")
        self._update_tooltip()

    def _on_edited(self, _text: str) -> None:
        if self.error:
            self.set_error("")

    def _update_tooltip(self) -> None:
        unit = f" {self.unit}" if self.unit else ""
        hint = f"a number in [{self.low:g}, {self.high:g}]{unit}; '.' or ',' as decimal mark"
        self.setToolTip(f"{self.error}\n{hint}" if self.error else hint)

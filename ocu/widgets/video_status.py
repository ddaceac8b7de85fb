"""What the vendor protocol cannot report: battery gauge, headlight state, roll and pitch.

Each widget shows a value only when an extended robot reported it and "not reported"
otherwise; none ever shows a made-up value. Feed them with `show_status(StatusFrame | None)`
(None: no extension, or the robot did not measure it).
"""

from __future__ import annotations

import math

from PySide6.QtCore import QPointF, QRectF, QSize, Qt
from PySide6.QtGui import QColor, QFont, QFontMetrics, QPainter, QPaintEvent, QPen, QPolygonF
from PySide6.QtWidgets import QLabel, QSizePolicy, QWidget

from ocu.records import StatusFrame

NOT_REPORTED = "not reported"
GOOD_COLOUR = QColor(40, 160, 70)
LOW_COLOUR = QColor(210, 40, 40)
UNKNOWN_COLOUR = QColor(140, 140, 140)
SKY_COLOUR = QColor(70, 130, 200)
GROUND_COLOUR = QColor(150, 100, 50)
ICON_WIDTH_PX = 40


class BatteryGauge(QWidget):
    """A battery icon filled to the charge, with percent and voltage; red and LOW when low."""

    def __init__(self, warning_percent: float = 20.0, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.setObjectName("battery_gauge")
        self.warning_percent = warning_percent
        self.charge_percent: float | None = None
        self.voltage_v: float | None = None
        bold = QFont(self.font())
        bold.setBold(True)
        widest = QFontMetrics(bold).horizontalAdvance("LOW Battery 100 % · 25.2 V")
        self.setMinimumSize(QSize(ICON_WIDTH_PX + widest + 12, 26))
        self.setSizePolicy(QSizePolicy.Policy.Preferred, QSizePolicy.Policy.Fixed)
        self._update_tooltip()

    @property
    def is_low(self) -> bool:
        """Whether a reported charge is at or below the warning threshold."""
        return self.charge_percent is not None and self.charge_percent <= self.warning_percent

    def set_warning_percent(self, percent: float) -> None:
        """Change the low-charge threshold."""
        self.warning_percent = percent
        self._update_tooltip()
        self.update()

    def show_status(self, status: StatusFrame | None) -> None:
        """Show a status packet's battery fields; None = not reported."""
        self.charge_percent = None if status is None else status.charge_percent
        self.voltage_v = None if status is None else status.voltage_v
        self._update_tooltip()
        self.update()

    def text(self) -> str:
        """What the gauge says in words."""
        if self.charge_percent is None and self.voltage_v is None:
            return f"Battery {NOT_REPORTED}"
        parts = []
        if self.charge_percent is not None:
            parts.append(f"{self.charge_percent:.0f} %")
        if self.voltage_v is not None:
            parts.append(f"{self.voltage_v:.1f} V")
        prefix = "LOW " if self.is_low else ""
        return f"{prefix}Battery {' · '.join(parts)}"

    def _update_tooltip(self) -> None:
        self.setToolTip(f"{self.text()} (warning at {self.warning_percent:.0f} %)")

    def paintEvent(self, event: QPaintEvent) -> None:
        painter = QPainter(self)
        painter.setRenderHint(QPainter.RenderHint.Antialiasing)
        height = self.height()
        body = QRectF(1, 3, 34, height - 6)
        tip = QRectF(body.right(), height / 2 - 4, 3, 8)
        colour = UNKNOWN_COLOUR
        if self.charge_percent is not None:
            colour = LOW_COLOUR if self.is_low else GOOD_COLOUR
        painter.setPen(QPen(self.palette().windowText().color(), 1.5))
        painter.setBrush(Qt.BrushStyle.NoBrush)
        painter.drawRoundedRect(body, 3, 3)
        painter.fillRect(tip, self.palette().windowText().color())
        if self.charge_percent is not None:
            fill = body.adjusted(2, 2, -2, -2)
            fill.setWidth(fill.width() * min(max(self.charge_percent, 0.0), 100.0) / 100.0)
            painter.fillRect(fill, colour)
        font = QFont(self.font())
        font.setBold(self.is_low)
        painter.setFont(font)
        painter.setPen(colour if self.is_low else self.palette().windowText().color())
        text_rect = QRectF(body.right() + 8, 0, self.width() - body.right() - 8, height)
        painter.drawText(text_rect, Qt.AlignmentFlag.AlignVCenter, self.text())
        painter.end()


class HeadlightIndicator(QLabel):
    """The headlight state the robot reports (not what the OCU asked for)."""

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.setObjectName("headlight_indicator")
        self.headlight_on: bool | None = None
        self.setToolTip("Headlight state reported by the robot (protocol extension)")
        bold = QFont(self.font())
        bold.setBold(True)
        widest = max(
            QFontMetrics(bold).horizontalAdvance("Headlight: ON"),
            self.fontMetrics().horizontalAdvance(f"Headlight: {NOT_REPORTED}"),
        )
        self.setMinimumWidth(widest + 8)  # a fixed width: the text changes, the layout not
        self.show_status(None)

    def show_status(self, status: StatusFrame | None) -> None:
        """Show a status packet's headlight field; None = not reported."""
        self.headlight_on = None if status is None else status.headlight_on
        if self.headlight_on is None:
            self.setText(f"Headlight: {NOT_REPORTED}")
            self.setStyleSheet(f"color: {UNKNOWN_COLOUR.name()};")
        elif self.headlight_on:
            self.setText("Headlight: ON")
            self.setStyleSheet("color: #c08000; font-weight: bold;")
        else:
            self.setText("Headlight: off")
            self.setStyleSheet("")


class AttitudeIndicator(QWidget):
    """A small artificial horizon with roll and pitch in degrees."""

    PITCH_PX_PER_RAD = 40.0

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.setObjectName("attitude_indicator")
        self.roll_rad: float | None = None
        self.pitch_rad: float | None = None
        self.setMinimumSize(QSize(190, 44))
        self.setSizePolicy(QSizePolicy.Policy.Preferred, QSizePolicy.Policy.Fixed)

    def show_status(self, status: StatusFrame | None) -> None:
        """Show a status packet's roll and pitch; None = not reported."""
        self.roll_rad = None if status is None else status.roll_rad
        self.pitch_rad = None if status is None else status.pitch_rad
        self.setToolTip(self.text())
        self.update()

    def text(self) -> str:
        """Roll and pitch in words."""
        if self.roll_rad is None or self.pitch_rad is None:
            return f"Roll/pitch {NOT_REPORTED}"
        return (
            f"Roll {math.degrees(self.roll_rad):+.1f}°\nPitch {math.degrees(self.pitch_rad):+.1f}°"
        )

    def paintEvent(self, event: QPaintEvent) -> None:
        painter = QPainter(self)
        painter.setRenderHint(QPainter.RenderHint.Antialiasing)
        side = self.height() - 4
        dial = QRectF(2, 2, side, side)
        centre = dial.center()
        painter.setPen(QPen(self.palette().windowText().color(), 1.2))
        if self.roll_rad is None or self.pitch_rad is None:
            painter.setBrush(UNKNOWN_COLOUR)
            painter.drawEllipse(dial)
        else:
            painter.save()
            painter.setClipRegion(self.visibleRegion().intersected(dial.toAlignedRect()))
            painter.translate(centre)
            painter.rotate(-math.degrees(self.roll_rad))
            # Nose down (positive pitch, REP 103) shows more ground: the horizon moves up.
            offset = -self.pitch_rad * self.PITCH_PX_PER_RAD
            painter.fillRect(QRectF(-side, -side + offset, 2 * side, side), SKY_COLOUR)
            painter.fillRect(QRectF(-side, offset, 2 * side, side), GROUND_COLOUR)
            painter.restore()
            painter.setBrush(Qt.BrushStyle.NoBrush)
            painter.drawEllipse(dial)
            # The robot's fixed reference mark.
            painter.setPen(QPen(QColor(255, 220, 0), 2))
            wing = side * 0.3
            painter.drawLine(
                QPointF(centre.x() - wing, centre.y()), QPointF(centre.x() - 3, centre.y())
            )
            painter.drawLine(
                QPointF(centre.x() + 3, centre.y()), QPointF(centre.x() + wing, centre.y())
            )
            painter.drawPolygon(
                QPolygonF(
                    [centre + QPointF(0, -2), centre + QPointF(2, 1), centre + QPointF(-2, 1)]
                )
            )
        painter.setPen(self.palette().windowText().color())
        text_rect = QRectF(dial.right() + 8, 0, self.width() - dial.right() - 8, self.height())
        painter.drawText(text_rect, Qt.AlignmentFlag.AlignVCenter, self.text())
        painter.end()

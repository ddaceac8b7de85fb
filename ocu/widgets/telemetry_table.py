"""A table with the latest telemetry of every motor, in SI units next to the raw values."""

from __future__ import annotations

import math

from PySide6.QtGui import QBrush, QColor
from PySide6.QtWidgets import QHeaderView, QTableWidget, QTableWidgetItem, QWidget

from ocu.profile import RobotProfile
from ocu.records import TelemetryFrame

COLUMNS = (
    "id",
    "joint",
    "state",
    "mode",
    "angle °",
    "speed",
    "current A",
    "status",
    "target °",
    "speed cmd",
    "cur cmd A",
)


FAULT_BACKGROUND = QColor("#ffcdd2")
FAULT_MARK = "⚠ "


def _deg(angle_rad: float | None) -> str:
    return "—" if angle_rad is None else f"{math.degrees(angle_rad):.2f}"


class TelemetryTable(QTableWidget):
    """One row per motor record of the telemetry frame: the profile's motors, more if sent."""

    def __init__(self, profile: RobotProfile, parent: QWidget | None = None) -> None:
        super().__init__(0, len(COLUMNS), parent)
        self.profile = profile
        self.setObjectName("telemetry_table")
        self.setHorizontalHeaderLabels(list(COLUMNS))
        self.horizontalHeader().setSectionResizeMode(QHeaderView.ResizeMode.ResizeToContents)
        self.verticalHeader().setVisible(False)
        self.verticalHeader().setDefaultSectionSize(22)
        self.setEditTriggers(QTableWidget.EditTrigger.NoEditTriggers)
        self._grow(len(profile.motors))

    def _grow(self, rows: int) -> None:
        """At least `rows` rows (a frame may carry devices the profile does not know)."""
        for row in range(self.rowCount(), rows):
            self.insertRow(row)
            for column in range(len(COLUMNS)):
                self.setItem(row, column, QTableWidgetItem("—"))

    def cell_text(self, row: int, column: str) -> str:
        """Text shown in one cell (for tests and screenshots)."""
        item = self.item(row, COLUMNS.index(column))
        return item.text() if item is not None else ""

    def show_frame(self, frame: TelemetryFrame) -> None:
        """Fill the rows from one telemetry packet.

        The model's signals are held while the cells change and one dataChanged follows: each
        cell's own signal made the contents-sized header measure every section again (110
        times a frame, most of the GUI thread's telemetry cost).
        """
        self._grow(len(frame.packet.motors))  # before the signals are held: the view must see it
        model = self.model()
        was_blocked = model.blockSignals(True)
        changed = False
        try:
            changed = self._fill(frame)
        finally:
            model.blockSignals(was_blocked)
        if changed:
            model.dataChanged.emit(
                model.index(0, 0), model.index(model.rowCount() - 1, model.columnCount() - 1)
            )

    def _fill(self, frame: TelemetryFrame) -> bool:
        changed = False
        for row in range(self.rowCount()):
            values = ["—"] * len(COLUMNS)
            fault: str | None = None
            if row < len(frame.packet.motors):
                record = frame.packet.motors[row]
                motor = self.profile.motor_by_device(record.device_id)
                reading = frame.readings.get(motor.name) if motor else None
                values[0] = str(record.device_id)
                values[1] = motor.name if motor else "(unknown)"
                values[2] = str(record.state)
                values[3] = str(record.mode)
                values[7] = f"0x{record.status & 0xFFFF:04x}"
                if reading is not None:
                    fault = reading.fault
                    values[4] = (FAULT_MARK if fault else "") + _deg(reading.angle_rad)
                    values[5] = f"{reading.speed_rad_s:+.3f}"
                    values[6] = f"{reading.current_a:.2f}"
                    values[8] = _deg(reading.target_angle_rad)
                    values[9] = f"{reading.speed_command_rad_s:+.3f}"
                    values[10] = f"{reading.current_command_a:.2f}"
            for column, text in enumerate(values):
                item = self.item(row, column)
                if item is not None and item.text() != text:
                    item.setText(text)
                    changed = True
            angle = self.item(row, COLUMNS.index("angle °"))
            if angle is not None and angle.toolTip() != (fault or ""):
                # Implausible: the reading is shown, marked, and says why it is not believed.
                angle.setToolTip(f"implausible: {fault}" if fault else "")
                angle.setBackground(QBrush(FAULT_BACKGROUND) if fault else QBrush())
                changed = True
        return changed

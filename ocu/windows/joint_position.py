"""Joint-position window: target angles with Accept, every motor's telemetry and live plots."""

from __future__ import annotations

import math

from PySide6.QtCore import Qt
from PySide6.QtWidgets import (
    QGridLayout,
    QHBoxLayout,
    QLabel,
    QPushButton,
    QSplitter,
    QVBoxLayout,
    QWidget,
)

from ocu.console.model import ConsoleModel
from ocu.control.position import PositionError
from ocu.profile import Motor
from ocu.records import TelemetryFrame
from ocu.widgets.number_box import NumberBox, NumberError, format_number
from ocu.widgets.telemetry_plots import TelemetryPlots
from ocu.widgets.telemetry_table import TelemetryTable
from ocu.windows.velocity import ERROR_TEXT_STYLE, channel_title

CONTROLLED_STYLE = "color: #1565c0; font-weight: bold;"
IMPLAUSIBLE_STYLE = "color: white; background: #c62828; font-weight: bold; padding: 0 3px;"


def limits_deg(motor: Motor) -> tuple[float, float]:
    """A joint's limits in degrees as the profile writes them (what the operator types)."""
    if motor.limits_deg is not None:
        return motor.limits_deg
    assert motor.limits_rad is not None, f"{motor.name} has no position limits"
    low, high = motor.limits_rad
    return math.degrees(low), math.degrees(high)


def target_rad(motor: Motor, degrees: float) -> float:
    """A target typed in degrees (checked against `limits_deg`) in radians within limits_rad.

    The comparison is made in the unit typed: radians(120) may differ from the profile's
    limit in radians in the last bit, and the controller checks radians.
    """
    assert motor.limits_rad is not None, f"{motor.name} has no position limits"
    low, high = motor.limits_rad
    return min(max(math.radians(degrees), low), high)


class JointPositionPanel(QWidget):
    """Targets for the joints with position feedback; telemetry table and plots below."""

    def __init__(self, model: ConsoleModel, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.setObjectName("joint_position_panel")
        self.model = model
        self.joints = [m.name for m in model.profile.positioned_motors]
        self.boxes: dict[str, NumberBox] = {}
        self.angle_labels: dict[str, QLabel] = {}
        self.status_labels: dict[str, QLabel] = {}

        targets = QWidget()
        grid = QGridLayout(targets)
        grid.setContentsMargins(0, 0, 0, 0)
        columns = ("joint", "angle °", "target °", "limits °", "control")
        for column, heading in enumerate(columns):
            header = QLabel(heading)
            header.setStyleSheet("color: #666;")
            grid.addWidget(header, 0, column)
        for row, name in enumerate(self.joints, start=1):
            low, high = limits_deg(model.profile.motors[name])
            title = QLabel(channel_title(name))
            title.setStyleSheet("font-weight: bold;")
            angle = QLabel("—")
            angle.setObjectName(f"angle_{name}")
            angle.setAlignment(Qt.AlignmentFlag.AlignRight | Qt.AlignmentFlag.AlignVCenter)
            angle.setMinimumWidth(64)
            box = NumberBox(low, high, "°", decimals=1)
            box.setObjectName(f"target_box_{name}")
            box.setFixedWidth(72)
            box.setPlaceholderText("—")
            box.returnPressed.connect(self.accept)
            limits = QLabel(f"{low:g} … {high:g}")
            status = QLabel("")
            status.setObjectName(f"target_status_{name}")
            status.setMinimumWidth(90)
            grid.addWidget(title, row, 0)
            grid.addWidget(angle, row, 1)
            grid.addWidget(box, row, 2)
            grid.addWidget(limits, row, 3)
            grid.addWidget(status, row, 4)
            self.boxes[name] = box
            self.angle_labels[name] = angle
            self.status_labels[name] = status
        grid.setColumnStretch(5, 1)
        buttons = QHBoxLayout()
        self.accept_button = QPushButton("Accept")
        self.accept_button.setObjectName("position_accept")
        self.accept_button.setToolTip("Move every joint with a typed target at once (Enter)")
        self.accept_button.clicked.connect(self.accept)
        self.cancel_button = QPushButton("Cancel targets")
        self.cancel_button.setObjectName("position_cancel")
        self.cancel_button.clicked.connect(lambda: model.cancel_targets(None))
        self.message_label = QLabel(
            "Type target angles, then Accept; any manual command on a joint takes it back."
        )
        self.message_label.setObjectName("position_message")
        self.message_label.setWordWrap(True)
        buttons.addWidget(self.accept_button)
        buttons.addWidget(self.cancel_button)
        buttons.addWidget(self.message_label, 1)
        top = QWidget()
        top.setObjectName("position_targets")
        self.targets_panel = top  # the command part (a replay disables it)
        top_layout = QVBoxLayout(top)
        top_layout.setContentsMargins(0, 0, 0, 0)
        top_layout.addWidget(targets)
        top_layout.addLayout(buttons)

        self.table = TelemetryTable(model.profile)
        self.plots = TelemetryPlots(model.robot)
        left = QSplitter(Qt.Orientation.Vertical)
        left.addWidget(top)
        left.addWidget(self.table)
        left.setStretchFactor(0, 0)
        left.setStretchFactor(1, 1)
        self.splitter = QSplitter(Qt.Orientation.Horizontal)
        self.splitter.setObjectName("joint_position_splitter")
        self.splitter.addWidget(left)
        self.splitter.addWidget(self.plots)
        self.splitter.setStretchFactor(0, 3)
        self.splitter.setStretchFactor(1, 2)
        self.splitter.setSizes([640, 400])
        layout = QVBoxLayout(self)
        layout.setContentsMargins(4, 4, 4, 4)
        layout.addWidget(self.splitter)

        model.events.targets_changed.connect(self._on_targets)
        model.robot.events.telemetry_changed.connect(self.on_telemetry)
        # Every e-stop, latched already or not (estop_changed fires only on a change).
        model.events.estop_requested.connect(self._on_estop)
        model.events.position_message.connect(self.show_message)

    # ---- operator -> model -----------------------------------------------------------------

    def accept(self) -> None:
        """Send every typed target to the position controller at once; all or nothing."""
        targets: dict[str, float] = {}
        errors: list[str] = []
        for name, box in self.boxes.items():
            if not box.isModified() or not box.text().strip():
                continue
            try:
                targets[name] = target_rad(self.model.profile.motors[name], box.value())
            except NumberError as err:
                errors.append(f"{channel_title(name)}: {err}")
        if not errors and not targets:
            errors.append("no target typed")
        if not errors:
            try:
                self.model.set_targets(targets)
            except PositionError as err:
                errors.append(str(err))
        if errors:
            self.message_label.setText("Not applied — " + "; ".join(errors))
            self.message_label.setStyleSheet(ERROR_TEXT_STYLE)
            return
        for name in targets:
            self.boxes[name].setModified(False)
        self.message_label.setStyleSheet("")
        self.message_label.setText(
            "Moving " + ", ".join(f"{n} → {math.degrees(v):.1f}°" for n, v in targets.items())
        )

    # ---- robot / model -> view -------------------------------------------------------------

    def on_telemetry(self, frame: TelemetryFrame) -> None:
        """Show the measured angles (implausible ones marked), fill the table and the plots."""
        for name, label in self.angle_labels.items():
            reading = frame.readings.get(name)
            if reading is None or reading.angle_rad is None:
                continue
            if reading.fault is not None:
                label.setText("implausible")
                label.setStyleSheet(IMPLAUSIBLE_STYLE)
                label.setToolTip(f"not believed, position control refused: {reading.fault}")
            else:
                label.setText(format_number(math.degrees(reading.angle_rad), 1))
                if label.toolTip():
                    label.setStyleSheet("")
                    label.setToolTip("")
        self.table.show_frame(frame)

    def show_message(self, text: str) -> None:
        """A controller message (reached, stale telemetry, ...)."""
        self.message_label.setStyleSheet("")
        self.message_label.setText(text)

    def _on_targets(self, targets: dict[str, float]) -> None:
        for name, status in self.status_labels.items():
            if name in targets:
                status.setText(f"→ {math.degrees(targets[name]):.1f}°")
                status.setStyleSheet(CONTROLLED_STYLE)
            else:
                status.setText("")
                status.setStyleSheet("")

    def _on_estop(self, _reason: str) -> None:
        for box in self.boxes.values():
            box.clear()
            box.setModified(False)
            box.set_error("")

"""The Gamepad dock and the status-bar pad indicator: views of the GamepadTeleop.

The panel shows the pad live (sticks, triggers, buttons, what each drives and whether it is
armed), the mapping in force, and calibrates each axis's range and centre the way
QGroundControl does: Calibrate, move every stick and trigger to its ends, let go, Save. The
calibration is written atomically to the calibration file (ocu.gamepad.calibration).
"""

from __future__ import annotations

from PySide6.QtCore import QPointF, QRectF, Qt, QTimer
from PySide6.QtGui import QColor, QPainter, QPaintEvent, QPen
from PySide6.QtWidgets import (
    QFrame,
    QGroupBox,
    QHBoxLayout,
    QHeaderView,
    QLabel,
    QPushButton,
    QScrollArea,
    QSizePolicy,
    QTableWidget,
    QTableWidgetItem,
    QVBoxLayout,
    QWidget,
)

from ocu.gamepad.calibration import (
    CalibrationError,
    CalibrationSession,
    CalibrationStore,
    PadCalibration,
)
from ocu.gamepad.pad import AXES, BUTTONS, PadInfo, PadState, control_label
from ocu.gamepad.teleop import GamepadTeleop, PadStatus

REFRESH_MS = 33
INDICATOR_STYLE = "font-weight:bold;font-size:11pt;padding:3px 8px;border-radius:4px;"
STATUS_STYLES = {
    PadStatus.OFF: "background:#9e9e9e;color:white;",
    PadStatus.UNAVAILABLE: "background:#9e9e9e;color:white;",
    PadStatus.NO_PAD: "background:#607d8b;color:white;",
    PadStatus.READY: "background:#1565c0;color:white;",
    PadStatus.ENGAGED: "background:#2e7d32;color:white;",
    PadStatus.INACTIVE: "background:#b8860b;color:white;",
    PadStatus.STALLED: "background:#c62828;color:white;",
    PadStatus.ERROR: "background:#c62828;color:white;",
}
STATUS_TEXT = {
    PadStatus.OFF: "PAD off",
    PadStatus.UNAVAILABLE: "PAD unavailable",
    PadStatus.NO_PAD: "no pad",
    PadStatus.READY: "PAD ready",
    PadStatus.ENGAGED: "PAD ● deadman",
    PadStatus.INACTIVE: "PAD inactive",
    PadStatus.STALLED: "PAD STALLED",
    PadStatus.ERROR: "PAD ERROR",
}
STATUS_HELP = {
    PadStatus.OFF: "gamepad support is off in this console",
    PadStatus.UNAVAILABLE: "SDL could not start",
    PadStatus.NO_PAD: "plug in a game controller",
    PadStatus.READY: "hold the deadman to drive",
    PadStatus.ENGAGED: "the deadman is held: the pad drives",
    PadStatus.INACTIVE: "the console is hidden (or unfocused, by the focus policy)",
    PadStatus.STALLED: "the poll thread stopped: the pad's motion was stopped",
    PadStatus.ERROR: "an SDL call failed: the pad's motion was stopped",
}
ARMED = QColor("#2e7d32")
IDLE = QColor("#78909c")
DISARMED = QColor("#ef6c00")
# The D-pad as arrows on the small button chips.
CHIP_TEXT = {"dpup": "D ▲", "dpdown": "D ▼", "dpleft": "D ◀", "dpright": "D ▶"}
CALIBRATION_HELP = (
    "Move both sticks in full circles and press both triggers all the way, "
    "then let go of everything and press Save."
)


def family_of(info: PadInfo | None) -> str:
    """The pad's family for button labels (an Xbox pad's when none is connected)."""
    return info.family if info is not None else "xbox"


def describe_control(family: str, control: str) -> str:
    """'rightshoulder + rightx' -> 'RB + right stick X' for a pad family."""
    return " + ".join(control_label(family, part) for part in control.split(" + "))


class PadIndicator(QLabel):
    """The pad's state in the status bar: hot-plug, deadman, stalls and errors at a glance."""

    def __init__(self, teleop: GamepadTeleop, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.setObjectName("pad_indicator")
        self.teleop = teleop
        teleop.events.status_changed.connect(self._show)
        self._show(teleop.status, teleop.status_text)

    def _show(self, status: PadStatus, text: str) -> None:
        self.setText(STATUS_TEXT[status])
        self.setStyleSheet(STATUS_STYLES[status] + INDICATOR_STYLE)
        self.setToolTip(f"{text + ': ' if text else ''}{STATUS_HELP[status]}")


class PadView(QWidget):
    """Both sticks, both triggers and the buttons, live; armed axes green."""

    def __init__(self, teleop: GamepadTeleop, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.setObjectName("pad_view")
        self.teleop = teleop
        self.setMinimumSize(360, 200)
        self.setSizePolicy(QSizePolicy.Policy.Expanding, QSizePolicy.Policy.Fixed)

    def paintEvent(self, event: QPaintEvent) -> None:
        """Sticks as circles with a dot, triggers as bars, buttons as chips."""
        painter = QPainter(self)
        painter.setRenderHint(QPainter.RenderHint.Antialiasing)
        radius = 52.0
        sticks = (("leftx", "lefty", 70.0), ("rightx", "righty", 290.0))
        for x_axis, y_axis, centre_x in sticks:
            self._stick(painter, QPointF(centre_x, 62.0), radius, x_axis, y_axis)
        self._trigger(painter, QRectF(150.0, 12.0, 16.0, 100.0), "lefttrigger")
        self._trigger(painter, QRectF(194.0, 12.0, 16.0, 100.0), "righttrigger")
        self._buttons(painter, top=128.0)
        painter.end()

    def _axis_colour(self, axis: str) -> QColor:
        teleop = self.teleop
        if not teleop.engaged or teleop.mapping.binding(axis, teleop.alt) is None:
            return IDLE
        return ARMED if teleop.armed(axis) else DISARMED

    def _stick(
        self, painter: QPainter, centre: QPointF, radius: float, x_axis: str, y_axis: str
    ) -> None:
        teleop = self.teleop
        painter.setPen(QPen(QColor("#455a64"), 1.5))
        painter.setBrush(QColor("#eceff1"))
        painter.drawEllipse(centre, radius, radius)
        deadzone = teleop.mapping.shape(x_axis).deadzone * radius
        painter.setBrush(QColor("#cfd8dc"))
        painter.setPen(Qt.PenStyle.NoPen)
        painter.drawEllipse(centre, deadzone, deadzone)
        state = teleop.state
        x = y = 0.0
        if state is not None:
            x = teleop.calibration.normalise(x_axis, state.axis(x_axis))
            y = teleop.calibration.normalise(y_axis, state.axis(y_axis))
        both_armed = self._axis_colour(x_axis) if x != 0 else self._axis_colour(y_axis)
        painter.setBrush(both_armed)
        painter.drawEllipse(QPointF(centre.x() + x * radius, centre.y() + y * radius), 7.0, 7.0)
        painter.setPen(QColor("#263238"))
        words = []
        for axis in (y_axis, x_axis):
            binding = teleop.mapping.binding(axis, teleop.alt)
            if binding is not None:
                words.append(binding.channel.replace("_", " "))
        painter.drawText(
            QRectF(centre.x() - 80, centre.y() + radius + 2, 160, 16),
            Qt.AlignmentFlag.AlignCenter,
            " / ".join(words),
        )

    def _trigger(self, painter: QPainter, rect: QRectF, axis: str) -> None:
        teleop = self.teleop
        state = teleop.state
        value = teleop.calibration.normalise(axis, state.axis(axis)) if state else 0.0
        painter.setPen(QPen(QColor("#455a64"), 1.0))
        painter.setBrush(QColor("#eceff1"))
        painter.drawRect(rect)
        filled = QRectF(rect.x(), rect.bottom() - rect.height() * value, rect.width(), 0.0)
        filled.setBottom(rect.bottom())
        painter.setBrush(self._axis_colour(axis))
        painter.drawRect(filled)
        painter.setPen(QColor("#263238"))
        label = control_label(family_of(teleop.info), axis)
        painter.drawText(
            QRectF(rect.x() - 12, rect.bottom() + 2, rect.width() + 24, 14),
            Qt.AlignmentFlag.AlignCenter,
            label,
        )

    def _buttons(self, painter: QPainter, top: float) -> None:
        teleop = self.teleop
        state = teleop.state
        down = state.down if state is not None else frozenset()
        family = family_of(teleop.info)
        shown = BUTTONS[:15]  # the buttons every pad of the database has
        per_row = (len(shown) + 1) // 2
        height, gap = 26.0, 4.0
        width = (self.width() - gap * (per_row + 1)) / per_row
        for index, button in enumerate(shown):
            row, column = divmod(index, per_row)
            rect = QRectF(gap + column * (width + gap), top + row * (height + gap), width, height)
            painter.setPen(QPen(QColor("#455a64"), 1.0))
            painter.setBrush(QColor("#ffb300") if button in down else QColor("#eceff1"))
            painter.drawRoundedRect(rect, 4.0, 4.0)
            painter.setPen(QColor("#263238"))
            text = CHIP_TEXT.get(button) or control_label(family, button)
            painter.drawText(rect, Qt.AlignmentFlag.AlignCenter, text)


class GamepadPanel(QWidget):
    """The Gamepad dock: state, live view, mapping, calibration (a view of the teleop)."""

    def __init__(
        self,
        teleop: GamepadTeleop,
        store: CalibrationStore | None,
        parent: QWidget | None = None,
    ) -> None:
        super().__init__(parent)
        self.setObjectName("gamepad_panel")
        self.teleop = teleop
        self.store = store
        self.session: CalibrationSession | None = None
        # Everything scrolls: the dock shares its area with others and may be short.
        outer = QVBoxLayout(self)
        outer.setContentsMargins(0, 0, 0, 0)
        scroll = QScrollArea()
        scroll.setWidgetResizable(True)
        scroll.setFrameShape(QFrame.Shape.NoFrame)
        scroll.setFocusPolicy(Qt.FocusPolicy.NoFocus)
        content = QWidget()
        scroll.setWidget(content)
        outer.addWidget(scroll)
        layout = QVBoxLayout(content)
        self.status_label = QLabel()
        self.status_label.setObjectName("pad_status")
        self.status_label.setWordWrap(True)
        layout.addWidget(self.status_label)
        self.view = PadView(teleop)
        layout.addWidget(self.view)

        mapping_box = QGroupBox("Mapping")
        mapping_layout = QVBoxLayout(mapping_box)
        self.mapping_table = QTableWidget(0, 2)
        self.mapping_table.setObjectName("pad_mapping")
        self.mapping_table.setHorizontalHeaderLabels(["control", "does"])
        self.mapping_table.verticalHeader().setVisible(False)
        self.mapping_table.horizontalHeader().setSectionResizeMode(
            1, QHeaderView.ResizeMode.Stretch
        )
        self.mapping_table.setFocusPolicy(Qt.FocusPolicy.NoFocus)
        self.mapping_table.setEditTriggers(QTableWidget.EditTrigger.NoEditTriggers)
        sources = QLabel("from " + " + ".join(teleop.mapping.sources))
        sources.setWordWrap(True)
        sources.setStyleSheet("color:#666;")
        mapping_layout.addWidget(self.mapping_table)
        mapping_layout.addWidget(sources)
        self.mapping_table.setMinimumHeight(160)
        layout.addWidget(mapping_box, 1)

        calibration_box = QGroupBox("Calibration (range and centre of each axis)")
        calibration_layout = QVBoxLayout(calibration_box)
        self.calibration_table = QTableWidget(len(AXES), 6)
        self.calibration_table.setObjectName("pad_calibration")
        self.calibration_table.setHorizontalHeaderLabels(
            ["axis", "raw", "min", "centre", "max", "output"]
        )
        self.calibration_table.verticalHeader().setVisible(False)
        self.calibration_table.setFocusPolicy(Qt.FocusPolicy.NoFocus)
        self.calibration_table.setEditTriggers(QTableWidget.EditTrigger.NoEditTriggers)
        self.calibration_table.horizontalHeader().setSectionResizeMode(
            QHeaderView.ResizeMode.Stretch
        )
        for row, axis in enumerate(AXES):
            for column in range(6):
                self.calibration_table.setItem(row, column, QTableWidgetItem(""))
            self._cell(row, 0, axis)
        self.calibration_table.setMinimumHeight(
            self.calibration_table.horizontalHeader().height()
            + 6
            + self.calibration_table.verticalHeader().defaultSectionSize() * len(AXES)
        )
        calibration_layout.addWidget(self.calibration_table)
        buttons = QHBoxLayout()
        self.calibrate_button = QPushButton("Calibrate…")
        self.calibrate_button.setObjectName("pad_calibrate")
        self.save_button = QPushButton("Save")
        self.save_button.setObjectName("pad_calibration_save")
        self.cancel_button = QPushButton("Cancel")
        self.reset_button = QPushButton("Reset to SDL's ranges")
        self.reset_button.setObjectName("pad_calibration_reset")
        for button in (
            self.calibrate_button,
            self.save_button,
            self.cancel_button,
            self.reset_button,
        ):
            button.setFocusPolicy(Qt.FocusPolicy.NoFocus)
            buttons.addWidget(button)
        buttons.addStretch(1)
        calibration_layout.addLayout(buttons)
        self.calibration_message = QLabel("")
        self.calibration_message.setObjectName("pad_calibration_message")
        self.calibration_message.setWordWrap(True)
        calibration_layout.addWidget(self.calibration_message)
        layout.addWidget(calibration_box)
        self.calibrate_button.clicked.connect(self.start_calibration)
        self.save_button.clicked.connect(self.save_calibration)
        self.cancel_button.clicked.connect(self.cancel_calibration)
        self.reset_button.clicked.connect(self.reset_calibration)

        teleop.events.status_changed.connect(lambda _status, _text: self._show_status())
        teleop.events.pad_changed.connect(self._on_pad)
        # Each state as it was taken (the event may reach this thread after newer ones came).
        teleop.events.state_changed.connect(self._feed)
        self._fill_mapping()
        self._show_status()
        self._update_buttons()
        self._timer = QTimer(self)
        self._timer.setInterval(REFRESH_MS)
        self._timer.timeout.connect(self.refresh)
        self._timer.start()

    # ---- calibration -----------------------------------------------------------------------

    def start_calibration(self) -> None:
        """Begin learning the ranges: the pad must be connected."""
        if self.teleop.info is None:
            self.calibration_message.setText("Plug in a pad first.")
            return
        self.session = CalibrationSession()
        self._feed()
        self.calibration_message.setText(CALIBRATION_HELP)
        self._update_buttons()

    def save_calibration(self) -> None:
        """Centres read now, at rest; refused with the reason if an axis was not moved."""
        info, state, session = self.teleop.info, self.teleop.state, self.session
        if session is None or info is None or state is None:
            return
        self._feed()
        try:
            calibration = session.finish(dict(zip(AXES, state.axes, strict=True)))
        except CalibrationError as err:
            self.calibration_message.setText(f"Not saved: {err}")
            return
        self._store(info, calibration)
        self.session = None
        self._update_buttons()

    def cancel_calibration(self) -> None:
        """Drop what was learnt; the calibration in use stays."""
        self.session = None
        self.calibration_message.setText("Calibration cancelled.")
        self._update_buttons()

    def reset_calibration(self) -> None:
        """Forget this pad's calibration: SDL's own ranges."""
        info = self.teleop.info
        if info is None:
            return
        self.session = None
        self._store(info, None)
        self._update_buttons()

    def _store(self, info: PadInfo, calibration: PadCalibration | None) -> None:
        if self.store is not None:
            try:
                self.store.save(info.guid, info.name, calibration)
            except (OSError, CalibrationError) as err:
                self.calibration_message.setText(f"Not saved: {err}")
                return
        self.teleop.set_calibration(calibration or PadCalibration())
        where = f" to {self.store.path}" if self.store is not None else " (this session only)"
        what = "Calibration saved" if calibration is not None else "Calibration reset"
        self.calibration_message.setText(f"{what}{where}.")

    def _feed(self, state: PadState | None = None) -> None:
        if state is None:
            state = self.teleop.state
        if self.session is not None and state is not None:
            self.session.feed(dict(zip(AXES, state.axes, strict=True)))

    def _update_buttons(self) -> None:
        calibrating = self.session is not None
        connected = self.teleop.info is not None
        self.calibrate_button.setEnabled(connected and not calibrating)
        self.save_button.setEnabled(connected and calibrating)
        self.cancel_button.setEnabled(calibrating)
        self.reset_button.setEnabled(connected and not calibrating)

    # ---- views -----------------------------------------------------------------------------

    def _on_pad(self, _info: PadInfo | None) -> None:
        if self.teleop.info is None:
            self.session = None
        self._fill_mapping()
        self._update_buttons()
        self._show_status()

    def help_rows(self) -> list[tuple[str, str]]:
        """The mapping for the help overlay, named as on the pad in use (none: no pad)."""
        if self.teleop.info is None:
            return []
        family = family_of(self.teleop.info)
        return [(describe_control(family, c), does) for c, does in self.teleop.mapping.describe()]

    def _fill_mapping(self) -> None:
        family = family_of(self.teleop.info)
        rows = self.teleop.mapping.describe()
        self.mapping_table.setRowCount(len(rows))
        for row, (control, does) in enumerate(rows):
            self.mapping_table.setItem(row, 0, QTableWidgetItem(describe_control(family, control)))
            self.mapping_table.setItem(row, 1, QTableWidgetItem(does))

    def _show_status(self) -> None:
        teleop = self.teleop
        status = teleop.status
        name = teleop.info.name if teleop.info is not None else ""
        text = STATUS_TEXT[status] if status is not PadStatus.NO_PAD else "No pad"
        detail = teleop.status_text if status in (PadStatus.ERROR, PadStatus.UNAVAILABLE) else ""
        parts = [f"<b>{text}</b>", name, STATUS_HELP[status], detail]
        mapping = teleop.mapping
        if mapping.deadman is None:
            parts.append("no deadman configured")
        if mapping.background:
            parts.append("works in the background while the deadman is held")
        self.status_label.setText(" · ".join(p for p in parts if p))
        self.status_label.setStyleSheet(f"padding:4px;{STATUS_STYLES[status]}")

    def _cell(self, row: int, column: int, text: str) -> None:
        item = self.calibration_table.item(row, column)
        if item is not None and item.text() != text:
            item.setText(text)

    def refresh(self) -> None:
        """Live values (about 30 Hz, only while the dock is shown)."""
        if not self.isVisible():
            return
        self.view.update()
        teleop = self.teleop
        state = teleop.state
        for row, axis in enumerate(AXES):
            calibration = teleop.calibration.axis(axis)
            low, high = calibration.minimum, calibration.maximum
            if self.session is not None and axis in self.session.low:
                low, high = self.session.low[axis], self.session.high[axis]
            self._cell(row, 1, str(state.axis(axis)) if state is not None else "—")
            self._cell(row, 2, str(low))
            self._cell(row, 3, str(calibration.centre))
            self._cell(row, 4, str(high))
            self._cell(row, 5, f"{teleop.value(axis):+.2f}")

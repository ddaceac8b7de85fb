"""Velocity window: a slider and a text box per channel, switches, torch, connect, StopAll.

Beside the Torch checkbox (what the operator asks for) the headlight indicator shows what
the robot reports; the console feeds it from the video panel's status (protocol extension).
"""

from __future__ import annotations

from PySide6.QtCore import Qt
from PySide6.QtWidgets import (
    QButtonGroup,
    QCheckBox,
    QGridLayout,
    QGroupBox,
    QHBoxLayout,
    QLabel,
    QPushButton,
    QSizePolicy,
    QVBoxLayout,
    QWidget,
)

from ocu import hotkeys
from ocu.console.model import ChannelCommand, ConsoleModel, Source
from ocu.widgets.number_box import NumberBox, NumberError, format_number
from ocu.widgets.value_slider import ValueSlider
from ocu.widgets.video_status import HeadlightIndicator

# Arrows beside the words of a switch whose directions are up and down.
ARROWS = {"up": "▲ up", "down": "▼ down"}
SOURCE_TEXT = {
    Source.NONE: "",
    Source.SLIDER: "slider",
    Source.TEXT: "typed",
    Source.HOTKEY: "key",
    Source.SWITCH: "switch",
    Source.POSITION: "position",
    Source.ROS: "ROS",
    Source.ARM: "arm",
    Source.GAMEPAD: "pad",
    Source.ASSIST: "assist",
    Source.TRACK: "track",
}
STOP_ALL_STYLE = (
    "QPushButton { background: #c62828; color: white; font-size: 16pt; font-weight: bold;"
    " padding: 8px 18px; border-radius: 6px; }"
    "QPushButton:pressed { background: #8e0000; }"
    "QPushButton:disabled { background: #bdbdbd; color: #eeeeee; }"
)
ERROR_TEXT_STYLE = "color: #c62828; font-weight: bold;"


def channel_title(name: str) -> str:
    """'drive_linear' -> 'Drive linear'."""
    return name.replace("_", " ").capitalize()


class VelocityPanel(QWidget):
    """Writes the operator's velocity input to the model; shows the model's commands."""

    def __init__(
        self, model: ConsoleModel, parent: QWidget | None = None, *, torch: bool = True
    ) -> None:
        super().__init__(parent)
        self.setObjectName("velocity_panel")
        # The panel itself takes the keyboard first (it is first in the focus chain), so the
        # console starts with the hotkeys live: not in a text box, where W would type, nor on
        # a slider, where Home would move the robot. Clicking its background returns there.
        self.setFocusPolicy(Qt.FocusPolicy.StrongFocus)
        self.model = model
        self.sliders: dict[str, ValueSlider] = {}
        self.boxes: dict[str, NumberBox] = {}
        self.source_labels: dict[str, QLabel] = {}
        self.limit_labels: dict[str, QLabel] = {}
        self.switch_buttons: dict[str, dict[int, QPushButton]] = {}

        layout = QVBoxLayout(self)
        grid = QGridLayout()
        grid.setHorizontalSpacing(8)
        grid.setColumnStretch(1, 1)
        for column, heading in enumerate(("channel", "velocity", "value", "unit", "by")):
            header = QLabel(heading)
            header.setStyleSheet("color: #666;")
            grid.addWidget(header, 0, column)
        for row, (name, channel) in enumerate(model.profile.channels.items(), start=1):
            limit = model.max_velocity(name)
            title = QLabel(channel_title(name))
            title.setStyleSheet("font-weight: bold;")
            slider = ValueSlider(limit)
            slider.setObjectName(f"velocity_slider_{name}")
            slider.value_moved.connect(lambda v, n=name: self._on_slider(n, v))
            box = NumberBox(-limit, limit, channel.unit)
            box.setObjectName(f"velocity_box_{name}")
            box.setFixedWidth(80)
            box.reset_value(0.0)
            box.returnPressed.connect(self.accept)
            unit = QLabel()
            source = QLabel()
            source.setMinimumWidth(56)
            source.setStyleSheet("color: #1565c0;")
            grid.addWidget(title, row, 0)
            grid.addWidget(slider, row, 1)
            grid.addWidget(box, row, 2)
            grid.addWidget(unit, row, 3)
            grid.addWidget(source, row, 4)
            self.sliders[name] = slider
            self.boxes[name] = box
            self.limit_labels[name] = unit
            self.source_labels[name] = source
            self._show_limit(name, limit)
        layout.addLayout(grid)

        accept_row = QHBoxLayout()
        self.accept_button = QPushButton("Accept")
        self.accept_button.setObjectName("velocity_accept")
        self.accept_button.setToolTip("Apply the typed values together (Enter in a box)")
        self.accept_button.clicked.connect(self.accept)
        self.message_label = QLabel()
        self.message_label.setObjectName("velocity_message")
        self.message_label.setWordWrap(True)
        self.message_label.setSizePolicy(QSizePolicy.Policy.Expanding, QSizePolicy.Policy.Preferred)
        accept_row.addWidget(self.accept_button)
        accept_row.addWidget(self.message_label, 1)
        layout.addLayout(accept_row)

        switches = QGroupBox("Switches")
        switch_layout = QGridLayout(switches)
        for row, (name, words) in enumerate(
            (n, tuple(ARROWS.get(w, w) for w in model.profile.channels[n].directions))
            for n in model.profile.switch_channels
        ):
            switch_layout.addWidget(QLabel(channel_title(name)), row, 0)
            group = QButtonGroup(self)
            group.setExclusive(True)
            buttons: dict[int, QPushButton] = {}
            choices = ((1, words[0]), (0, "■ stop"), (-1, words[1]))
            for column, (direction, text) in enumerate(choices):
                button = QPushButton(text)
                button.setObjectName(f"switch_{name}_{direction:+d}")
                button.setCheckable(True)
                # No keyboard focus: the arrows would click the neighbouring switch.
                button.setFocusPolicy(Qt.FocusPolicy.NoFocus)
                button.clicked.connect(lambda _=False, n=name, d=direction: self._on_switch(n, d))
                group.addButton(button)
                switch_layout.addWidget(button, row, column + 1)
                buttons[direction] = button
            buttons[0].setChecked(True)
            self.switch_buttons[name] = buttons
        if model.profile.switch_channels:  # a robot without switches shows no empty box
            layout.addWidget(switches)

        bottom = QHBoxLayout()
        self.connect_button = QPushButton()
        self.connect_button.setObjectName("connect_button")
        self.connect_button.clicked.connect(lambda: model.set_connected(not model.connected))
        self.torch_box = QCheckBox("Torch")
        self.torch_box.setObjectName("torch_box")
        self.torch_box.toggled.connect(model.set_torch)
        self.headlight = HeadlightIndicator()
        self.stop_button = QPushButton("STOP ALL")
        self.stop_button.setObjectName("stop_all")
        self.stop_button.setToolTip("Emergency stop (Space, from anywhere in the window)")
        self.stop_button.setStyleSheet(STOP_ALL_STYLE)
        self.stop_button.setMinimumHeight(52)
        self.stop_button.clicked.connect(lambda: hotkeys.emergency_stop(model, "StopAll"))
        bottom.addWidget(self.connect_button)
        bottom.addWidget(self.torch_box)
        bottom.addWidget(self.headlight)
        # A robot without a torch (the hardware's capabilities) shows neither.
        for widget in (self.torch_box, self.headlight):
            widget.setVisible(torch)
            widget.setEnabled(torch)
        bottom.addStretch(1)
        bottom.addWidget(self.stop_button)
        layout.addLayout(bottom)
        layout.addStretch(1)

        events = model.events
        events.channel_changed.connect(self._on_channel)
        events.max_changed.connect(self._on_max)
        # Every e-stop, latched already or not: a value typed after the first Space must not
        # survive the second one (estop_changed fires only when the latch changes).
        events.estop_requested.connect(self._on_estop)
        events.torch_changed.connect(self._on_torch)
        events.connection_changed.connect(self._on_connection)
        self._on_connection(model.connected)
        # What the robot reports of its headlight, beside what the operator asks for.
        model.robot.events.status_changed.connect(self.headlight.show_status)
        model.robot.events.extension_changed.connect(
            lambda _active, _reason: self.headlight.show_status(model.robot.status)
        )

    # ---- operator -> model -----------------------------------------------------------------

    def accept(self) -> None:
        """Apply every typed value together; refuse all of them if one is bad."""
        values: dict[str, float] = {}
        errors: list[str] = []
        for name, box in self.boxes.items():
            if not box.isModified():
                continue
            try:
                values[name] = box.value()
            except NumberError as err:
                errors.append(f"{channel_title(name)}: {err}")
        if errors:
            self.show_message("Not applied — " + "; ".join(errors), error=True)
            return
        if not values:
            self.show_message("Nothing typed: type a value, then Accept or Enter.")
            return
        self.model.set_velocities(values, Source.TEXT)
        for name in values:
            self.boxes[name].reset_value(self.model.channel(name).velocity)
        self.show_message(f"Applied {', '.join(channel_title(n) for n in values)}.")

    def show_message(self, text: str, error: bool = False) -> None:
        """A line under the grid: what Accept did or why it refused."""
        self.message_label.setText(text)
        self.message_label.setStyleSheet(ERROR_TEXT_STYLE if error else "")

    def _on_slider(self, name: str, value: float) -> None:
        self.model.set_velocity(name, value, Source.SLIDER)

    def _on_switch(self, name: str, direction: int) -> None:
        self.model.set_switch(name, direction)

    # ---- model -> view ---------------------------------------------------------------------

    def _on_channel(self, name: str, command: ChannelCommand) -> None:
        self.sliders[name].show_value(command.velocity)
        self.boxes[name].show_value(command.velocity)
        moving = command.velocity != 0.0
        self.source_labels[name].setText(SOURCE_TEXT[command.source] if moving else "")
        buttons = self.switch_buttons.get(name)
        if buttons is not None:
            direction = 0
            if command.source is Source.SWITCH and moving:
                direction = 1 if command.velocity > 0 else -1
            buttons[direction].setChecked(True)

    def _on_max(self, name: str, value: float) -> None:
        self.sliders[name].set_limit(value)
        self.boxes[name].set_range(-value, value)
        self._show_limit(name, value)

    def _show_limit(self, name: str, value: float) -> None:
        unit = self.model.profile.channels[name].unit
        self.limit_labels[name].setText(f"{unit}  (±{format_number(value, 2)})")

    def _on_estop(self, _reason: str) -> None:
        # Before the model zeroes the channels: every one is about to be zero.
        for box in self.boxes.values():
            box.reset_value(0.0)
        self.show_message("")

    def _on_torch(self, on: bool) -> None:
        self.torch_box.blockSignals(True)
        self.torch_box.setChecked(on)
        self.torch_box.blockSignals(False)

    def _on_connection(self, connected: bool) -> None:
        self.connect_button.setText("Disconnect" if connected else "Connect")

"""Max-velocity window: per channel the upper limit of its slider and of its hotkey speed."""

from __future__ import annotations

from PySide6.QtWidgets import (
    QGridLayout,
    QHBoxLayout,
    QLabel,
    QPushButton,
    QVBoxLayout,
    QWidget,
)

from ocu.console.model import ConsoleModel
from ocu.widgets.number_box import NumberBox, NumberError, format_number
from ocu.widgets.value_slider import ValueSlider
from ocu.windows.velocity import ERROR_TEXT_STYLE, channel_title


class MaxVelocityPanel(QWidget):
    """Sliders and boxes that set each channel's maximum (never above the hard maximum)."""

    def __init__(self, model: ConsoleModel, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.setObjectName("max_velocity_panel")
        self.model = model
        self.sliders: dict[str, ValueSlider] = {}
        self.boxes: dict[str, NumberBox] = {}
        self.hotkey_boxes: dict[str, NumberBox] = {}

        layout = QVBoxLayout(self)
        grid = QGridLayout()
        grid.setColumnStretch(1, 1)
        for column, heading in enumerate(("channel", "maximum", "max", "hard max", "hotkey speed")):
            header = QLabel(heading)
            header.setStyleSheet("color: #666;")
            grid.addWidget(header, 0, column)
        for row, (name, channel) in enumerate(model.profile.channels.items(), start=1):
            title = QLabel(channel_title(name))
            title.setStyleSheet("font-weight: bold;")
            slider = ValueSlider(channel.hard_max, symmetric=False)
            slider.setObjectName(f"max_slider_{name}")
            slider.show_value(model.max_velocity(name))
            slider.value_moved.connect(lambda v, n=name: self.model.set_max_velocity(n, v))
            box = NumberBox(0.0, channel.hard_max, channel.unit)
            box.setObjectName(f"max_box_{name}")
            box.setFixedWidth(72)
            box.reset_value(model.max_velocity(name))
            box.returnPressed.connect(self.accept)
            hard = QLabel(f"{format_number(channel.hard_max, 2)} {channel.unit}")
            hotkey = NumberBox(0.0, model.max_velocity(name), channel.unit)
            hotkey.setObjectName(f"hotkey_speed_box_{name}")
            hotkey.setFixedWidth(72)
            hotkey.reset_value(model.hotkey_speed(name))
            hotkey.returnPressed.connect(self.accept)
            grid.addWidget(title, row, 0)
            grid.addWidget(slider, row, 1)
            grid.addWidget(box, row, 2)
            grid.addWidget(hard, row, 3)
            grid.addWidget(hotkey, row, 4)
            self.sliders[name] = slider
            self.boxes[name] = box
            self.hotkey_boxes[name] = hotkey
        layout.addLayout(grid)
        row_layout = QHBoxLayout()
        self.accept_button = QPushButton("Accept")
        self.accept_button.setObjectName("max_accept")
        self.accept_button.clicked.connect(self.accept)
        self.message_label = QLabel(
            "Hotkey speed defaults to the maximum; Shift moves at a fraction of it."
        )
        self.message_label.setObjectName("max_message")
        self.message_label.setWordWrap(True)
        row_layout.addWidget(self.accept_button)
        row_layout.addWidget(self.message_label, 1)
        layout.addLayout(row_layout)
        layout.addStretch(1)

        model.events.max_changed.connect(self._on_max)
        model.events.hotkey_speed_changed.connect(self._on_hotkey_speed)
        model.events.estop_requested.connect(self._on_estop)

    def accept(self) -> None:
        """Apply the typed maxima first, then the typed hotkey speeds; all or nothing."""
        maxima: dict[str, float] = {}
        speeds: dict[str, float] = {}
        errors: list[str] = []
        for name in self.model.profile.channels:
            for target, box in ((maxima, self.boxes[name]), (speeds, self.hotkey_boxes[name])):
                if not box.isModified():
                    continue
                try:
                    target[name] = box.value()
                except NumberError as err:
                    errors.append(f"{channel_title(name)}: {err}")
        for name, speed in speeds.items():
            limit = maxima.get(name, self.model.max_velocity(name))
            if speed > limit:
                self.hotkey_boxes[name].set_error(f"above the maximum {limit:g}")
                errors.append(f"{channel_title(name)}: hotkey speed above the maximum {limit:g}")
        if errors:
            self.message_label.setText("Not applied — " + "; ".join(errors))
            self.message_label.setStyleSheet(ERROR_TEXT_STYLE)
            return
        for name, value in maxima.items():
            self.model.set_max_velocity(name, value)
            self.boxes[name].reset_value(self.model.max_velocity(name))
        for name, value in speeds.items():
            # The maximum itself means "follow the maximum", also when it changes later.
            kept = self.model.set_hotkey_speed(
                name, None if value >= self.model.max_velocity(name) else value
            )
            self.hotkey_boxes[name].reset_value(kept)
        self.message_label.setStyleSheet("")
        self.message_label.setText("Applied." if maxima or speeds else "Nothing typed.")

    def _on_max(self, name: str, value: float) -> None:
        self.sliders[name].show_value(value)
        self.boxes[name].show_value(value)
        self.hotkey_boxes[name].set_range(0.0, value)

    def _on_hotkey_speed(self, name: str, value: float) -> None:
        self.hotkey_boxes[name].show_value(value)

    def _on_estop(self, _reason: str) -> None:
        # A stop drops whatever was typed: Enter after it must not apply a half-typed limit.
        for name in self.model.profile.channels:
            self.boxes[name].reset_value(self.model.max_velocity(name))
            self.hotkey_boxes[name].reset_value(self.model.hotkey_speed(name))

"""Status-bar widgets: link state with telemetry age, rates, loss, address and e-stop state."""

from __future__ import annotations

import time

from PySide6.QtCore import QTimer
from PySide6.QtWidgets import QHBoxLayout, QLabel, QWidget

from ocu.link.core import LinkState, TelemetryFrame
from ocu.link.stats import LinkStats

STATE_STYLES = {
    LinkState.CONNECTING: "background:#b8860b;color:white;",
    LinkState.CONNECTED: "background:#2e7d32;color:white;",
    LinkState.LOST: "background:#c62828;color:white;",
    LinkState.CLOSED: "background:#555;color:white;",
}


def _label(name: str, text: str = "") -> QLabel:
    label = QLabel(text)
    label.setObjectName(name)
    return label


class LinkStatus(QWidget):
    """Always-visible link facts for the status bar."""

    def __init__(self, address_text: str, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.state = LinkState.CONNECTING
        self.last_telemetry_at: float | None = None
        layout = QHBoxLayout(self)
        layout.setContentsMargins(0, 0, 0, 0)
        self.state_label = _label("link_state")
        self.rates_label = _label("link_rates")
        self.loss_label = _label("link_loss")
        self.address_label = _label("link_address", address_text)
        self.estop_label = _label("estop_state")
        for label in (
            self.state_label,
            self.rates_label,
            self.loss_label,
            self.address_label,
            self.estop_label,
        ):
            label.setContentsMargins(6, 0, 6, 0)
            layout.addWidget(label)
        self.set_estop(False)
        self.rates_label.setText("RCP — Hz · telemetry — Hz")
        self.loss_label.setText("loss —")
        # The age of the last telemetry must tick even when nothing arrives.
        self._age_timer = QTimer(self)
        self._age_timer.setInterval(250)
        self._age_timer.timeout.connect(self._refresh_state)
        self._age_timer.start()
        self._refresh_state()

    def on_state(self, state: LinkState, reason: str) -> None:
        """Link state changed."""
        self.state = state
        self.state_label.setToolTip(reason)
        self._refresh_state()

    def on_telemetry(self, frame: TelemetryFrame) -> None:
        """Remember when telemetry last arrived."""
        self.last_telemetry_at = frame.received_at
        self._refresh_state()

    def on_stats(self, stats: LinkStats) -> None:
        """New counters and rates."""
        self.rates_label.setText(
            f"RCP {stats.rcp_rate_hz:.1f} Hz · telemetry {stats.telemetry_rate_hz:.1f} Hz"
            f" · video {stats.video_rate_hz:.1f} fps"
        )
        loss = "—" if stats.loss_estimate is None else f"{100 * stats.loss_estimate:.0f}%"
        self.loss_label.setText(f"loss {loss} · bad {stats.malformed} · foreign {stats.foreign}")

    def set_estop(self, active: bool) -> None:
        """Show whether an emergency stop holds the robot."""
        if active:
            self.estop_label.setText("E-STOP")
            self.estop_label.setStyleSheet(
                "background:#c62828;color:white;font-weight:bold;font-size:16pt;padding:2px 10px;"
            )
        else:
            self.estop_label.setText("e-stop ready (Space)")
            self.estop_label.setStyleSheet("font-size:12pt;padding:2px 10px;")

    def _refresh_state(self) -> None:
        text = "LINK LOST" if self.state == LinkState.LOST else self.state.value
        if self.last_telemetry_at is not None:
            text += f" · telemetry {time.monotonic() - self.last_telemetry_at:.1f} s ago"
        self.state_label.setText(text)
        self.state_label.setStyleSheet(
            STATE_STYLES[self.state] + "font-weight:bold;padding:2px 8px;"
        )

"""Status-bar widgets: link state with telemetry age, rates, loss, address and e-stop state.

Other parts of the console (the Record button, the ROS state) sit between the address and
the e-stop indicator, which stays at the right edge.
"""

from __future__ import annotations

import time

from PySide6.QtCore import QTimer
from PySide6.QtWidgets import QGridLayout, QHBoxLayout, QLabel, QWidget

from ocu.link.core import LinkState, TelemetryFrame
from ocu.link.stats import LinkStats

BLOCK = "font-weight:bold;font-size:15pt;padding:3px 12px;border-radius:4px;"
STATE_STYLES = {
    LinkState.CONNECTING: "background:#b8860b;color:white;",
    LinkState.CONNECTED: "background:#2e7d32;color:white;",
    LinkState.LOST: "background:#c62828;color:white;",
    LinkState.CLOSED: "background:#555;color:white;",
}
STATE_TEXT = {
    LinkState.CONNECTING: "CONNECTING",
    LinkState.CONNECTED: "CONNECTED",
    LinkState.LOST: "LINK LOST",
    LinkState.CLOSED: "DISCONNECTED",
}
ESTOP_STYLE = "background:#c62828;color:white;font-weight:bold;font-size:18pt;padding:3px 16px;"
MOVING_STYLE = "background:#ef6c00;color:white;font-weight:bold;font-size:18pt;padding:3px 16px;"
READY_STYLE = "background:#37474f;color:white;font-weight:bold;font-size:18pt;padding:3px 16px;"
REPLAY_STYLE = "background:#b00020;color:white;font-weight:bold;font-size:18pt;padding:3px 16px;"
INFO_STYLE = "font-size:12pt;padding:0 8px;"
# Two lines of link facts fit the height of the big indicators: the status bar stays one
# row tall and wide enough for the Record button and the ROS state at 1600 px.
FACT_STYLE = "font-size:10pt;padding:0 6px;"
AGE_REFRESH_MS = 250


def _label(name: str, style: str = INFO_STYLE) -> QLabel:
    label = QLabel()
    label.setObjectName(name)
    label.setStyleSheet(style)
    return label


class LinkStatus(QWidget):
    """Always-visible link facts and the e-stop state, for the status bar."""

    def __init__(self, address_text: str, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.state = LinkState.CONNECTING
        self.last_telemetry_at: float | None = None
        self.estop_active = False
        self.moving = False
        self.replay = False
        layout = QHBoxLayout(self)
        layout.setContentsMargins(2, 2, 2, 2)
        layout.setSpacing(6)
        self.state_label = _label("link_state")
        self.age_label = _label("telemetry_age", FACT_STYLE)
        self.rates_label = _label("link_rates", FACT_STYLE)
        self.loss_label = _label("link_loss", FACT_STYLE)
        self.address_label = _label("link_address", FACT_STYLE)
        self.address_label.setText(address_text)
        self.estop_label = _label("estop_state")
        self.estop_label.setMinimumWidth(220)
        facts = QGridLayout()
        facts.setContentsMargins(0, 0, 0, 0)
        facts.setVerticalSpacing(0)
        facts.addWidget(self.age_label, 0, 0)
        facts.addWidget(self.loss_label, 0, 1)
        facts.addWidget(self.rates_label, 1, 0, 1, 2)
        layout.addWidget(self.state_label)
        layout.addLayout(facts)
        layout.addStretch(1)
        layout.addWidget(self.address_label)
        layout.addWidget(self.estop_label)
        self._layout = layout
        self.rates_label.setText("RCP — Hz · telemetry — Hz")
        self.loss_label.setText("loss — · delay —")
        self._show_estop()
        # The age of the last telemetry must tick even when nothing arrives.
        self._age_timer = QTimer(self)
        self._age_timer.setInterval(AGE_REFRESH_MS)
        self._age_timer.timeout.connect(self._refresh_state)
        self._age_timer.start()
        self._refresh_state()

    def add_indicator(self, widget: QWidget) -> None:
        """Show another widget left of the e-stop indicator (Record button, ROS state)."""
        self._layout.insertWidget(self._layout.indexOf(self.estop_label), widget)

    def set_address(self, address_text: str) -> None:
        """The simulator or robot address shown."""
        self.address_label.setText(address_text)

    def on_state(self, state: LinkState, reason: str) -> None:
        """Link state changed."""
        self.state = state
        self.state_label.setToolTip(reason)
        if state == LinkState.CONNECTING:
            self.last_telemetry_at = None
        self._refresh_state()

    def on_telemetry(self, frame: TelemetryFrame) -> None:
        """Remember when telemetry last arrived."""
        self.last_telemetry_at = frame.received_at
        self._refresh_state()

    def on_stats(self, stats: LinkStats) -> None:
        """New counters and rates."""
        self.rates_label.setText(
            f"RCP {stats.rcp_rate_hz:.1f} Hz · telemetry {stats.telemetry_rate_hz:.1f} Hz"
            f" · video {stats.video_rate_hz:.0f} fps"
        )
        loss = "—" if stats.loss_estimate is None else f"{100 * stats.loss_estimate:.0f} %"
        delay = "—" if stats.delay_s is None else f"{1000 * stats.delay_s:.0f} ms"
        self.loss_label.setText(f"loss {loss} · delay {delay}")
        self.loss_label.setToolTip(
            "telemetry loss estimate, and the round trip measured from the speed commands the "
            "robot echoes (— until something has moved); "
            f"malformed {stats.malformed}, foreign {stats.foreign}, "
            f"duplicates {stats.duplicates}, reordered {stats.reordered}, "
            f"late telemetry dropped {stats.stale_telemetry}"
        )

    def set_replay(self) -> None:
        """A replay: the motion indicator says REPLAY for good (nothing is ever sent)."""
        self.replay = True
        self._show_estop()

    def set_estop(self, active: bool, reason: str = "") -> None:
        """Whether an emergency stop holds the robot until the operator acts again."""
        self.estop_active = active
        self.estop_label.setToolTip(reason)
        self._show_estop()

    def set_moving(self, moving: bool) -> None:
        """Whether any channel is commanded to move."""
        self.moving = moving
        self._show_estop()

    def _show_estop(self) -> None:
        if self.replay:
            self.estop_label.setText("REPLAY · nothing sent")
            self.estop_label.setStyleSheet(REPLAY_STYLE)
            self.estop_label.setToolTip("A recording is replayed: no robot is commanded")
        elif self.estop_active:
            self.estop_label.setText("E-STOP")
            self.estop_label.setStyleSheet(ESTOP_STYLE)
        elif self.moving:
            self.estop_label.setText("MOVING · Space = stop")
            self.estop_label.setStyleSheet(MOVING_STYLE)
        else:
            self.estop_label.setText("STOPPED · Space = stop")
            self.estop_label.setStyleSheet(READY_STYLE)

    def _refresh_state(self) -> None:
        style = STATE_STYLES[self.state] + BLOCK
        if self.state_label.styleSheet() != style:
            self.state_label.setStyleSheet(style)
        self.state_label.setText(STATE_TEXT[self.state])
        if self.last_telemetry_at is None:
            self.age_label.setText("no telemetry yet")
        else:
            age = time.monotonic() - self.last_telemetry_at
            self.age_label.setText(f"telemetry {age:.1f} s ago")

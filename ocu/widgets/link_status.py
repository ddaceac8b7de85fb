"""Status-bar widgets: link state with telemetry age, rates, loss, address and e-stop state.

Other parts of the console (the Record button, the ROS state) sit between the address and
the e-stop indicator, which stays at the right edge. The motion indicator is never cut: it
is as wide as its longest text, and where the bar is short of room the address, the rates
and the indicators with long texts give way, shortened with an ellipsis (whole in their
tooltips).
"""

from __future__ import annotations

import time

from PySide6.QtCore import QEvent, QTimer
from PySide6.QtGui import QResizeEvent
from PySide6.QtWidgets import QGridLayout, QHBoxLayout, QLabel, QWidget

from ocu.console.model import ConsoleModel
from ocu.records import LinkState, LinkStats
from ocu.widgets.elided_label import ElidedLabel

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
# What the motion indicator says: e-stopped, moving, stopped, replaying.
ESTOP_TEXTS = (
    ("E-STOP", ESTOP_STYLE),
    ("MOVING · Space = stop", MOVING_STYLE),
    ("STOPPED · Space = stop", READY_STYLE),
    ("REPLAY · nothing sent", REPLAY_STYLE),
)
# Two lines of link facts fit the height of the big indicators: the status bar stays one
# row tall and wide enough for the Record button and the ROS state at 1600 px.
FACT_STYLE = "font-size:10pt;padding:0 6px;"
AGE_REFRESH_MS = 250
NO_CAP = 16777215  # QWIDGETSIZE_MAX


def _label(name: str, style: str = INFO_STYLE) -> QLabel:
    label = QLabel()
    label.setObjectName(name)
    label.setStyleSheet(style)
    return label


def _elided(name: str) -> ElidedLabel:
    label = ElidedLabel()
    label.setObjectName(name)
    label.setStyleSheet(FACT_STYLE)
    return label


class LinkStatus(QWidget):
    """Always-visible link facts and the e-stop state, for the status bar (a model view)."""

    def __init__(
        self, model: ConsoleModel, address_text: str, parent: QWidget | None = None
    ) -> None:
        super().__init__(parent)
        self.model = model
        self.replay = False
        # What the state label shows: the model's state as of the last refresh on the GUI
        # thread (the control thread changes the model's first; its event follows).
        self._shown_state = model.robot.link_state
        self._reconnect: tuple[int, float] | None = None  # (failures, next attempt at)
        layout = QHBoxLayout(self)
        layout.setContentsMargins(2, 2, 2, 2)
        layout.setSpacing(6)
        self.state_label = _label("link_state")
        self.age_label = _label("telemetry_age", FACT_STYLE)
        self.rates_label = _elided("link_rates")
        self.loss_label = _label("link_loss", FACT_STYLE)
        self.address_label = _elided("link_address")  # also in the window's title
        self.address_label.setText(address_text)
        self.estop_label = _label("estop_state")
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
        # Labels that give way where the bar is short of room, the first first.
        self._giving_way: list[ElidedLabel] = [self.address_label]
        self.rates_label.setText("RCP — Hz · telemetry — Hz")
        self.loss_label.setText("loss — · delay —")
        self._fit_estop_label()
        self._show_estop()
        # The age of the last telemetry must tick even when nothing arrives.
        self._age_timer = QTimer(self)
        self._age_timer.setInterval(AGE_REFRESH_MS)
        self._age_timer.timeout.connect(self._refresh_state)
        self._age_timer.start()
        self._refresh_state()
        robot = model.robot.events
        robot.link_state_changed.connect(self._on_state)
        robot.stats_changed.connect(self.on_stats)
        robot.telemetry_changed.connect(lambda _frame: self._refresh_state())
        model.events.estop_changed.connect(lambda _active, reason: self._show_estop(reason))
        model.events.command_changed.connect(self._show_estop)

    @property
    def state(self) -> LinkState:
        """The link state shown: the label says this (the model's, as of the last refresh)."""
        return self._shown_state

    @property
    def last_telemetry_at(self) -> float | None:
        """When the telemetry shown arrived (the model's)."""
        return self.model.robot.last_telemetry_at

    def add_indicator(self, widget: QWidget) -> None:
        """Show another widget left of the e-stop indicator (Record button, ROS state)."""
        self._layout.insertWidget(self._layout.indexOf(self.estop_label), widget)
        if isinstance(widget, ElidedLabel):
            self._giving_way.append(widget)

    def resizeEvent(self, event: QResizeEvent) -> None:
        """Share the room again."""
        self._share_room()
        super().resizeEvent(event)

    def event(self, event: QEvent) -> bool:
        """A child's size changed (a new text): share the room again."""
        if event.type() == QEvent.Type.LayoutRequest:
            self._share_room()
        return super().event(event)

    def _share_room(self) -> None:
        """Where the widgets want more room than the bar has, the labels that give way are
        shortened, the first of them first (a box layout would shorten all of them alike)."""
        layout = self._layout
        margins = layout.contentsMargins()
        want = margins.left() + margins.right()
        shown = 0
        for index in range(layout.count()):
            item = layout.itemAt(index)
            if item is None or item.isEmpty():
                continue  # a hidden widget or the stretch: no room, no spacing
            shown += 1
            widget = item.widget()
            want += (widget.sizeHint() if widget is not None else item.sizeHint()).width()
        want += layout.spacing() * max(shown - 1, 0)
        short = want - self.width()
        for label in self._giving_way:
            cap = NO_CAP
            if short > 0 and not label.isHidden():
                hint = label.sizeHint().width()
                give = min(short, hint - label.minimumSizeHint().width())
                if give > 0:
                    cap = hint - give
                    short -= give
            if label.maximumWidth() != cap:
                label.setMaximumWidth(cap)

    def set_address(self, address_text: str) -> None:
        """The simulator or robot address shown."""
        self.address_label.setText(address_text)

    def _on_state(self, _state: LinkState, reason: str) -> None:
        self.state_label.setToolTip(reason)
        self._refresh_state()

    def on_stats(self, stats: LinkStats) -> None:
        """New counters and rates."""
        # A link that reconnects by itself (a UR): its next attempt, counted down between
        # two snapshots by the age refresh.
        self._reconnect = (
            None
            if stats.next_attempt_in_s is None
            else (stats.reconnect_failures, time.monotonic() + stats.next_attempt_in_s)
        )
        self._refresh_state()
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

    @property
    def estop_active(self) -> bool:
        """Whether an emergency stop holds the robot (the model's latch)."""
        return self.model.estopped

    @property
    def moving(self) -> bool:
        """Whether any channel is commanded to move (the model's command)."""
        return self.model.is_moving

    def _fit_estop_label(self) -> None:
        """The motion indicator's width: that of its widest text, so none is ever cut."""
        widths = []
        for text, style in ESTOP_TEXTS:
            self.estop_label.setText(text)
            self.estop_label.setStyleSheet(style)
            self.estop_label.ensurePolished()
            widths.append(self.estop_label.sizeHint().width())
        self.estop_label.setMinimumWidth(max(widths))

    def _show_estop(self, reason: str | None = None) -> None:
        if reason is not None:
            self.estop_label.setToolTip(reason)
        if self.replay:
            text, style = ESTOP_TEXTS[3]
            self.estop_label.setToolTip("A recording is replayed: no robot is commanded")
        elif self.estop_active:
            text, style = ESTOP_TEXTS[0]
        elif self.moving:
            text, style = ESTOP_TEXTS[1]
        else:
            text, style = ESTOP_TEXTS[2]
        self.estop_label.setText(text)
        self.estop_label.setStyleSheet(style)

    def _refresh_state(self) -> None:
        state = self._shown_state = self.model.robot.link_state
        style = STATE_STYLES[state] + BLOCK
        if self.state_label.styleSheet() != style:
            self.state_label.setStyleSheet(style)
        self.state_label.setText(STATE_TEXT[state])
        age = self.model.robot.telemetry_age()
        reconnect = self._reconnect if state is not LinkState.CONNECTED else None
        if reconnect is not None and state is not LinkState.CLOSED:
            failures, next_at = reconnect
            tried = (
                f" · {failures} attempt{'s' if failures != 1 else ''} failed" if failures else ""
            )
            wait_s = max(0.0, next_at - time.monotonic())
            self.age_label.setText(f"reconnecting{tried} · next in {wait_s:.1f} s")
        elif age is None:
            self.age_label.setText("no telemetry yet")
        else:
            self.age_label.setText(f"telemetry {age:.1f} s ago")

"""The Robot check dock: `ocu probe`'s judgement of what the console's own link receives.

The dock subscribes a `TelemetryLog` to the console's link (it sends nothing: the link's
own commands make the robot answer) and, while it is shown, judges what arrived since the
last "Check again" with the probe's pure `judge` once a second. It shows the findings as
plain sentences and an overall state: OK, MISMATCH, or listening. Motion the console
commanded meanwhile is noted, and the motors' speeds are then not judged.
"""

from __future__ import annotations

import threading
import time

from PySide6.QtCore import Qt, QTimer, Signal
from PySide6.QtGui import QBrush, QColor
from PySide6.QtWidgets import (
    QHBoxLayout,
    QLabel,
    QListWidget,
    QListWidgetItem,
    QPushButton,
    QVBoxLayout,
    QWidget,
)

from ocu.calibrate.observer import TelemetryLog
from ocu.calibrate.probe import MISMATCH, NOTE, OK, Finding, judge
from ocu.link.base import Link
from ocu.profile import RobotProfile
from ocu.records import CommandSent, LinkEvent

# What arrives in this long is judged (the tick's rate needs 1.5 s of telemetry).
MIN_LISTEN_S = 2.0
JUDGE_INTERVAL_MS = 1000

# The overall states the dock shows (and `state_changed` carries).
OFF = "off"
LISTENING = "listening"
STATE_OK = "ok"
STATE_MISMATCH = "mismatch"

MARKS = {OK: "✔", NOTE: "•", MISMATCH: "✖"}
COLOURS = {OK: "#2e7d32", NOTE: "#555555", MISMATCH: "#c62828"}


class _Window:
    """What one link delivered since a restart: the log, and whether motion was commanded."""

    def __init__(self, profile: RobotProfile) -> None:
        self.log = TelemetryLog(profile.link.telemetry_tick_hz)
        self.started = time.monotonic()
        self.foreign_at_start: int | None = None
        self._moved = threading.Event()

    def __call__(self, event: LinkEvent) -> None:
        """The link listener (the link's threads)."""
        if isinstance(event, CommandSent):
            if event.command.is_motion:
                self._moved.set()
            return
        self.log(event)

    @property
    def commanded_motion(self) -> bool:
        """Whether the console commanded any motion since the restart."""
        return self._moved.is_set()

    def foreign(self) -> int:
        """Datagrams from elsewhere since the restart (the link counts since it started)."""
        stats = self.log.stats
        if stats is None:
            return 0
        if self.foreign_at_start is None:
            self.foreign_at_start = stats.foreign
        return stats.foreign - self.foreign_at_start


class RobotCheckPanel(QWidget):
    """Findings about the robot on the console's link, in plain sentences, refreshable."""

    state_changed = Signal(str)

    def __init__(self, profile: RobotProfile, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.setObjectName("robot_check")
        self.profile = profile
        self._link: Link | None = None
        self._window: _Window | None = None
        self.state = OFF
        self.findings: list[Finding] = []

        intro = QLabel(
            "Checks what the console's link receives against the profile, as `ocu probe` "
            "does. It sends nothing."
        )
        intro.setWordWrap(True)
        self.verdict = QLabel()
        self.verdict.setObjectName("robot_check_verdict")
        self.verdict.setWordWrap(True)
        self.detail = QLabel()
        self.detail.setObjectName("robot_check_detail")
        self.again = QPushButton("Check again")
        self.again.setToolTip("Forget what arrived so far and listen afresh")
        self.again.clicked.connect(self.restart)
        self.list = QListWidget()
        self.list.setObjectName("robot_check_findings")
        self.list.setWordWrap(True)
        for widget in (self.again, self.list):
            # The console's keys drive the robot: nothing here keeps the keyboard.
            widget.setFocusPolicy(Qt.FocusPolicy.NoFocus)
        top = QHBoxLayout()
        top.addWidget(self.verdict, 1)
        top.addWidget(self.again)
        layout = QVBoxLayout(self)
        layout.addWidget(intro)
        layout.addLayout(top)
        layout.addWidget(self.detail)
        layout.addWidget(self.list, 1)
        self._timer = QTimer(self)
        self._timer.setInterval(JUDGE_INTERVAL_MS)
        self._timer.timeout.connect(self._tick)
        self._timer.start()
        self._show_state(OFF, "Not connected: connect to a robot to check it.")

    # ---- the link ------------------------------------------------------------------------

    def attach(self, link: Link | None) -> None:
        """Listen to this link (None: the console disconnected)."""
        if self._link is not None and self._window is not None:
            self._link.unsubscribe(self._window)
        self._link = link
        self._window = None
        if link is None:
            self.findings = []
            self.list.clear()
            self.detail.clear()
            self._show_state(OFF, "Not connected: connect to a robot to check it.")
            return
        self.restart()

    def restart(self) -> None:
        """Forget what arrived and listen afresh."""
        if self._link is None:
            return
        if self._window is not None:
            self._link.unsubscribe(self._window)
        self._window = _Window(self.profile)
        self._link.subscribe(self._window)
        self.findings = []
        self.list.clear()
        self.detail.setText(f"Listening to {self._link.description} …")
        self._show_state(LISTENING, "Listening…")

    # ---- judging -------------------------------------------------------------------------

    def _tick(self) -> None:
        if self._window is not None and self.isVisible():
            self.check()

    def check(self) -> bool:
        """Judge what arrived so far (once it listened long enough); whether it judged."""
        window = self._window
        if window is None:
            return False
        listened_s = time.monotonic() - window.started
        if listened_s < MIN_LISTEN_S:
            return False
        findings = judge(
            self.profile,
            window.log,
            listened_s,
            foreign=window.foreign(),
            commanded_motion=window.commanded_motion,
        )
        self._show_findings(findings, listened_s, window.log.datagram_count)
        return True

    def _show_findings(self, findings: list[Finding], listened_s: float, datagrams: int) -> None:
        self.findings = findings
        self.list.clear()
        # The contradictions first: they are what the operator must act on.
        for finding in sorted(findings, key=lambda f: f.level != MISMATCH):
            item = QListWidgetItem(f"{MARKS[finding.level]}  {finding.text}")
            item.setForeground(QBrush(QColor(COLOURS[finding.level])))
            if finding.key:
                item.setToolTip(f"profile key: {finding.key}")
            self.list.addItem(item)
        mismatches = sum(1 for f in findings if f.level == MISMATCH)
        self.detail.setText(
            f"{datagrams} datagram(s) in {listened_s:.0f} s from "
            f"{self._link.description if self._link is not None else '?'}."
        )
        if mismatches:
            self._show_state(
                STATE_MISMATCH,
                f"MISMATCH: {mismatches} contradiction(s) with the profile "
                "(`ocu calibrate` measures most of them).",
            )
        else:
            self._show_state(STATE_OK, "OK: everything that arrived matches the profile.")

    def _show_state(self, state: str, text: str) -> None:
        colour = {STATE_OK: "#2e7d32", STATE_MISMATCH: "#c62828"}.get(state, "#555555")
        self.verdict.setText(text)
        self.verdict.setStyleSheet(f"font-weight: bold; font-size: 13pt; color: {colour};")
        if state != self.state:
            self.state = state
            self.state_changed.emit(state)

"""The status bar's LIVE indicator: who watches the session live, who drives, allow / revoke.

Shown when the console serves the session over the Foxglove WebSocket protocol (`ocu --live`,
docs/live.md). It reads the server's counters twice a second: how many clients watch, and
with `--live-control` whether a client may drive and which one does (its address). A click
revokes the remote drive — the client driving stops at once and nothing a client sends moves
the robot — and a second click allows it again. The tooltip lists every client.
"""

from __future__ import annotations

from PySide6.QtCore import QTimer
from PySide6.QtGui import QMouseEvent
from PySide6.QtWidgets import QLabel, QWidget

from ocu.live.server import LiveServer

REFRESH_MS = 500
STYLE = "font-weight:bold;font-size:12pt;padding:3px 8px;border-radius:4px;color:white;"
WATCHED = "background:#00695c;"  # clients watch, nobody drives
DRIVEN = "background:#6a1b9a;"  # a client drives
REVOKED = "background:#546e7a;"  # the operator revoked the remote drive


class LiveIndicator(QLabel):
    """`LIVE 3 · drive: 127.0.0.1:50312` (module docstring)."""

    def __init__(self, server: LiveServer, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.setObjectName("live_status")
        self.server = server
        self._timer = QTimer(self)
        self._timer.setInterval(REFRESH_MS)
        self._timer.timeout.connect(self.refresh)
        self._timer.start()
        self.refresh()

    def refresh(self) -> None:
        """Read the server's state now."""
        stats = self.server.stats(fresh=False)  # never waits for the relay: the GUI thread
        host, port = self.server.address
        text = f"LIVE {len(stats.clients)}"
        style = WATCHED
        control = self.server.control
        if control is not None:
            owner = control.owner
            if not control.allowed:
                text += " · drive revoked"
                style = REVOKED
            elif owner is not None:
                text += f" · drive: {owner}"
                style = DRIVEN
            else:
                text += " · drive allowed"
        self.setText(text)
        self.setStyleSheet(STYLE + style)
        clients = "\n".join(
            f"{c.address}: {c.subscriptions} subscriptions, {c.sent} sent, {c.dropped} dropped"
            for c in stats.clients
        )
        hint = (
            "\nClick: revoke the remote drive (the client driving stops at once); again: allow"
            if control is not None
            else ""
        )
        self.setToolTip(
            f"Serving the session on ws://{host}:{port} (docs/live.md)\n"
            f"{clients or 'no client connected'}{hint}"
        )

    def mousePressEvent(self, event: QMouseEvent) -> None:
        """A click revokes the remote drive, or allows it again."""
        control = self.server.control
        if control is not None:
            control.set_allowed(not control.allowed)
            self.refresh()
        super().mousePressEvent(event)

    def stop(self) -> None:
        """No more refreshes (the window closes)."""
        self._timer.stop()

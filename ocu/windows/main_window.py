"""The main window: link status bar and the live telemetry of all ten motors."""

from __future__ import annotations

from PySide6.QtWidgets import QMainWindow, QWidget

from ocu.link.qt import LinkThread
from ocu.profile import RobotProfile
from ocu.widgets.link_status import LinkStatus
from ocu.widgets.telemetry_table import TelemetryTable


class MainWindow(QMainWindow):
    """Shows what the link sees; the link is owned by the caller."""

    def __init__(
        self,
        profile: RobotProfile,
        link: LinkThread,
        address_text: str,
        parent: QWidget | None = None,
    ) -> None:
        super().__init__(parent)
        self.profile = profile
        self.link = link
        self.setWindowTitle(f"ocu — {profile.name} — {address_text}")
        self.telemetry_table = TelemetryTable(profile)
        self.setCentralWidget(self.telemetry_table)
        self.link_status = LinkStatus(address_text)
        self.statusBar().addPermanentWidget(self.link_status, 1)
        link.telemetry_received.connect(self.telemetry_table.show_frame)
        link.telemetry_received.connect(self.link_status.on_telemetry)
        link.link_state_changed.connect(self.link_status.on_state)
        link.stats_updated.connect(self.link_status.on_stats)
        self.resize(1100, 420)

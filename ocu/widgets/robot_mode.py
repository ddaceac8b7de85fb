"""The status bar's word on the robot controller's own mode (a UR's robot and safety modes).

Hidden until the hardware reports a mode (the Engineer reports none). Green while the
controller takes motion (RUNNING · NORMAL), orange in reduced mode, red for a protective or
emergency stop or any mode that refuses motion; grey when the link is not heard (not known).
The link holds motion while the controller refuses it and nothing resumes when it is ready
again (docs/ur.md, "The UR link").
"""

from __future__ import annotations

from PySide6.QtWidgets import QWidget

from ocu.console.robot import RobotState
from ocu.records import RobotModeReport
from ocu.widgets.elided_label import ElidedLabel

STYLE = "font-weight:bold;font-size:11pt;padding:3px 8px;border-radius:4px;"
STYLES = {
    "moving": "background:#2e7d32;color:white;",
    "reduced": "background:#ef6c00;color:white;",
    "refused": "background:#c62828;color:white;",
    "unknown": "background:#9e9e9e;color:white;",
}


def style_of(report: RobotModeReport | None) -> str:
    """Which colour a report shows in."""
    if report is None:
        return "unknown"
    if not report.may_move:
        return "refused"
    return "reduced" if report.safety == "REDUCED" else "moving"


class RobotModeIndicator(ElidedLabel):
    """The controller's mode in the status bar (module docstring)."""

    def __init__(self, robot: RobotState, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.setObjectName("robot_mode")
        self.mode_style = "unknown"
        self.hide()
        robot.events.robot_mode_changed.connect(self._show)
        if robot.robot_mode is not None:
            self._show(robot.robot_mode)

    def _show(self, report: RobotModeReport | None) -> None:
        self.mode_style = style_of(report)
        text = "controller: not heard" if report is None else report.text
        self.setText(text)
        self.setToolTip(
            "The robot controller's own mode: it takes motion only when green or orange; "
            "after a stop, nothing resumes by itself."
        )
        self.setStyleSheet(STYLE + STYLES[self.mode_style])
        self.show()

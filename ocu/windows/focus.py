"""The console's focus stops: losing focus, hiding or minimising the window stops the robot.

`FocusStops` is a mixin of `ocu.windows.main_window.MainWindow`: the Qt events and the
application's signals that tell the window it can no longer be seen or typed into halt the
model, and the game controller follows its focus policy (docs/gamepad.md).
"""

from __future__ import annotations

from PySide6.QtCore import QEvent, Qt
from PySide6.QtGui import QHideEvent, QShowEvent
from PySide6.QtWidgets import QApplication, QMainWindow, QWidget

from ocu.console.model import ConsoleModel
from ocu.gamepad.teleop import GamepadTeleop


class FocusStops(QMainWindow):
    """The window's focus and visibility handlers (the window sets the attributes below)."""

    model: ConsoleModel
    teleop: GamepadTeleop
    # Set once the console has shut down: the pad is then left alone.
    _shut: bool

    def owns(self, widget: QWidget) -> bool:
        """Whether a widget belongs to this console (floating docks and dialogs included)."""
        current: QWidget | None = widget
        while current is not None:
            if current is self:
                return True
            current = current.parentWidget()
        return False

    def _focused(self) -> bool:
        active = QApplication.activeWindow()
        return active is not None and self.owns(active)

    def _check_focus(self) -> None:
        if not self._focused():
            # The mux's table (ocu/control/mux.md) says what goes on: a planner the operator
            # watches in another window (rviz), a pad whose mapping allows the background.
            self.model.halt(
                "console lost focus",
                lock="focus lost",
                pad_background=self.teleop.mapping.background,
            )
        self._apply_pad_policy()

    def _apply_pad_policy(self) -> None:
        """The pad's focus policy (docs/gamepad.md): never while the console cannot be seen;
        in the background only if its mapping allows it."""
        if self._shut:
            return
        if not self.isVisible() or self.isMinimized():
            self.teleop.set_active(False, "console hidden or minimised")
        elif not (self._focused() or self.teleop.mapping.background):
            self.teleop.set_active(False, "console lost focus")
        else:
            self.teleop.set_active(True)

    def _on_focus_window(self, _window: object) -> None:
        self._check_focus()

    def _on_application_state(self, state: Qt.ApplicationState) -> None:
        if state != Qt.ApplicationState.ApplicationActive:
            self.model.halt(
                "application inactive",
                lock="focus lost",
                pad_background=self.teleop.mapping.background,
            )
        self._apply_pad_policy()

    def changeEvent(self, event: QEvent) -> None:
        """Minimising or losing activation stops the robot."""
        if event.type() == QEvent.Type.WindowStateChange:
            if self.isMinimized():
                self.model.halt("window minimised")
            self._apply_pad_policy()
        elif event.type() == QEvent.Type.ActivationChange and not self.isActiveWindow():
            self._check_focus()
        super().changeEvent(event)

    def showEvent(self, event: QShowEvent) -> None:
        """A console shown again lets the pad engage again (with a fresh deadman press)."""
        super().showEvent(event)
        self._apply_pad_policy()

    def hideEvent(self, event: QHideEvent) -> None:
        """A hidden console commands nothing."""
        self.model.halt("window hidden")
        super().hideEvent(event)
        self._apply_pad_policy()

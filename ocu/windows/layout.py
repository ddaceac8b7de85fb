"""The console's docks: where each one goes, and what the settings remember between sessions
(the window's geometry and dock layout, the stream asked of each camera).

`DockLayout` is a mixin of `ocu.windows.main_window.MainWindow`: the window makes the panels
and their docks, this places them and saves and restores the layout.
"""

from __future__ import annotations

import logging
from collections.abc import Callable

from PySide6.QtCore import QByteArray, QSettings, Qt
from PySide6.QtWidgets import QDockWidget, QMainWindow, QWidget

from ocu.console.model import ConsoleModel
from ocu.profile import RobotProfile
from ocu.records import CameraRequest, CommandError
from ocu.widgets.link_graphs import LinkGraphsPanel
from ocu.widgets.model3d import Model3DWidget
from ocu.windows.settings_file import SettingsStatus

log = logging.getLogger("ocu.console")

# 2: the Video dock; 3: the Arm dock; 4: the Gamepad and Map docks; 5: Robot check, Calibration
LAYOUT_VERSION = 5
STREAMS_KEY = "video/streams"


def format_stream_setting(request: CameraRequest) -> str:
    """A stream request as the settings keep it: "CAMERA:WIDTHxHEIGHT@FPS"."""
    return f"{request.camera}:{request.width_px}x{request.height_px}@{request.fps}"


def parse_stream_setting(text: str) -> CameraRequest:
    """The stream request of a "CAMERA:WIDTHxHEIGHT@FPS" setting; ValueError if malformed."""
    try:
        camera, rest = text.split(":", 1)
        size, fps = rest.split("@", 1)
        width, height = size.lower().split("x", 1)
        request = CameraRequest(int(camera), int(width), int(height), int(fps))
        request.check()
    except ValueError as err:
        raise ValueError(f"not CAMERA:WIDTHxHEIGHT@FPS: {text!r} ({err})") from err
    return request


class DockLayout(QMainWindow):
    """The window's docks in place, and its layout and streams saved and restored.

    The window sets the attributes below; `_arrange_docks` adds the 3D model and Link docks.
    """

    profile: RobotProfile
    settings: QSettings
    # Whether the layout may be saved (ocu.windows.settings_file).
    settings_status: SettingsStatus
    model: ConsoleModel
    velocity_dock: QDockWidget
    max_dock: QDockWidget
    joint_dock: QDockWidget
    log_dock: QDockWidget
    _video_dock: QDockWidget | None  # only with cameras
    gamepad_dock: QDockWidget
    _map_dock: QDockWidget | None  # only with a chassis that drives
    robot_check_dock: QDockWidget
    _calibration_dock: QDockWidget | None
    arm_dock: QDockWidget | None
    # The layout "Reset layout" goes back to.
    _default_state: QByteArray
    # A floating dock is a window of its own (ocu.windows.focus).
    _check_focus: Callable[[], None]

    def _dock(self, name: str, title: str, widget: QWidget) -> QDockWidget:
        dock = QDockWidget(title, self)
        dock.setObjectName(name)
        dock.setWidget(widget)
        dock.setFeatures(
            QDockWidget.DockWidgetFeature.DockWidgetMovable
            | QDockWidget.DockWidgetFeature.DockWidgetFloatable
            | QDockWidget.DockWidgetFeature.DockWidgetClosable
        )
        dock.topLevelChanged.connect(lambda _floating: self._check_focus())
        return dock

    def docks(self) -> list[QDockWidget]:
        """Every dock of the console."""
        return self.findChildren(QDockWidget)

    def _arrange_docks(self) -> None:
        """The default layout of the docks made so far, with the 3D model and Link docks."""
        # Left: the operator's controls over the 3D model (Max velocity and Events as tabs
        # behind it); right: the cameras over the joints. Fits 1600x1000 with every dock.
        # The Video and Map docks exist only where the hardware has cameras, a chassis.
        self.addDockWidget(Qt.DockWidgetArea.LeftDockWidgetArea, self.velocity_dock)
        right = self._video_dock or self.joint_dock
        self.addDockWidget(Qt.DockWidgetArea.RightDockWidgetArea, right)
        if self._video_dock is not None:
            self.splitDockWidget(self._video_dock, self.joint_dock, Qt.Orientation.Vertical)
        self.model_dock = add_model_dock(self)
        self.tabifyDockWidget(self.model_dock, self.max_dock)
        self.tabifyDockWidget(self.max_dock, self.log_dock)
        self.tabifyDockWidget(self.log_dock, self.gamepad_dock)
        self.tabifyDockWidget(self.gamepad_dock, self.robot_check_dock)
        # The link in graphs, and the command rate (remembered in the settings).
        self.link_graphs = LinkGraphsPanel(self.profile, self.settings)
        self.link_dock = self._dock("link_dock", "Link", self.link_graphs)
        self.tabifyDockWidget(self.robot_check_dock, self.link_dock)
        # The map beside the 3D model: the robot's pose in the room, its arm in the other.
        if self._map_dock is not None:
            self.tabifyDockWidget(self.model_dock, self._map_dock)
        self.model_dock.raise_()
        self.resizeDocks([self.velocity_dock, right], [500, 1100], Qt.Orientation.Horizontal)
        self.resizeDocks([self.velocity_dock, self.model_dock], [440, 490], Qt.Orientation.Vertical)
        if self._video_dock is not None:
            self.resizeDocks(
                [self._video_dock, self.joint_dock], [480, 450], Qt.Orientation.Vertical
            )

    def _arrange_joint_tabs(self) -> None:
        """The Arm dock (if any) and the Calibration dock as tabs behind Joint position."""
        if self.arm_dock is not None:
            self.addDockWidget(Qt.DockWidgetArea.RightDockWidgetArea, self.arm_dock)
            self.tabifyDockWidget(self.joint_dock, self.arm_dock)
            self.joint_dock.raise_()
        # On the right, so the 3D model stays in view: it shows the joint a device should be.
        if self._calibration_dock is not None:
            self.addDockWidget(Qt.DockWidgetArea.RightDockWidgetArea, self._calibration_dock)
            self.tabifyDockWidget(self.joint_dock, self._calibration_dock)
        self.joint_dock.raise_()

    def restore_layout(self) -> bool:
        """Window geometry and dock layout from the settings; False if none was saved."""
        geometry = self.settings.value("main_window/geometry")
        state = self.settings.value("main_window/state")
        restored = False
        if isinstance(geometry, QByteArray):
            restored = self.restoreGeometry(geometry)
        if isinstance(state, QByteArray):
            restored = self.restoreState(state, LAYOUT_VERSION) and restored
        return restored

    def save_layout(self) -> None:
        """Remember window geometry and dock layout (unless the settings cannot be saved)."""
        if not self.settings_status.writable:
            log.warning("window layout not saved (%s)", "; ".join(self.settings_status.notes))
            return
        self.settings.setValue("main_window/geometry", self.saveGeometry())
        self.settings.setValue("main_window/state", self.saveState(LAYOUT_VERSION))
        self.settings.sync()

    def restore_streams(self) -> None:
        """The stream request of each camera from the settings (what the operator chose)."""
        saved = self.settings.value(STREAMS_KEY)
        if saved is None:
            return
        texts = saved if isinstance(saved, list) else [saved]
        for text in texts:
            try:
                request = parse_stream_setting(str(text))
                self.model.set_stream_request(request)
            except (ValueError, CommandError) as err:
                log.warning("settings %s: %s ignored (%s)", STREAMS_KEY, text, err)

    def save_streams(self) -> None:
        """Remember each camera's stream request."""
        if not self.settings_status.writable:
            return
        self.settings.setValue(
            STREAMS_KEY, [format_stream_setting(r) for r in self.model.stream_request]
        )

    def reset_layout(self) -> None:
        """Back to the default dock layout."""
        for dock in self.docks():
            dock.setFloating(False)
            dock.show()
        self.restoreState(self._default_state, LAYOUT_VERSION)


def add_model_dock(window: DockLayout) -> QDockWidget:
    """The 3D model dock under the velocity dock: live pose, a ghost at the targets."""
    widget = Model3DWidget(window.profile)
    dock = window._dock("model3d_dock", "3D model", widget)
    window.addDockWidget(Qt.DockWidgetArea.LeftDockWidgetArea, dock)
    window.splitDockWidget(window.velocity_dock, dock, Qt.Orientation.Vertical)
    return dock

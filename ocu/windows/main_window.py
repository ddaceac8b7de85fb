"""The cockpit: one window of dock widgets, a status bar that is always visible, hotkeys.

The window owns the operator model, the link's lifetime (Connect/Disconnect) and the Qt side
of the safety rules: focus loss, hiding, minimising (ocu.windows.focus), a lost link and
closing all stop the robot through the model; a stalled GUI thread is caught by the link's own
watchdog, and the model is halted when the thread comes back so nothing resumes by itself.
Where the docks go and what the settings remember: ocu.windows.layout.

The window only wires: the link's events (through its Qt adapter) go into the console model,
the model's command goes to the link, and the views subscribe to the model. Beside the
operator: the video panel shows the link's cameras, a Recorder (if given) records every link
the window makes, the ROS toggle lets a ROS 1 planner drive through the model until it acts.
A game controller drives too, given a pad mapping (docs/gamepad.md), under the window's focus
policy. Given a replay (a read-only link) instead of a link factory, the same window replays
a recording: REPLAY banner, command widgets disabled, no hotkeys, no pad, nothing sent.
"""

from __future__ import annotations

import logging
import math
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import TypeVar

from PySide6.QtCore import QSettings, Qt, QTimer
from PySide6.QtGui import QAction, QCloseEvent
from PySide6.QtWidgets import (
    QApplication,
    QDockWidget,
    QLabel,
    QListWidget,
    QMainWindow,
    QSizePolicy,
    QToolBar,
    QWidget,
)

from ocu import hotkeys
from ocu.console.arm import ArmGoal
from ocu.console.model import ConsoleModel
from ocu.console.poses import ARM_POSES_NAME
from ocu.core.hardware import HardwareComponent
from ocu.core.manager import DEFAULT_RATE_HZ
from ocu.core_process import CoreSpec
from ocu.gamepad.calibration import CalibrationStore, saved_or_default
from ocu.gamepad.core_pad import pose_hook
from ocu.gamepad.mapping import PadMapping, load_pad_mapping
from ocu.gamepad.teleop import GamepadTeleop
from ocu.hardware.engineer import engineer_capabilities, engineer_component
from ocu.hotkeys import KeyMap
from ocu.link.base import Link
from ocu.profile import RobotProfile
from ocu.qt.collector import pin_garbage_collection
from ocu.qt.gamepad import QtGamepad
from ocu.qt.link import QtLink
from ocu.qt.record import RecordButton
from ocu.qt.replay import ReplayController
from ocu.record.recorder import Recorder
from ocu.record.replay_link import ReplayLink
from ocu.records import LinkState
from ocu.widgets.gamepad import GamepadPanel, PadIndicator
from ocu.widgets.link_status import LinkStatus
from ocu.widgets.map_view import MapPanel, NavStatus
from ocu.widgets.model3d import Model3DWidget
from ocu.widgets.replay import ReplayBanner, ReplayControls
from ocu.widgets.robot_check import RobotCheckPanel
from ocu.widgets.robot_mode import RobotModeIndicator
from ocu.widgets.video import VideoPanel
from ocu.windows.arm import ArmModeIndicator, ArmPanel
from ocu.windows.calibration import CalibrationLinkFactory, CalibrationPanel
from ocu.windows.focus import FocusStops
from ocu.windows.help_overlay import HelpOverlay
from ocu.windows.joint_position import JointPositionPanel
from ocu.windows.key_filter import KeyFilter
from ocu.windows.layout import (
    LAYOUT_VERSION,
    DockLayout,
    format_stream_setting,
    parse_stream_setting,
)
from ocu.windows.max_velocity import MaxVelocityPanel
from ocu.windows.remote_control import RemoteControl, control_for
from ocu.windows.ros_control import RosControl
from ocu.windows.settings_file import SettingsStatus
from ocu.windows.velocity import VelocityPanel
from ocu.windows.x_keys import RemoteReader

# The stream settings are ocu.windows.layout's, still importable from here.
__all__ = [
    "GIL_SWITCH_INTERVAL_S",
    "LinkFactory",
    "MainWindow",
    "format_stream_setting",
    "parse_stream_setting",
]

log = logging.getLogger("ocu.console")

# The 3D view's predicted pose is redrawn this often (about 30 Hz).
VIEW_PERIOD_MS = 33
# The Calibration dock's default output, beside the settings.
CALIBRATED_PROFILE_NAME = "calibrated_profile.toml"
# How far the 3D model's ghost turns the joint the calibration asks about.
CALIBRATION_GHOST_DEG = 30.0
EVENT_LOG_LENGTH = 500
# An event seen this soon again among the last few lines is counted on its line, not added
# (Space held: an e-stop, and the link's and the panels' word on it, 25 times a second).
EVENT_REPEAT_S = 1.0
EVENT_REPEAT_ROWS = 6
_EVENT_ROLE = Qt.ItemDataRole.UserRole
DEFAULT_SIZE = (1560, 960)
MINIMUM_SIZE = (800, 560)
REPLAY_DISABLED_TIP = "Replay: commands are disabled"


class MissingCapabilityError(LookupError):
    """A view asked for that the hardware's capabilities did not bring."""


W = TypeVar("W")


def _present(view: W | None, capability: str, what: str) -> W:
    if view is None:
        raise MissingCapabilityError(f"the hardware has no {capability!r}: no {what}")
    return view


LinkFactory = Callable[[], Link]
# How a link becomes the hardware component the control thread reads and writes.
HardwareFor = Callable[[Link], HardwareComponent]
# The GUI thread shares the GIL with the link and decoder threads: at Python's default 5 ms
# switch interval a key press could wait that long for it behind a JPEG being corrected
# (bench_console_video: key p99 5.4 ms at 5 ms, 3.9 ms at 1 ms, same CPU).
GIL_SWITCH_INTERVAL_S = 0.001


class MainWindow(FocusStops, DockLayout, QMainWindow):
    """The operator console; `link_factory` makes a fresh, not yet started link per Connect.

    With `replay` (and no link factory) the console shows a recording instead; with a
    `recorder` it has a Record button and records every link it makes. With `pad_mapping`
    it reads game controllers (calibrations from `pad_calibrations`); without, the Gamepad
    dock shows the default mapping and says the pad is off. Its focus stops live in
    ocu.windows.focus, its dock layout and saved settings in ocu.windows.layout.
    """

    def __init__(
        self,
        profile: RobotProfile,
        link_factory: LinkFactory | None,
        address_text: str,
        settings: QSettings,
        key_map: KeyMap | None = None,
        *,
        connect: bool = True,
        arm_poses_path: Path | None = None,
        recorder: Recorder | None = None,
        replay: ReplayLink | None = None,
        pad_mapping: PadMapping | None = None,
        pad_calibrations: CalibrationStore | None = None,
        calibration_link: CalibrationLinkFactory | None = None,
        settings_status: SettingsStatus | None = None,
        control_hz: float = DEFAULT_RATE_HZ,
        hardware_for: HardwareFor = engineer_component,
        capabilities: frozenset[str] | None = None,
        core: CoreSpec | None = None,
        parent: QWidget | None = None,
    ) -> None:
        sys.setswitchinterval(min(sys.getswitchinterval(), GIL_SWITCH_INTERVAL_S))
        # Closed panels and dialogs are cyclic garbage holding QObjects: collected here only.
        pin_garbage_collection()
        super().__init__(parent)
        if (link_factory is None and core is None) == (replay is None):
            raise ValueError("a console needs either a link factory or a replay source")
        self.setObjectName("ocu_main_window")
        self.profile = profile
        self.link_factory = link_factory
        self.replay = replay
        self.recorder = recorder if replay is None else None
        self.settings = settings
        # Each link becomes a hardware component (ocu.core.hardware); the views the window
        # builds are those its capabilities ask for (the Engineer's: every one).
        self.hardware_for = hardware_for
        self.capabilities = (
            capabilities
            if capabilities is not None
            else engineer_capabilities(profile, extension=profile.extension is not None)
        )
        # Whether the layout may be saved (ocu.windows.settings_file: never over a file that
        # could not be read, not in a folder that cannot be written).
        self.settings_status = settings_status or SettingsStatus(Path(settings.fileName()))
        self.key_map = key_map if key_map is not None else hotkeys.load_key_map(profile)
        # The operator's stored arm poses sit beside the hotkey file and the settings.
        if arm_poses_path is None:
            arm_poses_path = Path(settings.fileName()).parent / ARM_POSES_NAME
        # The model runs on the control thread (ocu.windows.control, ocu.core), or in a process
        # of its own (`core`: ocu.windows.remote_control); the window and its views touch it
        # through a handle and are called on this thread.
        self.control = control_for(
            core,
            profile,
            self.key_map,
            arm_poses_path,
            control_hz=control_hz,
            pad_mapping=pad_mapping if replay is None else None,
            pad_calibrations=None if pad_calibrations is None else pad_calibrations.path,
            parent=self,
        )
        if isinstance(self.control, RemoteControl):
            self.link_factory = self.control.link_factory(address_text)
            self.hardware_for = self.control.hardware_for  # type: ignore[assignment]
            self.control.core_ended.connect(self.log_event)
        self.core = self.control.manager
        self.model: ConsoleModel = self.control.model
        self.link: QtLink | None = None
        self.replay_controller = ReplayController(replay, self) if replay is not None else None
        self._shut = False
        if replay is None:
            self.setWindowTitle(f"ocu — {profile.name} — {address_text}")
        else:
            self.setWindowTitle(
                f"ocu — REPLAY {replay.path.name} — {profile.name} — commands disabled"
            )

        self.velocity_panel = VelocityPanel(self.model, torch="torch" in self.capabilities)
        self.max_panel = MaxVelocityPanel(self.model)
        self.joint_panel = JointPositionPanel(self.model)
        self._video_panel = VideoPanel(self.model) if "cameras" in self.capabilities else None
        # The pad's teleop is a part of the model: under its lock, its events on this thread
        # (a core process reads the pad itself: its teleop, and its pose hook).
        self.teleop = self.control.teleop_for(
            lambda: GamepadTeleop(
                self.model,
                pad_mapping or load_pad_mapping(profile),
                calibration_for=lambda info: saved_or_default(pad_calibrations, info),
            )
        )
        if self.teleop is not getattr(self.control, "teleop", None):
            # The pad's "pose NAME" button; its word reaches the Events dock on this thread.
            self.teleop.register_hook("pose", lambda name: pose_hook(self.model, name))
        self.gamepad_panel = GamepadPanel(self.teleop, pad_calibrations)
        self._map_panel = MapPanel(self.model) if "drive" in self.capabilities else None
        self.event_log = QListWidget()
        self.event_log.setObjectName("event_log")
        self.event_log.setFocusPolicy(Qt.FocusPolicy.NoFocus)
        placeholder = QWidget()
        placeholder.setMaximumSize(0, 0)
        self.setCentralWidget(placeholder)
        self.setDockNestingEnabled(True)
        self.velocity_dock = self._dock("velocity_dock", "Velocity", self.velocity_panel)
        self.max_dock = self._dock("max_velocity_dock", "Max velocity", self.max_panel)
        self.joint_dock = self._dock("joint_position_dock", "Joint position", self.joint_panel)
        self.log_dock = self._dock("event_log_dock", "Events", self.event_log)
        self._video_dock = (
            None
            if self._video_panel is None
            else self._dock("video_dock", "Video", self._video_panel)
        )
        self.gamepad_dock = self._dock("gamepad_dock", "Gamepad", self.gamepad_panel)
        self._map_dock = (
            None if self._map_panel is None else self._dock("map_dock", "Map", self._map_panel)
        )
        self.robot_check = RobotCheckPanel(profile)
        self.robot_check_dock = self._dock("robot_check_dock", "Robot check", self.robot_check)
        # First contact (ocu calibrate) speaks the Engineer's wire: only where the hardware
        # can be calibrated so.
        self._calibration_panel: CalibrationPanel | None = None
        self._calibration_dock: QDockWidget | None = None
        if "calibration" in self.capabilities:
            panel = self._calibration_panel = CalibrationPanel(
                self.model,
                calibration_link if replay is None else None,
                Path(settings.fileName()).parent / CALIBRATED_PROFILE_NAME,
                show_joint=self._show_calibration_joint,
            )
            self._calibration_dock = self._dock("calibration_dock", "Calibration", panel)
            panel.finished.connect(lambda _result: self._after_calibration())
        self._arrange_docks()
        model_view = self.model_dock.widget()
        assert isinstance(model_view, Model3DWidget)
        self.model_view = model_view
        self.arm_panel: ArmPanel | None = None
        self.arm_dock: QDockWidget | None = None
        if self.model.arm is not None:
            self.arm_panel = ArmPanel(self.model.arm)
            self.arm_dock = self._dock("arm_dock", "Arm", self.arm_panel)
        self._arrange_joint_tabs()

        self.link_status = LinkStatus(self.model, address_text)
        self.statusBar().addPermanentWidget(self.link_status, 1)
        self.statusBar().setSizeGripEnabled(False)
        self.record_button: RecordButton | None = None
        if self.recorder is not None:
            self.record_button = RecordButton(self.recorder, parent=self)
            self.record_button.recording_started.connect(
                lambda path: self.log_event(f"recording to {path}")
            )
            self.record_button.recording_stopped.connect(
                lambda summary: self.log_event(f"recording finished: {summary}")
            )
            self.record_button.recording_failed.connect(
                lambda message: self.log_event(f"recording failed: {message}")
            )
            self.link_status.add_indicator(self.record_button)
        self.ros = RosControl(
            profile,
            self.model,
            address_text,
            before_start=lambda: self.model.halt("ROS control on"),
            log_event=self.log_event,
            parent=self,
            disabled_reason="a replay has no robot to command" if replay is not None else None,
        )
        self.link_status.add_indicator(self.ros.label)
        if self.model.arm is not None:
            self.arm_indicator = ArmModeIndicator(self.model.arm)
            self.link_status.add_indicator(self.arm_indicator)
        self.nav_status = NavStatus(self.model)
        if "drive" in self.capabilities:  # the zones and assisted modes act on the drive
            self.link_status.add_indicator(self.nav_status)
        # The controller's own mode, where the hardware reports one (a UR): hidden until then.
        self.robot_mode = RobotModeIndicator(self.model.robot)
        self.link_status.add_indicator(self.robot_mode)
        self.pad_indicator = PadIndicator(self.teleop)
        self.link_status.add_indicator(self.pad_indicator)
        self.teleop.events.message.connect(self.log_event)
        # The pad is read only on a live console: a replay commands nothing.
        self.gamepad: QtGamepad | None = None
        if (
            pad_mapping is not None
            and replay is None
            and not isinstance(self.control, RemoteControl)
        ):
            # The poll thread feeds the guarded teleop itself (ocu.windows.control).
            self.gamepad = QtGamepad(self.teleop, self, direct=True)
        self.help_overlay = HelpOverlay(
            self.model, self.key_map, self, pad_rows=self.gamepad_panel.help_rows
        )
        self._build_menu()

        self.key_filter: KeyFilter | None = None
        app = QApplication.instance()
        assert isinstance(app, QApplication)
        if replay is None:
            self.key_filter = KeyFilter(
                self.model, self.key_map, self.owns, parent=self, lock=self.control.lock
            )
            if isinstance(self.control, RemoteControl) and self.control.keys is not None:
                self.key_filter.use_reader(RemoteReader(self.control.keys))
            app.installEventFilter(self.key_filter)
        app.applicationStateChanged.connect(self._on_application_state)
        app.focusWindowChanged.connect(self._on_focus_window)

        events = self.model.events
        events.connection_changed.connect(self._on_connection)
        events.operator_acted.connect(self._on_operator_acted)
        events.message.connect(self.log_event)
        events.position_message.connect(self.log_event)
        video = self._video_panel
        if video is not None:
            video.snapshot_saved.connect(lambda path: self.log_event(f"snapshot saved: {path}"))
            video.snapshot_failed.connect(self.log_event)
        self.model.robot.events.extension_changed.connect(
            lambda active, _reason: self.log_event(
                "robot speaks the protocol extension" if active else "vendor protocol"
            )
        )
        if self.replay_controller is not None:
            self._build_replay_bar(self.replay_controller)
        self._wire_arm()
        for note in self.settings_status.notes:
            self.log_event(note)
        self.link_status.add_indicator(self.control.label)
        self.settings_label: QLabel | None = None
        if not self.settings_status.writable:
            # For the whole session, not only in the Events dock, which may be out of view.
            self.settings_label = QLabel("layout not saved")
            self.settings_label.setObjectName("settings_not_saved")
            self.settings_label.setStyleSheet("color:#b35c00;")
            self.settings_label.setToolTip("\n".join(self.settings_status.notes))
            self.link_status.add_indicator(self.settings_label)

        self.control.start()
        self.model.robot.events.telemetry_changed.connect(self.model_view.show_reading)
        self._view_timer = QTimer(self)
        self._view_timer.setInterval(VIEW_PERIOD_MS)
        self._view_timer.timeout.connect(self._view_tick)
        self._view_timer.start()

        # An explicit minimum keeps the layout from re-setting it whenever a label grows
        # (Qt's offscreen platform warns on every such change of a visible window).
        self.setMinimumSize(*MINIMUM_SIZE)
        self.resize(*DEFAULT_SIZE)
        self._default_state = self.saveState(LAYOUT_VERSION)
        self.layout_restored = self.restore_layout()
        if self.gamepad is not None:
            self.gamepad.start()
        # The stream size and rate asked of each camera are remembered between sessions.
        self.restore_streams()
        self.model.events.stream_request_changed.connect(lambda _streams: self.save_streams())
        if connect:
            self._start_link()
        else:
            self.model.set_connected(False)

    # ---- the menu and the replay bar -------------------------------------------------------

    def _build_menu(self) -> None:
        view = self.view_menu = self.menuBar().addMenu("&View")
        for dock in self.docks():
            view.addAction(dock.toggleViewAction())
        view.addSeparator()
        view.addAction(self.ros.action)
        view.aboutToShow.connect(self.ros.probe)
        view.addSeparator()
        reset = QAction("Reset layout", self)
        reset.triggered.connect(self.reset_layout)
        view.addAction(reset)
        help_action = QAction("Hotkeys (F1 or ?)", self)
        help_action.triggered.connect(lambda: hotkeys.toggle_help(self.model))
        self.menuBar().addAction(help_action)

    def _build_replay_bar(self, source: ReplayController) -> None:
        """REPLAY banner and play/seek/speed on top; every command widget disabled."""
        bar = QToolBar("Replay", self)
        bar.setObjectName("replay_toolbar")
        bar.setMovable(False)
        bar.setFloatable(False)
        bar.toggleViewAction().setEnabled(False)  # the banner cannot be hidden
        self.replay_banner = ReplayBanner(source.path)
        self.replay_controls = ReplayControls(source)
        self.replay_controls.setSizePolicy(
            QSizePolicy.Policy.Expanding, QSizePolicy.Policy.Preferred
        )
        bar.addWidget(self.replay_banner)
        bar.addWidget(self.replay_controls)
        self.addToolBar(Qt.ToolBarArea.TopToolBarArea, bar)
        self.replay_bar = bar
        disabled: list[QWidget] = [self.velocity_panel, self.max_panel]
        disabled.append(self.joint_panel.targets_panel)
        if self.arm_panel is not None:
            disabled.append(self.arm_panel)
        for widget in disabled:
            widget.setEnabled(False)
            widget.setToolTip(REPLAY_DISABLED_TIP)
        if self._map_panel is not None:
            self._map_panel.set_replay()
        # Odometry integrates recorded motion: at 4x, four robot seconds pass in one.
        self.model.nav.set_time_scale(source.speed)
        source.speed_changed.connect(self.model.nav.set_time_scale)
        self.link_status.set_replay()

    # ---- the views a capability brings ----------------------------------------------------

    def has(self, capability: str) -> bool:
        """Whether the window was built for hardware with this capability."""
        return capability in self.capabilities

    @property
    def calibration_panel(self) -> CalibrationPanel:
        """The Calibration dock's panel (hardware calibrated over its wire only)."""
        return _present(self._calibration_panel, "calibration", "Calibration panel")

    @property
    def calibration_dock(self) -> QDockWidget:
        """The Calibration dock (hardware calibrated over its wire only)."""
        return _present(self._calibration_dock, "calibration", "Calibration dock")

    @property
    def video_panel(self) -> VideoPanel:
        """The Video dock's panel (hardware with cameras only)."""
        return _present(self._video_panel, "cameras", "Video panel")

    @property
    def video_dock(self) -> QDockWidget:
        """The Video dock (hardware with cameras only)."""
        return _present(self._video_dock, "cameras", "Video dock")

    @property
    def map_panel(self) -> MapPanel:
        """The Map dock's panel (hardware that drives only)."""
        return _present(self._map_panel, "drive", "Map panel")

    @property
    def map_dock(self) -> QDockWidget:
        """The Map dock (hardware that drives only)."""
        return _present(self._map_dock, "drive", "Map dock")

    # ---- link ------------------------------------------------------------------------------

    def _start_link(self) -> None:
        if self.link is not None or self._shut:
            return
        if self._calibration_panel is not None and self._calibration_panel.running:
            # One client commands the robot at a time: the calibration has its own link.
            self.log_event("a calibration runs: the console connects when it ends")
            return
        if self.replay is not None:
            link: Link = self.replay
        else:
            assert self.link_factory is not None
            link = self.link_factory()
        if not link.read_only:
            # Subscribed before any datagram flows.
            if self.recorder is not None:
                self.recorder.attach(link)
            self.ros.link_started(link)
        # The control thread reads and writes the robot as a hardware component, tells it it
        # is alive and takes its telemetry; QtLink hands its video and events to the views.
        qt = QtLink(link, self, heartbeat=False)
        self.model.robot.on_link_state(LinkState.CONNECTING, "connecting")
        self.control.attach(self.hardware_for(link))  # subscribed before any datagram flows
        qt.link_state_changed.connect(self._on_link_state)
        qt.safety_event.connect(self._on_safety_event)
        self.link = qt
        if self._video_panel is not None:
            self._video_panel.set_link(qt)
        self.robot_check.attach(link)  # subscribed before any datagram flows
        self.link_graphs.attach(link)  # and the operator's command rate applied
        qt.start()
        self.log_event("replay started" if link.read_only else "link started")

    def _after_calibration(self) -> None:
        """Connect now if the operator asked for it while the calibration ran."""
        if self.model.connected and self.link is None:
            self._start_link()

    def _stop_link(self) -> None:
        qt, self.link = self.link, None
        if qt is None:
            return
        if self._video_panel is not None:
            self._video_panel.set_link(None)
        self.robot_check.attach(None)
        self.link_graphs.attach(None)
        if not qt.read_only:
            self.ros.link_stopping()  # ROS lets go (zeroing what it moved) before the zeros
        qt.shutdown()  # zeros last
        self.control.detach()
        if self.recorder is not None:
            self.recorder.detach(qt.link)
        self.model.robot.on_link_state(LinkState.CLOSED, "disconnected by the operator")
        self.log_event("replay stopped" if qt.read_only else "link stopped (zeros sent last)")

    def _on_connection(self, connected: bool) -> None:
        if connected:
            self._start_link()
        else:
            self._stop_link()

    def _on_operator_acted(self) -> None:
        self.ros.override("operator")

    def _override_ros(self, reason: str) -> None:
        """ROS loses control at once; the channels it drove stop."""
        self.ros.override(reason)
        self.model.clear_external()

    def _is_current_link(self) -> bool:
        # Queued signals of a link stopped meanwhile may still arrive; they are stale.
        return self.link is not None and self.sender() is self.link

    def _view_tick(self) -> None:
        """The 3D view: the pose predicted now, and where the last reading put the arm."""
        last = self.model.robot.last_telemetry_at
        if last is not None:
            predicted = self.model.predicted_angles(time.monotonic())
            self.model_view.set_joint_angles(predicted, fresh_at=last)
        if self.arm_panel is not None:
            self.arm_panel.refresh()
            self.model_view.pick_height_m = self.arm_panel.pick_height_m()

    # ---- the arm ---------------------------------------------------------------------------

    def _wire_arm(self) -> None:
        """The arm's model to the 3D view and the log; the 3D view's picks to the Arm dock."""
        self.model.events.targets_changed.connect(lambda _targets: self._update_ghost())
        arm = self.model.arm
        if arm is None:
            if self.model.arm_error:
                self.log_event(self.model.arm_error)
            return
        assert self.arm_panel is not None
        for problem in arm.poses.problems:  # also in the Arm dock, which may be out of view
            self.log_event(f"stored arm poses: {problem}")
        view = self.model_view
        workspace = arm.kinematics.workspace_slice()
        if workspace is not None:
            view.set_workspace(*workspace)
        arm.events.workspace_changed.connect(view.set_workspace_visible)
        arm.events.jog_changed.connect(view.set_jog_direction)
        arm.events.goal_changed.connect(self._on_arm_goal)
        view.point_picked.connect(self.arm_panel.on_point_picked)

    def _on_arm_goal(self, goal: ArmGoal | None) -> None:
        arm = self.model.arm
        assert arm is not None
        pose = None
        if goal is not None:
            pose = arm.kinematics.tool_matrix(arm.kinematics.vector(goal.joints))
        self.model_view.set_goal_pose(pose)
        self._update_ghost()

    def _show_calibration_joint(self, name: str | None) -> None:
        """The 3D model's ghost with one joint turned (the calibration asks if it moved)."""
        if name is None:
            self._update_ghost()
        else:
            self.model_view.set_ghost({name: math.radians(CALIBRATION_GHOST_DEG)})

    def _update_ghost(self) -> None:
        """The ghost: position targets and the arm's goal together."""
        ghost = dict(self.model.targets)
        arm = self.model.arm
        if arm is not None and arm.goal is not None:
            ghost.update(arm.goal.joints)
        self.model_view.set_ghost(ghost or None)

    def _on_link_state(self, state: LinkState, reason: str) -> None:
        if not self._is_current_link():
            return
        self.log_event(f"link {state.value}: {reason}")
        if state == LinkState.LOST:
            # The control thread halted the model already (ocu.core.feed).
            self._override_ros("link lost")

    def _on_safety_event(self, message: str) -> None:
        self.log_event(f"link: {message}")
        # The link zeroed the command by itself (watchdog, link lost): the control thread
        # halted the model (ocu.core.feed); ROS agrees, so nothing resumes when it comes back.
        self._override_ros(message)

    # ---- closing ---------------------------------------------------------------------------

    def closeEvent(self, event: QCloseEvent) -> None:
        """Stop, remember the layout, close the link (zeros last)."""
        self.shutdown()
        super().closeEvent(event)

    def shutdown(self) -> None:
        """Stop all motion and the link; idempotent (closeEvent and aboutToQuit both call it)."""
        if self._shut:
            return
        if self.gamepad is not None:
            self.gamepad.shutdown()  # no pad state arrives after the halt
        if self.key_filter is not None:
            self.key_filter.shutdown()  # no key acts after the halt either
        if self._calibration_panel is not None:
            self._calibration_panel.shutdown()  # its link's zeros before the window goes
        self.model.halt("console closed")
        self.control.shutdown()
        self._view_timer.stop()
        self.model_view.release()  # the 3D view's render thread ends with the window
        app = QApplication.instance()
        if isinstance(app, QApplication):
            app.applicationStateChanged.disconnect(self._on_application_state)
            app.focusWindowChanged.disconnect(self._on_focus_window)
        self._stop_link()  # the link's closing zeros land in a recording
        self.control.end()  # a core process ends after its link's shutdown
        self.save_layout()  # after the link: a disk that stalls a sync delays no stop
        self.ros.shutdown()
        if self.record_button is not None:
            self.record_button.stop_recording()
        self._shut = True

    # ---- messages --------------------------------------------------------------------------

    def log_event(self, text: str) -> None:
        """A line in the Events dock and the status bar (and the log)."""
        stamp = time.strftime("%H:%M:%S")
        now = time.monotonic()
        self.statusBar().showMessage(text, 8000)
        rows = self.event_log.count()
        for row in range(rows - 1, max(rows - EVENT_REPEAT_ROWS, 0) - 1, -1):
            item = self.event_log.item(row)
            seen = item.data(_EVENT_ROLE)  # [text, when, how many times]
            if seen and seen[0] == text and now - float(seen[1]) < EVENT_REPEAT_S:
                count = int(seen[2]) + 1
                item.setData(_EVENT_ROLE, [text, now, count])
                item.setText(f"{stamp}  {text} (×{count})")
                return
        self.event_log.addItem(f"{stamp}  {text}")
        self.event_log.item(rows).setData(_EVENT_ROLE, [text, now, 1])
        while self.event_log.count() > EVENT_LOG_LENGTH:
            self.event_log.takeItem(0)
        self.event_log.scrollToBottom()
        log.info("%s", text)

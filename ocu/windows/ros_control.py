"""The console's "ROS control" toggle: hosts the ROS 1 bridge beside the operator.

ROS may command the robot only while the toggle is on, and the operator always wins: any
key, slider, switch, typed value, target or Space overrides ROS at once (the toggle then
unchecks itself; turning it on again hands control back). ROS's velocities go into the console
model like any other input (queued to the GUI thread), so the link has one command and one
commander; a stalled GUI stops ROS too. rospy is imported only when the toggle is first
turned on, so the console runs and starts without ROS.

The toggle is enabled only when Debian's ROS 1 is installed and a ROS master answers; the
master is probed on a short-lived thread (a remote master may take a second to time out,
longer than the GUI may stall while the robot moves), at start and whenever the menu opens.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING

from PySide6.QtCore import QObject, Signal
from PySide6.QtGui import QAction
from PySide6.QtWidgets import QWidget

from ocu.console.channels import Source
from ocu.console.model import ConsoleModel
from ocu.link.base import Link
from ocu.profile import RobotProfile
from ocu.qt.inbox import to_gui
from ocu.records import CommandError
from ocu.ros.diagnostics import STATE_TEXT, BridgeState
from ocu.ros.environment import master_online, master_uri, missing_ros
from ocu.widgets.elided_label import ElidedLabel

if TYPE_CHECKING:
    from ocu.ros.rosbridge import RosBridge

log = logging.getLogger("ocu.console")

NODE_NAME = "ocu_console"
PROBE_TIMEOUT_S = 1.0
PROBE_JOIN_S = 2.0
ACTION_TEXT = "ROS control (cmd_vel, joint_goals)"
LABEL_BLOCK = "font-weight:bold;font-size:13pt;padding:3px 10px;border-radius:4px;"
STATE_STYLES = {
    BridgeState.LISTENING: "background:#1565c0;color:white;",
    BridgeState.COMMANDING: "background:#6a1b9a;color:white;font-size:15pt;",
    BridgeState.OVERRIDDEN: "background:#78909c;color:white;",
}
SHORT_TEXT = {
    BridgeState.LISTENING: "ROS on · waiting",
    BridgeState.COMMANDING: "ROS is commanding the robot",
    BridgeState.OVERRIDDEN: "ROS overridden",
}


Ends = tuple[dict[str, float], dict[str, float]]  # until, goals (Command.until, .goals)


class _ModelSink:
    """Where the hosted bridge's velocities go: into the model, on the GUI thread; with the
    ends and goals of its arm's timed move when the hardware takes one (ocu.control.arm_timed:
    the console's arm knows, the control manager told it)."""

    def __init__(
        self, post: Callable[[tuple[dict[str, float], Ends]], None], timed: Callable[[], bool]
    ) -> None:
        self._post = post
        self._timed = timed
        self._ends: Ends = ({}, {})

    @property
    def timed_moves(self) -> bool:
        """Whether the hardware runs a position command with a duration."""
        return self._timed()

    def set_ends(self, until: Mapping[str, float], goals: Mapping[str, float]) -> None:
        """The ends and goals that go with the next velocities."""
        self._ends = (dict(until), dict(goals))

    def set_velocities(self, **velocities: float) -> None:
        self._post((dict(velocities), self._ends))


class RosControl(QObject):
    """The toggle (`action`), the status-bar label (`label`) and the bridge behind them."""

    # From bridge and rospy threads: handed to the GUI thread (ocu.qt.inbox.to_gui).
    state_changed = Signal(object, str)
    _probed = Signal(object)
    _velocities = Signal(object)
    _path = Signal(object)

    def __init__(
        self,
        profile: RobotProfile,
        model: ConsoleModel,
        hardware_id: str,
        *,
        before_start: Callable[[], object],
        log_event: Callable[[str], None],
        parent: QWidget,
        disabled_reason: str | None = None,
    ) -> None:
        super().__init__(parent)
        self.profile = profile
        self.model = model
        self.hardware_id = hardware_id
        self.before_start = before_start
        self.log_event = log_event
        self.bridge: RosBridge | None = None
        self.link: Link | None = None
        self.unavailable: str | None = disabled_reason or "checking for a ROS master"
        self._fixed_reason = disabled_reason
        self._probe_thread: threading.Thread | None = None
        self._shut = False

        self.action = QAction(ACTION_TEXT, parent)
        self.action.setObjectName("ros_control_action")
        self.action.setCheckable(True)
        self.action.triggered.connect(self._on_triggered)
        # Shortened where the status bar is short of room (the whole state in its tooltip).
        self.label = ElidedLabel(floor_text="ROS on")
        self.label.setObjectName("ros_state")
        self.label.hide()
        self.state_changed.connect(self._on_state)
        self._probed.connect(self._on_probed)
        self._velocities.connect(self._apply_velocities)
        self._path.connect(self._follow_path)
        self._sink = _ModelSink(to_gui(self._velocities.emit), self._timed_moves)
        self._show_availability()
        self.probe()

    # ---- availability ----------------------------------------------------------------------

    def probe(self) -> None:
        """Check again whether ROS can be used (packages now, the master on a thread)."""
        if self._fixed_reason is not None or self._shut:
            return
        if self._probe_thread is not None and self._probe_thread.is_alive():
            return
        missing = missing_ros()
        if missing is not None:
            self._on_probed(missing)
            return
        uri = master_uri()
        probed = to_gui(self._probed.emit)

        def run() -> None:
            online = master_online(uri, timeout_s=PROBE_TIMEOUT_S)
            probed(None if online else f"no ROS master at {uri} (start roscore)")

        self._probe_thread = threading.Thread(target=run, name="ocu-ros-probe", daemon=True)
        self._probe_thread.start()

    def _on_probed(self, reason: str | None) -> None:
        self.unavailable = reason
        self._show_availability()

    def _show_availability(self) -> None:
        # A running bridge stays switchable off even if the master went away meanwhile.
        usable = self.unavailable is None or self.action.isChecked()
        self.action.setEnabled(usable)
        if self.unavailable is None:
            self.action.setToolTip(
                "Let ROS drive through cmd_vel and joint_goals; any operator input overrides"
            )
        else:
            self.action.setToolTip(f"ROS control unavailable: {self.unavailable}")

    # ---- the link --------------------------------------------------------------------------

    def link_started(self, link: Link) -> None:
        """A new link, not started yet: the bridge subscribes to it when turned on."""
        self.link = link

    def link_stopping(self) -> None:
        """The link is about to shut down: ROS lets go first (zeros what it moved)."""
        self.link = None
        if self.bridge is not None:
            self.bridge.stop()
        self.model.clear_external()
        self.action.setChecked(False)
        self._show_availability()

    def _timed_moves(self) -> bool:
        arm = self.model.arm
        return arm is not None and bool(arm.controller.timed_moves)

    def _apply_velocities(self, command: tuple[dict[str, float], Ends]) -> None:
        # GUI thread. A command the bridge sent before it was overridden may still be queued:
        # only a bridge in control may move the robot.
        if not self.in_control:
            return
        velocities, (until, goals) = command
        try:
            self.model.set_source_ends(Source.ROS, until, goals)
            self.model.set_external_velocities(velocities)
        except CommandError as err:
            log.warning("ROS command refused: %s", err)

    # ---- control ---------------------------------------------------------------------------

    @property
    def state(self) -> BridgeState:
        """off, listening, commanding or overridden."""
        return self.bridge.state if self.bridge is not None else BridgeState.OFF

    @property
    def in_control(self) -> bool:
        """Whether ROS may move the robot now (listening or commanding)."""
        return self.state in (BridgeState.LISTENING, BridgeState.COMMANDING)

    def override(self, reason: str) -> bool:
        """The operator takes over; True if ROS had control (the caller then sends)."""
        return self.bridge is not None and self.bridge.override(reason)

    def _on_triggered(self, checked: bool) -> None:
        if not checked:
            if self.bridge is not None:
                self.bridge.stop()
            self.model.clear_external()
            return
        refusal = self._refusal()
        if refusal is None:
            try:
                self._turn_on()
            except Exception as err:  # rospy raises its own exception types
                log.exception("ROS control could not start")
                refusal = f"could not start: {err}"
        if refusal is not None:
            self.action.setChecked(False)
            self.log_event(f"ROS control: {refusal}")

    def _refusal(self) -> str | None:
        if self.unavailable is not None:
            return self.unavailable
        if self.link is None:
            return "connect to the robot first"
        return None

    def _turn_on(self) -> None:
        link = self.link
        assert link is not None
        bridge = self.bridge
        if bridge is None:
            bridge = self.bridge = self._make_bridge()
        # Turning ROS on is the operator's deliberate act: it releases a latched e-stop, as
        # any other input of theirs does (ROS velocities are held at zero while latched).
        self.model.release_estop()
        if bridge.started:
            bridge.enable()  # back after an override
            return
        # One commander at a time: the operator's own motion stops before ROS takes over.
        self.before_start()
        bridge.start(link, self.model.limits, sink=self._sink)

    def _make_bridge(self) -> RosBridge:
        import rospy

        from ocu.ros.rosbridge import RosBridge
        from ocu.ros.topics import init_node

        if rospy.core.is_shutdown():
            raise RuntimeError("rospy was shut down in this process")
        if not rospy.core.is_initialized():
            init_node(NODE_NAME, anonymous=True)  # rospy allows one node per process
        arm = self.model.arm
        # The model feeds its own navigator; the bridge publishes from it (odom, tf, scan),
        # hands it other nodes' scans and passes /follow_path to the model's path mode.
        return RosBridge(
            self.profile,
            hardware_id=self.hardware_id,
            on_state_changed=to_gui(self.state_changed.emit),
            arm_poses_path=arm.poses.path if arm is not None else None,
            navigator=self.model.nav,
            feed_navigator=False,
            on_path=to_gui(self._path.emit),
        )

    def _follow_path(self, points: list[tuple[float, float]]) -> None:
        """/follow_path while ROS has control: the model's path mode, a planner's input."""
        if self.bridge is None or self.bridge.state not in (
            BridgeState.LISTENING,
            BridgeState.COMMANDING,
        ):
            self.log_event("ROS follow_path ignored: ROS control is not on")
            return
        try:
            self.model.start_path(points, external=True)
        except CommandError as err:
            self.log_event(f"ROS follow_path refused: {err}")

    def _on_state(self, state: BridgeState, text: str) -> None:
        if self.bridge is None:
            return
        current = self.bridge.state  # queued: show the state now, not the one reported
        self.action.setChecked(current in (BridgeState.LISTENING, BridgeState.COMMANDING))
        self._show_availability()
        style = STATE_STYLES.get(current)
        if style is None:
            self.label.hide()
        else:
            self.label.setText(SHORT_TEXT[current])
            self.label.setToolTip(STATE_TEXT[current])
            self.label.setStyleSheet(style + LABEL_BLOCK)
            self.label.show()
        self.log_event(f"ROS control: {text}")

    def shutdown(self) -> None:
        """Stop the bridge and wait for a probe in flight; idempotent."""
        self._shut = True
        if self.bridge is not None:
            self.bridge.stop()
        self._velocities.disconnect(self._apply_velocities)
        self._path.disconnect(self._follow_path)
        thread, self._probe_thread = self._probe_thread, None
        if thread is not None:
            thread.join(PROBE_JOIN_S)

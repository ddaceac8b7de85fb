"""The Arm dock and the status bar's arm indicator: Cartesian mode, jog frame and speeds, the
tool's pose, pose goals (typed or picked in the 3D view, a ghost before Accept; x, y, z and
pitch, or for an arm of six joints or more x, y, z, roll, pitch, yaw), stored poses.

A view of `ConsoleModel.arm` (ocu.console.arm): it subscribes to the arm's events and writes
the operator's input back to it; nothing here moves the robot by itself.
"""

from __future__ import annotations

import math

from PySide6.QtCore import Qt
from PySide6.QtWidgets import (
    QComboBox,
    QGridLayout,
    QGroupBox,
    QHBoxLayout,
    QLabel,
    QLineEdit,
    QListWidget,
    QPushButton,
    QVBoxLayout,
    QWidget,
)

from ocu.console.arm import ArmConsole, ArmGoal
from ocu.console.poses import PoseError
from ocu.control.arm import OK, SLOW, STOP, ArmStatus
from ocu.kinematics.analytic import BRANCHES
from ocu.kinematics.arm import ArmError, ToolPose
from ocu.kinematics.rpy import describe_pose, pose_from_rpy, rpy_of
from ocu.model.tree import Matrix
from ocu.widgets.number_box import NumberBox, NumberError, format_number
from ocu.windows.velocity import ERROR_TEXT_STYLE

MODE_STYLES = {
    False: "background:#37474f;color:white;font-weight:bold;font-size:13pt;padding:3px 10px;",
    True: "background:#6a1b9a;color:white;font-weight:bold;font-size:13pt;padding:3px 10px;",
}
STATUS_STYLES = {
    OK: "color:#2e7d32;font-weight:bold;",
    SLOW: "color:#b26a00;font-weight:bold;",
    STOP: "color:white;background:#c62828;font-weight:bold;padding:2px 4px;",
}
NEAREST = "nearest"
# Space cannot be typed into the name box: it is the e-stop everywhere (docs/console.md).
NAME_HINT = "Space is the e-stop: join words with _ or - (over_the_box)"
REACH_MM = 1500.0


def mode_text(arm: ArmConsole) -> str:
    """'JOINT' or 'CARTESIAN · tool' for the status bar."""
    return f"CARTESIAN · {arm.frame}" if arm.cartesian else "JOINT"


class ArmModeIndicator(QLabel):
    """Always visible in the status bar: joint or Cartesian mode, and the jog frame."""

    def __init__(self, arm: ArmConsole, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.setObjectName("arm_mode")
        self.arm = arm
        self.setToolTip("Arm mode (C): the driving keys move the joints, or the gripper (V: frame)")
        arm.events.mode_changed.connect(lambda _on: self.refresh())
        arm.events.frame_changed.connect(lambda _frame: self.refresh())
        self.refresh()

    def refresh(self) -> None:
        """Show the mode and frame."""
        self.setText(mode_text(self.arm))
        self.setStyleSheet(MODE_STYLES[self.arm.cartesian])


class ArmPanel(QWidget):
    """The Arm dock; see the module docstring."""

    def __init__(self, arm: ArmConsole, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.setObjectName("arm_panel")
        self.arm = arm
        settings = arm.settings
        layout = QVBoxLayout(self)
        layout.setContentsMargins(4, 4, 4, 4)

        # Mode, frame, branch and speeds.
        top = QGridLayout()
        self.mode_button = QPushButton()
        self.mode_button.setObjectName("arm_mode_button")
        self.mode_button.setCheckable(True)
        self.mode_button.setFocusPolicy(Qt.FocusPolicy.NoFocus)
        self.mode_button.clicked.connect(arm.set_cartesian)
        self.frame_box = QComboBox()
        self.frame_box.setObjectName("arm_frame")
        self.frame_box.addItems(list(arm.frames))
        self.frame_box.setFocusPolicy(Qt.FocusPolicy.NoFocus)
        self.frame_box.setToolTip("Jog frame (V): base, tool (the gripper) or camera")
        self.frame_box.currentTextChanged.connect(self._on_frame)
        self.elbow_box = QComboBox()
        self.elbow_box.setObjectName("arm_elbow")
        self.elbow_box.addItems([NEAREST, *BRANCHES])
        self.elbow_box.setFocusPolicy(Qt.FocusPolicy.NoFocus)
        self.elbow_box.setToolTip("Which IK branch a pose goal takes (nearest: least motion)")
        self.elbow_box.currentTextChanged.connect(self._on_elbow)
        self.linear_box = NumberBox(0.0, settings.max_linear_speed_m_s * 1000.0, "mm/s", 0)
        self.linear_box.setObjectName("arm_linear_speed")
        self.linear_box.setFixedWidth(64)
        self.linear_box.returnPressed.connect(self._on_speeds)
        max_pitch = math.degrees(settings.max_pitch_speed_rad_s)
        self.pitch_box = NumberBox(0.0, max_pitch, "°/s", 0)
        self.pitch_box.setObjectName("arm_pitch_speed")
        self.pitch_box.setFixedWidth(56)
        self.pitch_box.returnPressed.connect(self._on_speeds)
        top.addWidget(self.mode_button, 0, 0, 1, 2)
        top.addWidget(QLabel("frame"), 0, 2)
        top.addWidget(self.frame_box, 0, 3)
        top.addWidget(QLabel("goal IK"), 0, 4)
        top.addWidget(self.elbow_box, 0, 5)
        top.addWidget(QLabel("jog"), 1, 0)
        top.addWidget(self.linear_box, 1, 1)
        # Six joints or more: the same speed turns the tool about any axis (roll, pitch, yaw).
        top.addWidget(QLabel("mm/s  turn" if arm.whole_pose else "mm/s  pitch"), 1, 2)
        top.addWidget(self.pitch_box, 1, 3)
        speeds_hint = QLabel("°/s  (N slower, M faster, Shift fine)")
        speeds_hint.setStyleSheet("color:#666;")
        top.addWidget(speeds_hint, 1, 4, 1, 2)
        top.setColumnStretch(6, 1)
        layout.addLayout(top)

        # The tool now and the arm's state.
        self.pose_label = QLabel("tool0: —")
        self.pose_label.setObjectName("arm_tool_pose")
        self.status_label = QLabel("arm idle")
        self.status_label.setObjectName("arm_status")
        self.status_label.setWordWrap(True)
        layout.addWidget(self.pose_label)
        layout.addWidget(self.status_label)

        # Pose goal.
        # Six joints or more (a UR): the whole orientation, as roll, pitch, yaw (ROS's RPY).
        self.whole = arm.whole_pose
        goal_group = QGroupBox(
            "Pose goal: tool0 in the base frame"
            + (" (roll, pitch, yaw about its fixed x, y, z)" if self.whole else "")
        )
        goal_layout = QGridLayout(goal_group)
        self.goal_boxes: dict[str, NumberBox] = {}
        angles = ("roll", "pitch", "yaw") if self.whole else ("pitch",)
        fields = (("x", "mm"), ("y", "mm"), ("z", "mm"), *((a, "°") for a in angles))
        for column, (name, unit) in enumerate(fields):
            low, high = (-180.0, 180.0) if unit == "°" else (-REACH_MM, REACH_MM)
            box = NumberBox(low, high, unit, 0 if unit == "mm" else 1)
            box.setObjectName(f"arm_goal_{name}")
            box.setFixedWidth(64)
            box.returnPressed.connect(self.preview)
            goal_layout.addWidget(QLabel(f"{name} {unit}"), 0, column)
            goal_layout.addWidget(box, 1, column)
            self.goal_boxes[name] = box
        self.here_button = QPushButton("From tool")
        self.here_button.setToolTip("Fill the boxes with where tool0 is now")
        self.here_button.clicked.connect(self.fill_from_tool)
        self.preview_button = QPushButton("Preview")
        self.preview_button.setObjectName("arm_preview")
        self.preview_button.setToolTip("Solve and check the goal; the ghost shows it (Enter)")
        self.preview_button.clicked.connect(self.preview)
        self.accept_button = QPushButton("Accept")
        self.accept_button.setObjectName("arm_accept")
        self.accept_button.setToolTip("Move to the goal shown, all joints together (B)")
        self.accept_button.clicked.connect(self.accept)
        self.cancel_button = QPushButton("Cancel")
        self.cancel_button.setObjectName("arm_cancel")
        self.cancel_button.clicked.connect(arm.cancel_goal)
        buttons = QHBoxLayout()
        for button in (self.here_button, self.preview_button, self.accept_button,
                       self.cancel_button):  # fmt: skip
            button.setFocusPolicy(Qt.FocusPolicy.NoFocus)
            buttons.addWidget(button)
        goal_layout.addLayout(buttons, 2, 0, 1, len(fields))
        pick_hint = QLabel("Ctrl+click in the 3D view picks x, y at the height typed in z.")
        pick_hint.setStyleSheet("color:#666;")
        goal_layout.addWidget(pick_hint, 3, 0, 1, 4)
        layout.addWidget(goal_group)

        # Stored poses.
        poses_group = QGroupBox("Stored poses (F2 stow, F3 ready, F4 look forward, F5 look back)")
        poses_layout = QGridLayout(poses_group)
        self.pose_list = QListWidget()
        self.pose_list.setObjectName("arm_poses")
        self.pose_list.setFocusPolicy(Qt.FocusPolicy.NoFocus)
        self.pose_list.setMaximumHeight(96)
        self.pose_list.itemDoubleClicked.connect(lambda _item: self.go_selected())
        self.go_button = QPushButton("Go")
        self.go_button.setObjectName("arm_go")
        self.go_button.clicked.connect(self.go_selected)
        self.show_button = QPushButton("Show")
        self.show_button.setToolTip("Show the pose as a ghost; Accept moves there")
        self.show_button.clicked.connect(self.show_selected)
        self.name_box = QLineEdit()
        self.name_box.setObjectName("arm_pose_name")
        self.name_box.setPlaceholderText("name, e.g. over_the_box")
        self.name_box.setToolTip(NAME_HINT)
        self.name_box.returnPressed.connect(self.save_pose)
        self.save_button = QPushButton("Save here")
        self.save_button.setObjectName("arm_save_pose")
        self.save_button.setToolTip(f"Store where the arm is now under the name ({arm.poses.path})")
        self.save_button.clicked.connect(self.save_pose)
        self.delete_button = QPushButton("Delete")
        self.delete_button.clicked.connect(self.delete_selected)
        for button in (self.go_button, self.show_button, self.save_button, self.delete_button):
            button.setFocusPolicy(Qt.FocusPolicy.NoFocus)
        poses_layout.addWidget(self.pose_list, 0, 0, 3, 1)
        poses_layout.addWidget(self.go_button, 0, 1)
        poses_layout.addWidget(self.show_button, 1, 1)
        poses_layout.addWidget(self.delete_button, 2, 1)
        poses_layout.addWidget(self.name_box, 3, 0)
        poses_layout.addWidget(self.save_button, 3, 1)
        name_hint = QLabel(NAME_HINT)
        name_hint.setObjectName("arm_pose_name_hint")
        name_hint.setWordWrap(True)
        name_hint.setStyleSheet("color:#666;")
        poses_layout.addWidget(name_hint, 4, 0, 1, 2)
        layout.addWidget(poses_group)

        self.message_label = QLabel(arm.poses.error)
        self.message_label.setObjectName("arm_message")
        self.message_label.setWordWrap(True)
        if arm.poses.error:
            self.message_label.setStyleSheet(ERROR_TEXT_STYLE)
        layout.addWidget(self.message_label)
        layout.addStretch(1)

        events = arm.events
        events.mode_changed.connect(lambda _on: self._show_mode())
        events.frame_changed.connect(self._show_frame)
        events.speed_changed.connect(self._show_speeds)
        events.status_changed.connect(self.show_status)
        events.poses_changed.connect(self._show_poses)
        events.goal_changed.connect(self._show_goal)
        events.message.connect(self.show_message)
        self._show_mode()
        self._show_speeds(arm.linear_speed_m_s, arm.pitch_speed_rad_s)
        self._show_poses(arm.poses.names)
        self.show_status(arm.status)

    # ---- operator -> arm ---------------------------------------------------------------

    def _on_frame(self, frame: str) -> None:
        if frame and frame != self.arm.frame:
            self.arm.set_frame(frame)

    def _on_elbow(self, text: str) -> None:
        self.arm.elbow = None if text == NEAREST else text

    def _on_speeds(self) -> None:
        try:
            linear = self.linear_box.value() / 1000.0
            pitch = math.radians(self.pitch_box.value())
        except NumberError as err:
            self.show_error(str(err))
            return
        self.arm.set_speeds(linear, pitch)
        self.linear_box.setModified(False)
        self.pitch_box.setModified(False)

    def goal_pose(self) -> ToolPose | Matrix:
        """The typed goal (the whole pose where the arm takes one); NumberError (shown on its
        box) if one is not a number."""
        values = {name: box.value() for name, box in self.goal_boxes.items()}
        x, y, z = (values[axis] / 1000.0 for axis in "xyz")
        if self.whole:
            roll, pitch, yaw = (math.radians(values[a]) for a in ("roll", "pitch", "yaw"))
            return pose_from_rpy((x, y, z), (roll, pitch, yaw))
        return ToolPose(x, y, z, math.radians(values["pitch"]))

    def preview(self) -> ArmGoal | None:
        """Solve the typed goal and show it as a ghost."""
        try:
            goal = self.arm.preview_pose(self.goal_pose())
        except NumberError as err:
            self.show_error(f"goal not solved — {err}")
            return None
        except ArmError as err:
            self.show_error(f"goal refused — {err}")
            return None
        self.show_message(
            f"goal {goal.label}: {goal.duration_s:.1f} s; Accept (B) to move, Cancel to drop"
        )
        return goal

    def accept(self) -> None:
        """Move to the goal shown (previewing the typed one first when none is shown)."""
        if self.arm.goal is None and self.preview() is None:
            return
        try:
            self.arm.accept()
        except ArmError as err:
            self.show_error(f"not moved — {err}")

    def fill_from_tool(self) -> None:
        """The boxes take where tool0 is now."""
        pose = self.arm.tool_matrix() if self.whole else self.arm.tool_pose()
        if pose is None:
            self.show_error("tool0 unknown: no reading of every arm joint yet")
            return
        self.set_goal_boxes(pose)

    def set_goal_boxes(self, pose: ToolPose | Matrix) -> None:
        """Show a pose in the goal boxes."""
        if isinstance(pose, ToolPose):
            values = {"x": pose.x * 1000, "y": pose.y * 1000, "z": pose.z * 1000,
                      "pitch": math.degrees(pose.pitch)}  # fmt: skip
        else:
            x, y, z = (float(v) * 1000 for v in pose[:3, 3])
            roll, pitch, yaw = (math.degrees(v) for v in rpy_of(pose))
            values = {"x": x, "y": y, "z": z, "roll": roll, "pitch": pitch, "yaw": yaw}
        for name, value in values.items():
            if name in self.goal_boxes:
                self.goal_boxes[name].reset_value(value)
                self.goal_boxes[name].setModified(True)

    def pick_height_m(self) -> float:
        """The height a pick in the 3D view lands on: the z box, else the tool's."""
        try:
            return self.goal_boxes["z"].value() / 1000.0
        except NumberError:
            self.goal_boxes["z"].set_error("")
            pose = self.arm.tool_pose()
            return pose.z if pose is not None else 0.3

    def on_point_picked(self, x_m: float, y_m: float, z_m: float) -> None:
        """A point picked in the 3D view: x, y (and z) into the boxes, then a preview."""
        if self.whole and not all(self.goal_boxes[a].text().strip() for a in ("roll", "yaw")):
            # The orientation the tool has now: a pick moves it, it does not turn it.
            matrix = self.arm.tool_matrix()
            if matrix is not None:
                self.set_goal_boxes(matrix)
        for name, value in (("x", x_m * 1000), ("y", y_m * 1000), ("z", z_m * 1000)):
            self.goal_boxes[name].reset_value(value)
        if not self.goal_boxes["pitch"].text().strip():
            self.goal_boxes["pitch"].reset_value(-45.0)
        self.preview()

    def selected_pose(self) -> str | None:
        """The stored pose selected in the list."""
        item = self.pose_list.currentItem()
        return item.text() if item is not None else None

    def go_selected(self) -> None:
        """Move to the selected stored pose."""
        name = self.selected_pose()
        if name is None:
            self.show_error("select a pose first")
            return
        try:
            self.arm.go_to(name)
        except ArmError as err:
            self.show_error(f"{name}: not moved — {err}")

    def show_selected(self) -> None:
        """Show the selected stored pose as the goal."""
        name = self.selected_pose()
        if name is None:
            self.show_error("select a pose first")
            return
        try:
            self.arm.preview_named(name)
        except ArmError as err:
            self.show_error(f"{name}: {err}")

    def save_pose(self) -> None:
        """Store where the arm is under the typed name."""
        try:
            self.arm.save_pose(self.name_box.text())
        except PoseError as err:
            self.show_error(f"not saved — {err}")
            return
        self.name_box.clear()

    def delete_selected(self) -> None:
        """Forget the selected operator pose."""
        name = self.selected_pose()
        if name is None:
            self.show_error("select a pose first")
            return
        try:
            self.arm.delete_pose(name)
        except PoseError as err:
            self.show_error(str(err))

    # ---- arm -> view -------------------------------------------------------------------

    def refresh(self) -> None:
        """The tool's pose now (the window calls this on its view timer)."""
        if self.whole:  # the whole pose, as the goal boxes take it
            matrix = self.arm.tool_matrix()
            text = describe_pose(matrix) if matrix is not None else None
        else:
            pose = self.arm.tool_pose()
            text = pose.describe() if pose is not None else None
        status = self.arm.status
        extra = ""
        if status.condition is not None:
            extra += f"   cond {status.condition:.0f}"
        if status.clearance_m is not None:
            extra += f"   clearance {status.clearance_m * 1000:.0f} mm"
        self.pose_label.setText(f"tool0: {text}{extra}" if text else "tool0: —")

    def show_status(self, status: ArmStatus) -> None:
        """The arm's state and why it is slowed or stopped."""
        self.status_label.setText(status.describe())
        self.status_label.setStyleSheet(STATUS_STYLES.get(status.level, ""))

    def show_message(self, text: str) -> None:
        """A line about the arm."""
        self.message_label.setStyleSheet("")
        self.message_label.setText(text)

    def show_error(self, text: str) -> None:
        """A refusal, in red."""
        self.message_label.setStyleSheet(ERROR_TEXT_STYLE)
        self.message_label.setText(text)

    def _show_mode(self) -> None:
        on = self.arm.cartesian
        self.mode_button.setChecked(on)
        self.mode_button.setText("Cartesian mode (C): ON" if on else "Cartesian mode (C): off")
        self.mode_button.setStyleSheet(MODE_STYLES[on])

    def _show_frame(self, frame: str) -> None:
        if self.frame_box.currentText() != frame:
            self.frame_box.setCurrentText(frame)

    def _show_speeds(self, linear_m_s: float, pitch_rad_s: float) -> None:
        self.linear_box.show_value(linear_m_s * 1000.0)
        self.pitch_box.show_value(math.degrees(pitch_rad_s))

    def _show_poses(self, names: tuple[str, ...]) -> None:
        current = self.selected_pose()
        self.pose_list.clear()
        self.pose_list.addItems(list(names))
        if current in names:
            self.pose_list.setCurrentRow(names.index(current))

    def _show_goal(self, goal: ArmGoal | None) -> None:
        self.accept_button.setEnabled(goal is None or not goal.accepted)
        if goal is not None and not goal.accepted:
            self.show_message(
                f"goal {goal.label}: {format_number(goal.duration_s, 1)} s; Accept (B) moves there"
            )

"""The Calibration dock: `ocu calibrate` guided from the console (docs/calibration.md).

Start disconnects the console's link and runs the `Calibrator` on a thread of its own over a
fresh raw link to the same robot; the dock is its `Operator`: it shows every step and asks
its questions with buttons, a list of joints or a text box, and the calibrator's thread
waits for the answer. Asked which joint a device is, the 3D model's ghost turns the joint
the profile says (and the one picked in the list). The robot moves only while the operator
holds the deadman: the "Hold to move" button with the mouse, or Ctrl held anywhere in the
console; letting go, or the console losing the keyboard, releases it. Space, STOP ALL and
the dock's Stop set the calibrator's stop signal. "Robot on a stand" runs the automatic
steps only with no deadman, as `--yes` does. At the end the profile is written to the file
the operator chose and the console connects again (with the profile it started with:
`ocu --profile FILE` uses the new one).
"""

from __future__ import annotations

import math
import queue
import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from PySide6.QtCore import QEvent, QObject, Qt, Signal
from PySide6.QtGui import QKeyEvent
from PySide6.QtWidgets import (
    QApplication,
    QCheckBox,
    QComboBox,
    QFileDialog,
    QHBoxLayout,
    QLabel,
    QLineEdit,
    QListWidget,
    QPushButton,
    QVBoxLayout,
    QWidget,
)

from ocu.calibrate.guard import CalibrationAbortedError, Deadman, HeldFlag, OnStand, StopSignal
from ocu.calibrate.operator import DEFAULT_DRIVE_DISTANCE, DEFAULT_DRIVE_SPEEDS, DrivePlan
from ocu.calibrate.raw import raw_profile
from ocu.calibrate.session import CalibrationResult, Calibrator
from ocu.calibrate.writer import write_calibrated_profile
from ocu.console.model import ConsoleModel
from ocu.link.base import Link, LinkError
from ocu.profile import ProfileError, RobotProfile, load_profile_data
from ocu.qt.inbox import to_gui

# A factory of links to the console's robot for a given profile (the raw profile here).
CalibrationLinkFactory = Callable[[RobotProfile], Link]

# A button whose answer is what the text box or the list holds.
FROM_ENTRY = object()
DEADMAN_KEY = Qt.Key.Key_Control


@dataclass
class Question:
    """One question of the calibrator: text, answer buttons, and an entry if it needs one."""

    text: str
    buttons: list[tuple[str, object]]
    entry: str | None = None  # "number" or "choice"
    choices: Sequence[str] = ()
    default: str = ""
    # The joint the 3D model shows while the question is asked (and the one chosen after).
    joint: str | None = None
    answer: queue.Queue[object] = field(default_factory=queue.Queue)


class DockOperator(QObject):
    """The `Operator` the calibrator asks (its thread); the dock answers (the GUI thread)."""

    asked = Signal(object)
    said = Signal(str)

    def __init__(self, stop: StopSignal, *, guided: bool) -> None:
        super().__init__()
        self.stop = stop
        self._guided = guided
        # Made on the GUI thread, called on the calibrator's: handed over by the inbox.
        self._asked = to_gui(self.asked.emit)
        self._said = to_gui(self.said.emit)

    @property
    def guided(self) -> bool:
        """Whether the guided steps run (not "on a stand")."""
        return self._guided

    def _ask(self, question: Question) -> object:
        self._asked(question)
        while True:
            if self.stop.stopped:
                raise CalibrationAbortedError(self.stop.reason or "e-stop")
            try:
                return question.answer.get(timeout=0.05)
            except queue.Empty:
                continue

    def say(self, text: str) -> None:
        """A line in the dock's step list."""
        self._said(text)

    def confirm(self, step: str, text: str) -> bool:
        """Go on or skip (automatic steps run unasked on a stand)."""
        if not self._guided:
            return True
        return bool(self._ask(Question(text, [("Go on", True), ("Skip", False)])))

    def identify_joint(
        self, device_id: int, profile_name: str | None, choices: Sequence[str]
    ) -> str | None:
        """Which joint moved: the profile's, or the one named in the list."""
        if not self._guided:
            return None
        said = profile_name or "no joint"
        answer = self._ask(
            Question(
                f"Device {device_id} moved; the profile says it is the {said}. Which joint moved?",
                [("That one", FROM_ENTRY)],
                entry="choice",
                choices=choices,
                default=profile_name or "",
                joint=profile_name,
            )
        )
        return None if answer == profile_name else str(answer)

    def checks_angle(self, joint: str) -> bool:
        """Move the joint about 8° for the operator to measure?"""
        if not self._guided:
            return False
        text = f"Move the {joint} about 8° for you to measure?"
        return bool(self._ask(Question(text, [("Yes", True), ("No", False)])))

    def measured_angle(self, joint: str, moved_deg: float) -> float | None:
        """The angle measured, or None to accept the OCU's."""
        answer = self._ask(
            Question(
                f"The {joint} moved {moved_deg:.1f}° by the speed reports. How many degrees "
                "did you measure?",
                [("Use my angle", FROM_ENTRY), ("Accept the OCU's", None)],
                entry="number",
            )
        )
        return None if answer is None else float(str(answer))

    def wants_limits(self, joint: str) -> bool:
        """Search the joint's hard stops?"""
        if not self._guided:
            return False
        text = f"Find the {joint}'s hard stops by slow moves?"
        return bool(self._ask(Question(text, [("No", False), ("Yes", True)])))

    def drive_plan(self, kind: str) -> DrivePlan | None:
        """The distance of each run, or skip."""
        if not self._guided:
            return None
        unit = "m" if kind == "linear" else "rad"
        answer = self._ask(
            Question(
                f"Measure the {kind} drive constant (seed 000 §3.1)? Mark a start; the robot "
                f"drives at {', '.join(f'{s:g}' for s in DEFAULT_DRIVE_SPEEDS[kind])} while you "
                f"hold the deadman; let go at the mark. Distance per run in {unit}:",
                [("Drive", FROM_ENTRY), ("Skip", None)],
                entry="number",
                default=f"{DEFAULT_DRIVE_DISTANCE[kind]:.2f}",
            )
        )
        if answer is None:
            return None
        return DrivePlan(kind, float(str(answer)), DEFAULT_DRIVE_SPEEDS[kind])

    def drive_time(self, kind: str, index: int, commanded_s: float) -> float | None:
        """The stopwatch time of a run, or None to drop it."""
        answer = self._ask(
            Question(
                f"Run {index + 1}: the OCU drove for {commanded_s:.2f} s. Your measured time in s?",
                [("Use my time", FROM_ENTRY), ("Drop the run", None)],
                entry="number",
                default=f"{commanded_s:.2f}",
            )
        )
        return None if answer is None else float(str(answer))


class DeadmanKey(QObject):
    """Ctrl held anywhere in the application holds the deadman; losing the keyboard lets go."""

    def __init__(self, flag: HeldFlag, parent: QObject | None = None) -> None:
        super().__init__(parent)
        self.flag = flag

    def eventFilter(self, watched: QObject, event: QEvent) -> bool:
        """Watch Ctrl (never consumed) and the application's activation."""
        kind = event.type()
        if kind in (QEvent.Type.KeyPress, QEvent.Type.KeyRelease):
            assert isinstance(event, QKeyEvent)
            if event.key() == DEADMAN_KEY and not event.isAutoRepeat():
                self.flag.set(kind == QEvent.Type.KeyPress)
        elif kind in (QEvent.Type.ApplicationDeactivate, QEvent.Type.WindowDeactivate):
            self.flag.set(False)
        return False


class CalibrationPanel(QWidget):
    """Start, follow, answer and stop a calibration of the console's robot."""

    finished = Signal(object)  # the CalibrationResult (GUI thread)
    _done = Signal(object)

    def __init__(
        self,
        model: ConsoleModel,
        link_factory: CalibrationLinkFactory | None,
        default_out: Path,
        parent: QWidget | None = None,
        *,
        show_joint: Callable[[str | None], None] | None = None,
    ) -> None:
        super().__init__(parent)
        self.setObjectName("calibration")
        self.model = model
        self.profile = model.profile
        self.link_factory = link_factory
        self.show_joint = show_joint
        self.deadman = HeldFlag()
        self.stop: StopSignal | None = None
        self.result: CalibrationResult | None = None
        self.written: Path | None = None
        self._thread: threading.Thread | None = None
        self._question: Question | None = None
        self._reconnect = False
        self._key = DeadmanKey(self.deadman, self)

        intro = QLabel(
            "Measures the robot's axis map, directions, joint scales, ticks per radian and "
            "zero offsets (guided: also joint IDs, a known angle, limits, drive constants) "
            "and writes a profile. The console's link is disconnected meanwhile. Space or "
            "STOP ALL stop it."
        )
        intro.setWordWrap(True)
        self.out_edit = QLineEdit(str(default_out))
        self.out_edit.setObjectName("calibration_out")
        choose = QPushButton("Choose…")
        choose.clicked.connect(self._choose_out)
        self.on_stand = QCheckBox("Robot on a stand: automatic steps only, no deadman (--yes)")
        self.on_stand.setObjectName("calibration_on_stand")
        self.start_button = QPushButton("Start calibration")
        self.start_button.setObjectName("calibration_start")
        self.start_button.clicked.connect(self.start)
        self.stop_button = QPushButton("Stop")
        self.stop_button.setObjectName("calibration_stop")
        self.stop_button.clicked.connect(lambda: self.stop_now("Stop button"))
        self.deadman_button = QPushButton("Hold to move (or hold Ctrl)")
        self.deadman_button.setObjectName("calibration_deadman")
        self.deadman_button.pressed.connect(lambda: self.deadman.set(True))
        self.deadman_button.released.connect(lambda: self.deadman.set(False))
        self.status = QLabel()
        self.status.setObjectName("calibration_status")
        self.status.setWordWrap(True)
        self.question_label = QLabel()
        self.question_label.setObjectName("calibration_question")
        self.question_label.setWordWrap(True)
        self.entry = QLineEdit()
        self.entry.setObjectName("calibration_entry")
        self.choice = QComboBox()
        self.choice.setObjectName("calibration_choice")
        self.choice.currentTextChanged.connect(self._choice_changed)
        self.answer_row = QHBoxLayout()
        self.answer_buttons: list[QPushButton] = []
        self.steps = QListWidget()
        self.steps.setObjectName("calibration_steps")
        self.steps.setWordWrap(True)
        for widget in (self.steps, self.deadman_button, self.stop_button, self.start_button):
            # The console's keys stay the console's (Space must reach the e-stop).
            widget.setFocusPolicy(Qt.FocusPolicy.NoFocus)

        out_row = QHBoxLayout()
        out_row.addWidget(QLabel("Write to"))
        out_row.addWidget(self.out_edit, 1)
        out_row.addWidget(choose)
        run_row = QHBoxLayout()
        run_row.addWidget(self.start_button)
        run_row.addWidget(self.deadman_button, 1)
        run_row.addWidget(self.stop_button)
        layout = QVBoxLayout(self)
        layout.addWidget(intro)
        layout.addLayout(out_row)
        layout.addWidget(self.on_stand)
        layout.addLayout(run_row)
        layout.addWidget(self.status)
        layout.addWidget(self.question_label)
        layout.addWidget(self.entry)
        layout.addWidget(self.choice)
        layout.addLayout(self.answer_row)
        layout.addWidget(self.steps, 1)
        self._done.connect(self._on_done)
        model.events.estop_requested.connect(self._on_estop)
        self._clear_question()
        self._set_running(False)
        if link_factory is None:
            self.start_button.setEnabled(False)
            self.status.setText("No robot to calibrate (a replay).")

    # ---- running ---------------------------------------------------------------------------

    @property
    def running(self) -> bool:
        """Whether a calibration runs now."""
        return self._thread is not None

    def start(self) -> bool:
        """Disconnect the console and start a calibration; False if it cannot start."""
        if self.running or self.link_factory is None:
            return False
        out = Path(self.out_edit.text()).expanduser()
        if not out.parent.is_dir():
            self.status.setText(f"No directory {out.parent}: choose where to write the profile.")
            return False
        self._reconnect = self.model.connected
        self.model.set_connected(False)  # the console's link sends its zeros and closes
        try:
            link = self.link_factory(raw_profile(self.profile))
        except LinkError as err:
            self.status.setText(f"Cannot open a link to the robot: {err}")
            self._restore_connection()
            return False
        self.steps.clear()
        self.result = None
        self.written = None
        stop = self.stop = StopSignal()
        on_stand = self.on_stand.isChecked()
        operator = DockOperator(stop, guided=not on_stand)
        operator.asked.connect(self._on_asked)
        operator.said.connect(self._on_said)
        deadman: Deadman = OnStand() if on_stand else self.deadman
        self.deadman.set(False)
        calibrator = Calibrator(link, self.profile, operator, deadman=deadman, stop=stop)
        done = to_gui(self._done.emit)

        def run() -> None:
            result: CalibrationResult | None = None
            try:
                result = calibrator.run()
            finally:
                link.shutdown()  # zeros last
                done(result)

        self._operator = operator  # kept alive while its signals are in flight
        self._thread = threading.Thread(target=run, name="ocu-calibration", daemon=True)
        app = QApplication.instance()
        if app is not None and not on_stand:
            app.installEventFilter(self._key)
        self._set_running(True)
        self.status.setText(
            "Calibrating (robot on a stand)…"
            if on_stand
            else "Calibrating: hold the deadman while the robot may move."
        )
        self._thread.start()
        return True

    def stop_now(self, reason: str) -> None:
        """Stop the calibration (zeros; nothing is written)."""
        if self.stop is not None and self.running:
            self.stop.stop(reason)

    def _on_estop(self, reason: str) -> None:
        self.stop_now(reason)

    def _on_done(self, result: CalibrationResult | None) -> None:
        thread, self._thread = self._thread, None
        if thread is not None:
            thread.join(timeout=1.0)
        app = QApplication.instance()
        if app is not None:
            app.removeEventFilter(self._key)
        self.deadman.set(False)
        self._clear_question()
        self._set_running(False)
        self.result = result
        if result is None:
            self.status.setText("The calibration failed (see the log); nothing written.")
        elif result.aborted is not None:
            self.status.setText(f"STOPPED: {result.aborted}. Nothing written.")
        else:
            self._write(result)
        self._restore_connection()
        self.finished.emit(result)

    def _write(self, result: CalibrationResult) -> None:
        out = Path(self.out_edit.text()).expanduser()
        excursion = max(result.excursion_deg.values(), default=math.nan)
        try:
            base = load_profile_data(self.profile.source)
            write_calibrated_profile(
                out, base, result, robot="the console's robot", base_name=self.profile.source
            )
        except (ProfileError, OSError) as err:
            self.status.setText(f"Cannot write {out}: {err}")
            return
        self.written = out
        verdict = "complete" if result.complete else "with contradictions (see the steps)"
        self.status.setText(
            f"Wrote {out}: {len(result.measured)} key(s) measured, {verdict}; "
            f"{result.duration_s:.0f} s, largest excursion {excursion:.1f}°. "
            f"Start `ocu --profile {out}` to use it."
        )

    def _restore_connection(self) -> None:
        if self._reconnect:
            self._reconnect = False
            self.model.set_connected(True)

    def _set_running(self, running: bool) -> None:
        self.start_button.setEnabled(not running and self.link_factory is not None)
        self.stop_button.setEnabled(running)
        self.deadman_button.setEnabled(running and not self.on_stand.isChecked())
        self.on_stand.setEnabled(not running)

    # ---- the operator's side ---------------------------------------------------------------

    def _on_said(self, text: str) -> None:
        self.steps.addItem(text)
        self.steps.scrollToBottom()

    def _on_asked(self, question: Question) -> None:
        self._clear_question()
        self._question = question
        self.question_label.setText(question.text)
        self.question_label.show()
        if question.entry == "number":
            self.entry.setText(question.default)
            self.entry.show()
        elif question.entry == "choice":
            # Filled quietly: the joint shown is the question's until the operator picks.
            blocked = self.choice.blockSignals(True)
            self.choice.clear()
            self.choice.addItems(list(question.choices))
            if question.default:
                self.choice.setCurrentText(question.default)
            self.choice.blockSignals(blocked)
            self.choice.show()
        if question.joint is not None and self.show_joint is not None:
            self.show_joint(question.joint)
        for label, value in question.buttons:
            button = QPushButton(label)
            button.setFocusPolicy(Qt.FocusPolicy.NoFocus)
            button.clicked.connect(lambda _checked=False, v=value: self.answer(v))
            self.answer_row.addWidget(button)
            self.answer_buttons.append(button)

    def answer(self, value: Any) -> bool:
        """Answer the question shown (FROM_ENTRY: what the box holds); False if refused."""
        question = self._question
        if question is None:
            return False
        if value is FROM_ENTRY:
            if question.entry == "choice":
                value = self.choice.currentText()
            else:
                try:
                    number = float(self.entry.text())
                except ValueError:
                    number = math.nan
                if not math.isfinite(number) or number <= 0:
                    self.question_label.setText(
                        f"{question.text}\nNot a positive number: {self.entry.text()!r}"
                    )
                    return False
                value = number
        self._clear_question()
        question.answer.put(value)
        return True

    def _choice_changed(self, name: str) -> None:
        question = self._question
        if question is not None and question.entry == "choice" and self.show_joint is not None:
            self.show_joint(name or None)

    def _clear_question(self) -> None:
        if self._question is not None and self._question.joint and self.show_joint is not None:
            self.show_joint(None)
        self._question = None
        self.question_label.hide()
        self.entry.hide()
        self.choice.hide()
        for button in self.answer_buttons:
            self.answer_row.removeWidget(button)
            button.deleteLater()
        self.answer_buttons = []

    def _choose_out(self) -> None:
        path, _filter = QFileDialog.getSaveFileName(
            self, "Write the calibrated profile", self.out_edit.text(), "Profiles (*.toml)"
        )
        if path:
            self.out_edit.setText(path)

    def shutdown(self) -> None:
        """Stop a running calibration and wait for its zeros (the window closes)."""
        thread = self._thread
        if thread is None:
            return
        self.stop_now("console closed")
        thread.join(timeout=5.0)

"""The video dock: the camera view, its controls and the robot's video status.

`VideoView` (ocu.widgets.video_view) paints the frames; `VideoControls` are the two rows
above it: single/grid view, the camera (the vendor camera-selector button through the RCP),
the RCP's video bit-rate, snapshots, per-camera colour correction and undistortion, and per
camera the stream asked of an extended robot. The controls write what goes to the robot into
the console model (camera, bit-rate, stream requests), which the window sends to the link,
and the image processing settings into the link adapter's corrector; the status row shows
what the model knows of the robot (battery, headlight, roll/pitch; "not reported" without
the protocol extension).
"""

from __future__ import annotations

import logging
from dataclasses import replace
from datetime import datetime
from pathlib import Path

from PySide6.QtCore import QStandardPaths, Qt, QTimer, Signal
from PySide6.QtGui import QFont, QFontMetrics
from PySide6.QtWidgets import (
    QButtonGroup,
    QCheckBox,
    QComboBox,
    QHBoxLayout,
    QLabel,
    QPushButton,
    QSizePolicy,
    QSpinBox,
    QToolButton,
    QVBoxLayout,
    QWidget,
)

from ocu.console.model import ConsoleModel
from ocu.qt.link import QtLink
from ocu.records import CameraRequest, CommandError, LinkState, StatusFrame
from ocu.video.capture import CameraCapture, is_local, video_names
from ocu.video.correction import CorrectionSettings
from ocu.widgets.video_status import AttitudeIndicator, BatteryGauge, HeadlightIndicator
from ocu.widgets.video_view import (
    LIVE,
    NO_SIGNAL,
    NOT_STREAMED,
    VideoView,
    _named,
    percentile,
    snapshot_name,
)

__all__ = [
    "LIVE",
    "NOT_STREAMED",
    "NO_SIGNAL",
    "VideoControls",
    "VideoPanel",
    "percentile",
    "snapshot_name",
]

log = logging.getLogger("ocu.video")

STATS_PERIOD_MS = 500
STREAM_SIZES = ((320, 240), (640, 480), (800, 600), (1280, 720))
MAX_STREAM_FPS = 60
MAX_BITRATE_KBPS = 100_000
COLOUR_LABELS = {"off": "Colour: off", "gray_world": "Colour: gray world", "fixed": "Colour: fixed"}


class VideoControls(QWidget):
    """The two rows of controls above the view: what to show and what to ask of the robot.

    View choices (single/grid, the camera shown) act on the view; the camera selector, the
    bit-rate and the stream requests are commands and go into the model; colour correction
    and undistortion are the link adapter's image processing.
    """

    def __init__(self, model: ConsoleModel, view: VideoView, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.model = model
        self.view = view
        self.link: QtLink | None = None
        # The robot's cameras, then the local ones (ocu.video.capture: --camera).
        names = video_names(model.profile)
        self.camera_names = names

        self.single_button = _named(QToolButton(), "single_view")
        self.single_button.setText("Single")
        self.single_button.setCheckable(True)
        self.grid_button = _named(QToolButton(), "grid_view")
        self.grid_button.setText("2×2")
        self.grid_button.setCheckable(True)
        self.single_button.setChecked(True)
        self.view_group = QButtonGroup(self)
        self.view_group.setExclusive(True)
        self.view_group.addButton(self.single_button)
        self.view_group.addButton(self.grid_button)
        self.grid_button.toggled.connect(self.set_grid)

        self.camera_box = _named(QComboBox(), "camera_box")
        for index, name in enumerate(names):
            self.camera_box.addItem(f"{index + 1}: {name}", index)
        self.camera_box.setToolTip("Camera to show (vendor protocol: the one the robot streams)")
        self.camera_box.currentIndexChanged.connect(self.select_camera)

        self.bitrate_box = _named(QSpinBox(), "bitrate_box")
        self.bitrate_box.setRange(0, MAX_BITRATE_KBPS)
        self.bitrate_box.setSingleStep(100)
        self.bitrate_box.setSuffix(" kbit/s")
        self.bitrate_box.setToolTip("Video bit-rate field of the RCP (0 = robot default)")
        self.bitrate_box.setKeyboardTracking(False)
        self.bitrate_box.setValue(round(model.video_bitrate / 1000.0))
        self.bitrate_box.valueChanged.connect(self._on_bitrate)

        self.track_button = _named(QPushButton("Track"), "track_button")
        self.track_button.setCheckable(True)
        self.track_button.setToolTip(
            "Click-to-track: click an object in a camera on the arm (the Engineer's head, the "
            "xArm's gripper) and the arm keeps it centred (the xArm: and at its distance); "
            "Esc, any motion input, Space or a click outside the picture stops it"
        )
        self.snapshot_button = _named(QPushButton("Snapshot"), "snapshot_button")
        self.snapshot_button.setToolTip("Save the selected camera's picture as PNG")

        top = QHBoxLayout()
        top.setContentsMargins(0, 0, 0, 0)
        top.addWidget(self.single_button)
        top.addWidget(self.grid_button)
        top.addWidget(self.camera_box)
        bitrate_label = QLabel("Bit-rate")
        top.addWidget(bitrate_label)
        top.addWidget(self.bitrate_box)
        top.addStretch(1)
        top.addWidget(self.track_button)
        top.addWidget(self.snapshot_button)

        self.correction_label = _named(QLabel(), "correction_label")
        self.colour_box = _named(QComboBox(), "colour_box")
        for mode, label in COLOUR_LABELS.items():
            self.colour_box.addItem(label, mode)
        self.colour_box.setToolTip("Colour-cast correction of the selected camera")
        self.colour_box.currentIndexChanged.connect(self._on_correction)
        self.undistort_box = _named(QCheckBox("Undistort"), "undistort_box")
        self.undistort_box.setToolTip("Fisheye undistortion from the camera's calibration")
        self.undistort_box.toggled.connect(self._on_correction)
        self.size_box = _named(QComboBox(), "stream_size_box")
        for width, height in STREAM_SIZES:
            self.size_box.addItem(f"{width}×{height}", (width, height))
        self.size_box.setToolTip("Resolution asked of the robot (protocol extension)")
        self.size_box.currentIndexChanged.connect(self._on_stream_request)
        self.fps_box = _named(QSpinBox(), "stream_fps_box")
        self.fps_box.setRange(0, MAX_STREAM_FPS)
        self.fps_box.setSuffix(" fps")
        self.fps_box.setToolTip("Frame rate asked of the robot, 0 = off (protocol extension)")
        self.fps_box.setKeyboardTracking(False)
        self.fps_box.valueChanged.connect(self._on_stream_request)

        second = QHBoxLayout()
        second.setContentsMargins(0, 0, 0, 0)
        second.addWidget(self.correction_label)
        second.addWidget(self.colour_box)
        second.addWidget(self.undistort_box)
        second.addSpacing(12)
        stream_label = QLabel("Stream")
        second.addWidget(stream_label)
        second.addWidget(self.size_box)
        second.addWidget(self.fps_box)
        # A robot that streams no camera of its own (an arm with --camera): nothing of its
        # video is asked for, so its controls are not shown.
        self.robot_widgets = (
            bitrate_label, self.bitrate_box, stream_label, self.size_box, self.fps_box
        )  # fmt: skip
        if not model.profile.link.camera_names:
            for widget in self.robot_widgets:
                widget.hide()
        second.addStretch(1)

        metrics = self.fontMetrics()
        longest_name = max(names, key=metrics.horizontalAdvance)
        self.correction_label.setMinimumWidth(metrics.horizontalAdvance(f"{longest_name}:") + 4)
        layout = QVBoxLayout(self)
        layout.setContentsMargins(0, 0, 0, 0)
        layout.addLayout(top)
        layout.addLayout(second)

        events = model.events
        events.camera_changed.connect(self._on_model_camera)
        events.bitrate_changed.connect(self._on_model_bitrate)
        events.stream_request_changed.connect(lambda _streams: self.sync())
        model.robot.events.extension_changed.connect(lambda _active, _reason: self.sync())
        view.camera_clicked.connect(self.select_camera)
        view.camera_double_clicked.connect(self._on_double_click)
        if model.camera is not None:
            self._show_selected(model.camera)

    # ---- operator -> view / model ----------------------------------------------------------

    def set_grid(self, grid: bool) -> None:
        """Show every camera (True) or the selected one."""
        self.grid_button.setChecked(grid)
        self.single_button.setChecked(not grid)
        self.view.set_grid(grid)

    def select_camera(self, camera: int) -> None:
        """Show a camera and ask the robot for it (the vendor camera-selector button)."""
        if not 0 <= camera < len(self.camera_names):
            return
        self._show_selected(camera)
        # A local camera is only shown: the robot is asked for none of its own.
        if self.model.camera != camera and not is_local(self.model.profile, camera):
            self.model.select_camera(camera)
        self.sync()

    def _on_double_click(self, camera: int) -> None:
        self.select_camera(camera)
        self.set_grid(not self.view.grid)

    def set_bitrate(self, bitrate: float) -> None:
        """Set the RCP's video bit-rate field (bit/s)."""
        self.bitrate_box.setValue(round(bitrate / 1000.0))

    def _on_bitrate(self, kbps: int) -> None:
        self.model.set_video_bitrate(kbps * 1000.0)

    def set_correction(self, camera: int, settings: CorrectionSettings) -> None:
        """Change one camera's correction (takes effect from its next frame)."""
        if self.link is None:
            return
        self.link.corrector.set_settings(camera, settings)
        self.sync()

    def _on_correction(self, *_: object) -> None:
        if self.link is None:
            return
        camera = self.view.selected
        corrector = self.link.corrector
        settings = replace(
            corrector.settings(camera),
            colour=str(self.colour_box.currentData()),
            undistort=self.undistort_box.isChecked() and corrector.can_undistort(camera),
        )
        corrector.set_settings(camera, settings)

    def set_stream_request(self, camera: int, width_px: int, height_px: int, fps: int) -> None:
        """Ask the extended robot for a camera's resolution and frame rate."""
        self.model.set_stream_request(
            CameraRequest(camera=camera, width_px=width_px, height_px=height_px, fps=fps)
        )

    def _on_stream_request(self, *_: object) -> None:
        width, height = self.size_box.currentData()
        self.set_stream_request(self.view.selected, width, height, self.fps_box.value())

    # ---- model -> controls -----------------------------------------------------------------

    def _on_model_camera(self, camera: int | None) -> None:
        if camera is not None:
            self._show_selected(camera)
        self.sync()

    def _on_model_bitrate(self, bitrate: float) -> None:
        self.bitrate_box.blockSignals(True)
        self.bitrate_box.setValue(round(bitrate / 1000.0))
        self.bitrate_box.blockSignals(False)

    def _show_selected(self, camera: int) -> None:
        self.view.set_selected(camera)
        self.camera_box.blockSignals(True)
        self.camera_box.setCurrentIndex(camera)
        self.camera_box.blockSignals(False)

    def sync(self) -> None:
        """Show the selected camera's settings and what may be changed now."""
        camera = self.view.selected
        self.correction_label.setText(f"{self.camera_names[camera]}:")
        link = self.link
        extension = self.model.robot.extension_active
        # A replay sends nothing: what would go to the robot (bit-rate, stream) is disabled.
        commands = link is not None and not link.read_only
        robot_camera = not is_local(self.model.profile, camera)
        self.colour_box.setEnabled(link is not None)
        self.undistort_box.setEnabled(link is not None)
        self.bitrate_box.setEnabled(commands)
        # Tracking commands the waist and the neck: not in a replay, not without a link.
        self.track_button.setEnabled(commands)
        if not commands and self.track_button.isChecked():
            self.track_button.setChecked(False)
        widgets = (self.colour_box, self.undistort_box, self.size_box, self.fps_box)
        for widget in widgets:
            widget.blockSignals(True)
        if link is not None:
            settings = link.corrector.settings(camera)
            self.colour_box.setCurrentIndex(max(0, self.colour_box.findData(settings.colour)))
            can_undistort = link.corrector.can_undistort(camera)
            self.undistort_box.setEnabled(can_undistort)
            self.undistort_box.setChecked(settings.undistort)
            self.undistort_box.setToolTip(
                "Fisheye undistortion from the camera's calibration"
                if can_undistort
                else "No calibration for this camera in the profile"
            )
        streams = self.model.stream_request
        if camera < len(streams):
            request = streams[camera]
            size_index = self.size_box.findData((request.width_px, request.height_px))
            if size_index < 0:
                self.size_box.addItem(
                    f"{request.width_px}×{request.height_px}",
                    (request.width_px, request.height_px),
                )
                size_index = self.size_box.count() - 1
            self.size_box.setCurrentIndex(size_index)
            self.fps_box.setValue(request.fps)
        stream_tip = "" if extension else " (needs the protocol extension)"
        self.size_box.setEnabled(commands and extension and robot_camera)
        self.fps_box.setEnabled(commands and extension and robot_camera)
        self.size_box.setToolTip(f"Resolution asked of the robot{stream_tip}")
        for widget in widgets:
            widget.blockSignals(False)


class VideoPanel(QWidget):
    """The video dock; shows the frames of the link given with set_link() (after Connect)."""

    snapshot_saved = Signal(str)
    snapshot_failed = Signal(str)

    def __init__(
        self,
        model: ConsoleModel,
        parent: QWidget | None = None,
        *,
        snapshot_dir: Path | None = None,
    ) -> None:
        super().__init__(parent)
        self.setObjectName("video_panel")
        self.model = model
        self.profile = model.profile
        self.camera_names = video_names(self.profile)
        self.link: QtLink | None = None
        # Cameras of this machine (--camera), fed to the link's decoder (ocu.video.capture).
        self.captures: list[CameraCapture] = []
        self.snapshot_dir = snapshot_dir or default_snapshot_dir()

        self.view = VideoView(self.camera_names, self.profile.video.no_signal_after_s, self)
        self.controls = VideoControls(model, self.view, self)
        self.controls.snapshot_button.clicked.connect(self.save_snapshot)
        self.protocol_label = _named(QLabel(), "protocol_label")
        self.battery = BatteryGauge(self.profile.video.battery_warning_percent)
        self.headlight = HeadlightIndicator()
        self.attitude = AttitudeIndicator()
        self.counters_label = _named(QLabel(), "video_counters")
        self.counters_label.setSizePolicy(QSizePolicy.Policy.Ignored, QSizePolicy.Policy.Preferred)
        # A line of its own under the status row: beside the attitude it was squeezed into a
        # column a word wide.
        self.message_label = _named(QLabel(), "video_message")
        status = QHBoxLayout()
        status.addWidget(self.protocol_label)
        status.addWidget(self.battery)
        status.addWidget(self.headlight)
        status.addWidget(self.attitude)
        status.addStretch(1)
        # Labels whose text changes get room for their longest text up front, so the
        # panel's minimum size (and with it a top-level window's) never changes.
        bold = QFont(self.font())
        bold.setBold(True)
        self.protocol_label.setMinimumWidth(
            QFontMetrics(bold).horizontalAdvance("Protocol: extended") + 8
        )
        self.message_label.setSizePolicy(QSizePolicy.Policy.Ignored, QSizePolicy.Policy.Preferred)
        layout = QVBoxLayout(self)
        layout.setContentsMargins(4, 4, 4, 4)
        layout.addWidget(self.controls)
        layout.addWidget(self.view, 1)
        layout.addLayout(status)
        layout.addWidget(self.counters_label)
        layout.addWidget(self.message_label)
        if not self.profile.link.camera_names:
            # Only local cameras: the robot reports nothing of its video, light or attitude.
            for widget in (self.protocol_label, self.headlight, self.attitude):
                widget.hide()

        robot = model.robot.events
        robot.status_changed.connect(self._show_status)
        robot.extension_changed.connect(self._on_extension)
        robot.link_state_changed.connect(self._on_link_state)
        model.events.camera_changed.connect(lambda _camera: self._update_live())
        model.events.stream_request_changed.connect(lambda _streams: self._update_live())
        # Click-to-track: the Track button arms clicks on the pictures; the tracker follows
        # each new frame of the tracked camera (on the GUI thread: about a millisecond).
        self.controls.track_button.toggled.connect(self._on_track_button)
        self.view.track_clicked.connect(self.start_tracking_at)
        self.view.track_cancelled.connect(self._on_track_cancelled)
        self.view.frame_taken.connect(self._on_frame_taken)
        model.events.tracking_changed.connect(self.view.set_tracking)
        self._stats_timer = QTimer(self)
        self._stats_timer.setInterval(STATS_PERIOD_MS)
        self._stats_timer.timeout.connect(self.refresh_counters)
        self._stats_timer.start()
        self._grid_offered = False  # the extension's grid was shown once (_on_extension)
        self._extension_shown = False
        self._on_extension(model.robot.extension_active, "")
        # Settle the minimum size before any window exists: a top-level panel then has
        # nothing to propagate when shown (Qt's offscreen platform warns about that).
        layout.activate()

    # The controls, reachable from the panel (the console and the tests use them).

    def select_camera(self, camera: int) -> None:
        """Show a camera and ask the robot for it."""
        self.controls.select_camera(camera)

    def set_grid(self, grid: bool) -> None:
        """Show every camera (True) or the selected one."""
        self.controls.set_grid(grid)

    def set_bitrate(self, bitrate: float) -> None:
        """Set the RCP's video bit-rate field (bit/s)."""
        self.controls.set_bitrate(bitrate)

    def set_correction(self, camera: int, settings: CorrectionSettings) -> None:
        """Change one camera's correction."""
        self.controls.set_correction(camera, settings)

    def set_stream_request(self, camera: int, width_px: int, height_px: int, fps: int) -> None:
        """Ask the extended robot for a camera's resolution and frame rate."""
        self.controls.set_stream_request(camera, width_px, height_px, fps)

    @property
    def extension_active(self) -> bool:
        """Whether the panel shows the robot speaking the protocol extension (the model's, as
        of the last change the panel applied on the GUI thread)."""
        return self._extension_shown

    @property
    def status(self) -> StatusFrame | None:
        """The robot's latest status (the model's; None when not reported)."""
        return self.model.robot.status

    # ---- link -----------------------------------------------------------------------------

    # ---- click-to-track ---------------------------------------------------------------------

    def set_track_mode(self, on: bool) -> None:
        """Arm (or disarm) click-to-track: a click on a picture then tracks what it hits."""
        self.controls.track_button.setChecked(on)

    def start_tracking_at(self, camera: int, x: float, y: float) -> bool:
        """Track the object at a normalised point of a camera's picture; False (with a
        message) when it cannot be tracked."""
        frame = self.view.current_frame(camera)
        if frame is None or frame.decoded is None:
            self._track_refused("no picture of that camera yet")
            return False
        try:
            self.model.start_tracking(camera, frame.decoded.pixels, (x, y))
        except CommandError as err:
            self._track_refused(str(err))
            return False
        return True

    def _track_refused(self, reason: str) -> None:
        text = f"track: {reason}"
        self.message_label.setText(text)
        self.model.events.message.emit(text)

    def _on_track_button(self, on: bool) -> None:
        self.view.track_mode = on
        self.view.setCursor(Qt.CursorShape.CrossCursor if on else Qt.CursorShape.ArrowCursor)
        if not on:
            self.model.stop_tracking("Track switched off")

    def _on_track_cancelled(self) -> None:
        self.model.stop_tracking("click outside the picture")

    def _on_frame_taken(self, camera: int) -> None:
        tracking = self.model.tracking
        if tracking is None or tracking.camera != camera:
            return
        frame = self.view.current_frame(camera)
        if frame is not None and frame.decoded is not None:
            self.model.on_tracking_frame(camera, frame.decoded.pixels, frame.frame.received_at)

    def set_link(self, link: QtLink | None) -> None:
        """Show the video of a (new) link; None shows nothing."""
        if self.link is not None:
            self.link.video_frame_ready.disconnect(self.view.on_frame_ready)
        for capture in self.captures:
            capture.set_sink(link.decoder.submit if link is not None else None)
        self.link = link
        self.controls.link = link
        self.view.set_source(link.take_video_frame if link is not None else None)
        if self.profile.video.decode_at_display_size:
            self.view.set_display_sink(link.decoder.set_display if link is not None else None)
        if link is not None:
            link.video_frame_ready.connect(self.view.on_frame_ready)
        self._show_status(self.model.robot.status)
        self.controls.sync()
        self._update_live()

    def _on_link_state(self, state: LinkState, _reason: str) -> None:
        if state in (LinkState.LOST, LinkState.CLOSED):
            self.view.update()

    def _on_extension(self, active: bool, reason: str) -> None:
        self._extension_shown = active
        if active and not self._grid_offered:
            # The point of the extension: every camera at once. Only the first time: when
            # it comes back after a lost link, the view stays as the operator left it.
            self._grid_offered = True
            self.set_grid(True)
        self.protocol_label.setText("Protocol: <b>extended</b>" if active else "Protocol: vendor")
        self.protocol_label.setToolTip(reason or "")
        self._show_status(self.model.robot.status)
        self._update_live()

    def _show_status(self, status: StatusFrame | None) -> None:
        self.battery.show_status(status)
        self.headlight.show_status(status)
        self.attitude.show_status(status)

    def add_capture(self, capture: CameraCapture) -> None:
        """A camera of this machine, in its slot (`capture.slot`), fed to the link's decoder."""
        if not is_local(self.profile, capture.slot):
            raise ValueError(f"slot {capture.slot} is not a local camera of the profile")
        self.captures.append(capture)
        capture.set_sink(self.link.decoder.submit if self.link is not None else None)
        self._update_live()

    def _update_live(self) -> None:
        local = frozenset(capture.slot for capture in self.captures)
        if self.model.robot.extension_active:
            live = frozenset(r.camera for r in self.model.stream_request if r.fps > 0)
            self.view.set_live(live | local, "switched off (stream at 0 fps)")
        else:
            camera = self.model.camera
            streamed = self.view.selected if camera is None else camera
            self.view.set_live(
                frozenset({streamed}) | local, "vendor protocol: one camera at a time"
            )

    # ---- snapshots and counters -----------------------------------------------------------

    def save_snapshot(self) -> Path | None:
        """Save the selected camera's current picture as a timestamped PNG."""
        camera = self.view.selected
        frame = self.view.current_frame(camera)
        name = self.camera_names[camera]
        if frame is None or frame.image.isNull():
            self._snapshot_failed(f"snapshot: no picture from {name} yet")
            return None
        try:
            self.snapshot_dir.mkdir(parents=True, exist_ok=True)
        except OSError as err:
            self._snapshot_failed(f"snapshot: cannot create {self.snapshot_dir}: {err.strerror}")
            return None
        path = self.snapshot_dir / snapshot_name(name, datetime.now())
        # The view may show a frame decoded at a fraction of its size: save it whole.
        image = frame.image
        decoded = frame.decoded
        if (
            self.link is not None
            and decoded is not None
            and decoded.source_px
            != (
                decoded.width,
                decoded.height,
            )
        ):
            full = self.link.full_size(frame)
            if full is not None:
                image = full.image
        if not image.save(str(path)):  # the format follows the .png suffix
            self._snapshot_failed(f"snapshot: cannot write {path}")
            return None
        self.message_label.setText(f"Saved {path}")
        log.info("snapshot saved: %s", path)
        self.snapshot_saved.emit(str(path))
        return path

    def _snapshot_failed(self, message: str) -> None:
        self.message_label.setText(message)
        log.warning("%s", message)
        self.snapshot_failed.emit(message)

    def refresh_counters(self) -> None:
        """Update the per-camera counter lines and the reassembly counters."""
        link = self.link
        if link is None:
            self.counters_label.setText("no link")
            return
        for camera in range(len(self.camera_names)):
            decoded = link.decoder.stats(camera)
            view = self.view.stats(camera)
            dropped = decoded.skipped + link.frames.replaced(camera) + view.not_shown
            parts = [f"frames {view.shown}", f"dropped {dropped}"]
            if decoded.corrupt:
                parts.append(f"corrupt {decoded.corrupt}")
            self.view.extra_lines[camera] = " · ".join(parts)
        for capture in self.captures:
            # A local camera says what its own thread saw: why it delivers nothing, if so.
            status = capture.status().describe(
                self.view.clock(), self.profile.video.no_signal_after_s
            )
            self.view.extra_lines[capture.slot] += f" · {status}"
        if not self.camera_names[: len(self.profile.link.camera_names)]:
            # No camera of the robot's own (an arm): only the local cameras' counters.
            self.counters_label.setText("")
            self.view.update()
            return
        video = link.link.video_stats()
        if self.model.robot.extension_active or video.fragments:
            # Short beside the attitude (the dock may be narrow): the rare counters only when
            # they are not zero; all of them in the tooltip.
            counts = {
                "duplicates": video.duplicates,
                "out of order": video.out_of_order,
                "inconsistent": video.inconsistent,
            }
            lost = video.truncated + video.expired
            text = f"fragments {video.fragments} · lost frames {lost}"
            self.counters_label.setText(
                " · ".join([text, *(f"{name} {n}" for name, n in counts.items() if n)])
            )
            self.counters_label.setToolTip(
                " · ".join([text, *(f"{name} {n}" for name, n in counts.items())])
            )
        else:
            stats = self.model.robot.stats
            rate = 0.0 if stats is None else stats.video_rate_hz
            self.counters_label.setText(f"video {rate:.0f} fps (vendor)")
        self.view.update()


def default_snapshot_dir() -> Path:
    """Pictures/ocu in the user's picture folder (home if there is none)."""
    pictures = QStandardPaths.writableLocation(QStandardPaths.StandardLocation.PicturesLocation)
    return Path(pictures or Path.home()) / "ocu"

"""The camera viewer: one camera or all four, overlays, no-signal state, snapshots, controls.

`VideoView` paints the newest decoded frame of each camera. Frames reach it through the
link thread's one-slot mailboxes: `video_frame_ready(camera)` is emitted only when a mailbox
goes from empty to full, the view takes the frame at once and schedules a repaint, and Qt
merges repaints, so a slow paint skips stale frames instead of queueing them.

`VideoPanel` is the whole dock: view, camera selection (the vendor camera-selector button
through the RCP), single/grid view, the RCP's video bit-rate, per-camera correction and
stream request, snapshots, and the status the extension reports (battery, headlight,
roll/pitch; "not reported" without it).
"""

from __future__ import annotations

import logging
import math
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, replace
from datetime import datetime
from pathlib import Path
from typing import TYPE_CHECKING, TypeVar

from PySide6.QtCore import QRect, QRectF, QSize, QStandardPaths, Qt, QTimer, Signal, SignalInstance
from PySide6.QtGui import (
    QColor,
    QFont,
    QFontMetrics,
    QMouseEvent,
    QPainter,
    QPaintEvent,
    QPen,
)
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

from ocu.link.core import LinkState, StatusFrame
from ocu.link.qt import DecodedVideoFrame, LinkThread
from ocu.link.stats import RateMeter
from ocu.profile import RobotProfile
from ocu.protocol.extended import CameraRequest
from ocu.video.correction import CorrectionSettings
from ocu.widgets.video_status import AttitudeIndicator, BatteryGauge, HeadlightIndicator

if TYPE_CHECKING:
    from ocu.record.replay import ReplaySource

    # A live link or a replay of one: the same signals, decoder, corrector and frames.
    VideoLink = LinkThread | ReplaySource

log = logging.getLogger("ocu.video")

REFRESH_PERIOD_MS = 250
STATS_PERIOD_MS = 500
AGE_SAMPLES = 600
FPS_WINDOW_S = 1.0
GRID_COLUMNS = 2
OVERLAY_MARGIN_PX = 6
STREAM_SIZES = ((320, 240), (640, 480), (800, 600), (1280, 720))
MAX_STREAM_FPS = 60
MAX_BITRATE_KBPS = 100_000
COLOUR_LABELS = {"off": "Colour: off", "gray_world": "Colour: gray world", "fixed": "Colour: fixed"}
SELECTED_COLOUR = QColor(255, 200, 0)
NO_SIGNAL_COLOUR = QColor(230, 60, 60)
OVERLAY_BACKGROUND = QColor(0, 0, 0, 150)

LIVE = "live"
NO_SIGNAL = "no signal"
NOT_STREAMED = "not streamed"

FrameSource = Callable[[int], DecodedVideoFrame | None]
W = TypeVar("W", bound=QWidget)


def _named(widget: W, name: str) -> W:
    widget.setObjectName(name)
    return widget


def percentile(values: list[float], q: float) -> float:
    """The q-th percentile (0-100) by linear interpolation; nan for no values."""
    if not values:
        return math.nan
    ordered = sorted(values)
    position = (len(ordered) - 1) * q / 100.0
    low = int(position)
    high = min(low + 1, len(ordered) - 1)
    return ordered[low] + (ordered[high] - ordered[low]) * (position - low)


def fit_rect(cell: QRect, width: int, height: int) -> QRect:
    """The largest rectangle of the image's aspect ratio centred in cell."""
    if width <= 0 or height <= 0 or cell.width() <= 0 or cell.height() <= 0:
        return QRect(cell)
    scale = min(cell.width() / width, cell.height() / height)
    w, h = max(1, round(width * scale)), max(1, round(height * scale))
    return QRect(cell.x() + (cell.width() - w) // 2, cell.y() + (cell.height() - h) // 2, w, h)


def snapshot_name(camera: str, now: datetime) -> str:
    """A PNG file name with the camera and a millisecond timestamp."""
    return f"ocu-{camera}-{now:%Y%m%d-%H%M%S}-{now.microsecond // 1000:03d}.png"


@dataclass(frozen=True)
class CameraViewStats:
    """What the view saw of one camera."""

    taken: int
    shown: int
    not_shown: int
    shown_fps: float
    age_p50_ms: float
    age_p99_ms: float
    last_age_ms: float | None


class _CameraState:
    """GUI-thread state of one camera in the view."""

    def __init__(self) -> None:
        self.frame: DecodedVideoFrame | None = None
        self.painted = True
        self.taken = 0
        self.shown = 0
        self.not_shown = 0
        self.shown_rate = RateMeter(window_s=FPS_WINDOW_S)
        self.ages_ms: deque[float] = deque(maxlen=AGE_SAMPLES)
        self.last_age_ms: float | None = None


class VideoView(QWidget):
    """Paints the selected camera, or all cameras in a grid, keeping each aspect ratio."""

    camera_clicked = Signal(int)
    camera_double_clicked = Signal(int)
    # Emitted once per frame, when it is first painted: camera and arrival-to-paint age (s).
    frame_painted = Signal(int, float)

    def __init__(
        self,
        camera_names: tuple[str, ...],
        no_signal_after_s: float = 1.0,
        parent: QWidget | None = None,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        super().__init__(parent)
        self.setObjectName("video_view")
        self.camera_names = camera_names
        self.no_signal_after_s = no_signal_after_s
        self.clock = clock
        self.grid = False
        self.selected = 0
        self.live: frozenset[int] = frozenset(range(len(camera_names)))
        self.not_live_text = "not streamed"
        self.extra_lines: dict[int, str] = {}
        self._source: FrameSource | None = None
        self._cameras = [_CameraState() for _ in camera_names]
        self.setMinimumSize(QSize(320, 240))
        self.setSizePolicy(QSizePolicy.Policy.Expanding, QSizePolicy.Policy.Expanding)
        self.setAttribute(Qt.WidgetAttribute.WA_OpaquePaintEvent)
        self._refresh = QTimer(self)
        self._refresh.setInterval(REFRESH_PERIOD_MS)
        self._refresh.timeout.connect(self.update)
        self._refresh.start()

    # ---- model ----------------------------------------------------------------------------

    def set_source(self, source: FrameSource | None) -> None:
        """Where on_frame_ready takes frames from (a LinkThread's take_video_frame)."""
        self._source = source
        self._cameras = [_CameraState() for _ in self.camera_names]
        self.update()

    def set_grid(self, grid: bool) -> None:
        """All cameras in a grid (True) or the selected one alone."""
        self.grid = grid
        self.update()

    def set_selected(self, camera: int) -> None:
        """Select the camera shown alone (and framed in the grid)."""
        self.selected = camera
        self.update()

    def set_live(self, cameras: frozenset[int], not_live_text: str) -> None:
        """Which cameras are streamed; the others say not_live_text instead of NO SIGNAL."""
        self.live = cameras
        self.not_live_text = not_live_text
        self.update()

    def visible_cameras(self) -> list[int]:
        """Cameras on screen in the current mode."""
        return list(range(len(self.camera_names))) if self.grid else [self.selected]

    def current_frame(self, camera: int) -> DecodedVideoFrame | None:
        """The frame shown (or about to be shown) for a camera."""
        return self._cameras[camera].frame

    def on_frame_ready(self, camera: int) -> None:
        """Take the newest frame of a camera from the mailbox and schedule a repaint."""
        if self._source is None or not 0 <= camera < len(self._cameras):
            return
        frame = self._source(camera)
        if frame is None:
            return
        state = self._cameras[camera]
        if not state.painted:
            state.not_shown += 1
        state.frame = frame
        state.painted = False
        state.taken += 1
        cell = self.cell_rects().get(camera)
        if cell is not None:
            self.update(cell)  # only this camera's cell: Qt merges and clips the repaints

    def signal_state(self, camera: int) -> str:
        """LIVE, NO_SIGNAL (no frame for no_signal_after_s) or NOT_STREAMED."""
        if camera not in self.live:
            return NOT_STREAMED
        frame = self._cameras[camera].frame
        if frame is None or self.clock() - frame.frame.received_at > self.no_signal_after_s:
            return NO_SIGNAL
        return LIVE

    def stats(self, camera: int) -> CameraViewStats:
        """What the view saw of one camera."""
        state = self._cameras[camera]
        ages = list(state.ages_ms)
        return CameraViewStats(
            taken=state.taken,
            shown=state.shown,
            not_shown=state.not_shown,
            shown_fps=state.shown_rate.rate(self.clock()),
            age_p50_ms=percentile(ages, 50),
            age_p99_ms=percentile(ages, 99),
            last_age_ms=state.last_age_ms,
        )

    # ---- painting -------------------------------------------------------------------------

    def cell_rects(self) -> dict[int, QRect]:
        """Screen rectangle of each visible camera."""
        area = self.rect()
        if not self.grid:
            return {self.selected: area}
        count = len(self.camera_names)
        columns = min(GRID_COLUMNS, count)
        rows = math.ceil(count / columns)
        width, height = area.width() // columns, area.height() // rows
        return {
            camera: QRect((camera % columns) * width, (camera // columns) * height, width, height)
            for camera in range(count)
        }

    def camera_at(self, x: int, y: int) -> int | None:
        """The camera whose cell contains a point."""
        for camera, cell in self.cell_rects().items():
            if cell.contains(x, y):
                return camera
        return None

    def paintEvent(self, event: QPaintEvent) -> None:
        painter = QPainter(self)
        dirty = event.rect()
        painter.fillRect(dirty, Qt.GlobalColor.black)
        painter.setRenderHint(QPainter.RenderHint.SmoothPixmapTransform)
        first_paints: list[tuple[int, DecodedVideoFrame]] = []
        for camera, cell in self.cell_rects().items():
            if not cell.intersects(dirty):
                continue
            state = self._cameras[camera]
            frame = state.frame
            if frame is not None and not frame.image.isNull():
                image = frame.image
                painter.drawImage(fit_rect(cell, image.width(), image.height()), image)
                if not state.painted:
                    first_paints.append((camera, frame))
            self._paint_overlay(painter, camera, cell)
            if self.grid and camera == self.selected:
                painter.setPen(QPen(SELECTED_COLOUR, 2))
                painter.setBrush(Qt.BrushStyle.NoBrush)
                painter.drawRect(cell.adjusted(1, 1, -1, -1))
        painter.end()
        now = self.clock()
        for camera, frame in first_paints:
            state = self._cameras[camera]
            state.painted = True
            state.shown += 1
            state.shown_rate.add(now)
            age_s = now - frame.frame.received_at
            state.ages_ms.append(age_s * 1000.0)
            self.frame_painted.emit(camera, age_s)

    def _paint_overlay(self, painter: QPainter, camera: int, cell: QRect) -> None:
        state = self._cameras[camera]
        frame = state.frame
        now = self.clock()
        name = self.camera_names[camera]
        if frame is not None and frame.frame.camera is None:
            name = f"{name} (assumed: no camera was selected)"
        lines = [name]
        if frame is not None:
            age_ms = (now - frame.frame.received_at) * 1000.0
            state.last_age_ms = age_ms
            fps = state.shown_rate.rate(now)
            lines[0] += f" · {frame.image.width()}×{frame.image.height()} · {fps:.1f} fps"
            timing = f"age {age_ms:.0f} ms"
            decoded = frame.decoded
            if decoded is not None:
                timing += f" · decode {decoded.decode_ms:.1f} ms"
                if decoded.correction.colour_ms is not None:
                    timing += f" · colour {decoded.correction.colour_ms:.1f} ms"
                if decoded.correction.undistort_ms is not None:
                    timing += f" · undistort {decoded.correction.undistort_ms:.1f} ms"
            lines.append(timing)
        extra = self.extra_lines.get(camera)
        if extra:
            lines.append(extra)
        self._draw_text_box(painter, cell, lines)
        state_text = self.signal_state(camera)
        if state_text == NOT_STREAMED:
            self._draw_centre(
                painter, cell, "NOT STREAMED", self.not_live_text, QColor(200, 200, 200)
            )
        elif state_text == NO_SIGNAL:
            detail = (
                "no frame yet"
                if frame is None
                else f"last frame {now - frame.frame.received_at:.1f} s ago"
            )
            self._draw_centre(painter, cell, "NO SIGNAL", detail, NO_SIGNAL_COLOUR)

    def _draw_text_box(self, painter: QPainter, cell: QRect, lines: list[str]) -> None:
        metrics = painter.fontMetrics()
        line_px = metrics.height()
        width = max(metrics.horizontalAdvance(line) for line in lines) + 2 * OVERLAY_MARGIN_PX
        width = min(width, cell.width())
        box = QRect(cell.x(), cell.y(), width, line_px * len(lines) + OVERLAY_MARGIN_PX)
        painter.fillRect(box, OVERLAY_BACKGROUND)
        painter.setPen(Qt.GlobalColor.white)
        for index, line in enumerate(lines):
            painter.drawText(
                cell.x() + OVERLAY_MARGIN_PX,
                cell.y() + OVERLAY_MARGIN_PX // 2 + metrics.ascent() + index * line_px,
                line,
            )

    def _draw_centre(
        self, painter: QPainter, cell: QRect, title: str, detail: str, colour: QColor
    ) -> None:
        painter.fillRect(cell, QColor(0, 0, 0, 140))
        font = QFont(painter.font())
        font.setBold(True)
        font.setPointSizeF(max(10.0, min(28.0, cell.height() / 12)))
        painter.save()
        painter.setFont(font)
        painter.setPen(colour)
        centre = QRectF(cell).adjusted(0, -cell.height() / 8, 0, -cell.height() / 8)
        painter.drawText(centre, Qt.AlignmentFlag.AlignCenter, title)
        painter.restore()
        painter.setPen(Qt.GlobalColor.white)
        below = QRectF(cell).adjusted(0, cell.height() / 8, 0, cell.height() / 8)
        painter.drawText(below, Qt.AlignmentFlag.AlignCenter, detail)

    # ---- input ----------------------------------------------------------------------------

    def mousePressEvent(self, event: QMouseEvent) -> None:
        camera = self.camera_at(int(event.position().x()), int(event.position().y()))
        if camera is not None:
            self.camera_clicked.emit(camera)
        super().mousePressEvent(event)

    def mouseDoubleClickEvent(self, event: QMouseEvent) -> None:
        camera = self.camera_at(int(event.position().x()), int(event.position().y()))
        if camera is not None:
            self.camera_double_clicked.emit(camera)
        super().mouseDoubleClickEvent(event)


class VideoPanel(QWidget):
    """Everything video for the console dock; rebind with set_link() after each Connect."""

    snapshot_saved = Signal(str)
    snapshot_failed = Signal(str)
    # The extension's latest status, or None when it is not (or no longer) reported.
    status_changed = Signal(object)
    extension_active_changed = Signal(bool)

    def __init__(
        self,
        profile: RobotProfile,
        link_thread: VideoLink | None,
        parent: QWidget | None = None,
        *,
        snapshot_dir: Path | None = None,
    ) -> None:
        super().__init__(parent)
        self.setObjectName("video_panel")
        self.profile = profile
        self.camera_names = profile.link.camera_names
        self.link: VideoLink | None = None
        self.extension_active = False
        self.status: StatusFrame | None = None
        self.snapshot_dir = snapshot_dir or default_snapshot_dir()
        ext = profile.extension
        self._requests = {
            index: CameraRequest(
                camera=index,
                width_px=ext.stream_width_px if ext else 640,
                height_px=ext.stream_height_px if ext else 480,
                fps=ext.stream_fps if ext else 30,
            )
            for index in range(len(self.camera_names))
        }
        self._build()
        self.set_link(link_thread)

    # ---- layout ---------------------------------------------------------------------------

    def _build(self) -> None:
        self.view = VideoView(self.camera_names, self.profile.video.no_signal_after_s, self)

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
        for index, name in enumerate(self.camera_names):
            self.camera_box.addItem(f"{index + 1}: {name}", index)
        self.camera_box.setToolTip("Camera to show (vendor protocol: the one the robot streams)")
        self.camera_box.currentIndexChanged.connect(self._on_camera_box)

        self.bitrate_box = _named(QSpinBox(), "bitrate_box")
        self.bitrate_box.setRange(0, MAX_BITRATE_KBPS)
        self.bitrate_box.setSingleStep(100)
        self.bitrate_box.setSuffix(" kbit/s")
        self.bitrate_box.setToolTip("Video bit-rate field of the RCP (0 = robot default)")
        self.bitrate_box.setKeyboardTracking(False)
        self.bitrate_box.valueChanged.connect(self._on_bitrate)

        self.snapshot_button = _named(QPushButton("Snapshot"), "snapshot_button")
        self.snapshot_button.setToolTip("Save the selected camera's picture as PNG")
        self.snapshot_button.clicked.connect(self.save_snapshot)

        top = QHBoxLayout()
        top.addWidget(self.single_button)
        top.addWidget(self.grid_button)
        top.addWidget(self.camera_box)
        top.addWidget(QLabel("Bit-rate"))
        top.addWidget(self.bitrate_box)
        top.addStretch(1)
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
        second.addWidget(self.correction_label)
        second.addWidget(self.colour_box)
        second.addWidget(self.undistort_box)
        second.addSpacing(12)
        second.addWidget(QLabel("Stream"))
        second.addWidget(self.size_box)
        second.addWidget(self.fps_box)
        second.addStretch(1)

        self.protocol_label = _named(QLabel(), "protocol_label")
        self.battery = BatteryGauge(self.profile.video.battery_warning_percent)
        self.headlight = HeadlightIndicator()
        self.attitude = AttitudeIndicator()
        self.counters_label = _named(QLabel(), "video_counters")
        self.counters_label.setSizePolicy(QSizePolicy.Policy.Ignored, QSizePolicy.Policy.Preferred)
        self.counters_label.setWordWrap(True)  # two lines beside the attitude, not cut off
        self.message_label = _named(QLabel(), "video_message")
        status = QHBoxLayout()
        status.addWidget(self.protocol_label)
        status.addWidget(self.battery)
        status.addWidget(self.headlight)
        status.addWidget(self.attitude)
        status.addWidget(self.counters_label, 1)

        # Labels whose text changes get room for their longest text up front, so the
        # panel's minimum size (and with it a top-level window's) never changes.
        metrics = self.fontMetrics()
        bold = QFont(self.font())
        bold.setBold(True)
        self.protocol_label.setMinimumWidth(
            QFontMetrics(bold).horizontalAdvance("Protocol: extended") + 8
        )
        longest_name = max(self.camera_names, key=metrics.horizontalAdvance)
        self.correction_label.setMinimumWidth(metrics.horizontalAdvance(f"{longest_name}:") + 4)
        self.message_label.setSizePolicy(QSizePolicy.Policy.Ignored, QSizePolicy.Policy.Preferred)

        layout = QVBoxLayout(self)
        layout.setContentsMargins(4, 4, 4, 4)
        layout.addLayout(top)
        layout.addLayout(second)
        layout.addWidget(self.view, 1)
        layout.addLayout(status)
        layout.addWidget(self.message_label)

        self.view.camera_clicked.connect(self.select_camera)
        self.view.camera_double_clicked.connect(self._on_double_click)
        self._stats_timer = QTimer(self)
        self._stats_timer.setInterval(STATS_PERIOD_MS)
        self._stats_timer.timeout.connect(self.refresh_counters)
        self._stats_timer.start()
        # Settle the minimum size before any window exists: a top-level panel then has
        # nothing to propagate when shown (Qt's offscreen platform warns about that).
        layout.activate()

    # ---- link -----------------------------------------------------------------------------

    def set_link(self, link_thread: VideoLink | None) -> None:
        """Show the video of a (new) link thread; None shows nothing."""
        old = self.link
        if old is not None:
            for signal, slot in self._connections(old):
                signal.disconnect(slot)
        self.link = link_thread
        self.view.set_source(link_thread.take_video_frame if link_thread is not None else None)
        self._set_extension(link_thread is not None and link_thread.core.extension_active, "")
        self._show_status(None)
        if link_thread is not None:
            for signal, slot in self._connections(link_thread):
                signal.connect(slot)
            command = link_thread.core.command
            self.bitrate_box.blockSignals(True)
            self.bitrate_box.setValue(round(command.video_bitrate / 1000.0))
            self.bitrate_box.blockSignals(False)
            if command.camera is not None and 0 <= command.camera < len(self.camera_names):
                self._show_selected(command.camera)
            for request in link_thread.core.stream_request.cameras:
                if request.camera in self._requests:
                    self._requests[request.camera] = request
        self._sync_controls()
        self._update_live()

    def _connections(self, link: VideoLink) -> list[tuple[SignalInstance, Callable[..., None]]]:
        return [
            (link.video_frame_ready, self.view.on_frame_ready),
            (link.status_received, self._on_status),
            (link.extension_changed, self._set_extension),
            (link.link_state_changed, self._on_link_state),
        ]

    def _on_status(self, status: StatusFrame) -> None:
        if self.extension_active:
            self._show_status(status)

    def _on_link_state(self, state: LinkState, reason: str) -> None:
        if state in (LinkState.LOST, LinkState.CLOSED):
            self.view.update()

    def _set_extension(self, active: bool, reason: str) -> None:
        changed = active != self.extension_active
        self.extension_active = active
        if not active:
            self._show_status(None)
        if changed and active:
            self.set_grid(True)  # the point of the extension: every camera at once
        self.protocol_label.setText("Protocol: <b>extended</b>" if active else "Protocol: vendor")
        self.protocol_label.setToolTip(reason or "")
        self._sync_controls()
        self._update_live()
        if changed:
            self.extension_active_changed.emit(active)

    def _show_status(self, status: StatusFrame | None) -> None:
        self.status = status
        self.battery.show_status(status)
        self.headlight.show_status(status)
        self.attitude.show_status(status)
        self.status_changed.emit(status)

    def _update_live(self) -> None:
        if self.extension_active:
            live = frozenset(c for c, r in self._requests.items() if r.fps > 0)
            self.view.set_live(live, "switched off (stream at 0 fps)")
        else:
            camera = self.link.core.command.camera if self.link is not None else None
            streamed = self.view.selected if camera is None else camera
            self.view.set_live(frozenset({streamed}), "vendor protocol: one camera at a time")

    # ---- controls -------------------------------------------------------------------------

    def set_grid(self, grid: bool) -> None:
        """Show every camera (True) or the selected one."""
        self.grid_button.setChecked(grid)
        self.single_button.setChecked(not grid)
        self.view.set_grid(grid)

    def select_camera(self, camera: int) -> None:
        """Select a camera; sends the vendor camera-selector button through the RCP."""
        if not 0 <= camera < len(self.camera_names):
            return
        self._show_selected(camera)
        if self.link is not None:
            core = self.link.core
            command = core.command
            if command.camera != camera:
                core.set_command(replace(command, camera=camera))
        self._sync_controls()
        self._update_live()

    def _show_selected(self, camera: int) -> None:
        self.view.set_selected(camera)
        self.camera_box.blockSignals(True)
        self.camera_box.setCurrentIndex(camera)
        self.camera_box.blockSignals(False)

    def _on_camera_box(self, index: int) -> None:
        self.select_camera(index)

    def _on_double_click(self, camera: int) -> None:
        self.select_camera(camera)
        self.set_grid(not self.view.grid)

    def set_bitrate(self, bitrate: float) -> None:
        """Set the RCP's video bit-rate field (bit/s)."""
        self.bitrate_box.setValue(round(bitrate / 1000.0))

    def _on_bitrate(self, kbps: int) -> None:
        if self.link is None:
            return
        core = self.link.core
        core.set_command(replace(core.command, video_bitrate=kbps * 1000.0))

    def set_correction(self, camera: int, settings: CorrectionSettings) -> None:
        """Change one camera's correction (takes effect from its next frame)."""
        if self.link is None:
            return
        self.link.corrector.set_settings(camera, settings)
        self._sync_controls()

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
        self._requests[camera] = replace(
            self._requests[camera], width_px=width_px, height_px=height_px, fps=fps
        )
        if self.link is not None:
            self.link.core.set_stream_request(list(self._requests.values()))
        self._sync_controls()
        self._update_live()

    def _on_stream_request(self, *_: object) -> None:
        width, height = self.size_box.currentData()
        self.set_stream_request(self.view.selected, width, height, self.fps_box.value())

    def _sync_controls(self) -> None:
        camera = self.view.selected
        name = self.camera_names[camera]
        self.correction_label.setText(f"{name}:")
        has_link = self.link is not None
        # A replay sends nothing: what would go to the robot (bit-rate, stream) is disabled.
        commands = isinstance(self.link, LinkThread)
        self.colour_box.setEnabled(has_link)
        self.undistort_box.setEnabled(has_link)
        self.bitrate_box.setEnabled(commands)
        widgets = (self.colour_box, self.undistort_box, self.size_box, self.fps_box)
        for widget in widgets:
            widget.blockSignals(True)
        if self.link is not None:
            settings = self.link.corrector.settings(camera)
            self.colour_box.setCurrentIndex(max(0, self.colour_box.findData(settings.colour)))
            can_undistort = self.link.corrector.can_undistort(camera)
            self.undistort_box.setEnabled(can_undistort)
            self.undistort_box.setChecked(settings.undistort)
            self.undistort_box.setToolTip(
                "Fisheye undistortion from the camera's calibration"
                if can_undistort
                else "No calibration for this camera in the profile"
            )
        request = self._requests[camera]
        size_index = self.size_box.findData((request.width_px, request.height_px))
        if size_index < 0:
            self.size_box.addItem(
                f"{request.width_px}×{request.height_px}", (request.width_px, request.height_px)
            )
            size_index = self.size_box.count() - 1
        self.size_box.setCurrentIndex(size_index)
        self.fps_box.setValue(request.fps)
        stream_tip = "" if self.extension_active else " (needs the protocol extension)"
        self.size_box.setEnabled(commands and self.extension_active)
        self.fps_box.setEnabled(commands and self.extension_active)
        self.size_box.setToolTip(f"Resolution asked of the robot{stream_tip}")
        for widget in widgets:
            widget.blockSignals(False)

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
        if not frame.image.save(str(path)):  # the format follows the .png suffix
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
        if self.link is None:
            self.counters_label.setText("no link")
            return
        decoder = self.link.decoder
        for camera in range(len(self.camera_names)):
            decoded = decoder.stats(camera)
            view = self.view.stats(camera)
            dropped = decoded.skipped + self.link.frames.replaced(camera) + view.not_shown
            parts = [f"frames {view.shown}", f"dropped {dropped}"]
            if decoded.corrupt:
                parts.append(f"corrupt {decoded.corrupt}")
            self.view.extra_lines[camera] = " · ".join(parts)
        if self.extension_active or self.link.core.video_stats().fragments:
            stats = self.link.core.video_stats()
            self.counters_label.setText(
                f"fragments {stats.fragments} · lost frames {stats.truncated + stats.expired}"
                f" · duplicates {stats.duplicates} · out of order {stats.out_of_order}"
                f" · inconsistent {stats.inconsistent}"
            )
        else:
            link_stats = self.link.core.stats()
            self.counters_label.setText(f"video {link_stats.video_rate_hz:.0f} fps (vendor)")
        self.view.update()


def default_snapshot_dir() -> Path:
    """Pictures/ocu in the user's picture folder (home if there is none)."""
    pictures = QStandardPaths.writableLocation(QStandardPaths.StandardLocation.PicturesLocation)
    return Path(pictures or Path.home()) / "ocu"

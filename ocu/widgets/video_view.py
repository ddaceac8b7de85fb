"""The camera view: paints the newest decoded frame of one camera or all four, with overlays.

Frames reach it through the link adapter's one-slot mailboxes (ocu.qt.link): a
`video_frame_ready(camera)` is emitted only when a mailbox goes from empty to full, the view
takes the frame at once and schedules a repaint, and Qt merges repaints, so a slow paint skips
stale frames instead of queueing them. It shows the camera's name, frames per second, frame
age (arrival to paint) and size, and a clear NO SIGNAL state.
"""

from __future__ import annotations

import math
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from datetime import datetime
from typing import TypeVar

from PySide6.QtCore import QPoint, QRect, QRectF, QSize, Qt, QTimer, Signal
from PySide6.QtGui import (
    QColor,
    QFont,
    QFontMetrics,
    QHideEvent,
    QImage,
    QMouseEvent,
    QPainter,
    QPaintEvent,
    QPen,
    QResizeEvent,
    QShowEvent,
)
from PySide6.QtWidgets import QSizePolicy, QWidget

from ocu.console.tracking import TrackView
from ocu.link.stats import RateMeter
from ocu.qt.link import DecodedVideoFrame
from ocu.video.tracker import TrackState

REFRESH_PERIOD_MS = 250
OVERLAY_PERIOD_S = 0.25
AGE_SAMPLES = 600
FPS_WINDOW_S = 1.0
GRID_COLUMNS = 2
OVERLAY_MARGIN_PX = 6
SELECTED_COLOUR = QColor(255, 200, 0)
NO_SIGNAL_COLOUR = QColor(230, 60, 60)
OVERLAY_BACKGROUND = QColor(0, 0, 0, 150)
TRACK_COLOUR = QColor(60, 230, 90)
TRACK_ERROR_COLOUR = QColor(255, 220, 0)
TRACK_LOST_COLOUR = QColor(240, 60, 60)

LIVE = "live"
NO_SIGNAL = "no signal"
NOT_STREAMED = "not streamed"

FrameSource = Callable[[int], DecodedVideoFrame | None]
# Told how large each camera is shown (device pixels), None when no cell shows it.
DisplaySink = Callable[[int, tuple[int, int] | None], None]
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
        # The text box drawn over the picture, rendered once and redrawn as an image until
        # its text changes (at most every OVERLAY_PERIOD_S): text is costly, 120 frames/s.
        self.overlay: QImage | None = None
        self.overlay_key: tuple[tuple[str, ...], int] | None = None
        self.overlay_at = -math.inf


class VideoView(QWidget):
    """Paints the selected camera, or all cameras in a grid, keeping each aspect ratio."""

    camera_clicked = Signal(int)
    camera_double_clicked = Signal(int)
    # Emitted once per frame, when it is first painted: camera and arrival-to-paint age (s).
    frame_painted = Signal(int, float)
    # A new frame was taken from a camera's mailbox (click-to-track follows it).
    frame_taken = Signal(int)
    # Click-to-track mode: a click in a camera's picture (camera, x, y normalised to the
    # picture), and a click outside every picture.
    track_clicked = Signal(int, float, float)
    track_cancelled = Signal()

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
        self.track_mode = False
        self.tracking: TrackView | None = None
        self._source: FrameSource | None = None
        self._display_sink: DisplaySink | None = None
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
        """Where on_frame_ready takes frames from (a QtLink's take_video_frame)."""
        self._source = source
        self._cameras = [_CameraState() for _ in self.camera_names]
        self.update()

    def set_display_sink(self, sink: DisplaySink | None) -> None:
        """Who decodes for this view: told each camera's cell size whenever it changes."""
        self._display_sink = sink
        self._report_display()

    def set_grid(self, grid: bool) -> None:
        """All cameras in a grid (True) or the selected one alone."""
        self.grid = grid
        self._report_display()
        self.update()

    def set_selected(self, camera: int) -> None:
        """Select the camera shown alone (and framed in the grid)."""
        self.selected = camera
        self._report_display()
        self.update()

    def _report_display(self) -> None:
        """Tell the decoder how large each camera is shown: it decodes no more than that."""
        sink = self._display_sink
        if sink is None:
            return
        cells = self.cell_rects() if self.isVisible() else {}
        ratio = self.devicePixelRatioF()
        for camera in range(len(self.camera_names)):
            cell = cells.get(camera)
            size = None
            if cell is not None:
                size = (round(cell.width() * ratio), round(cell.height() * ratio))
            sink(camera, size)

    def resizeEvent(self, event: QResizeEvent) -> None:
        super().resizeEvent(event)
        self._report_display()

    def showEvent(self, event: QShowEvent) -> None:
        super().showEvent(event)
        self._report_display()

    def hideEvent(self, event: QHideEvent) -> None:
        super().hideEvent(event)
        self._report_display()

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
        self.frame_taken.emit(camera)

    def set_tracking(self, view: TrackView | None) -> None:
        """What click-to-track draws (None: nothing)."""
        previous, self.tracking = self.tracking, view
        for tracked in (previous, view):
            cell = None if tracked is None else self.cell_rects().get(tracked.camera)
            if cell is not None:
                self.update(cell)

    def image_rect(self, camera: int) -> QRect | None:
        """Where a camera's picture is drawn (None: not on screen or no frame yet)."""
        cell = self.cell_rects().get(camera)
        frame = self._cameras[camera].frame
        if cell is None or frame is None or frame.image.isNull():
            return None
        image = frame.image
        target = fit_rect(cell, image.width(), image.height())
        if abs(target.width() - image.width()) <= 2 and abs(target.height() - image.height()) <= 2:
            return QRect(
                cell.x() + (cell.width() - image.width()) // 2,
                cell.y() + (cell.height() - image.height()) // 2,
                image.width(),
                image.height(),
            )
        return target

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
        first_paints: list[tuple[int, DecodedVideoFrame]] = []
        for camera, cell in self.cell_rects().items():
            if not cell.intersects(dirty):
                continue
            state = self._cameras[camera]
            frame = state.frame
            if frame is not None and not frame.image.isNull():
                image = frame.image
                target = fit_rect(cell, image.width(), image.height())
                # Decoded at the size the cell shows it, the image is drawn 1:1, centred: a
                # copy, no filtering (a pixel or two of rounding is not worth a rescale).
                one_to_one = (
                    abs(target.width() - image.width()) <= 2
                    and abs(target.height() - image.height()) <= 2
                )
                if one_to_one:
                    corner = QPoint(
                        cell.x() + (cell.width() - image.width()) // 2,
                        cell.y() + (cell.height() - image.height()) // 2,
                    )
                    painter.drawImage(corner, image)
                else:
                    painter.setRenderHint(QPainter.RenderHint.SmoothPixmapTransform)
                    painter.drawImage(target, image)
                if not state.painted:
                    first_paints.append((camera, frame))
            self._paint_overlay(painter, camera, cell)
            if self.tracking is not None and self.tracking.camera == camera:
                self._paint_tracking(painter, camera, self.tracking)
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
        if frame is not None:
            state.last_age_ms = (now - frame.frame.received_at) * 1000.0
        if state.overlay is None or now - state.overlay_at >= OVERLAY_PERIOD_S:
            state.overlay_at = now
            key = (tuple(self._overlay_lines(camera, now)), cell.width())
            if key != state.overlay_key:
                state.overlay_key = key
                state.overlay = self._text_box(list(key[0]), cell.width())
        if state.overlay is not None:
            painter.drawImage(cell.topLeft(), state.overlay)
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

    def _paint_tracking(self, painter: QPainter, camera: int, view: TrackView) -> None:
        """The tracked box, the error (image centre to the box's centre), LOST when lost."""
        area = self.image_rect(camera)
        if area is None:
            return
        painter.save()
        painter.setBrush(Qt.BrushStyle.NoBrush)
        middle = area.center()
        painter.setPen(QPen(TRACK_ERROR_COLOUR, 1))
        painter.drawLine(middle - QPoint(6, 0), middle + QPoint(6, 0))
        painter.drawLine(middle - QPoint(0, 6), middle + QPoint(0, 6))
        box = view.box
        if box is not None:
            rect = QRectF(
                area.x() + box.x * area.width(),
                area.y() + box.y * area.height(),
                box.width * area.width(),
                box.height * area.height(),
            )
            painter.setPen(QPen(TRACK_ERROR_COLOUR, 2))
            painter.drawLine(middle, rect.center().toPoint())
            painter.setPen(QPen(TRACK_COLOUR, 2))
            painter.drawRect(rect)
            error_x = (box.centre[0] - 0.5) * area.width()
            error_y = (box.centre[1] - 0.5) * area.height()
            painter.drawText(
                rect.bottomLeft() + QPoint(0, painter.fontMetrics().ascent() + 2),
                f"track {error_x:+.0f}, {error_y:+.0f} px",
            )
        if view.state is TrackState.LOST:
            font = QFont(painter.font())
            font.setBold(True)
            font.setPointSizeF(max(10.0, min(24.0, area.height() / 14)))
            painter.setFont(font)
            painter.setPen(TRACK_LOST_COLOUR)
            # Below the centre: the text box over the picture's top is not covered.
            band = QRectF(
                area.x(), area.y() + area.height() * 0.6, area.width(), area.height() * 0.2
            )
            painter.drawText(band, Qt.AlignmentFlag.AlignCenter, "LOST")
        painter.restore()

    def _overlay_lines(self, camera: int, now: float) -> list[str]:
        """Name, size and rate; age and the time each stage took; the counters."""
        frame = self._cameras[camera].frame
        name = self.camera_names[camera]
        if frame is not None and frame.frame.camera is None:
            name = f"{name} (assumed: no camera was selected)"
        lines = [name]
        if frame is not None:
            fps = self._cameras[camera].shown_rate.rate(now)
            width, height = frame.image.width(), frame.image.height()
            size = f"{width}×{height}"
            decoded = frame.decoded
            if decoded is not None and decoded.source_px != (width, height):
                source_width, source_height = decoded.source_px
                size = f"{source_width}×{source_height} shown {size}"
                if decoded.reduction > 1:
                    size += f" (decoded 1/{decoded.reduction})"
            lines[0] += f" · {size} · {fps:.1f} fps"
            timing = f"age {(now - frame.frame.received_at) * 1000.0:.0f} ms"
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
        return lines

    def _text_box(self, lines: list[str], max_width: int) -> QImage:
        """White lines on a translucent box, as an image to draw at a cell's corner."""
        metrics = QFontMetrics(self.font())
        line_px = metrics.height()
        width = max(metrics.horizontalAdvance(line) for line in lines) + 2 * OVERLAY_MARGIN_PX
        width = max(1, min(width, max_width))
        height = line_px * len(lines) + OVERLAY_MARGIN_PX
        ratio = self.devicePixelRatioF()
        image = QImage(
            round(width * ratio), round(height * ratio), QImage.Format.Format_ARGB32_Premultiplied
        )
        image.setDevicePixelRatio(ratio)
        image.fill(OVERLAY_BACKGROUND)
        painter = QPainter(image)
        painter.setFont(self.font())
        painter.setPen(Qt.GlobalColor.white)
        for index, line in enumerate(lines):
            painter.drawText(
                OVERLAY_MARGIN_PX,
                OVERLAY_MARGIN_PX // 2 + metrics.ascent() + index * line_px,
                line,
            )
        painter.end()
        return image

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
        x, y = int(event.position().x()), int(event.position().y())
        camera = self.camera_at(x, y)
        if camera is not None:
            self.camera_clicked.emit(camera)
        if self.track_mode and event.button() == Qt.MouseButton.LeftButton:
            area = None if camera is None else self.image_rect(camera)
            if camera is not None and area is not None and area.contains(x, y):
                self.track_clicked.emit(
                    camera,
                    (event.position().x() - area.x()) / max(area.width(), 1),
                    (event.position().y() - area.y()) / max(area.height(), 1),
                )
            else:
                self.track_cancelled.emit()
        super().mousePressEvent(event)

    def mouseDoubleClickEvent(self, event: QMouseEvent) -> None:
        camera = self.camera_at(int(event.position().x()), int(event.position().y()))
        if camera is not None:
            self.camera_double_clicked.emit(camera)
        super().mouseDoubleClickEvent(event)

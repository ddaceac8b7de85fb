"""The map dock: a top-down view centred on the robot, and the controls of the assisted modes.

`MapView` draws, in the odometry frame (north up, centred on the robot, pan and zoom kept):
the occupancy grid built from the scans, a metre grid, the trail, the planned path, the
waypoints and shuttle points, the latest scan, the footprint with its heading and the 2-sigma
ellipse of the position's uncertainty, and the safety-zone rings (the footprint grown by each
zone's distance). A click sets a waypoint, or a shuttle point in that mode; a drag pans, the
wheel zooms about the cursor, a double click centres on the robot again. It reads the console
model (its navigator) and writes the operator's clicks back to it; it works in a replay,
where the buttons that command the robot are disabled.

`MapPanel` adds the buttons (path, ellipse, linear, stop, clear, override, reset) and a line
of facts; `NavStatus` is the status bar's word on the zones and the assisted mode.
"""

from __future__ import annotations

import math

import numpy as np
from PySide6.QtCore import QLineF, QPointF, QRectF, Qt, QTimer
from PySide6.QtGui import (
    QColor,
    QImage,
    QMouseEvent,
    QPainter,
    QPainterPath,
    QPaintEvent,
    QPen,
    QPolygonF,
    QTransform,
    QWheelEvent,
)
from PySide6.QtWidgets import (
    QComboBox,
    QHBoxLayout,
    QLabel,
    QPushButton,
    QSizePolicy,
    QVBoxLayout,
    QWidget,
)

from ocu.console.model import ConsoleModel
from ocu.nav.navigator import ZONES_OFF_NO_DATA, ZoneState
from ocu.records import CommandError
from ocu.widgets.elided_label import ElidedLabel

REFRESH_MS = 100
DEFAULT_SCALE_PX_PER_M = 60.0
MIN_SCALE = 8.0
MAX_SCALE = 600.0
CLICK_SLOP_PX = 5
WAYPOINTS = "waypoints"
SHUTTLE = "shuttle points"
BACKGROUND = QColor(128, 128, 128)
GRID_PEN = QColor(255, 255, 255, 40)
TRAIL_COLOUR = QColor(79, 195, 247)
PATH_COLOUR = QColor(25, 118, 210)
WAYPOINT_COLOUR = QColor(255, 152, 0)
SHUTTLE_COLOUR = QColor(171, 71, 188)
SCAN_COLOUR = QColor(229, 57, 53)
ROBOT_COLOUR = QColor(38, 50, 56)
# Stop zone first, then each zone outward.
ZONE_COLOURS = (
    QColor(211, 47, 47),
    QColor(245, 124, 0),
    QColor(251, 192, 45),
    QColor(124, 179, 66),
)
ZONE_STYLES = {
    "limit": "background:#ef6c00;color:white;",
    "stop": "background:#c62828;color:white;",
    "override": "background:#b71c1c;color:#ffeb3b;",
    "off": "background:#616161;color:white;",
    "clear": "background:#2e7d32;color:white;",
}
STATUS_STYLE = "font-weight:bold;font-size:11pt;padding:3px 8px;border-radius:4px;"


class MapView(QWidget):
    """The top-down map (see the module docstring)."""

    def __init__(self, model: ConsoleModel, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.setObjectName("map_view")
        self.model = model
        self.nav = model.nav
        self.scale_px_per_m = DEFAULT_SCALE_PX_PER_M
        # Where the view's centre is, relative to the robot (m).
        self.pan_m = (0.0, 0.0)
        self.click_mode = WAYPOINTS
        self.read_only = False
        self._press: QPointF | None = None
        self._dragged = False
        self._grid_image: QImage | None = None
        self._grid_scans = -1
        self._grid_pixels: np.ndarray | None = None
        self.setMinimumSize(240, 200)
        self.setSizePolicy(QSizePolicy.Policy.Expanding, QSizePolicy.Policy.Expanding)
        self.setMouseTracking(False)
        self.setFocusPolicy(Qt.FocusPolicy.NoFocus)
        self._timer = QTimer(self)
        self._timer.setInterval(REFRESH_MS)
        self._timer.timeout.connect(self.update)
        self._timer.start()
        model.events.odometry_reset.connect(self.centre)

    # ---- coordinates -------------------------------------------------------------------

    def _centre_m(self) -> tuple[float, float]:
        pose = self.nav.estimate().pose
        return pose.x_m + self.pan_m[0], pose.y_m + self.pan_m[1]

    def world_to_screen(self, x_m: float, y_m: float) -> QPointF:
        """Screen position of a point of the odometry frame."""
        cx, cy = self._centre_m()
        return QPointF(
            self.width() / 2.0 + (x_m - cx) * self.scale_px_per_m,
            self.height() / 2.0 - (y_m - cy) * self.scale_px_per_m,
        )

    def screen_to_world(self, point: QPointF) -> tuple[float, float]:
        """The odometry-frame point under a screen position."""
        cx, cy = self._centre_m()
        return (
            cx + (point.x() - self.width() / 2.0) / self.scale_px_per_m,
            cy - (point.y() - self.height() / 2.0) / self.scale_px_per_m,
        )

    def _world_transform(self) -> QTransform:
        cx, cy = self._centre_m()
        s = self.scale_px_per_m
        return QTransform(
            s, 0.0, 0.0, -s, self.width() / 2.0 - cx * s, self.height() / 2.0 + cy * s
        )

    def centre(self) -> None:
        """Centre the view on the robot again."""
        self.pan_m = (0.0, 0.0)
        self.update()

    def zoom(self, factor: float, about: QPointF | None = None) -> None:
        """Zoom by a factor, keeping the point under `about` (the centre if None) in place."""
        about = about if about is not None else QPointF(self.width() / 2.0, self.height() / 2.0)
        before = self.screen_to_world(about)
        self.scale_px_per_m = min(max(self.scale_px_per_m * factor, MIN_SCALE), MAX_SCALE)
        after = self.screen_to_world(about)
        self.pan_m = (self.pan_m[0] + before[0] - after[0], self.pan_m[1] + before[1] - after[1])
        self.update()

    # ---- mouse -------------------------------------------------------------------------

    def wheelEvent(self, event: QWheelEvent) -> None:
        """Zoom about the cursor."""
        steps = event.angleDelta().y() / 120.0
        if steps:
            self.zoom(1.2**steps, event.position())
        event.accept()

    def mousePressEvent(self, event: QMouseEvent) -> None:
        """Start a click or a drag."""
        self._press = event.position()
        self._dragged = False
        event.accept()

    def mouseMoveEvent(self, event: QMouseEvent) -> None:
        """Pan while dragging."""
        if self._press is None:
            return
        delta = event.position() - self._press
        if not self._dragged and math.hypot(delta.x(), delta.y()) < CLICK_SLOP_PX:
            return
        self._dragged = True
        self.pan_m = (
            self.pan_m[0] - delta.x() / self.scale_px_per_m,
            self.pan_m[1] + delta.y() / self.scale_px_per_m,
        )
        self._press = event.position()
        self.update()

    def mouseReleaseEvent(self, event: QMouseEvent) -> None:
        """A click without a drag marks a point."""
        clicked = self._press is not None and not self._dragged
        if clicked and not self.read_only and event.button() == Qt.MouseButton.LeftButton:
            self.click(event.position())
        self._press = None
        event.accept()

    def mouseDoubleClickEvent(self, event: QMouseEvent) -> None:
        """Centre on the robot."""
        self.centre()
        event.accept()

    def click(self, point: QPointF) -> None:
        """Mark the point under a screen position (a waypoint, or a shuttle point)."""
        x_m, y_m = self.screen_to_world(point)
        if self.click_mode == SHUTTLE:
            self.model.add_shuttle_point(x_m, y_m)
        else:
            self.model.add_waypoint(x_m, y_m)
        self.update()

    # ---- drawing -----------------------------------------------------------------------

    def paintEvent(self, event: QPaintEvent) -> None:
        """Draw the map (see the module docstring)."""
        del event
        painter = QPainter(self)
        painter.setRenderHint(QPainter.RenderHint.Antialiasing)
        painter.fillRect(self.rect(), BACKGROUND)
        estimate = self.nav.estimate()
        painter.save()
        painter.setTransform(self._world_transform())
        self._draw_grid_map(painter)
        self._draw_metre_grid(painter)
        self._draw_trail(painter)
        self._draw_path(painter)
        self._draw_zones(painter, estimate.pose)
        self._draw_scan(painter, estimate.pose)
        self._draw_robot(painter, estimate)
        painter.restore()
        self._draw_marks(painter)
        self._draw_scale(painter)
        painter.end()

    def _pen(
        self, colour: QColor, width_px: float, style: Qt.PenStyle = Qt.PenStyle.SolidLine
    ) -> QPen:
        # Cosmetic: the width is in pixels whatever the zoom (and far cheaper to draw).
        pen = QPen(colour, width_px)
        pen.setStyle(style)
        pen.setCosmetic(True)
        return pen

    def _draw_grid_map(self, painter: QPainter) -> None:
        grid = self.nav.grid
        if grid is None:
            return
        if grid.scans != self._grid_scans or self._grid_image is None:
            self._grid_scans = grid.scans
            # Row 0 is the lowest y: flip so the image's top row is the highest y.
            pixels = np.ascontiguousarray(grid.image()[::-1])
            self._grid_pixels = pixels  # the QImage does not copy
            height, width = pixels.shape
            self._grid_image = QImage(
                pixels.data, width, height, pixels.strides[0], QImage.Format.Format_Grayscale8
            )
        x0, y0 = grid.origin_m
        size = grid.size_m
        painter.save()
        # The image's top-left is (x0, y0 + size); flip back the world's y for it.
        painter.translate(x0, y0 + size)
        painter.scale(size / grid.cells, -size / grid.cells)
        painter.setRenderHint(QPainter.RenderHint.SmoothPixmapTransform, False)
        painter.drawImage(QPointF(0.0, 0.0), self._grid_image)
        painter.restore()

    def _visible_bounds(self) -> tuple[float, float, float, float]:
        x0, y0 = self.screen_to_world(QPointF(0.0, float(self.height())))
        x1, y1 = self.screen_to_world(QPointF(float(self.width()), 0.0))
        return x0, y0, x1, y1

    def _draw_metre_grid(self, painter: QPainter) -> None:
        x0, y0, x1, y1 = self._visible_bounds()
        step = 1.0 if self.scale_px_per_m >= 20 else 5.0
        painter.setPen(self._pen(GRID_PEN, 1.0))
        # Axis-aligned lines need no antialiasing (and software rendering of it is slow).
        painter.setRenderHint(QPainter.RenderHint.Antialiasing, False)
        lines: list[QLineF] = []
        x = math.floor(x0 / step) * step
        while x <= x1:
            lines.append(QLineF(x, y0, x, y1))
            x += step
        y = math.floor(y0 / step) * step
        while y <= y1:
            lines.append(QLineF(x0, y, x1, y))
            y += step
        painter.drawLines(lines)
        painter.setRenderHint(QPainter.RenderHint.Antialiasing, True)

    def _draw_trail(self, painter: QPainter) -> None:
        trail = list(self.nav.trail)
        if len(trail) < 2:
            return
        painter.setPen(self._pen(TRAIL_COLOUR, 2.0))
        painter.drawPolyline(QPolygonF([QPointF(x, y) for x, y in trail]))

    def _draw_path(self, painter: QPainter) -> None:
        path = self.nav.planned_path()
        if len(path) >= 2 and self.model.assist_mode == "path":
            painter.setPen(self._pen(PATH_COLOUR, 3.0))
            painter.drawPolyline(QPolygonF([QPointF(float(x), float(y)) for x, y in path]))
        points = self.model.waypoints
        if points and self.model.assist_mode != "path":
            pose = self.nav.estimate().pose
            line = [(pose.x_m, pose.y_m), *points]
            painter.setPen(self._pen(WAYPOINT_COLOUR, 1.5, Qt.PenStyle.DashLine))
            painter.drawPolyline(QPolygonF([QPointF(x, y) for x, y in line]))
        shuttle = self.model.shuttle_points
        if len(shuttle) == 2:
            painter.setPen(self._pen(SHUTTLE_COLOUR, 2.0, Qt.PenStyle.DashLine))
            painter.drawLine(QPointF(*shuttle[0]), QPointF(*shuttle[1]))

    def _draw_zones(self, painter: QPainter, pose: object) -> None:
        footprint = self.nav.footprint
        if footprint is None:
            return
        settings = self.nav.settings.zones
        distances = (settings.stop_m, *settings.within_m)
        active = self.nav.zones.active
        painter.save()
        self._to_robot(painter)
        for index, distance in enumerate(distances):
            colour = QColor(ZONE_COLOURS[min(index, len(ZONE_COLOURS) - 1)])
            colour.setAlpha(220 if active else 70)
            painter.setPen(self._pen(colour, 1.5))
            painter.setBrush(Qt.BrushStyle.NoBrush)
            rect = QRectF(
                -footprint.rear_m - distance,
                -footprint.half_width_m - distance,
                footprint.front_m + footprint.rear_m + 2 * distance,
                2 * (footprint.half_width_m + distance),
            )
            painter.drawRoundedRect(rect, distance, distance)
        painter.restore()
        del pose

    def _to_robot(self, painter: QPainter) -> None:
        pose = self.nav.estimate().pose
        painter.translate(pose.x_m, pose.y_m)
        painter.rotate(math.degrees(pose.heading_rad))

    def _draw_scan(self, painter: QPainter, pose: object) -> None:
        _scan, points = self.nav.scan()
        if len(points) == 0:
            return
        age = self.nav.scan_age_s()
        colour = QColor(SCAN_COLOUR)
        if age is None or age > self.nav.settings.scan_stale_after_s:
            colour.setAlpha(80)
        painter.save()
        self._to_robot(painter)
        painter.setPen(self._pen(colour, 4.0))
        painter.setRenderHint(QPainter.RenderHint.Antialiasing, False)
        painter.drawPoints(QPolygonF([QPointF(float(x), float(y)) for x, y in points]))
        painter.restore()
        del pose

    def _draw_robot(self, painter: QPainter, estimate: object) -> None:
        from ocu.nav.odometry import OdometryEstimate

        assert isinstance(estimate, OdometryEstimate)
        pose = estimate.pose
        # The 2-sigma ellipse of the position.
        cov = estimate.covariance[:2, :2]
        values, vectors = np.linalg.eigh(cov)
        if values.max() > 1e-8:
            painter.save()
            painter.translate(pose.x_m, pose.y_m)
            painter.rotate(math.degrees(math.atan2(vectors[1, 1], vectors[0, 1])))
            a = 2.0 * math.sqrt(max(values[1], 0.0))
            b = 2.0 * math.sqrt(max(values[0], 0.0))
            colour = QColor(ROBOT_COLOUR)
            colour.setAlpha(50)
            painter.setBrush(colour)
            painter.setPen(self._pen(ROBOT_COLOUR, 1.0, Qt.PenStyle.DotLine))
            painter.drawEllipse(QPointF(0.0, 0.0), a, b)
            painter.restore()
        footprint = self.nav.footprint
        painter.save()
        self._to_robot(painter)
        body = QColor(255, 183, 77) if not estimate.stale else QColor(189, 189, 189)
        painter.setBrush(body)
        painter.setPen(self._pen(ROBOT_COLOUR, 2.0))
        if footprint is not None:
            painter.drawRect(
                QRectF(
                    -footprint.rear_m,
                    -footprint.half_width_m,
                    footprint.front_m + footprint.rear_m,
                    2 * footprint.half_width_m,
                )
            )
            tip = footprint.front_m
        else:
            painter.drawEllipse(QPointF(0.0, 0.0), 0.3, 0.3)
            tip = 0.3
        arrow = QPainterPath(QPointF(tip * 0.9, 0.0))
        arrow.lineTo(QPointF(tip * 0.3, 0.15))
        arrow.lineTo(QPointF(tip * 0.3, -0.15))
        arrow.closeSubpath()
        painter.setBrush(ROBOT_COLOUR)
        painter.drawPath(arrow)
        painter.restore()

    def _draw_marks(self, painter: QPainter) -> None:
        """Waypoints and shuttle points, in screen pixels so they keep their size."""
        font = painter.font()
        font.setBold(True)
        painter.setFont(font)
        for marks, colour, labels in (
            (self.model.waypoints, WAYPOINT_COLOUR, None),
            (self.model.shuttle_points, SHUTTLE_COLOUR, ("A", "B")),
        ):
            for index, (x, y) in enumerate(marks):
                centre = self.world_to_screen(x, y)
                painter.setPen(QPen(QColor(0, 0, 0), 1.5))
                painter.setBrush(colour)
                painter.drawEllipse(centre, 9.0, 9.0)
                painter.setPen(QColor(255, 255, 255))
                text = labels[index] if labels else str(index + 1)
                painter.drawText(
                    QRectF(centre.x() - 9, centre.y() - 9, 18, 18),
                    Qt.AlignmentFlag.AlignCenter,
                    text,
                )

    def _draw_scale(self, painter: QPainter) -> None:
        metres = 1.0 if self.scale_px_per_m >= 30 else 5.0
        length = metres * self.scale_px_per_m
        x, y = 12.0, self.height() - 14.0
        painter.setPen(QPen(QColor(255, 255, 255), 2))
        painter.drawLine(QPointF(x, y), QPointF(x + length, y))
        painter.drawLine(QPointF(x, y - 4), QPointF(x, y + 4))
        painter.drawLine(QPointF(x + length, y - 4), QPointF(x + length, y + 4))
        painter.drawText(QPointF(x + length + 6, y + 4), f"{metres:g} m")


class MapPanel(QWidget):
    """The map with its buttons and a line of facts (the dock's widget)."""

    def __init__(self, model: ConsoleModel, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.setObjectName("map_panel")
        self.model = model
        self.view = MapView(model)
        self.facts = QLabel()
        self.facts.setObjectName("map_facts")
        self.facts.setStyleSheet("font-size:10pt;")
        self.facts.setWordWrap(True)
        self.path_button = self._button("Follow path (P)", self._toggle_path)
        self.ellipse_button = self._button("Ellipse", self._ellipse)
        self.linear_button = self._button("Linear (L)", self._toggle_linear)
        self.clear_button = self._button("Clear (X)", model.clear_waypoints)
        self.override_button = self._button("Override zones (Z)", model.override_zones)
        self.reset_button = self._button("Reset odometry (O)", model.reset_odometry)
        self.centre_button = self._button("Centre", self.view.centre)
        self.click_mode = QComboBox()
        self.click_mode.addItems([WAYPOINTS, SHUTTLE])
        self.click_mode.setFocusPolicy(Qt.FocusPolicy.NoFocus)
        self.click_mode.setToolTip("What a click on the map marks")
        self.click_mode.currentTextChanged.connect(self._set_click_mode)
        row = QHBoxLayout()
        row.setContentsMargins(0, 0, 0, 0)
        row.addWidget(QLabel("Click:"))
        row.addWidget(self.click_mode)
        for button in (
            self.path_button,
            self.ellipse_button,
            self.linear_button,
            self.clear_button,
        ):
            row.addWidget(button)
        row.addStretch(1)
        second = QHBoxLayout()
        second.setContentsMargins(0, 0, 0, 0)
        for button in (self.override_button, self.reset_button, self.centre_button):
            second.addWidget(button)
        second.addStretch(1)
        layout = QVBoxLayout(self)
        layout.setContentsMargins(4, 4, 4, 4)
        layout.addLayout(row)
        layout.addLayout(second)
        layout.addWidget(self.view, 1)
        layout.addWidget(self.facts)
        self._timer = QTimer(self)
        self._timer.setInterval(REFRESH_MS * 3)
        self._timer.timeout.connect(self.refresh_facts)
        self._timer.start()
        model.events.assist_changed.connect(lambda _kind, _text: self._buttons())
        self._buttons()
        self.refresh_facts()

    def _button(self, text: str, action: object) -> QPushButton:
        button = QPushButton(text)
        button.setFocusPolicy(Qt.FocusPolicy.NoFocus)
        button.clicked.connect(lambda: self._run(action))
        return button

    def _run(self, action: object) -> None:
        assert callable(action)
        try:
            action()
        except CommandError as err:
            self.model.events.message.emit(str(err))

    def _set_click_mode(self, mode: str) -> None:
        self.view.click_mode = mode

    def _toggle_path(self) -> None:
        if self.model.assist_mode == "path":
            self.model.stop_assist("stopped from the map")
        else:
            self.model.start_path()

    def _toggle_linear(self) -> None:
        if self.model.assist_mode == "linear":
            self.model.stop_assist("stopped from the map")
        else:
            self.model.start_linear()

    def _ellipse(self) -> None:
        if self.model.assist_mode is not None:
            self.model.stop_assist("stopped from the map")
        else:
            self.model.start_ellipse()

    def _buttons(self) -> None:
        mode = self.model.assist_mode
        self.path_button.setText("Stop path (P)" if mode == "path" else "Follow path (P)")
        self.linear_button.setText("Stop linear (L)" if mode == "linear" else "Linear (L)")
        self.ellipse_button.setText("Stop" if mode is not None else "Ellipse")

    def set_replay(self) -> None:
        """A replay: nothing that commands the robot; reset and the view still work."""
        self.view.read_only = True
        for button in (
            self.path_button,
            self.ellipse_button,
            self.linear_button,
            self.clear_button,
            self.override_button,
        ):
            button.setEnabled(False)
            button.setToolTip("Replay: commands are disabled")
        self.click_mode.setEnabled(False)

    def refresh_facts(self) -> None:
        """Pose, uncertainty, where it comes from, scan and zones."""
        nav = self.model.nav
        estimate = nav.estimate()
        pose = estimate.pose
        source = {"tracks": "track speeds", "commands": "commands", "stopped": "at rest"}.get(
            estimate.source, estimate.source
        )
        heading = "IMU heading" if estimate.heading_measured else "integrated heading"
        stale = "  ODOMETRY STALE" if estimate.stale else ""
        age = nav.scan_age_s()
        scan = "no range data" if age is None else f"scan {age:.1f} s old"
        progress = nav.assist_progress()
        mode = self.model.assist_mode
        assist = (
            f"  ·  {mode} mode" + (f" {progress:.0%}" if progress is not None else "")
            if mode
            else ""
        )
        self.facts.setText(
            f"x {pose.x_m:+.2f} m  y {pose.y_m:+.2f} m  θ {math.degrees(pose.heading_rad):+.0f}°"
            f"  ±{estimate.sigma_xy_m:.2f} m ±{math.degrees(estimate.sigma_heading_rad):.1f}°"
            f"  ·  {source}, {heading}  ·  {estimate.distance_m:.1f} m driven  ·  {scan}"
            f"{assist}{stale}"
        )
        self.facts.setStyleSheet(
            "font-size:10pt;color:#c62828;font-weight:bold;"
            if estimate.stale
            else "font-size:10pt;"
        )


class NavStatus(ElidedLabel):
    """The status bar's word on the safety zones and the assisted mode (shortened, whole in
    its tooltip, where the status bar is short of room)."""

    def __init__(self, model: ConsoleModel, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.setObjectName("nav_status")
        self.model = model
        self._zones: ZoneState | None = None
        self._assist = ""
        model.events.zones_changed.connect(self._on_zones)
        model.events.assist_changed.connect(self._on_assist)
        self._show()

    def _on_zones(self, zones: ZoneState) -> None:
        self._zones = zones
        self._show()

    def _on_assist(self, kind: str | None, _text: str) -> None:
        self._assist = f"{kind.upper()} MODE · " if kind else ""
        self._show()

    def _show(self) -> None:
        zones = self._zones
        text = zones.text if zones is not None else ZONES_OFF_NO_DATA
        if zones is not None and zones.overridden:
            style = "override"
        elif zones is not None and zones.decision is not None and zones.decision.stopped:
            style = "stop"
        elif zones is not None and (zones.limiting or zones.blind):
            style = "limit"
        elif zones is None or not zones.active:
            style = "off"
        else:
            style = "clear"
        self.setText(self._assist + text)
        self.setStyleSheet(STATUS_STYLE + ZONE_STYLES[style])
        self.setProperty("zone_style", style)

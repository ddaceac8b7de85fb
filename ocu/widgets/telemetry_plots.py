"""Live plots of every motor's position, speed and current over a bounded time window."""

from __future__ import annotations

import math
from collections import deque

import pyqtgraph as pg
from PySide6.QtCore import QTimer
from PySide6.QtWidgets import QVBoxLayout, QWidget

from ocu.link.core import TelemetryFrame
from ocu.profile import RobotProfile

WINDOW_S = 60.0
REDRAW_PERIOD_MS = 250
QUANTITIES = (
    ("position", "angle", "°"),
    ("speed", "speed", "rad/s · m/s"),
    ("current", "current", "A"),
)


class TelemetryPlots(QWidget):
    """Three stacked plots sharing the time axis (seconds before the latest packet)."""

    def __init__(
        self, profile: RobotProfile, window_s: float = WINDOW_S, parent: QWidget | None = None
    ) -> None:
        super().__init__(parent)
        self.setObjectName("telemetry_plots")
        self.profile = profile
        self.window_s = window_s
        self.samples: dict[str, deque[tuple[float, float | None, float, float]]] = {
            name: deque() for name in profile.motors
        }
        self._latest_at: float | None = None
        self._dirty = False
        layout = QVBoxLayout(self)
        layout.setContentsMargins(0, 0, 0, 0)
        self.graphics = pg.GraphicsLayoutWidget()
        self.graphics.setBackground("w")
        layout.addWidget(self.graphics)
        self.plots: dict[str, pg.PlotItem] = {}
        self.curves: dict[tuple[str, str], pg.PlotDataItem] = {}
        colours = {
            name: pg.intColor(index, hues=len(profile.motors), values=1, maxValue=200)
            for index, name in enumerate(profile.motors)
        }
        first: pg.PlotItem | None = None
        for row, (key, title, unit) in enumerate(QUANTITIES):
            plot = self.graphics.addPlot(row=row, col=0)
            plot.setTitle(f"{title} ({unit})", size="9pt")
            plot.getAxis("left").enableAutoSIPrefix(False)
            plot.getAxis("bottom").enableAutoSIPrefix(False)
            plot.showGrid(x=True, y=True, alpha=0.3)
            plot.setXRange(-window_s, 0.0, padding=0.0)
            plot.setMouseEnabled(x=False, y=True)
            if first is None:
                first = plot
                plot.addLegend(offset=(2, 2), labelTextSize="7pt", colCount=4)
            else:
                plot.setXLink(first)
            if row == len(QUANTITIES) - 1:
                plot.setLabel("bottom", "seconds before the latest packet")
            for name, motor in profile.motors.items():
                if key == "position" and not motor.has_position:
                    continue
                curve = plot.plot([], [], pen=pg.mkPen(colours[name], width=2), name=name)
                self.curves[(key, name)] = curve
            self.plots[key] = plot
        self._timer = QTimer(self)
        self._timer.setInterval(REDRAW_PERIOD_MS)
        self._timer.timeout.connect(self.redraw)
        self._timer.start()

    def add_frame(self, frame: TelemetryFrame) -> None:
        """Store one packet's readings; old samples beyond the window are dropped."""
        at = frame.received_at
        for name, reading in frame.readings.items():
            series = self.samples.get(name)
            if series is None:
                continue
            # An implausible angle (-11796480° for a broken encoder) would flatten the plot.
            angle = None
            if reading.angle_rad is not None and reading.fault is None:
                angle = math.degrees(reading.angle_rad)
            series.append((at, angle, reading.speed_rad_s, reading.current_a))
            while series and series[0][0] < at - self.window_s:
                series.popleft()
        self._latest_at = at
        self._dirty = True

    def sample_count(self, name: str) -> int:
        """Samples held for one motor (bounded by the window)."""
        return len(self.samples[name])

    def redraw(self) -> None:
        """Re-plot the curves if new samples arrived."""
        if not self._dirty or self._latest_at is None:
            return
        self._dirty = False
        latest = self._latest_at
        for name, series in self.samples.items():
            times = [s[0] - latest for s in series]
            for index, (key, _, _) in enumerate(QUANTITIES, start=1):
                curve = self.curves.get((key, name))
                if curve is None:
                    continue
                values = [s[index] for s in series]
                points = [(t, v) for t, v in zip(times, values, strict=True) if v is not None]
                curve.setData([p[0] for p in points], [p[1] for p in points])

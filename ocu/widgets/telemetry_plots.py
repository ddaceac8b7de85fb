"""Live plots of every motor's position, speed and current: a view of the robot's history.

The samples live in the console model (ocu.console.robot.RobotState.history); each plot
redraws from it at most four times a second, and only while it is on screen. The value
axes move in steps (a range is kept until the data leaves it or fills less than a quarter of
it), so the axes — most of a plot's painting cost — are not laid out again at every redraw.

The plots paint on the GUI thread, and a key pressed while they paint waits for them: so the
three are redrawn in turn, a third of the period apart, each one paint of its own (about a
third as long as all three at once), with one-pixel cosmetic pens (Qt draws those as one
polyline; a wider pen makes pyqtgraph build line segments in Python at every paint) and no
finite check (the samples are filtered before they are handed over).
"""

from __future__ import annotations

import math

import numpy as np
import pyqtgraph as pg
from PySide6.QtCore import QTimer
from PySide6.QtGui import QShowEvent
from PySide6.QtWidgets import QVBoxLayout, QWidget

from ocu.console.robot import RobotState
from ocu.records import TelemetryFrame

REDRAW_PERIOD_MS = 250
# A value range is widened with this margin (fraction of the data's span) when data leaves it.
RANGE_MARGIN = 0.25
# ...and narrowed again when the data fills less than this fraction of it.
RANGE_SHRINK_BELOW = 0.25
MIN_SPAN = 1e-3
QUANTITIES = (
    ("position", "angle", "°"),
    ("speed", "speed", "rad/s · m/s"),
    ("current", "current", "A"),
)


class TelemetryPlots(QWidget):
    """Three stacked plots sharing the time axis (seconds before the latest packet)."""

    def __init__(self, robot: RobotState, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.setObjectName("telemetry_plots")
        self.robot = robot
        profile = robot.profile
        window_s = robot.history_s
        self._dirty: set[str] = set()  # the quantities with samples not yet drawn
        self._turn = 0  # the quantity the next tick redraws
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
            plot.enableAutoRange(y=False)  # stepped ranges instead (see the module docstring)
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
                pen = pg.mkPen(colours[name], width=1, cosmetic=True)
                curve = plot.plot([], [], pen=pen, name=name, skipFiniteCheck=True)
                curve.setClipToView(True)
                curve.setDownsampling(auto=True, method="peak")
                self.curves[(key, name)] = curve
            self.plots[key] = plot
        self._ranges: dict[str, tuple[float, float]] = {}
        self._timer = QTimer(self)
        self._timer.setInterval(REDRAW_PERIOD_MS // len(QUANTITIES))
        self._timer.timeout.connect(self._redraw_next)
        self._timer.start()
        robot.events.telemetry_changed.connect(self._on_telemetry)

    def _on_telemetry(self, _frame: TelemetryFrame) -> None:
        self._dirty = {key for key, _, _ in QUANTITIES}

    def _redraw_next(self) -> None:
        key = QUANTITIES[self._turn][0]
        self._turn = (self._turn + 1) % len(QUANTITIES)
        self.redraw(keys=(key,))

    def sample_count(self, name: str) -> int:
        """Samples of one motor in the model's history (bounded by its window)."""
        return len(self.robot.history[name])

    def redraw(self, *, force: bool = False, keys: tuple[str, ...] | None = None) -> None:
        """Re-plot the curves of `keys` (all: None) that have new samples, when on screen;
        `force`: whether or not they have, and on screen or not."""
        latest = self.robot.last_telemetry_at
        if force:
            wanted = {key for key, _, _ in QUANTITIES} if keys is None else set(keys)
        else:
            wanted = set(self._dirty) if keys is None else self._dirty & set(keys)
        if not wanted or latest is None:
            return
        # The viewport, not the view: a QGraphicsView's own region is all covered by its
        # opaque viewport child, so the view's visibleRegion() is empty even on screen.
        if not force and self.graphics.viewport().visibleRegion().isEmpty():
            return  # hidden (a closed dock, another tab): drawn when shown again
        self._dirty -= wanted
        spans: dict[str, list[float]] = {key: [] for key in wanted}
        for name, series in self.robot.history.items():
            if not series:
                continue
            samples = np.array(
                # tuple(): one copy the control thread cannot change under the loop.
                [(s[0], math.nan if s[1] is None else s[1], s[2], s[3]) for s in tuple(series)],
                dtype=np.float64,
            )
            times = samples[:, 0] - latest
            for index, (key, _, _) in enumerate(QUANTITIES, start=1):
                curve = self.curves.get((key, name)) if key in wanted else None
                if curve is None:
                    continue
                values = samples[:, index]
                known = np.isfinite(values)
                curve.setData(times[known], values[known])
                if known.any():
                    spans[key] += [float(values[known].min()), float(values[known].max())]
        for key, extremes in spans.items():
            if extremes:
                self._step_range(key, min(extremes), max(extremes))

    def showEvent(self, event: QShowEvent) -> None:
        super().showEvent(event)
        self.redraw()

    def _step_range(self, key: str, low: float, high: float) -> None:
        """Keep the value axis still unless the data leaves it or shrinks far inside it."""
        current = self._ranges.get(key)
        span = max(high - low, MIN_SPAN)
        if current is not None:
            shown_low, shown_high = current
            inside = shown_low <= low and high <= shown_high
            if inside and span >= RANGE_SHRINK_BELOW * (shown_high - shown_low):
                return
        margin = RANGE_MARGIN * span
        self._ranges[key] = (low - margin, high + margin)
        self.plots[key].setYRange(low - margin, high + margin, padding=0.0)

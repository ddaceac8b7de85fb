"""Live plots of every motor's position, speed and current: a view of the robot's history.

The samples live in the console model (ocu.console.robot.RobotState.history); the plots
redraw from it at most four times a second.
"""

from __future__ import annotations

import pyqtgraph as pg
from PySide6.QtCore import QTimer
from PySide6.QtWidgets import QVBoxLayout, QWidget

from ocu.console.robot import RobotState
from ocu.records import TelemetryFrame

REDRAW_PERIOD_MS = 250
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
        robot.events.telemetry_changed.connect(self._on_telemetry)

    def _on_telemetry(self, _frame: TelemetryFrame) -> None:
        self._dirty = True

    def sample_count(self, name: str) -> int:
        """Samples of one motor in the model's history (bounded by its window)."""
        return len(self.robot.history[name])

    def redraw(self) -> None:
        """Re-plot the curves if new samples arrived."""
        latest = self.robot.last_telemetry_at
        if not self._dirty or latest is None:
            return
        self._dirty = False
        for name, series in self.robot.history.items():
            times = [s[0] - latest for s in series]
            for index, (key, _, _) in enumerate(QUANTITIES, start=1):
                curve = self.curves.get((key, name))
                if curve is None:
                    continue
                values = [s[index] for s in series]
                points = [(t, v) for t, v in zip(times, values, strict=True) if v is not None]
                curve.setData([p[0] for p in points], [p[1] for p in points])

"""The Link dock: the command rate set while driving, and how the link behaved, in graphs.

Four plots share one time axis (seconds before now) over a chosen window of 1-10 minutes:
the rates (commands sent, telemetry, video and scans received), the loss each way, the
measured round trip and the delay's jitter, and the age of each camera's newest frame. LINK LOST,
the link's return and emergency stops are vertical lines through all four. The figures come
from a `LinkHistory` (ocu.link.history) subscribed to the console's link, a replay's too.

Pause freezes the picture; while paused the time axis scrolls and zooms with the mouse over
the whole history. The plots redraw twice a second, and only while they are on screen and
something new arrived. The command rate (the profile's bounds) and the window are remembered
in the console's settings; the rate is applied to every live link the console starts.
"""

from __future__ import annotations

import logging
import math
import time

import numpy as np
import pyqtgraph as pg
from PySide6.QtCore import QSettings, Qt, QTimer
from PySide6.QtGui import QShowEvent
from PySide6.QtWidgets import (
    QFrame,
    QHBoxLayout,
    QLabel,
    QPushButton,
    QScrollArea,
    QSpinBox,
    QVBoxLayout,
    QWidget,
)

from ocu.link.base import Link
from ocu.link.history import LinkHistory, LinkMark, LinkSeries, MarkKind
from ocu.profile import RobotProfile

log = logging.getLogger("ocu.widgets")

REDRAW_PERIOD_MS = 500
AXIS_WIDTH_PX = 44
MIN_PLOT_HEIGHT_PX = 95
# A value axis starts at zero and ends this far above the data's top (and at least at the
# minimum), stepping only when the data leaves it or falls below a third of it.
Y_HEADROOM = 1.35
DELAY_TOP_PERCENTILE = 95.0
UPLINK_UNMEASURABLE_TITLE = "commands lost (OCU → robot): not measurable"
Y_MIN_TOPS = {"rates": 10.0, "video": 10.0, "delay": 50.0, "frame_age": 1.0}
RATE_KEY = "link/command_rate_hz"
WINDOW_KEY = "link/window_min"
WINDOW_MIN_RANGE = (1, 10)
DEFAULT_WINDOW_MIN = 2
MARK_COLOURS = {
    MarkKind.LINK_LOST: "#c62828",
    MarkKind.LINK_BACK: "#2e7d32",
    MarkKind.ESTOP: "#ef6c00",
}
# (figure, legend name, colour, dashed) per plot; the frame ages are added per camera.
RATE_CURVES = (
    ("command_rate_hz", "commands sent", "#1565c0", False),
    ("command_rate_setting_hz", "command rate set", "#1565c0", True),
    ("telemetry_rate_hz", "telemetry received", "#2e7d32", False),
    ("scan_rate_hz", "scans received", "#8d6e63", False),
)
VIDEO_CURVES = (("video_rate_hz", "frames received, all cameras", "#6a1b9a", False),)
LOSS_CURVES = (
    ("downlink_loss", "telemetry lost (robot → OCU)", "#c62828", False),
    ("uplink_loss", "commands lost (OCU → robot)", "#283593", False),
)
DELAY_CURVES = (
    ("round_trip_s", "round trip", "#00838f", False),
    ("jitter_s", "jitter (robot → OCU delay)", "#f9a825", False),
)
# Figures shown in other units than the history's.
SCALES = {"downlink_loss": 100.0, "uplink_loss": 100.0, "round_trip_s": 1000.0, "jitter_s": 1000.0}


def _legend_key(label: str, colour: str, dashed: bool | None) -> str:
    """A curve's key in a plot's title: its line (none for None) and label in its colour."""
    line = "" if dashed is None else ("╌╌ " if dashed else "── ")
    return f"<span style='color:{pg.mkColor(colour).name()}'>{line}{label}</span>"


def _setting_number(settings: QSettings, key: str, default: float) -> float:
    """A number from the settings; the default (and a warning) for anything else."""
    value = settings.value(key)
    if value is None:
        return default
    try:
        number = float(str(value))
    except ValueError:
        log.warning("settings %s: %r is not a number, %g used", key, value, default)
        return default
    return number if math.isfinite(number) else default


class LinkGraphsPanel(QWidget):
    """The Link dock's contents (see the module docstring)."""

    def __init__(
        self, profile: RobotProfile, settings: QSettings, parent: QWidget | None = None
    ) -> None:
        super().__init__(parent)
        self.setObjectName("link_graphs")
        self.profile = profile
        self.settings = settings
        self.camera_names = profile.link.camera_names
        self.history = LinkHistory(len(self.camera_names))
        self.link: Link | None = None
        self._drawn_version = -1
        self._frozen_at: float | None = None
        self._mark_items: list[tuple[pg.InfiniteLine, pg.PlotItem, float]] = []
        self._drawn_marks: list[LinkMark] = []
        # The GUI thread's time for the last redraw (perf_counter seconds): the dock's cost.
        self.last_redraw_s = 0.0
        self.redraws = 0

        link = profile.link
        self.rate_box = QSpinBox()
        self.rate_box.setObjectName("command_rate")
        self.rate_box.setRange(math.ceil(link.send_rate_min_hz), math.floor(link.send_rate_max_hz))
        self.rate_box.setSuffix(" Hz")
        self.rate_box.setFocusPolicy(Qt.FocusPolicy.ClickFocus)
        self.rate_box.setToolTip(
            "How often the command is sent to the robot (it is also sent at once when it "
            f"changes); {link.send_rate_min_hz:g}-{link.send_rate_max_hz:g} Hz. Camera rates: "
            "the Video dock. The telemetry rate is the robot's own: no protocol asks for it."
        )
        saved_rate = _setting_number(settings, RATE_KEY, link.send_rate_hz)
        self.rate_box.setValue(round(saved_rate))
        self.rate_box.valueChanged.connect(self._on_rate)
        self.window_box = QSpinBox()
        self.window_box.setObjectName("graph_window")
        self.window_box.setRange(*WINDOW_MIN_RANGE)
        self.window_box.setSuffix(" min")
        self.window_box.setFocusPolicy(Qt.FocusPolicy.ClickFocus)
        saved_window = _setting_number(settings, WINDOW_KEY, DEFAULT_WINDOW_MIN)
        self.window_box.setValue(round(saved_window))
        self.window_box.valueChanged.connect(self._on_window)
        self.pause_button = QPushButton("Pause")
        self.pause_button.setObjectName("pause_graphs")
        self.pause_button.setCheckable(True)
        self.pause_button.setFocusPolicy(Qt.FocusPolicy.NoFocus)
        self.pause_button.setToolTip("Freeze the graphs; drag or zoom the time axis to look back")
        self.pause_button.toggled.connect(self._on_pause)
        self.figures = QLabel("no statistics yet")
        self.figures.setObjectName("link_figures")
        self.figures.setWordWrap(True)

        controls = QHBoxLayout()
        controls.addWidget(QLabel("Command rate"))
        controls.addWidget(self.rate_box)
        controls.addSpacing(12)
        controls.addWidget(QLabel("Window"))
        controls.addWidget(self.window_box)
        controls.addStretch(1)
        controls.addWidget(self.pause_button)

        self.graphics = pg.GraphicsLayoutWidget()
        self.graphics.setBackground("w")
        self.plots: dict[str, pg.PlotItem] = {}
        self.curves: dict[str, pg.PlotDataItem] = {}
        self._plot_of: dict[str, str] = {}
        first: pg.PlotItem | None = None
        camera_curves = tuple(
            (
                f"frame_age_{index}",
                name,
                pg.intColor(index, hues=max(len(self.camera_names), 1)).name(),
            )
            for index, name in enumerate(self.camera_names)
        )
        layout_rows = (
            ("rates", "rates (Hz)", RATE_CURVES),
            ("video", "video (frames/s)", VIDEO_CURVES),
            ("loss", "loss (%)", LOSS_CURVES),
            ("delay", "round trip and jitter (ms)", DELAY_CURVES),
            ("frame_age", "frame age (s)", tuple((k, n, c, False) for k, n, c in camera_curves)),
        )
        for row, (key, title, curves) in enumerate(layout_rows):
            plot = self.graphics.addPlot(row=row, col=0)
            # The legend is the title: it never covers the data.
            keys = [_legend_key(label, colour, dashed) for _, label, colour, dashed in curves]
            if key == "loss":
                # Against a vendor robot the commands' curve gives way to the statement.
                unmeasurable = _legend_key(UPLINK_UNMEASURABLE_TITLE, "#555555", None)
                self._loss_titles = (
                    f"{title}: {' '.join(keys)}",
                    f"{title}: {keys[0]} · {unmeasurable}",
                )
                keys = [keys[0], "·", unmeasurable]
            plot.setTitle(f"{title}: {' '.join(keys)}", size="9pt")
            for axis in ("left", "bottom"):
                plot.getAxis(axis).enableAutoSIPrefix(False)
            plot.showGrid(x=True, y=True, alpha=0.3)
            plot.setMouseEnabled(x=False, y=False)
            plot.hideButtons()
            plot.getAxis("left").setWidth(AXIS_WIDTH_PX)
            if first is None:
                first = plot
            else:
                plot.setXLink(first)
            if row == len(layout_rows) - 1:
                plot.setLabel("bottom", "seconds before now")
            else:
                # One time axis for all: the upper plots keep its grid, not its numbers.
                plot.getAxis("bottom").setStyle(showValues=False)
                plot.getAxis("bottom").setHeight(4)
            for name, _label, colour, dashed in curves:
                style = Qt.PenStyle.DashLine if dashed else Qt.PenStyle.SolidLine
                pen = pg.mkPen(colour, width=1 if dashed else 2, style=style)
                curve = plot.plot([], [], pen=pen)
                curve.setClipToView(True)
                curve.setDownsampling(auto=True, method="peak")
                self.curves[name] = curve
                self._plot_of[name] = key
            self.plots[key] = plot
        for plot in self.plots.values():
            plot.enableAutoRange(y=False)
        self.plots["loss"].setYRange(0.0, 100.0, padding=0.05)
        self._y_tops: dict[str, float] = {}
        self._uplink_measurable = False

        layout = QVBoxLayout(self)
        layout.setContentsMargins(4, 4, 4, 4)
        layout.addLayout(controls)
        layout.addWidget(self.figures)
        # Every plot keeps a readable height; a short dock scrolls (float it to see all).
        self.graphics.setMinimumHeight(MIN_PLOT_HEIGHT_PX * len(layout_rows))
        scroll = QScrollArea()
        scroll.setWidgetResizable(True)
        scroll.setFrameShape(QFrame.Shape.NoFrame)
        scroll.setWidget(self.graphics)
        layout.addWidget(scroll, 1)
        self._set_x_range()

        self._timer = QTimer(self)
        self._timer.setInterval(REDRAW_PERIOD_MS)
        self._timer.timeout.connect(self.redraw)
        self._timer.start()

    # ---- the link --------------------------------------------------------------------------

    def attach(self, link: Link | None) -> None:
        """Follow this link's statistics (None: none); a live link gets the command rate."""
        if self.link is not None:
            self.link.unsubscribe(self.history)
        self.link = link
        if link is None:
            return
        link.subscribe(self.history)
        live = not link.read_only
        self.rate_box.setEnabled(live)
        if live:
            self._apply_rate(self.rate_box.value())

    def _on_rate(self, rate_hz: int) -> None:
        self.settings.setValue(RATE_KEY, rate_hz)
        self._apply_rate(rate_hz)

    def _apply_rate(self, rate_hz: float) -> None:
        if self.link is None or self.link.read_only:
            return
        try:
            self.link.set_rate_hz(float(rate_hz))
        except ValueError as err:
            # Another profile's bounds: the link keeps its rate, the operator is told.
            log.warning("command rate %g Hz not applied: %s", rate_hz, err)

    # ---- the view --------------------------------------------------------------------------

    @property
    def window_s(self) -> float:
        """The time window shown (seconds)."""
        return self.window_box.value() * 60.0

    @property
    def paused(self) -> bool:
        """Whether the graphs are frozen."""
        return self.pause_button.isChecked()

    def _on_window(self, minutes: int) -> None:
        self.settings.setValue(WINDOW_KEY, minutes)
        self._set_x_range()
        self._drawn_version = -1
        self.redraw()

    def _on_pause(self, paused: bool) -> None:
        self.pause_button.setText("Resume" if paused else "Pause")
        self._frozen_at = self.history.clock() if paused else None
        for plot in self.plots.values():
            plot.setMouseEnabled(x=paused, y=False)
        self._set_x_range()
        self._drawn_version = -1
        self.redraw(force=True)

    def _set_x_range(self) -> None:
        self.plots["rates"].setXRange(-self.window_s, 0.0, padding=0.0)

    def showEvent(self, event: QShowEvent) -> None:
        super().showEvent(event)
        self._drawn_version = -1
        self.redraw()

    def redraw(self, *, force: bool = False) -> None:
        """Re-plot from the history if it changed (and the dock is on screen)."""
        if not force and (self.paused or not self.isVisible() or self.window().isMinimized()):
            return  # frozen, or not on screen (a closed dock, another tab): drawn when shown
        version = self.history.version
        if version == self._drawn_version and not force:
            return
        started = time.perf_counter()
        self._drawn_version = version
        now = self._frozen_at if self._frozen_at is not None else self.history.clock()
        # Paused: the whole history, to scroll back through; live: the window.
        start = -math.inf if self.paused else now - self.window_s
        series = self.history.series(start, now)
        self._draw_curves(series, now)
        self._draw_marks(self.history.marks(start, now), now)
        self._show_figures()
        self.last_redraw_s = time.perf_counter() - started
        self.redraws += 1

    def _draw_curves(self, series: LinkSeries, now: float) -> None:
        times = series.times_s - now
        # Unknown values break a curve (connect="finite"): a gap, not a line across it.
        columns = {name: values * SCALES.get(name, 1.0) for name, values in series.figures.items()}
        for index in range(len(self.camera_names)):
            columns[f"frame_age_{index}"] = series.frame_age_s[:, index]
        tops: dict[str, float] = {}
        for name, values in columns.items():
            curve = self.curves.get(name)
            if curve is None:
                continue
            curve.setData(times, values, connect="finite")
            if np.isfinite(values).any():
                plot = self._plot_of[name]
                # The round trip's first estimate is its largest (the safe side): a spike
                # may leave the axis rather than flatten everything else.
                top = (
                    float(np.nanpercentile(values, DELAY_TOP_PERCENTILE))
                    if plot == "delay"
                    else float(np.nanmax(values))
                )
                tops[plot] = max(tops.get(plot, 0.0), top)
        for plot, minimum in Y_MIN_TOPS.items():
            self._step_top(plot, max(tops.get(plot, 0.0), minimum))

    def _step_top(self, plot: str, high: float) -> None:
        """Keep a value axis still unless the data leaves it or shrinks far inside it."""
        top = self._y_tops.get(plot)
        if top is not None and high <= top and high * Y_HEADROOM * 3.0 >= top:
            return
        self._y_tops[plot] = high * Y_HEADROOM
        self.plots[plot].setYRange(0.0, high * Y_HEADROOM, padding=0.0)

    def _draw_marks(self, marks: list[LinkMark], now: float) -> None:
        """One dashed line per event through every plot, labelled in the top one."""
        if marks != self._drawn_marks:
            for line, plot, _ in self._mark_items:
                plot.removeItem(line)
            self._mark_items = []
            top = self.plots["rates"]
            for mark in marks:
                colour = MARK_COLOURS[mark.kind]
                for plot in self.plots.values():
                    line = pg.InfiniteLine(
                        angle=90,
                        pen=pg.mkPen(colour, width=2, style=Qt.PenStyle.DashLine),
                        label=mark.kind.value if plot is top else None,
                        labelOpts={"position": 0.9, "color": colour, "fill": (255, 255, 255, 200)},
                    )
                    line.setToolTip(mark.message)
                    plot.addItem(line, ignoreBounds=True)
                    self._mark_items.append((line, plot, mark.time_s))
            self._drawn_marks = marks
        for line, _, time_s in self._mark_items:
            line.setValue(time_s - now)

    def _show_figures(self) -> None:
        stats = self.history.latest()
        if stats is None:
            return

        def ms(value: float | None) -> str:
            return "—" if value is None else f"{value * 1e3:.0f} ms"

        measurable = stats.uplink_loss is not None
        if measurable != self._uplink_measurable:
            self._uplink_measurable = measurable
            self.plots["loss"].setTitle(self._loss_titles[0 if measurable else 1], size="9pt")
        loss = "—" if stats.loss_estimate is None else f"{stats.loss_estimate:.0%}"
        self.figures.setText(
            f"sent {stats.rcp_rate_hz:.1f} Hz (set {stats.send_rate_hz:g}) · received: "
            f"telemetry {stats.telemetry_rate_hz:.1f} Hz, video {stats.video_rate_hz:.1f} fps, "
            f"scans {stats.scan_rate_hz:.1f} Hz · telemetry lost {loss} · commands lost "
            f"{self.history.uplink_loss_text} · round trip {ms(stats.delay_s)}, "
            f"jitter {ms(stats.jitter_s)}"
        )

    def curve_points(self, name: str) -> int:
        """How many known values one curve holds (tests)."""
        _, values = self.curves[name].getData()
        return 0 if values is None else int(np.isfinite(values).sum())

    def mark_labels(self) -> list[str]:
        """The kinds of the marks drawn (tests)."""
        return [mark.kind.value for mark in self._drawn_marks]

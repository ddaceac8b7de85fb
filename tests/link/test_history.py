"""The link history (no Qt): samples become series, state changes and e-stops marks."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from ocu.link.history import (
    FIGURES,
    SILENT_AFTER_S,
    UPLINK_LOSS_UNMEASURABLE,
    LinkHistory,
    MarkKind,
)
from ocu.link.stats import JitterMeter
from ocu.records import LinkState, LinkStateChanged, LinkStats, SafetyEvent


class Clock:
    """A clock the test moves."""

    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


def stats(**fields: object) -> LinkStats:
    """LinkStats of a healthy link, with some fields changed."""
    healthy = replace(
        LinkStats.empty(5.0),
        rcp_rate_hz=5.0,
        telemetry_rate_hz=10.0,
        video_rate_hz=30.0,
        loss_estimate=0.2,
        last_valid_age_s=0.05,
        delay_s=0.18,
        jitter_s=0.03,
        scan_rate_hz=10.0,
        frame_age_s=(0.1, None, 0.3, 0.4),
    )
    return replace(healthy, **fields)  # type: ignore[arg-type]


def test_samples_become_series_of_every_figure() -> None:
    clock = Clock()
    history = LinkHistory(4, clock=clock)
    for k in range(4):
        clock.now = 100.0 + 0.5 * k
        history(stats(rcp_rate_hz=5.0 + k))
    series = history.series()
    assert len(series) == 4
    assert series.times_s.tolist() == [100.0, 100.5, 101.0, 101.5]
    assert set(series.figures) == set(FIGURES)
    assert series.figures["command_rate_hz"].tolist() == [5.0, 6.0, 7.0, 8.0]
    assert series.figures["command_rate_setting_hz"].tolist() == [5.0] * 4
    assert series.figures["telemetry_rate_hz"][0] == 10.0
    assert series.figures["video_rate_hz"][0] == 30.0
    assert series.figures["scan_rate_hz"][0] == 10.0
    assert series.figures["downlink_loss"][0] == pytest.approx(0.2)
    assert series.figures["round_trip_s"][0] == pytest.approx(0.18)
    assert series.figures["jitter_s"][0] == pytest.approx(0.03)
    # One column per camera; a camera without a frame yet is NaN.
    assert series.frame_age_s.shape == (4, 4)
    assert series.frame_age_s[0, 0] == pytest.approx(0.1)
    assert math.isnan(series.frame_age_s[0, 1])
    assert history.latest() == stats(rcp_rate_hz=8.0)


def test_series_picks_a_time_range_and_the_history_keeps_its_span() -> None:
    clock = Clock()
    history = LinkHistory(4, span_s=10.0, clock=clock)
    for k in range(30):
        clock.now = 100.0 + k
        history(stats())
    # Only the last 10 s are kept.
    assert history.series().times_s[0] == pytest.approx(119.0)
    picked = history.series(125.0, 127.0)
    assert picked.times_s.tolist() == [125.0, 126.0, 127.0]
    assert len(history.series(200.0, 300.0)) == 0


def test_unknown_figures_are_nan_and_fewer_cameras_are_padded() -> None:
    history = LinkHistory(4, clock=Clock())
    history(stats(loss_estimate=None, delay_s=None, jitter_s=None, frame_age_s=(0.2,)))
    series = history.series()
    for name in ("downlink_loss", "round_trip_s", "jitter_s"):
        assert math.isnan(series.figures[name][0])
    assert series.frame_age_s[0, 0] == pytest.approx(0.2)
    assert np.isnan(series.frame_age_s[0, 1:]).all()


def test_a_silent_robot_loses_everything_and_its_round_trip_is_unknown() -> None:
    """The link's figures keep their last values while nothing arrives; the history not."""
    history = LinkHistory(4, clock=Clock())
    history(stats(last_valid_age_s=SILENT_AFTER_S / 2))
    history(stats(last_valid_age_s=SILENT_AFTER_S + 0.5))
    series = history.series()
    assert series.figures["downlink_loss"].tolist() == [pytest.approx(0.2), 1.0]
    assert not math.isnan(series.figures["round_trip_s"][0])
    assert math.isnan(series.figures["round_trip_s"][1])
    assert math.isnan(series.figures["jitter_s"][1])


def test_link_lost_its_return_and_emergency_stops_are_marked() -> None:
    clock = Clock()
    history = LinkHistory(4, clock=clock)
    history(LinkStateChanged(LinkState.CONNECTING, "connecting"))
    history(LinkStateChanged(LinkState.CONNECTED, "packets"))  # not a return: never lost
    clock.now = 110.0
    history(LinkStateChanged(LinkState.LOST, "no valid packet for 3.0 s"))
    history(LinkStateChanged(LinkState.LOST, "again"))  # one loss, one mark
    clock.now = 120.0
    history(LinkStateChanged(LinkState.CONNECTED, "packets again"))
    clock.now = 125.0
    history(SafetyEvent("EMERGENCY STOP (Space)"))
    history(SafetyEvent("link lost: motion commands zeroed"))  # LINK LOST says it already
    marks = history.marks()
    assert [(m.time_s, m.kind) for m in marks] == [
        (110.0, MarkKind.LINK_LOST),
        (120.0, MarkKind.LINK_BACK),
        (125.0, MarkKind.ESTOP),
    ]
    assert marks[0].message == "no valid packet for 3.0 s"
    assert [m.kind for m in history.marks(115.0, 130.0)] == [MarkKind.LINK_BACK, MarkKind.ESTOP]


def test_the_version_moves_with_every_sample_and_mark() -> None:
    history = LinkHistory(4, clock=Clock())
    first = history.version
    history(stats())
    second = history.version
    history(SafetyEvent("EMERGENCY STOP (operator)"))
    assert first < second < history.version


def test_uplink_loss_is_the_robots_echo_or_stated_as_not_measurable() -> None:
    history = LinkHistory(4, clock=Clock())
    assert history.uplink_loss_text == UPLINK_LOSS_UNMEASURABLE
    history(stats())  # a vendor robot: no echo
    assert not history.uplink_measurable
    assert history.uplink_loss_text == UPLINK_LOSS_UNMEASURABLE
    assert "not measurable" in UPLINK_LOSS_UNMEASURABLE
    assert math.isnan(history.series().figures["uplink_loss"][0])
    history(stats(uplink_loss=0.25))  # an extended robot echoes its sequenced RCPs
    assert history.uplink_measurable
    assert history.uplink_loss_text == "25%"
    assert history.series().figures["uplink_loss"][1] == pytest.approx(0.25)
    # Silence: what the robot applied meanwhile is not known.
    history(stats(uplink_loss=0.25, last_valid_age_s=SILENT_AFTER_S + 1.0))
    assert math.isnan(history.series().figures["uplink_loss"][2])


def test_jitter_is_the_spread_of_the_windows_round_trips() -> None:
    meter = JitterMeter(window_s=10.0, min_samples=3)
    meter.add(0.10, 0.0)
    meter.add(0.20, 1.0)
    assert meter.jitter(1.0) is None  # too few to say
    meter.add(0.30, 2.0)
    assert meter.jitter(2.0) == pytest.approx(float(np.std([0.1, 0.2, 0.3])))
    # The first two leave the window: too few again.
    assert meter.jitter(11.5) is None
    for at, delay in ((12.0, 0.2), (12.5, 0.2), (13.0, 0.5)):
        meter.add(delay, at)
    assert meter.jitter(13.0) == pytest.approx(float(np.std([0.2, 0.2, 0.5])))
    meter.reset()
    assert meter.jitter(13.0) is None

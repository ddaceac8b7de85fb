"""The Link dock's figures in a recording: recorded live, replayed into a LinkHistory."""

from __future__ import annotations

import statistics
from pathlib import Path

import numpy as np
import pytest

from ocu.link.history import LinkHistory, MarkKind
from ocu.link.live import UdpLink
from ocu.profile import RobotProfile
from ocu.record.inspect import render, summarize
from ocu.record.reader import Recording
from ocu.record.recorder import Recorder
from ocu.record.replay_link import ReplayLink
from ocu.records import Command, LinkStats
from ocu.sim.faults import FaultConfig
from ocu.sim.simulator import RobotSimulator
from tests.record.helpers import Collector


def figures(stats: LinkStats) -> tuple[object, ...]:
    """The figures the Link dock adds to the link statistics."""
    return (stats.delay_s, stats.jitter_s, stats.scan_rate_hz, stats.frame_age_s)


@pytest.fixture
def recorded(profile: RobotProfile, tmp_path: Path) -> tuple[Path, list[LinkStats]]:
    """An extended robot behind a jittery link, driven back and forth, recorded."""
    sim = RobotSimulator(
        profile,
        telemetry_hz=20.0,
        video_fps=5.0,
        video_size=(64, 48),
        extended=True,
        faults=FaultConfig(latency_ms=30.0, jitter_ms=15.0),
        seed=3,
    )
    sim.start()
    live = Collector()
    link = UdpLink(profile, sim.address, listener=live, gui_alive_timeout_s=None, extension=True)
    recorder = Recorder(profile)
    recorder.attach(link)
    path = tmp_path / "link.mcap"
    recorder.start(path)
    link.start()

    def known() -> bool:
        return any(s.jitter_s is not None and any(s.frame_age_s) for s in live.stats)

    try:
        speed = 0.3
        for _ in range(100):
            speed = -speed
            link.set_command(Command(velocities={"waist": speed}))
            if live.wait(known, 0.1):
                break
        assert known(), "the live link never measured its jitter and frame ages"
        link.emergency_stop("test")
        count = len(live.stats)
        assert live.wait(lambda: len(live.stats) >= count + 2)
    finally:
        link.shutdown()
        sim.stop()
    recorder.stop()
    return path, list(live.stats)


def test_a_replay_feeds_the_link_history_the_figures_recorded_live(
    profile: RobotProfile, recorded: tuple[Path, list[LinkStats]]
) -> None:
    path, live_stats = recorded
    collector = Collector()
    history = LinkHistory(len(profile.link.camera_names))
    source = ReplayLink(path, profile, on_finished=collector.mark_finished)
    source.subscribe(collector)
    source.subscribe(history)
    source.start()
    try:
        source.set_speed(4.0)
        source.play()
        assert collector.wait(lambda: collector.finished)
    finally:
        source.shutdown()
    assert [figures(s) for s in collector.stats] == [figures(s) for s in live_stats]
    assert len(history) == len(live_stats)
    series = history.series()
    jitter = series.figures["jitter_s"]
    assert (jitter[np.isfinite(jitter)] > 0.0).any()
    assert np.isfinite(series.frame_age_s).any()
    assert [mark.kind for mark in history.marks()] == [MarkKind.ESTOP]


def test_inspect_states_the_round_trip_and_its_jitter(
    profile: RobotProfile, recorded: tuple[Path, list[LinkStats]]
) -> None:
    path, live_stats = recorded
    with Recording(path) as recording:
        summary = summarize(recording, profile)
    measured = [s.delay_s * 1e3 for s in live_stats if s.delay_s is not None]
    assert summary.round_trip_median_ms == pytest.approx(statistics.median(measured))
    assert summary.round_trip_max_ms == pytest.approx(max(measured))
    assert summary.jitter_median_ms is not None
    assert summary.jitter_median_ms > 0.0
    assert "round trip    median" in render(summary)
    # The extended robot echoed its sequenced RCPs. No loss was injected on the way to it;
    # the e-stop's burst (five zeros in 40 ms) may be reordered by the jitter, and a zero
    # overtaken by the next one is dropped as late: a few of the ~100 RCPs at most.
    assert summary.rcp_loss is not None
    assert summary.rcp_loss <= 0.1
    assert "(the robot's echo of its sequenced RCPs)" in render(summary)

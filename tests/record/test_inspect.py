"""`ocu inspect`: loss by hand-checkable rules, against the simulator's own drop counter."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from ocu.link.live import UdpLink
from ocu.link.stats import tick_loss
from ocu.profile import RobotProfile
from ocu.record.inspect import main, summarize
from ocu.record.reader import Recording
from ocu.record.recorder import Recorder
from ocu.sim.faults import FaultConfig
from ocu.sim.simulator import RobotSimulator
from tests.record.helpers import Collector


def test_tick_loss_counts_the_span_not_the_steps() -> None:
    # Period 50: 0 50 100 [150 lost] 200 250.
    assert tick_loss([0, 50, 100, 200, 250]).lost == 1
    # A late packet then an on-time one (steps 84 and 18) is no loss.
    jittered = tick_loss([0, 50, 134, 150, 200, 250])
    assert (jittered.lost, jittered.period_ticks) == (0, 50.0)
    # Duplicates and a reordered packet are counted as such, not as loss.
    mixed = tick_loss([0, 50, 50, 150, 100, 200])
    assert (mixed.received, mixed.lost, mixed.duplicates, mixed.reordered) == (5, 0, 1, 1)
    assert tick_loss([7]).lost == 0
    assert tick_loss([]).received == 0


def test_telemetry_loss_matches_the_simulator_drops(profile: RobotProfile, tmp_path: Path) -> None:
    sim = RobotSimulator(
        profile, telemetry_hz=50.0, video_fps=0.0, faults=FaultConfig(loss=0.2), seed=7
    )
    sim.start()
    collector = Collector()
    recorder = Recorder(profile)
    link = UdpLink(
        profile, sim.address, listener=collector, gui_alive_timeout_s=None, send_rate_hz=20.0
    )
    recorder.attach(link)
    path = tmp_path / "lossy.mcap"
    recorder.start(path)
    link.start()
    try:
        assert collector.wait(lambda: len(collector.telemetry) >= 100)
        link.emergency_stop("test")
        assert collector.wait(lambda: len(collector.telemetry) >= 110)
        dropped_before = sim.state().dropped_to_ocu
    finally:
        link.shutdown()
        sim.stop()
    dropped_after = sim.state().dropped_to_ocu
    recorder.stop()

    with Recording(path) as recording:
        summary = summarize(recording, recording.profile())
    assert summary.telemetry_received == len(collector.telemetry)
    # Telemetry is all that goes to the OCU, so the simulator's drops are its loss. Drops
    # before the first and after the last packet received cannot be seen; a send the
    # simulator skipped when its loop was starved of CPU (two shared cores) leaves the same
    # gap in the ticks as a drop and counts as one.
    assert dropped_before - 4 <= summary.telemetry_lost <= dropped_after + 2
    loss = summary.telemetry_loss
    assert loss is not None
    assert 0.1 < loss < 0.3
    assert summary.estops == 1
    assert summary.rcp_sent == sum(1 for d in collector.sent if d[0] == 1)
    assert summary.rcp_rate_hz == pytest.approx(20.0, rel=0.3)
    assert summary.telemetry_rate_hz == pytest.approx(50.0 * 0.8, rel=0.3)
    assert not summary.truncated


def test_main_prints_text_json_and_says_truncated(
    profile: RobotProfile, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    sim = RobotSimulator(profile, telemetry_hz=20.0, video_fps=10.0, video_size=(160, 120))
    sim.start()
    collector = Collector()
    recorder = Recorder(profile, chunk_bytes=8 * 1024)
    link = UdpLink(profile, sim.address, listener=collector, gui_alive_timeout_s=None)
    recorder.attach(link)
    path = tmp_path / "s.mcap"
    recorder.start(path)
    link.start()
    try:
        assert collector.wait(lambda: len(collector.video) >= 10)
    finally:
        link.shutdown()
        sim.stop()
    recorder.stop()

    assert main([str(path)]) == 0
    text = capsys.readouterr().out
    assert "complete" in text
    assert "/raw/telemetry" in text
    assert "drop: not observable from the OCU" in text
    assert "video front" in text

    assert main([str(path), "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    topics = {c["topic"]: c for c in data["channels"]}
    assert topics["/raw/video"]["messages"] == len(collector.video)
    assert data["cameras"][0]["name"] == "front"
    assert data["cameras"][0]["lost"] is None  # vendor video has no sequence numbers

    cut = tmp_path / "cut.mcap"
    cut.write_bytes(path.read_bytes()[: path.stat().st_size * 2 // 3])
    assert main([str(cut)]) == 0
    assert "TRUNCATED" in capsys.readouterr().out

    not_mcap = tmp_path / "x.mcap"
    not_mcap.write_bytes(b"hello")
    assert main([str(not_mcap)]) == 1
    assert "not an MCAP file" in capsys.readouterr().err
    assert main([str(tmp_path / "missing.mcap")]) == 1
    assert "No such file" in capsys.readouterr().err

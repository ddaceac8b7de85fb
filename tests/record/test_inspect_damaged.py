"""`ocu inspect` on files with zeros where records should be: answered at once, data kept.

A 2 GB file that starts with a real recording's header and is zeros after it took about
12 minutes: the reader stepped through the zeros as empty records, nine bytes at a time.
The files here are sparse (truncate extends them without writing), so they cost no disk.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from ocu.link.live import UdpLink
from ocu.profile import RobotProfile, load_profile
from ocu.record.inspect import main, summarize
from ocu.record.reader import Recording
from ocu.record.recorder import Recorder
from ocu.records import CameraRequest
from ocu.sim.simulator import RobotSimulator
from tests.record.helpers import Collector

HUGE_BYTES = 2 * 1024**3
# A hang guard for a file the old reader needed minutes for, not a timing assertion
# (bench/bench_inspect_zeros.py measures the time).
HANG_GUARD_S = 120.0


@pytest.fixture(scope="module")
def recording(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A real recording of a few seconds (telemetry, extension video), in many small chunks."""
    profile = load_profile()
    path = tmp_path_factory.mktemp("inspect") / "real.mcap"
    sim = RobotSimulator(profile, telemetry_hz=20.0, video_fps=0.0, extended=True)
    sim.start()
    collector = Collector()
    recorder = Recorder(profile, chunk_bytes=8 * 1024)
    link = UdpLink(
        profile, sim.address, listener=collector, gui_alive_timeout_s=None, extension=True
    )
    link.set_stream_request([CameraRequest(0, 64, 48, 10)])
    recorder.attach(link)
    recorder.start(path)
    link.start()
    try:
        assert collector.wait(lambda: len(collector.video) >= 10 and len(collector.telemetry) >= 40)
    finally:
        link.shutdown()
        sim.stop()
    recorder.stop()
    return path


def messages_per_chunk(path: Path) -> list[int]:
    with Recording(path) as recording:
        return [len(recording.read_chunk(k)) for k in range(len(recording.chunks))]


def head_then_zeros(source: Path, target: Path, keep_bytes: int) -> Path:
    """The first keep_bytes of source, then zeros up to HUGE_BYTES (a sparse file)."""
    with source.open("rb") as stream:
        head = stream.read(keep_bytes)
    target.write_bytes(head)
    os.truncate(target, HUGE_BYTES)
    return target


def test_a_2_gb_file_of_zeros_after_the_header_is_answered_at_once(
    recording: Path, tmp_path: Path
) -> None:
    with Recording(recording) as real:
        first_chunk_at = real.chunks[0].offset
    path = head_then_zeros(recording, tmp_path / "zeros.mcap", first_chunk_at)
    result = subprocess.run(
        [sys.executable, "-m", "ocu", "inspect", str(path)],
        capture_output=True,
        text=True,
        timeout=HANG_GUARD_S,
        check=False,
    )
    assert result.returncode == 0, result.stderr
    assert "Traceback" not in result.stderr
    assert "(2.1 GB, TRUNCATED" in result.stdout
    assert f"zeros instead of records at byte {first_chunk_at}: the 2.1 GB after it" in (
        result.stdout
    )


def test_the_chunks_before_the_zeros_are_read(
    recording: Path, tmp_path: Path, profile: RobotProfile
) -> None:
    counts = messages_per_chunk(recording)
    assert len(counts) > 6
    with Recording(recording) as real:
        cut_at = real.chunks[4].offset
    path = head_then_zeros(recording, tmp_path / "four.mcap", cut_at)
    with Recording(path) as damaged:
        assert damaged.damaged_at == cut_at
        assert damaged.truncated
        assert len(damaged.chunks) == 4
        summary = summarize(damaged, damaged.profile(profile))
    assert sum(c.messages for c in summary.channels) == sum(counts[:4])


def test_chunks_after_zeros_are_found_through_the_chunk_index(
    recording: Path, tmp_path: Path, profile: RobotProfile, capsys: pytest.CaptureFixture[str]
) -> None:
    counts = messages_per_chunk(recording)
    data = bytearray(recording.read_bytes())
    with Recording(recording) as real:
        lost = real.chunks[3]
    # One chunk record overwritten with zeros, as a crash can leave a region unwritten.
    end = lost.offset + 9 + lost.length
    data[lost.offset : end] = bytes(end - lost.offset)
    path = tmp_path / "hole.mcap"
    path.write_bytes(bytes(data))
    with Recording(path) as damaged:
        assert damaged.damaged_at == lost.offset
        assert not damaged.truncated  # its footer and summary are intact
        assert damaged.recovered_chunks == len(counts) - 4
        summary = summarize(damaged, damaged.profile(profile))
    assert sum(c.messages for c in summary.channels) == sum(counts) - counts[3]
    assert main([str(path)]) == 0
    out = capsys.readouterr().out
    assert f"zeros instead of records at byte {lost.offset}: {len(counts) - 4} later chunk(s)" in (
        out
    )

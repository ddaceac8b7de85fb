"""An MCAP file another tool wrote is refused as "not an ocu recording", everywhere."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
from mcap.writer import Writer

from ocu.record.errors import RecordingError
from ocu.record.reader import Recording
from tests.windows.console_fixtures import RUN_TIMEOUT_S, run_ocu

LIBRARY = "other-logger 1.0"
# The raw RCP topic of an ocu recording, so reading it as ours would count 100 RCPs sent.
TOPIC = "/raw/rcp"


def write_foreign(path: Path, messages: int = 100) -> Path:
    """A valid MCAP file with one JSON channel and no ocu metadata; small chunks."""
    with path.open("wb") as stream:
        writer = Writer(stream, chunk_size=256)
        writer.start(profile="", library=LIBRARY)
        schema = writer.register_schema("Command", "jsonschema", b'{"type": "object"}')
        channel = writer.register_channel(TOPIC, "json", schema)
        for index in range(messages):
            stamp = index * 100_000_000
            data = json.dumps({"speed": index}).encode()
            writer.add_message(channel, log_time=stamp, publish_time=stamp, data=data)
        writer.finish()  # type: ignore[no-untyped-call]
    return path


REFUSAL = (
    r"is not an ocu recording \(no 'ocu\.recording' metadata\): "
    rf"written by '{LIBRARY}', channels: /raw/rcp \(json\)$"
)


@pytest.mark.parametrize("cut", [False, True], ids=["finished", "cut-short"])
def test_recording_refuses_a_foreign_file(tmp_path: Path, cut: bool) -> None:
    path = write_foreign(tmp_path / "other.mcap")
    if cut:  # no summary: the channel is found in the first chunk
        path.write_bytes(path.read_bytes()[: path.stat().st_size // 2])
    with pytest.raises(RecordingError, match=REFUSAL):
        Recording(path)


def test_ocu_inspect_refuses_a_foreign_file(tmp_path: Path) -> None:
    path = write_foreign(tmp_path / "other.mcap")
    result = subprocess.run(
        [sys.executable, "-m", "ocu", "inspect", str(path)],
        capture_output=True,
        text=True,
        timeout=RUN_TIMEOUT_S,
        check=False,
    )
    assert result.returncode == 1
    assert result.stdout == ""
    lines = result.stderr.splitlines()
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith(f"ocu inspect: {path} is not an ocu recording")


def test_ocu_replay_refuses_a_foreign_file(tmp_path: Path) -> None:
    path = write_foreign(tmp_path / "other.mcap")
    result = run_ocu(tmp_path, "--replay", str(path), "--quit-after", "1")
    assert result.returncode == 1
    assert "Traceback" not in result.stderr
    assert f"{path} is not an ocu recording" in result.stderr
    assert "replay started" not in result.stderr

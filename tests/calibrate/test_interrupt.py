"""Ctrl-C at any point of `ocu calibrate`: a clean message and exit status, never a traceback;
the profile written whole or not at all, and zeros the last thing the robot got.

Before, SIGINT was handled only while the calibrator ran: one after it (printing the
findings, writing the profile) ended in a KeyboardInterrupt traceback, and one while a guided
question waited on the terminal did nothing until Enter was pressed.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import IO

import pytest

from ocu.profile import load_profile
from ocu.sim.simulator import RobotSimulator
from tests.calibrate.scrambled import scrambled_truth

pytestmark = pytest.mark.slow

RUN_TIMEOUT_S = 240.0
DEADLINE_S = 15.0


@pytest.fixture
def sim() -> Iterator[RobotSimulator]:
    with RobotSimulator(scrambled_truth(7), telemetry_hz=20.0, video_fps=0.0) as robot:
        yield robot


@contextmanager
def calibrating(sim: RobotSimulator, out: Path, *options: str) -> Iterator[subprocess.Popen[str]]:
    """`ocu calibrate` against the simulator; killed if a failed test leaves it running."""
    host, port = sim.address
    command = [sys.executable, "-m", "ocu", "calibrate", "--robot", f"{host}:{port}"]
    with subprocess.Popen(
        [*command, "--out", str(out), *options],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        # Each line (and each prompt) reaches the test as it is printed.
        env={**os.environ, "PYTHONUNBUFFERED": "1"},
    ) as process:
        try:
            yield process
        finally:
            if process.poll() is None:
                process.kill()
                process.wait(DEADLINE_S)


def read_until(stream: IO[str], marker: str, timeout_s: float = RUN_TIMEOUT_S) -> str:
    """What the process printed up to and including `marker` (a prompt ends no line)."""
    seen = ""
    deadline = time.monotonic() + timeout_s
    while marker not in seen:
        assert time.monotonic() < deadline, f"{marker!r} never came: {seen[-2000:]}"
        char = stream.read(1)
        assert char, f"the output ended before {marker!r}: {seen[-2000:]}"
        seen += char
    return seen


def assert_clean_stop(
    process: subprocess.Popen[str], out: Path, sim: RobotSimulator
) -> tuple[str, str]:
    # Standard input stays open: its end would answer a waiting question too.
    process.wait(DEADLINE_S)
    stdout, stderr = process.communicate(timeout=DEADLINE_S)
    assert "Traceback" not in stderr, stderr
    assert "KeyboardInterrupt" not in stderr, stderr
    assert process.returncode == 1, stdout + stderr
    assert "stopped: SIGINT" in stdout, stdout
    if out.exists():
        load_profile(out)  # whole: it loads
    assert not [p for p in out.parent.iterdir() if p.name.endswith(".tmp")]
    received = sim.received_commands()
    assert received, "the robot heard nothing"
    assert not any(received[-1].packet.axes)
    return stdout, stderr


def test_ctrl_c_as_the_profile_is_written(sim: RobotSimulator, tmp_path: Path) -> None:
    out = tmp_path / "calibrated.toml"
    with calibrating(sim, out, "--yes") as process:
        assert process.stdout is not None
        # Printed after the robot was zeroed, just before the profile is written.
        read_until(process.stdout, "calibration took")
        process.send_signal(signal.SIGINT)
        stdout, _ = assert_clean_stop(process, out, sim)
    # Either the stop came first (nothing written) or the write finished whole.
    assert ("nothing written" in stdout) != out.exists(), stdout


def test_ctrl_c_while_a_question_waits_for_its_answer(sim: RobotSimulator, tmp_path: Path) -> None:
    out = tmp_path / "calibrated.toml"
    with calibrating(sim, out, "--on-stand") as process:  # guided on the terminal; no answer
        assert process.stdout is not None
        read_until(process.stdout, "Go on? [Y/n]")
        process.send_signal(signal.SIGINT)
        stdout, _ = assert_clean_stop(process, out, sim)
    assert "nothing written" in stdout
    assert not out.exists()

"""A console process frozen (SIGSTOP) while driving sends zeros first when it wakes (SIGCONT).

The robot stopped on its own watchdog during the freeze; the stale motion command must not
restart it. The child is a real console without Qt (tests/link/drive_child.py) on a real UDP
link; the simulator in this process records what it received.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from ocu.profile import RobotProfile
from ocu.sim.simulator import RobotSimulator

DEADLINE_S = 10.0
FREEZE_S = 2.0
ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture
def sim(profile: RobotProfile) -> Iterator[RobotSimulator]:
    simulator = RobotSimulator(profile, telemetry_hz=10.0, video_fps=0.0)
    simulator.start()
    yield simulator
    simulator.stop()


def wait_for(predicate: object, timeout_s: float, what: str) -> None:
    assert callable(predicate)
    deadline = time.monotonic() + timeout_s
    while not predicate():
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        time.sleep(0.01)


def process_state(pid: int) -> str:
    """The kernel's state letter of a process (T: stopped)."""
    text = Path(f"/proc/{pid}/stat").read_text()
    return text.rsplit(")", 1)[1].split()[0]


@pytest.mark.parametrize("mode", ["hold", "path"])
def test_the_first_datagram_after_a_freeze_is_zero(sim: RobotSimulator, mode: str) -> None:
    host, port = sim.address
    with subprocess.Popen(
        [sys.executable, "-m", "tests.link.drive_child", host, str(port), mode],
        cwd=ROOT,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
    ) as child:
        try:
            frozen_and_woken(sim, child, mode)
        finally:
            if child.poll() is None:
                os.kill(child.pid, signal.SIGCONT)
                assert child.stdin is not None
                child.stdin.close()
                child.wait(DEADLINE_S)


def frozen_and_woken(sim: RobotSimulator, child: subprocess.Popen[str], mode: str) -> None:
    """Drive, freeze 2 s, wake: the first datagram after the freeze is zero."""
    assert child.stdout is not None
    assert child.stdout.readline().strip() == "driving"
    assert sim.wait_until(lambda s: s.velocities["neck"] > 0, DEADLINE_S), "never drove"
    # A few periodic ticks of motion, so the freeze falls between two of them.
    count = len(sim.received_commands())
    wait_for(lambda: len(sim.received_commands()) >= count + 3, DEADLINE_S, "ticks")
    child.send_signal(signal.SIGSTOP)
    wait_for(lambda: process_state(child.pid) == "T", DEADLINE_S, "the child to stop")
    before = len(sim.received_commands())
    time.sleep(FREEZE_S)  # the freeze itself, not a synchronisation
    assert sim.state().watchdog_stopped  # the robot stopped on its own meanwhile
    assert len(sim.received_commands()) == before
    child.send_signal(signal.SIGCONT)
    wait_for(lambda: len(sim.received_commands()) > before, DEADLINE_S, "a datagram")
    first = sim.received_commands()[before]
    assert not any(first.packet.axes), f"first datagram after the freeze: {first}"
    if mode == "hold":
        # The console halted too: nothing resumes by itself.
        woke = first.time_s
        wait_for(lambda: sim.state().time_s > woke + 1.0, DEADLINE_S, "a second")
        after = sim.received_commands()[before:]
        assert not any(any(r.packet.axes) for r in after), after

"""The live server's relay process (ocu.live.relay): it ends with the console, and when it
ends what a remote client drove stops at once."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest

from ocu.console.model import ConsoleModel
from ocu.hardware.registry import HARDWARE
from ocu.headless import HeadlessConsole
from ocu.live.options import serve_console
from ocu.live.server import RELAY_NICE_STEPS, LiveServer
from ocu.priority import current_nice
from ocu.profile import RobotProfile
from ocu.sim.simulator import RobotSimulator, SimState
from tests.live.node_client import NodeClient, require_node

ROOT = Path(__file__).resolve().parents[2]
DEADLINE_S = 10.0
TWIST = "geometry_msgs/msg/Twist"


def gone(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return True
    # A zombie (its parent has not waited yet) is gone too.
    stat = Path(f"/proc/{pid}/stat")
    try:
        return stat.read_text().rsplit(")", 1)[1].split()[0] == "Z"
    except (OSError, IndexError):
        return True


def wait_for(condition: object, timeout_s: float = DEADLINE_S) -> bool:
    assert callable(condition)
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if condition():
            return True
        time.sleep(0.02)
    return bool(condition())


def test_the_relay_ends_when_the_console_is_killed() -> None:
    """A console that crashes must not leave a server behind showing a robot nobody drives."""
    script = (
        "import sys\n"
        "from ocu.live.server import LiveServer\n"
        "from ocu.profile import load_profile\n"
        "server = LiveServer(load_profile(), '127.0.0.1', 0)\n"
        "server.start()\n"
        "print(server.relay_pid, server.address[1], flush=True)\n"
        "sys.stdin.read()\n"
    )
    with subprocess.Popen(
        [sys.executable, "-c", script],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
        cwd=ROOT,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
    ) as console:
        try:
            assert console.stdout is not None
            relay_pid, _port = (int(word) for word in console.stdout.readline().split())
            assert not gone(relay_pid)
            os.kill(console.pid, signal.SIGKILL)
            console.wait(DEADLINE_S)
            assert wait_for(lambda: gone(relay_pid)), f"the relay {relay_pid} outlived it"
        finally:
            if console.poll() is None:
                console.kill()


@dataclass
class Driven:
    sim: RobotSimulator
    console: HeadlessConsole
    server: LiveServer


@pytest.fixture
def driven(profile: RobotProfile) -> Iterator[Driven]:
    require_node()
    sim = RobotSimulator(profile, telemetry_hz=50.0, video_fps=0.0)
    sim.start()
    hardware = HARDWARE.create("engineer", profile, f"{sim.address[0]}:{sim.address[1]}")
    console = HeadlessConsole(ConsoleModel(profile), hardware)
    server = LiveServer(profile, "127.0.0.1", 0, control=True)
    server.start()
    serve_console(server, console.manager)
    console.start()
    try:
        yield Driven(sim, console, server)
    finally:
        server.stop()
        console.stop()
        sim.stop()


def moving(state: SimState) -> bool:
    return abs(state.commanded_velocities.get("drive_linear", 0.0)) > 0.0


def test_a_relay_that_dies_stops_the_remote_drive_at_once(driven: Driven) -> None:
    """The client keeps publishing at 2 Hz (each message holds the drive 0.6 s): the stop
    must come from the relay's end, named as such, not from the stream's timeout."""
    messages: list[str] = []
    driven.console.model.events.message.connect(messages.append)
    spec: dict[str, object] = {"topic": "/cmd_vel", "encoding": "json", "schemaName": TWIST}
    spec |= {"rateHz": 2.0, "count": 1000, "linear": 0.3, "angular": 0.0}
    client = NodeClient(f"ws://127.0.0.1:{driven.server.address[1]}", topics=[], publish=spec)
    try:
        assert driven.sim.wait_until(moving, DEADLINE_S)
        relay_pid = driven.server.relay_pid
        assert relay_pid is not None
        os.kill(relay_pid, signal.SIGKILL)
        assert driven.sim.wait_until(lambda state: not moving(state), DEADLINE_S)
        assert wait_for(lambda: any("the live relay ended" in m for m in messages)), messages
        control = driven.server.control
        assert control is not None
        assert control.owner is None
        assert driven.server.stats().clients == ()
    finally:
        client.close()


def test_the_relay_runs_behind_the_console(profile: RobotProfile) -> None:
    """Observers come after the operator: at the default priority and at least 5 nice values
    behind the console (which raises its own to -10 where it may)."""
    server = LiveServer(profile, "127.0.0.1", 0)
    server.start()
    try:
        pid = server.relay_pid
        assert pid is not None
        nice = int(Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[16])
        console = current_nice()
        assert nice == min(19, console + max(RELAY_NICE_STEPS, -console))
        assert nice >= 0
    finally:
        server.stop()

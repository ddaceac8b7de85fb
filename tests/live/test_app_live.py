"""`ocu --live`: the Engineer console, its replay and the UR console served to the npm client."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from ocu.link.live import UdpLink
from ocu.live.navigation import ODOM
from ocu.live.robot import TF
from ocu.profile import RobotProfile
from ocu.record import schemas as s
from ocu.record.recorder import Recorder
from ocu.records import LinkEvent, TelemetryFrame
from ocu.sim.simulator import RobotSimulator
from tests.live.node_client import NodeClient, count, require_node

ROOT = Path(__file__).resolve().parents[2]
START_DEADLINE_S = 120.0
SERVING = re.compile(r"live: serving on ws://127\.0\.0\.1:(\d+)")


def console(tmp_path: Path, *options: str) -> subprocess.Popen[str]:
    env = {**os.environ, "QT_QPA_PLATFORM": "offscreen", "PYTHONPATH": str(ROOT)}
    env.pop("OCU_LIVE_TOKEN", None)
    return subprocess.Popen(
        [sys.executable, "-m", "ocu", "--config-dir", str(tmp_path), "--no-gamepad", *options],
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )


def served_port(process: subprocess.Popen[str], lines: list[str]) -> int:
    """The port the console's log says it serves on (read until it says so)."""
    assert process.stderr is not None
    deadline = time.monotonic() + START_DEADLINE_S
    while time.monotonic() < deadline:
        line = process.stderr.readline()
        assert line, "".join(lines)  # it exited before serving
        lines.append(line)
        found = SERVING.search(line)
        if found:
            return int(found.group(1))
    raise AssertionError("".join(lines))


def watch(process: subprocess.Popen[str], port: int, topics: list[str]) -> NodeClient:
    """A client of the console; every topic gets messages (the Engineer sends telemetry once
    a second), then the console quits by SIGTERM."""
    client = NodeClient(f"ws://127.0.0.1:{port}", topics=topics, brief=True)
    try:
        for topic in topics:
            counts = {t: len(client.messages(t)) for t in topics}
            assert client.wait(count(topic, 3)), (topic, counts, client.of("status"))
    finally:
        process.send_signal(signal.SIGTERM)
        client.wait(lambda events: any(e["event"] in ("close", "exit") for e in events))
        client.close()
    return client


def test_ocu_live_serves_the_engineer_console(tmp_path: Path) -> None:
    require_node()
    lines: list[str] = []
    with console(tmp_path, "--live", "127.0.0.1:0") as process:
        port = served_port(process, lines)
        watch(process, port, [s.JOINT_STATES, TF, s.LINK_STATS, ODOM])
        _, rest = process.communicate(timeout=60)
    assert process.returncode == 0, "".join(lines) + rest
    assert "link stopped (zeros sent last)" in rest


def test_ocu_live_serves_the_ur_console(tmp_path: Path) -> None:
    require_node()
    lines: list[str] = []
    with console(tmp_path, "--profile", "ur5e", "--live", "0") as process:
        port = served_port(process, lines)
        watch(process, port, [s.JOINT_STATES, TF])
        _, rest = process.communicate(timeout=60)
    assert process.returncode == 0, "".join(lines) + rest


def test_ocu_replay_live_serves_the_recording(tmp_path: Path, profile: RobotProfile) -> None:
    require_node()
    recording = tmp_path / "session.mcap"
    record(profile, recording, frames=400)
    lines: list[str] = []
    with console(tmp_path, "--replay", str(recording), "--live", "0") as process:
        port = served_port(process, lines)
        watch(process, port, [s.JOINT_STATES, TF, ODOM])
        _, rest = process.communicate(timeout=60)
    assert process.returncode == 0, "".join(lines) + rest


def test_ocu_live_control_drives_the_console_from_a_client(tmp_path: Path) -> None:
    require_node()
    lines: list[str] = []
    with console(tmp_path, "--live", "0", "--live-control") as process:
        port = served_port(process, lines)
        spec: dict[str, object] = {"topic": "/cmd_vel", "encoding": "json"}
        spec["schemaName"] = "geometry_msgs/msg/Twist"
        spec |= {"rateHz": 10.0, "count": 1000, "linear": 0.3, "angular": 0.0}
        client = NodeClient(f"ws://127.0.0.1:{port}", topics=[s.CMD_VEL], publish=spec)
        try:
            # What the console sent the robot, read back from its own live channel.
            assert client.wait(
                lambda events: any(
                    m["decoded"]["linear"]["x"] > 0.0 for m in client.messages(s.CMD_VEL)
                )
            ), (client.of("status"), "".join(lines))
        finally:
            process.send_signal(signal.SIGTERM)
            client.close()
        _, rest = process.communicate(timeout=60)
    assert process.returncode == 0, "".join(lines) + rest
    assert "live client 127.0.0.1:" in "".join(lines) + rest  # the Events dock's line, logged


def record(profile: RobotProfile, path: Path, frames: int) -> None:
    """A recording of the simulator with this many telemetry packets (the waist turning)."""
    sim = RobotSimulator(profile, telemetry_hz=100.0, video_fps=5.0, video_size=(160, 120))
    sim.start()
    recorder = Recorder(profile)
    link = UdpLink(profile, sim.address, gui_alive_timeout_s=None)
    seen = threading.Semaphore(0)

    def on_event(event: LinkEvent) -> None:
        if isinstance(event, TelemetryFrame):
            seen.release()

    link.subscribe(on_event)
    recorder.attach(link)
    recorder.start(path)
    link.start()
    link.set_velocities(waist=0.3)
    try:
        for _ in range(frames):
            assert seen.acquire(timeout=30.0)
    finally:
        link.shutdown()
        recorder.stop()
        sim.stop()


@pytest.mark.parametrize(
    ("options", "message"),
    [
        (("--live", "0.0.0.0:8765"), "refusing to serve a non-loopback address without a token"),
        (("--live", "8765", "--live-token", "short"), "at least 8 characters"),
        (("--live", "x:y"), "bad port in 'x:y'"),
        (("--live-control",), "--live-control needs --live"),
        (("--replay", "x.mcap", "--live", "0", "--live-control"), "nothing to drive with"),
    ],
)
def test_ocu_live_refuses_before_anything_starts(
    tmp_path: Path, options: tuple[str, ...], message: str
) -> None:
    with console(tmp_path, *options) as process:
        _, err = process.communicate(timeout=120)
    assert process.returncode == 2, err
    assert message in err
    assert "scheduling priority" not in err  # refused before the console started

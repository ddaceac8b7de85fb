"""`--live-control`: a client's /cmd_vel as the input mux's `live` source.

The rules on the real console model with a stepped clock (LiveControl), then the whole path:
the npm Foxglove client publishes a Twist, the live server hands it to the control core
(HeadlessConsole, the console's core without Qt), and the simulator, over a real UDP link,
is what is checked.
"""

from __future__ import annotations

import json
import struct
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass, field

import pytest
from PySide6.QtCore import Qt
from PySide6.QtTest import QTest
from pytestqt.qtbot import QtBot
from websockets.sync.client import connect

from ocu.console.channels import Source
from ocu.console.model import ConsoleModel
from ocu.hardware.registry import HARDWARE
from ocu.headless import HeadlessConsole
from ocu.live.control import NOT_FREE, LiveControl, TwistError, decode_twist
from ocu.live.options import LiveError, serve_console, start_live
from ocu.live.server import LiveServer
from ocu.profile import RobotProfile
from ocu.record import schemas as s
from ocu.sim.simulator import RobotSimulator, SimState
from ocu.widgets.live_status import LiveIndicator
from tests.live.node_client import NodeClient, require_node

TWIST = "geometry_msgs/msg/Twist"


class Clock:
    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


@dataclass
class Core:
    """The control core's side LiveControl takes: the model and its lock."""

    model: ConsoleModel
    lock: threading.RLock = field(default_factory=threading.RLock)


@pytest.fixture
def clock() -> Clock:
    return Clock()


@pytest.fixture
def core(profile: RobotProfile, clock: Clock) -> Core:
    return Core(ConsoleModel(profile, clock=clock))


def drive(model: ConsoleModel) -> tuple[float, float]:
    return model.channel("drive_linear").velocity, model.channel("drive_turn").velocity


def test_the_timeout_follows_the_clients_rate(core: Core, clock: Clock) -> None:
    control = LiveControl(core, clock)
    messages: list[str] = []
    core.model.events.message.connect(messages.append)
    assert control.twist("a:1", 0.2, 0.1) is None
    assert drive(core.model) == (0.2, 0.1)
    assert core.model.channel("drive_linear").source is Source.LIVE
    assert messages == ["live client a:1 drives (/cmd_vel)"]
    # The first message: the table's 0.6 s.
    clock.now += 0.59
    control.expire()
    assert drive(core.model) == (0.2, 0.1)
    # 10 Hz: 1.5 intervals, 0.15 s.
    assert control.twist("a:1", 0.2, 0.1) is None
    clock.now += 0.1
    assert control.twist("a:1", 0.2, 0.1) is None
    clock.now += 0.14
    control.expire()
    assert drive(core.model) == (0.2, 0.1)
    clock.now += 0.02
    control.expire()
    assert drive(core.model) == (0.0, 0.0)
    assert control.owner is None
    # Once a second (a panel's default): 0.6 s, not the 1.5 s its rate would give.
    for _ in range(3):
        clock.now += 1.0
        assert control.twist("a:1", 0.2, 0.0) is None
    clock.now += 0.59
    control.expire()
    assert drive(core.model) == (0.2, 0.0)
    clock.now += 0.02
    control.expire()
    assert drive(core.model) == (0.0, 0.0)


def test_one_client_commands_at_a_time(core: Core, clock: Clock) -> None:
    control = LiveControl(core, clock)
    assert control.twist("a:1", 0.2, 0.0) is None
    assert control.twist("b:2", -0.2, 0.0) == "a:1 commands /cmd_vel now"
    assert drive(core.model) == (0.2, 0.0)
    # The first leaves: its drive stops at once, the other may take it.
    control.release("a:1", "left")
    assert drive(core.model) == (0.0, 0.0)
    assert control.twist("b:2", -0.2, 0.0) is None
    assert drive(core.model) == (-0.2, 0.0)
    # Silent past its timeout: another takes over.
    clock.now += 0.61
    assert control.twist("a:1", 0.1, 0.0) is None
    assert control.owner == "a:1"


def test_the_operator_and_the_locks_stop_it(core: Core, clock: Clock) -> None:
    control = LiveControl(core, clock)
    model = core.model
    control.twist("a:1", 0.2, 0.0)
    model.hotkey_down("Y", "shoulder", 1)  # any operator input
    assert drive(model) == (0.0, 0.0)
    assert control.owner is None
    model.hotkey_down("W", "drive_linear", 1)
    assert control.twist("a:1", -0.2, 0.0) is None  # the turn is free, the drive is the key's
    assert model.channel("drive_linear").source is Source.HOTKEY
    model.hotkey_up("W")
    model.hotkey_up("Y")
    for lock in ("focus lost", "GUI silent"):
        control.twist("a:1", 0.2, 0.0)
        assert drive(model) == (0.2, 0.0)
        model.halt(lock, lock=lock)
        assert drive(model) == (0.0, 0.0)
    control.twist("a:1", 0.2, 0.0)
    model.emergency_stop()
    assert drive(model) == (0.0, 0.0)
    # Space latches: the client's next messages move nothing until the operator acts.
    assert control.twist("a:1", 0.2, 0.0) == NOT_FREE
    assert drive(model) == (0.0, 0.0)
    assert control.owner is None


def test_twists_are_decoded_strictly() -> None:
    message = {"linear": {"x": 0.5, "y": 0, "z": 0}, "angular": {"x": 0, "y": 0, "z": -0.25}}
    assert decode_twist("json", json.dumps(message).encode()) == (0.5, -0.25)
    cdr = b"\x00\x01\x00\x00" + struct.pack("<6d", 0.5, 0, 0, 0, 0, -0.25)
    assert decode_twist("cdr", cdr) == (0.5, -0.25)
    for encoding, payload, reason in [
        ("json", b"{", "not a JSON Twist"),
        ("json", b'{"linear": {"x": "fast"}, "angular": {"z": 0}}', "linear.x must be a finite"),
        ("json", b'{"linear": {"x": NaN}, "angular": {"z": 0}}', "linear.x must be a finite"),
        ("cdr", cdr[:20], "not a CDR Twist"),
        ("cdr", b"\x00\x01\x00\x00" + struct.pack("<6d", 1e400, 0, 0, 0, 0, 0), "finite"),
    ]:
        with pytest.raises(TwistError, match=reason):
            decode_twist(encoding, payload)


def test_live_control_needs_a_server_and_a_chassis(profile: RobotProfile) -> None:
    with pytest.raises(LiveError, match="--live-control needs --live"):
        start_live(profile, None, None, control=True)


# ---- the whole path: npm client -> server -> control core -> UDP -> simulator ---------------


@dataclass
class Driven:
    sim: RobotSimulator
    console: HeadlessConsole
    server: LiveServer

    @property
    def url(self) -> str:
        return f"ws://127.0.0.1:{self.server.address[1]}"


def moving(state: SimState) -> bool:
    return abs(state.commanded_velocities.get("drive_linear", 0.0)) > 0.0


def still(state: SimState) -> bool:
    return not moving(state)


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


def publish(url: str, encoding: str, rate_hz: float, count: int, linear: float) -> NodeClient:
    spec: dict[str, object] = {"topic": "/cmd_vel", "encoding": encoding, "schemaName": TWIST}
    spec |= {"rateHz": rate_hz, "count": count, "linear": linear, "angular": 0.0}
    return NodeClient(url, topics=[], publish=spec)


def published(client: NodeClient, n: int) -> bool:
    return client.wait(lambda events: any(e.get("n") == n for e in events))


def test_a_foxglove_client_drives_the_robot_and_stops_when_it_goes_quiet(
    driven: Driven,
) -> None:
    client = publish(driven.url, "json", 20.0, 20, 0.3)
    try:
        assert driven.sim.wait_until(moving, 10.0)
        assert driven.sim.state().commanded_velocities["drive_linear"] > 0.0
        assert published(client, 20)
        last_ms = client.of("published")[-1]["local_ms"]
        assert driven.sim.wait_until(still, 5.0)
        stopped_after_ms = time.time() * 1000.0 - last_ms
    finally:
        client.close()
    # At 20 Hz its timeout is 0.15 s; the control cycle and the link's next datagram follow.
    assert stopped_after_ms < 600.0, stopped_after_ms
    assert driven.server.stats().clients == ()


def test_a_panel_at_one_hertz_moves_the_robot_in_short_bursts(driven: Driven) -> None:
    client = publish(driven.url, "cdr", 1.0, 3, 0.3)
    try:
        for n in (1, 2, 3):
            assert published(client, n)
            assert driven.sim.wait_until(moving, 5.0)
            sent_ms = client.of("published")[n - 1]["local_ms"]
            assert driven.sim.wait_until(still, 5.0)
            moved_ms = time.time() * 1000.0 - sent_ms
            # It stopped long before the next message: 0.6 s, the table's bound.
            assert moved_ms < 950.0, moved_ms
            assert len(client.of("published")) == n
    finally:
        client.close()


def test_a_second_client_is_refused_and_leaving_stops_at_once(driven: Driven) -> None:
    first = publish(driven.url, "json", 2.0, 1000, 0.3)
    second = None
    try:
        assert driven.sim.wait_until(moving, 10.0)
        second = publish(driven.url, "json", 2.0, 1000, -0.3)
        assert second.wait(
            lambda events: any("commands /cmd_vel now" in e.get("message", "") for e in events)
        )
        assert driven.sim.state().commanded_velocities["drive_linear"] > 0.0
        first.close()
        assert driven.sim.wait_until(
            lambda state: state.commanded_velocities.get("drive_linear", 0.0) <= 0.0, 5.0
        )
        # Then the second may drive.
        assert driven.sim.wait_until(
            lambda state: state.commanded_velocities.get("drive_linear", 0.0) < 0.0, 5.0
        )
    finally:
        first.close()
        if second is not None:
            second.close()


def test_without_live_control_nothing_a_client_sends_moves_the_robot(
    profile: RobotProfile,
) -> None:
    require_node()
    sim = RobotSimulator(profile, telemetry_hz=50.0, video_fps=0.0)
    sim.start()
    server = LiveServer(profile, "127.0.0.1", 0)
    server.start()
    url = f"ws://127.0.0.1:{server.address[1]}"
    spec: dict[str, object] = {"topic": "/cmd_vel", "encoding": "json", "schemaName": TWIST}
    spec |= {"rateHz": 20.0, "count": 5, "linear": 0.3, "angular": 0.0}
    client = NodeClient(url, topics=[s.JOINT_STATES], publish=spec)
    try:
        assert client.wait(lambda events: bool(client.of("serverInfo")))
        assert "clientPublish" not in client.of("serverInfo")[0]["capabilities"]
        assert not client.of("published")  # the npm client does not publish without it
        # A client that publishes all the same is refused.
        with connect(url, subprotocols=["foxglove.websocket.v1"]) as ws:  # type: ignore[list-item]
            advertise = {"id": 1, "topic": "/cmd_vel", "encoding": "json", "schemaName": TWIST}
            ws.send(json.dumps({"op": "advertise", "channels": [advertise]}))
            twist = {"linear": {"x": 0.3, "y": 0, "z": 0}, "angular": {"x": 0, "y": 0, "z": 0}}
            ws.send(b"\x01\x01\x00\x00\x00" + json.dumps(twist).encode())
            texts = [ws.recv(timeout=10.0) for _ in range(4)]
        assert sum("client publish is off (ocu --live-control)" in str(t) for t in texts) == 2
    finally:
        client.close()
        server.stop()
        sim.stop()
    assert still(sim.state())


def test_the_operator_revokes_the_remote_drive_from_the_status_bar(
    driven: Driven, qtbot: QtBot
) -> None:
    """The console's LIVE indicator: who drives; a click revokes (the robot stops at once and
    stays still while the client goes on publishing), a second click allows again."""
    indicator = LiveIndicator(driven.server)
    qtbot.addWidget(indicator)
    assert indicator.text() == "LIVE 0 · drive allowed"
    client = publish(driven.url, "json", 20.0, 400, 0.3)  # 20 s of /cmd_vel
    try:
        assert driven.sim.wait_until(moving, 10.0)
        qtbot.waitUntil(lambda: indicator.text().startswith("LIVE 1 · drive: 127.0.0.1:"))
        QTest.mouseClick(indicator, Qt.MouseButton.LeftButton)
        assert indicator.text() == "LIVE 1 · drive revoked"
        assert driven.sim.wait_until(still, 2.0)
        # The client goes on publishing: nothing moves the robot while revoked.
        count = len(client.of("published"))
        assert client.wait(lambda events: len([e for e in events if "n" in e]) > count + 10)
        assert still(driven.sim.state())
        QTest.mouseClick(indicator, Qt.MouseButton.LeftButton)
        assert driven.sim.wait_until(moving, 5.0)  # allowed again: its next message drives
        qtbot.waitUntil(lambda: indicator.text().startswith("LIVE 1 · drive: "))
    finally:
        client.close()
    indicator.stop()

"""The live server's services, called by the npm Foxglove client as Foxglove's Call Service
panel calls them: the e-stop (with `--live` alone) and the named poses (`--live-control`).

What is checked is what the Engineer's simulator received over the real UDP link.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any

import pytest

from ocu.console.model import ConsoleModel
from ocu.hardware.registry import HARDWARE
from ocu.headless import HeadlessConsole
from ocu.live.options import serve_console
from ocu.live.server import LiveServer
from ocu.live.services import ESTOP, ESTOP_DONE, MOVE_TO_NAMED_POSE
from ocu.profile import RobotProfile
from ocu.ros.host import live_goal_core
from ocu.sim.simulator import RobotSimulator, SimState
from tests.live.node_client import NodeClient, require_node


@dataclass
class Served:
    sim: RobotSimulator
    console: HeadlessConsole
    server: LiveServer

    @property
    def url(self) -> str:
        return f"ws://127.0.0.1:{self.server.address[1]}"

    def act(self, action: Callable[[ConsoleModel], Any]) -> Any:
        with self.console.manager.lock:
            return action(self.console.model)


def served(profile: RobotProfile, *, control: bool) -> Iterator[Served]:
    require_node()
    sim = RobotSimulator(profile, telemetry_hz=50.0, video_fps=0.0)
    sim.start()
    hardware = HARDWARE.create("engineer", profile, f"{sim.address[0]}:{sim.address[1]}")
    console = HeadlessConsole(ConsoleModel(profile), hardware)
    server = LiveServer(profile, "127.0.0.1", 0, control=control)
    server.start()
    serve_console(server, console.manager, live_goal_core)
    console.start()
    try:
        yield Served(sim, console, server)
    finally:
        server.stop()
        console.stop()
        sim.stop()


@pytest.fixture
def watched(profile: RobotProfile) -> Iterator[Served]:
    yield from served(profile, control=False)


@pytest.fixture
def controlled(profile: RobotProfile) -> Iterator[Served]:
    yield from served(profile, control=True)


def driving(state: SimState) -> bool:
    return state.commanded_velocities.get("drive_linear", 0.0) > 0.0


def answers(client: NodeClient, n: int) -> list[dict[str, Any]]:
    assert client.wait(lambda events: len(client.of("serviceResponse")) >= n)
    return client.of("serviceResponse")


def test_a_watcher_without_live_control_stops_the_robot_and_cannot_release_it(
    watched: Served,
) -> None:
    """The operator drives with a key; an observer's /estop stops the robot and latches."""
    watched.act(lambda model: model.hotkey_down("W", "drive_linear", 1))
    assert watched.sim.wait_until(driving, 10.0)
    calls = [
        {"service": ESTOP, "encoding": "json", "request": {}},
        {"service": ESTOP, "encoding": "cdr", "request": {}, "delayMs": 300},
    ]
    client = NodeClient(watched.url, topics=[], calls=calls)
    try:
        responses = answers(client, 2)
        info = client.of("serverInfo")[0]
        assert "services" in info["capabilities"]
        assert "clientPublish" not in info["capabilities"]
        # The e-stop only: nothing releases it, nothing moves the arm.
        names = [entry[0] for entry in client.of("services")[0]["services"]]
        assert names == [ESTOP]
    finally:
        client.close()
    assert [r["encoding"] for r in responses] == ["json", "cdr"]
    for response in responses:
        assert response["decoded"] == {"success": True, "message": ESTOP_DONE}
    assert watched.sim.wait_until(lambda state: not driving(state), 2.0)
    assert watched.console.model.estopped
    # The key is still held: the latch keeps the robot still until the operator acts.
    assert not watched.sim.wait_until(driving, 0.5)


def test_a_client_moves_the_arm_to_a_named_pose_by_calling_a_service(
    controlled: Served, profile: RobotProfile
) -> None:
    assert profile.arm is not None
    ready = dict(profile.arm.poses["ready"])
    # Called again every 1.5 s, as an impatient user would: a control cycle stalled on a
    # loaded machine halts a move (a safety stop) and the next call plans it again.
    again = {"service": MOVE_TO_NAMED_POSE, "encoding": "json", "request": {"name": "ready"}}
    calls = [
        {"service": MOVE_TO_NAMED_POSE, "encoding": "cdr", "request": {"name": "no such pose"}},
        *({**again, "delayMs": 1500 * k} for k in range(12)),
    ]
    arm = controlled.console.model.arm
    assert arm is not None
    controlled.sim.wait_until(lambda state: state.telemetry_sent > 5, 10.0)

    def at_ready(state: SimState) -> bool:
        return all(abs(state.joints_rad[j] - a) < 0.03 for j, a in ready.items())

    client = NodeClient(controlled.url, topics=[], calls=calls)
    try:
        assert client.wait(lambda events: bool(client.of("services")))
        names = [entry[0] for entry in client.of("services")[0]["services"]]
        assert names == [ESTOP, MOVE_TO_NAMED_POSE]
        refused = min(answers(client, 2), key=lambda r: r["callId"])
        assert not refused["decoded"]["success"]
        assert "no such pose" in refused["decoded"]["message"]
        assert controlled.sim.wait_until(at_ready, 30.0), controlled.sim.state().joints_rad
        assert {"success": True, "message": "moving the arm to ready"} in [
            r["decoded"] for r in client.of("serviceResponse")
        ]
    finally:
        client.close()

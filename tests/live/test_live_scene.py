"""The zones, the planned path and the arm's goal as `foxglove_msgs/msg/SceneUpdate`, decoded
by the npm Foxglove client with Foxglove's own CDR decoder from the schema the server gives.

The console's core (HeadlessConsole) runs on the simulator over a real UDP link; the test sets
the goal and the path in its model, as the operator's window would, and checks what the
client decoded against the model.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any

import pytest

from ocu.console.model import ConsoleModel
from ocu.hardware.registry import HARDWARE
from ocu.headless import HeadlessConsole
from ocu.live.options import serve_console
from ocu.live.scene import (
    ARM_GOAL,
    LIMITING_LINE_M,
    PLAN,
    ZONE_LINE_M,
    ZONES,
    zone_outline,
    zones_update,
)
from ocu.live.server import LiveServer
from ocu.nav.navigator import NO_ZONES, ZoneState
from ocu.nav.world import load_world
from ocu.nav.zones import ZoneDecision
from ocu.profile import RobotProfile
from ocu.sim.simulator import RobotSimulator
from tests.live.node_client import DEADLINE_S, NodeClient, require_node


@dataclass
class Served:
    sim: RobotSimulator
    console: HeadlessConsole
    server: LiveServer

    @property
    def url(self) -> str:
        return f"ws://127.0.0.1:{self.server.address[1]}"

    def act(self, action: Callable[[ConsoleModel], Any]) -> Any:
        """Change the model as the window does: under the control core's lock."""
        with self.console.manager.lock:
            return action(self.console.model)


@pytest.fixture
def served(profile: RobotProfile) -> Iterator[Served]:
    require_node()
    sim = RobotSimulator(
        profile, telemetry_hz=50.0, video_fps=0.0, extended=True, world=load_world("default")
    )
    sim.start()
    hardware = HARDWARE.create("engineer", profile, f"{sim.address[0]}:{sim.address[1]}")
    console = HeadlessConsole(ConsoleModel(profile), hardware)
    server = LiveServer(profile, "127.0.0.1", 0)
    server.start()
    serve_console(server, console.manager)
    console.start()
    try:
        yield Served(sim, console, server)
    finally:
        server.stop()
        console.stop()
        sim.stop()


def entities(message: dict[str, Any]) -> list[dict[str, Any]]:
    return list(message["decoded"]["entities"])


def metadata(entity: dict[str, Any]) -> dict[str, str]:
    return {pair["key"]: pair["value"] for pair in entity["metadata"]}


def last(client: NodeClient, topic: str) -> dict[str, Any]:
    return client.messages(topic)[-1]


def test_a_client_sees_the_zones_the_path_and_the_arm_goal_as_they_change(
    served: Served, profile: RobotProfile
) -> None:
    client = NodeClient(served.url, topics=[ZONES, PLAN, ARM_GOAL])
    try:
        advertised = client.wait(lambda events: bool(client.of("advertise")))
        assert advertised
        kinds = {t[0]: (t[1], t[2]) for t in client.of("advertise")[0]["topics"]}
        for topic in (ZONES, PLAN, ARM_GOAL):
            assert kinds[topic] == ("foxglove_msgs/msg/SceneUpdate", "cdr")
        assert not client.of("error")  # Foxglove's parser took the schema

        # The zones: one ring per zone, the footprint grown by its distance, in base_link.
        def zones_like_the_model(events: list[dict[str, Any]]) -> bool:
            messages = [e for e in events if e.get("topic") == ZONES]
            if not messages:
                return False
            state = served.console.model.nav.zones
            return metadata(entities(messages[-1])[0])["state"] == state.text and state.active

        assert client.wait(zones_like_the_model), served.console.model.nav.zones
        zones = entities(last(client, ZONES))[0]
        assert not last(client, ZONES)["trailing"]
        assert zones["frame_id"] == "base_link"
        assert zones["frame_locked"]
        assert metadata(zones)["active"] == "true"
        settings = profile.navigation.zones
        footprint = profile.navigation.footprint
        assert footprint is not None
        distances = (settings.stop_m, *settings.within_m)
        assert len(zones["lines"]) == len(distances)
        for line, distance in zip(zones["lines"], distances, strict=True):
            assert line["type"] == 1  # LINE_LOOP
            expected = [v for point in zone_outline(footprint, distance) for v in point]
            got = [v for p in line["points"] for v in (p["x"], p["y"])]
            assert got == pytest.approx(expected)
        # Its front edge is the footprint's front plus the zone's distance.
        assert max(p["x"] for p in zones["lines"][-1]["points"]) == pytest.approx(
            footprint.front_m + distances[-1]
        )

        # No assisted mode, no goal: nothing drawn.
        assert client.wait(lambda events: bool(client.messages(PLAN)))
        assert last(client, PLAN)["decoded"]["deletions"][0]["id"] == "plan"

        # The arm's goal: a preview of a stored pose (once the arm has been read), then dropped.
        arm = served.console.model.arm
        assert arm is not None
        assert until(lambda: set(arm.kinematics.joints) <= read(served.console.model))
        served.act(lambda model: arm.preview_named("ready"))
        goal = arm.goal
        assert goal is not None

        def goal_shown(events: list[dict[str, Any]]) -> bool:
            shown = [e for e in events if e.get("topic") == ARM_GOAL and entities(e)]
            return bool(shown) and metadata(entities(shown[-1])[0])["label"] == "ready"

        assert client.wait(goal_shown)
        entity = entities(last(client, ARM_GOAL))[0]
        kin = arm.kinematics
        assert entity["frame_id"] == kin.chain.base
        assert metadata(entity)["state"] == "preview"
        for joint, angle in goal.joints.items():
            assert float(metadata(entity)[joint]) == pytest.approx(angle, abs=1e-6)
        tool = kin.tool_matrix(kin.vector(goal.joints))
        x_axis = entity["arrows"][0]["pose"]
        position = x_axis["position"]
        assert (position["x"], position["y"], position["z"]) == pytest.approx(
            tuple(tool[:3, 3]), abs=1e-9
        )
        assert [a["color"]["r"] for a in entity["arrows"]] == pytest.approx([0.9, 0.1, 0.1])
        assert entity["texts"][0]["text"] == "ready (preview)"

        served.act(lambda model: arm.cancel_goal())
        assert client.wait(lambda events: bool(last(client, ARM_GOAL)["decoded"]["deletions"]))
        assert last(client, ARM_GOAL)["decoded"]["deletions"][0]["id"] == "arm_goal"

        # The path mode's path in odom, then gone when the mode stops.
        served.act(lambda model: model.start_path([(1.0, 0.0), (1.5, 0.5)]))
        assert client.wait(lambda events: bool(entities(last(client, PLAN))))
        plan = entities(last(client, PLAN))[0]
        assert plan["frame_id"] == "odom"
        points = served.console.model.nav.planned_path()
        got = [v for p in plan["lines"][0]["points"] for v in (p["x"], p["y"])]
        assert got == pytest.approx([float(v) for v in points.ravel()])
        assert math.isclose(got[-2], 1.5, abs_tol=0.05)
        served.act(lambda model: model.stop_assist("test"))
        assert client.wait(lambda events: bool(last(client, PLAN)["decoded"]["deletions"]))
    finally:
        client.close()


def read(model: ConsoleModel) -> set[str]:
    """The joints the console has a reading of."""
    return {name for name, r in model.robot.readings.items() if r.angle_rad is not None}


def until(condition: Callable[[], bool], timeout_s: float = DEADLINE_S) -> bool:
    """Whether the condition held before the deadline (polled: the model has no signal for
    a test thread to wait on)."""
    deadline = time.monotonic() + timeout_s
    while not condition():
        if time.monotonic() > deadline:
            return False
        time.sleep(0.01)
    return True


def test_the_zone_limiting_the_drive_is_drawn_thicker_and_off_zones_faint(
    profile: RobotProfile,
) -> None:
    footprint = profile.navigation.footprint
    assert footprint is not None
    settings = profile.navigation.zones
    stamp = {"sec": 1, "nanosec": 0}
    slowed = ZoneDecision(0.2, 0.1, distance_m=0.5, zone=1, limited=True)
    state = ZoneState(slowed, active=True, overridden=False, text=slowed.message())
    lines = zones_update(footprint, settings, state, stamp)["entities"][0]["lines"]
    assert [line["thickness"] for line in lines] == [
        ZONE_LINE_M,
        ZONE_LINE_M,
        LIMITING_LINE_M,  # zone 1: ring 2 (the stop zone is ring 0)
        ZONE_LINE_M,
    ]
    stopped = ZoneDecision(0.0, 0.0, distance_m=0.05, zone=-1, limited=True)
    state = ZoneState(stopped, active=True, overridden=False, text=stopped.message())
    entity = zones_update(footprint, settings, state, stamp)["entities"][0]
    assert entity["lines"][0]["thickness"] == LIMITING_LINE_M
    assert metadata(entity)["state"] == "stopped: obstacle 0.05 m ahead"
    off = zones_update(footprint, settings, NO_ZONES, stamp)["entities"][0]
    assert {line["color"]["a"] for line in off["lines"]} == {0.27}
    assert metadata(off)["active"] == "false"

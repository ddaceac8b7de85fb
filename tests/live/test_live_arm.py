"""`--live-control`: a client's `/joint_goals`, `/arm/named_pose` and `/arm/twist_cmd` as the input
mux's `live` source, under the locks of every source (docs/live.md).

The npm Foxglove client publishes; the live server hands the message to the control core
(HeadlessConsole, the console's core without Qt) through the ROS bridge's goal core; what is
checked is what the simulator received: the Engineer's datagrams (its commanded velocities and
joint angles) over a real UDP link, the UR simulator's URScript over real TCP.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any

import pytest

from ocu.console.model import ConsoleModel
from ocu.hardware.registry import HARDWARE
from ocu.hardware.ur import SimulatedUr
from ocu.headless import HeadlessConsole
from ocu.live.control import NOT_FREE, LiveControl
from ocu.live.goals import LiveGoals
from ocu.live.messages import TWIST_STAMPED, JointGoal
from ocu.live.options import serve_console
from ocu.live.server import LiveServer
from ocu.profile import RobotProfile
from ocu.profile.ur import load_ur_profile
from ocu.profile.ur_robot import ur_robot_profile
from ocu.record import schemas as s
from ocu.ros.bridge import BridgeCore
from ocu.ros.host import live_goal_core
from ocu.sim.simulator import RobotSimulator, SimState
from tests.live.node_client import DEADLINE_S, NodeClient, require_node

JOINT_STATE = "sensor_msgs/msg/JointState"
AGAIN: dict[str, Any] = {"rateHz": 1.0, "count": 60}
ARM_TWIST = "geometry_msgs/msg/TwistStamped"


@dataclass
class Served:
    console: HeadlessConsole
    server: LiveServer

    @property
    def url(self) -> str:
        return f"ws://127.0.0.1:{self.server.address[1]}"

    @property
    def model(self) -> ConsoleModel:
        return self.console.model

    def act(self, action: Callable[[ConsoleModel], Any]) -> Any:
        """Operator input as the window gives it: under the control core's lock."""
        with self.console.manager.lock:
            return action(self.console.model)


def serve(model: ConsoleModel, hardware: Any) -> Served:
    console = HeadlessConsole(model, hardware)
    server = LiveServer(model.profile, "127.0.0.1", 0, control=True)
    server.start()
    serve_console(server, console.manager, live_goal_core)
    console.start()
    return Served(console, server)


@pytest.fixture
def engineer(profile: RobotProfile) -> Iterator[tuple[RobotSimulator, Served]]:
    require_node()
    sim = RobotSimulator(profile, telemetry_hz=50.0, video_fps=0.0)
    sim.start()
    hardware = HARDWARE.create("engineer", profile, f"{sim.address[0]}:{sim.address[1]}")
    served = serve(ConsoleModel(profile), hardware)
    try:
        yield sim, served
    finally:
        served.server.stop()
        served.console.stop()
        sim.stop()


def publish(url: str, topic: str, schema: str, message: dict[str, Any], **spec: Any) -> NodeClient:
    """A client that advertises `topic` and publishes `message` (count, rateHz, encoding)."""
    options = {"topic": topic, "schemaName": schema, "message": message, "encoding": "json"}
    options |= {"rateHz": 20.0, "count": 1} | spec
    return NodeClient(url, topics=[], publish=options)


def joint_goal(names: list[str], positions: list[float]) -> dict[str, Any]:
    header = {"stamp": {"sec": 0, "nanosec": 0}, "frame_id": ""}
    return {"header": header, "name": names, "position": positions, "velocity": [], "effort": []}


def at(pose: dict[str, float], tolerance_rad: float = 0.03) -> Callable[[SimState], bool]:
    return lambda state: all(
        abs(state.joints_rad[joint] - angle) < tolerance_rad for joint, angle in pose.items()
    )


def arm_still(channels: tuple[str, ...]) -> Callable[[SimState], bool]:
    return lambda state: all(state.commanded_velocities.get(c, 0.0) == 0.0 for c in channels)


def statuses(client: NodeClient, text: str) -> bool:
    return client.wait(lambda events: any(text in e.get("message", "") for e in events))


def test_a_client_moves_the_engineers_arm_to_a_named_pose_and_to_joint_goals(
    engineer: tuple[RobotSimulator, Served], profile: RobotProfile
) -> None:
    sim, served = engineer
    assert profile.arm is not None
    ready = dict(profile.arm.poses["ready"])
    # Once a second, as a panel repeats it: a stalled control cycle on a loaded machine
    # halts a move (a safety stop), and the next message plans it again from where it is.
    named = publish(
        served.url, "/arm/named_pose", "std_msgs/msg/String", {"data": "ready"}, **AGAIN
    )
    try:
        assert sim.wait_until(at(ready), DEADLINE_S), sim.state().joints_rad
    finally:
        named.close()
    # A joint goal in CDR, as Foxglove's Publish panel sends it with a cdr-only server.
    target = {"waist": ready["waist"] + 0.3}
    goal = publish(
        served.url,
        "/joint_goals",
        JOINT_STATE,
        joint_goal(list(target), list(target.values())),
        encoding="cdr",
        definition=s.JOINT_STATE.definition,
        **AGAIN,
    )
    try:
        assert sim.wait_until(at(target), DEADLINE_S), sim.state().joints_rad
        assert goal.wait(lambda events: bool(goal.of("published")))
    finally:
        goal.close()


def test_operator_keys_space_and_leaving_stop_a_clients_arm_move(
    engineer: tuple[RobotSimulator, Served], profile: RobotProfile
) -> None:
    sim, served = engineer
    assert profile.arm is not None
    arm = served.model.arm
    assert arm is not None
    channels = arm.channels
    stow, ready = dict(profile.arm.poses["stow"]), dict(profile.arm.poses["ready"])
    far = ready if math.dist(ready.values(), stow.values()) > 0.5 else stow

    def moving(state: SimState) -> bool:
        return any(state.commanded_velocities.get(c, 0.0) != 0.0 for c in channels)

    name = "ready" if far is ready else "stow"
    message = {"data": name}
    first = publish(served.url, "/arm/named_pose", "std_msgs/msg/String", message)
    try:
        assert sim.wait_until(moving, DEADLINE_S)
        # Any operator input stops it (a key on the drive, not on the arm), and the move does
        # not resume by itself.
        served.act(lambda model: model.hotkey_down("W", "drive_linear", 1))
        assert sim.wait_until(arm_still(channels), 5.0)
        served.act(lambda model: model.hotkey_up("W"))
        assert not sim.wait_until(moving, 0.5)  # it stays still
        assert not at(far)(sim.state())
    finally:
        first.close()
    # Space: stops, and nothing a client sends moves the arm until the operator acts.
    again = publish(served.url, "/arm/named_pose", "std_msgs/msg/String", message)
    try:
        assert sim.wait_until(moving, DEADLINE_S)
        served.act(lambda model: model.emergency_stop())
        assert sim.wait_until(arm_still(channels), 5.0)
    finally:
        again.close()
    latched = publish(served.url, "/arm/named_pose", "std_msgs/msg/String", message)
    try:
        assert statuses(latched, NOT_FREE)
        assert arm_still(channels)(sim.state())
    finally:
        latched.close()
    served.act(lambda model: model.release_estop())
    # A client that leaves mid-move stops it at once.
    leaving = publish(served.url, "/arm/named_pose", "std_msgs/msg/String", {"data": "stow"})
    try:
        assert sim.wait_until(moving, DEADLINE_S)
    finally:
        leaving.close()
    assert sim.wait_until(arm_still(channels), 2.0)
    assert not at(stow)(sim.state())


class Clock:
    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


@dataclass
class Core:
    model: ConsoleModel
    lock: threading.RLock = field(default_factory=threading.RLock)


def test_one_client_commands_the_arm_at_a_time_until_its_move_ends(profile: RobotProfile) -> None:
    """The rules on the real model and the real goal core, with a stepped clock."""
    clock = Clock()
    core = Core(ConsoleModel(profile, clock=clock))
    control = LiveControl(core, clock, LiveGoals(core, BridgeCore(profile, clock=clock)))
    assert control.topics() == ("/cmd_vel", "/joint_goals", "/arm/twist_cmd", "/arm/named_pose")
    goal = JointGoal(("waist",), (0.5,))
    assert control.command("a:1", "/joint_goals", goal) is None
    assert control.owner == "a:1"
    assert control.command("b:2", "/joint_goals", goal) == "a:1 commands /joint_goals now"
    assert control.twist("b:2", 0.1, 0.0) == "a:1 commands /joint_goals now"
    # A goal is one message for one move: the client commands while the move goes on.
    clock.now += 5.0
    control.expire()
    assert control.owner == "a:1"
    # Its goal cancelled (an empty goal): it lets go after its timeout.
    assert control.command("a:1", "/joint_goals", JointGoal((), ())) is None
    control.step()
    clock.now += 0.61
    control.expire()
    assert control.owner is None
    assert control.command("b:2", "/joint_goals", goal) is None
    # Leaving stops it at once; a bad goal is refused with the core's reason.
    control.release("b:2", "left")
    assert control.owner is None
    assert "nose" in str(control.command("a:1", "/joint_goals", JointGoal(("nose",), (0.1,))))
    core.model.emergency_stop()
    assert control.command("a:1", "/joint_goals", goal) == NOT_FREE


def test_a_quiet_drive_stream_stops_the_tracks_while_the_clients_goal_goes_on(
    profile: RobotProfile,
) -> None:
    clock = Clock()
    core = Core(ConsoleModel(profile, clock=clock))
    control = LiveControl(core, clock, LiveGoals(core, BridgeCore(profile, clock=clock)))
    model = core.model
    assert control.twist("a:1", 0.2, 0.0) is None
    assert control.command("a:1", "/joint_goals", JointGoal(("waist",), (0.5,))) is None
    assert model.channel("drive_linear").velocity == 0.2
    # Its Twists stop: the tracks stop after the stream's timeout, the goal goes on.
    clock.now += 0.61
    control.expire()
    assert model.channel("drive_linear").velocity == 0.0
    assert control.owner == "a:1"
    assert control.twist("b:2", 0.2, 0.0) == "a:1 commands /joint_goals now"


# ---- the UR: the URScript the simulator received ------------------------------------------


@pytest.fixture
def ur() -> Iterator[tuple[SimulatedUr, Served]]:
    require_node()
    profile = ur_robot_profile(load_ur_profile("ur5e"))
    hardware = HARDWARE.create("ur-sim", profile)
    assert isinstance(hardware, SimulatedUr)
    served = serve(ConsoleModel(profile), hardware)
    try:
        yield hardware, served
    finally:
        served.server.stop()
        served.console.stop()


def until(condition: Callable[[], bool], timeout_s: float = DEADLINE_S) -> bool:
    """Whether the condition held before the deadline (polled: the UR simulator's thread has
    nothing to wait on)."""
    deadline = time.monotonic() + timeout_s
    while not condition():
        if time.monotonic() > deadline:
            return False
        time.sleep(0.005)
    return True


def test_a_client_jogs_the_ur_with_arm_twist_cmd_and_it_stops_with_the_stream(
    ur: tuple[SimulatedUr, Served],
) -> None:
    hardware, served = ur
    sim = hardware.simulator
    assert until(lambda: served.model.robot.frame is not None)
    start = sim.snapshot().q
    header = {"stamp": {"sec": 0, "nanosec": 0}, "frame_id": "base_link"}
    twist = {"linear": {"x": 0.0, "y": 0.0, "z": 0.05}, "angular": {"x": 0, "y": 0, "z": 0}}
    client = publish(
        served.url,
        "/arm/twist_cmd",
        ARM_TWIST,
        {"header": header, "twist": twist},
        count=20,
        encoding="cdr",
        definition=TWIST_STAMPED.definition,
    )
    try:
        assert until(lambda: max(abs(v) for v in sim.snapshot().qd) > 0.0)
        assert sim.snapshot().program == "speedj"
        assert client.wait(lambda events: any(e.get("n") == 20 for e in events))
        last_ms = client.of("published")[-1]["local_ms"]
        assert until(lambda: max(abs(v) for v in sim.snapshot().qd) == 0.0, 5.0)
        stopped_after_ms = time.time() * 1000.0 - last_ms
    finally:
        client.close()
    moved = [abs(a - b) for a, b in zip(sim.snapshot().q, start, strict=True)]
    assert max(moved) > 0.005, moved
    # The jog's own timeout (the profile's 0.1 s) and the control cycle, not a second.
    assert stopped_after_ms < 600.0, stopped_after_ms


def test_a_client_moves_the_ur_to_a_joint_goal(ur: tuple[SimulatedUr, Served]) -> None:
    hardware, served = ur
    sim = hardware.simulator
    assert until(lambda: served.model.robot.frame is not None)
    arm = served.model.arm
    assert arm is not None
    joint = arm.kinematics.joints[0]
    start = sim.snapshot().q[0]
    goal = publish(
        served.url, "/joint_goals", JOINT_STATE, joint_goal([joint], [start + 0.2]), **AGAIN
    )
    try:
        assert until(lambda: abs(sim.snapshot().q[0] - (start + 0.2)) < 0.01)
        assert sim.snapshot().last_command in ("speedj", "stopj")
    finally:
        goal.close()


def test_a_client_learns_twist_stamped_from_the_server_and_viewers_see_the_jog(
    ur: tuple[SimulatedUr, Served],
) -> None:
    """Foxglove's Publish panel encodes cdr only with a definition the server advertised:
    /arm/twist_cmd is a channel of the server's (the twists the live source took), so the
    client takes TwistStamped's definition from it, and a viewer sees the jog."""
    hardware, served = ur
    sim = hardware.simulator
    assert until(lambda: served.model.robot.frame is not None)
    watcher = NodeClient(served.url, topics=["/arm/twist_cmd"])
    header = {"stamp": {"sec": 0, "nanosec": 0}, "frame_id": "base_link"}
    twist = {"linear": {"x": 0.0, "y": 0.0, "z": 0.04}, "angular": {"x": 0, "y": 0, "z": 0}}
    client = None
    try:
        assert watcher.wait(lambda events: any(e["event"] == "advertise" for e in events))
        client = publish(
            served.url,
            "/arm/twist_cmd",
            ARM_TWIST,
            {"header": header, "twist": twist},
            count=10,
            encoding="cdr",
            definition="advertised",
        )
        assert client.wait(lambda events: any(e["event"] == "definition" for e in events))
        assert until(lambda: max(abs(v) for v in sim.snapshot().qd) > 0.0)
        assert watcher.wait(lambda events: len(watcher.messages("/arm/twist_cmd")) >= 3)
        seen = watcher.messages("/arm/twist_cmd")[0]["decoded"]
        assert seen["header"]["frame_id"] == "base_link"
        assert seen["twist"]["linear"] == {"x": 0.0, "y": 0.0, "z": 0.04}
        assert seen["header"]["stamp"]["sec"] > 0  # stamped by the console when taken
    finally:
        watcher.close()
        if client is not None:
            client.close()
    channels = [t for e in watcher.of("advertise") for t in e["topics"]]
    assert ["/arm/twist_cmd", ARM_TWIST, "cdr"] in channels

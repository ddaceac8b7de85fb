"""`ocu-ros`'s joint between the ROS bridge and the console model (ocu.ros.host), without ROS:
a real BridgeCore, ConsoleModel and HeadlessConsole over the simulator plug-in."""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator

import pytest

from ocu.console.model import ConsoleModel
from ocu.core.hardware import HardwareComponent
from ocu.hardware.engineer import SimulatedEngineer
from ocu.hardware.registry import HARDWARE
from ocu.headless import HeadlessConsole
from ocu.profile import RobotProfile
from ocu.records import LinkState
from ocu.ros.bridge import BridgeCore
from ocu.ros.host import ModelSink
from ocu.sim.simulator import SimState

DEADLINE_S = 10.0
SILENT_AFTER_S = 0.3
PLANNER_PERIOD_S = 0.05


def wait_for(predicate: Callable[[], bool], what: str) -> None:
    deadline = time.monotonic() + DEADLINE_S
    while not predicate():
        assert time.monotonic() < deadline, f"no {what} within {DEADLINE_S} s"
        time.sleep(0.01)


def driving(state: SimState) -> bool:
    return state.velocities["drive_linear"] > 0.0


@pytest.fixture
def hardware(profile: RobotProfile) -> Iterator[HardwareComponent]:
    component = HARDWARE.create("engineer-sim", profile, telemetry_hz=20.0, video_fps=0.0, seed=5)
    yield component
    component.shutdown()


def test_a_silent_bridge_thread_stops_what_ros_moves_until_it_steps_again(
    profile: RobotProfile, hardware: HardwareComponent
) -> None:
    assert isinstance(hardware, SimulatedEngineer)
    sim = hardware.simulator
    headless = HeadlessConsole(ConsoleModel(profile), hardware)
    sink = ModelSink(headless, silent_after_s=SILENT_AFTER_S)
    core = BridgeCore(profile)
    core.attach(sink, headless.model.limits, link_state=lambda: hardware.link.state)
    sink.start(core)
    headless.start()
    try:
        wait_for(lambda: hardware.link.state is LinkState.CONNECTED, "connection")

        def planner_until(predicate: Callable[[SimState], bool], *, step: bool) -> None:
            # A planner streams cmd_vel (rospy's threads); `step`: the bridge thread runs.
            deadline = time.monotonic() + DEADLINE_S
            while not predicate(sim.state()):
                assert time.monotonic() < deadline, sim.state().velocities
                if step:
                    sink.stepped()
                core.on_cmd_vel(0.25, 0.0)
                time.sleep(PLANNER_PERIOD_S)  # the planner's pace

        planner_until(driving, step=True)
        # The bridge thread stops stepping; the planner streams on.
        silent_from = time.monotonic()
        planner_until(lambda s: not driving(s), step=False)
        assert time.monotonic() - silent_from < SILENT_AFTER_S + 0.5
        stopped_at = sim.state().time_s
        count = sim.state().rcp_count
        planner_until(lambda s: s.rcp_count >= count + 10, step=False)
        held = [r for r in sim.received_commands() if r.time_s > stopped_at]
        assert held
        assert all(r.packet.axes[profile.channels["drive_linear"].axis] == 0 for r in held)
        # It steps again: the next cmd_vel is obeyed.
        planner_until(driving, step=True)
    finally:
        sink.close()
        core.detach(stop=True)
        headless.stop()

"""The "ur" and "ur-sim" hardware plug-ins: what they describe, and the control core driving
the UR simulator through them (real TCP on 127.0.0.1; the SIMULATOR's snapshot is read)."""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator

import pytest

from ocu.console.model import ConsoleModel
from ocu.core.hardware import HardwareComponent
from ocu.hardware.registry import HARDWARE
from ocu.hardware.ur import SimulatedUr, parse_host
from ocu.headless import HeadlessConsole
from ocu.link.base import LinkError
from ocu.link.ur import UrLink
from ocu.profile import RobotProfile
from ocu.profile.ur import load_ur_profile
from ocu.profile.ur_robot import ur_robot_profile
from ocu.records import Command, LinkState
from ocu.sim.ur import UrSimulator

DEADLINE_S = 10.0


def wait_for(condition: Callable[[], bool], what: str) -> None:
    deadline = time.monotonic() + DEADLINE_S
    while not condition():
        if time.monotonic() > deadline:
            raise AssertionError(f"not {what} within {DEADLINE_S} s")
        time.sleep(0.001)  # polling interval: the condition decides


@pytest.fixture
def ur_profile() -> RobotProfile:
    return ur_robot_profile(load_ur_profile("ur5e"))


@pytest.fixture
def simulated(ur_profile: RobotProfile) -> Iterator[SimulatedUr]:
    component = HARDWARE.create("ur-sim", ur_profile)
    assert isinstance(component, SimulatedUr)
    yield component
    component.shutdown()


def test_the_ur_plugins_describe_an_arm_and_nothing_else(simulated: SimulatedUr) -> None:
    assert {"ur", "ur-sim"} <= set(HARDWARE.names)
    names = load_ur_profile("ur5e").joint_names
    assert [joint.name for joint in simulated.joints] == list(names)
    assert simulated.state_interfaces()[:3] == (
        "shoulder_pan_joint/position",
        "shoulder_pan_joint/velocity",
        "shoulder_pan_joint/effort",
    )
    assert simulated.command_interfaces() == tuple(f"{name}/velocity" for name in names)
    assert simulated.capabilities == frozenset({"arm"})
    for capability in ("drive", "cameras", "torch", "range_scan", "battery", "imu"):
        assert not simulated.has(capability)
    assert not simulated.set_stream_request([])
    assert isinstance(simulated.link, UrLink)


def test_the_control_core_drives_the_simulated_ur(
    simulated: SimulatedUr, ur_profile: RobotProfile
) -> None:
    model = ConsoleModel(ur_profile)
    console = HeadlessConsole(model, simulated)
    console.start()
    try:
        wait_for(lambda: simulated.link.state is LinkState.CONNECTED, "connected")
        console.call(lambda: model.set_velocity("wrist_3_joint", 0.3))
        wait_for(lambda: abs(simulated.simulator.snapshot().qd[5] - 0.3) < 1e-6, "wrist 3 moving")
        console.call(lambda: model.emergency_stop("test"))
        wait_for(lambda: simulated.simulator.snapshot().program == "stopj", "stopj running")
        wait_for(lambda: all(abs(v) < 1e-9 for v in simulated.simulator.snapshot().qd), "at rest")
    finally:
        console.stop()


def test_the_ur_plugin_over_tcp_sends_stopj_last(ur_profile: RobotProfile) -> None:
    arm = load_ur_profile("ur5e")
    with UrSimulator(arm, ports=(0, 0, 0)) as sim:
        ports = (sim.ports["primary"], sim.ports["secondary"], sim.ports["realtime"])
        component: HardwareComponent = HARDWARE.create(
            "ur", ur_profile, "127.0.0.1", ports=ports, gui_alive_timeout_s=None
        )
        component.start()
        try:
            wait_for(lambda: component.link.state is LinkState.CONNECTED, "connected")
            assert component.write(Command({"wrist_2_joint": -0.2}))
            wait_for(lambda: abs(sim.snapshot().qd[4] + 0.2) < 1e-6, "wrist 2 moving")
        finally:
            component.shutdown()
        wait_for(lambda: sim.snapshot().program == "stopj", "stopj after shutdown")
        wait_for(lambda: all(abs(v) < 1e-9 for v in sim.snapshot().qd), "at rest")


def test_targets_and_profiles_the_ur_plugin_refuses(profile: RobotProfile) -> None:
    assert parse_host("10.0.0.2") == ("10.0.0.2", (30001, 30002, 30003))
    assert parse_host("ur.local:40000") == ("ur.local", (40001, 40002, 40003))
    for bad in (":30000", "host:port", "host:70000"):
        with pytest.raises(LinkError, match="HOST"):
            parse_host(bad)
    # The Engineer's profile is no UR arm's.
    with pytest.raises(LinkError, match="not a UR arm"):
        HARDWARE.create("ur", profile, "10.0.0.2")
    with pytest.raises(LinkError, match="no target"):
        HARDWARE.create("ur-sim", ur_robot_profile(load_ur_profile("ur5")), "10.0.0.2")

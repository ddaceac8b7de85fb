"""The hardware component and its registry: the Engineer's three plug-ins over real links.

The simulator runs for real (in this process over the virtual wire, or over UDP on
127.0.0.1); the recording is one the recorder wrote during a run and is read back.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TypeVar

import pytest

from ocu.console.model import ConsoleModel
from ocu.core.hardware import CAPABILITIES, HardwareComponent, HardwareError, HardwareRegistry
from ocu.hardware.engineer import SimulatedEngineer, engineer_component
from ocu.hardware.registry import HARDWARE
from ocu.headless import HeadlessConsole
from ocu.link.base import LinkError
from ocu.profile import RobotProfile
from ocu.record.recorder import Recorder
from ocu.record.replay_link import ReplayLink
from ocu.records import Command
from ocu.sim.simulator import RobotSimulator

DEADLINE_S = 10.0
T = TypeVar("T")
# The Engineer has every capability but timed moves (its protocol carries velocities only).
EVERY_CAPABILITY = frozenset(CAPABILITIES) - {"timed_moves"}


def wait_for(condition: Callable[[], bool], what: str) -> None:
    """Poll a condition until a deadline (no fixed sleep decides anything)."""
    deadline = time.monotonic() + DEADLINE_S
    while not condition():
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out waiting for {what}")
        time.sleep(0.005)


def waist_speed(headless: HeadlessConsole) -> float | None:
    """The waist's speed in the newest telemetry the model has, None before any."""

    def read() -> float | None:
        frame = headless.model.robot.frame
        return None if frame is None else frame.readings["waist"].speed_rad_s

    return headless.call(read)


@pytest.fixture
def simulated(profile: RobotProfile) -> Iterator[HardwareComponent]:
    component = HARDWARE.create("engineer-sim", profile, telemetry_hz=20.0, video_fps=0.0, seed=3)
    yield component
    component.shutdown()


def test_the_registry_holds_the_engineers_three_plugins(profile: RobotProfile) -> None:
    assert HARDWARE.names[:3] == ("engineer", "engineer-sim", "engineer-recording")
    with pytest.raises(HardwareError, match="no hardware plug-in 'ur5e'"):
        HARDWARE.create("ur5e", profile, "10.0.0.2:30004")
    registry = HardwareRegistry()
    registry.register("sim", lambda profile, target: HARDWARE.create("engineer-sim", profile))
    with pytest.raises(HardwareError, match="registered twice"):
        registry.register("sim", lambda profile, target: HARDWARE.create("engineer-sim", profile))
    with pytest.raises(LinkError, match="HOST:PORT"):
        HARDWARE.create("engineer", profile, "no-port")


def test_the_engineers_joints_and_interfaces(
    profile: RobotProfile, simulated: HardwareComponent
) -> None:
    joints = {joint.name: joint for joint in simulated.joints}
    assert set(joints) == set(profile.motors)
    assert joints["waist"].state == ("position", "velocity", "effort")
    assert joints["left_track"].state == ("velocity", "effort")  # a track has no encoder
    # Velocity commands only (the Engineer has no position command), and only for the
    # motors the RCP drives: head_pan and gripper_roll report but take no command.
    commanded = {name for name, joint in joints.items() if joint.command == ("velocity",)}
    assert commanded == set(profile.motors) - {"head_pan", "gripper_roll"}
    assert joints["head_pan"].command == ()
    assert "waist/position" in simulated.state_interfaces()
    assert "left_track/position" not in simulated.state_interfaces()
    assert "waist/velocity" in simulated.command_interfaces()
    assert not any(name.endswith("/position") for name in simulated.command_interfaces())
    assert simulated.capabilities == EVERY_CAPABILITY
    assert simulated.has("cameras")
    assert not simulated.read_only
    with pytest.raises(HardwareError, match="unknown capability"):
        simulated.has("teleporter")


def test_the_simulator_plugin_reads_into_the_model_and_writes_to_the_robot(
    profile: RobotProfile, simulated: HardwareComponent
) -> None:
    assert isinstance(simulated, SimulatedEngineer)
    sim = simulated.simulator
    headless = HeadlessConsole(ConsoleModel(profile), simulated)
    headless.start()
    try:
        # read: the control thread feeds the model what the simulator sent.
        wait_for(lambda: waist_speed(headless) is not None, "telemetry in the model")
        # write: a changed command reaches the simulator.
        headless.call(lambda: headless.model.set_velocity("waist", 0.3))
        assert sim.wait_until(lambda s: s.velocities["waist"] > 0.1, DEADLINE_S)
        wait_for(lambda: (waist_speed(headless) or 0.0) > 0.1, "the waist moving in the model")
        # The e-stop goes through the component at once.
        headless.call(lambda: headless.model.emergency_stop("test"))
        assert sim.wait_until(lambda s: s.all_stopped, DEADLINE_S)
    finally:
        headless.stop()


def test_the_udp_plugin_writes_what_the_robot_receives_and_never_undoes_its_zeros(
    profile: RobotProfile,
) -> None:
    sim = RobotSimulator(profile, telemetry_hz=20.0, video_fps=0.0, extended=True)
    sim.start()
    host, port = sim.address
    component = HARDWARE.create("engineer", profile, f"{host}:{port}", gui_alive_timeout_s=None)
    try:
        assert component.capabilities == EVERY_CAPABILITY
        component.start()
        moving = Command(velocities={"shoulder": 0.2})
        assert component.write(moving)
        assert sim.wait_until(lambda s: s.velocities["shoulder"] > 0.05, DEADLINE_S)
        # The link zeroes by itself (its watchdog, LINK LOST): the cycle's next write of the
        # same, unchanged command must not set the robot going again.
        component.link.set_command(Command())
        assert sim.wait_until(lambda s: s.all_stopped, DEADLINE_S)
        assert component.write(moving)
        assert component.link.command == Command()
        # A changed command is written.
        assert component.write(Command(velocities={"shoulder": -0.2}))
        assert sim.wait_until(lambda s: s.velocities["shoulder"] < -0.05, DEADLINE_S)
        assert component.emergency_stop("test")
        assert sim.wait_until(lambda s: s.all_stopped, DEADLINE_S)
    finally:
        component.shutdown()
        sim.stop()


def test_a_vendor_only_link_has_no_extension_capabilities(profile: RobotProfile) -> None:
    sim = RobotSimulator(profile, telemetry_hz=20.0, video_fps=0.0)
    sim.start()
    host, port = sim.address
    try:
        component = HARDWARE.create("engineer", profile, f"{host}:{port}", extension=False)
        component.shutdown()
    finally:
        sim.stop()
    assert component.capabilities == EVERY_CAPABILITY - {"range_scan", "battery", "imu"}


def test_a_recording_reads_back_and_refuses_commands(
    profile: RobotProfile, simulated: HardwareComponent, tmp_path: Path
) -> None:
    path = tmp_path / "run.mcap"
    recorder = Recorder(profile)
    recorder.attach(simulated.link)
    recorder.start(path)
    headless = HeadlessConsole(ConsoleModel(profile), simulated)
    headless.start()
    try:
        headless.call(lambda: headless.model.set_velocity("waist", 0.3))
        wait_for(lambda: (waist_speed(headless) or 0.0) > 0.1, "the waist moving")
    finally:
        headless.stop()
        stats = recorder.stop()
    assert stats.error is None

    recording = HARDWARE.create("engineer-recording", profile, str(path))
    assert recording.read_only
    assert recording.plugin == "engineer-recording"
    assert recording.capabilities == EVERY_CAPABILITY
    assert not recording.write(Command(velocities={"waist": 0.5}))
    assert not recording.emergency_stop("test")
    assert not recording.set_stream_request(())
    assert recording.link.command == Command()  # nothing reached the link
    replay = recording.link
    assert isinstance(replay, ReplayLink)
    headless = HeadlessConsole(ConsoleModel(profile), recording)
    headless.start()
    try:
        replay.set_speed(4.0)
        replay.play()
        # read: the recorded motion reaches the model through the component.
        wait_for(lambda: (waist_speed(headless) or 0.0) > 0.1, "the recorded waist motion")
    finally:
        headless.stop()


def test_a_component_checks_its_description(profile: RobotProfile) -> None:
    sim = RobotSimulator(profile, telemetry_hz=20.0, video_fps=0.0)
    sim.start()
    try:
        component = HARDWARE.create("engineer", profile, f"127.0.0.1:{sim.address[1]}")
        with pytest.raises(HardwareError, match="unknown capabilities"):
            HardwareComponent("x", component.link, joints=(), capabilities={"warp"})
        with pytest.raises(HardwareError, match="named twice"):
            HardwareComponent("x", component.link, joints=component.joints * 2, capabilities=())
        same = engineer_component(component.link)
        assert same.joints == component.joints
        component.shutdown()
        same.shutdown()
    finally:
        sim.stop()

"""Driving with a map end to end: the console model over a real link to the real simulator,
with latency, loss and noise, judged by what the simulator received and where it really is."""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterator

import pytest

from ocu.console.model import ConsoleModel
from ocu.hardware.engineer import engineer_component
from ocu.headless import HeadlessConsole
from ocu.link.live import UdpLink
from ocu.nav.world import load_world
from ocu.profile import RobotProfile
from ocu.protocol.mapping import CommandMapper
from ocu.records import LinkState
from ocu.sim.faults import FaultConfig
from ocu.sim.simulator import RobotSimulator, SimState

LINEAR = "drive_linear"
DEADLINE_S = 20.0
# A radio link: 60 ms each way with up to 30 ms of jitter (reordering), 10 % loss.
FIELD = FaultConfig(latency_ms=60.0, jitter_ms=30.0, loss=0.1)


@pytest.fixture
def field_sim(profile: RobotProfile) -> Iterator[RobotSimulator]:
    """The extended simulator in the default room over a lossy, delayed link."""
    sim = RobotSimulator(
        profile,
        extended=True,
        world=load_world("default"),
        telemetry_hz=10.0,
        video_fps=0.0,
        faults=FIELD,
        seed=11,
    )
    extension = sim.extension
    assert extension is not None
    for camera in range(len(profile.link.camera_names)):
        extension.stop_camera(camera)  # the cores go to the physics, scans and the test
    sim.start()
    yield sim
    sim.stop()


@pytest.fixture
def console(profile: RobotProfile, field_sim: RobotSimulator) -> Iterator[HeadlessConsole]:
    model = ConsoleModel(profile)
    headless = HeadlessConsole(
        model, engineer_component(UdpLink(profile, field_sim.address, extension=True))
    )
    headless.start()
    wait(lambda: headless.call(lambda: model.nav.zones.text) != "", "zones")
    wait(lambda: headless.call(lambda: model.robot.link_state) is LinkState.CONNECTED, "link")
    wait(lambda: headless.call(model.nav.scan_age_s) is not None, "a scan")
    yield headless
    headless.stop()


def wait(condition: Callable[[], bool], what: str, timeout_s: float = DEADLINE_S) -> None:
    deadline = time.monotonic() + timeout_s
    while not condition():
        if time.monotonic() > deadline:
            raise AssertionError(f"no {what} within {timeout_s:.0f} s")
        time.sleep(0.05)


def sent_speeds(profile: RobotProfile, sim: RobotSimulator, since_s: float) -> list[float]:
    """The drive_linear speed of every RCP the simulator received after `since_s`."""
    mapper = CommandMapper(profile)
    return [
        mapper.to_command(rcp.packet).velocity(LINEAR)
        for rcp in sim.received_commands()
        if rcp.time_s >= since_s
    ]


def still(sim: RobotSimulator, for_s: float = 0.5) -> SimState:
    """Wait until the robot has not moved for `for_s`; its state."""
    last = sim.state().pose
    since = time.monotonic()
    while time.monotonic() - since < for_s:
        time.sleep(0.05)
        pose = sim.state().pose
        if math.dist(pose[:2], last[:2]) > 0.002:
            last, since = pose, time.monotonic()
    return sim.state()


def test_full_speed_at_a_wall_stops_short_of_it(
    profile: RobotProfile, field_sim: RobotSimulator, console: HeadlessConsole
) -> None:
    model = console.model
    console.call(lambda: model.set_max_velocity(LINEAR, 0.45))
    start = time.monotonic()
    console.call(lambda: model.hotkey_down("W", LINEAR, 1))
    wait(lambda: field_sim.state().pose[0] > 2.0, "drive toward the east wall")
    state = still(field_sim)
    assert state.collisions == 0
    gap = 4.95 - (state.pose[0] + 0.62)  # the wall's face minus the footprint's front
    assert 0.0 < gap < 0.45  # it got close, and stopped short
    speeds = sent_speeds(profile, field_sim, start)
    assert max(speeds) == pytest.approx(0.45, abs=0.01)  # full speed far from the wall
    # The key is still held: the zones, not the operator, hold the robot.
    assert speeds[-1] == 0.0
    assert console.call(lambda: model.nav.zones.text).startswith("stopped: obstacle")
    console.call(lambda: model.hotkey_up("W"))


def test_the_path_mode_stops_at_once_on_the_emergency_stop(
    profile: RobotProfile, field_sim: RobotSimulator, console: HeadlessConsole
) -> None:
    model = console.model
    console.call(lambda: model.set_waypoints([(2.5, 0.0), (2.5, 1.0)]))
    console.call(model.start_path)
    wait(lambda: field_sim.state().pose[0] > 0.3, "the path mode to move the robot")
    console.call(lambda: model.emergency_stop("Space"))
    stopped_at = time.monotonic()
    state = still(field_sim, 1.0)
    assert state.all_stopped
    assert console.call(lambda: model.assist_mode) is None
    # The e-stop burst reached the robot; nothing after it asked for motion.
    assert all(speed == 0.0 for speed in sent_speeds(profile, field_sim, stopped_at + 0.2))


def test_the_path_mode_stops_on_link_lost_and_never_resumes(
    profile: RobotProfile, field_sim: RobotSimulator, console: HeadlessConsole
) -> None:
    model = console.model
    console.call(lambda: model.set_waypoints([(2.5, 0.0)]))
    console.call(model.start_path)
    wait(lambda: field_sim.state().pose[0] > 0.3, "the path mode to move the robot")
    field_sim.cut_link()
    wait(lambda: console.call(lambda: model.robot.link_state) is LinkState.LOST, "LINK LOST")
    assert console.call(lambda: model.assist_mode) is None
    field_sim.restore_link()
    restored = time.monotonic()
    wait(lambda: console.call(lambda: model.robot.link_state) is LinkState.CONNECTED, "link")
    time.sleep(1.0)
    assert all(speed == 0.0 for speed in sent_speeds(profile, field_sim, restored))
    assert still(field_sim).all_stopped

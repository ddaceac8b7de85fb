"""Driving with a map in the console model (no Qt): the safety zones on every command source,
the override, and the assisted modes yielding to the operator, the e-stop, LINK LOST and
stale odometry."""

from __future__ import annotations

from collections.abc import Callable

import pytest

from ocu.console.model import ConsoleModel, Source
from ocu.nav.geometry import Pose
from ocu.nav.navigator import ZONES_BLIND, ZONES_CLEAR, ZONES_OFF_NO_DATA, ZoneState
from ocu.nav.world import parse_world
from ocu.profile import RobotProfile
from ocu.protocol import TelemetryPacket
from ocu.protocol.mapping import scan_frame
from ocu.records import Command, JointReading, LinkState, ScanFrame, TelemetryFrame
from ocu.sim.rangefinder import RangeSensor, RangeSensorConfig

LINEAR, TURN = "drive_linear", "drive_turn"


class Clock:
    """A clock the test moves."""

    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


@pytest.fixture
def clock() -> Clock:
    return Clock()


@pytest.fixture
def model(profile: RobotProfile, clock: Clock) -> ConsoleModel:
    console = ConsoleModel(profile, clock=clock)
    console.robot.on_link_state(LinkState.CONNECTED, "test")
    return console


def wall_scan(clock: Clock, gap_m: float) -> ScanFrame:
    """A scan of a wall `gap_m` ahead of the robot's front (the footprint reaches 0.62 m)."""
    world = parse_world(
        {"wall": [{"from_m": [0.62 + gap_m + 0.05, -4.0], "to_m": [0.67 + gap_m, 4.0]}]}
    )
    sensor = RangeSensor(world, RangeSensorConfig(noise_m=0.0))
    return scan_frame(sensor.sweep(Pose(0.0, 0.0, 0.0), 0), clock.now, 0.0)


def tracks(clock: Clock, speed_m_s: float = 0.0) -> TelemetryFrame:
    def track(name: str, device: int) -> JointReading:
        return JointReading(name, device, 1, 2, None, speed_m_s, 0.5, 0, None, speed_m_s, 0.5)

    readings = {"left_track": track("left_track", 1), "right_track": track("right_track", 2)}
    return TelemetryFrame(TelemetryPacket(tick=1), readings, clock.now, 0.0, 0.0)


SOURCES: dict[str, Callable[[ConsoleModel], object]] = {
    "hotkey": lambda m: m.hotkey_down("W", LINEAR, 1),
    "slider": lambda m: m.set_velocity(LINEAR, 0.3),
    "typed": lambda m: m.set_velocities({LINEAR: 0.3}),
    "ros": lambda m: m.set_external_velocities({LINEAR: 0.3}),
    "gamepad": lambda m: m.set_gamepad({LINEAR: 1.0}),
}


@pytest.mark.parametrize("source", list(SOURCES))
def test_every_source_is_slowed_near_an_obstacle(
    model: ConsoleModel, clock: Clock, source: str
) -> None:
    zones: list[ZoneState] = []
    model.events.zones_changed.connect(zones.append)
    model.on_scan(wall_scan(clock, 0.25))
    SOURCES[source](model)
    assert model.channel(LINEAR).velocity == pytest.approx(0.2)  # the innermost zone's cap
    assert zones[-1].text.startswith("slowed: obstacle 0.2")
    assert zones[-1].text.endswith(" m ahead")


def test_an_arc_is_slowed_with_its_turn_radius_kept(model: ConsoleModel, clock: Clock) -> None:
    model.on_scan(wall_scan(clock, 0.25))
    model.set_velocities({LINEAR: 0.3, TURN: 0.4})
    linear, turn = model.channel(LINEAR).velocity, model.channel(TURN).velocity
    assert 0.0 < linear <= 0.2 + 1e-9
    assert linear / turn == pytest.approx(0.3 / 0.4)


def test_the_zones_stop_motion_toward_a_wall_and_follow_new_scans(
    model: ConsoleModel, clock: Clock
) -> None:
    model.on_scan(wall_scan(clock, 2.0))
    model.hotkey_down("W", LINEAR, 1)
    assert model.channel(LINEAR).velocity == pytest.approx(0.3)
    clock.now += 0.1
    model.on_scan(wall_scan(clock, 0.05))  # the robot came close while the key was held
    assert model.velocities() == {}
    assert model.nav.zones.text == "stopped: obstacle 0.04 m ahead"
    model.hotkey_up("W")
    model.hotkey_down("S", LINEAR, -1)  # backing off is never held back
    assert model.channel(LINEAR).velocity == pytest.approx(-0.3)


def test_a_stop_for_an_obstacle_holds_until_it_clears_by_a_margin(
    model: ConsoleModel, clock: Clock
) -> None:
    # Held W at 0.3 m/s: 3 cm of margin; the stop distance is 0.10 m of travel to contact.
    model.on_scan(wall_scan(clock, 0.10))
    model.hotkey_down("W", LINEAR, 1)
    assert model.nav.zones.text.startswith("stopped")
    # The next scan puts the wall 6 cm further (the margin moved with a scan's age): a motion
    # the zones stopped stays stopped until it clears the stop distance by 5 cm more ...
    clock.now += 0.1
    model.on_scan(wall_scan(clock, 0.16))
    assert model.nav.zones.text.startswith("stopped")
    assert model.velocities() == {}
    # ... which a fresh press of the same key does not get round either ...
    model.hotkey_up("W")
    model.hotkey_down("W", LINEAR, 1)
    assert model.nav.zones.text.startswith("stopped")
    # ... and beyond it the innermost zone lets the robot creep on.
    clock.now += 0.1
    model.on_scan(wall_scan(clock, 0.25))
    assert model.nav.zones.text.startswith("slowed")
    assert model.channel(LINEAR).velocity == pytest.approx(0.2)


def test_without_range_data_the_zones_are_off_and_say_so(model: ConsoleModel, clock: Clock) -> None:
    model.hotkey_down("W", LINEAR, 1)
    assert model.channel(LINEAR).velocity == pytest.approx(0.3)
    assert model.nav.zones.text == ZONES_OFF_NO_DATA
    model.on_scan(wall_scan(clock, 3.0))
    model.update()
    assert model.nav.zones.text == ZONES_CLEAR
    assert model.channel(LINEAR).velocity == pytest.approx(0.3)


def test_range_data_that_stops_holds_the_drive_to_a_creep(
    model: ConsoleModel, clock: Clock
) -> None:
    model.on_scan(wall_scan(clock, 3.0))
    model.hotkey_down("W", LINEAR, 1)
    assert model.channel(LINEAR).velocity == pytest.approx(0.3)
    clock.now += 1.0  # the scans stopped coming: the wall may be anywhere now
    model.update()
    assert model.nav.zones.text == f"{ZONES_BLIND}: at most 0.20 m/s"
    assert model.nav.zones.blind
    assert model.channel(LINEAR).velocity == pytest.approx(0.2)  # the innermost zone's cap
    model.hotkey_up("W")
    model.override_zones()  # the operator's deliberate act lets a push through
    model.hotkey_down("W", LINEAR, 1)
    assert model.channel(LINEAR).velocity == pytest.approx(0.3)
    model.hotkey_up("W")
    model.on_scan(wall_scan(clock, 3.0))  # the sensor is back
    model.hotkey_down("W", LINEAR, 1)
    assert model.nav.zones.text == ZONES_CLEAR
    assert model.channel(LINEAR).velocity == pytest.approx(0.3)
    model.hotkey_up("W")
    # A new connection (another robot, maybe without a sensor) starts with the zones off.
    clock.now += 1.0
    model.robot.on_link_state(LinkState.CONNECTING, "connecting")
    model.robot.on_link_state(LinkState.CONNECTED, "test")
    model.hotkey_down("W", LINEAR, 1)
    assert model.nav.zones.text == ZONES_OFF_NO_DATA
    assert model.channel(LINEAR).velocity == pytest.approx(0.3)


def test_the_override_lets_one_push_through(model: ConsoleModel, clock: Clock) -> None:
    model.on_scan(wall_scan(clock, 0.05))
    model.override_zones()
    model.hotkey_down("W", LINEAR, 1)
    assert model.channel(LINEAR).velocity == pytest.approx(0.3)
    assert model.nav.zones.text.startswith("ZONES OVERRIDDEN")
    model.hotkey_up("W")  # the push ends: so does the override
    model.update()
    model.hotkey_down("W", LINEAR, 1)
    assert model.velocities() == {}
    model.hotkey_up("W")
    model.override_zones()
    model.emergency_stop("Space")  # an e-stop ends an override that was armed
    model.hotkey_down("W", LINEAR, 1)
    assert model.velocities() == {}


def start_path(model: ConsoleModel, clock: Clock) -> None:
    model.on_telemetry(tracks(clock))
    model.set_waypoints([(2.0, 0.0)])
    model.start_path()
    clock.now += 0.05
    model.update()
    assert model.assist_mode == "path"
    assert model.channel(LINEAR).source is Source.ASSIST
    assert model.channel(LINEAR).velocity > 0.0


@pytest.mark.parametrize(
    ("interrupt", "reason"),
    [
        (lambda m: m.hotkey_down("Q", "waist", 1), "operator took over"),
        (lambda m: m.set_velocity("shoulder", 0.1), "operator took over"),
        (lambda m: m.set_gamepad({"shoulder": 0.5}), "operator took over"),
        (lambda m: m.emergency_stop("Space"), "EMERGENCY STOP (Space)"),
        (lambda m: m.halt("console lost focus"), "console lost focus"),
    ],
)
def test_the_path_mode_yields_at_once(
    model: ConsoleModel, clock: Clock, interrupt: Callable[[ConsoleModel], object], reason: str
) -> None:
    messages: list[str] = []
    model.events.assist_changed.connect(lambda _kind, text: messages.append(text))
    start_path(model, clock)
    interrupt(model)
    assert model.assist_mode is None
    assert model.channel(LINEAR).velocity == 0.0
    assert model.channel(TURN).velocity == 0.0
    assert messages[-1] == f"path mode stopped: {reason}"
    clock.now += 0.05
    model.update()  # nothing resumes
    assert model.channel(LINEAR).velocity == 0.0


def test_the_path_mode_stops_on_link_lost_and_stale_odometry(
    model: ConsoleModel, clock: Clock
) -> None:
    messages: list[str] = []
    model.events.assist_changed.connect(lambda _kind, text: messages.append(text))
    start_path(model, clock)
    model.robot.on_link_state(LinkState.LOST, "no packets")
    model.update()
    assert model.assist_mode is None
    assert model.velocities() == {}
    assert messages[-1] == "path mode stopped: LINK LOST"
    model.robot.on_link_state(LinkState.CONNECTED, "back")
    start_path(model, clock)
    clock.now += 3.0  # no telemetry for longer than odometry.stale_after_s
    model.update()
    assert model.assist_mode is None
    assert model.velocities() == {}
    assert messages[-1].startswith("path mode stopped: odometry stale")


def test_the_assisted_modes_are_slowed_by_the_zones_too(model: ConsoleModel, clock: Clock) -> None:
    model.on_telemetry(tracks(clock))
    model.on_scan(wall_scan(clock, 0.05))
    model.set_waypoints([(2.0, 0.0)])
    model.start_path()
    for _ in range(10):
        clock.now += 0.05
        model.on_telemetry(tracks(clock))
        model.on_scan(wall_scan(clock, 0.05))
        model.update()
    assert model.assist_mode == "path"
    assert model.velocities() == {}


def test_odometry_integrates_what_was_sent(model: ConsoleModel, clock: Clock) -> None:
    model.on_command_sent(Command({LINEAR: 0.3}), clock.now)
    for _ in range(10):
        clock.now += 0.2
        model.on_command_sent(Command({LINEAR: 0.3}), clock.now)
    assert model.nav.estimate().pose.x_m == pytest.approx(0.6)
    model.reset_odometry()
    assert model.nav.estimate().pose == Pose(0.0, 0.0, 0.0)


def test_the_grid_takes_five_scans_a_second_and_the_zones_every_scan(
    model: ConsoleModel, clock: Clock
) -> None:
    assert model.nav.grid is not None
    texts: list[str] = []
    model.events.zones_changed.connect(lambda zones: texts.append(zones.text))
    for k in range(10):  # one second of a 10 Hz sensor, the wall coming closer
        model.on_scan(wall_scan(clock, 2.0 - 0.19 * k))
        clock.now += 0.1
    assert model.nav.grid.scans == 5
    model.hotkey_down("W", LINEAR, 1)
    assert texts[-1].startswith("slowed: obstacle 0.2")  # the newest scan, not the grid's
    model.reset_odometry()
    model.on_scan(wall_scan(clock, 0.5))  # a reset map takes the next scan at once
    assert model.nav.grid.scans == 1

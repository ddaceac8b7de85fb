"""A channel that ends by itself (Command.until): the link zeroes it at its time, with no newer
command, and the robot stops there.

The position controller gives each motion the time the joint would reach its target; on a
loaded machine the control thread's next tick can come late, and before this the joint ran
on past the target until then (the 1 Hz position test's reversal). The simulator in this
process records what it received over a real UDP socket on 127.0.0.1.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Iterator
from dataclasses import replace

import pytest

from ocu.link.live import UdpLink
from ocu.profile import RobotProfile
from ocu.protocol.mapping import CommandMapper
from ocu.records import Command, CommandError, LinkEvent, SafetyEvent
from ocu.sim.simulator import RobotSimulator

DEADLINE_S = 10.0
SPEED_RAD_S = 0.5


def test_a_command_without_its_ended_channels() -> None:
    command = Command(velocities={"shoulder": 0.5, "elbow": -0.2}, until={"shoulder": 10.0})
    assert command.expired(9.0) is command
    assert command.next_end == 10.0
    ended = command.expired(10.0)
    assert ended.velocities == {"elbow": -0.2}
    assert ended.until == {}
    assert ended.next_end is None
    # The same on the wire now, whatever the ends: a new end alone sends nothing at once.
    assert command.same_wire(Command(velocities={"shoulder": 0.5, "elbow": -0.2}))
    assert not command.same_wire(ended)
    # A channel given a new velocity by hand runs until the next command: no end.
    assert command.with_velocity("shoulder", 0.1).until == {}
    assert command.stopped().until == {}
    with pytest.raises(CommandError, match="shoulder: the end of its motion must be finite"):
        Command(velocities={"shoulder": 0.5}, until={"shoulder": math.inf})


@pytest.fixture
def sim(profile: RobotProfile) -> Iterator[RobotSimulator]:
    simulator = RobotSimulator(profile, telemetry_hz=10.0, video_fps=0.0)
    simulator.start()
    yield simulator
    simulator.stop()


def shoulder_axis(profile: RobotProfile, axes: tuple[int, ...]) -> int:
    return axes[profile.channels["shoulder"].axis]


def test_the_link_stops_a_channel_at_its_end_with_no_newer_command(
    profile: RobotProfile, sim: RobotSimulator
) -> None:
    safety: list[str] = []

    def on_event(event: LinkEvent) -> None:
        if isinstance(event, SafetyEvent):
            safety.append(event.message)

    link = UdpLink(profile, sim.address, extension=False)
    link.subscribe(on_event)
    link.start()
    stop_beating = threading.Event()

    def beat() -> None:
        # The commanding thread is alive all along: no watchdog may be what stops it.
        while not stop_beating.wait(0.05):
            link.heartbeat()

    beater = threading.Thread(target=beat, daemon=True)
    try:
        assert sim.wait_until(lambda s: s.telemetry_sent >= 1, DEADLINE_S)
        link.heartbeat()
        beater.start()
        start = sim.state().joints_rad["shoulder"]
        run_s = 0.6
        sent_at = time.monotonic()
        link.set_command(
            Command(velocities={"shoulder": SPEED_RAD_S}, until={"shoulder": sent_at + run_s})
        )
        assert sim.wait_until(lambda s: s.velocities["shoulder"] > 0, DEADLINE_S)
        assert sim.wait_until(lambda s: s.all_stopped, DEADLINE_S), "the shoulder never stopped"
        ended_at = sim.state().time_s
        # Nothing but the end stopped it: no newer command, no watchdog.
        assert link.command.velocities == {}
        assert safety == []
        # It ran for its time (a late loop would add to it; this machine may be busy).
        assert ended_at - sent_at >= run_s
        travelled = sim.state().joints_rad["shoulder"] - start
        assert travelled == pytest.approx(SPEED_RAD_S * run_s, rel=0.5)
        # The zero went out as a stop does: repeated against loss.
        stopped_count = sim.state().rcp_count
        repeats = profile.link.estop_repeats
        assert sim.wait_until(lambda s: s.rcp_count >= stopped_count + repeats - 1, DEADLINE_S)
        axes = [shoulder_axis(profile, r.packet.axes) for r in sim.received_commands()]
        first_zero = next(i for i, a in enumerate(axes) if i and a == 0 and axes[i - 1] != 0)
        assert axes[first_zero:].count(0) >= repeats
    finally:
        stop_beating.set()
        if beater.is_alive():
            beater.join()
        link.shutdown()


def test_a_newer_command_before_the_end_replaces_it(
    profile: RobotProfile, sim: RobotSimulator
) -> None:
    link = UdpLink(profile, sim.address, extension=False, gui_alive_timeout_s=None)
    link.start()
    try:
        assert sim.wait_until(lambda s: s.telemetry_sent >= 1, DEADLINE_S)
        now = time.monotonic()
        link.set_command(
            Command(velocities={"shoulder": SPEED_RAD_S}, until={"shoulder": now + 0.3})
        )
        # Replaced before its end by the same speed with no end: it must not stop at 0.3 s.
        link.set_command(Command(velocities={"shoulder": SPEED_RAD_S}))
        assert sim.wait_until(lambda s: s.velocities["shoulder"] > 0, DEADLINE_S)
        assert not sim.wait_until(lambda s: s.all_stopped, 1.0)
        link.set_command(Command())
        assert sim.wait_until(lambda s: s.all_stopped, DEADLINE_S)
    finally:
        link.shutdown()


def test_a_packet_built_after_the_end_carries_zero(profile: RobotProfile) -> None:
    # What _send_current builds between the end and the loop's wake-up.
    mapper = CommandMapper(profile)
    command = Command(velocities={"shoulder": SPEED_RAD_S}, until={"shoulder": 5.0})
    assert shoulder_axis(profile, mapper.to_packet(command.expired(4.9)).axes) != 0
    assert shoulder_axis(profile, mapper.to_packet(command.expired(5.0)).axes) == 0


def test_a_goal_needs_an_end_and_goes_with_its_channel() -> None:
    """Command.goals (a position command with a duration) belongs to a channel with an end:
    refused without one; dropped with the channel's end when it comes, when the channel is
    set again, and by a stop."""
    with pytest.raises(CommandError, match="a goal must be finite and have an end"):
        Command(velocities={"elbow": 0.2}, goals={"elbow": 0.5})
    with pytest.raises(CommandError):
        Command(velocities={"elbow": 0.2}, until={"elbow": 3.0}, goals={"elbow": math.nan})
    command = Command(
        velocities={"elbow": 0.2, "base": 0.1},
        until={"elbow": 3.0, "base": 5.0},
        goals={"elbow": 0.5, "base": -0.2},
    )
    assert command.expired(4.0).goals == {"base": -0.2}
    assert command.with_velocity("base", 0.3).goals == {"elbow": 0.5}
    assert command.stopped().goals == {}
    assert not command.same_wire(replace(command, goals={"elbow": 0.6, "base": -0.2}))
